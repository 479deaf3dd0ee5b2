#include "server/session.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <limits>
#include <tuple>
#include <unordered_map>

#include <glm/geometric.hpp>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "server/cell_deadlines.h"
#include "server/wire.h"

namespace vistream::server {

namespace {

namespace v1 = vistream::v1;

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

absl::Status CheckFinite(const v1::Vec3& v, const char* what, uint64_t pose) {
  for (auto [name, x] : {std::pair{"x", v.x()}, {"y", v.y()}, {"z", v.z()}}) {
    if (!std::isfinite(x)) {
      return absl::InvalidArgumentError(absl::StrCat("pose ", pose, ": ", what, ".", name, " is ", x,
                                                     " (positions and velocities must be finite)"));
    }
  }
  return absl::OkStatus();
}

// The encoded geometry bytes `m` carries (what the credit charges an ObjectGeometry); 0 for any
// other message.
double GeometryBytes(const v1::ServerMessage& m) {
  if (m.has_cluster()) return static_cast<double>(m.cluster().vertices().size() + m.cluster().indices().size());
  return m.has_geometry() ? static_cast<double>(m.geometry().vertices().size() + m.geometry().indices().size()) : 0.0;
}

// A level mesh's fields, which ObjectGeometry and ClusterGeometry name alike.
template <typename Message>
void SetLevelMesh(const scenes::EncodedLevelMesh& g, uint32_t level, Message* geo) {
  geo->set_level(level);
  geo->set_vertex_count(g.vertex_count);
  geo->set_index_count(g.index_count);
  geo->set_vertices(g.vertices);
  geo->set_indices(g.indices);
  geo->set_step_log2(g.step_log2);
  geo->mutable_origin()->Add(std::begin(g.origin), std::end(g.origin));
  geo->set_wide(g.wide);
}

// Object `o`'s geometry at `level` (0: full) for the wire (ObjectGeometry); returns its encoded
// bytes (what the credit charges).
size_t FillObject(const ServedScene& scene, uint32_t o, uint32_t level, v1::ObjectGeometry* geo) {
  geo->set_object_id(o);
  if (level == 0) {
    const scenes::EncodedMesh& g = scene.geometry(o);
    geo->set_vertex_count(g.vertex_count);
    geo->set_index_count(g.index_count);
    geo->set_vertices(g.vertices);
    geo->set_indices(g.indices);
    // A level's bounds are its mesh's, which the receiver has (58 bytes a message saved).
    const scenes::Aabb& b = scene.scene().objects[o].bounds;
    SetVec(b.min, geo->mutable_bounds_min());
    SetVec(b.max, geo->mutable_bounds_max());
    return g.EncodedBytes();
  }
  const scenes::EncodedLevelMesh& g = scene.level_geometry(o, level);
  SetLevelMesh(g, level, geo);
  geo->set_keeps_triangles(g.index_count == scene.scene().objects[o].mesh.indices.size());
  geo->set_full_bytes(scene.geometry(o).EncodedBytes());
  return g.EncodedBytes();
}

// Cluster `c`'s geometry at `level` >= 1 for the wire (ClusterGeometry); returns its encoded bytes.
size_t FillCluster(const ServedScene& scene, uint32_t c, uint32_t level, v1::ClusterGeometry* geo) {
  const scenes::EncodedLevelMesh& g = scene.cluster_geometry(c, level);
  geo->set_cluster_id(c);
  SetLevelMesh(g, level, geo);
  const std::vector<uint32_t>& objects = scene.scene().levels.clusters[c].objects;
  geo->mutable_objects()->Add(objects.begin(), objects.end());
  uint64_t full = 0;
  for (uint32_t o : objects) full += scene.geometry(o).EncodedBytes();
  geo->set_full_bytes(full);
  geo->set_keeps_triangles(scene.levels()->ClusterKeepsTriangles(c, level));
  const std::vector<uint32_t>& pieces = scene.levels()->ClusterObjectTriangles(c, level);
  geo->mutable_object_triangles()->Add(pieces.begin(), pieces.end());
  return g.EncodedBytes();
}

}  // namespace

ServedScene* SceneDirectory::Find(std::string_view name) const {
  for (ServedScene* s : scenes) {
    if (s->name() == name) return s;
  }
  return nullptr;
}

std::string SceneDirectory::Names() const {
  std::string out;
  for (const ServedScene* s : scenes) absl::StrAppend(&out, out.empty() ? "'" : ", '", s->name(), "'");
  return out;
}

std::shared_ptr<Session> Session::Create(uint64_t id, ServedScene* scene, const SessionLimits& limits, EventLog* log,
                                         std::function<void()> wake, SessionSeams seams) {
  return std::shared_ptr<Session>(new Session(id, scene, nullptr, limits, log, std::move(wake), std::move(seams)));
}

std::shared_ptr<Session> Session::Create(uint64_t id, const SceneDirectory* scenes, const SessionLimits& limits,
                                         EventLog* log, std::function<void()> wake, SessionSeams seams) {
  return std::shared_ptr<Session>(new Session(id, nullptr, scenes, limits, log, std::move(wake), std::move(seams)));
}

Session::Session(uint64_t id, ServedScene* scene, const SceneDirectory* directory, const SessionLimits& limits,
                 EventLog* log, std::function<void()> wake, SessionSeams seams)
    : id_(id),
      directory_(directory),
      scene_(scene),
      limits_(limits),
      log_(log),
      wake_(std::move(wake)),
      seams_(std::move(seams)),
      pvs_(seams_.pvs != nullptr ? seams_.pvs : scene != nullptr ? &scene->scheduler() : nullptr),
      masks_(seams_.masks != nullptr ? seams_.masks : scene != nullptr ? &scene->masks() : nullptr),
      start_s_(Now()),
      epsilon_size_m_(limits.epsilon_size_m) {
  ChainOptions chain = limits.chain;
  chain.standing_size_m = epsilon_size_m_;
  planner_ = MaskPlanner(chain);
  stats_.set_session_id(id);
  stats_.set_cell_id(-1);
  pose_tokens_ = 2.0 * limits_.max_pose_rate_hz;
}

Session::~Session() { End(); }

double Session::Now() const { return seams_.clock ? seams_.clock() : SteadySeconds(); }

void Session::End() {
  PvsSource* pvs = nullptr;
  {
    std::lock_guard lock(mu_);
    if (ended_) return;
    ended_ = true;
    pvs = pvs_;
  }
  if (pvs != nullptr) pvs->CancelAll(id_);  // none before Hello picked a scene
}

ServedScene* Session::scene() const {
  std::lock_guard lock(mu_);
  return hello_ ? scene_ : nullptr;
}

bool Session::greeted() const {
  std::lock_guard lock(mu_);
  return hello_;
}

absl::Status Session::failure() const {
  std::lock_guard lock(mu_);
  return failure_;
}

absl::Status Session::OnMessage(const v1::ClientMessage& message, double now) {
  switch (message.body_case()) {
    case v1::ClientMessage::kHello: {
      std::lock_guard lock(mu_);
      return OnHello(message.hello());
    }
    case v1::ClientMessage::kPose:
      return OnPose(message.pose(), now);
    case v1::ClientMessage::kCredit: {
      std::lock_guard lock(mu_);
      if (!hello_) return absl::FailedPreconditionError("Credit before Hello: a session starts with Hello");
      // Clamped: a client may grant "everything" without overflowing the count.
      constexpr int64_t kMaxCredit = int64_t{1} << 52;
      credit_ = std::min(kMaxCredit, credit_ + static_cast<int64_t>(std::min<uint64_t>(message.credit().bytes(), kMaxCredit)));
      return absl::OkStatus();
    }
    case v1::ClientMessage::BODY_NOT_SET:
      break;
  }
  return absl::InvalidArgumentError("empty ClientMessage: expected hello, pose or credit");
}


absl::Status Session::OnHello(const v1::Hello& hello) {
  if (hello_) return absl::FailedPreconditionError("second Hello: a session says Hello exactly once");
  if (hello.protocol_version() != v1::PROTOCOL_VERSION_CURRENT) {
    return absl::FailedPreconditionError(absl::StrCat("protocol version ", hello.protocol_version(),
                                                      " is not supported: this server speaks version ",
                                                      static_cast<int>(v1::PROTOCOL_VERSION_CURRENT)));
  }
  if (directory_ != nullptr) {
    ServedScene* picked = directory_->Find(hello.scene());
    if (picked == nullptr) {
      return absl::NotFoundError(absl::StrCat("scene '", hello.scene(), "' is not served here: this server serves ",
                                              directory_->Names()));
    }
    scene_ = picked;
    pvs_ = &picked->scheduler();
    masks_ = &picked->masks();
    epsilon_size_m_ = picked->viewcell().epsilon_m;
    ChainOptions chain = limits_.chain;
    chain.standing_size_m = epsilon_size_m_;
    planner_ = MaskPlanner(chain);
  } else if (hello.scene() != scene_->name()) {
    return absl::NotFoundError(
        absl::StrCat("scene '", hello.scene(), "' is not served here: this server serves '", scene_->name(), "'"));
  }
  const scenes::Scene& scene = scene_->scene();
  if (hello.held_levels_size() != 0 && hello.held_levels_size() != hello.held_objects_size()) {
    return absl::InvalidArgumentError(absl::StrCat("Hello.held_levels has ", hello.held_levels_size(),
                                                   " entries for ", hello.held_objects_size(),
                                                   " held_objects: expected one each, or none"));
  }
  if (hello.has_levels() && hello.levels().screen_error_px() != 0.0) {
    const v1::LevelRequest& l = hello.levels();
    if (l.viewport_width_px() < 1 || l.viewport_width_px() > 16384 || l.viewport_height_px() < 1 ||
        l.viewport_height_px() > 16384) {
      return absl::InvalidArgumentError(absl::StrCat("Hello.levels: viewport ", l.viewport_width_px(), " x ",
                                                     l.viewport_height_px(), " px is outside 1 to 16384"));
    }
    if (!(l.vertical_fov_rad() > 0.0 && l.vertical_fov_rad() < 3.14159)) {
      return absl::InvalidArgumentError(
          absl::StrCat("Hello.levels.vertical_fov_rad = ", l.vertical_fov_rad(), ": expected an angle in (0, pi)"));
    }
    if (!(l.screen_error_px() > 0.0 && l.screen_error_px() <= 1000.0)) {
      return absl::InvalidArgumentError(
          absl::StrCat("Hello.levels.screen_error_px = ", l.screen_error_px(), ": expected 0 (off) or (0, 1000] pixels"));
    }
    screen_ = {l.viewport_width_px(), l.viewport_height_px(), l.vertical_fov_rad()};
    tau_px_ = l.screen_error_px();
    levels_on_ = scene_->levels() != nullptr;
    clusters_on_ = levels_on_ && l.clusters() && !scene.levels.clusters.empty();
  }
  if (hello.held_cluster_levels_size() != hello.held_clusters_size()) {
    return absl::InvalidArgumentError(absl::StrCat("Hello.held_cluster_levels has ", hello.held_cluster_levels_size(),
                                                   " entries for ", hello.held_clusters_size(),
                                                   " held_clusters: expected one each"));
  }
  for (int k = 0; k < hello.held_clusters_size(); ++k) {
    const uint32_t c = hello.held_clusters(k), level = hello.held_cluster_levels(k);
    if (c >= kClusterKey) {
      return absl::InvalidArgumentError(absl::StrCat("Hello.held_clusters[", k, "] = ", c, " is not a cluster id"));
    }
    // A cluster or level this session could not have sent counts as not held.
    if (!clusters_on_ || c >= scene.levels.clusters.size() || level < 1 ||
        level > scene.levels.clusters[c].levels.size()) {
      continue;
    }
    if (!sent_.insert(kClusterKey | c).second) continue;
    held_level_[kClusterKey | c] = level;
    held_bytes_ += scene_->ClusterRawBytes(c, level);
  }
  for (int k = 0; k < hello.held_objects_size(); ++k) {
    const uint32_t o = hello.held_objects(k);
    if (o >= scene.objects.size()) {
      return absl::InvalidArgumentError(absl::StrCat("Hello.held_objects[", k, "] = ", o, ": the scene has ",
                                                     scene.objects.size(), " objects"));
    }
    const uint32_t level = hello.held_levels_size() != 0 ? hello.held_levels(k) : 0;
    if (level != 0) {
      // A level this session could not have sent (a server restarted without levels, or with
      // other ones): the object counts as not held, and comes again at the level its cells need.
      const size_t count = levels_on_ ? scene_->levels()->levels().objects[o].size() : 0;
      if (level > count) continue;
    }
    if (!sent_.insert(o).second) continue;  // named twice: the first counts
    if (level != 0) held_level_[o] = level;
    held_bytes_ += scene_->RawBytes(o, level);
  }
  pvs_deltas_ = hello.pvs_deltas();
  hello_ = true;
  planner_.set_deflate(hello.deflated_masks());
  planner_.set_on(hello.epsilon_masks() && seams_.epsilon_masks && scene_->epsilon() != nullptr && masks_ != nullptr);
  stats_.set_scene(scene_->name());
  memory_budget_ = hello.memory_budget_bytes();
  v1::ServerMessage info;
  *info.mutable_scene_info() = scene_->scene_info();
  info.mutable_scene_info()->set_levels(levels_on_);
  QueueControl(std::move(info));
  if (log_ != nullptr) {
    log_->SetScene(id_, scene_->name());
    log_->Write(id_, "hello", {{"scene", scene_->name()},
                               {"held_objects", hello.held_objects_size()},
                               {"memory_budget_bytes", static_cast<uint64_t>(memory_budget_)},
                               {"epsilon_masks", planner_.on() ? "yes" : "no"}});
  }
  return absl::OkStatus();
}

absl::Status Session::OnPose(const v1::Pose& pose, double now) {
  std::vector<CellId> left;
  {
    std::lock_guard lock(mu_);
    ++poses_;
    if (!hello_) return absl::FailedPreconditionError("Pose before Hello: a session starts with Hello");
    if (absl::Status st = CheckFinite(pose.position(), "position", poses_); !st.ok()) return st;
    if (absl::Status st = CheckFinite(pose.velocity(), "velocity", poses_); !st.ok()) return st;
    if (!std::isfinite(pose.yaw_rad()) || !std::isfinite(pose.pitch_rad()) || !std::isfinite(pose.client_time_s())) {
      return absl::InvalidArgumentError(absl::StrCat("pose ", poses_, ": yaw, pitch and client_time_s must be finite"));
    }
    // A token bucket: bursts up to two seconds' worth, then the sustained rate.
    if (last_pose_s_ > 0.0) {
      pose_tokens_ = std::min(2.0 * limits_.max_pose_rate_hz,
                              pose_tokens_ + (now - last_pose_s_) * limits_.max_pose_rate_hz);
    }
    last_pose_s_ = now;
    pose_tokens_ -= 1.0;
    if (pose_tokens_ < 0.0) {
      return absl::ResourceExhaustedError(absl::StrFormat(
          "pose %d: more than %.0f poses per second (the session's limit)", poses_, limits_.max_pose_rate_hz));
    }
    const glm::dvec3 p = ToVec(pose.position());
    const std::optional<CellId> cell = scene_->grid().CellAt(glm::dvec2(p));
    if (!cell.has_value()) {
      const scenes::Aabb b = scene_->grid().Bounds();
      return absl::OutOfRangeError(absl::StrFormat(
          "pose %d: position (%.2f, %.2f) is outside the viewcell grid [%.1f, %.1f] x [%.1f, %.1f] m", poses_, p.x,
          p.y, b.min.x, b.max.x, b.min.y, b.max.y));
    }
    // The PVSs hold for eyes inside their viewcell's band only (a client above the roofs sees
    // what no viewcell's PVS holds); where cells follow terrain, each cell has its own.
    const visibility::ViewcellGrid& grid = scene_->grid();
    const visibility::CellBand band = grid.Band(*cell);
    if (!(p.z >= band.z0 && p.z <= band.z1)) {
      if (!grid.has_bands()) {
        return absl::OutOfRangeError(absl::StrFormat(
            "pose %d: eye height %.2f m is outside the viewcells' band [%.2f, %.2f] m", poses_, p.z, band.z0, band.z1));
      }
      const visibility::CellCoord c = grid.Coord(*cell);
      return absl::OutOfRangeError(absl::StrFormat(
          "pose %d: eye height %.2f m is outside viewcell %d,%d's band [%.2f, %.2f] m", poses_, p.z, c.i, c.j,
          band.z0, band.z1));
    }
    position_ = p;
    velocity_ = ToVec(pose.velocity());
    if (!current_.has_value() || *current_ != *cell) {
      const std::optional<CellId> from = current_;
      const std::vector<CellId> before = wanted_;
      current_ = *cell;
      stats_.set_cell_id(*cell);
      if (from.has_value()) {
        stats_.set_crossings(stats_.crossings() + 1);
        if (seams_.late_cell && !Served(*cell)) seams_.late_cell(scene_->name());
        if (log_ != nullptr) {
          const visibility::CellCoord a = scene_->grid().Coord(*from), b = scene_->grid().Coord(*cell);
          log_->Write(id_, "crossing", {{"from", absl::StrCat(a.i, ",", a.j)}, {"to", absl::StrCat(b.i, ",", b.j)}});
        }
      }
      SetWanted(now);
      for (CellId c : before) {
        if (std::find(wanted_.begin(), wanted_.end(), c) == wanted_.end()) left.push_back(c);
      }
      if (from.has_value() && seams_.crossing_served) {
        Crossing crossing{now, {}};
        for (CellId c : wanted_) {
          if (std::find(before.begin(), before.end(), c) == before.end() && !Served(c)) crossing.cells.push_back(c);
        }
        crossings_.push_back(std::move(crossing));
        // Bounded: a client that crosses back and forth and grants no credit keeps cells
        // unserved; its oldest crossings are then not timed.
        if (crossings_.size() > 64) crossings_.pop_front();
        NoteServedCrossings(now);
      }
      // Geometry the cells left behind needed stays with the client: it is evicted only when the
      // memory budget needs the room (MakeRoom: what no wanted cell needs first), so nothing is
      // sent twice unless the budget forced it out (DESIGN.md: never sent twice in a session).
    } else if (seams_.look_ahead && Turned(velocity_, ranked_velocity_)) {
      SetWanted(now);  // the cells ahead are others now: re-rank requests and geometry
    }
    UpdateMasks(now);
  }
  for (CellId c : left) pvs_->Cancel(id_, c);
  return absl::OkStatus();
}

void Session::SetWanted(double now) {
  ranked_velocity_ = velocity_;
  const std::vector<std::pair<double, CellId>> order =
      WantedCells(scene_->grid(), *current_, position_, velocity_, now, seams_.look_ahead);
  wanted_.clear();
  for (const auto& [deadline, c] : order) wanted_.push_back(c);
  // Forget what no longer matters: requests, PVSs, their queued lists and geometry.
  auto unwanted = [&](CellId c) { return std::find(wanted_.begin(), wanted_.end(), c) == wanted_.end(); };
  std::erase_if(received_, [&](const auto& entry) { return unwanted(entry.first); });
  std::erase_if(cell_levels_, [&](const auto& entry) { return unwanted(entry.first); });
  std::erase_if(requested_, unwanted);
  std::erase_if(emitted_, unwanted);
  std::erase_if(pending_geometry_, [&](const auto& entry) { return unwanted(entry.first); });
  planner_.Rewant(wanted_);
  std::erase_if(control_, [&](const Control& c) {
    if (!c.cell.has_value() || !unwanted(*c.cell)) return false;
    control_bytes_ -= c.bytes;
    return true;
  });
  // Ask for what is missing, in order: the scheduler serves the earliest deadline first, and
  // a cell asked for again gets its new deadline (re-prioritised as the client turns).
  for (const auto& [deadline, c] : order) {
    if (received_.count(c) == 0) RequestCell(c, deadline);
  }
  EmitReady();
  // Geometry of wanted cells that was skipped for the memory budget gets another chance.
  for (CellId c : wanted_) {
    auto it = received_.find(c);
    if (it == received_.end() || emitted_.count(c) == 0) continue;
    std::deque<uint32_t>& q = pending_geometry_[c];
    const std::unordered_set<uint32_t> queued(q.begin(), q.end());
    const auto lv = cell_levels_.find(c);
    const CellLevels* levels = lv == cell_levels_.end() ? nullptr : &lv->second;
    if (levels != nullptr) {
      for (const auto& [cluster, level] : levels->clusters) {
        const uint32_t key = kClusterKey | cluster;
        if (!Satisfied(c, key) && queued.count(key) == 0) q.push_back(key);
      }
    }
    for (uint32_t o : it->second->objects) {
      if (levels != nullptr && levels->cover.contains(o)) continue;
      if (!Satisfied(c, o) && queued.count(o) == 0) q.push_back(o);
    }
  }
}

void Session::RequestCell(CellId cell, double deadline) {
  requested_.insert(cell);
  std::weak_ptr<Session> weak = weak_from_this();
  CellPvsPtr cached = pvs_->Request(id_, cell, deadline, [weak](const CellPvsPtr& pvs) {
    std::shared_ptr<Session> s = weak.lock();
    if (s == nullptr) return;
    {
      std::lock_guard lock(s->mu_);
      if (s->ended_) return;
      s->OnCellReady(pvs, false);
    }
    if (s->wake_) s->wake_();
  });
  if (cached != nullptr) OnCellReady(cached, true);
}

void Session::OnCellReady(const CellPvsPtr& pvs, bool from_cache) {
  if (requested_.erase(pvs->cell) == 0) return;  // no longer wanted
  received_[pvs->cell] = pvs;
  if (levels_on_) {
    // The coarsest level of each object that holds from anywhere in the cell's eye band.
    const scenes::Aabb box = scene_->grid().CellBox(pvs->cell);
    const std::vector<scenes::DrawItem> items =
        scenes::ChooseLevels(*scene_->levels(), pvs->objects, box, screen_, tau_px_, /*clusters=*/false);
    CellLevels& levels = cell_levels_[pvs->cell];
    levels = CellLevels{};
    levels.objects.assign(pvs->objects.size(), 0);
    for (const scenes::DrawItem& it : items) {
      const auto at = std::lower_bound(pvs->objects.begin(), pvs->objects.end(), it.id);
      levels.objects[static_cast<size_t>(at - pvs->objects.begin())] = it.level;
    }
    // Clusters where they cost no more bytes and triangles than the objects' own levels; each
    // object keeps its own level too (a client holding it there need not get the cluster).
    if (clusters_on_) {
      const std::vector<scenes::DrawItem> with =
          scenes::ChooseLevels(*scene_->levels(), pvs->objects, box, screen_, tau_px_, /*clusters=*/true);
      for (const scenes::DrawItem& it : with) {
        if (it.kind != scenes::DrawItem::Kind::kCluster) continue;
        levels.clusters.emplace_back(it.id, it.level);
        std::vector<uint32_t>& members = levels.members[it.id];
        const std::vector<uint32_t>& all = scene_->scene().levels.clusters[it.id].objects;
        std::set_intersection(all.begin(), all.end(), pvs->objects.begin(), pvs->objects.end(),
                              std::back_inserter(members));
        for (uint32_t o : members) levels.cover.emplace(o, it.id);
      }
    }
  }
  if (log_ != nullptr) {
    const visibility::CellCoord c = scene_->grid().Coord(pvs->cell);
    log_->Write(id_, "pvs", {{"cell", absl::StrCat(c.i, ",", c.j)},
                             {"source", from_cache ? "cache" : pvs->from_store ? "store" : "computed"},
                             {"ms", from_cache ? 0.0 : pvs->compute_s * 1000.0},  // a cache hit costs none
                             {"objects", static_cast<uint64_t>(pvs->objects.size())}});
  }
  EmitReady();
}

void Session::EmitReady() {
  if (!current_.has_value()) return;
  // The current cell goes first; its neighbours wait for it.
  if (emitted_.count(*current_) == 0) {
    if (received_.count(*current_) == 0) return;
    Emit(*current_);
  }
  for (CellId c : wanted_) {
    if (emitted_.count(c) == 0 && received_.count(c) > 0) Emit(c);
  }
  PostMasks();
}

void Session::Emit(CellId cell) {
  const CellPvsPtr& pvs = received_.at(cell);
  v1::ServerMessage m;
  v1::ViewcellPvs* list = m.mutable_pvs();
  list->set_cell_id(cell);
  list->mutable_object_ids()->Add(pvs->objects.begin(), pvs->objects.end());
  list->set_compute_s(pvs->compute_s);
  const CellLevels* levels = nullptr;
  if (levels_on_) {
    if (clusters_on_) {
      AdoptHeldClusters(cell);
      DropDearClusters(cell);
    }
    levels = &cell_levels_.at(cell);
    list->mutable_object_levels()->Add(levels->objects.begin(), levels->objects.end());
    for (const auto& [c, level] : levels->clusters) {
      list->add_cluster_ids(c);
      list->add_cluster_levels(level);
    }
  }
  QueueControl(std::move(m));
  control_.back().cell = cell;
  emitted_.insert(cell);
  // What the cell needs: its chosen clusters (each standing for its objects), then the others.
  std::deque<uint32_t>& q = pending_geometry_[cell];
  if (levels != nullptr) {
    for (const auto& [c, level] : levels->clusters) {
      if (!Satisfied(cell, kClusterKey | c)) q.push_back(kClusterKey | c);
    }
  }
  for (uint32_t o : pvs->objects) {
    if (levels != nullptr && levels->cover.contains(o)) continue;
    if (!Satisfied(cell, o)) q.push_back(o);
  }
  stats_.set_pvs_sent(stats_.pvs_sent() + 1);
}

void Session::AdoptHeldClusters(CellId cell) {
  CellLevels& levels = cell_levels_.at(cell);
  const scenes::LevelIndex& index = *scene_->levels();
  const scenes::Scene& scene = scene_->scene();
  const std::vector<uint32_t>& pvs = received_.at(cell)->objects;
  const scenes::Aabb box = scene_->grid().CellBox(cell);
  std::vector<std::pair<uint32_t, uint32_t>> held;  // (cluster, level), ascending
  for (const auto& [key, level] : held_level_) {
    if ((key & kClusterKey) != 0) held.emplace_back(key & ~kClusterKey, level);
  }
  std::sort(held.begin(), held.end());
  bool adopted = false;
  for (const auto& [c, level] : held) {
    const scenes::Cluster& cluster = scene.levels.clusters[c];
    if (levels.members.contains(c) || !index.ClusterKeepsTriangles(c, level)) continue;
    if (scenes::ErrorPixels(cluster.levels[level - 1].error_m, scenes::BoxDistance(box, cluster.bounds), screen_) >
        tau_px_) {
      continue;  // too coarse from here
    }
    std::vector<uint32_t> members;
    std::set_intersection(cluster.objects.begin(), cluster.objects.end(), pvs.begin(), pvs.end(),
                          std::back_inserter(members));
    // Only where it draws what the objects' own levels would (their triangles, masked alike).
    const bool fits = !members.empty() && std::all_of(members.begin(), members.end(), [&](uint32_t o) {
      const uint32_t own = NeededLevel(cell, o);
      const size_t full = scene.objects[o].mesh.TriangleCount();
      return own == 0 || scene.levels.objects[o][own - 1].mesh.TriangleCount() == full;
    });
    if (!fits) continue;
    // It replaces the chosen clusters that share an object with it (not yet sent: it is held).
    std::erase_if(levels.clusters, [&](const std::pair<uint32_t, uint32_t>& other) {
      const std::vector<uint32_t>& theirs = levels.members.at(other.first);
      const bool shares = std::any_of(theirs.begin(), theirs.end(), [&](uint32_t o) {
        return std::binary_search(members.begin(), members.end(), o);
      });
      if (!shares) return false;
      for (uint32_t o : theirs) levels.cover.erase(o);
      levels.members.erase(other.first);
      return true;
    });
    for (uint32_t o : members) levels.cover[o] = c;
    levels.members[c] = std::move(members);
    levels.clusters.emplace_back(c, level);
    adopted = true;
  }
  if (adopted) std::sort(levels.clusters.begin(), levels.clusters.end());
}

void Session::DropDearClusters(CellId cell) {
  CellLevels& levels = cell_levels_.at(cell);
  const scenes::LevelIndex& index = *scene_->levels();
  std::erase_if(levels.clusters, [&](const std::pair<uint32_t, uint32_t>& chosen) {
    const auto [c, level] = chosen;
    if (HeldLevel(kClusterKey | c) != 0 && HeldLevel(kClusterKey | c) <= level) return false;  // held: free
    uint64_t missing = 0;
    std::vector<uint32_t>& members = levels.members.at(c);
    for (uint32_t o : members) {
      const uint32_t own = NeededLevel(cell, o);
      if (sent_.count(o) > 0 && HeldLevel(o) <= own) continue;
      // An object another wanted cell needs on its own (not through this cluster) comes anyway.
      bool needed_elsewhere = false;
      for (const auto& [other, other_levels] : cell_levels_) {
        if (other == cell || other_levels.objects.empty()) continue;
        const std::vector<uint32_t>& pvs = received_.at(other)->objects;
        if (!std::binary_search(pvs.begin(), pvs.end(), o)) continue;
        const auto cover = other_levels.cover.find(o);
        if (cover == other_levels.cover.end() || cover->second != c) {
          needed_elsewhere = true;
          break;
        }
      }
      if (!needed_elsewhere) missing += index.ObjectBytes(o, own);
    }
    if (index.ClusterBytes(c, level) <= missing) return false;
    for (uint32_t o : members) levels.cover.erase(o);
    levels.members.erase(c);
    return true;
  });
}

v1::ServerMessage Session::Forget(std::vector<uint32_t> objects, const char* reason) {
  std::sort(objects.begin(), objects.end());
  v1::ServerMessage m;
  for (uint32_t key : objects) {
    held_bytes_ -= RawBytesOf(key, HeldLevel(key));
    sent_.erase(key);
    held_level_.erase(key);
    if ((key & kClusterKey) != 0) {
      m.mutable_evict()->add_cluster_ids(key & ~kClusterKey);
    } else {
      m.mutable_evict()->add_object_ids(key);
    }
  }
  stats_.set_evicted_objects(stats_.evicted_objects() + objects.size());
  if (log_ != nullptr) {
    log_->Write(id_, "evict", {{"objects", static_cast<uint64_t>(objects.size())}, {"reason", reason}});
  }
  return m;
}

std::optional<v1::ServerMessage> Session::MakeRoom(size_t bytes, size_t rank) {
  // Rank what the client holds by when it is needed (the position of its earliest wanted cell;
  // the current cell is 0): objects of no wanted cell first, then latest needed first, and
  // never one needed as soon as `rank` or sooner; among those needed alike, the largest held
  // first (with levels: the finer levels of objects gone far away, issue 45).
  const size_t kNever = wanted_.size();
  std::unordered_map<uint32_t, size_t> needed_at;  // object -> position of its first wanted cell
  for (size_t k = 0; k < wanted_.size(); ++k) {
    auto it = received_.find(wanted_[k]);
    if (it == received_.end()) continue;
    for (uint32_t o : it->second->objects) needed_at.emplace(o, k);  // keeps the earliest
    if (auto lv = cell_levels_.find(wanted_[k]); lv != cell_levels_.end()) {
      for (const auto& [c, level] : lv->second.clusters) needed_at.emplace(kClusterKey | c, k);
    }
  }
  // (need rank, bytes held, object): latest need first, then largest first.
  std::vector<std::tuple<size_t, uint64_t, uint32_t>> candidates;
  for (uint32_t o : sent_) {
    auto it = needed_at.find(o);
    const size_t at = it == needed_at.end() ? kNever : it->second;
    if (at <= rank) continue;
    candidates.emplace_back(at, RawBytesOf(o, HeldLevel(o)), o);
  }
  std::sort(candidates.begin(), candidates.end(), std::greater<>());
  std::vector<uint32_t> evict;
  size_t freed = 0;
  for (const auto& [at, held, o] : candidates) {
    if (held_bytes_ - freed + bytes <= memory_budget_) break;
    evict.push_back(o);
    freed += held;
  }
  if (evict.empty() || held_bytes_ - freed + bytes > memory_budget_) return std::nullopt;  // cannot fit
  // Evicted objects of wanted cells are queued again at the next crossing or turn (SetWanted).
  v1::ServerMessage m = Forget(std::move(evict), "memory budget");
  stats_.set_bytes_sent(stats_.bytes_sent() + m.ByteSizeLong());
  return m;
}

void Session::UpdateMasks(double now) {
  if (!planner_.on() || !current_.has_value()) return;
  planner_.Advance(
      position_, velocity_, now, scene_->grid(),
      [this](CellId c) { return std::find(wanted_.begin(), wanted_.end(), c) != wanted_.end(); }, &stats_);
  PostMasks();
}

void Session::PostMasks() {
  if (!planner_.on()) return;
  const visibility::EpsilonSuperset* eps = scene_->epsilon();
  for (MaskPlanner::Job& job : planner_.TakeJobs(emitted_, received_)) {
    std::weak_ptr<Session> weak = weak_from_this();
    // The work computes the mask; what it returns queues it (the simulator charges the work's
    // time before delivering).
    masks_->Post(
        [weak, key = job.key, box = job.box, pvs = std::move(job.pvs), eps]() -> std::function<void()> {
          {
            std::shared_ptr<Session> s = weak.lock();
            if (s == nullptr) return nullptr;
            std::lock_guard lock(s->mu_);
            if (s->ended_ || !s->planner_.Planned(key)) return nullptr;  // the path moved on
          }
          BuiltMask mask = BuildMask(*eps, box, *pvs);
          return [weak, key, mask = std::move(mask)]() mutable {
            std::shared_ptr<Session> s = weak.lock();
            if (s == nullptr) return;
            {
              std::lock_guard lock(s->mu_);
              if (s->ended_ || !s->planner_.AddComputed(key, std::move(mask))) return;  // dropped meanwhile
            }
            if (s->wake_) s->wake_();
          };
        },
        job.deadline);
  }
}

std::optional<v1::ServerMessage> Session::SendObject(uint32_t o, size_t rank, bool* sent) {
  if (rank >= wanted_.size()) return SendLevel(o, 0, rank, sent);
  const CellId cell = wanted_[rank];
  if (auto lv = cell_levels_.find(cell); lv != cell_levels_.end()) {
    if (auto c = lv->second.cover.find(o); c != lv->second.cover.end()) {
      const uint32_t key = kClusterKey | c->second;
      *sent = false;
      if (sent_.count(key) > 0) return std::nullopt;  // drawn by the cluster held
      return SendLevel(key, NeededLevel(cell, key), rank, sent);
    }
  }
  return SendLevel(o, NeededLevel(cell, o), rank, sent);
}

std::optional<v1::ServerMessage> Session::SendLevel(uint32_t key, uint32_t level, size_t rank, bool* sent) {
  *sent = false;
  // A level replaces the one held: the budget counts the difference.
  const uint64_t raw = RawBytesOf(key, level);
  const uint64_t replaced = sent_.count(key) > 0 ? RawBytesOf(key, HeldLevel(key)) : 0;
  if (memory_budget_ != 0 && held_bytes_ - replaced + raw > memory_budget_) {
    // Room is made by evicting what the client needs later than this cell (the Evict goes
    // first, the object right after it); without such objects it waits for the next crossing.
    return MakeRoom(raw - std::min(raw, replaced), rank);
  }
  v1::ServerMessage m;
  const size_t encoded = (key & kClusterKey) != 0 ? FillCluster(*scene_, key & ~kClusterKey, level, m.mutable_cluster())
                                                  : FillObject(*scene_, key, level, m.mutable_geometry());
  sent_.insert(key);
  if (level == 0) held_level_.erase(key);
  else held_level_[key] = level;
  held_bytes_ += raw - replaced;
  const size_t bytes = m.ByteSizeLong();
  credit_ -= static_cast<int64_t>(encoded);
  stats_.set_objects_sent(stats_.objects_sent() + 1);
  stats_.set_geometry_bytes_sent(stats_.geometry_bytes_sent() + encoded);
  stats_.set_bytes_sent(stats_.bytes_sent() + bytes);
  *sent = true;
  return m;
}

uint32_t Session::HeldLevel(uint32_t o) const {
  const auto it = held_level_.find(o);
  return it == held_level_.end() ? 0 : it->second;
}

uint64_t Session::RawBytesOf(uint32_t key, uint32_t level) const {
  return (key & kClusterKey) != 0 ? scene_->ClusterRawBytes(key & ~kClusterKey, level) : scene_->RawBytes(key, level);
}

uint32_t Session::NeededLevel(CellId cell, uint32_t key) const {
  if (!levels_on_) return 0;
  const auto lv = cell_levels_.find(cell);
  const auto pvs = received_.find(cell);
  if (lv == cell_levels_.end() || pvs == received_.end()) return 0;
  if ((key & kClusterKey) != 0) {
    const auto& clusters = lv->second.clusters;
    const auto at = std::lower_bound(clusters.begin(), clusters.end(), std::pair{key & ~kClusterKey, uint32_t{0}});
    return at != clusters.end() && at->first == (key & ~kClusterKey) ? at->second : 0;
  }
  const std::vector<uint32_t>& objects = pvs->second->objects;
  const auto at = std::lower_bound(objects.begin(), objects.end(), key);
  if (at == objects.end() || *at != key) return 0;
  return lv->second.objects[static_cast<size_t>(at - objects.begin())];
}

bool Session::Satisfied(CellId cell, uint32_t key) const {
  // Held at the level the cell needs, or finer (a cluster's level 0 is never needed).
  auto held_for = [&](uint32_t k) {
    return sent_.count(k) > 0 && (!levels_on_ || HeldLevel(k) <= NeededLevel(cell, k));
  };
  if (held_for(key)) return true;
  if (!clusters_on_) return false;
  const auto lv = cell_levels_.find(cell);
  if (lv == cell_levels_.end()) return false;
  if ((key & kClusterKey) != 0) {
    const auto members = lv->second.members.find(key & ~kClusterKey);
    return members != lv->second.members.end() && std::all_of(members->second.begin(), members->second.end(), held_for);
  }
  const auto c = lv->second.cover.find(key);
  return c != lv->second.cover.end() && held_for(kClusterKey | c->second);
}

bool Session::Drawable(CellId cell, uint32_t key) const {
  if (sent_.count(key) > 0) return true;
  if (!clusters_on_) return false;
  const auto lv = cell_levels_.find(cell);
  if (lv == cell_levels_.end()) return false;
  if ((key & kClusterKey) != 0) {
    const auto members = lv->second.members.find(key & ~kClusterKey);
    return members != lv->second.members.end() &&
           std::all_of(members->second.begin(), members->second.end(), [&](uint32_t o) { return sent_.count(o) > 0; });
  }
  const auto c = lv->second.cover.find(key);
  return c != lv->second.cover.end() && sent_.count(kClusterKey | c->second) > 0;
}

void Session::QueueControl(v1::ServerMessage message) {
  const size_t bytes = message.ByteSizeLong();
  control_.push_back(Control{std::move(message), bytes, std::nullopt});
  control_bytes_ += bytes;
  if (control_bytes_ > limits_.max_queued_bytes && failure_.ok()) {
    failure_ = absl::ResourceExhaustedError(absl::StrCat(
        control_bytes_, " bytes are queued for a client that does not read them (the limit is ",
        limits_.max_queued_bytes, ")"));
  }
}

bool Session::Served(CellId cell) const {
  if (emitted_.count(cell) == 0) return false;
  auto it = pending_geometry_.find(cell);
  if (it == pending_geometry_.end()) return true;
  return std::all_of(it->second.begin(), it->second.end(), [&](uint32_t o) { return Satisfied(cell, o); });
}

void Session::NoteServedCrossings(double now) {
  while (!crossings_.empty()) {
    Crossing& c = crossings_.front();
    // A cell the client turned away from no longer counts.
    std::erase_if(c.cells, [&](CellId cell) {
      return std::find(wanted_.begin(), wanted_.end(), cell) == wanted_.end() || Served(cell);
    });
    if (!c.cells.empty()) return;
    seams_.crossing_served(scene_->name(), now - c.at_s);
    crossings_.pop_front();
  }
}

std::optional<v1::ServerMessage> Session::NextMessage() {
  std::lock_guard lock(mu_);
  if (ended_ || !failure_.ok()) return std::nullopt;
  if (!crossings_.empty() && control_.empty()) NoteServedCrossings(Now());
  if (!control_.empty()) {
    Control c = std::move(control_.front());
    control_.pop_front();
    control_bytes_ -= c.bytes;
    if (c.message.has_pvs() && pvs_deltas_) {
      // The difference from the list sent before, where that is shorter (decided as it goes
      // out: a queued list may be dropped before it is sent).
      v1::ViewcellPvs* list = c.message.mutable_pvs();
      proto::PvsList next{list->cell_id(), {list->object_ids().begin(), list->object_ids().end()},
                          {list->object_levels().begin(), list->object_levels().end()},
                          {list->cluster_ids().begin(), list->cluster_ids().end()},
                          {list->cluster_levels().begin(), list->cluster_levels().end()}};
      if (previous_list_.has_value()) {
        v1::ViewcellPvs delta = *list;
        proto::EncodePvsDelta(*previous_list_, next, &delta);
        if (delta.ByteSizeLong() < list->ByteSizeLong()) *list = std::move(delta);
      }
      previous_list_ = std::move(next);
      c.bytes = c.message.ByteSizeLong();
    }
    stats_.set_bytes_sent(stats_.bytes_sent() + c.bytes);
    return std::move(c.message);
  }
  if (credit_ <= 0 || !current_.has_value()) return std::nullopt;
  // The link budget: while the client's cell or the next lacks geometry, masks take at most
  // their share, and objects it lacks go before finer levels.
  const bool urgent = Urgent();
  if (!urgent) mask_tokens_ = 0.0;
  auto earn = [&](const std::optional<v1::ServerMessage>& m) {
    if (!urgent || !m.has_value()) return;
    mask_tokens_ =
        std::min(mask_tokens_ + GeometryBytes(*m) * kUrgentMaskShare / (1.0 - kUrgentMaskShare), kMaxMaskTokens);
  };
  if (urgent && mask_tokens_ < 0.0) {
    std::optional<v1::ServerMessage> m = NextMissingObject();
    if (m.has_value()) {
      earn(m);
      return m;
    }
  }
  // ε-first: the objects the last mask sent needs, then the next mask, soonest reached first.
  if (std::optional<v1::ServerMessage> m = planner_.NextObject(
          sent_, [this](uint32_t o, size_t rank, bool* sent) { return SendObject(o, rank, sent); });
      m.has_value()) {
    if (urgent) mask_tokens_ -= GeometryBytes(*m);
    return m;
  }
  // With levels, an object whose level for the mask's cell does not keep the full mesh's
  // triangles is drawn whole: its set goes as all of them.
  auto whole = [this](CellId cell, uint32_t o) -> uint32_t {
    const uint32_t level = NeededLevel(cell, o);
    if (level == 0) return 0;
    const size_t full = scene_->scene().objects[o].mesh.TriangleCount();
    return scene_->scene().levels.objects[o][level - 1].mesh.TriangleCount() == full ? 0 : static_cast<uint32_t>(full);
  };
  if (std::optional<MaskPlanner::Sent> mask =
          planner_.NextMask(wanted_, emitted_, sent_, &stats_,
                            levels_on_ ? std::function<uint32_t(CellId, uint32_t)>(whole) : nullptr);
      mask.has_value()) {
    const v1::EpsilonMask& e = mask->message.epsilon_mask();
    credit_ -= static_cast<int64_t>(e.triangles().size());
    if (urgent) mask_tokens_ -= static_cast<double>(e.triangles().size());
    if (log_ != nullptr) {
      const visibility::CellCoord c = scene_->grid().Coord(mask->cell);
      log_->Write(id_, "mask", {{"cell", absl::StrCat(c.i, ",", c.j)},
                                {"objects", static_cast<uint64_t>(e.object_count())},
                                {"triangles", static_cast<uint64_t>(e.triangle_count())},
                                {"bytes", static_cast<uint64_t>(e.triangles().size())},
                                {"delta", e.base_mask_id() != 0 ? "yes" : "no"},
                                {"ms", mask->compute_ms}});
    }
    return std::move(mask->message);
  }
  // Geometry: the current cell's first, then the others in the order they will be reached;
  // while urgent, what the client lacks there before finer levels.
  if (urgent) {
    std::optional<v1::ServerMessage> m = NextMissingObject();
    if (m.has_value()) {
      earn(m);
      return m;
    }
  }
  for (size_t rank = 0; rank < wanted_.size(); ++rank) {
    const CellId c = wanted_[rank];
    auto it = pending_geometry_.find(c);
    if (it == pending_geometry_.end()) continue;
    std::deque<uint32_t>& q = it->second;
    while (!q.empty()) {
      const uint32_t o = q.front();
      q.pop_front();
      if (Satisfied(c, o)) continue;
      bool sent = false;
      std::optional<v1::ServerMessage> m = SendLevel(o, NeededLevel(c, o), rank, &sent);
      if (!m.has_value()) continue;  // no room: it waits for the next crossing
      if (!sent) q.push_front(o);    // the Evict goes first, the object right after it
      earn(m);
      return m;
    }
  }
  return std::nullopt;
}

bool Session::LacksGeometry(CellId cell) const {
  if (emitted_.count(cell) == 0) return false;
  auto it = pending_geometry_.find(cell);
  if (it == pending_geometry_.end()) return false;
  return std::any_of(it->second.begin(), it->second.end(), [&](uint32_t key) { return !Drawable(cell, key); });
}

bool Session::Urgent() const {
  for (size_t rank = 0; rank < std::min(kUrgentCells, wanted_.size()); ++rank) {
    if (LacksGeometry(wanted_[rank])) return true;
  }
  return false;
}

std::optional<v1::ServerMessage> Session::NextMissingObject() {
  for (size_t rank = 0; rank < std::min(kUrgentCells, wanted_.size()); ++rank) {
    const CellId c = wanted_[rank];
    auto it = pending_geometry_.find(c);
    if (it == pending_geometry_.end()) continue;
    std::deque<uint32_t>& q = it->second;
    for (auto at = q.begin(); at != q.end(); ++at) {
      const uint32_t o = *at;
      if (Drawable(c, o)) continue;  // held at some level: a finer one waits its turn
      bool sent = false;
      std::optional<v1::ServerMessage> m = SendLevel(o, NeededLevel(c, o), rank, &sent);
      if (m.has_value() && !sent) return m;  // the Evict first; the object stays queued
      q.erase(at);                           // sent, or no room: it waits for the next crossing
      if (m.has_value()) return m;
      break;  // the iterator is gone; the next call looks again
    }
  }
  return std::nullopt;
}

v1::SessionStats Session::Stats() const {
  std::lock_guard lock(mu_);
  v1::SessionStats s = stats_;
  size_t pending = 0;
  for (const auto& [c, q] : pending_geometry_) pending += q.size();
  s.set_queued_bytes(control_bytes_ + pending * sizeof(uint32_t));
  s.set_held_bytes(held_bytes_);
  s.set_seconds(Now() - start_s_);
  return s;
}

}  // namespace vistream::server
