#pragma once
// The latency section of `vistream report`: stalls and arrival margin against walking speed
// and link bandwidth, masked frames, hole frames and triangles drawn with and without ε-masks
// (pvs against pvs+eps, and along the walk), bytes against the baselines, the highest speed
// without stalls and without hole frames per scheme; from `vistream simulate --json` (the
// discrete-event simulator of server and link).

#include <string>
#include <vector>

#include "tools/report_page.h"

namespace vistream::tools {

struct LatencyPlan {
  std::string scene, path;
  std::vector<double> speeds_kmh;      // the speed sweep, schemes pvs and pvs+eps at the scene's link
  double speed_sweep_bps = 0.0;        // else at this bandwidth (and the scene's latency), when > 0
  std::vector<double> bandwidths_mbps; // the bandwidth sweep, at `sweep_speed_kmh` and the scene's latency
  double sweep_speed_kmh = 6.0;        // also the speed of the per-scheme comparison
  std::vector<std::string> schemes;
};

LatencyPlan LatencyPlanFor(bool quick);

void LatencySection(Page& page, const LatencyPlan& plan);

}  // namespace vistream::tools
