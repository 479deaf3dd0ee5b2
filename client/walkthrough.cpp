#include "client/walkthrough.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <memory>
#include <set>
#include <thread>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>
#include <nlohmann/json.hpp>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "client/connection.h"
#include "client/object_store.h"
#include "client/overlay.h"
#include "client/png_image.h"
#include "client/renderer.h"
#include "scenes/walk.h"
#include "client/window_input.h"
#include "gl/gl_context.h"
#include "gl/id_renderer.h"
#include "proto/scene_info.h"
#include "scenes/catalog.h"
#include "visibility/viewcell_grid.h"

namespace vistream::client {

namespace v1 = vistream::v1;

namespace {

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double at = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<size_t>(std::floor(at));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (v[hi] - v[lo]) * (at - static_cast<double>(lo));
}

// What one step of the loop found: the eye's cell and whether its PVS is ready to draw.
struct Pumped {
  std::optional<uint32_t> cell;
  const std::vector<uint32_t>* pvs = nullptr;
  size_t missing = 0;  // of the PVS list, objects not here and uploaded
  bool complete = false;
};

class Loop {
 public:
  Loop(const WalkthroughOptions& o, WalkthroughSummary* sum) : opt_(o), sum_(sum) {}
  absl::Status Run();

 private:
  absl::Status Prepare();
  // Follows the walk named opt_.path (empty: the first) of walks_; NOT_FOUND listing walks_
  // when there is none such.
  absl::Status ChooseWalk();
  // Follows `path` from its start (`from_here`: from its point nearest the eye); the window's
  // walk list (P) and ChooseWalk.
  absl::Status FollowWalk(const scenes::WalkPath& path, bool from_here);
  // The window's keys (F1, M, H, P, space, +/-, R, F11, F12) and resizing; the walk list's choice.
  absl::Status HandleWindow();
  // The overlay's status for this frame (counters as they stand after it).
  OverlayStatus Status(const Pumped& p, const FrameStats& fs, const EpsilonMaskSet* mask, bool hole,
                       uint64_t triangles_without, double now) const;
  // Draws the overlay over the frame just drawn and acts on what its walk list asked.
  absl::Status DrawOverlay(const OverlayStatus& status, double dt);

  // The window without a walk: starts where the first walk starts, if there is one.
  void StartAtFirstWalk();
  // SceneInfo arrived: the server's walks join walks_; a pending walk is chosen.
  absl::Status OnSceneInfo(const v1::SceneInfo& info);
  absl::Status Startup();
  absl::Status PreloadEverything();
  absl::Status Walkthrough();
  // Takes the network's events into the store and uploads within `upload_budget`.
  absl::StatusOr<Pumped> Pump(const glm::dvec3& eye, uint64_t upload_budget);
  absl::Status Screenshot(double t);
  // Compares what was drawn (`mask`: the mask the frame drew, or none) with the full scene.
  absl::Status Verify(const std::vector<DrawnObject>& drawn, const EpsilonMaskSet* mask);
  void Log(const std::string& line) const {
    if (opt_.log) opt_.log(line);
  }
  bool Cancelled() const { return opt_.cancel != nullptr && opt_.cancel->load(); }
  void SendPose(const glm::dvec3& velocity, double since_start);
  // Which held cells are complete at `t` (walk clock), and the eye's cell.
  void ObserveCells(double t, std::optional<uint32_t> cell, bool stalled) {
    if (connection_ == nullptr || !store_->has_scene_info()) return;
    margins_.Observe(t, store_->pvs_lists(), [this](uint32_t id) { return renderer_->Uploaded(id); }, cell,
                     store_->grid().nx, stalled);
  }

  const WalkthroughOptions& opt_;
  WalkthroughSummary* sum_;
  std::optional<scenes::CatalogEntry> entry_;
  absl::Status catalog_status_;          // why entry_ is none
  std::vector<scenes::WalkPath> walks_;  // the catalog entry's, then the server's (SceneInfo.paths)
  bool walk_pending_ = false;            // following a walk not chosen yet (ChooseWalk)
  std::optional<scenes::Walk> walk_;
  std::optional<scenes::WalkPath> walk_path_;  // walk_'s, to rebuild it over the local terrain
  double walk_limit_s_ = 0.0;
  uint64_t memory_budget_ = 0, triangle_budget_ = 0;
  std::optional<scenes::Scene> owned_scene_;
  const scenes::Scene* full_scene_ = nullptr;
  std::unique_ptr<gl::IdRenderer> ids_;
  std::unique_ptr<gl::GlContext> context_;
  std::unique_ptr<Renderer> renderer_;
  std::unique_ptr<WindowInput> input_;
  std::unique_ptr<Connection> connection_;
  std::unique_ptr<ObjectStore> store_;
  std::vector<Event> preload_;        // draw_everything: the whole scene, applied by the first Pump
  std::vector<uint32_t> everything_;  // draw_everything: every object id
  Camera camera_;
  bool have_start_ = false;  // camera_ holds a start pose
  std::FILE* frame_log_ = nullptr;
  std::FILE* cell_log_ = nullptr;
  std::FILE* overlay_dump_ = nullptr;
  CellMargins margins_;
  double session_start_ = 0.0;
  uint64_t masks_seen_ = 0;
  std::unique_ptr<Overlay> overlay_;
  std::vector<std::string> overlay_lines_;  // the statistics panel's last lines (overlay_dump)
  MinimapCells minimap_cells_;
  double walk_t_ = 0.0;       // the walk's clock: seconds along it
  double rate_ = 1.0;         // + and -: the speed factor
  bool paused_ = false;       // space
  bool walk_ends_run_ = true; // a walk chosen in the window (P) does not end the run at its end
  FixedPose start_pose_;      // R
  bool screenshot_now_ = false;
  double lost_at_ = 0.0;
  bool link_up_ = true, gave_up_flag_ = false;
  uint64_t reconnected_ = 0;  // the connection came back (the Connection counts a session when it ends)
};

absl::Status Loop::ChooseWalk() {
  const scenes::WalkPath* path = nullptr;
  std::vector<std::string> names;
  for (const scenes::WalkPath& w : walks_) {
    names.push_back(w.name);
    if (path == nullptr && (w.name == opt_.path || opt_.path.empty())) path = &w;
  }
  if (path == nullptr) {
    if (walks_.empty() && !entry_.has_value()) {
      return absl::NotFoundError(absl::StrCat("the server's scene '", sum_->scene,
                                              "' has no entry in the scene catalog (", catalog_status_.message(),
                                              ") and the server sends no walks: there is no walk to follow; give "
                                              "--pose instead"));
    }
    return absl::NotFoundError(
        opt_.path.empty()
            ? absl::StrCat("scene '", sum_->scene, "'", entry_.has_value() ? absl::StrCat(" (", entry_->file, ")") : "",
                           " has no walks")
            : absl::StrCat("scene '", sum_->scene, "' has no walk '", opt_.path, "'; its walks: ",
                           absl::StrJoin(names, ", ")));
  }
  return FollowWalk(*path, false);
}

absl::Status Loop::FollowWalk(const scenes::WalkPath& path, bool from_here) {
  const double speed = opt_.speed_kmh > 0.0 ? opt_.speed_kmh / 3.6 : path.speed_mps;
  // With the scene here, terrain and all, the eye keeps its height above the ground.
  absl::StatusOr<scenes::Walk> walk =
      full_scene_ != nullptr && !full_scene_->terrain.empty()
          ? scenes::Walk::Create(path, speed, std::make_shared<const scenes::TerrainHeight>(*full_scene_))
          : scenes::Walk::Create(path, speed);
  if (!walk.ok()) return walk.status();
  double from_s = 0.0;
  if (from_here) {
    // The walk's point nearest the eye, to a metre.
    double best = std::numeric_limits<double>::infinity();
    for (double along = 0.0; along <= walk->length_m() + 0.5; along += 1.0) {
      const glm::dvec2 q = walk->PointAt(along);
      const double d = glm::length(q - glm::dvec2(camera_.eye));
      if (d < best) best = d, from_s = std::min(along, walk->length_m()) / walk->speed_mps();
    }
  }
  walk_ = std::move(*walk);
  walk_path_ = path;
  walk_pending_ = false;
  walk_limit_s_ = opt_.seconds > 0.0 ? std::min(opt_.seconds, walk_->duration_s()) : walk_->duration_s();
  walk_t_ = from_s;
  paused_ = false;
  sum_->path = path.name;
  sum_->speed_kmh = speed * 3.6;
  const scenes::WalkPose start = walk_->At(from_s);
  camera_.eye = start.eye;
  camera_.yaw_rad = start.yaw_rad;
  camera_.pitch_rad = 0.0;
  have_start_ = true;
  return absl::OkStatus();
}

void Loop::StartAtFirstWalk() {
  if (have_start_ || walks_.empty()) return;
  absl::StatusOr<scenes::Walk> walk = scenes::Walk::Create(walks_.front(), walks_.front().speed_mps);
  if (walk.ok()) {
    camera_.eye = walk->At(0.0).eye;
    camera_.yaw_rad = walk->At(0.0).yaw_rad;
    have_start_ = true;
  }
}

absl::Status Loop::OnSceneInfo(const v1::SceneInfo& info) {
  // The server's walks at the speed and eye height of the catalog's first walk, else the defaults.
  const scenes::WalkPath defaults = walks_.empty() ? scenes::WalkPath{} : walks_.front();
  for (int k = 0; k < info.paths_size(); ++k) {
    const v1::ScenePathInfo& p = info.paths(k);
    const bool taken = std::any_of(walks_.begin(), walks_.end(), [&](const scenes::WalkPath& w) { return w.name == p.name(); });
    bool finite = true;
    for (double v : p.xy()) finite = finite && std::isfinite(v);
    if (taken || p.name().empty() || p.xy_size() < 4 || p.xy_size() % 2 != 0 || !finite) {
      if (!taken) Log(absl::StrCat("the server's walk ", k, " ('", p.name(), "') is not a named polyline: ignored"));
      continue;
    }
    scenes::WalkPath w;
    w.name = p.name();
    w.speed_mps = defaults.speed_mps;
    w.eye_height_m = defaults.eye_height_m;
    for (int i = 0; i + 1 < p.xy_size(); i += 2) w.waypoints.emplace_back(p.xy(i), p.xy(i + 1));
    walks_.push_back(std::move(w));
  }
  if (walk_pending_) return ChooseWalk();
  if (!opt_.pose.has_value()) StartAtFirstWalk();
  return absl::OkStatus();
}

absl::Status Loop::Prepare() {
  absl::StatusOr<v1::ServerStats> stats = Probe(opt_.server, opt_.connect_timeout_s, opt_.cancel, opt_.security);
  if (!stats.ok()) return stats.status();
  absl::StatusOr<std::string> scene = PickScene(*stats, opt_.scene, opt_.server);
  if (!scene.ok()) return scene.status();
  sum_->scene = *scene;
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry(sum_->scene, opt_.catalog_dir);
  if (entry.ok()) entry_ = std::move(*entry);

  // The walks: the catalog entry's now; the server's own (SceneInfo.paths) join them when
  // SceneInfo arrives. A walk the catalog has is chosen now, any other then (ChooseWalk).
  if (entry_.has_value()) {
    walks_ = entry_->walks;
  } else {
    catalog_status_ = entry.status();
    Log(absl::StrCat("no scene catalog entry for '", sum_->scene, "' (", catalog_status_.message(),
                     "): no walks, client budgets or effects from the catalog"));
  }
  const bool follow = !opt_.pose.has_value() && (opt_.headless || !opt_.path.empty());
  if (follow) {
    const bool known = std::any_of(walks_.begin(), walks_.end(), [&](const scenes::WalkPath& w) {
      return opt_.path.empty() || w.name == opt_.path;
    });
    walk_pending_ = true;
    if (known) {
      if (absl::Status st = ChooseWalk(); !st.ok()) return st;
    }
  } else if (opt_.pose.has_value()) {
    camera_.eye = opt_.pose->eye;
    camera_.yaw_rad = opt_.pose->yaw_rad;
    camera_.pitch_rad = opt_.pose->pitch_rad;
    have_start_ = true;
  } else {
    StartAtFirstWalk();
  }

  const std::optional<scenes::ClientSpec>& client = entry_.has_value() ? entry_->simulation.client : std::nullopt;
  memory_budget_ = opt_.memory_budget_bytes.value_or(
      client.has_value() && client->memory_mb.has_value() ? static_cast<uint64_t>(*client->memory_mb * 1048576.0) : 0);
  triangle_budget_ =
      opt_.triangle_budget.value_or(client.has_value() ? client->triangle_budget.value_or(0) : uint64_t{0});
  sum_->memory_budget_bytes = memory_budget_;
  sum_->triangle_budget = triangle_budget_;

  if (opt_.verify || opt_.draw_everything) {
    if (opt_.local_scene != nullptr) {
      full_scene_ = opt_.local_scene;
    } else {
      Log(absl::StrCat("loading the full scene '", sum_->scene, "' locally"));
      absl::StatusOr<scenes::LoadedScene> loaded = scenes::LoadScene(sum_->scene, {opt_.catalog_dir, {}});
      if (!loaded.ok()) {
        return absl::Status(loaded.status().code(),
                            absl::StrCat(opt_.verify ? "--verify" : "drawing everything",
                                         " needs the scene locally: ", loaded.status().message()));
      }
      owned_scene_ = std::move(loaded->scene);
      full_scene_ = &*owned_scene_;
    }
  }
  if (walk_.has_value() && full_scene_ != nullptr && !full_scene_->terrain.empty()) {
    // The scene is here, terrain and all: the eye keeps its height above the ground. (Without
    // it a walk over terrain keeps its eye inside each cell's band: see the frame loop.)
    absl::StatusOr<scenes::Walk> walk = scenes::Walk::Create(
        *walk_path_, walk_->speed_mps(), std::make_shared<const scenes::TerrainHeight>(*full_scene_));
    if (!walk.ok()) return walk.status();
    walk_ = std::move(*walk);
    camera_.eye = walk_->At(0.0).eye;
  }
  if (opt_.verify) {
    absl::StatusOr<std::unique_ptr<gl::IdRenderer>> ids = gl::IdRenderer::Create(*full_scene_, 1);
    if (!ids.ok()) return ids.status();
    ids_ = std::move(*ids);
    sum_->verified = true;
  }

  const int samples = opt_.msaa_samples >= 0 ? opt_.msaa_samples : opt_.headless ? 0 : 4;
  absl::StatusOr<std::unique_ptr<gl::GlContext>> context =
      opt_.headless ? gl::GlContext::CreateOffscreen()
                    : gl::GlContext::CreateWindowed(opt_.width, opt_.height, absl::StrCat("vistream: ", sum_->scene),
                                                    opt_.vsync);
  if (!context.ok()) return context.status();
  context_ = std::move(*context);
  int width = opt_.width, height = opt_.height;
  if (!opt_.headless) {
    context_->FramebufferSize(&width, &height);
    input_ = std::make_unique<WindowInput>(context_->window());
  }
  absl::StatusOr<std::unique_ptr<Renderer>> renderer =
      Renderer::Create(context_.get(), width, height, opt_.headless, samples);
  if (!renderer.ok()) return renderer.status();
  renderer_ = std::move(*renderer);
  if (entry_.has_value() && entry_->effects.fog.has_value()) {
    renderer_->SetFog(entry_->effects.fog->start_m, entry_->effects.fog->end_m);
  }
  if (!opt_.headless || opt_.overlay) {
    absl::StatusOr<std::unique_ptr<Overlay>> overlay = Overlay::Create(context_.get(), context_->window());
    if (!overlay.ok()) return overlay.status();
    overlay_ = std::move(*overlay);
    overlay_->show_stats = overlay_->show_minimap = opt_.headless ? opt_.overlay : opt_.window_panels;
  }
  camera_.width = width;
  camera_.height = height;
  sum_->width = width;
  sum_->height = height;

  if (!opt_.frame_log.empty()) {
    frame_log_ = std::fopen(opt_.frame_log.c_str(), "w");
    if (frame_log_ == nullptr) {
      return absl::UnavailableError(absl::StrCat(opt_.frame_log, ": cannot open for writing (--frame-log)"));
    }
    // A line at a time, so that the log can be followed while the client runs (tail -f, tests).
    std::setvbuf(frame_log_, nullptr, _IOLBF, 0);
    std::fprintf(frame_log_,
                 "frame,t_s,x_m,y_m,cell,stall,objects_drawn,triangles_drawn,frame_ms,held_bytes,masked,hole,"
                 "triangles_without_masks,mask_id\n");
  }
  if (!opt_.overlay_dump.empty()) {
    overlay_dump_ = std::fopen(opt_.overlay_dump.c_str(), "w");
    if (overlay_dump_ == nullptr) {
      return absl::UnavailableError(absl::StrCat(opt_.overlay_dump, ": cannot open for writing (--overlay-dump)"));
    }
  }
  if (!opt_.cell_log.empty()) {
    cell_log_ = std::fopen(opt_.cell_log.c_str(), "w");
    if (cell_log_ == nullptr) {
      return absl::UnavailableError(absl::StrCat(opt_.cell_log, ": cannot open for writing (--cell-log)"));
    }
  }
  if (!opt_.screenshots_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(opt_.screenshots_dir, ec);
    if (ec) {
      return absl::UnavailableError(
          absl::StrCat(opt_.screenshots_dir, ": cannot create: ", ec.message(), " (--screenshots)"));
    }
  }

  ConnectionOptions co;
  co.address = opt_.server;
  co.scene = sum_->scene;
  co.memory_budget_bytes = memory_budget_;
  co.triangle_budget = triangle_budget_;
  co.connect_timeout_s = opt_.connect_timeout_s;
  co.security = opt_.security;
  co.epsilon_masks = opt_.use_masks;
  store_ = std::make_unique<ObjectStore>(memory_budget_);
  if (opt_.draw_everything) return PreloadEverything();
  connection_ = std::make_unique<Connection>(co);
  return absl::OkStatus();
}

absl::Status Loop::PreloadEverything() {
  const scenes::Scene& scene = *full_scene_;
  const scenes::ViewcellSpec spec = scenes::ViewcellSpecFor(sum_->scene, 0.0, opt_.catalog_dir);
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(scene, spec);
  if (!grid.ok()) return grid.status();
  std::vector<Event> events;
  events.emplace_back(MakeSceneInfo(scene, *grid, scene.name));
  for (const scenes::Object& o : scene.objects) {
    ReceivedObject r;
    r.id = o.id;
    r.mesh = o.mesh;
    r.bounds_min = o.bounds.min;
    r.bounds_max = o.bounds.max;
    r.raw_bytes = uint64_t{o.mesh.positions.size()} * 24 + uint64_t{o.mesh.indices.size()} * 4;
    events.emplace_back(std::move(r));
    everything_.push_back(o.id);
  }
  preload_ = std::move(events);
  return absl::OkStatus();
}

void Loop::SendPose(const glm::dvec3& velocity, double since_start) {
  if (connection_ == nullptr) return;
  connection_->SetPose(camera_.eye, velocity, camera_.yaw_rad, camera_.pitch_rad, since_start);
}

absl::StatusOr<Pumped> Loop::Pump(const glm::dvec3& eye, uint64_t upload_budget) {
  std::vector<Event> events = connection_ != nullptr ? connection_->Take() : std::move(preload_);
  preload_.clear();
  for (const Event& e : events) {
    if (std::holds_alternative<v1::EpsilonMask>(e)) ++masks_seen_;
  }
  Pumped p;
  if (store_->has_scene_info()) p.cell = store_->grid().CellAt(eye.x, eye.y);
  const bool had_info = store_->has_scene_info();
  const std::vector<uint32_t> dropped = store_->Apply(std::move(events), p.cell);
  if (!dropped.empty()) connection_->Forget(dropped);
  if (store_->failure().has_value()) {
    if (store_->failure_is_bad_data()) {
      return absl::DataLossError(absl::StrCat("the server at ", opt_.server, " sent what this client cannot use: ",
                                              *store_->failure()));
    }
    return absl::UnavailableError(absl::StrCat("the server at ", opt_.server, " ended the session: ", *store_->failure()));
  }
  if (!had_info && store_->has_scene_info()) {
    const v1::SceneInfo& info = store_->scene_info();
    sum_->scene_objects = info.object_count();
    sum_->scene_triangles = info.triangle_count();
    if (full_scene_ != nullptr && (full_scene_->objects.size() != info.object_count() ||
                                    full_scene_->TriangleCount() != info.triangle_count())) {
      return absl::FailedPreconditionError(absl::StrCat(
          "--verify: the local scene '", sum_->scene, "' has ", full_scene_->objects.size(), " objects and ",
          full_scene_->TriangleCount(), " triangles; the server's has ", info.object_count(), " and ",
          info.triangle_count()));
    }
    // The far plane beyond the whole scene seen from anywhere in it.
    const glm::dvec3 lo(info.bounds_min().x(), info.bounds_min().y(), info.bounds_min().z());
    const glm::dvec3 hi(info.bounds_max().x(), info.bounds_max().y(), info.bounds_max().z());
    camera_.far_m = std::max(1000.0, 2.0 * glm::length(hi - lo));
    if (absl::Status st = OnSceneInfo(info); !st.ok()) return st;
    if (!have_start_) {
      const GridInfo& g = store_->grid();
      camera_.eye = {g.x0 + 0.5 * g.nx * g.cell_size, g.y0 + 0.5 * g.ny * g.cell_size, g.base_z + 0.6 * g.height};
      if (g.has_bands()) {
        // Cells follow terrain: 0.6 of the band's height above the cell's highest ground.
        if (const std::optional<uint32_t> c = g.CellAt(camera_.eye.x, camera_.eye.y)) {
          camera_.eye.z = g.Band(*c).second - 0.4 * g.height;
        }
      }
      have_start_ = true;
    }
    p.cell = store_->grid().CellAt(eye.x, eye.y);
  }
  if (p.cell.has_value()) p.pvs = store_->Pvs(*p.cell);
  static const std::vector<uint32_t> kNone;
  renderer_->Sync(*store_, p.pvs != nullptr ? *p.pvs : kNone, upload_budget);
  if (p.pvs != nullptr) {
    p.missing = static_cast<size_t>(
        std::count_if(p.pvs->begin(), p.pvs->end(), [&](uint32_t id) { return !renderer_->Uploaded(id); }));
  }
  p.complete = opt_.draw_everything ? renderer_->pending_uploads() == 0 : p.pvs != nullptr && p.missing == 0;
  return p;
}

absl::Status Loop::Startup() {
  session_start_ = Now();
  if (connection_ != nullptr) connection_->Start();
  Log(absl::StrCat("connected to ", opt_.server, " (scene ", sum_->scene, "); waiting for the first viewcell"));
  uint64_t objects_seen = 0;
  double last_arrival = Now();
  double last_drawn = Now();  // the window's last frame while waiting
  // Following a walk, it waits for the cell it starts in and the first cell the walk enters
  // (what it reaches first), telling the server the velocity it will walk at so that the cells
  // ahead are ranked first; the simulator models the same (server/simulator.cpp).
  // (A walk of the server's own is known once SceneInfo has come.)
  auto velocity = [this] { return walk_.has_value() ? walk_->At(0.0).velocity : glm::dvec3(0.0); };
  std::optional<uint32_t> ahead;
  // Drawing everything, no PVS list ever comes: what is preloaded is all there is to wait for.
  bool ahead_known = (!walk_.has_value() && !walk_pending_) || opt_.draw_everything;
  auto ahead_complete = [&] {
    if (!ahead_known && store_->has_scene_info() && !walk_.has_value()) ahead_known = true;
    if (!ahead_known && store_->has_scene_info()) {
      const GridInfo& g = store_->grid();
      const std::vector<uint32_t> along =
          walk_->CellsAlong(g.cell_size, [&g](const glm::dvec2& q) { return g.CellAt(q.x, q.y); });
      if (along.size() > 1) ahead = along[1];
      ahead_known = true;
    }
    if (!ahead_known) return false;
    if (!ahead.has_value()) return true;
    const std::vector<uint32_t>* list = store_->Pvs(*ahead);
    return list != nullptr &&
           std::all_of(list->begin(), list->end(), [&](uint32_t id) { return renderer_->Uploaded(id); });
  };
  for (;;) {
    if (have_start_) SendPose(velocity(), Now() - session_start_);
    absl::StatusOr<Pumped> p = Pump(camera_.eye, ~uint64_t{0});
    if (!p.ok()) return p.status();
    ObserveCells(Now() - session_start_, std::nullopt, false);  // the walk's clock: shifted at its start
    if (p->complete && ahead_complete()) break;
    if (const uint64_t n = connection_ != nullptr ? connection_->stats().objects_received : 0; n != objects_seen) {
      objects_seen = n;
      last_arrival = Now();
    }
    // The list is here but its geometry stopped coming while the store is at least half full:
    // the server keeps the memory budget (it sends until the next object would not fit).
    // Walk on; frames in such cells count as stalls. Below half the budget the link is only
    // slow (an object of a few kB takes seconds at tens of kbit/s): keep waiting.
    if (p->pvs != nullptr && memory_budget_ != 0 && Now() - last_arrival > 3.0 &&
        2 * store_->held_bytes() >= memory_budget_) {
      sum_->startup_s = Now() - session_start_;
      Log(absl::StrFormat("the first viewcell's PVS (%d objects) does not fit the %.1f MiB memory budget: walking "
                          "on with %d of them after %.1f s",
                          p->pvs->size(), memory_budget_ / 1048576.0, store_->objects().size(), sum_->startup_s));
      return absl::OkStatus();
    }
    if (store_->has_scene_info() && !p->cell.has_value()) {
      return absl::OutOfRangeError(absl::StrFormat("the eye (%.1f, %.1f) is outside the scene's viewcell grid",
                                                   camera_.eye.x, camera_.eye.y));
    }
    if (Cancelled()) return absl::CancelledError("stopped while waiting for the first viewcell");
    if (Now() - session_start_ > opt_.startup_timeout_s) {
      return absl::DeadlineExceededError(absl::StrFormat(
          "the server at %s did not send the first viewcell's PVS and geometry within %.0f s", opt_.server,
          opt_.startup_timeout_s));
    }
    if (input_ != nullptr) {
      std::vector<uint32_t> none;
      const double begin = Now();
      renderer_->Draw(*store_, camera_, none, nullptr, 0, nullptr);
      renderer_->Resolve();
      if (overlay_ != nullptr) {
        // The panels say what the window waits for.
        OverlayStatus st = Status(*p, FrameStats{}, nullptr, false, 0, begin);
        st.starting_s = begin - session_start_;
        st.startup_timeout_s = opt_.startup_timeout_s;
        st.frames = st.stalls = 0;
        if (absl::Status s = DrawOverlay(st, begin - last_drawn); !s.ok()) return s;
      }
      last_drawn = begin;
      context_->SwapBuffers();
      input_->Poll();
      for (const WindowInput::KeyPress& k : input_->TakeKeys()) {
        if (k.key == GLFW_KEY_Q || k.key == GLFW_KEY_ESCAPE) input_->Close();
      }
      if (input_->ShouldClose()) return absl::CancelledError("the window was closed while loading");
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  sum_->startup_s = Now() - session_start_;
  Log(ahead.has_value() ? absl::StrFormat("first viewcell and the next on the walk complete after %.1f s", sum_->startup_s)
                        : absl::StrFormat("first viewcell complete after %.1f s", sum_->startup_s));
  return absl::OkStatus();
}

absl::Status Loop::Screenshot(double t) {
  absl::StatusOr<std::vector<uint8_t>> rgb = renderer_->ReadRgb();
  if (!rgb.ok()) return rgb.status();
  // F12 and SIGUSR1 without --screenshots: a folder of their own in the working folder.
  std::error_code cwd_error;
  const std::string dir = opt_.screenshots_dir.empty()
                              ? (std::filesystem::current_path(cwd_error) / "vistream-screenshots").string()
                              : opt_.screenshots_dir;
  if (opt_.screenshots_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return absl::UnavailableError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  const std::string path = (std::filesystem::path(dir) /
                            absl::StrFormat("frame-%06d-t%07.1fs.png", static_cast<int>(sum_->frames), t))
                               .string();
  if (absl::Status s = WritePng(path, {renderer_->width(), renderer_->height(), std::move(*rgb)}); !s.ok()) return s;
  sum_->screenshots.push_back(path);
  return absl::OkStatus();
}

absl::Status Loop::Verify(const std::vector<DrawnObject>& drawn, const EpsilonMaskSet* mask) {
  std::vector<uint8_t> flags(ids_->triangle_count(), 0);
  for (const DrawnObject& d : drawn) {
    if (d.id >= full_scene_->objects.size()) continue;
    const uint64_t first = ids_->FirstTriangle(d.id);
    const size_t n = full_scene_->objects[d.id].mesh.TriangleCount();
    const std::vector<uint8_t>* bits = nullptr;
    if (d.masked && mask != nullptr) bits = mask->Bits(d.id);
    for (size_t t = 0; t < n; ++t) {
      flags[first + t] = bits == nullptr || visibility::MaskBit(*bits, t) ? 1 : 0;
    }
  }
  const glm::dvec3 forward = camera_.Forward(), up = camera_.Up();
  absl::StatusOr<std::vector<uint32_t>> full =
      ids_->RenderView(camera_.eye, forward, up, camera_.fov_y_rad, camera_.width, camera_.height, nullptr);
  if (!full.ok()) return full.status();
  absl::StatusOr<std::vector<uint32_t>> part =
      ids_->RenderView(camera_.eye, forward, up, camera_.fov_y_rad, camera_.width, camera_.height, &flags);
  if (!part.ok()) return part.status();
  uint64_t differ = 0;
  for (size_t k = 0; k < full->size(); ++k) differ += (*full)[k] != (*part)[k] ? 1 : 0;
  sum_->pixel_error += differ;
  sum_->checked_pixels += full->size();
  ++sum_->checked_frames;
  if (differ > 0) {
    Log(absl::StrFormat("verify: %d pixels differ at (%.1f, %.1f)", differ, camera_.eye.x, camera_.eye.y));
  }
  return context_->MakeCurrent();
}

OverlayStatus Loop::Status(const Pumped& p, const FrameStats& fs, const EpsilonMaskSet* mask, bool hole,
                           uint64_t triangles_without, double now) const {
  OverlayStatus st;
  st.server = opt_.server;
  st.scene = sum_->scene;
  if (connection_ == nullptr) {
    st.link = OverlayStatus::Link::kLocal;
  } else {
    const ConnectionStats c = connection_->stats();
    st.reconnects = std::max<uint64_t>(c.reconnects, reconnected_);
    st.bytes_received = c.bytes_received;
    st.backoff_s = c.backoff_s;
    st.link = link_up_ ? OverlayStatus::Link::kConnected
              : gave_up_flag_ ? OverlayStatus::Link::kGivenUp
                              : OverlayStatus::Link::kReconnecting;
    st.lost_for_s = link_up_ ? 0.0 : now - lost_at_;
  }
  st.give_up_s = opt_.give_up_s;
  st.cell = p.cell;
  if (p.cell.has_value()) {
    const GridInfo& g = store_->grid();
    st.cell_i = static_cast<int>(*p.cell % static_cast<uint32_t>(g.nx));
    st.cell_j = static_cast<int>(*p.cell / static_cast<uint32_t>(g.nx));
  }
  st.pvs_listed = p.pvs != nullptr;
  st.pvs_complete = p.complete;
  if (p.pvs != nullptr) {
    st.pvs_objects = p.pvs->size();
    st.pvs_missing = p.missing;
  }
  st.held_objects = store_->objects().size();
  st.held_bytes = store_->held_bytes();
  st.memory_budget_bytes = memory_budget_;
  // The counters as they will stand after this frame (the summary's at the end).
  st.frames = sum_->frames + 1;
  st.stalls = sum_->stalls + (p.complete ? 0 : 1);
  st.stall_s = sum_->stall_s;
  st.hole_frames = sum_->hole_frames + (hole ? 1 : 0);
  st.frames_masked = sum_->frames_masked + (fs.mask_used ? 1 : 0);
  st.masks_received = masks_seen_;
  st.masked = mask != nullptr;
  st.hole = hole;
  if (mask != nullptr) {
    st.mask_id = mask->mask_id;
    st.mask_box_min = mask->box_min;
    st.mask_box_max = mask->box_max;
  }
  st.triangles_drawn = fs.triangles_drawn;
  st.triangles_without_masks = triangles_without;
  st.scene_triangles = sum_->scene_triangles;
  st.eye = camera_.eye;
  st.yaw_rad = camera_.yaw_rad;
  if (walk_.has_value()) {
    st.walk = sum_->path;
    st.walk_t_s = std::min(walk_t_, walk_limit_s_);
    st.walk_duration_s = walk_limit_s_;
    st.speed_kmh = walk_->speed_mps() * 3.6 * rate_;
    st.walk_paused = paused_;
  } else {
    st.speed_kmh = (!walks_.empty() ? walks_.front().speed_mps : 1.4) * 3.6 * rate_;
  }
  return st;
}

absl::Status Loop::DrawOverlay(const OverlayStatus& status, double dt) {
  MinimapView map;
  if (store_->has_scene_info()) {
    map.grid = &store_->grid();
    map.radius_m = MinimapRadius(*map.grid);
    minimap_cells_.Refresh(*store_, [this](uint32_t id) { return renderer_->Uploaded(id); }, camera_.eye,
                           map.radius_m);
    map.cells = &minimap_cells_.states();
  }
  if (walk_.has_value() && walk_path_.has_value()) map.walk = walk_path_->waypoints;
  std::vector<std::string> names;
  for (const scenes::WalkPath& w : walks_) names.push_back(w.name);
  absl::StatusOr<OverlayRequest> frame =
      overlay_->Frame(status, map, names, renderer_->width(), renderer_->height(), dt);
  if (!frame.ok()) return frame.status();
  const OverlayRequest& req = *frame;
  overlay_lines_ = overlay_->last_lines();
  if (req.follow_walk.has_value() && *req.follow_walk < walks_.size()) {
    const scenes::WalkPath chosen = walks_[*req.follow_walk];
    if (absl::Status st = FollowWalk(chosen, !req.from_start); !st.ok()) return st;
    walk_ends_run_ = false;
    Log(absl::StrFormat("following the walk '%s' from %s", chosen.name, req.from_start ? "its start" : "here"));
  }
  return absl::OkStatus();
}

absl::Status Loop::HandleWindow() {
  // The window's size: the projection and the viewport follow it (F11, a drag, a tiling
  // window manager).
  int fw = 0, fh = 0;
  context_->FramebufferSize(&fw, &fh);
  if (fw > 0 && fh > 0 && (fw != renderer_->width() || fh != renderer_->height())) {
    if (absl::Status st = renderer_->Resize(fw, fh); !st.ok()) return st;
    camera_.width = fw;
    camera_.height = fh;
    sum_->width = fw;
    sum_->height = fh;
  }
  auto faster = [this] { rate_ = std::min(rate_ * 1.25, 64.0); };
  auto slower = [this] { rate_ = std::max(rate_ / 1.25, 1.0 / 64.0); };
  const std::vector<unsigned> chars = input_->TakeChars();
  const std::vector<WindowInput::KeyPress> keys = input_->TakeKeys();
  // A key may change what a panel says (the walk list's row, the speed): rebuilt this frame.
  if (!chars.empty() || !keys.empty()) overlay_->Invalidate();
  for (unsigned c : chars) {
    if (c == '?') overlay_->show_help = !overlay_->show_help;
    if (c == '+') faster();
    if (c == '-') slower();
  }
  for (const WindowInput::KeyPress& k : keys) {
    const bool enter = k.key == GLFW_KEY_ENTER || k.key == GLFW_KEY_KP_ENTER;
    if (overlay_->show_walks && (k.key == GLFW_KEY_UP || k.key == GLFW_KEY_DOWN || enter || k.key == GLFW_KEY_F ||
                                 k.key == GLFW_KEY_ESCAPE)) {
      // The walk list's keys: Up/Down choose, Enter from its start, F from here, Esc closes.
      size_t& sel = overlay_->walk_selected();
      if (k.key == GLFW_KEY_UP && sel > 0) --sel;
      if (k.key == GLFW_KEY_DOWN && sel + 1 < walks_.size()) ++sel;
      if ((enter || k.key == GLFW_KEY_F) && sel < walks_.size()) {
        const scenes::WalkPath chosen = walks_[sel];
        if (absl::Status st = FollowWalk(chosen, k.key == GLFW_KEY_F); !st.ok()) return st;
        walk_ends_run_ = false;
        Log(absl::StrFormat("following the walk '%s' from %s", chosen.name,
                            k.key == GLFW_KEY_F ? "here" : "its start"));
      }
      if (k.key != GLFW_KEY_UP && k.key != GLFW_KEY_DOWN) overlay_->show_walks = false;
      continue;
    }
    const bool moves = k.key == GLFW_KEY_W || k.key == GLFW_KEY_A || k.key == GLFW_KEY_S || k.key == GLFW_KEY_D ||
                       k.key == GLFW_KEY_UP || k.key == GLFW_KEY_DOWN || k.key == GLFW_KEY_LEFT ||
                       k.key == GLFW_KEY_RIGHT;
    if (moves && walk_.has_value()) {
      // Walking leaves the walk followed: free walking from where the eye is.
      Log(absl::StrFormat("left the walk '%s': walking freely", sum_->path));
      walk_.reset();
      paused_ = false;
      continue;
    }
    switch (k.key) {
      case GLFW_KEY_F1: overlay_->show_stats = !overlay_->show_stats; break;
      case GLFW_KEY_M: overlay_->show_minimap = !overlay_->show_minimap; break;
      case GLFW_KEY_H: overlay_->show_help = !overlay_->show_help; break;
      case GLFW_KEY_P: overlay_->show_walks = !overlay_->show_walks; break;
      case GLFW_KEY_SPACE:
        if (walk_.has_value()) {
          paused_ = !paused_;
          Log(paused_ ? "walk paused" : "walk resumed");
        }
        break;
      case GLFW_KEY_R:
        if (walk_.has_value()) {
          walk_t_ = 0.0;
        } else {
          camera_.eye = start_pose_.eye;
          camera_.yaw_rad = start_pose_.yaw_rad;
          camera_.pitch_rad = start_pose_.pitch_rad;
        }
        break;
      case GLFW_KEY_F11: input_->ToggleFullScreen(); break;
      case GLFW_KEY_F12: screenshot_now_ = true; break;
      case GLFW_KEY_Q: input_->Close(); break;
      case GLFW_KEY_ESCAPE:
        if (overlay_->show_help) {
          overlay_->show_help = false;
        } else {
          input_->Escape();
        }
        break;
      default: break;
    }
  }
  return absl::OkStatus();
}

absl::Status Loop::Walkthrough() {
  const double t0 = Now();
  margins_.Shift(session_start_ - t0);
  double paused = 0.0, next_shot = 0.0, next_check = 0.0, prev_end = Now(), last_title = 0.0;
  double prev_begin = Now();  // free walking moves by the frame period (not the idle gap after a frame)
  int next_progress = 1;
  std::vector<double> frame_ms;
  uint64_t triangles = 0, objects = 0;
  std::set<uint32_t> cells;
  glm::dvec3 prev_eye = camera_.eye;
  const double free_speed = !walks_.empty() ? walks_.front().speed_mps : 1.4;
  std::vector<DrawnObject> drawn;
  bool was_connected = true;
  double lost_at = 0.0;
  std::optional<uint32_t> stalled_in;  // the cell a stall was last reported for
  std::optional<uint32_t> holed_in;    // the cell a hole frame was last reported for
  uint64_t triangles_without = 0;      // over the frames: what the viewcell PVS alone would draw
  absl::Status gave_up;  // the server lost for longer than --give-up: the walk ends with it
  start_pose_ = {camera_.eye, camera_.yaw_rad, camera_.pitch_rad};
  walk_ends_run_ = opt_.headless;  // the window stays open at a walk's end
  double prev_t = 0.0;
  for (;;) {
    const double begin = Now();
    const double t = begin - t0 - paused;
    if (input_ != nullptr) {
      if (absl::Status st = HandleWindow(); !st.ok()) return st;
    }
    const double frame_period = begin - prev_begin;
    prev_begin = begin;
    if (opt_.screenshot_request != nullptr && opt_.screenshot_request->exchange(false)) screenshot_now_ = true;
    // The walk's clock: the frame's time at the speed factor, unless paused (the headless
    // walk's clock is t itself).
    if (!paused_) walk_t_ += (t - prev_t) * rate_;
    prev_t = t;
    bool last = opt_.seconds > 0.0 && t >= opt_.seconds;  // walks clamp to it below
    // The window closed (Q, its close button): one more frame, the last, with its screenshot.
    if (input_ != nullptr && input_->ShouldClose()) last = true;
    const bool cancel = Cancelled();
    if (cancel) {
      sum_->cancelled = true;
      last = true;  // this frame is the last: its screenshot and check are taken
    }
    glm::dvec3 velocity(0.0);
    if (walk_.has_value()) {
      walk_t_ = std::min(walk_t_, walk_limit_s_);
      const double at = walk_t_;
      last = last || (walk_ends_run_ && walk_t_ >= walk_limit_s_);
      const scenes::WalkPose pose = walk_->At(at);
      camera_.eye = pose.eye;
      if (store_->has_scene_info() && store_->grid().has_bands()) {
        // Cells follow terrain this client may not hold: the eye stays in its cell's band, where
        // the server accepts it and the PVSs hold.
        const GridInfo& g = store_->grid();
        if (const std::optional<uint32_t> c = g.CellAt(camera_.eye.x, camera_.eye.y)) {
          camera_.eye.z = std::clamp(camera_.eye.z, g.Band(*c).first, g.Band(*c).second);
        }
      }
      camera_.yaw_rad = pose.yaw_rad;
      velocity = last || paused_ || walk_t_ >= walk_limit_s_ ? glm::dvec3(0.0) : pose.velocity * rate_;
    } else if (opt_.pose.has_value()) {
      const uint64_t frames = opt_.frames > 0 ? opt_.frames : (opt_.headless ? 1 : ~uint64_t{0});
      last = last || sum_->frames + 1 >= frames;
    } else if (input_ != nullptr) {
      const double dt = std::clamp(frame_period, 1e-3, 0.1);
      glm::dvec3 eye = camera_.eye;
      input_->Update(dt, free_speed * rate_, &eye, &camera_.yaw_rad, &camera_.pitch_rad, overlay_->WantsMouse());
      // The PVSs hold inside the grid: the eye stays in it.
      const GridInfo& g = store_->grid();
      eye.x = std::clamp(eye.x, g.x0 + 0.01, g.x0 + g.nx * g.cell_size - 0.01);
      eye.y = std::clamp(eye.y, g.y0 + 0.01, g.y0 + g.ny * g.cell_size - 0.01);
      // ...and in its cell's band (where cells follow terrain, the band moves with the ground).
      if (const std::optional<uint32_t> c = g.CellAt(eye.x, eye.y); c.has_value() && g.has_bands()) {
        eye.z = std::clamp(eye.z, g.Band(*c).first, g.Band(*c).second);
      }
      velocity = (eye - camera_.eye) / dt;
      camera_.eye = eye;
    }
    SendPose(velocity, begin - session_start_);
    if (connection_ != nullptr && connection_->connected() != was_connected) {
      was_connected = !was_connected;
      lost_at = begin;
      if (was_connected) ++reconnected_;
      Log(was_connected ? absl::StrFormat("reconnected to %s", opt_.server)
                        : absl::StrFormat("lost the server at %s; reconnecting (drawing what is held)", opt_.server));
    }
    link_up_ = was_connected;
    lost_at_ = lost_at;
    const bool gave_up_before = gave_up_flag_;
    gave_up_flag_ = !was_connected && opt_.give_up_s > 0.0 && begin - lost_at > opt_.give_up_s;
    if (gave_up_flag_ && !gave_up_before && input_ != nullptr) {
      Log(absl::StrFormat("gave up on the server at %s after %.0f s; the window stays open on what it holds",
                          opt_.server, opt_.give_up_s));
    }
    if (gave_up_flag_) {
      // The summary of what was walked is still made (and printed), then the error. The
      // window stays open, saying so, until it is closed (or the server comes back).
      gave_up = absl::UnavailableError(absl::StrFormat("lost the server at %s: no answer for %.0f s", opt_.server,
                                                       opt_.give_up_s));
      if (input_ == nullptr) break;
    } else if (was_connected) {
      gave_up = absl::OkStatus();
    }
    absl::StatusOr<Pumped> p = Pump(camera_.eye, opt_.upload_budget_bytes);
    if (!p.ok()) return p.status();
    ObserveCells(t, p->cell, !p->complete);
    // The frame rule: the eye's mask once all its objects are here (a masked frame); else the
    // viewcell's PVS once complete; else what is held (a hole frame).
    MaskChoice choice;
    if (opt_.use_masks && !opt_.draw_everything) {
      choice = store_->ChooseMask(camera_.eye, [this](uint32_t id) { return renderer_->Uploaded(id); });
    }
    const EpsilonMaskSet* use_mask = choice.mask;
    const bool hole = use_mask == nullptr && !p->complete;
    std::vector<uint32_t> everything;
    if (!p->complete) {
      // What is held: a hole frame draws it, and a PVS-only client would have.
      for (const auto& [id, o] : store_->objects()) everything.push_back(id);
    }
    const std::vector<uint32_t>* without_masks =
        opt_.draw_everything ? &everything_ : p->complete ? p->pvs : &everything;
    const std::vector<uint32_t>* set = use_mask != nullptr ? &use_mask->object_ids : without_masks;
    const bool check = ids_ != nullptr && (t >= next_check || last);
    drawn.clear();
    const FrameStats fs = renderer_->Draw(*store_, camera_, *set, use_mask, sum_->frames + 1, check ? &drawn : nullptr);
    // What the PVS alone would have drawn (counted, not drawn).
    const uint64_t triangles_without_masks =
        use_mask != nullptr ? renderer_->CountTriangles(*store_, camera_, *without_masks) : fs.triangles_drawn;
    // The window shows the single-sample frame, and the overlay is drawn over it (headless
    // without the overlay, a screenshot resolves the frame it reads).
    if (input_ != nullptr || overlay_ != nullptr) renderer_->Resolve();
    uint64_t bytes_received = 0;  // as the overlay's status read it (one look at the connection a frame)
    if (overlay_ != nullptr) {
      // A screenshot shows the panels as they stand this frame, and so does the last frame.
      if (screenshot_now_ || last || (!opt_.screenshots_dir.empty() && t >= next_shot)) overlay_->Invalidate();
      const OverlayStatus status = Status(*p, fs, use_mask, hole, triangles_without_masks, begin);
      bytes_received = status.bytes_received;
      if (absl::Status st = DrawOverlay(status, frame_period); !st.ok()) return st;
    }
    renderer_->Finish();
    const double end = Now();
    if (overlay_ != nullptr) overlay_->AddFrame((end - begin) * 1000.0, end, bytes_received);
    ++sum_->frames;
    frame_ms.push_back((end - begin) * 1000.0);
    if (hole) {
      ++sum_->hole_frames;
      if (p->cell != holed_in && p->cell.has_value()) {
        holed_in = p->cell;
        Log(absl::StrFormat("hole frame at %.0f s: %s", t,
                            !opt_.use_masks ? "its viewcell's PVS is incomplete (no ε-masks asked for)"
                            : choice.in_box ? "the eye's masks lack objects and its viewcell's PVS is incomplete"
                                            : "the eye is in no mask's box and its viewcell's PVS is incomplete"));
      }
    }
    if (!p->complete) {
      if (p->cell != stalled_in && p->cell.has_value()) {
        stalled_in = p->cell;
        size_t missing = 0;
        if (p->pvs != nullptr) {
          for (uint32_t id : *p->pvs) missing += store_->Find(id) == nullptr ? 1 : 0;
        }
        const GridInfo& g = store_->grid();
        Log(absl::StrFormat(
            "stall in viewcell %d,%d at %.0f s: %s; holding %.1f MiB%s", *p->cell % static_cast<uint32_t>(g.nx),
            *p->cell / static_cast<uint32_t>(g.nx), t,
            p->pvs == nullptr ? std::string("its PVS list has not arrived")
                              : absl::StrFormat("%d of its %d objects have not arrived", missing, p->pvs->size()),
            store_->held_bytes() / 1048576.0,
            memory_budget_ > 0 ? absl::StrFormat(" of a %.1f MiB budget", memory_budget_ / 1048576.0) : ""));
      }
      ++sum_->stalls;
      sum_->stall_s += end - prev_end;
    }
    prev_end = end;
    triangles += fs.triangles_drawn;
    triangles_without += triangles_without_masks;
    objects += fs.objects_drawn;
    sum_->max_triangles_drawn = std::max(sum_->max_triangles_drawn, fs.triangles_drawn);
    if (memory_budget_ != 0 && store_->held_bytes() > memory_budget_) ++sum_->frames_over_memory_budget;
    if (triangle_budget_ != 0 && fs.triangles_drawn > triangle_budget_) ++sum_->frames_over_triangle_budget;
    if (fs.mask_used) ++sum_->frames_masked;
    if (p->cell.has_value()) cells.insert(*p->cell);
    sum_->distance_m += glm::length(camera_.eye - prev_eye);
    prev_eye = camera_.eye;

    const double pause_begin = Now();
    if (!opt_.screenshots_dir.empty() && (t >= next_shot || last)) {
      if (absl::Status s = Screenshot(t); !s.ok()) return s;
      while (next_shot <= t) next_shot += opt_.every_s;
      screenshot_now_ = false;
    }
    if (screenshot_now_) {
      // Asked for (F12, SIGUSR1): one that cannot be written is said, and the walk goes on.
      screenshot_now_ = false;
      if (absl::Status s = Screenshot(t); s.ok()) {
        Log(absl::StrCat("screenshot: ", sum_->screenshots.back()));
      } else {
        Log(absl::StrCat("screenshot failed: ", s.message()));
      }
    }
    if (check) {
      if (absl::Status s = Verify(drawn, use_mask); !s.ok()) return s;
      while (next_check <= t) next_check += opt_.every_s;
    }
    if (frame_log_ != nullptr) {
      std::fprintf(frame_log_, "%llu,%.3f,%.2f,%.2f,%lld,%d,%u,%llu,%.3f,%llu,%d,%d,%llu,%u\n",
                   static_cast<unsigned long long>(sum_->frames), t, camera_.eye.x, camera_.eye.y,
                   p->cell.has_value() ? static_cast<long long>(*p->cell) : -1LL, p->complete ? 0 : 1,
                   fs.objects_drawn, static_cast<unsigned long long>(fs.triangles_drawn), frame_ms.back(),
                   static_cast<unsigned long long>(store_->held_bytes()), fs.mask_used ? 1 : 0, hole ? 1 : 0,
                   static_cast<unsigned long long>(triangles_without_masks),
                   use_mask != nullptr ? use_mask->mask_id : 0u);
    }
    // Where on the walk (its clock: paused, faster, restarted), not the run's time.
    if (walk_.has_value() && walk_t_ >= next_progress * 0.1 * walk_limit_s_ && next_progress <= 9) {
      Log(absl::StrFormat("walk %d%%: %.0f of %.0f s, %d frames, %d stalls, %.1f MB held", next_progress * 10,
                          walk_t_, walk_limit_s_, sum_->frames, sum_->stalls, store_->held_bytes() / 1e6));
      ++next_progress;
    }
    if (input_ != nullptr) {
      context_->SwapBuffers();
      input_->Poll();
      if (end - last_title > 0.5) {
        const double fps = 1000.0 / std::max(1e-3, frame_ms.back());
        std::string cell = "-";
        if (p->cell.has_value()) {
          const GridInfo& g = store_->grid();
          cell = absl::StrCat(*p->cell % static_cast<uint32_t>(g.nx), ",", *p->cell / static_cast<uint32_t>(g.nx));
        }
        input_->SetTitle(absl::StrFormat(
            "vistream %s | %.0f fps | cell %s | %s | PVS %d | held %d objects, %.1f MB | drawn %d tris (PVS %d) | "
            "stalls %d, holes %d",
            sum_->scene, fps, cell, use_mask != nullptr ? "masked" : hole ? "HOLE" : "PVS",
            p->pvs != nullptr ? p->pvs->size() : 0, store_->objects().size(), store_->held_bytes() / 1e6,
            fs.triangles_drawn, triangles_without_masks, sum_->stalls, sum_->hole_frames));
        last_title = end;
      }
    }
    paused += Now() - pause_begin;
    if (last) break;
    if (opt_.max_fps > 0.0) {
      const double wait = begin + 1.0 / opt_.max_fps - Now();
      if (wait > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(wait));
    }
  }
  const double walked = Now() - t0 - paused;
  sum_->walk_s = walked;
  margins_.Finish(walked);
  sum_->fps = walked > 0.0 ? static_cast<double>(sum_->frames) / walked : 0.0;
  sum_->frame_ms_p50 = Percentile(frame_ms, 0.5);
  sum_->frame_ms_p99 = Percentile(frame_ms, 0.99);
  sum_->frame_ms_max = frame_ms.empty() ? 0.0 : *std::max_element(frame_ms.begin(), frame_ms.end());
  if (sum_->frames > 0) {
    sum_->mean_triangles_drawn = static_cast<double>(triangles) / static_cast<double>(sum_->frames);
    sum_->mean_objects_drawn = static_cast<double>(objects) / static_cast<double>(sum_->frames);
    sum_->mean_triangles_without_masks = static_cast<double>(triangles_without) / static_cast<double>(sum_->frames);
  }
  sum_->cells_visited = cells.size();
  return gave_up;
}

absl::Status Loop::Run() {
  absl::Status s = Prepare();
  if (s.ok()) s = Startup();
  if (s.ok()) {
    s = Walkthrough();
  } else if (s.code() == absl::StatusCode::kCancelled) {
    sum_->cancelled = true;
    s = absl::OkStatus();
  }
  if (connection_ != nullptr) {
    const absl::Status end = connection_->Stop();
    const ConnectionStats c = connection_->stats();
    sum_->bytes_received = c.bytes_received;
    sum_->geometry_bytes = c.geometry_bytes;
    sum_->objects_received = c.objects_received;
    sum_->duplicates = c.duplicates;
    sum_->reconnects = c.reconnects;
    if (s.ok() && !end.ok() && end.code() != absl::StatusCode::kUnavailable) s = end;
  }
  if (store_ != nullptr) {
    sum_->max_held_bytes = store_->max_held_bytes();
    sum_->evicted_by_server = store_->evicted_by_server();
    sum_->evicted_by_budget = store_->evicted_by_budget();
  }
  sum_->masks_received = masks_seen_;
  if (overlay_dump_ != nullptr) {
    bool failed = false;
    for (const std::string& line : overlay_lines_) {
      failed = failed || std::fprintf(overlay_dump_, "%s\n", line.c_str()) < 0;
    }
    if ((std::fclose(overlay_dump_) != 0 || failed) && s.ok()) {
      s = absl::DataLossError(absl::StrCat(opt_.overlay_dump, ": writing the overlay's lines failed (--overlay-dump)"));
    }
  }
  sum_->margins = margins_.Summary();
  sum_->cells = margins_.entries();
  if (cell_log_ != nullptr) {
    const std::string csv = margins_.Csv();
    const bool failed = std::fwrite(csv.data(), 1, csv.size(), cell_log_) != csv.size();
    if ((std::fclose(cell_log_) != 0 || failed) && s.ok()) {
      s = absl::DataLossError(absl::StrCat(opt_.cell_log, ": writing the cell log failed"));
    }
  }
  if (frame_log_ != nullptr) {
    const bool failed = std::ferror(frame_log_) != 0;
    if ((std::fclose(frame_log_) != 0 || failed) && s.ok()) {
      s = absl::DataLossError(absl::StrCat(opt_.frame_log, ": writing the frame log failed"));
    }
  }
  // GL objects go with their context, the id renderer's first (it makes its own).
  overlay_.reset();
  renderer_.reset();
  ids_.reset();
  context_.reset();
  return s;
}

}  // namespace

absl::Status RunWalkthrough(const WalkthroughOptions& options, WalkthroughSummary* summary) {
  *summary = WalkthroughSummary{};
  summary->server = options.server;
  Loop loop(options, summary);
  return loop.Run();
}

absl::StatusOr<WalkthroughSummary> RunWalkthrough(const WalkthroughOptions& options) {
  WalkthroughSummary summary;
  if (absl::Status s = RunWalkthrough(options, &summary); !s.ok()) return s;
  return summary;
}

std::string SummaryJson(const WalkthroughSummary& s) {
  nlohmann::ordered_json j;
  j["server"] = s.server;
  j["scene"] = s.scene;
  j["path"] = s.path;
  j["speed_kmh"] = s.speed_kmh;
  j["size"] = absl::StrCat(s.width, "x", s.height);
  j["frames"] = s.frames;
  j["stalls"] = s.stalls;
  j["stall_s"] = s.stall_s;
  j["bytes_received"] = s.bytes_received;
  j["geometry_bytes"] = s.geometry_bytes;
  j["objects_received"] = s.objects_received;
  j["duplicates"] = s.duplicates;
  j["reconnects"] = s.reconnects;
  j["mean_triangles_drawn"] = s.mean_triangles_drawn;
  j["mean_triangles_without_masks"] = s.mean_triangles_without_masks;
  j["max_triangles_drawn"] = s.max_triangles_drawn;
  j["mean_objects_drawn"] = s.mean_objects_drawn;
  j["scene_triangles"] = s.scene_triangles;
  j["scene_objects"] = s.scene_objects;
  j["max_held_bytes"] = s.max_held_bytes;
  // 0 means no budget: null says so.
  j["memory_budget_bytes"] = s.memory_budget_bytes > 0 ? nlohmann::json(s.memory_budget_bytes) : nlohmann::json();
  j["frames_over_memory_budget"] = s.frames_over_memory_budget;
  j["triangle_budget"] = s.triangle_budget > 0 ? nlohmann::json(s.triangle_budget) : nlohmann::json();
  j["frames_over_triangle_budget"] = s.frames_over_triangle_budget;
  j["evicted_by_server"] = s.evicted_by_server;
  j["evicted_by_budget"] = s.evicted_by_budget;
  j["fps"] = s.fps;
  j["frame_ms_p50"] = s.frame_ms_p50;
  j["frame_ms_p99"] = s.frame_ms_p99;
  j["frame_ms_max"] = s.frame_ms_max;
  // null when nothing was checked: no check is not a check that found nothing.
  j["pixel_error"] = s.verified ? nlohmann::ordered_json(s.pixel_error) : nlohmann::ordered_json(nullptr);
  j["checked_frames"] = s.checked_frames;
  j["checked_pixels"] = s.checked_pixels;
  j["masks_received"] = s.masks_received;
  j["frames_masked"] = s.frames_masked;
  j["hole_frames"] = s.hole_frames;
  j["cells_visited"] = s.cells_visited;
  j["startup_s"] = s.startup_s;
  j["walk_s"] = s.walk_s;
  j["distance_m"] = s.distance_m;
  j["cells_entered"] = s.margins.cells_entered;
  j["stalled_cells"] = s.margins.stalled_cells;
  // null when no cell was entered after the start cell: no margin was measured.
  j["min_margin_s"] = s.margins.min_margin_s.has_value() ? nlohmann::ordered_json(*s.margins.min_margin_s)
                                                         : nlohmann::ordered_json(nullptr);
  j["mean_margin_s"] = s.margins.mean_margin_s.has_value() ? nlohmann::ordered_json(*s.margins.mean_margin_s)
                                                           : nlohmann::ordered_json(nullptr);
  j["screenshots"] = s.screenshots;
  j["cancelled"] = s.cancelled;
  return j.dump(2);
}

std::string SummaryText(const WalkthroughSummary& s) {
  std::string out = absl::StrFormat(
      "walkthrough of %s%s: %d frames in %.1f s (%.1f fps; frame time p50 %.1f ms, p99 %.1f ms), %.0f m walked, "
      "%d viewcells\n",
      s.scene.empty() ? std::string("no scene (stopped before the server said which)") : s.scene,
      s.path.empty() ? "" : absl::StrCat(" along '", s.path, "'"), s.frames, s.walk_s, s.fps,
      s.frame_ms_p50, s.frame_ms_p99, s.distance_m, s.cells_visited);
  absl::StrAppendFormat(&out, "  stalls: %d (%.2f s); first viewcell after %.1f s\n", s.stalls, s.stall_s,
                        s.startup_s);
  if (s.margins.cells_entered > 0) {
    absl::StrAppendFormat(&out,
                          "  cells_entered: %d, stalled_cells: %d, min_margin_s: %.3f, mean_margin_s: %.3f (arrival "
                          "margins after the start cell)\n",
                          s.margins.cells_entered, s.margins.stalled_cells, *s.margins.min_margin_s,
                          *s.margins.mean_margin_s);
  } else {
    out += "  cells_entered: 0 (no arrival margin measured after the start cell)\n";
  }
  absl::StrAppendFormat(&out,
                        "  received %.1f MB (%d objects, %d twice, %d reconnects); held at most %.2f MiB%s\n",
                        s.bytes_received / 1e6, s.objects_received, s.duplicates, s.reconnects,
                        s.max_held_bytes / 1048576.0,
                        s.memory_budget_bytes > 0
                            ? absl::StrFormat(" of a %.2f MiB budget", s.memory_budget_bytes / 1048576.0)
                            : std::string());
  absl::StrAppendFormat(&out, "  drawn: %.0f triangles a frame on average (%.3f%% of the scene's %d)\n",
                        s.mean_triangles_drawn,
                        s.scene_triangles > 0 ? 100.0 * s.mean_triangles_drawn / s.scene_triangles : 0.0,
                        s.scene_triangles);
  absl::StrAppendFormat(&out,
                        "  masks: %d received, %d of %d frames masked, %d hole frames; without masks %.0f triangles "
                        "a frame (%.1f%% of it drawn)\n",
                        s.masks_received, s.frames_masked, s.frames, s.hole_frames, s.mean_triangles_without_masks,
                        s.mean_triangles_without_masks > 0
                            ? 100.0 * s.mean_triangles_drawn / s.mean_triangles_without_masks
                            : 0.0);
  if (s.verified) {
    absl::StrAppendFormat(&out, "  pixel error: %d of %d pixels in %d checked frames\n", s.pixel_error,
                          s.checked_pixels, s.checked_frames);
  } else {
    out += "  pixel error: not checked (--verify checks it)\n";
  }
  if (!s.screenshots.empty()) {
    absl::StrAppendFormat(&out, "  %d screenshots in %s\n", s.screenshots.size(),
                          std::filesystem::path(s.screenshots.front()).parent_path().string());
  }
  if (s.cancelled) out += "  stopped early\n";
  return out;
}

}  // namespace vistream::client
