#pragma once
// The client's on-screen overlay (Dear ImGui): a statistics panel (F1), a minimap of the
// viewcell grid (M, client/minimap.h), the key list (H or ?, from the window's key table:
// client/window_keys.h) and the list of the scene's walks (P). The same
// overlay draws into the window and, for `--overlay`, into the headless client's off-screen
// frames: ImGui builds the panels, and they are drawn through the context's GL function table
// (gl/gl_functions.h), so that an OSMesa frame gets them as a window does. (Debian's ImGui
// OpenGL 3 back end loads its GL from libGL.so.1, GLX's, which cannot draw into an OSMesa
// context: its ~100 lines of drawing are done through the table instead, in
// client/overlay_painter.h. The GLFW back end, keyboard and mouse for the window, is Debian's.)

#include <array>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "client/minimap.h"
#include "client/object_store.h"
#include "gl/gl_context.h"

namespace vistream::client {

// What the client knows this frame, as the overlay shows it (all filled by the walkthrough
// loop; units in the names).
struct OverlayStatus {
  std::string server, scene;
  enum class Link { kConnected, kReconnecting, kGivenUp, kLocal } link = Link::kConnected;
  double lost_for_s = 0.0;         // kReconnecting: since the connection dropped
  double give_up_s = 0.0;          // the client gives up after this long without the server; 0 never
  double backoff_s = 0.0;          // kReconnecting: the wait before the latest attempt
  uint64_t reconnects = 0;
  double starting_s = -1.0;        // >= 0: the window has waited this long for the first viewcell
  double startup_timeout_s = 0.0;  // starting: the client gives up after this long
  std::optional<uint32_t> cell;    // the eye's viewcell id; none outside the grid or before SceneInfo
  int cell_i = -1, cell_j = -1;
  size_t pvs_objects = 0;          // its PVS list's length (0: not arrived)
  bool pvs_listed = false, pvs_complete = false;
  size_t pvs_missing = 0;          // of the list, objects not here and uploaded
  size_t held_objects = 0;
  uint64_t held_bytes = 0, memory_budget_bytes = 0;  // budget 0: none
  uint64_t bytes_received = 0;     // since the start (the overlay derives the rate)
  uint64_t frames = 0, stalls = 0, hole_frames = 0, frames_masked = 0;
  // Levels of detail (issue 45): the screen error asked for (0: off), frames drawing a coarser
  // level than the cell asks, objects received at a level and the bytes those levels saved.
  double lod_tau_px = 0.0;
  uint64_t coarse_frames = 0, level_objects = 0, level_bytes_saved = 0;
  bool server_without_levels = false;  // levels asked for, the server has none (SceneInfo.levels false)
  double stall_s = 0.0;
  bool masked = false, hole = false;  // what this frame drew
  uint32_t mask_id = 0;               // masked: the server's id of the ε-mask drawn
  glm::dvec3 mask_box_min{0.0}, mask_box_max{0.0};  // masked: its neighbourhood, scene-local m
  uint64_t masks_received = 0;
  uint64_t triangles_drawn = 0, triangles_without_masks = 0, scene_triangles = 0;
  glm::dvec3 eye{0.0};
  double yaw_rad = 0.0;
  // The walk followed: its name, where on it, paused, the speed (km/h, after +/-).
  std::string walk;
  double walk_t_s = 0.0, walk_duration_s = 0.0, speed_kmh = 0.0;
  bool walk_paused = false;
};

// What the user asked for through the overlay's walk list this frame.
struct OverlayRequest {
  std::optional<size_t> follow_walk;  // index into the names given to Frame
  bool from_start = true;             // else from the walk's point nearest the eye
};

class Overlay {
 public:
  // `window`: the GLFWwindow of gl::GlContext::window() (its keyboard and mouse reach the
  // panels), or null off-screen. `context` current. Errors: GL failing (shaders, the font).
  static absl::StatusOr<std::unique_ptr<Overlay>> Create(gl::GlContext* context, void* window);
  ~Overlay();
  Overlay(const Overlay&) = delete;
  Overlay& operator=(const Overlay&) = delete;

  // Records a frame's time for the frame-time graph (the last kHistoryS seconds) and the
  // byte rate. `now_s`: a steady clock.
  void AddFrame(double frame_ms, double now_s, uint64_t bytes_received);
  // Draws the panels over the frame just drawn (into the framebuffer bound: the window's or the
  // renderer's off-screen one, resolved: Renderer::Resolve), `width` x `height` pixels; `dt_s`
  // since the last call. The panels are opaque; they are built (ImGui) and drawn into a texture
  // kRebuildS apart, and at once when Invalidate was called, a panel was shown or hidden, the
  // size changed or the mouse is over a panel; every frame copies their rectangles from that
  // texture (a CPU rasteriser pays for ImGui's thousands of small triangles 1 frame in 12 at
  // 60 Hz, and blends nothing). Into a multisample framebuffer they are drawn each frame
  // instead. `walks`: the names for the walk list. Returns what the walk list asked for.
  // Errors (INTERNAL): GL failing.
  absl::StatusOr<OverlayRequest> Frame(const OverlayStatus& status, const MinimapView& map,
                                       const std::vector<std::string>& walks, int width, int height, double dt_s);
  // The next Frame rebuilds the panels (a key was pressed; a screenshot will be taken).
  void Invalidate();

  bool show_stats = true;    // F1
  bool show_minimap = true;  // M
  bool show_help = false;    // H or ?
  bool show_walks = false;   // P
  // Whether the mouse is over a panel (its click is the panel's, not the start of mouse look).
  bool WantsMouse() const;
  // The walk list's highlighted row (the loop's Up/Down move it; Enter and F follow it).
  size_t& walk_selected();
  // The statistics panel's lines of the last Frame (made whether it is shown or not).
  const std::vector<std::string>& last_lines() const;

  static constexpr double kHistoryS = 5.0;
  static constexpr double kRebuildS = 0.2;  // the panels' numbers change 5 times a second
  // The panels' places (pixels from the top left; tests look there): the statistics at the top
  // left, the minimap at the top right, kMinimapPx square (smaller where the frame is too narrow
  // for both: down to kMinimapMinPx).
  static constexpr int kMargin = 10;
  static constexpr int kStatsWidth = 400;
  static constexpr int kMinimapPx = 260;
  static constexpr int kMinimapMinPx = 120;  // in a frame too narrow for both panels side by side

 private:
  struct Impl;
  explicit Overlay(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The statistics panel's lines, as drawn (tests compare them with the run's summary): `fps`
// over the last second, `frame_ms` the last frame's time, `bytes_per_s` over the last second.
std::vector<std::string> OverlayLines(const OverlayStatus& status, double fps, double frame_ms, double bytes_per_s);

}  // namespace vistream::client
