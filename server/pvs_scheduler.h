#pragma once
// The viewcell PVSs the sessions ask for: computed on a pool of worker threads, earliest
// deadline first, and kept in a cache shared by every session (a byte budget, least recently
// used out first). Two sessions that need the same cell at the same time wait for one
// computation; a request nobody wants any more is dropped before it starts.

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <thread>
#include <unordered_map>
#include <vector>

#include "visibility/viewcell_grid.h"

namespace vistream::server {

using visibility::CellId;

struct CellPvs {
  CellId cell = 0;
  std::vector<uint32_t> objects;  // ascending object ids
  double compute_s = 0.0;         // worker time spent; 0 for a PVS file's sets
  size_t Bytes() const { return sizeof(CellPvs) + objects.size() * sizeof(uint32_t); }
};
using CellPvsPtr = std::shared_ptr<const CellPvs>;

struct SchedulerStats {
  uint64_t computed = 0;    // cells computed
  uint64_t cache_hits = 0;  // requests answered from the cache or joined to a running job
  uint64_t dropped = 0;     // jobs dropped before they started (no one wanted them any more)
  uint64_t cache_bytes = 0;
  uint64_t queued = 0;      // jobs waiting for a worker
  double compute_s = 0.0;
};

class PvsScheduler {
 public:
  // Computes one cell; called on a worker thread, concurrently from several. `worker` is the
  // worker's index in [0, threads).
  using Compute = std::function<CellPvs(CellId cell, unsigned worker)>;
  // Receives a requested cell's PVS, on a worker thread. Must not call back into the scheduler
  // while holding a lock the scheduler's callers hold.
  using Done = std::function<void(const CellPvsPtr&)>;

  // Starts `threads` workers (at least one). Compute may run per-thread set-up first (e.g. an
  // OpenGL context): `init(worker)` runs once on each worker thread before any job.
  PvsScheduler(Compute compute, unsigned threads, size_t cache_bytes,
               std::function<void(unsigned)> init = nullptr);
  // Stops the workers; requests still waiting are dropped without calling their Done.
  ~PvsScheduler();
  PvsScheduler(const PvsScheduler&) = delete;
  PvsScheduler& operator=(const PvsScheduler&) = delete;

  // Asks for `cell` on behalf of `requester` (a session id), needed by `deadline` (seconds on
  // the steady clock; sooner is served first). A cached cell is returned at once and `done`
  // is not called; otherwise `done` is called later on a worker thread, exactly once unless
  // the request is cancelled first. Asking again for the same cell replaces the deadline and
  // the callback.
  CellPvsPtr Request(uint64_t requester, CellId cell, double deadline, Done done);
  // `requester` no longer needs `cell` (it turned away): its Done will not be called, and a
  // job no one else waits for is dropped if it has not started.
  void Cancel(uint64_t requester, CellId cell);
  // Everything `requester` asked for (its session ended).
  void CancelAll(uint64_t requester);
  // The cached PVS of `cell`, if any (refreshes its place in the LRU order).
  CellPvsPtr Cached(CellId cell);

  SchedulerStats stats() const;

 private:
  struct Waiter {
    double deadline;
    Done done;
  };
  struct Job {
    std::map<uint64_t, Waiter> waiters;
    double key = 0.0;  // the earliest deadline, its key in queue_ while not running
    bool running = false;
  };

  void WorkerLoop(unsigned worker);
  void Requeue(CellId cell, Job* job);  // after its waiters changed; lock held
  void Insert(const CellPvsPtr& pvs);   // into the cache; lock held

  Compute compute_;
  std::function<void(unsigned)> init_;
  size_t cache_budget_;

  mutable std::mutex mu_;
  std::condition_variable work_;
  bool stopping_ = false;
  std::unordered_map<CellId, Job> jobs_;
  std::set<std::pair<double, CellId>> queue_;  // jobs not running, by earliest deadline
  std::list<CellPvsPtr> lru_;                  // most recently used first
  std::unordered_map<CellId, std::list<CellPvsPtr>::iterator> cache_;
  SchedulerStats stats_;
  std::vector<std::jthread> workers_;
};

}  // namespace vistream::server
