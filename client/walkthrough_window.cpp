// The walkthrough's window (client/walkthrough_loop.h): its size, its key presses as the key
// table says (client/window_keys.h), the overlay's status and the walk list's choice.

#include <algorithm>

#include <absl/strings/str_format.h>

#include "client/walkthrough_loop.h"
#include "client/window_keys.h"

namespace vistream::client {

absl::Status WalkthroughLoop::HandleWindow() {
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
  const std::vector<unsigned> chars = input_->TakeChars();
  const std::vector<WindowInput::KeyPress> keys = input_->TakeKeys();
  // A key may change what a panel says (the walk list's row, the speed): rebuilt this frame.
  if (!chars.empty() || !keys.empty()) overlay_->Invalidate();
  for (unsigned c : chars) {
    if (const KeyBinding* b = BindingOfChar(c)) Press(b->action);
  }
  for (const WindowInput::KeyPress& k : keys) {
    // The walk list, while shown, takes its own keys.
    if (const WalkListBinding* w = overlay_->show_walks ? WalkListBindingOfKey(k.key) : nullptr) {
      if (absl::Status st = PressInWalkList(w->action); !st.ok()) return st;
      continue;
    }
    const KeyBinding* b = BindingOfKey(k.key);
    if (b == nullptr) continue;
    if (IsMovement(b->action) && walk_.has_value()) {
      // Walking leaves the walk followed: free walking from where the eye is.
      Log(absl::StrFormat("left the walk '%s': walking freely", sum_->path));
      walk_.reset();
      paused_ = false;
      continue;
    }
    Press(b->action);
  }
  return absl::OkStatus();
}

void WalkthroughLoop::Press(WindowAction action) {
  switch (action) {
    case WindowAction::kStats: overlay_->show_stats = !overlay_->show_stats; break;
    case WindowAction::kMinimap: overlay_->show_minimap = !overlay_->show_minimap; break;
    case WindowAction::kHelp: overlay_->show_help = !overlay_->show_help; break;
    case WindowAction::kWalkList: overlay_->show_walks = !overlay_->show_walks; break;
    case WindowAction::kPause:
      if (walk_.has_value()) {
        paused_ = !paused_;
        Log(paused_ ? "walk paused" : "walk resumed");
      }
      break;
    case WindowAction::kFaster: rate_ = std::min(rate_ * 1.25, 64.0); break;
    case WindowAction::kSlower: rate_ = std::max(rate_ / 1.25, 1.0 / 64.0); break;
    case WindowAction::kRestart:
      if (walk_.has_value()) {
        walk_t_ = 0.0;
      } else {
        camera_.eye = start_pose_.eye;
        camera_.yaw_rad = start_pose_.yaw_rad;
        camera_.pitch_rad = start_pose_.pitch_rad;
      }
      break;
    case WindowAction::kFullScreen: input_->ToggleFullScreen(); break;
    case WindowAction::kScreenshot: screenshot_now_ = true; break;
    case WindowAction::kQuit: input_->Close(); break;
    case WindowAction::kEscape:
      if (overlay_->show_help) {
        overlay_->show_help = false;
      } else {
        input_->Escape();
      }
      break;
    default: break;  // held keys (WindowInput::Update) and the mouse
  }
}

absl::Status WalkthroughLoop::PressInWalkList(WalkListAction action) {
  size_t& sel = overlay_->walk_selected();
  switch (action) {
    case WalkListAction::kUp:
      if (sel > 0) --sel;
      return absl::OkStatus();
    case WalkListAction::kDown:
      if (sel + 1 < walks_.size()) ++sel;
      return absl::OkStatus();
    case WalkListAction::kFollowFromStart:
    case WalkListAction::kFollowFromHere:
      if (absl::Status st = FollowChosenWalk(sel, action == WalkListAction::kFollowFromHere); !st.ok()) return st;
      break;
    case WalkListAction::kClose: break;
  }
  overlay_->show_walks = false;
  return absl::OkStatus();
}

absl::Status WalkthroughLoop::FollowChosenWalk(size_t index, bool from_here) {
  if (index >= walks_.size()) return absl::OkStatus();
  const scenes::WalkPath chosen = walks_[index];
  if (absl::Status st = FollowWalk(chosen, from_here); !st.ok()) return st;
  walk_ends_run_ = false;
  Log(absl::StrFormat("following the walk '%s' from %s", chosen.name, from_here ? "here" : "its start"));
  return absl::OkStatus();
}

OverlayStatus WalkthroughLoop::Status(const Pumped& p, const FrameStats& fs, const EpsilonMaskSet* mask, bool hole,
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
    st.level_objects = c.level_objects;
    st.level_bytes_saved = c.level_bytes_saved;
    st.backoff_s = c.backoff_s;
    st.link = link_up_ ? OverlayStatus::Link::kConnected
              : gave_up_flag_ ? OverlayStatus::Link::kGivenUp
                              : OverlayStatus::Link::kReconnecting;
    st.lost_for_s = link_up_ ? 0.0 : now - lost_at_;
  }
  st.give_up_s = opt_.give_up_s;
  st.cell = p.cell;
  if (p.cell.has_value()) {
    const visibility::CellCoord c = store_->grid().Coord(*p.cell);
    st.cell_i = c.i;
    st.cell_j = c.j;
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
  st.lod_tau_px = opt_.lod_tau_px;
  st.server_without_levels = store_->has_scene_info() && !store_->scene_info().levels();
  st.coarse_frames = sum_->coarse_frames + (p.complete && p.coarse > 0 ? 1 : 0);
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

absl::Status WalkthroughLoop::DrawOverlay(const OverlayStatus& status, double dt) {
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
  if (req.follow_walk.has_value()) return FollowChosenWalk(*req.follow_walk, !req.from_start);
  return absl::OkStatus();
}

}  // namespace vistream::client
