#include "client/walkthrough.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>

#include <absl/strings/str_cat.h>

#include "client/screenshots.h"
#include "client/walk_follow.h"
#include "client/walkthrough_loop.h"
#include "proto/scene_info.h"
#include "scenes/geometry_codec.h"
#include "visibility/viewcell_grid.h"

namespace vistream::client {

double Now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

absl::Status WalkthroughLoop::Prepare() {
  absl::StatusOr<v1::ServerStats> stats = Probe(opt_.server, opt_.connect_timeout_s, opt_.cancel, opt_.security);
  if (!stats.ok()) return stats.status();
  absl::StatusOr<std::string> scene = PickScene(*stats, opt_.scene, opt_.server);
  if (!scene.ok()) return scene.status();
  sum_->scene = *scene;
  // A scene the server loaded from a glTF file has no catalog entry: its walks are the file's,
  // which the server sends (SceneInfo.paths).
  const bool gltf = scenes::IsGltfPath(sum_->scene);
  absl::StatusOr<scenes::CatalogEntry> entry =
      gltf ? absl::StatusOr<scenes::CatalogEntry>(absl::NotFoundError("a glTF file, not a catalog entry"))
           : scenes::FindCatalogEntry(sum_->scene, opt_.catalog_dir);
  if (entry.ok()) entry_ = std::move(*entry);

  // The walks: the catalog entry's now; the server's own (SceneInfo.paths) join them when
  // SceneInfo arrives. A walk the catalog has is chosen now, any other then (ChooseWalk).
  if (entry_.has_value()) {
    walks_ = entry_->walks;
  } else {
    catalog_status_ = entry.status();
    Log(gltf ? absl::StrCat("the server's scene is the glTF file '", sum_->scene,
                            "': walks from the file (the server sends them), no client budgets or effects from the "
                            "catalog")
             : absl::StrCat("no scene catalog entry for '", sum_->scene, "' (", catalog_status_.message(),
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
  sum_->lod_tau_px = opt_.lod_tau_px;
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
    absl::StatusOr<scenes::Walk> walk = MakeWalk(*walk_path_, walk_->speed_mps(), full_scene_);
    if (!walk.ok()) return walk.status();
    walk_ = std::move(*walk);
    camera_.eye = walk_->At(0.0).eye;
  }
  if (opt_.verify) {
    // With the scene's own levels, if it has them; a server that made its own at start gets
    // them made here when its first level is drawn (WalkthroughLoop::Verify).
    absl::StatusOr<std::unique_ptr<gl::IdRenderer>> ids =
        gl::IdRenderer::Create(*full_scene_, 1, /*levels=*/!full_scene_->levels.empty());
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
    if (absl::Status st = CreateScreenshotDir(opt_.screenshots_dir); !st.ok()) return st;
  }

  ConnectionOptions co;
  co.address = opt_.server;
  co.scene = sum_->scene;
  co.memory_budget_bytes = memory_budget_;
  co.triangle_budget = triangle_budget_;
  co.connect_timeout_s = opt_.connect_timeout_s;
  co.security = opt_.security;
  co.epsilon_masks = opt_.use_masks;
  co.screen_error_px = opt_.lod_tau_px;
  co.clusters = opt_.lod_clusters;
  co.viewport_width_px = static_cast<uint32_t>(width);
  co.viewport_height_px = static_cast<uint32_t>(height);
  co.vertical_fov_rad = camera_.fov_y_rad;
  store_ = std::make_unique<ObjectStore>(memory_budget_);
  if (opt_.draw_everything) return PreloadEverything();
  connection_ = std::make_unique<Connection>(co);
  return absl::OkStatus();
}

absl::Status WalkthroughLoop::PreloadEverything() {
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
    r.raw_bytes = scenes::RawMeshBytes(o.mesh.positions.size(), o.mesh.indices.size());
    events.emplace_back(std::move(r));
    everything_.push_back(o.id);
  }
  preload_ = std::move(events);
  return absl::OkStatus();
}

absl::Status WalkthroughLoop::Run() {
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
    sum_->level_objects_received = c.level_objects;
    sum_->level_bytes_saved = c.level_bytes_saved;
    sum_->cluster_levels_received = c.cluster_levels;
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

absl::Status RunWalkthrough(const WalkthroughOptions& options, WalkthroughSummary* summary) {
  *summary = WalkthroughSummary{};
  summary->server = options.server;
  WalkthroughLoop loop(options, summary);
  return loop.Run();
}

absl::StatusOr<WalkthroughSummary> RunWalkthrough(const WalkthroughOptions& options) {
  WalkthroughSummary summary;
  if (absl::Status s = RunWalkthrough(options, &summary); !s.ok()) return s;
  return summary;
}

}  // namespace vistream::client
