#pragma once
// Progress for long computations: a bar on a terminal, a log line per 10% otherwise, and a
// cancellation flag the computation polls.

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>

namespace vistream::scenes {

class Progress {
 public:
  // `total` units of work; `cancel` (may be null) is polled by Cancelled().
  Progress(std::string label, uint64_t total, const std::atomic<bool>* cancel = nullptr);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  void Advance(uint64_t units = 1);
  // A short text shown after the bar (rates, estimates); printed with the next update.
  void SetDetail(std::string detail) { detail_ = std::move(detail); }
  // Marks the work complete and prints the elapsed time.
  void Finish();
  bool Cancelled() const { return cancel_ != nullptr && cancel_->load(std::memory_order_relaxed); }

  // Silences every Progress in this process (tests, --json output on a terminal).
  static void SetQuiet(bool quiet);

 private:
  void Print(bool final_line);

  std::string label_;
  std::string detail_;
  uint64_t total_;
  uint64_t done_ = 0;
  int last_decile_ = -1;
  int last_permille_ = -1;
  bool finished_ = false;
  bool terminal_;
  const std::atomic<bool>* cancel_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace vistream::scenes
