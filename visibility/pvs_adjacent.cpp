// PvsComputer::ComputeAdjacent: the PVS of several adjacent viewcells in one traversal of the
// kd-tree, sharing between the cells what one cell's query learns about a node, and the
// traversal between threads from the root down.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <memory>
#include <mutex>
#include <thread>

#include "visibility/pvs.h"

namespace vistream::visibility {

namespace {

// A node waiting in a thread's traversal: the cells that saw its parent, and for each cell the
// line of the free ray that proved the parent visible from it.
struct AdjacentEntry {
  int32_t node = 0;
  uint32_t mask = 0;
  uint32_t hints = 0;  // index of this entry's FreeLines (one per cell) in the walker's pool
};

// A node handed from one thread to another, with its cells' lines.
struct DonatedEntry {
  int32_t node = 0;
  uint32_t mask = 0;
  std::vector<FreeLine> hints;
};

// The nodes that threads hand to idle ones. A thread that runs out of work waits here until a
// busy one donates the oldest node of its stack (the largest subtree it holds) or all are idle.
class SharedWork {
 public:
  SharedWork(unsigned threads, DonatedEntry root) : threads_(threads) { queue_.push_back(std::move(root)); }

  // The next node to expand, or false when every thread is idle and nothing is queued.
  bool Take(DonatedEntry* out) {
    std::unique_lock lock(mu_);
    ++idle_;
    UpdateHungry();
    while (queue_.empty() && idle_ < threads_) cv_.wait(lock);
    if (queue_.empty()) {
      cv_.notify_all();
      return false;
    }
    --idle_;
    *out = std::move(queue_.back());
    queue_.pop_back();
    UpdateHungry();
    return true;
  }
  void Give(DonatedEntry entry) {
    {
      std::lock_guard lock(mu_);
      queue_.push_back(std::move(entry));
      UpdateHungry();
    }
    cv_.notify_one();
  }
  // Whether a thread waits for work that nobody has queued yet (read without the lock: a
  // stale answer only delays or hastens one donation).
  bool Hungry() const { return hungry_.load(std::memory_order_relaxed); }

 private:
  void UpdateHungry() { hungry_.store(idle_ > queue_.size() && idle_ < threads_, std::memory_order_relaxed); }

  const unsigned threads_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<DonatedEntry> queue_;
  size_t idle_ = 0;
  std::atomic<bool> hungry_{false};
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
      std::vector<PvsResult> part =
          ComputeAdjacent(cells.subspan(k, std::min<size_t>(32, n - k)), options, threads, union_cull);
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
  CellQueryOptions unprobed = options;
  unprobed.probe_rays = false;

  // One traversal state per thread: its own engine, stack, hints and per-cell object lists.
  struct Walker {
    explicit Walker(const OccluderSet& occluders, size_t cells)
        : drs(occluders), pools(cells), objects(cells), stats(cells) {}
    DualRaySpace drs;
    // Per cell, the free lines this thread found from it (as PvsComputer::Compute keeps them).
    std::vector<FreeLinePool> pools;
    std::vector<AdjacentEntry> stack;
    std::vector<FreeLine> hints;  // pool: entry e's lines at [e.hints, e.hints + cells), ascending by stack order
    std::vector<FreeLine> found;  // the free lines found so far for the node being expanded
    std::vector<std::vector<ObjectId>> objects;
    std::vector<CellQueryStats> stats;
    CellQueryStats union_stats;
  };
  // Expands `e`: tests its node for the cells in its mask and pushes its children (or, for a
  // leaf, lists its objects) for the cells that see it.
  auto expand = [&](Walker& w, const AdjacentEntry& e) {
    const KdNode& node = nodes[e.node];
    uint32_t seen = 0;
    const uint32_t base = static_cast<uint32_t>(w.hints.size());
    w.hints.resize(base + n);
    w.found.clear();
    bool union_tested = false;
    bool hidden_before = false;
    for (size_t c = 0; c < n; ++c) {
      if ((e.mask >> c & 1) == 0) continue;
      const FreeLine& parent_hint = w.hints[e.hints + c];
      FreeLine witness;
      // A free ray found for a neighbour that, extended, joins this cell to the node proves
      // the node visible from it: Visible would say so too (a free ray leaves its raster a
      // gap), after its probe rays and, for a node seen through a narrow gap, its blockers.
      bool visible = false;
      for (auto it = w.found.rbegin(); it != w.found.rend() && !visible; ++it) {
        if (w.drs.ProvenVisibleAlong(cells[c], node.bounds, *it, &w.stats[c])) {
          visible = true;
          witness = *it;
        }
      }
      if (!visible) {
        // The parent's line first, else a neighbour's (it may still save a probe or two).
        const FreeLine& hint = parent_hint.valid || w.found.empty() ? parent_hint : w.found.back();
        // Hidden from an earlier cell of the batch: likely hidden from this one too, so its
        // probe rays would mostly be traced in vain (the answer is the same without them).
        visible = w.drs.Visible(cells[c], node.bounds, hidden_before ? unprobed : options, &w.stats[c], hint,
                                &witness, &w.pools[c]);
        if (visible && witness.valid) w.found.push_back(witness);
      }
      hidden_before |= !visible;
      if (visible) {
        seen |= 1u << c;
        w.hints[base + c] = witness.valid ? witness : parent_hint;
        continue;
      }
      // Hidden from this cell: if the union box is hidden too, so is every other cell.
      if (union_cull && !union_tested && seen == 0 && (uint64_t{e.mask} >> (c + 1)) != 0) {
        union_tested = true;
        if (!w.drs.Visible(all, node.bounds, options, &w.union_stats)) break;
      }
    }
    if (seen == 0) return;
    if (node.IsLeaf()) {
      for (size_t c = 0; c < n; ++c) {
        if ((seen >> c & 1) == 0) continue;
        for (ObjectId id : tree_.LeafObjects(node)) w.objects[c].push_back(id);
      }
      return;
    }
    w.stack.push_back({node.right, seen, base});
    w.stack.push_back({node.left, seen, base});
  };

  // Every thread walks depth first from the nodes it takes; one that runs dry is handed the
  // oldest node of a busy thread's stack. So the threads share the tree from the root down:
  // the top levels (large boxes, many of them seen only through gaps, so costly) run in
  // parallel too, and the load evens out however unequal the subtrees are.
  const unsigned count = threads != 0 ? threads : std::max(1u, std::thread::hardware_concurrency());
  SharedWork work(count, DonatedEntry{0, full, std::vector<FreeLine>(n)});
  std::vector<std::unique_ptr<Walker>> walkers;
  for (unsigned t = 0; t < count; ++t) walkers.push_back(std::make_unique<Walker>(occluders_, n));
  auto run = [&](Walker& w) {
    DonatedEntry taken;
    while (work.Take(&taken)) {
      w.hints = std::move(taken.hints);  // the stack is empty: no older line is in use
      w.stack.push_back({taken.node, taken.mask, 0});
      while (!w.stack.empty()) {
        if (w.stack.size() > 1 && work.Hungry()) {
          const AdjacentEntry& oldest = w.stack.front();
          const auto lines = w.hints.begin() + oldest.hints;
          work.Give(DonatedEntry{oldest.node, oldest.mask, std::vector<FreeLine>(lines, lines + static_cast<ptrdiff_t>(n))});
          w.stack.erase(w.stack.begin());
        }
        const AdjacentEntry e = w.stack.back();
        w.stack.pop_back();
        // The stack's lines lie in ascending order, e's last: what follows them belongs to
        // subtrees already walked, so the pool stays as deep as the stack.
        w.hints.resize(e.hints + n);
        expand(w, e);
      }
    }
  };
  {
    std::vector<std::jthread> pool;
    for (unsigned t = 1; t < count; ++t) pool.emplace_back([&, t] { run(*walkers[t]); });
    run(*walkers[0]);
  }
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  for (size_t c = 0; c < n; ++c) {
    PvsResult& r = results[c];
    for (const auto& w : walkers) {
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
