#include "server/pvs_scheduler.h"

#include <atomic>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace vistream::server {
namespace {

// A compute function the test releases cell by cell, recording the order cells start in.
class Gate {
 public:
  CellPvs Compute(CellId cell) {
    {
      std::unique_lock lock(mu_);
      started_.push_back(cell);
      cv_.notify_all();
      cv_.wait(lock, [&] { return open_; });
    }
    CellPvs p;
    p.objects = {cell, cell + 1000};
    return p;
  }
  void Open() {
    std::lock_guard lock(mu_);
    open_ = true;
    cv_.notify_all();
  }
  void WaitStarted(size_t n) {
    std::unique_lock lock(mu_);
    cv_.wait(lock, [&] { return started_.size() >= n; });
  }
  std::vector<CellId> started() {
    std::lock_guard lock(mu_);
    return started_;
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  bool open_ = false;
  std::vector<CellId> started_;
};

struct Arrivals {
  std::mutex mu;
  std::condition_variable cv;
  std::vector<std::pair<uint64_t, CellId>> got;
  PvsScheduler::Done For(uint64_t who) {
    return [this, who](const CellPvsPtr& p) {
      std::lock_guard lock(mu);
      got.emplace_back(who, p->cell);
      cv.notify_all();
    };
  }
  void WaitFor(size_t n) {
    std::unique_lock lock(mu);
    cv.wait(lock, [&] { return got.size() >= n; });
  }
};

TEST(PvsScheduler, TwoSessionsAskingForOneCellWaitForOneComputation) {
  Gate gate;
  std::atomic<int> computed{0};
  PvsScheduler s([&](CellId c, unsigned) { ++computed; return gate.Compute(c); }, 1, 1 << 20);
  Arrivals a;
  EXPECT_EQ(s.Request(1, 7, 1.0, a.For(1)), nullptr);
  gate.WaitStarted(1);
  EXPECT_EQ(s.Request(2, 7, 2.0, a.For(2)), nullptr);  // joins the running job
  gate.Open();
  a.WaitFor(2);
  EXPECT_EQ(computed.load(), 1);
  // Now cached: answered at once, no callback.
  const CellPvsPtr cached = s.Request(3, 7, 3.0, a.For(3));
  ASSERT_NE(cached, nullptr);
  EXPECT_EQ(cached->objects, (std::vector<uint32_t>{7, 1007}));
  EXPECT_EQ(s.stats().computed, 1u);
  EXPECT_EQ(s.stats().cache_hits, 2u);
}

TEST(PvsScheduler, EarliestDeadlineFirstAndDroppedWhenNoOneWaits) {
  Gate gate;
  PvsScheduler s([&](CellId c, unsigned) { return gate.Compute(c); }, 1, 1 << 20);
  Arrivals a;
  s.Request(1, 100, 0.0, a.For(1));  // occupies the one worker
  gate.WaitStarted(1);
  s.Request(1, 1, 9.0, a.For(1));
  s.Request(1, 2, 5.0, a.For(1));
  s.Request(1, 3, 7.0, a.For(1));
  s.Request(2, 1, 1.0, a.For(2));  // another session needs cell 1 soon: it moves up
  s.Request(1, 4, 6.0, a.For(1));
  s.Cancel(1, 4);                  // turned away: dropped before it starts
  s.Cancel(1, 3);
  s.Request(1, 3, 8.0, a.For(1));  // asked again later, with a new deadline
  gate.Open();
  a.WaitFor(5);  // 100, then 1 (twice), 2, 3
  EXPECT_EQ(gate.started(), (std::vector<CellId>{100, 1, 2, 3}));
  EXPECT_EQ(s.stats().dropped, 2u);
  for (const auto& [who, cell] : a.got) EXPECT_NE(cell, 4u);
}

TEST(PvsScheduler, TheCacheKeepsItsByteBudgetLeastRecentlyUsedOut) {
  PvsScheduler s([](CellId c, unsigned) { CellPvs p; p.objects.assign(1000, c); return p; }, 2,
                 3 * (sizeof(CellPvs) + 4000));
  Arrivals a;
  for (CellId c = 0; c < 3; ++c) s.Request(1, c, 0.0, a.For(1));
  a.WaitFor(3);
  // Two workers finish 0, 1 and 2 in any order, so the test sets the recency itself:
  // 1 is used least recently, then 2, then 0.
  ASSERT_NE(s.Cached(1), nullptr);
  ASSERT_NE(s.Cached(2), nullptr);
  ASSERT_NE(s.Cached(0), nullptr);
  s.Request(1, 3, 0.0, a.For(1));
  a.WaitFor(4);
  EXPECT_NE(s.Cached(0), nullptr);
  EXPECT_NE(s.Cached(3), nullptr);
  EXPECT_NE(s.Cached(2), nullptr);
  EXPECT_EQ(s.Cached(1), nullptr);  // the least recently used went
  EXPECT_LE(s.stats().cache_bytes, 3 * (sizeof(CellPvs) + 4000));
}

TEST(PvsScheduler, StoppingDropsWhatWaits) {
  Gate gate;
  Arrivals a;
  {
    PvsScheduler s([&](CellId c, unsigned) { return gate.Compute(c); }, 1, 1 << 20);
    s.Request(1, 1, 0.0, a.For(1));
    gate.WaitStarted(1);
    for (CellId c = 2; c < 10; ++c) s.Request(1, c, 1.0, a.For(1));
    gate.Open();
  }  // joins: the running job finishes, the waiting ones may be dropped
  EXPECT_LE(a.got.size(), 9u);
  EXPECT_GE(a.got.size(), 1u);
}

}  // namespace
}  // namespace vistream::server
