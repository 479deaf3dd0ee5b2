#include "visibility/pvs.h"

#include <algorithm>
#include <chrono>
#include <memory>
#include <mutex>

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
  while (!stack.empty()) {
    const auto [index, hint] = stack.back();
    stack.pop_back();
    const KdNode& node = nodes[index];
    FreeLine witness;
    if (!drs->Visible(cell, node.bounds, options, &result.stats, hint, &witness)) continue;
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

namespace {

// A node waiting in the shared traversal: the cells that saw its parent, and for each cell the
// line of the free ray that proved the parent visible from it.
struct AdjacentEntry {
  int32_t node = 0;
  uint32_t mask = 0;
  uint32_t hints = 0;  // index of this entry's FreeLines (one per cell) in the hint pool
};

}  // namespace

std::vector<PvsResult> PvsComputer::ComputeAdjacent(std::span<const scenes::Aabb> cells,
                                                    const CellQueryOptions& options, unsigned threads,
                                                    bool union_cull) const {
  const auto start = std::chrono::steady_clock::now();
  const size_t n = cells.size();
  std::vector<PvsResult> results(n);
  if (n > 32) {  // in batches of 32: a cell mask is 32 bits
    for (size_t k = 0; k < n; k += 32) {
      std::vector<PvsResult> part = ComputeAdjacent(cells.subspan(k, std::min<size_t>(32, n - k)), options, threads, union_cull);
      std::move(part.begin(), part.end(), results.begin() + static_cast<ptrdiff_t>(k));
    }
    return results;
  }
  if (tree_.empty() || n == 0) return results;
  scenes::Aabb all = cells[0];
  for (const scenes::Aabb& c : cells) {
    all.min = glm::min(all.min, c.min);
    all.max = glm::max(all.max, c.max);
  }
  const auto& nodes = tree_.nodes();
  const uint32_t full = static_cast<uint32_t>((uint64_t{1} << std::min<size_t>(n, 32)) - 1);

  // One traversal state per thread: its own engine, stack, hints and per-cell object lists.
  struct Walker {
    explicit Walker(const OccluderSet& occluders, size_t cells) : drs(occluders), objects(cells), stats(cells) {}
    DualRaySpace drs;
    std::vector<AdjacentEntry> stack;
    std::vector<FreeLine> hints;  // pool: entry e's lines at [e.hints, e.hints + cells)
    std::vector<std::vector<ObjectId>> objects;
    std::vector<CellQueryStats> stats;
    CellQueryStats union_stats;
  };
  // Expands `e`: tests its node for the cells in its mask and pushes its children (or, for a
  // leaf, lists its objects) for the cells that see it. Pushes onto `out`.
  auto expand = [&](Walker& w, const AdjacentEntry& e, std::vector<AdjacentEntry>* out) {
    const KdNode& node = nodes[e.node];
    uint32_t seen = 0;
    const uint32_t base = static_cast<uint32_t>(w.hints.size());
    w.hints.resize(base + n);
    FreeLine shared;  // the last free line found for this node, tried first by the next cell
    bool union_tested = false;
    for (size_t c = 0; c < n; ++c) {
      if ((e.mask >> c & 1) == 0) continue;
      const FreeLine& parent_hint = w.hints[e.hints + c];
      FreeLine witness;
      const bool visible =
          w.drs.Visible(cells[c], node.bounds, options, &w.stats[c], parent_hint.valid ? parent_hint : shared, &witness);
      if (visible) {
        seen |= 1u << c;
        w.hints[base + c] = witness.valid ? witness : parent_hint;
        if (witness.valid) shared = witness;
        continue;
      }
      // Hidden from this cell: if the union box is hidden too, so is every other cell.
      if (union_cull && !union_tested && seen == 0 && (uint64_t{e.mask} >> (c + 1)) != 0) {
        union_tested = true;
        if (!w.drs.Visible(all, node.bounds, options, &w.union_stats)) break;
      }
    }
    if (seen == 0) {
      w.hints.resize(base);
      return;
    }
    if (node.IsLeaf()) {
      for (size_t c = 0; c < n; ++c) {
        if ((seen >> c & 1) == 0) continue;
        for (ObjectId id : tree_.LeafObjects(node)) w.objects[c].push_back(id);
      }
      w.hints.resize(base);
      return;
    }
    out->push_back({node.right, seen, base});
    out->push_back({node.left, seen, base});
  };

  // The top of the tree on this thread, breadth first, until there are subtrees enough to share.
  std::vector<std::unique_ptr<Walker>> walkers;
  walkers.push_back(std::make_unique<Walker>(occluders_, n));
  Walker& first = *walkers[0];
  std::vector<AdjacentEntry> frontier = {{0, full, 0}}, next;
  first.hints.assign(n, FreeLine{});
  const size_t want = threads == 1 ? 1 : 64;
  while (!frontier.empty() && frontier.size() < want) {
    next.clear();
    for (const AdjacentEntry& e : frontier) expand(first, e, &next);
    frontier.swap(next);
  }
  // The subtrees, depth first, on up to `threads` threads, each with its own walker.
  std::mutex mu;
  ParallelFor(frontier.size(), threads, [&] {
    Walker* mine = nullptr;
    {
      std::lock_guard lock(mu);
      walkers.push_back(std::make_unique<Walker>(occluders_, n));
      mine = walkers.back().get();
    }
    return [&, mine](size_t i) {
      const AdjacentEntry& root = frontier[i];
      mine->hints.assign(first.hints.begin() + root.hints, first.hints.begin() + root.hints + n);
      mine->stack.push_back({root.node, root.mask, 0});
      while (!mine->stack.empty()) {
        const AdjacentEntry e = mine->stack.back();
        mine->stack.pop_back();
        expand(*mine, e, &mine->stack);
      }
    };
  });
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  for (size_t c = 0; c < n; ++c) {
    PvsResult& r = results[c];
    for (const auto& w : walkers) {
      if (w == nullptr) continue;
      r.objects.insert(r.objects.end(), w->objects[c].begin(), w->objects[c].end());
      r.stats += w->stats[c];
    }
    std::sort(r.objects.begin(), r.objects.end());
    for (ObjectId id : r.objects) r.triangles += scene_.objects[id].mesh.TriangleCount();
    r.ms = ms;
  }
  return results;
}

}  // namespace vistream::visibility
