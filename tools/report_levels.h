#pragma once
// The "levels of detail: what accuracy costs" section of `vistream report` (issue 45): for each
// scene, the same walk simulated at every screen error tau (`simulate --lod off,0.5,1,2,4,16`:
// bytes down and mean triangles drawn a frame at the walk's speed, and the highest speed
// without a stall, `--speed max`), and the real client drawing the levels against the full
// scene (`bench client --lod ... --verify`: the share of differing pixels and the farthest of
// them from a full-detail silhouette). One plot, four panels against tau, and a table.

#include <string>
#include <vector>

#include "tools/report_page.h"

namespace vistream::tools {

struct LevelsPlan {
  std::vector<std::string> scenes;  // simulated (catalog names or .json entries)
  std::string taus;                 // --lod of every step: off first, then pixels
  bool speed_search = true;         // --speed max (minutes a scene and tau)
  std::string client_scene;         // bench client --verify (empty: none)
  std::string client_seconds;
};

LevelsPlan LevelsPlanFor(bool quick);

void LevelsSection(Page& page, const LevelsPlan& plan);

}  // namespace vistream::tools
