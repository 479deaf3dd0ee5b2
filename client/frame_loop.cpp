// The walkthrough's frames (client/walkthrough_loop.h; the frame rule: client/walkthrough.h).
// Each frame moves the eye, tells the server, takes what the network thread decoded (Pump),
// draws the ε-mask, the viewcell PVS or what is held, and counts, logs and checks it.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <thread>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <glm/geometric.hpp>

#include "client/cell_completion.h"
#include "client/screenshots.h"
#include "client/verification.h"
#include "client/walkthrough_loop.h"
#include "scenes/cluster_triangles.h"
#include "scenes/levels.h"

namespace vistream::client {

absl::Status WalkthroughLoop::Walkthrough() {
  const double t0 = Now();
  margins_.Shift(session_start_ - t0);
  double paused = 0.0, next_shot = 0.0, next_check = 0.0, prev_end = Now();
  double prev_begin = Now();  // free walking moves by the frame period (not the idle gap after a frame)
  int next_progress = 1;
  FrameTally tally;
  glm::dvec3 prev_eye = camera_.eye;
  const double free_speed = !walks_.empty() ? walks_.front().speed_mps : 1.4;
  std::vector<DrawnObject> drawn;
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
    const glm::dvec3 velocity = MoveEye(frame_period, free_speed, &last);
    SendPose(velocity, begin - session_start_);
    WatchLink(begin, &gave_up);
    if (gave_up_flag_ && input_ == nullptr) break;
    absl::StatusOr<Pumped> p = Pump(camera_.eye, opt_.upload_budget_bytes);
    if (!p.ok()) return p.status();
    ObserveCells(t, p->cell, !p->complete);
    // The frame rule: the eye's mask once all its objects are here (a masked frame); else the
    // viewcell's PVS once complete; else what is held (a hole frame).
    MaskChoice choice;
    if (opt_.use_masks && !opt_.draw_everything) {
      choice = store_->ChooseMask(camera_.eye, [this](uint32_t id) { return renderer_->Uploaded(id); },
                                  [this](uint32_t c) { return renderer_->ClusterUploaded(c); });
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
    // Objects a cluster the list chose stands for are drawn as its pieces (the mask's cell's list,
    // or the complete cell's).
    const std::optional<uint32_t> list_cell =
        use_mask != nullptr ? std::optional<uint32_t>(use_mask->cell) : p->complete ? p->cell : std::nullopt;
    const FrameStats fs =
        renderer_->Draw(*store_, camera_, *set, use_mask, sum_->frames + 1, check ? &drawn : nullptr, list_cell);
    // What the PVS alone would have drawn (counted, not drawn).
    const uint64_t triangles_without_masks =
        use_mask != nullptr
            ? renderer_->CountTriangles(*store_, camera_, *without_masks, p->complete ? p->cell : std::nullopt)
            : fs.triangles_drawn;
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
    tally.frame_ms.push_back((end - begin) * 1000.0);
    ReportHoleAndStall(t, *p, choice, hole);
    if (hole) ++sum_->hole_frames;
    if (!p->complete) {
      ++sum_->stalls;
      sum_->stall_s += end - prev_end;
    } else if (p->coarse > 0) {
      ++sum_->coarse_frames;
    }
    prev_end = end;
    tally.triangles += fs.triangles_drawn;
    tally.triangles_without_masks += triangles_without_masks;
    tally.objects += fs.objects_drawn;
    sum_->max_triangles_drawn = std::max(sum_->max_triangles_drawn, fs.triangles_drawn);
    if (memory_budget_ != 0 && store_->held_bytes() > memory_budget_) ++sum_->frames_over_memory_budget;
    if (triangle_budget_ != 0 && fs.triangles_drawn > triangle_budget_) ++sum_->frames_over_triangle_budget;
    if (fs.mask_used) ++sum_->frames_masked;
    if (p->cell.has_value()) tally.cells.insert(*p->cell);
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
                   fs.objects_drawn, static_cast<unsigned long long>(fs.triangles_drawn), tally.frame_ms.back(),
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
      if (end - last_title_ > 0.5) {
        SetTitle(*p, fs, use_mask != nullptr, hole, triangles_without_masks, tally.frame_ms.back());
        last_title_ = end;
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
  tally.Fill(walked, sum_);
  return gave_up;
}

glm::dvec3 WalkthroughLoop::MoveEye(double frame_period, double free_speed, bool* last) {
  glm::dvec3 velocity(0.0);
  if (walk_.has_value()) {
    walk_t_ = std::min(walk_t_, walk_limit_s_);
    const double at = walk_t_;
    *last = *last || (walk_ends_run_ && walk_t_ >= walk_limit_s_);
    const scenes::WalkPose pose = walk_->At(at);
    camera_.eye = pose.eye;
    if (store_->has_scene_info() && store_->grid().has_bands()) {
      // Cells follow terrain this client may not hold: the eye stays in its cell's band, where
      // the server accepts it and the PVSs hold.
      const visibility::ViewcellGrid& g = store_->grid();
      if (const std::optional<uint32_t> c = g.CellAt({camera_.eye.x, camera_.eye.y})) {
        camera_.eye.z = std::clamp(camera_.eye.z, g.Band(*c).z0, g.Band(*c).z1);
      }
    }
    camera_.yaw_rad = pose.yaw_rad;
    velocity = *last || paused_ || walk_t_ >= walk_limit_s_ ? glm::dvec3(0.0) : pose.velocity * rate_;
  } else if (opt_.pose.has_value()) {
    const uint64_t frames = opt_.frames > 0 ? opt_.frames : (opt_.headless ? 1 : ~uint64_t{0});
    *last = *last || sum_->frames + 1 >= frames;
  } else if (input_ != nullptr) {
    const double dt = std::clamp(frame_period, 1e-3, 0.1);
    glm::dvec3 eye = camera_.eye;
    input_->Update(dt, free_speed * rate_, &eye, &camera_.yaw_rad, &camera_.pitch_rad, overlay_->WantsMouse());
    // The PVSs hold inside the grid: the eye stays in it.
    const visibility::ViewcellGrid& g = store_->grid();
    eye.x = std::clamp(eye.x, g.corner().x + 0.01, g.corner().x + g.nx() * g.cell_size() - 0.01);
    eye.y = std::clamp(eye.y, g.corner().y + 0.01, g.corner().y + g.ny() * g.cell_size() - 0.01);
    // ...and in its cell's band (where cells follow terrain, the band moves with the ground).
    if (const std::optional<uint32_t> c = g.CellAt({eye.x, eye.y}); c.has_value() && g.has_bands()) {
      eye.z = std::clamp(eye.z, g.Band(*c).z0, g.Band(*c).z1);
    }
    velocity = (eye - camera_.eye) / dt;
    camera_.eye = eye;
  }
  return velocity;
}

void WalkthroughLoop::WatchLink(double now, absl::Status* gave_up) {
  if (connection_ != nullptr && connection_->connected() != link_up_) {
    link_up_ = !link_up_;
    lost_at_ = now;
    if (link_up_) ++reconnected_;
    Log(link_up_ ? absl::StrFormat("reconnected to %s", opt_.server)
                 : absl::StrFormat("lost the server at %s; reconnecting (drawing what is held)", opt_.server));
  }
  const bool gave_up_before = gave_up_flag_;
  gave_up_flag_ = !link_up_ && opt_.give_up_s > 0.0 && now - lost_at_ > opt_.give_up_s;
  if (gave_up_flag_ && !gave_up_before && input_ != nullptr) {
    Log(absl::StrFormat("gave up on the server at %s after %.0f s; the window stays open on what it holds",
                        opt_.server, opt_.give_up_s));
  }
  if (gave_up_flag_) {
    // The summary of what was walked is still made (and printed), then the error. The
    // window stays open, saying so, until it is closed (or the server comes back).
    *gave_up = absl::UnavailableError(
        absl::StrFormat("lost the server at %s: no answer for %.0f s", opt_.server, opt_.give_up_s));
  } else if (link_up_) {
    *gave_up = absl::OkStatus();
  }
}

void WalkthroughLoop::ReportHoleAndStall(double t, const Pumped& p, const MaskChoice& choice, bool hole) {
  if (hole && p.cell != holed_in_ && p.cell.has_value()) {
    holed_in_ = p.cell;
    Log(absl::StrFormat("hole frame at %.0f s: %s", t,
                        !opt_.use_masks ? "its viewcell's PVS is incomplete (no ε-masks asked for)"
                        : choice.in_box ? "the eye's masks lack objects and its viewcell's PVS is incomplete"
                                        : "the eye is in no mask's box and its viewcell's PVS is incomplete"));
  }
  if (!p.complete && p.cell != stalled_in_ && p.cell.has_value()) {
    stalled_in_ = p.cell;
    size_t missing = 0;
    if (p.pvs != nullptr) missing = MissingObjects(*p.pvs, [&](uint32_t id) { return store_->Find(id) != nullptr; });
    const visibility::CellCoord c = store_->grid().Coord(*p.cell);
    Log(absl::StrFormat(
        "stall in viewcell %d,%d at %.0f s: %s; holding %.1f MiB%s", c.i, c.j, t,
        p.pvs == nullptr ? std::string("its PVS list has not arrived")
                         : absl::StrFormat("%d of its %d objects have not arrived", missing, p.pvs->size()),
        store_->held_bytes() / 1048576.0,
        memory_budget_ > 0 ? absl::StrFormat(" of a %.1f MiB budget", memory_budget_ / 1048576.0) : ""));
  }
}

void WalkthroughLoop::SetTitle(const Pumped& p, const FrameStats& fs, bool masked, bool hole,
                               uint64_t triangles_without, double frame_ms) {
  const double fps = 1000.0 / std::max(1e-3, frame_ms);
  std::string cell = "-";
  if (p.cell.has_value()) {
    const visibility::CellCoord c = store_->grid().Coord(*p.cell);
    cell = absl::StrCat(c.i, ",", c.j);
  }
  input_->SetTitle(absl::StrFormat(
      "vistream %s | %.0f fps | cell %s | %s | PVS %d | held %d objects, %.1f MB | drawn %d tris (PVS %d) | "
      "stalls %d, holes %d",
      sum_->scene, fps, cell, masked ? "masked" : hole ? "HOLE" : "PVS", p.pvs != nullptr ? p.pvs->size() : 0,
      store_->objects().size(), store_->held_bytes() / 1e6, fs.triangles_drawn, triangles_without, sum_->stalls,
      sum_->hole_frames));
}

absl::Status WalkthroughLoop::Screenshot(double t) {
  absl::StatusOr<std::string> path = WriteScreenshot(*renderer_, opt_.screenshots_dir, sum_->frames, t);
  if (!path.ok()) return path.status();
  sum_->screenshots.push_back(*path);
  return absl::OkStatus();
}

absl::Status WalkthroughLoop::Verify(const std::vector<DrawnObject>& drawn, const EpsilonMaskSet* mask) {
  if (!ids_->has_levels() &&
      std::any_of(drawn.begin(), drawn.end(),
                  [](const DrawnObject& d) { return d.level > 0 || d.cluster.has_value(); })) {
    // The server sends levels it made at start: the check makes the same ones here, once.
    if (full_scene_->levels.empty()) {
      Log(absl::StrCat("--verify: making the levels of detail of '", sum_->scene, "' as a server does"));
      absl::StatusOr<scenes::SceneLevels> made = scenes::MakeLevels(*full_scene_, scenes::SessionLevelOptions());
      if (!made.ok()) return made.status();
      if (!owned_scene_.has_value()) owned_scene_ = *full_scene_;  // the caller's scene is not ours to change
      owned_scene_->levels = *std::move(made);
      full_scene_ = &*owned_scene_;
    } else if (!full_scene_->levels.clusters.empty()) {
      // Levels from a file made before cluster levels kept each object's triangles in one run:
      // grouped as a server groups them.
      scenes::SceneLevels grouped = full_scene_->levels;
      scenes::GroupClusterTriangles(*full_scene_, &grouped);
      bool changed = false;
      for (size_t c = 0; c < grouped.clusters.size() && !changed; ++c) {
        for (size_t k = 0; k < grouped.clusters[c].levels.size(); ++k) {
          const scenes::Mesh& before = full_scene_->levels.clusters[c].levels[k].mesh;
          changed = changed || grouped.clusters[c].levels[k].mesh.indices != before.indices;
        }
      }
      if (changed) {
        if (!owned_scene_.has_value()) owned_scene_ = *full_scene_;
        owned_scene_->levels = std::move(grouped);
        full_scene_ = &*owned_scene_;
      }
    }
    ids_.reset();
    absl::StatusOr<std::unique_ptr<gl::IdRenderer>> ids = gl::IdRenderer::Create(*full_scene_, 1, /*levels=*/true);
    if (!ids.ok()) return ids.status();
    ids_ = std::move(*ids);
  }
  // A level drawn is the local scene's level only if the server made the same: the triangle
  // counts must agree (a server's levels made with other options would make the check wrong).
  for (const DrawnObject& d : drawn) {
    if (d.cluster.has_value()) {
      const StoredCluster* held = store_->FindCluster(*d.cluster);
      const auto& clusters = full_scene_->levels.clusters;
      if (held == nullptr || *d.cluster >= clusters.size() || d.level > clusters[*d.cluster].levels.size()) continue;
      const size_t local = clusters[*d.cluster].levels[d.level - 1].mesh.TriangleCount();
      if (held->data.mesh.TriangleCount() != local || held->data.objects != clusters[*d.cluster].objects) {
        return absl::FailedPreconditionError(absl::StrFormat(
            "--verify: cluster %d's level %d has %d triangles from the server and %d in the local scene: the server "
            "made its levels otherwise (check with --lod-clusters off, or give the client the server's scene file)",
            *d.cluster, d.level, held->data.mesh.TriangleCount(), local));
      }
      continue;
    }
    const StoredObject* o = d.level > 0 ? store_->Find(d.id) : nullptr;
    if (o == nullptr || o->data.level != d.level || d.id >= full_scene_->levels.objects.size() ||
        d.level > full_scene_->levels.objects[d.id].size()) {
      continue;  // CompareWithFullScene says what is missing
    }
    const size_t local = full_scene_->levels.objects[d.id][d.level - 1].mesh.TriangleCount();
    if (o->data.mesh.TriangleCount() != local) {
      return absl::FailedPreconditionError(absl::StrFormat(
          "--verify: object %d's level %d has %d triangles from the server and %d in the local scene: the server "
          "made its levels otherwise (check with --lod off, or give the client the server's scene file)",
          d.id, d.level, o->data.mesh.TriangleCount(), local));
    }
  }
  absl::StatusOr<PixelComparison> c = CompareWithFullScene(*ids_, *full_scene_, camera_, drawn, mask);
  if (!c.ok()) return c.status();
  sum_->pixel_error += c->differ;
  sum_->checked_pixels += c->pixels;
  ++sum_->checked_frames;
  sum_->max_silhouette_px = std::max(sum_->max_silhouette_px, c->max_silhouette_px);
  if (c->differ > 0) {
    Log(absl::StrFormat("verify: %d pixels differ at (%.1f, %.1f), the farthest %.1f px from a full-detail silhouette",
                        c->differ, camera_.eye.x, camera_.eye.y, c->max_silhouette_px));
  }
  return context_->MakeCurrent();
}

void WalkthroughLoop::SendPose(const glm::dvec3& velocity, double since_start) {
  if (connection_ == nullptr) return;
  connection_->SetPose(camera_.eye, velocity, camera_.yaw_rad, camera_.pitch_rad, since_start);
}

void WalkthroughLoop::ObserveCells(double t, std::optional<uint32_t> cell, bool stalled) {
  if (connection_ == nullptr || !store_->has_scene_info()) return;
  margins_.Observe(t, store_->pvs_lists(), [this](uint32_t id) { return renderer_->Uploaded(id); }, cell,
                   store_->grid().nx(), stalled);
}

absl::StatusOr<Pumped> WalkthroughLoop::Pump(const glm::dvec3& eye, uint64_t upload_budget) {
  std::vector<Event> events = connection_ != nullptr ? connection_->Take() : std::move(preload_);
  preload_.clear();
  for (const Event& e : events) {
    if (std::holds_alternative<v1::EpsilonMask>(e)) ++masks_seen_;
  }
  Pumped p;
  if (store_->has_scene_info()) p.cell = store_->grid().CellAt({eye.x, eye.y});
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
    sum_->server_levels = info.levels();
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
      const visibility::ViewcellGrid& g = store_->grid();
      camera_.eye = {g.corner().x + 0.5 * g.nx() * g.cell_size(), g.corner().y + 0.5 * g.ny() * g.cell_size(),
                     g.base_z() + 0.6 * g.height()};
      if (g.has_bands()) {
        // Cells follow terrain: 0.6 of the band's height above the cell's highest ground.
        if (const std::optional<uint32_t> c = g.CellAt({camera_.eye.x, camera_.eye.y})) {
          camera_.eye.z = g.Band(*c).z1 - 0.4 * g.height();
        }
      }
      have_start_ = true;
    }
    p.cell = store_->grid().CellAt({eye.x, eye.y});
  }
  if (p.cell.has_value()) p.pvs = store_->Pvs(*p.cell);
  static const std::vector<uint32_t> kNone;
  renderer_->Sync(*store_, p.pvs != nullptr ? *p.pvs : kNone, upload_budget);
  if (p.pvs != nullptr) {
    p.missing = MissingObjects(*p.pvs, [&](uint32_t id) { return Drawable(*p.cell, id); });
  }
  p.complete = opt_.draw_everything ? renderer_->pending_uploads() == 0 : p.pvs != nullptr && p.missing == 0;
  if (const std::vector<uint32_t>* levels = p.cell.has_value() ? store_->PvsLevels(*p.cell) : nullptr;
      p.pvs != nullptr && levels != nullptr) {
    p.coarse = CoarseObjects(*p.pvs, *levels, [&](uint32_t id) { return renderer_->UploadedLevel(id); });
    // An object drawn as a cluster's piece is coarse where the cluster is held coarser than the
    // list asks (and it is not held at its own level or finer).
    if (const auto* chosen = store_->PvsClusters(*p.cell)) {
      for (size_t k = 0; k < p.pvs->size() && k < levels->size(); ++k) {
        const uint32_t id = (*p.pvs)[k];
        const auto piece = store_->CoveringCluster(*p.cell, id);
        if (!piece.has_value() || !renderer_->ClusterUploaded(piece->first)) continue;
        const auto own = renderer_->UploadedLevel(id);
        const bool own_coarse = own.has_value() && *own > (*levels)[k];
        const auto at = std::lower_bound(chosen->begin(), chosen->end(), std::pair{piece->first, uint32_t{0}});
        const bool piece_coarse = store_->FindCluster(piece->first)->data.level > at->second;
        if (own_coarse && !piece_coarse) --p.coarse;  // the piece is drawn, fine enough
        if (!own.has_value() && piece_coarse) ++p.coarse;
        if (own.has_value() && !own_coarse && piece_coarse) ++p.coarse;  // the piece is drawn
      }
    }
  }
  return p;
}

}  // namespace vistream::client
