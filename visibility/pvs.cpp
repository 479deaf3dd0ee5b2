#include "visibility/pvs.h"

#include <algorithm>
#include <chrono>
#include <memory>

#include "visibility/parallel.h"

namespace vistream::visibility {

PvsComputer::PvsComputer(const scenes::Scene& scene, const KdTree& tree)
    : scene_(scene), tree_(tree), occluders_(OccluderSet::Build(scene)) {}

PvsResult PvsComputer::Compute(const scenes::Aabb& cell, const CellQueryOptions& options) const {
  DualRaySpace drs(occluders_);
  return Compute(cell, options, &drs);
}

PvsResult PvsComputer::Compute(const scenes::Aabb& cell, const CellQueryOptions& options, DualRaySpace* drs) const {
  const auto start = std::chrono::steady_clock::now();
  PvsResult result;
  if (tree_.empty()) return result;
  const auto& nodes = tree_.nodes();
  // Each node waits with the line of the free ray that proved its parent visible: the
  // likeliest free ray for it too.
  std::vector<std::pair<int32_t, FreeLine>> stack = {{0, FreeLine{}}};
  // The free lines found so far from this cell: one may run through the gap that shows a
  // node far from the one it was found for.
  FreeLinePool pool;
  while (!stack.empty()) {
    const auto [index, hint] = stack.back();
    stack.pop_back();
    const KdNode& node = nodes[index];
    FreeLine witness;
    if (!drs->Visible(cell, node.bounds, options, &result.stats, hint, &witness, &pool)) continue;
    if (node.IsLeaf()) {
      for (ObjectId id : tree_.LeafObjects(node)) result.objects.push_back(id);
    } else {
      if (!witness.valid) witness = hint;
      stack.emplace_back(node.right, witness);
      stack.emplace_back(node.left, witness);
    }
  }
  std::sort(result.objects.begin(), result.objects.end());
  for (ObjectId id : result.objects) result.triangles += scene_.objects[id].mesh.TriangleCount();
  result.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  return result;
}

std::vector<PvsResult> PvsComputer::ComputeBatch(std::span<const scenes::Aabb> cells, const CellQueryOptions& options,
                                                 unsigned threads) const {
  std::vector<PvsResult> results(cells.size());
  // One query engine per thread: it keeps scratch between cells.
  ParallelFor(cells.size(), threads, [&] {
    return [&, drs = std::make_shared<DualRaySpace>(occluders_)](size_t i) {
      results[i] = Compute(cells[i], options, drs.get());
    };
  });
  return results;
}

}  // namespace vistream::visibility
