#include "client/cell_completion.h"

#include <algorithm>
#include <cstdint>
#include <map>
#include <optional>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace vistream::client {
namespace {

// The plain definition: scan the list every time.
struct Reference {
  std::map<uint32_t, double> held;  // id -> arrival
  std::map<uint32_t, std::pair<std::vector<uint32_t>, double>> lists;

  std::optional<double> CompleteAt(uint32_t cell) const {
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

TEST(CellCompletion, AgreesWithScanningTheListThroughArrivalsDropsAndNewLists) {
  std::mt19937 rng(7);
  for (int round = 0; round < 40; ++round) {
    CellCompletion h;
    Reference ref;
    std::vector<std::pair<uint32_t, double>> completions;
    h.on_complete = [&](uint32_t cell, double t) { completions.emplace_back(cell, t); };
    const uint32_t ids = 5 + round % 30;
    double t = 0.0;
    for (int step = 0; step < 400; ++step) {
      t += std::uniform_real_distribution<double>(0.0, 1.0)(rng);
      const uint32_t cell = rng() % 4;
      std::vector<bool> before(4);
      for (uint32_t c = 0; c < 4; ++c) before[c] = ref.CompleteAt(c).has_value();
      const bool list_step = rng() % 10 == 0;
      switch (list_step ? 0 : rng() % 9) {
        case 0: {  // a list, new or replacing the cell's
          std::vector<uint32_t> objects;
          for (uint32_t o = 0; o < ids; ++o) {
            if (rng() % 3 == 0) objects.push_back(o);
          }
          h.SetList(cell, objects, t);
          ref.lists[cell] = {objects, t};
          before[cell] = false;  // a list arriving whole completes its cell anew
          break;
        }
        case 1: {
          const uint32_t o = rng() % ids;
          h.Drop(o);
          ref.held.erase(o);
          break;
        }
        default: {  // arrivals, some of objects held already
          const uint32_t o = rng() % ids;
          h.Arrive(o, t);
          ref.held[o] = t;
          ASSERT_NE(h.Held(o), nullptr);
          EXPECT_EQ(h.Held(o)->arrival_s, t);
          break;
        }
      }
      // Asked as the simulator asks: after every message, about a few cells; the rule stated
      // once (CellComplete) says the same.
      for (uint32_t c = 0; c < 4; ++c) {
        ASSERT_EQ(h.CompleteAt(c), ref.CompleteAt(c)) << "round " << round << " step " << step << " cell " << c;
        ASSERT_EQ(h.Complete(c), CellComplete(h.List(c), [&](uint32_t o) { return ref.held.count(o) > 0; }));
        const std::vector<uint32_t>* list = h.List(c);
        ASSERT_EQ(h.Missing(c),
                  list == nullptr ? 0 : MissingObjects(*list, [&](uint32_t o) { return ref.held.count(o) > 0; }));
        // on_complete heard exactly the cells that became complete at this step.
        const bool heard = std::count(completions.begin(), completions.end(), std::make_pair(c, t)) > 0;
        ASSERT_EQ(heard, !before[c] && ref.CompleteAt(c).has_value()) << "round " << round << " step " << step;
      }
    }
  }
}

TEST(CellCompletion, ArriveSaysWhenAnObjectIsHeldForTheFirstTime) {
  CellCompletion h;
  EXPECT_TRUE(h.Arrive(3, 1.0));
  EXPECT_FALSE(h.Arrive(3, 2.0));  // again while held
  h.Drop(3);
  EXPECT_EQ(h.Held(3), nullptr);
  EXPECT_FALSE(h.Arrive(3, 3.0));  // again after a drop
  EXPECT_TRUE(h.Arrive(100, 3.0));
  EXPECT_EQ(h.Held(50), nullptr);
  size_t held = 0;
  h.ForEachHeld([&](uint32_t, const CellCompletion::Object&) { ++held; });
  EXPECT_EQ(held, 2u);
}

TEST(CellCompletion, ALaterArrivalOfAHeldObjectMovesTheCellsCompletionTime) {
  CellCompletion h;
  const std::vector<uint32_t> objects = {1, 2};
  h.SetList(0, objects, 0.5);
  h.Arrive(1, 1.0);
  h.Arrive(2, 2.0);
  EXPECT_EQ(h.CompleteAt(0), 2.0);
  h.Arrive(1, 5.0);  // sent again (after an eviction the client never saw, say)
  EXPECT_EQ(h.CompleteAt(0), 5.0);
  h.Drop(2);
  EXPECT_EQ(h.CompleteAt(0), std::nullopt);
  EXPECT_EQ(h.Missing(0), 1u);
  EXPECT_EQ(h.CompleteAt(9), std::nullopt);  // no list
  h.DropList(0);
  EXPECT_EQ(h.List(0), nullptr);
  EXPECT_FALSE(h.Complete(0));
}

// Levels of detail (issue 45): an object held coarser than a list asks completes the cell (it is
// drawn) and counts as coarse until the finer level arrives, which does not move the cell's
// completion time; dropping it makes it missing.
TEST(CellCompletion, ACoarserLevelCompletesTheCellAndCountsAsCoarse) {
  CellCompletion h;
  const std::vector<uint32_t> objects{1, 2}, levels{0, 2};
  h.SetList(7, objects, 0.5, levels);
  h.Arrive(1, 1.0, 3);  // coarser than 0
  h.Arrive(2, 2.0, 2);  // as asked
  EXPECT_TRUE(h.Complete(7));
  EXPECT_EQ(h.Coarse(7), 1u);
  EXPECT_EQ(*h.CompleteAt(7), 2.0);
  h.Arrive(1, 3.0, 0);  // the finer level
  EXPECT_EQ(h.Coarse(7), 0u);
  EXPECT_EQ(*h.CompleteAt(7), 2.0);
  EXPECT_EQ(h.Held(1)->level, 0u);
  h.Arrive(2, 4.0, 1);  // finer than asked: not coarse
  EXPECT_EQ(h.Coarse(7), 0u);
  // Another list naming object 2 at full detail sees it coarse.
  h.SetList(8, std::vector<uint32_t>{2}, 5.0, std::vector<uint32_t>{0});
  EXPECT_EQ(h.Coarse(8), 1u);
  h.Drop(2);
  EXPECT_EQ(h.Coarse(8), 0u);
  EXPECT_EQ(h.Missing(8), 1u);
  EXPECT_FALSE(h.Complete(7));
}

TEST(CellCompletion, AnEmptyListIsCompleteWhenItArrives) {
  CellCompletion h;
  std::vector<uint32_t> heard;
  h.on_complete = [&](uint32_t cell, double) { heard.push_back(cell); };
  h.SetList(4, {}, 1.0);
  EXPECT_TRUE(h.Complete(4));
  EXPECT_EQ(h.CompleteAt(4), 1.0);
  EXPECT_EQ(heard, (std::vector<uint32_t>{4}));
}

}  // namespace
}  // namespace vistream::client
