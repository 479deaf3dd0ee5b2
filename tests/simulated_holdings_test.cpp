#include "server/simulated_holdings.h"

#include <algorithm>
#include <cstdint>
#include <map>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>

namespace vistream::server {
namespace {

// The plain definition: scan the list every time.
struct Reference {
  std::map<uint32_t, double> held;  // id -> arrival
  std::map<visibility::CellId, std::pair<std::vector<uint32_t>, double>> lists;

  std::optional<double> CompleteAt(visibility::CellId cell) const {
    auto it = lists.find(cell);
    if (it == lists.end()) return std::nullopt;
    double when = it->second.second;
    for (uint32_t o : it->second.first) {
      auto h = held.find(o);
      if (h == held.end()) return std::nullopt;
      when = std::max(when, h->second);
    }
    return when;
  }
};

TEST(SimulatedHoldings, CompleteAtAgreesWithScanningTheListThroughArrivalsEvictionsAndNewLists) {
  std::mt19937 rng(7);
  for (int round = 0; round < 40; ++round) {
    SimulatedHoldings h;
    Reference ref;
    const uint32_t ids = 5 + round % 30;
    double t = 0.0;
    for (int step = 0; step < 400; ++step) {
      t += std::uniform_real_distribution<double>(0.0, 1.0)(rng);
      const visibility::CellId cell = rng() % 4;
      switch (rng() % 10) {
        case 0: {  // a list, new or replacing the cell's
          std::vector<uint32_t> objects;
          for (uint32_t o = 0; o < ids; ++o) {
            if (rng() % 3 == 0) objects.push_back(o);
          }
          h.SetList(cell, objects, t);
          ref.lists[cell] = {objects, t};
          break;
        }
        case 1: {
          const uint32_t o = rng() % ids;
          h.Evict(o);
          ref.held.erase(o);
          break;
        }
        default: {  // arrivals, some of objects held already
          const uint32_t o = rng() % ids;
          h.Receive(o, t, o + 1);
          ref.held[o] = t;
          ASSERT_NE(h.Of(o), nullptr);
          EXPECT_EQ(h.Of(o)->triangles, o + 1);
          break;
        }
      }
      // Asked as the simulator asks: after every message, about a few cells.
      for (visibility::CellId c = 0; c < 4; ++c) {
        ASSERT_EQ(h.CompleteAt(c), ref.CompleteAt(c)) << "round " << round << " step " << step << " cell " << c;
      }
    }
  }
}

TEST(SimulatedHoldings, ReceiveSaysWhenAnObjectIsHeldForTheFirstTimeInTheRun) {
  SimulatedHoldings h;
  EXPECT_TRUE(h.Receive(3, 1.0, 10));
  EXPECT_FALSE(h.Receive(3, 2.0, 10));  // again while held
  h.Evict(3);
  EXPECT_EQ(h.Of(3), nullptr);
  EXPECT_FALSE(h.Receive(3, 3.0, 10));  // again after an eviction
  EXPECT_TRUE(h.Receive(100, 3.0, 1));
  EXPECT_EQ(h.Of(50), nullptr);
  EXPECT_GE(h.IdBound(), 101u);
}

TEST(SimulatedHoldings, ALaterArrivalOfAHeldObjectMovesTheCellsCompletionTime) {
  SimulatedHoldings h;
  const std::vector<uint32_t> objects = {1, 2};
  h.SetList(0, objects, 0.5);
  h.Receive(1, 1.0, 1);
  h.Receive(2, 2.0, 1);
  EXPECT_EQ(h.CompleteAt(0), 2.0);
  h.Receive(1, 5.0, 1);  // sent again (after an eviction the client never saw, say)
  EXPECT_EQ(h.CompleteAt(0), 5.0);
  h.Evict(2);
  EXPECT_EQ(h.CompleteAt(0), std::nullopt);
  EXPECT_EQ(h.CompleteAt(9), std::nullopt);  // no list
}

}  // namespace
}  // namespace vistream::server
