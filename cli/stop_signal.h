#ifndef VISTREAM_CLI_STOP_SIGNAL_H_
#define VISTREAM_CLI_STOP_SIGNAL_H_

// The rule the executables share for SIGINT/SIGTERM (vistream, vistream-server): the first
// signal asks for an orderly stop; a second one a second or more later stops at once (a stop
// that hangs can be cut short); one within the second is the first delivered twice (timeout(1)
// signals both the child and its process group) and does not count.

#include <time.h>

#include <atomic>
#include <cstdint>

namespace vistream::cli {

enum class StopSignal {
  kFirst,   // the first: `*stop` is now true; stop in order
  kEcho,    // within a second of the first: ignore it
  kSecond,  // a second or more after the first: stop at once
};

// What the signal now being handled is. Async-signal-safe (atomics and clock_gettime only):
// call it from the handler, with the same `stop` and `first_ns` for every signal.
inline StopSignal ClassifyStopSignal(std::atomic<bool>* stop, std::atomic<int64_t>* first_ns) {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);
  const int64_t now = int64_t{t.tv_sec} * 1000000000 + t.tv_nsec;
  if (!stop->exchange(true)) {
    first_ns->store(now);
    return StopSignal::kFirst;
  }
  return now - first_ns->load() < 1000000000 ? StopSignal::kEcho : StopSignal::kSecond;
}

}  // namespace vistream::cli

#endif  // VISTREAM_CLI_STOP_SIGNAL_H_
