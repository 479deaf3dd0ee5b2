#pragma once
// The summary of one walkthrough (client/walkthrough.h): what was walked, drawn, received and
// checked, as JSON for scripts (`vistream-client --json`, `vistream bench client`) and as lines
// for people; and the tally of frames from which the frame loop makes its means and percentiles.

#include <cstdint>
#include <set>
#include <string>
#include <vector>

#include "client/cell_margins.h"

namespace vistream::client {

struct WalkthroughSummary {
  std::string server, scene, path;
  double speed_kmh = 0.0;
  int width = 0, height = 0;
  uint64_t frames = 0, stalls = 0;
  double stall_s = 0.0;
  uint64_t bytes_received = 0, geometry_bytes = 0, objects_received = 0, duplicates = 0, reconnects = 0;
  double mean_triangles_drawn = 0.0, mean_objects_drawn = 0.0;
  uint64_t max_triangles_drawn = 0;
  uint64_t scene_triangles = 0, scene_objects = 0;
  uint64_t max_held_bytes = 0, memory_budget_bytes = 0, frames_over_memory_budget = 0;
  uint64_t triangle_budget = 0, frames_over_triangle_budget = 0;
  uint64_t evicted_by_server = 0, evicted_by_budget = 0;
  double fps = 0.0, frame_ms_p50 = 0.0, frame_ms_p99 = 0.0, frame_ms_max = 0.0;
  bool verified = false;
  uint64_t pixel_error = 0, checked_frames = 0, checked_pixels = 0;
  uint64_t masks_received = 0, frames_masked = 0, cells_visited = 0;
  uint64_t hole_frames = 0;  // neither a usable mask nor the complete viewcell PVS
  // Levels of detail (issue 45): the screen error asked for (0: off); frames of a complete
  // viewcell drawing some object at a coarser level than its list asks (the finer one on its
  // way); geometry received at a level and the encoded bytes those levels saved.
  double lod_tau_px = 0.0;
  bool server_levels = false;  // this session got levels: asked for and the server has them (SceneInfo.levels)
  uint64_t coarse_frames = 0, level_objects_received = 0, level_bytes_saved = 0;
  uint64_t cluster_levels_received = 0;  // ClusterGeometry messages (issue 45)
  // --verify: the largest distance, pixels, of a differing pixel from the nearest full-detail
  // silhouette over the checked frames (0: none differed).
  double max_silhouette_px = 0.0;
  // The same frames' viewcell PVS after view-frustum culling (what a PVS-only client would
  // draw: on a stall, what is held); equal to mean_triangles_drawn without masks.
  double mean_triangles_without_masks = 0.0;
  double startup_s = 0.0, walk_s = 0.0, distance_m = 0.0;
  // Arrival margins (client/cell_margins.h), walk-clock seconds, over the viewcells entered
  // after the start cell (the walk waits for that one).
  MarginSummary margins;
  std::vector<CellEntry> cells;  // every entry, the start cell's first
  std::vector<std::string> screenshots;
  bool cancelled = false;
};

// The summary as JSON (one object; its keys are the --json output's) and as lines for people.
std::string SummaryJson(const WalkthroughSummary& s);
std::string SummaryText(const WalkthroughSummary& s);

// What the frame loop adds up frame by frame (client/frame_loop.cpp).
struct FrameTally {
  std::vector<double> frame_ms;  // each frame's time, milliseconds, in order
  uint64_t triangles = 0, objects = 0;
  uint64_t triangles_without_masks = 0;  // what the viewcell PVS alone would have drawn
  std::set<uint32_t> cells;              // the viewcells the eye was in

  // Fills the summary's frame rate (over `walked_s` seconds of walk, pauses left out), frame-time
  // percentiles (milliseconds), per-frame means (over s->frames) and the cells visited.
  void Fill(double walked_s, WalkthroughSummary* s) const;
};

}  // namespace vistream::client
