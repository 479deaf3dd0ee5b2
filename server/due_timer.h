#pragma once
// One thread that runs callbacks when they fall due, on the steady clock: the server's link
// emulation wakes sessions whose emulated link has something due with it (server/session_reactor.h),
// and the Hello watchdog ends sessions that have not said Hello in time (server/admission.h).
// A callback must not block for long (it holds up the ones after it) and must not destroy the
// timer; what it reads must outlive the timer or be held weakly.

#include <condition_variable>
#include <cstdint>
#include <functional>
#include <mutex>
#include <queue>
#include <thread>
#include <vector>

namespace vistream::server {

class DueTimer {
 public:
  DueTimer();
  // Stops the thread; callbacks not yet due are dropped, never run.
  ~DueTimer();
  DueTimer(const DueTimer&) = delete;
  DueTimer& operator=(const DueTimer&) = delete;

  // Runs `run` on the timer's thread at `at_s` (seconds on the steady clock, as
  // std::chrono::steady_clock's time_since_epoch) or as soon after as the thread gets to it;
  // callbacks run one at a time, in the order they fall due (equal times: the order added).
  // Thread-safe.
  void At(double at_s, std::function<void()> run);

 private:
  struct Due {
    double at_s;
    uint64_t order;  // ties go in the order added
    std::function<void()> run;
    bool operator>(const Due& o) const { return at_s != o.at_s ? at_s > o.at_s : order > o.order; }
  };
  void Run();

  std::mutex mu_;
  std::condition_variable cv_;
  std::priority_queue<Due, std::vector<Due>, std::greater<Due>> due_;
  uint64_t added_ = 0;
  bool stop_ = false;
  std::thread thread_;  // last: starts after the members above exist
};

}  // namespace vistream::server
