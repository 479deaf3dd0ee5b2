#pragma once
// What one walkthrough is asked to do (client/walkthrough.h RunWalkthrough): the server, the
// walk, the frame, the screenshots and checks, the mode of drawing. Apart from walkthrough.h so
// that the loop's own header (client/walkthrough_loop.h) reads them without including the
// entry point that runs the loop.

#include <atomic>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "client/cell_margins.h"
#include "client/channel_security.h"
#include "scenes/scene.h"

namespace vistream::client {

struct FixedPose {
  glm::dvec3 eye{0.0};  // scene-local metres
  double yaw_rad = 0.0, pitch_rad = 0.0;
};

struct WalkthroughOptions {
  std::string server = "127.0.0.1:50051";
  ChannelSecurity security;     // TLS and the bearer token (client/channel_security.h)
  bool headless = false;
  std::string scene;          // the server's scene to walk (ServerStats.scenes); empty: its only one
  // A walk to follow: the scene's catalog entry's walks, then those the server sends
  // (SceneInfo.paths: the scene's own, derived from its data), a name used by the first not
  // repeated. Empty: the first of them (headless). A walk only the server has is chosen when
  // SceneInfo arrives.
  std::string path;
  double speed_kmh = 0.0;     // 0: the walk's own speed
  double seconds = 0.0;       // stop after this much of the walk; 0: the whole walk
  int width = 1280, height = 720;
  std::string screenshots_dir;  // PNGs every `every_s` seconds of the walk, and of the last frame
  double every_s = 10.0;        // between screenshots and between --verify checks
  bool verify = false;          // compare drawn set and full scene in the object-id buffer
  std::string frame_log;        // a CSV line per frame
  std::string cell_log;         // a CSV line per viewcell entered (client/cell_margins.h)
  std::string catalog_dir;      // empty: the built-in catalog
  std::optional<uint64_t> memory_budget_bytes;  // none: the catalog's client.memory_mb, else unlimited
  std::optional<uint64_t> triangle_budget;      // none: the catalog's client.triangle_budget
  uint64_t upload_budget_bytes = uint64_t{4} << 20;  // GPU uploads per frame
  double max_fps = 60.0;        // 0: as fast as it draws
  bool use_masks = true;        // false: ask for no ε-mask and draw the viewcell PVS whole (a baseline)
  // Levels of detail (issue 45): the screen error tau, pixels, the client accepts (Hello.levels
  // with the frame's size and field of view); 0: every object at full detail. A server without
  // levels sends full detail whatever is asked.
  double lod_tau_px = 1.0;
  // With levels: cluster levels too (LevelRequest.clusters): far groups of objects drawn as one
  // cluster level's pieces where a cell's list chooses them (off by default: they save little).
  bool lod_clusters = false;
  // A baseline: no server geometry; the whole scene (loaded locally, or local_scene) is
  // uploaded before the walk and drawn every frame with frustum culling.
  bool draw_everything = false;
  // The full scene when the caller has it (tests, benchmarks) for --verify and
  // draw_everything; otherwise it is loaded from the catalog. Not owned.
  const scenes::Scene* local_scene = nullptr;
  std::optional<FixedPose> pose;  // stand here instead of walking (screenshots of a pose)
  uint64_t frames = 0;          // with a pose: stop after this many frames; 0: 1 headless
  double startup_timeout_s = 300.0;
  double connect_timeout_s = 10.0;
  double give_up_s = 60.0;      // a server lost this long ends the run (error); 0: never
  const std::atomic<bool>* cancel = nullptr;  // set: the loop ends after the frame
  // Set (SIGUSR1, or F12 in the window): the next frame is written as a PNG into
  // screenshots_dir (else ./vistream-screenshots), and the flag cleared.
  std::atomic<bool>* screenshot_request = nullptr;
  // The overlay (client/overlay.h): the window always has it (F1 statistics, M minimap, both
  // shown at the start); headless, `overlay` draws both into every frame and screenshot.
  bool overlay = false;
  bool window_panels = true;  // the window starts with the panels shown (F1 and M toggle them)
  std::string overlay_dump;   // at the end: the statistics panel's lines of the last frame
  int msaa_samples = -1;      // multisample antialiasing: -1 the default (4 in the window, none headless), 0 none
  bool vsync = true;          // the window waits for the display's refresh
  std::function<void(const std::string&)> log;  // progress lines; may be empty
};

}  // namespace vistream::client
