#pragma once
// Progress and cancellation for long computations. A library never prints: it reports to the
// ProgressSink its caller passes (a terminal bar in the vistream tool, log lines or nothing in
// the server) and polls the caller's cancel flag.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>

namespace vistream::scenes {

// Where a computation's progress goes. Calls come from the computing thread, one task at a
// time per Progress; a sink shared between threads must guard itself.
class ProgressSink {
 public:
  virtual ~ProgressSink() = default;
  // A task `label` of `total` units starts.
  virtual void Start(std::string_view label, uint64_t total) = 0;
  // `done` of `total` units after `seconds`; `detail` is a short text (rates, estimates).
  // Called at most once per thousandth of the total.
  virtual void Update(std::string_view label, uint64_t done, uint64_t total, double seconds,
                      std::string_view detail) = 0;
  // The task ended after `seconds`: completed, or stopped early (cancelled or failed).
  virtual void End(std::string_view label, double seconds, bool completed) = 0;
};

// What a long computation takes from its caller. Both may be null: no report, no cancel.
struct RunControl {
  ProgressSink* progress = nullptr;
  const std::atomic<bool>* cancel = nullptr;

  bool Cancelled() const { return cancel != nullptr && cancel->load(std::memory_order_relaxed); }
};

// One task's progress: counts units, reports to the sink when the thousandth changes.
class Progress {
 public:
  Progress(const RunControl& run, std::string label, uint64_t total);
  // Ends the task as stopped early unless Finish() was called.
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void Advance(uint64_t units = 1);
  // A short text reported with the next update (rates, estimates).
  void SetDetail(std::string detail) { detail_ = std::move(detail); }
  // Marks the work complete (or, when cancelled, stopped early) and reports the elapsed time.
  void Finish();
  bool Cancelled() const { return run_.Cancelled(); }

 private:
  void Report(bool force);

  RunControl run_;
  std::string label_;
  std::string detail_;
  uint64_t total_;
  uint64_t done_ = 0;
  int last_permille_ = -1;
  bool ended_ = false;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace vistream::scenes
