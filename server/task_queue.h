#pragma once
// Where ε-masks are computed: MaskQueue, worker threads that run only when the CPU would
// otherwise idle, in the server; the simulator's own runner on simulated time
// (simulation/simulator.h). Both take the job whose result is wanted soonest first.

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

namespace vistream::server {

class TaskRunner {
 public:
  // A job in two steps: the work (run off the caller's thread, or at a simulated time, whose
  // length the simulator measures), which returns what delivers its result (run right after
  // it by MaskQueue, or when the simulated work ends). Work that finds its result no longer
  // wanted returns an empty delivery at once: it is counted as dropped, not as computed.
  using Work = std::function<std::function<void()>()>;
  virtual ~TaskRunner() = default;
  // `deadline`: when the result is wanted, in seconds on the poster's clock; the earliest
  // deadline runs first (ties in the order posted).
  virtual void Post(Work work, double deadline) = 0;
};

// CPU seconds the calling thread has used (CLOCK_THREAD_CPUTIME_ID): what TaskStats::cpu_s sums.
double ThreadCpuSeconds();

struct TaskStats {
  uint64_t computed = 0;  // works that delivered a result
  uint64_t dropped = 0;   // works that found themselves stale, or pushed out of a full queue
  double cpu_s = 0.0;     // CPU time of the works that delivered (thread CPU time)
  uint64_t queued = 0;
};

// Worker threads at the SCHED_IDLE policy (Linux): the kernel runs them only on cores that
// nothing else wants, so the PVS workers and the transport never wait for a mask. Bounded: when
// more than `capacity` jobs wait, the one with the latest deadline is dropped, counted and not
// run (a session's box whose job was dropped gets no mask: the client draws the PVS there).
class MaskQueue : public TaskRunner {
 public:
  // `threads` workers (at least one); `idle_priority` false: ordinary threads (tests).
  explicit MaskQueue(unsigned threads, size_t capacity = 4096, bool idle_priority = true);
  ~MaskQueue() override;
  MaskQueue(const MaskQueue&) = delete;
  MaskQueue& operator=(const MaskQueue&) = delete;

  void Post(Work work, double deadline) override;
  TaskStats stats() const;
  // Whether the workers got the SCHED_IDLE policy (false: the kernel refused; they run at the
  // ordinary policy, lowest nice value they may set).
  bool idle_priority() const;

 private:
  void Loop();

  const size_t capacity_;
  const bool want_idle_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  bool stopping_ = false;
  uint64_t seq_ = 0;
  std::map<std::pair<double, uint64_t>, Work> tasks_;  // by (deadline, order posted)
  TaskStats stats_;
  bool idle_ok_ = true;
  std::vector<std::jthread> threads_;  // last: start after the members they read
};

}  // namespace vistream::server
