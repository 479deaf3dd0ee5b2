#pragma once
// The "visibility at the server's pace" section of `vistream report`: the figures issue 22
// sets targets for, each from the command that measures it — one 100 m viewcell at 128² and a
// batch of the five viewcells a diagonal crossing makes adjacent (`bench table1 --batch`), the
// ε-superset over a viewcell's PVS (`bench epsilon --pvs-cell`), and AGVS's sampling rate
// (`agvs --seconds`). The targets are printed beside the figures; the page says met or missed
// and by what factor, but never fails a step for a miss.

#include <string>
#include <vector>

#include "tools/report_page.h"

namespace vistream::tools {

struct PacePlan {
  struct Table1Run {
    std::string scene, cells;
  };
  std::vector<Table1Run> table1;         // per scene: viewcells sampled (100 m, 128², cpu, --batch)
  std::string epsilon_scene, epsilon_count;
  std::vector<std::string> agvs_scenes;  // AGVS rate, per scene
  std::string agvs_seconds;
};

PacePlan PacePlanFor(bool quick);

void PaceSection(Page& page, const PacePlan& plan);

}  // namespace vistream::tools
