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

// Cluster levels (issue 45): an object of a list that a held cluster chosen by the list stands
// for is drawable (not missing), complete when the cluster is held at the level the list asks or
// finer; the counts agree with scanning the list through random arrivals and drops of objects
// and clusters, and new lists.
TEST(CellCompletion, ClustersCountAsTheListsRuleSaysThroughRandomEvents) {
  std::mt19937 rng(11);
  auto pick = [&](uint32_t n) { return static_cast<uint32_t>(rng() % n); };
  constexpr uint32_t kObjects = 40, kClusters = 6, kCells = 4;
  // Fixed cluster membership: cluster c stands for objects c * 6 .. c * 6 + 8 (overlapping).
  auto members = [](uint32_t c) {
    std::vector<uint32_t> m;
    for (uint32_t o = c * 6; o < c * 6 + 9 && o < kObjects; ++o) m.push_back(o);
    return m;
  };
  CellCompletion h;
  std::map<uint32_t, uint32_t> held, held_clusters;  // id -> level
  struct List {
    std::vector<uint32_t> objects, levels, clusters, cluster_levels;
  };
  std::map<uint32_t, List> lists;
  size_t covered_checks = 0;
  for (int step = 0; step < 4000; ++step) {
    const uint32_t what = pick(10);
    if (what == 0) {
      List l;
      for (uint32_t o = 0; o < kObjects; ++o) {
        if (pick(2) == 0) {
          l.objects.push_back(o);
          l.levels.push_back(pick(3));
        }
      }
      // Chosen clusters share no object of the list.
      std::vector<bool> taken(kObjects, false);
      for (uint32_t c = 0; c < kClusters; ++c) {
        if (pick(2) != 0) continue;
        const std::vector<uint32_t> m = members(c);
        if (std::any_of(m.begin(), m.end(), [&](uint32_t o) { return taken[o]; })) continue;
        for (uint32_t o : m) taken[o] = true;
        l.clusters.push_back(c);
        l.cluster_levels.push_back(1 + pick(3));
      }
      const uint32_t cell = pick(kCells);
      h.SetList(cell, l.objects, step, l.levels, l.clusters, l.cluster_levels);
      lists[cell] = l;
    } else if (what < 5) {
      const uint32_t o = pick(kObjects), level = pick(4);
      h.Arrive(o, step, level);
      held[o] = level;
    } else if (what < 7) {
      const uint32_t o = pick(kObjects);
      h.Drop(o);
      held.erase(o);
    } else if (what < 9) {
      const uint32_t c = pick(kClusters), level = 1 + pick(3);
      const std::vector<uint32_t> m = members(c);
      h.ArriveCluster(c, step, level, m);
      held_clusters[c] = level;
    } else {
      const uint32_t c = pick(kClusters);
      h.DropCluster(c);
      held_clusters.erase(c);
    }
    for (const auto& [cell, l] : lists) {
      size_t missing = 0, coarse = 0;
      for (size_t k = 0; k < l.objects.size(); ++k) {
        const uint32_t o = l.objects[k];
        int own = 0;  // 0 missing, 1 coarse, 2 complete
        if (auto it = held.find(o); it != held.end()) own = it->second <= l.levels[k] ? 2 : 1;
        int by_cluster = 0;
        std::optional<uint32_t> covering;
        for (size_t c = 0; c < l.clusters.size(); ++c) {
          const std::vector<uint32_t> m = members(l.clusters[c]);
          auto it = held_clusters.find(l.clusters[c]);
          if (it == held_clusters.end() || !std::binary_search(m.begin(), m.end(), o)) continue;
          by_cluster = it->second <= l.cluster_levels[c] ? 2 : 1;
          covering = l.clusters[c];
        }
        EXPECT_EQ(h.CoveringCluster(cell, o), covering) << "cell " << cell << " object " << o;
        covered_checks += covering.has_value() ? 1 : 0;
        const int st = std::max(own, by_cluster);
        missing += st == 0 ? 1 : 0;
        coarse += st == 1 ? 1 : 0;
      }
      ASSERT_EQ(h.Missing(cell), missing) << "step " << step << " cell " << cell;
      ASSERT_EQ(h.Coarse(cell), coarse) << "step " << step << " cell " << cell;
      ASSERT_EQ(h.Complete(cell), missing == 0);
    }
  }
  EXPECT_GT(covered_checks, 1000u);
}

TEST(CellCompletion, AClusterCompletesTheObjectsItStandsForAndItsDropMakesThemMissing) {
  CellCompletion h;
  std::vector<double> heard;
  h.on_complete = [&](uint32_t, double t) { heard.push_back(t); };
  const std::vector<uint32_t> objects{1, 2, 3}, levels{1, 1, 0}, clusters{5}, cluster_levels{2};
  h.SetList(0, objects, 1.0, levels, clusters, cluster_levels);
  h.Arrive(3, 2.0);
  EXPECT_EQ(h.Missing(0), 2u);
  h.ArriveCluster(5, 3.0, 4, std::vector<uint32_t>{1, 2, 9});  // coarser than the list asks
  EXPECT_TRUE(h.Complete(0));
  EXPECT_EQ(h.Coarse(0), 2u);
  EXPECT_EQ(*h.CompleteAt(0), 3.0);
  EXPECT_EQ(heard, (std::vector<double>{3.0}));
  EXPECT_EQ(h.CoveringCluster(0, 1), 5u);
  EXPECT_FALSE(h.CoveringCluster(0, 3).has_value());
  h.ArriveCluster(5, 4.0, 2, std::vector<uint32_t>{1, 2, 9});  // as asked
  EXPECT_EQ(h.Coarse(0), 0u);
  ASSERT_NE(h.HeldCluster(5), nullptr);
  EXPECT_EQ(h.HeldCluster(5)->level, 2u);
  h.Arrive(1, 5.0, 1);  // held on its own too
  h.DropCluster(5);
  EXPECT_EQ(h.HeldCluster(5), nullptr);
  EXPECT_EQ(h.Missing(0), 1u);  // object 2
  EXPECT_FALSE(h.Complete(0));
  // A list that does not choose the cluster does not count it.
  h.ArriveCluster(5, 6.0, 1, std::vector<uint32_t>{1, 2, 9});
  h.SetList(1, std::vector<uint32_t>{2}, 7.0);
  EXPECT_EQ(h.Missing(1), 1u);
  EXPECT_TRUE(h.Complete(0));
}

}  // namespace
}  // namespace vistream::client
