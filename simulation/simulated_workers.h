#pragma once
// The server's workers on simulated time, for the discrete-event simulator
// (simulation/simulator.h): the clock and its events, the PVS scheduler's policy
// (server/pvs_scheduler.h PvsSchedulePolicy) on simulated PVS workers, the ε-mask queue on a
// simulated mask worker (server/task_queue.h), and the PVSs computed once per process. The
// session they serve is the server's own (server/session.h); only the time work takes is
// modelled: a job costs the wall time its real computation took on this machine (or a fixed
// time, for tests), counted on the simulated clock.
//
// Units: seconds of simulated time.

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <queue>
#include <unordered_map>
#include <utility>
#include <vector>

#include "server/pvs_scheduler.h"
#include "server/served_scene.h"
#include "server/task_queue.h"

namespace vistream::simulation {

using server::CellId;
using server::CellPvsPtr;

// Simulated time: events run in time order (ties in the order they were added).
class EventQueue {
 public:
  double now() const { return now_; }
  // Runs `fn` at `t` (not before now()).
  void At(double t, std::function<void()> fn);
  bool empty() const { return events_.empty(); }
  double next_time() const { return events_.top().t; }
  // Runs the earliest event, advancing now() to its time.
  void RunNext();

 private:
  struct Event {
    double t;
    uint64_t seq;
    std::function<void()> fn;
    bool operator>(const Event& o) const { return t != o.t ? t > o.t : seq > o.seq; }
  };
  double now_ = 0.0;
  uint64_t seq_ = 0;
  std::priority_queue<Event, std::vector<Event>, std::greater<>> events_;
};

// Viewcell PVSs computed in this process, with the wall time each took, so that a speed search
// or a comparison of schemes computes each cell once (whether a run pays the time is the
// simulated cache's decision). Not thread-safe.
class PvsMemo {
 public:
  struct Entry {
    CellPvsPtr pvs;
    double seconds = 0.0;  // wall time of the computation on this machine
  };
  // The PVS of `cell`, computed with scene.ComputePvs(cell, 0) the first time.
  const Entry& Get(const server::ServedScene& scene, CellId cell);
  // The radius baseline's set of `cell`: every object whose box lies within `radius_m` (metres,
  // box to box) of the cell's, found by a scan of the scene the first time. Kept like the PVSs,
  // so that every run of a process (a speed search's probes and its run at the answer) is
  // charged the same seconds for it.
  const Entry& GetRadius(const server::ServedScene& scene, CellId cell, double radius_m);
  size_t size() const { return entries_.size(); }

 private:
  std::unordered_map<CellId, Entry> entries_;
  std::map<std::pair<CellId, double>, Entry> radius_entries_;
};

// The server's PVS scheduling policy (PvsSchedulePolicy) on `workers` simulated workers: a job
// starts when a worker is free, takes `compute`'s seconds, and its waiters hear at the end.
class SimulatedScheduler : public server::PvsSource {
 public:
  // A cell's set and the simulated seconds it costs.
  using Compute = std::function<CellPvsPtr(CellId cell, double* seconds)>;
  // `cache` false: no cache at all (the plain scheme).
  SimulatedScheduler(EventQueue* queue, Compute compute, unsigned workers, size_t cache_bytes, bool cache);

  CellPvsPtr Request(uint64_t requester, CellId cell, double deadline, Done done) override;
  void Cancel(uint64_t requester, CellId cell) override;
  void CancelAll(uint64_t requester) override;
  CellPvsPtr Cached(CellId cell) override;
  server::SchedulerStats stats() const override;

  // Starts waiting jobs on the free workers at queue->now(). `on_start(cell, seconds)` hears of
  // each job started (may be empty).
  void Dispatch(const std::function<void(CellId, double)>& on_start);
  // Whether a simulated worker is free (no PVS job waits for it after Dispatch).
  bool has_free_worker() const { return busy_ < workers_; }

 private:
  EventQueue* queue_;
  Compute compute_;
  unsigned workers_, busy_ = 0;
  server::PvsSchedulePolicy policy_;
};

// ε-masks on one simulated worker, earliest deadline first, as MaskQueue runs them: a job
// starts only when `may_start` says so (the simulator: while a PVS worker is free, as the
// server's idle-priority mask threads run only on cores the PVS workers leave), and delivers its
// measured time (or `fixed_s`) later. A job whose work returns no delivery (stale) costs nothing.
class SimulatedTaskRunner : public server::TaskRunner {
 public:
  SimulatedTaskRunner(EventQueue* queue, std::optional<double> fixed_s, std::function<bool()> may_start = nullptr)
      : queue_(queue), fixed_s_(fixed_s), may_start_(std::move(may_start)) {}
  void Post(Work work, double deadline) override { waiting_.emplace(std::pair{deadline, seq_++}, std::move(work)); }
  // Starts the earliest waiting job if the worker is free (and may_start allows).
  void Dispatch();
  uint64_t ran() const { return ran_; }        // jobs that computed a mask
  uint64_t dropped() const { return dropped_; }  // jobs found stale
  double busy_s() const { return busy_s_; }     // simulated seconds spent computing

 private:
  EventQueue* queue_;
  std::optional<double> fixed_s_;
  std::function<bool()> may_start_;
  std::map<std::pair<double, uint64_t>, Work> waiting_;
  uint64_t seq_ = 0;
  bool busy_ = false;
  uint64_t ran_ = 0, dropped_ = 0;
  double busy_s_ = 0.0;
};

}  // namespace vistream::simulation
