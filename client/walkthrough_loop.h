#pragma once
// The walkthrough's loop (client/walkthrough.h's RunWalkthrough), inside the client library
// only: one object holding one run's state, its parts in the files named for their ideas:
//   client/walkthrough.cpp         setting up (scene, walks, budgets, GL, logs, connection) and
//                                  ending the run (the summary's counters, logs closed)
//   client/walkthrough_startup.cpp waiting for the first viewcell (and the next on the walk)
//   client/walk_follow.cpp         choosing a walk and following it, from its start or the
//                                  point nearest the eye; the server's walks joining the list
//   client/frame_loop.cpp          the frames: moving the eye, the link, taking what the network
//                                  decoded, the frame rule, drawing, counting, logging
//   client/walkthrough_window.cpp  the window: its key presses (client/window_keys.h), its size,
//                                  the overlay's status and walk list
// Screenshots (client/screenshots.h), --verify (client/verification.h) and the summary
// (client/walkthrough_summary.h) are functions of their own that the loop calls; what a run is
// asked to do is client/walkthrough_options.h.

#include <cstdio>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <absl/status/status.h>
#include <absl/status/statusor.h>
#include <glm/vec3.hpp>

#include "client/cell_margins.h"
#include "client/connection.h"
#include "client/object_store.h"
#include "client/overlay.h"
#include "client/renderer.h"
#include "client/walkthrough_options.h"
#include "client/walkthrough_summary.h"
#include "client/window_input.h"
#include "client/window_keys.h"
#include "gl/gl_context.h"
#include "gl/id_renderer.h"
#include "scenes/catalog.h"
#include "scenes/walk.h"

namespace vistream::client {

// Seconds on a steady clock.
double Now();

// What one step of the loop found: the eye's cell and whether its PVS is ready to draw.
struct Pumped {
  std::optional<uint32_t> cell;
  const std::vector<uint32_t>* pvs = nullptr;
  size_t missing = 0;  // of the PVS list, objects not here and uploaded
  size_t coarse = 0;   // of the PVS list, objects uploaded at a coarser level than it asks
  bool complete = false;
};

class WalkthroughLoop {
 public:
  WalkthroughLoop(const WalkthroughOptions& o, WalkthroughSummary* sum) : opt_(o), sum_(sum) {}
  // Sets up, waits for the first viewcell, walks, and fills the summary (client/walkthrough.cpp).
  absl::Status Run();

 private:
  // --- client/walkthrough.cpp: setting up.
  absl::Status Prepare();
  // draw_everything: the whole local scene as the events the first Pump applies.
  absl::Status PreloadEverything();

  // --- client/walk_follow.cpp.
  // Follows the walk named opt_.path (empty: the first) of walks_; NOT_FOUND listing walks_
  // when there is none such.
  absl::Status ChooseWalk();
  // Follows `path` from its start (`from_here`: from its point nearest the eye); the window's
  // walk list (P) and ChooseWalk.
  absl::Status FollowWalk(const scenes::WalkPath& path, bool from_here);
  // The window without a walk: starts where the first walk starts, if there is one.
  void StartAtFirstWalk();
  // SceneInfo arrived: the server's walks join walks_; a pending walk is chosen.
  absl::Status OnSceneInfo(const v1::SceneInfo& info);

  // --- client/walkthrough_startup.cpp.
  absl::Status Startup();

  // --- client/frame_loop.cpp.
  absl::Status Walkthrough();
  // Takes the network's events into the store and uploads within `upload_budget`.
  // Whether object `id` of `cell`'s list can be drawn: uploaded, or a held cluster the list
  // chose stands for it and is uploaded (drawn as its piece; issue 45).
  bool Drawable(uint32_t cell, uint32_t id) const {
    if (renderer_->Uploaded(id)) return true;
    const auto piece = store_->CoveringCluster(cell, id);
    return piece.has_value() && renderer_->ClusterUploaded(piece->first);
  }
  absl::StatusOr<Pumped> Pump(const glm::dvec3& eye, uint64_t upload_budget);
  // Moves the eye for the frame at `t` (the run's clock, pauses left out): along the walk, at
  // the fixed pose, or by the keys and mouse (`frame_period` seconds since the last frame).
  // Returns the eye's velocity (m/s, for the server); sets *last when the walk or the pose's
  // frames end the run.
  glm::dvec3 MoveEye(double frame_period, double free_speed, bool* last);
  // Whether the server is reachable this frame (`now`: steady clock): logs a loss or a return,
  // and says when the loss has lasted past --give-up (then *gave_up holds the error).
  void WatchLink(double now, absl::Status* gave_up);
  // Logs the first hole frame and the first stall in each cell.
  void ReportHoleAndStall(double t, const Pumped& p, const MaskChoice& choice, bool hole);
  // The window's title: what the frame drew, twice a second.
  void SetTitle(const Pumped& p, const FrameStats& fs, bool masked, bool hole, uint64_t triangles_without,
                double frame_ms);
  // The screenshot of the frame just drawn (t: the walk's clock), listed in the summary.
  absl::Status Screenshot(double t);
  // Compares what was drawn (`mask`: the mask the frame drew, or none) with the full scene.
  absl::Status Verify(const std::vector<DrawnObject>& drawn, const EpsilonMaskSet* mask);
  void SendPose(const glm::dvec3& velocity, double since_start);
  // Which held cells are complete at `t` (walk clock), and the eye's cell.
  void ObserveCells(double t, std::optional<uint32_t> cell, bool stalled);

  // --- client/walkthrough_window.cpp.
  // The window's keys (client/window_keys.h) and resizing; the walk list's choice.
  absl::Status HandleWindow();
  // The overlay's status for this frame (counters as they stand after it).
  OverlayStatus Status(const Pumped& p, const FrameStats& fs, const EpsilonMaskSet* mask, bool hole,
                       uint64_t triangles_without, double now) const;
  // Draws the overlay over the frame just drawn and acts on what its walk list asked.
  absl::Status DrawOverlay(const OverlayStatus& status, double dt);
  // A key pressed (or a character typed) for `action`; the walk list's keys while it is shown.
  void Press(WindowAction action);
  absl::Status PressInWalkList(WalkListAction action);
  // Follows walks_[index] chosen in the window (the walk list's keys or buttons); none past
  // the list's end.
  absl::Status FollowChosenWalk(size_t index, bool from_here);

  void Log(const std::string& line) const {
    if (opt_.log) opt_.log(line);
  }
  bool Cancelled() const { return opt_.cancel != nullptr && opt_.cancel->load(); }

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
  double lost_at_ = 0.0;      // when the link last went down or came back (steady clock)
  bool link_up_ = true, gave_up_flag_ = false;
  uint64_t reconnected_ = 0;  // the connection came back (the Connection counts a session when it ends)
  std::optional<uint32_t> stalled_in_;  // the cell a stall was last reported for
  std::optional<uint32_t> holed_in_;    // the cell a hole frame was last reported for
  double last_title_ = 0.0;             // when the window's title was last set (steady clock)
};

}  // namespace vistream::client
