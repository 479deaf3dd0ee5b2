#pragma once
// The potentially visible set of a viewcell: a top-down kd-tree traversal that culls every
// node whose box the dual ray space proves hidden from the cell. Conservative: an object is
// left out only if every segment from the cell to its box meets an occluder.

#include <cstdint>
#include <span>
#include <vector>

#include "scenes/scene.h"
#include "visibility/dual_ray_space.h"
#include "visibility/kdtree.h"
#include "visibility/occluder_set.h"

namespace vistream::visibility {

struct PvsResult {
  std::vector<ObjectId> objects;  // sorted ascending
  uint64_t triangles = 0;
  double ms = 0.0;                // wall time of this cell's computation
  CellQueryStats stats;
};

class PvsComputer {
 public:
  // Prepares the occluders of `scene` (kept by reference, with `tree`; both must outlive this).
  PvsComputer(const scenes::Scene& scene, const KdTree& tree);

  // One viewcell (scene-local metres), on the calling thread.
  PvsResult Compute(const scenes::Aabb& cell, const CellQueryOptions& options) const;

  // Several viewcells on up to `threads` worker threads (0: one per core); results in the
  // order of `cells`, identical whatever the thread count.
  std::vector<PvsResult> ComputeBatch(std::span<const scenes::Aabb> cells, const CellQueryOptions& options,
                                      unsigned threads = 0) const;

  // One viewcell with the caller's query engine (built on occluders()), for another raster
  // backend; on the calling thread.
  PvsResult Compute(const scenes::Aabb& cell, const CellQueryOptions& options, DualRaySpace* drs) const;

  const OccluderSet& occluders() const { return occluders_; }

 private:
  const scenes::Scene& scene_;
  const KdTree& tree_;
  OccluderSet occluders_;
};

}  // namespace vistream::visibility
