#include "simulation/simulator.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <set>
#include <thread>
#include <unordered_set>

#include <absl/strings/str_cat.h>
#include <google/protobuf/descriptor.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "client/camera.h"
#include "client/cell_completion.h"
#include "client/client_model.h"
#include "client/mask_holdings.h"
#include "proto/pvs_delta.h"
#include "scenes/walk.h"
#include "server/emulated_link.h"
#include "server/link_model.h"
#include "server/session.h"

namespace vistream::simulation {

using server::LinkModel;
using server::LinkParamsFrom;
using server::SchedulerStats;
using server::SessionLimits;
using server::SessionSeams;
using server::Session;

namespace {

namespace v1 = vistream::v1;

double WallSeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The message's kind as the protocol names it (its body field: "geometry", "pvs", ...).
const char* BodyName(const v1::ServerMessage& m) {
  const google::protobuf::FieldDescriptor* body = m.GetDescriptor()->FindFieldByNumber(m.body_case());
  return body != nullptr ? body->name().c_str() : "other";
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
    for (uint32_t o : memo->Get(scene, c).pvs->objects) r = std::max(r, scenes::BoxDistance(box, scene.scene().objects[o].bounds));
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
    const std::optional<double> t = completion_.CompleteAt(cell);
    return t.has_value() ? std::optional<double>(FrameCeil(*t)) : std::nullopt;
  }
  double FrameCeil(double t) const {
    if (!r_.frame_declared) return t;
    return std::ceil(t / r_.frame_s - 1e-9) * r_.frame_s;
  }
  void Frame(double t);
  void Pose(double t);
  void CloseRecord(double t);
  // A record of entering `cell` at `t` (client/cell_margins.h's, as the real client keeps them).
  client::CellEntry Entry(CellId cell, double t) const {
    client::CellEntry e;
    e.cell = cell;
    const visibility::CellCoord c = scene_.grid().Coord(cell);
    e.i = c.i;
    e.j = c.j;
    e.entered_s = t;
    return e;
  }

  ServedScene& scene_;
  const SimulationOptions& opt_;
  const scenes::Walk& walk_;
  SimulationResult& r_;

  EventQueue q_;
  // The emulated link both ways (server/emulated_link.h, the one the server's --emulate-link
  // runs): what is on it, delivered at its modelled arrival.
  std::unique_ptr<server::EmulatedLink<v1::ClientMessage>> up_;
  std::unique_ptr<server::EmulatedLink<v1::ServerMessage>> down_;
  std::unique_ptr<SimulatedScheduler> sched_;
  std::unique_ptr<SimulatedTaskRunner> masks_;
  std::shared_ptr<Session> session_;
  bool down_busy_ = false;
  absl::Status failure_;

  // The client: the client model's rules (client/client_model.h, mask_holdings.h,
  // cell_completion.h), on simulated time.
  client::CellCompletion completion_;  // lists and objects held, with their arrival times
  proto::PvsListDecoder lists_;        // lists sent as differences (Hello.pvs_deltas)
  client::MaskHoldings masks_held_;
  std::set<uint64_t> masks_drawn_;     // keys of the held masks drawn on some frame
  client::CreditWindow credit_;
  client::PoseCadence poses_;
  std::unordered_set<uint32_t> drawn_whole_;  // held at a level a mask's bits do not apply to
  std::unordered_set<uint32_t> clusters_whole_;  // clusters held at a level a mask's bits do not apply to
  // Whether object `o` is held and uploaded by a frame at `t` (with a declared frame time, an
  // object is uploaded at the first frame after its arrival).
  bool Ready(uint32_t o, double t, std::optional<uint32_t> cell) const {
    const client::CellCompletion::Object* h = completion_.Held(o);
    if (h != nullptr && FrameCeil(h->arrival_s) <= t + 1e-9) return true;
    // Or drawn by a held cluster the cell's list chose for it.
    const std::optional<uint32_t> c = cell.has_value() ? completion_.CoveringCluster(*cell, o) : std::nullopt;
    return c.has_value() && FrameCeil(completion_.HeldCluster(*c)->arrival_s) <= t + 1e-9;
  }
  // Triangles of object `o` as held (its level's).
  uint64_t TrianglesOf(uint32_t o) const {
    const client::CellCompletion::Object* h = completion_.Held(o);
    if (h != nullptr && h->level > 0) return scene_.scene().levels.objects[o][h->level - 1].mesh.TriangleCount();
    return scene_.scene().objects[o].mesh.indices.size() / 3;
  }
  // Drops the masks of cells other than the client's and the 8 around it, then the oldest
  // over MaskHoldings::kMaxMasks.
  void KeepMasks() { masks_held_.KeepNear(cell_.has_value() ? cell_ : start_cell_, scene_.grid()); }
  std::optional<double> walk_t0_;  // when the walk started (the first viewcell complete)
  std::optional<CellId> start_cell_;
  std::optional<CellId> ahead_cell_;  // the first cell the walk enters, if it leaves the first
  bool walking_done_ = false;
  std::optional<CellId> cell_;     // while walking: the cell of the last frame
  bool pending_ = false;           // the current record waits for its cell to complete
  uint64_t frame_index_ = 0;       // of the next frame since the walk started
  uint64_t triangle_every_ = 1;    // frames between two triangle counts (10 Hz)
  uint64_t triangle_samples_ = 0;
  double triangles_sum_ = 0.0;
  std::array<double, SimulationResult::kTriangleBandsM.size()> triangles_by_distance_sum_{};
  double triangles_without_sum_ = 0.0;
  double crossing_compute_s_ = 0.0;
  bool crossed_ = false;
};

// Triangles drawn are counted on frames this far apart (10 Hz).
constexpr double kTriangleSampleS = 0.1;

void Run::SendUp(v1::ClientMessage m, const char* what) {
  const size_t bytes = m.ByteSizeLong();
  const LinkModel::Delivery d = up_->Send(q_.now(), std::move(m), bytes);
  if (d.jitter_s > 0.0) ++r_.jitter_draws;
  r_.lost_segments += d.lost_segments;
  if (opt_.log != nullptr) Log("uplink", {{"t_s", q_.now()}, {"message", what}, {"bytes", static_cast<uint64_t>(bytes)},
                 {"arrival_s", d.arrival_s}, {"jitter_ms", d.jitter_s * 1000.0}, {"lost", d.lost_segments}});
  // Messages arrive in the order sent: this event takes this message off the link.
  q_.At(d.arrival_s, [this] {
    const std::optional<v1::ClientMessage> arrived = up_->TakeArrived(q_.now());
    if (!arrived.has_value() || !failure_.ok()) return;
    absl::Status st = session_->OnMessage(*arrived, q_.now());
    if (!st.ok()) failure_ = absl::InternalError(absl::StrCat("the simulated session ended: ", st.ToString()));
  });
}

void Run::Pull() {
  if (down_busy_ || !failure_.ok()) return;
  std::optional<v1::ServerMessage> m = session_->NextMessage();
  if (!m.has_value()) return;
  const size_t bytes = m->ByteSizeLong();
  const char* kind = BodyName(*m);
  const LinkModel::Delivery d = down_->Send(q_.now(), *std::move(m), bytes);
  if (d.jitter_s > 0.0) ++r_.jitter_draws;
  r_.lost_segments += d.lost_segments;
  if (opt_.log != nullptr) Log("downlink", {{"t_s", q_.now()}, {"message", kind},
                   {"bytes", static_cast<uint64_t>(bytes)}, {"arrival_s", d.arrival_s},
                   {"jitter_ms", d.jitter_s * 1000.0}, {"lost", d.lost_segments}});
  // One message on the wire at a time: the next is taken from the session when this one has
  // left (the link's free time), as the server's writes go one at a time.
  down_busy_ = true;
  q_.At(d.sent_s, [this] { down_busy_ = false; });
  q_.At(d.arrival_s, [this] {
    if (const std::optional<v1::ServerMessage> arrived = down_->TakeArrived(q_.now())) Receive(*arrived);
  });
}

void Run::Receive(const v1::ServerMessage& m) {
  const double t = q_.now();
  // What the message costs the credit; a grant goes back as the client grants it.
  credit_.Consume(client::ChargedBytes(m));
  ++r_.messages;
  if (credit_.GrantDue()) SendUp(client::CreditMessage(credit_.TakeGrant()), "credit");
  switch (m.body_case()) {
    case v1::ServerMessage::kPvs: {
      r_.list_bytes += m.ByteSizeLong();
      absl::StatusOr<proto::PvsList> list = lists_.Decode(m.pvs());
      if (!list.ok()) {
        failure_ = absl::InternalError(absl::StrCat("the simulated client cannot read a PVS list: ", list.status().message()));
        break;
      }
      completion_.SetList(list->cell, list->objects, t, list->levels, list->cluster_ids, list->cluster_levels);
      break;
    }
    case v1::ServerMessage::kCluster: {
      const v1::ClusterGeometry& g = m.cluster();
      if (g.keeps_triangles()) {
        clusters_whole_.erase(g.cluster_id());
      } else {
        clusters_whole_.insert(g.cluster_id());
      }
      const std::span<const uint32_t> objects(g.objects().data(), static_cast<size_t>(g.objects().size()));
      completion_.ArriveCluster(g.cluster_id(), t, g.level(), objects);
      ++r_.cluster_levels_received;
      r_.geometry_bytes += client::ChargedBytes(m);
      ++r_.objects_received;
      break;
    }
    case v1::ServerMessage::kGeometry: {
      if (completion_.Arrive(m.geometry().object_id(), t, m.geometry().level())) ++r_.distinct_objects;
      // A level that does not keep the full mesh's triangles is drawn whole under a mask.
      if (m.geometry().level() > 0 && !m.geometry().keeps_triangles()) {
        drawn_whole_.insert(m.geometry().object_id());
      } else {
        drawn_whole_.erase(m.geometry().object_id());
      }
      if (m.geometry().level() > 0) ++r_.level_objects_received;
      r_.geometry_bytes += client::ChargedBytes(m);
      ++r_.objects_received;
      break;
    }
    case v1::ServerMessage::kEvict:
      for (uint32_t o : m.evict().object_ids()) {
        completion_.Drop(o);
        drawn_whole_.erase(o);
      }
      for (uint32_t c : m.evict().cluster_ids()) {
        completion_.DropCluster(c);
        clusters_whole_.erase(c);
      }
      break;
    case v1::ServerMessage::kEpsilonMask: {
      const v1::EpsilonMask& e = m.epsilon_mask();
      ++r_.masks;
      r_.mask_bytes += client::ChargedBytes(m);
      if (absl::Status st = masks_held_.Add(e, static_cast<uint32_t>(scene_.scene().objects.size()), r_.scene_triangles);
          !st.ok()) {
        failure_ = absl::InternalError(
            absl::StrCat("the simulated client cannot decode ε-mask ", e.mask_id(), ": ", st.message()));
        break;
      }
      if (opt_.log != nullptr) {
        const client::EpsilonMaskSet& mask = masks_held_.masks().at(e.mask_id());
        const visibility::CellCoord c = scene_.grid().Coord(mask.cell);
        Log("mask_arrival", {{"t_s", t}, {"mask_id", static_cast<uint64_t>(mask.mask_id)}, {"cell", absl::StrCat(c.i, ",", c.j)},
                             {"box", absl::StrFormat("%.2f,%.2f,%.2f,%.2f,%.2f,%.2f", mask.box_min.x, mask.box_min.y,
                                                     mask.box_min.z, mask.box_max.x, mask.box_max.y, mask.box_max.z)},
                             {"objects", static_cast<uint64_t>(mask.objects.size())}, {"triangles", mask.triangles},
                             {"bytes", static_cast<uint64_t>(e.triangles().size())},
                             {"delta", e.base_mask_id() != 0 ? "yes" : "no"}});
      }
      KeepMasks();
      break;
    }
    default:
      break;
  }
  // The walk starts once the first viewcell and the first one the walk enters are complete (at
  // a frame, as the real client, client/walkthrough_startup.cpp).
  if (!walk_t0_.has_value() && start_cell_.has_value()) {
    std::optional<double> done = CompleteAt(*start_cell_);
    if (done.has_value() && ahead_cell_.has_value()) {
      const std::optional<double> ahead = CompleteAt(*ahead_cell_);
      done = ahead.has_value() ? std::optional<double>(std::max(*done, *ahead)) : std::nullopt;
    }
    if (done.has_value()) {
      walk_t0_ = std::max(*done, t);
      r_.startup_s = *walk_t0_;
      r_.cells.push_back(Entry(*start_cell_, *walk_t0_));
      r_.cells.back().complete_s = *walk_t0_;
      r_.cells.back().start = true;
      cell_ = *start_cell_;
      if (opt_.log != nullptr) Log("walk_start", {{"t_s", *walk_t0_}});
      q_.At(*walk_t0_, [this] { Frame(q_.now()); });
    }
  }
}

void Run::CloseRecord(double t) {
  if (r_.cells.empty() || !pending_) return;
  client::CellEntry& rec = r_.cells.back();
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
    client::CellEntry rec = Entry(*cell, t);
    const std::optional<double> done = CompleteAt(*cell);
    if (done.has_value() && *done <= t + 1e-9) {
      rec.complete_s = *done;
      rec.margin_s = t - *done;
    } else {
      pending_ = true;
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
  if (pending_ && completion_.Complete(*cell_)) {
    const std::optional<double> done = CompleteAt(*cell_);
    if (done.has_value() && *done <= t + 1e-9) {
      client::CellEntry& rec = r_.cells.back();
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
  } else if (cell_.has_value() && completion_.Coarse(*cell_) > 0) {
    ++r_.coarse_frames;
  }
  // The mask drawn, by the client model's rule (client/mask_holdings.h), of the masks whose
  // objects have arrived and been uploaded.
  const client::MaskChoice choice =
      masks_held_.Choose(pose.eye, [&](uint32_t o, uint32_t mask_cell) { return Ready(o, t, mask_cell); });
  const client::EpsilonMaskSet* mask = choice.mask;
  const bool hole = mask == nullptr && !complete;
  if (mask != nullptr) {
    ++r_.frames_masked;
    if (masks_drawn_.insert(mask->key).second) ++r_.masks_used;
  } else if (choice.in_box) {
    ++r_.frames_in_unready_mask;
  }
  if (hole) ++r_.hole_frames;
  // Triangles drawn, counted on frames 10 times a second (the mean over every frame, sampled).
  if (opt_.count_triangles && (r_.frames - 1) % triangle_every_ == 0) {
    // What the renderer draws, culled against the view frustum: the mask's triangles; else the
    // cell's PVS; else (a hole) everything held. Without masks: the PVS, or during a stall
    // everything held.
    client::Camera camera;  // the renderer's (client/camera.h), level
    camera.eye = pose.eye;
    camera.yaw_rad = pose.yaw_rad;
    const scenes::ViewFrustum frustum = camera.Frustum();
    const auto& objects = scene_.scene().objects;
    auto seen = [&](uint32_t o) { return frustum.MayOverlap(objects[o].bounds.min, objects[o].bounds.max); };
    const scenes::SceneLevels& levels = scene_.scene().levels;
    // A held cluster the cell's list chose draws the objects it stands for there as its pieces
    // (scenes/cluster_triangles.h): the object's run of the cluster level's triangles.
    // (A masked frame's by the mask's cell's list.)
    auto covering = [&](std::optional<uint32_t> list_cell, uint32_t o) -> std::optional<uint32_t> {
      return list_cell.has_value() ? completion_.CoveringCluster(*list_cell, o) : std::nullopt;
    };
    auto piece = [&](uint32_t c, uint32_t o) -> uint64_t {
      const std::vector<uint32_t>& members = levels.clusters[c].objects;
      const auto at = std::lower_bound(members.begin(), members.end(), o);
      return scene_.levels()->ClusterObjectTriangles(c, completion_.HeldCluster(c)->level)[at - members.begin()];
    };
    // Each drawn object's triangles also by its box's distance from the eye (kTriangleBandsM).
    using Bands = std::array<uint64_t, SimulationResult::kTriangleBandsM.size()>;
    auto band = [&](uint32_t o) {
      const scenes::Aabb& b = objects[o].bounds;
      const double d = glm::length(glm::clamp(pose.eye, b.min, b.max) - pose.eye);
      size_t i = 0;
      while (i + 1 < SimulationResult::kTriangleBandsM.size() && d >= SimulationResult::kTriangleBandsM[i + 1]) ++i;
      return i;
    };
    Bands bands_without{}, bands_masked{};
    uint64_t without = 0;
    auto add_without = [&](uint32_t o, uint64_t n) {
      without += n;
      if (mask == nullptr) bands_without[band(o)] += n;  // a masked frame's bands are the mask's
    };
    if (complete && cell_.has_value()) {
      for (uint32_t o : *completion_.List(*cell_)) {
        if (!seen(o)) continue;
        if (const std::optional<uint32_t> c = covering(cell_, o)) {
          add_without(o, piece(*c, o));
        } else if (completion_.Held(o) != nullptr) {
          add_without(o, TrianglesOf(o));
        }
      }
    } else {
      completion_.ForEachHeld([&](uint32_t o, const client::CellCompletion::Object&) {
        if (seen(o)) add_without(o, TrianglesOf(o));
      });
    }
    uint64_t tris = without;
    if (mask != nullptr) {
      tris = 0;
      for (size_t k = 0; k < mask->object_ids.size(); ++k) {
        const uint32_t o = mask->object_ids[k];
        if (!seen(o)) continue;
        uint64_t n = 0;
        if (const std::optional<uint32_t> c = covering(mask->cell, o)) {
          // A piece of a level that keeps the objects' triangles keeps the mask's bits; a
          // simplified one is drawn whole.
          n = clusters_whole_.count(*c) > 0 ? piece(*c, o) : mask->object_triangles[k];
        } else {
          // A level that keeps the object's triangles (ObjectGeometry.keeps_triangles) keeps
          // the mask's bits; another is drawn whole (as client/renderer.h draws it).
          n = drawn_whole_.count(o) > 0 ? TrianglesOf(o) : mask->object_triangles[k];
        }
        tris += n;
        bands_masked[band(o)] += n;
      }
    }
    const Bands& bands = mask != nullptr ? bands_masked : bands_without;
    for (size_t i = 0; i < bands.size(); ++i) triangles_by_distance_sum_[i] += static_cast<double>(bands[i]);
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
  // Waiting to walk: at the start, with the velocity it will walk at, so that the server ranks
  // the cells ahead first (as the real client, client/walkthrough_startup.cpp).
  scenes::WalkPose pose = walk_.At(0.0);
  if (walk_t0_.has_value()) {
    const double walk_t = t - *walk_t0_;
    pose = walk_.At(std::min(walk_t, walk_.duration_s()));
    if (walk_t >= walk_.duration_s()) pose.velocity = glm::dvec3(0.0);
  }
  SendUp(client::PoseMessage(client::MakePose(pose.eye, pose.velocity, pose.yaw_rad, 0.0, t)), "pose");
  poses_.Sent(t);
  q_.At(poses_.next_s(), [this] { Pose(q_.now()); });
}

absl::Status Run::Go(const scenes::CatalogEntry& entry, const scenes::RunControl& run) {
  const double wall_start = WallSeconds();
  const scenes::SimulationSpec& sim = entry.simulation;
  r_.link_declared = opt_.link.has_value();
  r_.link = LinkParamsFrom(opt_.link, opt_.time_scale);
  up_ = std::make_unique<server::EmulatedLink<v1::ClientMessage>>(r_.link, opt_.seed);
  down_ = std::make_unique<server::EmulatedLink<v1::ServerMessage>>(r_.link, opt_.seed + 1);
  r_.frame_declared = sim.client.has_value() && sim.client->frame_ms.has_value();
  r_.frame_s = r_.frame_declared ? *sim.client->frame_ms / 1000.0 : 1.0 / 60.0;
  r_.scene_triangles = scene_.scene().TriangleCount();
  triangle_every_ = std::max<uint64_t>(1, static_cast<uint64_t>(std::llround(kTriangleSampleS / r_.frame_s)));

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
  client::HelloSettings hello;
  hello.scene = scene_.scene().name;
  hello.epsilon_masks = opt_.scheme == Scheme::kPvsEps;
  hello.screen_error_px = opt_.lod_tau_px;
  hello.clusters = opt_.lod_clusters;
  r_.lod_tau_px = opt_.lod_tau_px;
  if (opt_.lod_tau_px > 0.0 && scene_.levels() == nullptr) {
    return absl::FailedPreconditionError("levels of detail asked for, but the scene has none");
  }
  if (sim.client.has_value() && sim.client->memory_mb.has_value()) {
    hello.memory_budget_bytes = static_cast<uint64_t>(*sim.client->memory_mb * 1048576.0);
  }
  if (sim.client.has_value() && sim.client->triangle_budget.has_value()) {
    hello.triangle_budget = *sim.client->triangle_budget;
  }
  SendUp(client::HelloMessage(hello), "hello");
  SendUp(client::CreditMessage(credit_.Open()), "credit");
  poses_.Restart(0.0);
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
  for (size_t i = 0; i < triangles_by_distance_sum_.size(); ++i) {
    r_.mean_triangles_by_distance[i] =
        triangle_samples_ > 0 ? triangles_by_distance_sum_[i] / static_cast<double>(triangle_samples_) : 0.0;
  }
  r_.mean_triangles_without_masks =
      triangle_samples_ > 0 ? triangles_without_sum_ / static_cast<double>(triangle_samples_) : 0.0;
  r_.masks_computed = masks_->ran();
  r_.mask_compute_s = masks_->busy_s();
  double sum = 0.0;
  size_t n = 0;
  r_.min_margin_s = 0.0;
  for (const client::CellEntry& c : r_.cells) {
    if (c.start) continue;
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

}  // namespace vistream::simulation
