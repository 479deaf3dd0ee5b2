#include "client/walkthrough_summary.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

namespace vistream::client {

namespace {

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  const double at = q * static_cast<double>(v.size() - 1);
  const auto lo = static_cast<size_t>(std::floor(at));
  const size_t hi = std::min(lo + 1, v.size() - 1);
  return v[lo] + (v[hi] - v[lo]) * (at - static_cast<double>(lo));
}

}  // namespace

void FrameTally::Fill(double walked_s, WalkthroughSummary* s) const {
  s->fps = walked_s > 0.0 ? static_cast<double>(s->frames) / walked_s : 0.0;
  s->frame_ms_p50 = Percentile(frame_ms, 0.5);
  s->frame_ms_p99 = Percentile(frame_ms, 0.99);
  s->frame_ms_max = frame_ms.empty() ? 0.0 : *std::max_element(frame_ms.begin(), frame_ms.end());
  if (s->frames > 0) {
    s->mean_triangles_drawn = static_cast<double>(triangles) / static_cast<double>(s->frames);
    s->mean_objects_drawn = static_cast<double>(objects) / static_cast<double>(s->frames);
    s->mean_triangles_without_masks = static_cast<double>(triangles_without_masks) / static_cast<double>(s->frames);
  }
  s->cells_visited = cells.size();
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
  j["lod_tau_px"] = s.lod_tau_px > 0.0 ? nlohmann::ordered_json(s.lod_tau_px) : nlohmann::ordered_json(nullptr);
  j["server_levels"] = s.server_levels;
  j["coarse_frames"] = s.coarse_frames;
  j["level_objects_received"] = s.level_objects_received;
  j["level_bytes_saved"] = s.level_bytes_saved;
  j["cluster_levels_received"] = s.cluster_levels_received;
  j["max_silhouette_px"] = s.verified ? nlohmann::ordered_json(s.max_silhouette_px) : nlohmann::ordered_json(nullptr);
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
  if (s.lod_tau_px > 0.0 && !s.server_levels && s.scene_objects > 0) {
    absl::StrAppendFormat(&out,
                          "  levels of detail: tau %.2f px asked for, but the server has no levels (vistream-server "
                          "--levels makes them): full detail\n",
                          s.lod_tau_px);
  } else if (s.lod_tau_px > 0.0) {
    absl::StrAppendFormat(&out,
                          "  levels of detail at tau %.2f px: %d objects received at a level, %d cluster levels "
                          "(%.1f MB saved), %d coarse frames\n",
                          s.lod_tau_px, s.level_objects_received, s.cluster_levels_received, s.level_bytes_saved / 1e6,
                          s.coarse_frames);
  } else {
    out += "  levels of detail: off (full detail)\n";
  }
  if (s.verified) {
    absl::StrAppendFormat(&out, "  pixel error: %d of %d pixels in %d checked frames%s\n", s.pixel_error,
                          s.checked_pixels, s.checked_frames,
                          s.pixel_error > 0
                              ? absl::StrFormat("; the farthest %.1f px from a full-detail silhouette",
                                                s.max_silhouette_px)
                              : std::string());
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
