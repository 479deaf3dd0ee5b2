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

  // Adjacent viewcells at once (scene-local metres; e.g. the five cells a client
  // crossing a corner diagonally comes to border: ViewcellGrid::NewlyAdjacent), sharing work:
  // one traversal of the kd-tree for all of them (32 at a time), each node tested only for the
  // cells that see its parent (dual ray space, section 5 of Koltun et al. 2001, per node and
  // cell as Compute). A free ray that proved a node visible from one cell is tried for the
  // next: if, extended, it joins that cell to the node (DualRaySpace::ProvenVisibleAlong), the
  // node is visible from it without a query of its own; else it serves as a hint.
  // With `union_cull`, a node that the union box of the cells (their bounding box) is proven
  // not to see is culled for all of them at once: conservative, since each cell lies inside
  // that box, but the sets may then be smaller than Compute's where the union's raster closes
  // a gap that a cell's leaves open. Without it the sets are exactly Compute's. Up to `threads`
  // threads (0: one per core) share the traversal from the root down (an idle thread is handed
  // the oldest node of a busy one's stack); results in the order of `cells`, identical
  // whatever the thread count; each result's `ms` is the whole batch's wall time.
  std::vector<PvsResult> ComputeAdjacent(std::span<const scenes::Aabb> cells, const CellQueryOptions& options,
                                         unsigned threads = 0, bool union_cull = false) const;

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
