#pragma once
// When a walking client will reach each cell it is sent for (DESIGN.md "Server and client": on
// start the client's viewcell and its eight neighbours, current cell first, then in the order
// the client will reach them by its velocity). The deadlines order a session's wanted cells,
// its PVS requests (the scheduler serves the earliest deadline first, server/pvs_scheduler.h)
// and its geometry. Times are seconds on the session's clock; positions and velocities metres
// and metres per second in the scene's frame (z up; only x and y count).

#include <utility>
#include <vector>

#include <glm/vec3.hpp>

#include "visibility/viewcell_grid.h"

namespace vistream::server {

using visibility::CellId;

// When a client at `position` moving at `velocity` reaches `cell` (not its own), from `now`: a
// cell on its line of travel when the line enters it, at its speed (walking pace, 1 m/s, at
// least); a standing client's (under 0.1 m/s) when it could walk there; a cell off the line
// after a turn, so after the cells on it that are as near.
double CellDeadline(const visibility::ViewcellGrid& grid, CellId cell, const glm::dvec3& position,
                    const glm::dvec3& velocity, double now);

// Whether the client turned (30 degrees or more), started or stopped (crossing 0.1 m/s) between
// `ranked` (the velocity the wanted cells were ordered for) and `velocity`.
bool Turned(const glm::dvec3& velocity, const glm::dvec3& ranked);

// The cells a client in `current` wants, with their deadlines: `current` at `now` first, then
// its neighbours (ViewcellGrid::Neighbours) by CellDeadline when `look_ahead`, or else in the
// grid's fixed order, a millisecond apart (the 1998 paper's plain scheme).
std::vector<std::pair<double, CellId>> WantedCells(const visibility::ViewcellGrid& grid, CellId current,
                                                   const glm::dvec3& position, const glm::dvec3& velocity,
                                                   double now, bool look_ahead);

}  // namespace vistream::server
