#pragma once
// Work spread over a few threads, for the batch calls a server makes (several viewcells or
// neighbourhoods at once).

#include <algorithm>
#include <atomic>
#include <thread>
#include <vector>

namespace vistream::visibility {

// Calls worker(i) for every i in [0, count) on up to `threads` threads (0: one per core), the
// calling thread included. make_worker() is called once per thread and returns that thread's
// worker, so per-thread state lives in it. Each i goes to exactly one thread.
template <typename MakeWorker>
void ParallelFor(size_t count, unsigned threads, MakeWorker&& make_worker) {
  if (count == 0) return;
  if (threads == 0) threads = std::max(1u, std::thread::hardware_concurrency());
  threads = std::min<unsigned>(threads, static_cast<unsigned>(std::min<size_t>(count, ~0u)));
  std::atomic<size_t> next{0};
  auto work = [&] {
    auto worker = make_worker();
    for (size_t i = next++; i < count; i = next++) worker(i);
  };
  std::vector<std::jthread> pool;
  for (unsigned t = 1; t < threads; ++t) pool.emplace_back(work);
  work();
}

}  // namespace vistream::visibility
