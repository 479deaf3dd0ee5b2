#pragma once
// The ε-neighbourhoods ahead of a walking client (Cohen-Or & Zadicario 1998, section 3: the
// client renders on its own inside a neighbourhood while the server prepares the next). From
// the eye, its velocity and its recent turn the chain predicts where the eye will be over the
// next seconds and covers that path with boxes, each inside one viewcell (a mask narrows that
// cell's PVS, which holds for no eye beyond it): long along the path, a margin either side for a
// walker who drifts, thin in z around the eye (where cells follow terrain, a box ahead spans its
// cell's band: the ground ahead may rise or fall). A standing client gets one box around it.
//
// The chain is kept, not redrawn: boxes the predicted path still runs through stay (their
// masks are computed once); the path is extended past the last box as the eye moves on; when
// the eye leaves every box (it turned, jumped, stopped short) the chain starts again from it.
//
// Units: metres and seconds, scene-local frame (z up). Pure and deterministic; not thread-safe.

#include <cstdint>
#include <functional>
#include <vector>

#include <glm/vec3.hpp>

#include "scenes/aabb.h"
#include "visibility/viewcell_grid.h"

namespace vistream::server {

struct ChainOptions {
  double standing_size_m = 4.0;     // a standing client's box edge (the catalog's epsilon_m)
  double standing_speed_mps = 0.3;  // slower than this: standing
  double box_seconds = 3.0;         // a box covers about this much of the walk...
  double min_length_m = 4.0;        // ...but at least this much of the path
  double max_length_m = 20.0;       // and at most this much
  double max_area_m2 = 80.0;        // nor more ground than this (a box across a diagonal street)
  double lateral_m = 1.0;           // margin around the predicted path, every side in xy
  double height_m = 0.6;            // box height, centred on the eye, kept inside its cell's band
  double horizon_s = 8.0;           // the chain reaches this far ahead in time...
  double min_horizon_m = 12.0;      // ...but at least this far
  double max_horizon_m = 160.0;     // and at most this far
  double max_turn_rad_s = 0.6;      // the turn rate used, clamped
  double turn_s = 2.0;              // the turn is assumed to go on this long, then straight on
  double step_m = 0.5;              // sampling of the predicted path
};

struct Neighbourhood {
  uint64_t id = 0;      // unique within the chain, from 1, in the order planned
  visibility::CellId cell = 0;
  scenes::Aabb box;
  double along_m = 0.0;  // metres along the predicted path from the eye to the box, when planned
};

class NeighbourhoodChain {
 public:
  explicit NeighbourhoodChain(ChainOptions options = {}) : opt_(options) {}

  struct Update {
    std::vector<Neighbourhood> added;  // new boxes, in path order
    std::vector<uint64_t> removed;     // boxes left behind or off the path now
  };
  // Plans for an eye at `eye` moving at `velocity` (m/s; z ignored), turning at `turn_rad_s`
  // (counter-clockwise, rad/s). Only cells for which `allowed(cell)` holds get boxes (the
  // session's wanted cells: their PVSs are what masks narrow); the path stops at the first
  // other cell and at the grid's edge. An eye outside the grid or its cell's band gets no box.
  Update Advance(const glm::dvec3& eye, const glm::dvec3& velocity, double turn_rad_s,
                 const visibility::ViewcellGrid& grid, const std::function<bool(visibility::CellId)>& allowed);
  // Forgets every box (their ids are not reused).
  std::vector<uint64_t> Clear();

  const std::vector<Neighbourhood>& boxes() const { return boxes_; }
  const ChainOptions& options() const { return opt_; }

  // The predicted eye positions every step_m along the path, from the eye (index 0) to one
  // box length past the horizon, or to the last point on the grid (exposed for tests).
  std::vector<glm::dvec3> PredictPath(const glm::dvec3& eye, const glm::dvec3& velocity, double turn_rad_s,
                                      const visibility::ViewcellGrid& grid) const;

 private:
  bool Covered(const glm::dvec3& p) const;

  ChainOptions opt_;
  std::vector<Neighbourhood> boxes_;  // path order
  uint64_t next_id_ = 1;
};

}  // namespace vistream::server
