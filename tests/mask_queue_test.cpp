// Where the server computes ε-masks (server/task_queue.h): earliest deadline first, stale work
// costing nothing, and threads that yield every core to ordinary work (the PVS workers).
#include "server/task_queue.h"

#include <atomic>
#include <chrono>
#include <future>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace vistream::server {
namespace {

TEST(MaskQueue, TheEarliestDeadlineRunsFirstAndStaleWorkIsCountedAsDropped) {
  MaskQueue q(1, 64, /*idle_priority=*/false);
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::mutex mu;
  std::vector<int> order;
  // The first job holds the one thread while the others queue.
  q.Post([released]() -> std::function<void()> { released.wait(); return [] {}; }, 0.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  for (int d : {30, 10, 20, 5}) {
    q.Post([&, d]() -> std::function<void()> {
      if (d == 5) return nullptr;  // found itself stale
      return [&, d] {
        std::lock_guard lock(mu);
        order.push_back(d);
      };
    }, d);
  }
  release.set_value();
  for (int k = 0; k < 500 && q.stats().computed + q.stats().dropped < 5; ++k) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  std::lock_guard lock(mu);
  EXPECT_EQ(order, (std::vector<int>{10, 20, 30}));
  EXPECT_EQ(q.stats().computed, 4u);
  EXPECT_EQ(q.stats().dropped, 1u);
}

TEST(MaskQueue, AFullQueueDropsTheLatestDeadline) {
  MaskQueue q(1, 2, /*idle_priority=*/false);
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::atomic<int> ran{0}, late{0};
  q.Post([released]() -> std::function<void()> { released.wait(); return nullptr; }, 0.0);
  std::this_thread::sleep_for(std::chrono::milliseconds(50));
  q.Post([&]() -> std::function<void()> { ++ran; return [] {}; }, 1.0);
  q.Post([&]() -> std::function<void()> { ++late; return [] {}; }, 9.0);
  q.Post([&]() -> std::function<void()> { ++ran; return [] {}; }, 2.0);  // pushes out the 9
  release.set_value();
  for (int k = 0; k < 500 && ran < 2; ++k) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_EQ(ran, 2);
  EXPECT_EQ(late, 0);
  EXPECT_EQ(q.stats().dropped, 2u);  // the 9 pushed out, the first job's empty delivery
}

// While ordinary threads keep every core busy (the PVS workers in the server), a mask thread
// gets next to no CPU; it runs once they are done.
TEST(MaskQueue, ItsThreadsGetNoCpuWhileOrdinaryThreadsWantEveryCore) {
  MaskQueue q(1);
  ASSERT_TRUE(q.idle_priority()) << "the kernel refused SCHED_IDLE: masks would compete with PVS work";
  const unsigned cores = std::max(1u, std::thread::hardware_concurrency());
  std::atomic<bool> busy_done{false}, started{false};
  std::atomic<double> cpu_while_busy{-1.0};
  std::promise<double> finished;
  std::vector<std::jthread> busy;
  for (unsigned k = 0; k < cores; ++k) {
    busy.emplace_back([&] {
      const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(1500);
      while (std::chrono::steady_clock::now() < until) {
      }
    });
  }
  // An ordinary thread doing what the mask thread does: the share it gets is what the mask
  // thread would get without SCHED_IDLE (about 1/(cores + 1) of the machine, less when other
  // processes load it too).
  std::atomic<double> control_cpu{-1.0};
  std::jthread control([&] {
    const double c0 = ThreadCpuSeconds();
    while (!busy_done) {
    }
    control_cpu = ThreadCpuSeconds() - c0;
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const auto posted = std::chrono::steady_clock::now();
  q.Post([&]() -> std::function<void()> {
    started = true;
    const double c0 = ThreadCpuSeconds();
    while (!busy_done) {
    }
    cpu_while_busy = ThreadCpuSeconds() - c0;
    return [&] { finished.set_value(ThreadCpuSeconds()); };
  }, 0.0);
  busy.clear();  // joins: about 1.4 s of every core taken
  const double busy_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - posted).count();
  busy_done = true;
  ASSERT_EQ(finished.get_future().wait_for(std::chrono::seconds(30)), std::future_status::ready);
  control.join();
  ASSERT_GT(busy_s, 1.0);
  ASSERT_GT(control_cpu.load(), 0.05 * busy_s) << "the ordinary control thread got no CPU either: nothing measured";
  EXPECT_LT(cpu_while_busy.load(), 0.25 * control_cpu.load())
      << "the mask thread ran " << cpu_while_busy.load() << " s, an ordinary thread " << control_cpu.load() << " s of "
      << busy_s << " s while every core was wanted";
}

}  // namespace
}  // namespace vistream::server
