// The walkthrough's start-up (client/walkthrough_loop.h): the session starts, and the loop
// waits for the first viewcell's PVS and geometry (and, following a walk, the next cell it
// enters), drawing the window meanwhile, before the walk's clock starts.

#include <algorithm>
#include <chrono>
#include <thread>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "client/walkthrough_loop.h"
#include "client/window_keys.h"

namespace vistream::client {

absl::Status WalkthroughLoop::Startup() {
  session_start_ = Now();
  if (connection_ != nullptr) connection_->Start();
  Log(absl::StrCat("connected to ", opt_.server, " (scene ", sum_->scene, "); waiting for the first viewcell"));
  uint64_t objects_seen = 0;
  double last_arrival = Now();
  double last_drawn = Now();  // the window's last frame while waiting
  // Following a walk, it waits for the cell it starts in and the first cell the walk enters
  // (what it reaches first), telling the server the velocity it will walk at so that the cells
  // ahead are ranked first; the simulator models the same (simulation/simulator.cpp).
  // (A walk of the server's own is known once SceneInfo has come.)
  auto velocity = [this] { return walk_.has_value() ? walk_->At(0.0).velocity : glm::dvec3(0.0); };
  std::optional<uint32_t> ahead;
  // Drawing everything, no PVS list ever comes: what is preloaded is all there is to wait for.
  bool ahead_known = (!walk_.has_value() && !walk_pending_) || opt_.draw_everything;
  auto ahead_complete = [&] {
    if (!ahead_known && store_->has_scene_info() && !walk_.has_value()) ahead_known = true;
    if (!ahead_known && store_->has_scene_info()) {
      const visibility::ViewcellGrid& g = store_->grid();
      const std::vector<uint32_t> along =
          walk_->CellsAlong(g.cell_size(), [&g](const glm::dvec2& q) { return g.CellAt(q); });
      if (along.size() > 1) ahead = along[1];
      ahead_known = true;
    }
    if (!ahead_known) return false;
    if (!ahead.has_value()) return true;
    const std::vector<uint32_t>* list = store_->Pvs(*ahead);
    return list != nullptr &&
           std::all_of(list->begin(), list->end(), [&](uint32_t id) { return Drawable(*ahead, id); });
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
      // While loading, Esc and Q only close the window (client/window_keys.h).
      for (const WindowInput::KeyPress& k : input_->TakeKeys()) {
        const KeyBinding* b = BindingOfKey(k.key);
        if (b != nullptr && (b->action == WindowAction::kQuit || b->action == WindowAction::kEscape)) input_->Close();
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

}  // namespace vistream::client
