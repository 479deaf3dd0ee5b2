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
#include <optional>
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
  bool from_store = false;        // read from the shared PVS store (server/pvs_store.h), not computed
  size_t Bytes() const { return sizeof(CellPvs) + objects.size() * sizeof(uint32_t); }
};
using CellPvsPtr = std::shared_ptr<const CellPvs>;

struct SchedulerStats {
  uint64_t computed = 0;    // cells computed (or looked up in a PVS file)
  uint64_t store_hits = 0;  // cells read from the shared PVS store instead
  uint64_t cache_hits = 0;  // requests answered from the cache or joined to a running job
  uint64_t dropped = 0;     // jobs dropped before they started (no one wanted them any more)
  uint64_t cache_bytes = 0;
  uint64_t queued = 0;      // jobs waiting for a worker
  double compute_s = 0.0;
};

// What a session asks for viewcell PVSs: the threaded PvsScheduler in the server, the
// simulator's SimulatedScheduler (simulation/simulated_workers.h) on simulated time. Both keep the same
// policy (PvsSchedulePolicy): earliest deadline first, a shared LRU byte cache, joins, drops.
class PvsSource {
 public:
  // Receives a requested cell's PVS (PvsScheduler: on a worker thread; it must not call back
  // into the scheduler while holding a lock the scheduler's callers hold).
  using Done = std::function<void(const CellPvsPtr&)>;
  virtual ~PvsSource() = default;

  // Asks for `cell` on behalf of `requester` (a session id), needed by `deadline` (seconds on
  // the caller's clock; sooner is served first). A cached cell is returned at once and `done`
  // is not called; otherwise `done` is called later, exactly once unless the request is
  // cancelled first, and never from within Request. Asking again for the same cell replaces
  // the deadline and the callback.
  virtual CellPvsPtr Request(uint64_t requester, CellId cell, double deadline, Done done) = 0;
  // `requester` no longer needs `cell` (it turned away): its Done will not be called, and a
  // job no one else waits for is dropped if it has not started.
  virtual void Cancel(uint64_t requester, CellId cell) = 0;
  // Everything `requester` asked for (its session ended).
  virtual void CancelAll(uint64_t requester) = 0;
  // The cached PVS of `cell`, if any (refreshes its place in the LRU order).
  virtual CellPvsPtr Cached(CellId cell) = 0;
  virtual SchedulerStats stats() const = 0;
};

// The scheduling policy without threads or clocks (not thread-safe; the caller locks): jobs
// with their waiters, the queue by earliest deadline, the LRU byte cache, and the counts.
class PvsSchedulePolicy {
 public:
  using Done = PvsSource::Done;
  // `cache_bytes`: the cache's budget (the newest entry is always kept); `cache` false: no
  // cache at all (every request is computed; the paper's plain scheme).
  explicit PvsSchedulePolicy(size_t cache_bytes, bool cache = true) : cache_budget_(cache_bytes), use_cache_(cache) {}

  // As PvsSource::Request; returns whether a job was (re)queued in `*queued` (may be null).
  CellPvsPtr Request(uint64_t requester, CellId cell, double deadline, Done done, bool* queued = nullptr);
  void Cancel(uint64_t requester, CellId cell);
  void CancelAll(uint64_t requester);
  CellPvsPtr Cached(CellId cell);
  bool HasQueued() const { return !queue_.empty(); }
  // The earliest-deadline job waiting, now marked running; none when no job waits.
  std::optional<CellId> StartNext();
  // The running job of `pvs->cell` finished after `seconds` of work: caches the PVS and
  // returns its waiters' callbacks (ordered by requester), to be called without a lock.
  std::vector<Done> Finish(const CellPvsPtr& pvs, double seconds);
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
  // After a job's waiters changed; returns whether it is queued.
  bool Requeue(CellId cell, Job* job);
  void Insert(const CellPvsPtr& pvs);

  size_t cache_budget_;
  bool use_cache_;
  std::unordered_map<CellId, Job> jobs_;
  std::set<std::pair<double, CellId>> queue_;  // jobs not running, by earliest deadline
  std::list<CellPvsPtr> lru_;                  // most recently used first
  std::unordered_map<CellId, std::list<CellPvsPtr>::iterator> cache_;
  SchedulerStats stats_;
};

class PvsScheduler;

// Worker threads shared by the PvsSchedulers of every scene a server serves. A free worker
// takes the earliest-deadline job of the next scheduler in turn that has one (round robin over
// the schedulers, earliest deadline first within each), so a flood of requests on one scene
// holds at most its turn of the workers while another scene waits: a job of the waiting scene
// starts as soon as any worker is free.
class PvsWorkerPool {
 public:
  // `threads` workers (at least one), started at once.
  explicit PvsWorkerPool(unsigned threads);
  // Stops the workers after their running jobs; schedulers must be gone first.
  ~PvsWorkerPool();
  PvsWorkerPool(const PvsWorkerPool&) = delete;
  PvsWorkerPool& operator=(const PvsWorkerPool&) = delete;

  unsigned threads() const { return threads_; }

 private:
  friend class PvsScheduler;
  void Add(PvsScheduler* lane);
  // Removes `lane`: no job of it starts afterwards; waits for its running ones.
  void Remove(PvsScheduler* lane);
  void WorkerLoop(unsigned worker);

  const unsigned threads_;
  std::mutex mu_;  // guards the lanes and every lane's policy
  std::condition_variable work_;
  std::condition_variable idle_;  // a lane's running job finished
  std::vector<PvsScheduler*> lanes_;
  size_t next_lane_ = 0;
  bool stopping_ = false;
  std::vector<std::jthread> workers_;  // last: start after the members above exist
};

class PvsScheduler : public PvsSource {
 public:
  // Computes one cell; called on a worker thread, concurrently from several. `worker` is the
  // worker's index in [0, threads).
  using Compute = std::function<CellPvs(CellId cell, unsigned worker)>;

  // Starts `threads` workers of its own (at least one). Compute may run per-thread set-up
  // first (e.g. an OpenGL context): `init(worker)` runs once on each worker thread before any
  // job.
  PvsScheduler(Compute compute, unsigned threads, size_t cache_bytes,
               std::function<void(unsigned)> init = nullptr);
  // Runs on `pool`'s workers, shared with the other schedulers on it (not owned; it must
  // outlive this scheduler); its own cache of `cache_bytes`. `init(worker)` runs on a worker
  // thread before that worker's first job of this scheduler.
  PvsScheduler(Compute compute, PvsWorkerPool* pool, size_t cache_bytes,
               std::function<void(unsigned)> init = nullptr);
  // Stops taking jobs (requests still waiting are dropped without calling their Done) and
  // waits for the running ones.
  ~PvsScheduler() override;
  PvsScheduler(const PvsScheduler&) = delete;
  PvsScheduler& operator=(const PvsScheduler&) = delete;

  // PvsSource, deadlines on the steady clock; `done` is called on a worker thread.
  CellPvsPtr Request(uint64_t requester, CellId cell, double deadline, Done done) override;
  void Cancel(uint64_t requester, CellId cell) override;
  void CancelAll(uint64_t requester) override;
  CellPvsPtr Cached(CellId cell) override;
  SchedulerStats stats() const override;
  unsigned threads() const { return pool_->threads(); }
  // Called (on the worker, without a lock) with the seconds each computation took (not for
  // PVSs read from the store); set it before the first request.
  void SetComputeObserver(std::function<void(double seconds)> observe);

 private:
  friend class PvsWorkerPool;
  std::function<void(double)> observe_;  // guarded by mu_

  Compute compute_;
  std::function<void(unsigned)> init_;
  std::unique_ptr<PvsWorkerPool> own_pool_;  // the first constructor's
  PvsWorkerPool* pool_;
  std::mutex& mu_;                           // the pool's
  PvsSchedulePolicy policy_;
  size_t running_ = 0;                       // jobs of this scheduler being computed
  std::vector<char> initialised_;            // per worker: init_ ran there
};

}  // namespace vistream::server
