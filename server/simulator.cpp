#include "server/simulator.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <set>
#include <thread>
#include <unordered_set>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "scenes/view_frustum.h"
#include "scenes/walk.h"
#include "server/link_model.h"
#include "server/session.h"
#include "server/simulated_holdings.h"
#include "server/wire.h"
#include "visibility/mask_codec.h"

namespace vistream::server {

namespace {

namespace v1 = vistream::v1;

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The client renderer's view (client/renderer.h Camera: 60 degrees vertical field of view,
// 1280 x 720, a level eye), culled as it culls.
scenes::ViewFrustum RendererFrustum(const glm::dvec3& eye, double yaw_rad) {
  constexpr double kFovY = 1.0471975511965976, kAspect = 1280.0 / 720.0;
  return scenes::ViewFrustum(eye, glm::dvec3(std::cos(yaw_rad), std::sin(yaw_rad), 0.0), glm::dvec3(0.0, 0.0, 1.0),
                             kFovY, kAspect);
}

double BoxDistance(const scenes::Aabb& a, const scenes::Aabb& b) {
  const double dx = std::max({0.0, a.min.x - b.max.x, b.min.x - a.max.x});
  const double dy = std::max({0.0, a.min.y - b.max.y, b.min.y - a.max.y});
  const double dz = std::max({0.0, a.min.z - b.max.z, b.min.z - a.max.z});
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

const char* BodyName(const v1::ServerMessage& m) {
  switch (m.body_case()) {
    case v1::ServerMessage::kSceneInfo: return "scene_info";
    case v1::ServerMessage::kPvs: return "pvs";
    case v1::ServerMessage::kGeometry: return "geometry";
    case v1::ServerMessage::kEvict: return "evict";
    case v1::ServerMessage::kEpsilonMask: return "epsilon_mask";
    default: return "other";
  }
}

}  // namespace

std::string_view SchemeName(Scheme scheme) {
  switch (scheme) {
    case Scheme::kPvsEps: return "pvs+eps";
    case Scheme::kPvs: return "pvs";
    case Scheme::kRadius: return "radius";
    case Scheme::kPlain: return "plain";
  }
  return "?";
}

absl::StatusOr<Scheme> ParseScheme(std::string_view text) {
  for (Scheme s : {Scheme::kPvsEps, Scheme::kPvs, Scheme::kRadius, Scheme::kPlain}) {
    if (text == SchemeName(s)) return s;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("'", std::string(text), "' is not a scheme: expected pvs+eps, pvs, radius or plain"));
}

absl::StatusOr<const scenes::WalkPath*> FindWalk(const scenes::CatalogEntry& entry, const std::string& name) {
  if (entry.walks.empty()) {
    return absl::FailedPreconditionError(absl::StrCat("scene '", entry.name, "' declares no walk to simulate"));
  }
  if (name.empty()) return &entry.walks.front();
  for (const scenes::WalkPath& w : entry.walks) {
    if (w.name == name) return &w;
  }
  std::vector<std::string> names;
  for (const scenes::WalkPath& w : entry.walks) names.push_back(w.name);
  return absl::NotFoundError(
      absl::StrCat("scene '", entry.name, "' has no walk '", name, "'; its walks: ", absl::StrJoin(names, ", ")));
}

// EventQueue

void EventQueue::At(double t, std::function<void()> fn) { events_.push(Event{std::max(t, now_), seq_++, std::move(fn)}); }

void EventQueue::RunNext() {
  Event e = events_.top();
  events_.pop();
  now_ = e.t;
  e.fn();
}

// PvsMemo

const PvsMemo::Entry& PvsMemo::Get(const ServedScene& scene, CellId cell) {
  auto it = entries_.find(cell);
  if (it != entries_.end()) return it->second;
  const double start = WallSeconds();
  auto pvs = std::make_shared<CellPvs>(scene.ComputePvs(cell, 0));
  pvs->cell = cell;
  const double seconds = WallSeconds() - start;
  return entries_.emplace(cell, Entry{std::move(pvs), seconds}).first->second;
}

const PvsMemo::Entry& PvsMemo::GetRadius(const ServedScene& scene, CellId cell, double radius_m) {
  auto it = radius_entries_.find({cell, radius_m});
  if (it != radius_entries_.end()) return it->second;
  const double start = WallSeconds();
  auto pvs = std::make_shared<CellPvs>();
  pvs->cell = cell;
  const scenes::Aabb box = scene.grid().CellBox(cell);
  for (const scenes::Object& o : scene.scene().objects) {
    if (BoxDistance(box, o.bounds) <= radius_m) pvs->objects.push_back(o.id);
  }
  const double seconds = WallSeconds() - start;
  return radius_entries_.emplace(std::make_pair(cell, radius_m), Entry{std::move(pvs), seconds}).first->second;
}

// SimulatedScheduler

SimulatedScheduler::SimulatedScheduler(EventQueue* queue, Compute compute, unsigned workers, size_t cache_bytes,
                                       bool cache)
    : queue_(queue), compute_(std::move(compute)), workers_(std::max(1u, workers)), policy_(cache_bytes, cache) {}

CellPvsPtr SimulatedScheduler::Request(uint64_t requester, CellId cell, double deadline, Done done) {
  return policy_.Request(requester, cell, deadline, std::move(done));
}
void SimulatedScheduler::Cancel(uint64_t requester, CellId cell) { policy_.Cancel(requester, cell); }
void SimulatedScheduler::CancelAll(uint64_t requester) { policy_.CancelAll(requester); }
CellPvsPtr SimulatedScheduler::Cached(CellId cell) { return policy_.Cached(cell); }
SchedulerStats SimulatedScheduler::stats() const { return policy_.stats(); }

void SimulatedScheduler::Dispatch(const std::function<void(CellId, double)>& on_start) {
  while (busy_ < workers_) {
    const std::optional<CellId> cell = policy_.StartNext();
    if (!cell.has_value()) return;
    double seconds = 0.0;
    CellPvsPtr pvs = compute_(*cell, &seconds);
    ++busy_;
    if (on_start) on_start(*cell, seconds);
    queue_->At(queue_->now() + seconds, [this, pvs, seconds] {
      --busy_;
      for (Done& d : policy_.Finish(pvs, seconds)) {
        if (d) d(pvs);
      }
    });
  }
}

// SimulatedTaskRunner

void SimulatedTaskRunner::Dispatch() {
  while (!busy_ && !waiting_.empty() && (!may_start_ || may_start_())) {
    Work work = std::move(waiting_.begin()->second);
    waiting_.erase(waiting_.begin());
    const double start = WallSeconds();
    std::function<void()> deliver = work();
    if (!deliver) {
      ++dropped_;
      continue;  // stale: no time spent
    }
    const double seconds = fixed_s_.has_value() ? *fixed_s_ : WallSeconds() - start;
    busy_ = true;
    ++ran_;
    busy_s_ += seconds;
    queue_->At(queue_->now() + seconds, [this, deliver = std::move(deliver)] {
      busy_ = false;
      deliver();
    });
  }
}

// The radius scheme's R

absl::StatusOr<double> NoHoleRadius(ServedScene& scene, const scenes::CatalogEntry& entry, const std::string& path,
                                    PvsMemo* memo) {
  absl::StatusOr<const scenes::WalkPath*> w = FindWalk(entry, path);
  if (!w.ok()) return w.status();
  absl::StatusOr<scenes::Walk> walk = scenes::Walk::Create(**w, std::max(0.1, (*w)->speed_mps), scene.terrain());
  if (!walk.ok()) return walk.status();
  double r = 0.0;
  std::set<CellId> seen;
  for (CellId c : walk->CellsAlong(scene.grid().cell_size(), [&](const glm::dvec2& p) { return scene.grid().CellAt(p); })) {
    if (!seen.insert(c).second) continue;
    const scenes::Aabb box = scene.grid().CellBox(c);
    for (uint32_t o : memo->Get(scene, c).pvs->objects) r = std::max(r, BoxDistance(box, scene.scene().objects[o].bounds));
  }
  return r;
}

// Simulate

namespace {

// The modelled client's side of one run, and the run's bookkeeping.
class Run {
 public:
  Run(ServedScene& scene, const SimulationOptions& opt, const scenes::Walk& walk, SimulationResult* result)
      : scene_(scene), opt_(opt), walk_(walk), r_(*result) {}

  absl::Status Go(const scenes::CatalogEntry& entry, const scenes::RunControl& run);

 private:
  // Callers check opt_.log first: the fields cost formatting.
  void Log(std::string_view event, std::initializer_list<EventLog::Field> fields) { opt_.log->Write(0, event, fields); }
  void SendUp(v1::ClientMessage m, const char* what);
  void Pull();
  void Receive(const v1::ServerMessage& m);
  // When `cell` became complete (list and objects arrived; uploaded at the next frame when the
  // frame time is declared), if it is.
  std::optional<double> CompleteAt(CellId cell) {
    const std::optional<double> t = holdings_.CompleteAt(cell);
    return t.has_value() ? std::optional<double>(FrameCeil(*t)) : std::nullopt;
  }
  double FrameCeil(double t) const {
    if (!r_.frame_declared) return t;
    return std::ceil(t / r_.frame_s - 1e-9) * r_.frame_s;
  }
  void Frame(double t);
  void Pose(double t);
  void CloseRecord(double t);

  ServedScene& scene_;
  const SimulationOptions& opt_;
  const scenes::Walk& walk_;
  SimulationResult& r_;

  EventQueue q_;
  std::unique_ptr<LinkModel> up_, down_;
  std::unique_ptr<SimulatedScheduler> sched_;
  std::unique_ptr<SimulatedTaskRunner> masks_;
  std::shared_ptr<Session> session_;
  bool down_busy_ = false;
  absl::Status failure_;

  // The client.
  SimulatedHoldings holdings_;
  uint64_t holdings_generation_ = 0;  // bumped whenever an object arrives or is dropped
  // An ε-mask as the client holds it (client/: the masks of its cell and the 8 around it, at
  // most kMaxMasks, the oldest dropped first).
  struct HeldMask {
    uint32_t id = 0;
    CellId cell = 0;
    scenes::Aabb box;
    std::vector<std::pair<uint32_t, uint64_t>> objects;  // ascending ids, visible triangles of each
    uint64_t triangles = 0;                               // over every object
    double arrival_s = 0.0;
    bool used = false;  // drawn on some frame
    // When it became drawable (FrameCeil of the latest arrival among it and its objects), if
    // every object is held; valid while holdings_generation_ equals checked.
    std::optional<double> ready_s;
    uint64_t checked = std::numeric_limits<uint64_t>::max();
  };
  std::deque<HeldMask> masks_held_;  // in arrival order
  visibility::MaskBases mask_bases_;  // the latest mask of each cell: deltas' bases
  // Drops the masks of cells other than the client's and the 8 around it, then the oldest over kMaxMasks.
  void KeepMasks();
  // Whether `m` can be drawn at `t` (it and every object it names arrived and were uploaded).
  bool MaskReady(HeldMask& m, double t);
  void Consume(uint64_t bytes);  // bytes charged to the credit were consumed: grant them back
  uint64_t consumed_since_grant_ = 0;
  std::optional<double> walk_t0_;  // when the walk started (the first viewcell complete)
  std::optional<CellId> start_cell_;
  std::optional<CellId> ahead_cell_;  // the first cell the walk enters, if it leaves the first
  bool walking_done_ = false;
  std::optional<CellId> cell_;     // while walking: the cell of the last frame
  bool pending_ = false;           // the current record waits for its cell to complete
  // While pending: whether its list is here, and which of its objects are not.
  bool pending_list_ = false;
  std::unordered_set<uint32_t> missing_;
  void StartPending(CellId cell) {
    missing_.clear();
    const std::vector<uint32_t>* list = holdings_.ListOf(cell);
    pending_list_ = list != nullptr;
    if (!pending_list_) return;
    for (uint32_t o : *list) {
      if (holdings_.Of(o) == nullptr) missing_.insert(o);
    }
  }
  uint64_t frame_index_ = 0;       // of the next frame since the walk started
  uint64_t triangle_every_ = 1;    // frames between two triangle counts (10 Hz)
  uint64_t triangle_samples_ = 0;
  double triangles_sum_ = 0.0;
  double triangles_without_sum_ = 0.0;
  double crossing_compute_s_ = 0.0;
  bool crossed_ = false;
};

constexpr uint64_t kCreditWindow = uint64_t{8} << 20;  // client/connection.h credit_window_bytes
constexpr double kPosePeriod = 0.1;                   // 10 Hz
constexpr size_t kMaxMasks = 64;                      // ε-masks the client holds at most

bool Inside(const glm::dvec3& e, const scenes::Aabb& b) {
  return e.x >= b.min.x && e.x <= b.max.x && e.y >= b.min.y && e.y <= b.max.y && e.z >= b.min.z && e.z <= b.max.z;
}

void Run::SendUp(v1::ClientMessage m, const char* what) {
  const size_t bytes = m.ByteSizeLong();
  const LinkModel::Delivery d = up_->Send(q_.now(), bytes);
  if (d.jitter_s > 0.0) ++r_.jitter_draws;
  r_.lost_segments += d.lost_segments;
  if (opt_.log != nullptr) Log("uplink", {{"t_s", q_.now()}, {"message", what}, {"bytes", static_cast<uint64_t>(bytes)},
                 {"arrival_s", d.arrival_s}, {"jitter_ms", d.jitter_s * 1000.0}, {"lost", d.lost_segments}});
  q_.At(d.arrival_s, [this, m = std::move(m)] {
    if (!failure_.ok()) return;
    absl::Status st = session_->OnMessage(m, q_.now());
    if (!st.ok()) failure_ = absl::InternalError(absl::StrCat("the simulated session ended: ", st.ToString()));
  });
}

void Run::Pull() {
  if (down_busy_ || !failure_.ok()) return;
  std::optional<v1::ServerMessage> m = session_->NextMessage();
  if (!m.has_value()) return;
  const size_t bytes = m->ByteSizeLong();
  const LinkModel::Delivery d = down_->Send(q_.now(), bytes);
  if (d.jitter_s > 0.0) ++r_.jitter_draws;
  r_.lost_segments += d.lost_segments;
  if (opt_.log != nullptr) Log("downlink", {{"t_s", q_.now()}, {"message", BodyName(*m)},
                   {"bytes", static_cast<uint64_t>(bytes)}, {"arrival_s", d.arrival_s},
                   {"jitter_ms", d.jitter_s * 1000.0}, {"lost", d.lost_segments}});
  down_busy_ = true;
  q_.At(d.sent_s, [this] { down_busy_ = false; });
  q_.At(d.arrival_s, [this, m = std::move(*m)] { Receive(m); });
}

void Run::Receive(const v1::ServerMessage& m) {
  const double t = q_.now();
  switch (m.body_case()) {
    case v1::ServerMessage::kPvs: {
      const v1::ViewcellPvs& p = m.pvs();
      holdings_.SetList(p.cell_id(), std::span<const uint32_t>(p.object_ids().data(), p.object_ids().size()), t);
      if (pending_ && cell_ == p.cell_id()) StartPending(p.cell_id());
      break;
    }
    case v1::ServerMessage::kGeometry: {
      const v1::ObjectGeometry& g = m.geometry();
      if (holdings_.Receive(g.object_id(), t, g.index_count() / 3)) ++r_.distinct_objects;
      if (pending_) missing_.erase(g.object_id());
      ++holdings_generation_;
      const uint64_t encoded = g.vertices().size() + g.indices().size();
      r_.geometry_bytes += encoded;
      ++r_.objects_received;
      Consume(encoded);
      break;
    }
    case v1::ServerMessage::kEvict:
      ++holdings_generation_;
      for (uint32_t o : m.evict().object_ids()) {
        holdings_.Evict(o);
        if (pending_ && pending_list_) {
          const std::vector<uint32_t>& list = *holdings_.ListOf(*cell_);  // ascending
          if (std::binary_search(list.begin(), list.end(), o)) missing_.insert(o);
        }
      }
      break;
    case v1::ServerMessage::kEpsilonMask: {
      const v1::EpsilonMask& e = m.epsilon_mask();
      ++r_.masks;
      r_.mask_bytes += e.triangles().size();
      Consume(e.triangles().size());  // a mask costs credit like geometry (proto EpsilonMask)
      const scenes::Scene& sc = scene_.scene();
      absl::StatusOr<visibility::DecodedMask> d = mask_bases_.Decode(
          e.cell_id(), e.mask_id(), e.base_mask_id(), e.triangles(), static_cast<uint32_t>(sc.objects.size()),
          r_.scene_triangles);
      if (!d.ok()) {
        failure_ = absl::InternalError(
            absl::StrCat("the simulated client cannot decode ε-mask ", e.mask_id(), ": ", d.status().message()));
        break;
      }
      HeldMask mask;
      mask.id = e.mask_id();
      mask.cell = e.cell_id();
      mask.box.min = ToVec(e.neighbourhood_min());
      mask.box.max = ToVec(e.neighbourhood_max());
      mask.arrival_s = t;
      mask.triangles = d->triangles;
      mask.objects.reserve(d->objects.size());
      for (const visibility::MaskObject& o : d->objects) {
        uint64_t n = 0;
        for (uint8_t byte : o.bits) n += static_cast<uint64_t>(std::popcount(byte));
        mask.objects.emplace_back(o.object, n);
      }
      if (opt_.log != nullptr) {
        const visibility::CellCoord c = scene_.grid().Coord(mask.cell);
        const scenes::Aabb& b = mask.box;
        Log("mask_arrival", {{"t_s", t}, {"mask_id", static_cast<uint64_t>(mask.id)}, {"cell", absl::StrCat(c.i, ",", c.j)},
                             {"box", absl::StrFormat("%.2f,%.2f,%.2f,%.2f,%.2f,%.2f", b.min.x, b.min.y, b.min.z, b.max.x,
                                                     b.max.y, b.max.z)},
                             {"objects", static_cast<uint64_t>(mask.objects.size())}, {"triangles", mask.triangles},
                             {"bytes", static_cast<uint64_t>(e.triangles().size())},
                             {"delta", e.base_mask_id() != 0 ? "yes" : "no"}});
      }
      masks_held_.push_back(std::move(mask));
      KeepMasks();
      break;
    }
    default:
      break;
  }
  // The walk starts once the first viewcell is complete (at a frame, as the real client).
  // The walk starts once the first viewcell and the first one the walk enters are complete (at
  // a frame, as the real client, client/walkthrough.cpp Startup).
  if (!walk_t0_.has_value() && start_cell_.has_value()) {
    std::optional<double> done = CompleteAt(*start_cell_);
    if (done.has_value() && ahead_cell_.has_value()) {
      const std::optional<double> ahead = CompleteAt(*ahead_cell_);
      done = ahead.has_value() ? std::optional<double>(std::max(*done, *ahead)) : std::nullopt;
    }
    if (done.has_value()) {
      walk_t0_ = std::max(*done, t);
      r_.startup_s = *walk_t0_;
      CellRecord rec;
      rec.cell = *start_cell_;
      rec.entered_s = rec.complete_s = *walk_t0_;
      rec.startup = true;
      r_.cells.push_back(rec);
      cell_ = *start_cell_;
      if (opt_.log != nullptr) Log("walk_start", {{"t_s", *walk_t0_}});
      q_.At(*walk_t0_, [this] { Frame(q_.now()); });
    }
  }
}

void Run::Consume(uint64_t bytes) {
  // The client's grant (client/connection.cpp): what it consumed, once half the window is.
  consumed_since_grant_ += bytes;
  if (consumed_since_grant_ >= kCreditWindow / 2) {
    v1::ClientMessage c;
    c.mutable_credit()->set_bytes(consumed_since_grant_);
    consumed_since_grant_ = 0;
    SendUp(std::move(c), "credit");
  }
}

void Run::KeepMasks() {
  const std::optional<CellId> at = cell_.has_value() ? cell_ : start_cell_;
  if (at.has_value()) {
    const visibility::CellCoord c = scene_.grid().Coord(*at);
    std::erase_if(masks_held_, [&](const HeldMask& m) {
      const visibility::CellCoord mc = scene_.grid().Coord(m.cell);
      return std::abs(mc.i - c.i) > 1 || std::abs(mc.j - c.j) > 1;
    });
  }
  while (masks_held_.size() > kMaxMasks) masks_held_.pop_front();
}

bool Run::MaskReady(HeldMask& m, double t) {
  if (m.checked != holdings_generation_) {
    m.checked = holdings_generation_;
    double latest = m.arrival_s;
    m.ready_s.reset();
    bool all = true;
    for (const auto& [o, n] : m.objects) {
      const SimulatedHoldings::Held* h = holdings_.Of(o);
      if (h == nullptr) {
        all = false;
        break;
      }
      latest = std::max(latest, h->arrival_s);
    }
    if (all) m.ready_s = FrameCeil(latest);
  }
  return m.ready_s.has_value() && *m.ready_s <= t + 1e-9;
}

void Run::CloseRecord(double t) {
  if (r_.cells.empty() || !pending_) return;
  CellRecord& rec = r_.cells.back();
  rec.complete_s = t;  // never completed while the client was in it
  rec.margin_s = rec.entered_s - t;
  pending_ = false;
}

void Run::Frame(double t) {
  const double walk_t = t - *walk_t0_;
  const bool last = walk_t >= walk_.duration_s();
  const scenes::WalkPose pose = walk_.At(std::min(walk_t, walk_.duration_s()));
  const std::optional<CellId> cell = scene_.grid().CellAt(glm::dvec2(pose.eye));
  ++r_.frames;
  if (cell.has_value() && cell != cell_) {
    CloseRecord(t);
    ++r_.crossings;
    if (crossed_) r_.compute_s_per_crossing.push_back(crossing_compute_s_);
    crossed_ = true;
    crossing_compute_s_ = 0.0;
    cell_ = cell;
    KeepMasks();
    CellRecord rec;
    rec.cell = *cell;
    rec.entered_s = t;
    const std::optional<double> done = CompleteAt(*cell);
    if (done.has_value() && *done <= t + 1e-9) {
      rec.complete_s = *done;
      rec.margin_s = t - *done;
    } else {
      pending_ = true;
      StartPending(*cell);
      rec.stalled = true;
      ++r_.stalled_cells;
    }
    const visibility::CellCoord c = scene_.grid().Coord(*cell);
    // An entry into an incomplete cell has no margin yet: its stall_end (or the next entry) says.
    if (opt_.log != nullptr && pending_) {
      Log("enter", {{"t_s", t}, {"cell", absl::StrCat(c.i, ",", c.j)}, {"complete", "no"}});
    } else if (opt_.log != nullptr) {
      Log("enter", {{"t_s", t}, {"cell", absl::StrCat(c.i, ",", c.j)}, {"complete", "yes"}, {"margin_s", rec.margin_s}});
    }
    r_.cells.push_back(rec);
  }
  bool complete = true;
  if (pending_ && pending_list_ && missing_.empty()) {
    const std::optional<double> done = CompleteAt(*cell_);
    if (done.has_value() && *done <= t + 1e-9) {
      CellRecord& rec = r_.cells.back();
      rec.complete_s = *done;
      rec.margin_s = rec.entered_s - *done;
      pending_ = false;
      if (opt_.log != nullptr) Log("stall_end", {{"t_s", t}, {"stalled_s", *done - rec.entered_s}});
    }
  }
  if (pending_) {
    complete = false;
    ++r_.stalls;
    r_.stall_s += r_.frame_s;
  }
  // The mask drawn: of the held masks whose box the eye is in and whose objects are all here,
  // the one with the fewest triangles.
  HeldMask* mask = nullptr;
  bool in_unready = false;
  for (HeldMask& m : masks_held_) {
    if (!Inside(pose.eye, m.box)) continue;
    if (!MaskReady(m, t)) {
      in_unready = true;
    } else if (mask == nullptr || m.triangles < mask->triangles) {
      mask = &m;
    }
  }
  const bool hole = mask == nullptr && !complete;
  if (mask != nullptr) {
    ++r_.frames_masked;
    if (!mask->used) ++r_.masks_used;
    mask->used = true;
  } else if (in_unready) {
    ++r_.frames_in_unready_mask;
  }
  if (hole) ++r_.hole_frames;
  // Triangles drawn, counted on frames 10 times a second (the mean over every frame, sampled).
  if (opt_.count_triangles && (r_.frames - 1) % triangle_every_ == 0) {
    // What the renderer draws, culled against the view frustum: the mask's triangles; else the
    // cell's PVS; else (a hole) everything held. Without masks: the PVS, or during a stall
    // everything held.
    const scenes::ViewFrustum frustum = RendererFrustum(pose.eye, pose.yaw_rad);
    const auto& objects = scene_.scene().objects;
    auto seen = [&](uint32_t o) { return frustum.MayOverlap(objects[o].bounds.min, objects[o].bounds.max); };
    uint64_t without = 0;
    if (complete && cell_.has_value()) {
      for (uint32_t o : *holdings_.ListOf(*cell_)) {
        const SimulatedHoldings::Held* h = holdings_.Of(o);
        if (h != nullptr && seen(o)) without += h->triangles;
      }
    } else {
      for (uint32_t o = 0; o < holdings_.IdBound(); ++o) {
        const SimulatedHoldings::Held* h = holdings_.Of(o);
        if (h != nullptr && seen(o)) without += h->triangles;
      }
    }
    uint64_t tris = without;
    if (mask != nullptr) {
      tris = 0;
      for (const auto& [o, n] : mask->objects) {
        if (seen(o)) tris += n;
      }
    }
    triangles_sum_ += static_cast<double>(tris);
    triangles_without_sum_ += static_cast<double>(without);
    ++triangle_samples_;
    r_.max_triangles_drawn = std::max(r_.max_triangles_drawn, tris);
    const double sample_t = std::min(walk_t, walk_.duration_s());
    r_.triangle_samples.push_back(SimulationResult::TriangleSample{sample_t, sample_t * walk_.speed_mps(), tris,
                                                                   without, mask != nullptr, hole});
  }
  if (last) {
    CloseRecord(t);
    walking_done_ = true;
    return;
  }
  // Frame times from the start, not summed, so that they stay on the frame grid.
  ++frame_index_;
  q_.At(*walk_t0_ + static_cast<double>(frame_index_) * r_.frame_s, [this] { Frame(q_.now()); });
}

void Run::Pose(double t) {
  v1::ClientMessage m;
  v1::Pose* p = m.mutable_pose();
  // Waiting to walk: at the start, with the velocity it will walk at, so that the server ranks
  // the cells ahead first (as the real client, client/walkthrough.cpp Startup).
  scenes::WalkPose pose = walk_.At(0.0);
  if (walk_t0_.has_value()) {
    const double walk_t = t - *walk_t0_;
    pose = walk_.At(std::min(walk_t, walk_.duration_s()));
    if (walk_t >= walk_.duration_s()) pose.velocity = glm::dvec3(0.0);
  }
  SetVec(pose.eye, p->mutable_position());
  SetVec(pose.velocity, p->mutable_velocity());
  p->set_yaw_rad(pose.yaw_rad);
  p->set_pitch_rad(0.0);
  p->set_client_time_s(t);
  SendUp(std::move(m), "pose");
  q_.At(t + kPosePeriod, [this] { Pose(q_.now()); });
}

absl::Status Run::Go(const scenes::CatalogEntry& entry, const scenes::RunControl& run) {
  const double wall_start = WallSeconds();
  const scenes::SimulationSpec& sim = entry.simulation;
  r_.link_declared = opt_.link.has_value();
  r_.link = LinkParamsFrom(opt_.link, opt_.time_scale);
  up_ = std::make_unique<LinkModel>(r_.link, opt_.seed);
  down_ = std::make_unique<LinkModel>(r_.link, opt_.seed + 1);
  r_.frame_declared = sim.client.has_value() && sim.client->frame_ms.has_value();
  r_.frame_s = r_.frame_declared ? *sim.client->frame_ms / 1000.0 : 1.0 / 60.0;
  r_.scene_triangles = scene_.scene().TriangleCount();
  triangle_every_ = std::max<uint64_t>(1, static_cast<uint64_t>(std::llround(kPosePeriod / r_.frame_s)));

  // The PVS each scheme streams for a cell, and what computing it costs.
  std::shared_ptr<PvsMemo> memo = opt_.memo != nullptr ? opt_.memo : std::make_shared<PvsMemo>();
  if (opt_.scheme == Scheme::kRadius) {
    if (opt_.radius_m > 0.0) {
      r_.radius_m = opt_.radius_m;
    } else {
      absl::StatusOr<double> radius = NoHoleRadius(scene_, entry, opt_.path, memo.get());
      if (!radius.ok()) return radius.status();
      r_.radius_m = *radius;
    }
  }
  SimulatedScheduler::Compute compute = [&](CellId cell, double* seconds) -> CellPvsPtr {
    const PvsMemo::Entry& e =
        opt_.scheme == Scheme::kRadius ? memo->GetRadius(scene_, cell, r_.radius_m) : memo->Get(scene_, cell);
    *seconds = opt_.fixed_compute_s.value_or(e.seconds);
    return e.pvs;
  };
  const unsigned workers = opt_.workers != 0 ? opt_.workers : std::max(1u, std::thread::hardware_concurrency());
  sched_ = std::make_unique<SimulatedScheduler>(&q_, compute, workers, opt_.cache_bytes, opt_.scheme != Scheme::kPlain);
  masks_ = std::make_unique<SimulatedTaskRunner>(&q_, opt_.fixed_compute_s,
                                                 [this] { return sched_->has_free_worker(); });

  SessionLimits limits;
  limits.epsilon_size_m = entry.viewcell.epsilon_m;
  SessionSeams seams;
  seams.pvs = sched_.get();
  seams.masks = masks_.get();
  seams.clock = [this] { return q_.now(); };
  seams.look_ahead = opt_.scheme != Scheme::kPlain;
  seams.epsilon_masks = opt_.scheme == Scheme::kPvsEps;
  session_ = Session::Create(1, &scene_, limits, opt_.log, nullptr, std::move(seams));

  start_cell_ = scene_.grid().CellAt(walk_.PointAt(0.0));
  if (const std::vector<CellId> along = walk_.CellsAlong(
          scene_.grid().cell_size(), [this](const glm::dvec2& p) { return scene_.grid().CellAt(p); });
      start_cell_.has_value() && along.size() > 1 && along[0] == *start_cell_) {
    ahead_cell_ = along[1];
  }
  if (!start_cell_.has_value()) {
    return absl::OutOfRangeError("the walk starts outside the scene's viewcell grid");
  }
  // Hello with the declared client budgets only, then the credit window.
  v1::ClientMessage hello;
  hello.mutable_hello()->set_scene(scene_.scene().name);
  hello.mutable_hello()->set_protocol_version(v1::PROTOCOL_VERSION_CURRENT);
  hello.mutable_hello()->set_epsilon_masks(opt_.scheme == Scheme::kPvsEps);
  if (sim.client.has_value() && sim.client->memory_mb.has_value()) {
    hello.mutable_hello()->set_memory_budget_bytes(static_cast<uint64_t>(*sim.client->memory_mb * 1048576.0));
  }
  if (sim.client.has_value() && sim.client->triangle_budget.has_value()) {
    hello.mutable_hello()->set_triangle_budget(*sim.client->triangle_budget);
  }
  SendUp(std::move(hello), "hello");
  v1::ClientMessage credit;
  credit.mutable_credit()->set_bytes(kCreditWindow);
  SendUp(std::move(credit), "credit");
  q_.At(0.0, [this] { Pose(q_.now()); });

  const auto on_start = [this](CellId cell, double seconds) {
    crossing_compute_s_ += seconds;
    const visibility::CellCoord c = scene_.grid().Coord(cell);
    if (opt_.log != nullptr) Log("compute", {{"t_s", q_.now()}, {"cell", absl::StrCat(c.i, ",", c.j)}, {"ms", seconds * 1000.0}});
  };
  uint64_t events = 0;
  while (!walking_done_ && !q_.empty()) {
    if (!failure_.ok()) return failure_;
    if (!walk_t0_.has_value() && q_.next_time() > opt_.startup_limit_s) {
      return absl::DeadlineExceededError(absl::StrFormat(
          "the first viewcell's PVS and geometry did not arrive within %.0f s of simulated time (link: %s)",
          opt_.startup_limit_s, r_.link.Describe()));
    }
    q_.RunNext();
    sched_->Dispatch(on_start);
    masks_->Dispatch();
    Pull();
    if ((++events & 0xfff) == 0 && run.Cancelled()) return absl::CancelledError("simulation stopped");
  }
  if (!failure_.ok()) return failure_;
  if (crossed_) r_.compute_s_per_crossing.push_back(crossing_compute_s_);
  r_.masks_dropped = session_->Stats().epsilon_masks_dropped();
  session_->End();

  const SchedulerStats s = sched_->stats();
  r_.pvs_computed = s.computed;
  r_.pvs_cache_hits = s.cache_hits;
  r_.bytes = down_->wire_bytes();
  r_.uplink_bytes = up_->wire_bytes();
  r_.path_m = walk_.length_m();
  r_.walk_s = walk_.duration_s();
  r_.sim_s = q_.now();
  r_.mean_triangles_drawn = triangle_samples_ > 0 ? triangles_sum_ / static_cast<double>(triangle_samples_) : 0.0;
  r_.mean_triangles_without_masks =
      triangle_samples_ > 0 ? triangles_without_sum_ / static_cast<double>(triangle_samples_) : 0.0;
  r_.masks_computed = masks_->ran();
  r_.mask_compute_s = masks_->busy_s();
  double sum = 0.0;
  size_t n = 0;
  r_.min_margin_s = 0.0;
  for (const CellRecord& c : r_.cells) {
    if (c.startup) continue;
    r_.min_margin_s = n == 0 ? c.margin_s : std::min(r_.min_margin_s, c.margin_s);
    sum += c.margin_s;
    ++n;
  }
  r_.mean_margin_s = n > 0 ? sum / static_cast<double>(n) : 0.0;
  if (opt_.log != nullptr) Log("simulation_end", {{"t_s", q_.now()}, {"stalls", r_.stalls}, {"bytes", r_.bytes},
                         {"wall_s", WallSeconds() - wall_start}});
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<SimulationResult> Simulate(ServedScene& scene, const scenes::CatalogEntry& entry,
                                          const SimulationOptions& options, const scenes::RunControl& run) {
  absl::StatusOr<const scenes::WalkPath*> path = FindWalk(entry, options.path);
  if (!path.ok()) return path.status();
  if (!(options.time_scale > 0.0) || !std::isfinite(options.time_scale)) {
    return absl::InvalidArgumentError(absl::StrCat("time scale ", options.time_scale, " is not positive"));
  }
  const double speed = options.speed_mps == 0.0 ? (*path)->speed_mps : options.speed_mps;
  if (!(speed > 0.0) || !std::isfinite(speed)) {
    return absl::InvalidArgumentError(absl::StrCat("speed ", speed * 3.6, " km/h is not a positive number"));
  }
  absl::StatusOr<scenes::Walk> walk = scenes::Walk::Create(**path, speed * options.time_scale, scene.terrain());
  if (!walk.ok()) return walk.status();
  SimulationResult result;
  result.speed_mps = speed;
  SimulationOptions opt = options;
  if (opt.memo == nullptr) opt.memo = std::make_shared<PvsMemo>();
  Run r(scene, opt, *walk, &result);
  if (absl::Status st = r.Go(entry, run); !st.ok()) return st;
  return result;
}

absl::StatusOr<SpeedSearch> FindMaxSpeed(ServedScene& scene, const scenes::CatalogEntry& entry,
                                         const SimulationOptions& options, double lo_mps, double hi_mps,
                                         double precision, const scenes::RunControl& run,
                                         SpeedCriterion criterion) {
  if (!(lo_mps > 0.0 && hi_mps > lo_mps && precision > 0.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("speed search: bracket [", lo_mps, ", ", hi_mps, "] m/s or precision ", precision, " is invalid"));
  }
  SimulationOptions opt = options;
  if (opt.memo == nullptr) opt.memo = std::make_shared<PvsMemo>();
  SpeedSearch out;
  // Probes skip the per-frame culling; the run at the answer counts triangles as asked.
  auto probe = [&](double speed) -> absl::StatusOr<uint64_t> {
    opt.speed_mps = speed;
    opt.count_triangles = false;
    absl::StatusOr<SimulationResult> r = Simulate(scene, entry, opt, run);
    if (!r.ok()) return r.status();
    const uint64_t bad = criterion == SpeedCriterion::kNoHole ? r->hole_frames : r->stalls;
    out.runs.emplace_back(speed, bad);
    return bad;
  };
  auto finish = [&](double max_mps, double stall_mps) -> absl::StatusOr<SpeedSearch> {
    out.max_speed_mps = max_mps;
    out.stall_speed_mps = stall_mps;
    // The run at the answer; when even the bottom of the bracket stalls, the run there (it
    // shows how badly).
    opt.speed_mps = max_mps > 0.0 ? max_mps : stall_mps;
    opt.count_triangles = options.count_triangles;
    absl::StatusOr<SimulationResult> r = Simulate(scene, entry, opt, run);
    if (!r.ok()) return r.status();
    out.at_max = std::move(*r);
    return out;
  };
  absl::StatusOr<uint64_t> hi = probe(hi_mps);
  if (!hi.ok()) return hi.status();
  if (*hi == 0) return finish(hi_mps, 0.0);
  double a = lo_mps, b = hi_mps;  // a: no stalls, b: stalls
  absl::StatusOr<const scenes::WalkPath*> walk = FindWalk(entry, options.path);
  if (!walk.ok()) return walk.status();
  const double start = options.speed_mps > 0.0 ? options.speed_mps : (*walk)->speed_mps;
  bool start_ok = false;
  if (start > lo_mps && start < hi_mps) {
    absl::StatusOr<uint64_t> s = probe(start);
    if (!s.ok()) return s.status();
    start_ok = *s == 0;
    (start_ok ? a : b) = start;
  }
  if (!start_ok) {
    absl::StatusOr<uint64_t> lo = probe(lo_mps);
    if (!lo.ok()) return lo.status();
    if (*lo > 0) return finish(0.0, lo_mps);
  }
  while (b > a * (1.0 + precision)) {
    const double m = std::sqrt(a * b);
    absl::StatusOr<uint64_t> s = probe(m);
    if (!s.ok()) return s.status();
    (*s == 0 ? a : b) = m;
  }
  return finish(a, b);
}

}  // namespace vistream::server
