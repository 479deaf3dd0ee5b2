#include "visibility/dual_ray_space.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "scenes/random.h"
#include "tests/dual_ray_space_test_util.h"
#include "tests/test_util.h"

namespace vistream::visibility {
namespace {

using scenes::Aabb;
using scenes::Occluder25D;
using scenes::Scene;

using vistream::testing::Box;
using vistream::testing::Rect;
using test_queries::Describe;
using test_queries::FindFreeSegment;
using test_queries::ForEachRandomPlanarProblem;
using test_queries::ForEachRandomQuery;
using test_queries::kCell;
using test_queries::RandomQuery;
using test_queries::SegmentFree;
using test_queries::Translated;

bool Visible(const Scene& s, const Aabb& a, const Aabb& b, uint32_t res = 128) {
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  return drs.Visible(a, b, CellQueryOptions{.max_res = res});
}


// --- Known answers. ---

TEST(DualRaySpace, WallBetweenCellsOccludes) {
  Scene s;
  s.occluders.push_back(Rect(20, -200, 25, 200, 30));
  EXPECT_FALSE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
  // A wall lower than the line over it does not.
  s.occluders[0].height = 3;
  EXPECT_TRUE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
}

TEST(DualRaySpace, GapWiderThanAPixelMakesBVisible) {
  Scene s;
  s.occluders.push_back(Rect(20, -200, 25, 4, 30));
  s.occluders.push_back(Rect(20, 6, 25, 200, 30));
  EXPECT_TRUE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
  // Closing the gap to nothing (touching walls) occludes again: the walls fuse.
  s.occluders[1] = Rect(20, 4, 25, 200, 30);
  EXPECT_FALSE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
}

TEST(DualRaySpace, TerracedHousesFuseWithoutCracks) {
  // Forty houses of different heights sharing walls: one blocker, no crack at any wall.
  Scene s;
  for (int k = 0; k < 40; ++k) s.occluders.push_back(Rect(20, -200 + 10 * k, 28, -190 + 10 * k, 25 + k % 7));
  EXPECT_FALSE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 12)));
  EXPECT_FALSE(Visible(s, kCell, Box(40, -30, 0, 90, 40, 20)));
}

TEST(DualRaySpace, ZeroThicknessWallOccludes) {
  Scene s;
  s.occluders.push_back(Occluder25D{{{20, -200}, {20, 200}, {20, -200}}, 30, 0});  // zero area
  EXPECT_FALSE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
  // Repeated vertices do no harm either.
  s.occluders[0] = Occluder25D{{{20, -200}, {25, -200}, {25, -200}, {25, 200}, {20, 200}, {20, 200}}, 30, 0};
  EXPECT_FALSE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
}

TEST(DualRaySpace, TouchingOrOverlappingBoxesAreVisible) {
  Scene s;
  s.occluders.push_back(Rect(-1000, -1000, 1000, 1000, 500));  // everything inside a building
  EXPECT_TRUE(Visible(s, kCell, Box(10, 0, 0, 20, 10, 10)));   // B touches A
  EXPECT_TRUE(Visible(s, kCell, Box(5, 5, 0, 20, 20, 10)));    // B overlaps A
}

TEST(DualRaySpace, NonConvexFootprintOccludesAndItsNotchStaysOpen) {
  Scene s;
  // A U-shaped building open towards A: a ray can enter the notch but not get through.
  s.occluders.push_back(Occluder25D{{{20, -100}, {40, -100}, {40, 100}, {20, 100}, {20, 8}, {35, 8}, {35, 2}, {20, 2}}, 40, 0});
  EXPECT_FALSE(Visible(s, kCell, Box(60, 0, 0, 70, 10, 10)));
  // B inside the notch is visible through its mouth.
  EXPECT_TRUE(Visible(s, kCell, Box(22, 3, 0, 30, 7, 10)));
}

TEST(DualRaySpace, CpuRasterIsConservativeAtEveryResolution) {
  Scene s;
  s.occluders.push_back(Rect(20, -200, 25, 200, 30));
  for (uint32_t res : {16u, 32u, 64u, 128u, 256u}) {
    EXPECT_FALSE(Visible(s, kCell, Box(50, 0, 0, 60, 10, 10), res)) << res;
  }
}

// --- Hard cases. ---

TEST(DualRaySpace, TinyAndHugeViewcells) {
  Scene s;
  s.occluders.push_back(Rect(20, -5000, 25, 5000, 30));
  EXPECT_FALSE(Visible(s, Box(0, 0, 1, 0.5, 0.5, 3), Box(50, 0, 0, 60, 10, 10)));
  Scene wide;
  wide.occluders.push_back(Rect(2100, -50000, 2200, 50000, 300));
  EXPECT_FALSE(Visible(wide, Box(0, 0, 0.5, 2000, 2000, 2.5), Box(2500, 0, 0, 2600, 100, 50)));
}

TEST(DualRaySpace, VeryTallVeryCloseBIsSeenOverAWall) {
  // T nearly vertical: the wall is far below the line from A's rim to B's top.
  Scene s;
  s.occluders.push_back(Rect(10.5, -100, 11, 100, 50));
  EXPECT_TRUE(Visible(s, kCell, Box(11.5, 0, 0, 12, 10, 5000)));
}

TEST(DualRaySpace, TenThousandOccludersInOneShaft) {
  Scene s;
  scenes::Rng rng(7);
  for (int k = 0; k < 10000; ++k) {
    const double x = rng.Uniform(15, 985), y = rng.Uniform(-200, 200);
    s.occluders.push_back(Rect(x, y, x + rng.Uniform(0.1, 2), y + rng.Uniform(0.1, 2), rng.Uniform(1, 40)));
  }
  const Aabb b = Box(990, 0, 0, 1000, 10, 10);
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  CellQueryStats stats;
  const bool visible = drs.Visible(kCell, b, {}, &stats);
  // Without the free-ray shortcut every blocker is built: the same answer, the long way.
  CellQueryStats slow;
  EXPECT_EQ(drs.Visible(kCell, b, CellQueryOptions{.free_ray_test = false}, &slow), visible);
  EXPECT_GT(slow.gathered, 100u);
  if (!visible) {
    const auto free = FindFreeSegment(kCell, b, s, 1, 20000);
    EXPECT_FALSE(free.has_value()) << "occluded, yet a free segment exists";
  }
}

// Every hard case at once: the planar problems and blockers hold no NaN or infinity, the answer
// is conservative (cpu raster and exact test alike), and moving everything to
// (500000, 5000000) changes nothing.
TEST(DualRaySpace, HardCasesStayFiniteConservativeAndTranslationInvariant) {
  struct Case {
    std::string name;
    Scene scene;
    Aabb a, b;
  };
  std::vector<Case> cases;
  auto add = [&](std::string name, std::vector<Occluder25D> occluders, Aabb a, Aabb b) {
    Scene s;
    s.occluders = std::move(occluders);
    cases.push_back({std::move(name), std::move(s), a, b});
  };
  const Aabb b = Box(50, 0, 0, 60, 10, 10);
  std::vector<Occluder25D> terrace;
  for (int k = 0; k < 40; ++k) terrace.push_back(Rect(20, -200 + 10 * k, 28, -190 + 10 * k, 25 + k % 7));
  add("shared walls", terrace, kCell, b);
  // The shaft's sides are y = 0 and y = 10 here: walls lying along them, and one across.
  add("edges collinear with the shaft's sides", {Rect(20, -5, 30, 0, 30), Rect(20, 10, 30, 15, 30), Rect(32, 0, 33, 10, 30)},
      kCell, b);
  // Corner-to-corner rays of the shaft pass through these vertices.
  add("rays through vertices", {Rect(25, 2.5, 30, 5, 30), Rect(25, 5, 30, 7.5, 30), Rect(30, 0, 35, 2.5, 30)}, kCell, b);
  add("zero-thickness wall", {Occluder25D{{{20, -200}, {20, 200}, {20, -200}}, 30, 0}}, kCell, b);
  add("repeated vertices", {Occluder25D{{{20, -200}, {25, -200}, {25, -200}, {25, 200}, {20, 200}, {20, 200}}, 30, 0}},
      kCell, b);
  add("zero-area footprint", {Occluder25D{{{20, 0}, {20, 0}, {20, 0}}, 30, 0}, Rect(22, -100, 23, 100, 30)}, kCell, b);
  add("B touching A", {Rect(-1000, -1000, 1000, 1000, 500)}, kCell, Box(10, 0, 0, 20, 10, 10));
  add("0.5 m viewcell", {Rect(20, -5000, 25, 5000, 30)}, Box(0, 0, 1, 0.5, 0.5, 3), b);
  add("2 km viewcell", {Rect(2100, -50000, 2200, 50000, 300)}, Box(0, 0, 0.5, 2000, 2000, 2.5),
      Box(2500, 0, 0, 2600, 100, 50));
  add("T almost vertical", {Rect(10.5, -100, 11, 100, 50)}, kCell, Box(11.5, 0, 0, 12, 10, 5000));
  std::vector<Occluder25D> many;
  scenes::Rng rng(7);
  for (int k = 0; k < 10000; ++k) {
    const double x = rng.Uniform(15, 985), y = rng.Uniform(-200, 200);
    many.push_back(Rect(x, y, x + rng.Uniform(0.1, 2), y + rng.Uniform(0.1, 2), rng.Uniform(1, 40)));
  }
  add("10,000 occluders in one shaft", many, kCell, Box(990, 0, 0, 1000, 10, 10));

  const glm::dvec3 t(500000, 5000000, 0);
  int occluded = 0;
  for (const Case& c : cases) {
    const OccluderSet set = OccluderSet::Build(c.scene);
    const OccluderSet far_set = OccluderSet::Build(Translated(c.scene, glm::dvec2(t)));
    DualRaySpace drs(set), far_drs(far_set);
    const Aabb fa{c.a.min + t, c.a.max + t}, fb{c.b.min + t, c.b.max + t};
    for (int axis = 0; axis < 2; ++axis) {
      for (double sign : {1.0, -1.0}) {
        PlanarProblem pr;
        if (!MakePlanarProblem(c.a, c.b, axis, sign, &pr)) continue;
        for (double x : {pr.origin.x, pr.origin.y, pr.x1, pr.x2, pr.r1, pr.l1, pr.r2, pr.l2, pr.alpha, pr.beta}) {
          ASSERT_TRUE(std::isfinite(x)) << c.name;
        }
        drs.BuildBlockers(pr);
        ASSERT_TRUE(std::isfinite(drs.blockers().eps)) << c.name;
        for (const BlockerCoeff& k : drs.blockers().coeffs) {
          ASSERT_TRUE(std::isfinite(k.a) && std::isfinite(k.b) && std::isfinite(k.c) && std::isfinite(k.inv_b)) << c.name;
        }
        for (const Blocker& g : drs.blockers().groups) ASSERT_FALSE(std::isnan(g.width)) << c.name;
      }
    }
    for (bool exact : {false, true}) {
      const CellQueryOptions options{.max_res = 128, .exact = exact};
      const bool visible = drs.Visible(c.a, c.b, options);
      EXPECT_EQ(visible, far_drs.Visible(fa, fb, options)) << c.name << (exact ? ", exact" : ", cpu");
      if (visible) continue;
      ++occluded;
      EXPECT_FALSE(FindFreeSegment(c.a, c.b, c.scene, 3, 4000).has_value())
          << c.name << (exact ? ", exact" : ", cpu") << ": occluded, but a segment is free";
    }
  }
  EXPECT_GE(occluded, 10);
}

// --- The property test: never "occluded" while a free segment exists. ---


TEST(DualRaySpace, NeverOccludedWhileAFreeSegmentExists) {
  int occluded = 0, cases = 0;
  ForEachRandomQuery(1, 300, 4, [&](const RandomQuery& r) {
    const uint32_t res = 16u << r.rng.Below(5);
    ++cases;
    const bool visible = r.drs.Visible(kCell, r.b, CellQueryOptions{.max_res = res});
    // The accelerations (traced free rays, free-ray tests at gaps) never change an answer.
    ASSERT_EQ(visible, r.drs.Visible(kCell, r.b, CellQueryOptions{.max_res = res, .free_ray_test = false}))
        << "seed " << r.seed << " query " << r.q << ": " << Describe(r.s, kCell, r.b);
    if (visible) return;
    ++occluded;
    const auto free = FindFreeSegment(kCell, r.b, r.s, r.seed * 31 + r.q, 3000);
    ASSERT_FALSE(free.has_value()) << "seed " << r.seed << " query " << r.q << " res " << res
                                   << ": occluded, but the segment (" << free->first.x << ", " << free->first.y
                                   << ", " << free->first.z << ") - (" << free->second.x << ", " << free->second.y
                                   << ", " << free->second.z << ") is free. " << Describe(r.s, kCell, r.b);
  });
  // The test means something only if occlusion is found often.
  EXPECT_GT(occluded, cases / 10) << occluded << " of " << cases;
}

TEST(DualRaySpace, TranslatingEverythingFarAwayChangesNothing) {
  const glm::dvec2 t(500000, 5000000);
  const glm::dvec3 t3(t, 0);
  for (uint64_t seed = 1; seed <= 60; ++seed) {
    scenes::Rng rng(seed);
    const Scene s = testing::RandomGridScene(rng);
    const Scene far = Translated(s, t);
    const OccluderSet near_set = OccluderSet::Build(s), far_set = OccluderSet::Build(far);
    DualRaySpace near_drs(near_set), far_drs(far_set);
    for (int q = 0; q < 4; ++q) {
      const double bx = std::floor(rng.Uniform(30, 90)), by = std::floor(rng.Uniform(-30, 40));
      const Aabb b = Box(bx, by, 0, bx + 5, by + 5, 10);
      const Aabb a2{kCell.min + t3, kCell.max + t3}, b2{b.min + t3, b.max + t3};
      CellQueryStats sn, sf;
      EXPECT_EQ(near_drs.Visible(kCell, b, {}, &sn), far_drs.Visible(a2, b2, {}, &sf)) << "seed " << seed;
      EXPECT_EQ(sn.raster_rows, sf.raster_rows) << "seed " << seed;
    }
  }
}

// --- Row-by-row refinement and the free-line search. ---

// PlanarOccluded refines only the rows with a gap, one at a time; it must decide exactly as
// whole rasters at 16, 32 and 64 would: occluded iff at one resolution every row is full or
// covered by the blockers together (BandCovered, or BandCoveredSlanted). With the free-ray
// search on, it must still agree: a free ray leaves a gap at every resolution.
TEST(DualRaySpace, RowByRowRefinementDecidesLikeWholeRasters) {
  int occluded = 0, visible = 0, union_helped = 0, slant_helped = 0;
  CpuRaster raster;
  std::vector<uint8_t> pixels;
  std::vector<std::pair<double, double>> scratch;
  SlantedScratch slanted;
  ForEachRandomPlanarProblem(1, 150, 3, [&](const RandomQuery& r, const PlanarProblem& pr, const Blockers& blockers) {
    bool covered = false, raster_full = false;
    for (uint32_t n = 16; n <= 64 && !covered && !blockers.groups.empty(); n *= 2) {
      raster.Draw(blockers, n, &pixels);
      raster_full |= std::count(pixels.begin(), pixels.end(), 1) == static_cast<long>(pixels.size());
      covered = true;
      for (uint32_t j = 0; j < n && covered; ++j) {
        const bool row_full = std::count(pixels.begin() + j * n, pixels.begin() + (j + 1) * n, 1) == n;
        const double v0 = static_cast<double>(j) / n, v1 = (j + 1.0) / n;
        covered = row_full || blockers.BandCovered(v0, v1, &scratch);
        if (!covered && blockers.BandCoveredSlanted(v0, v1, &slanted)) covered = true, ++slant_helped;
      }
    }
    ASSERT_TRUE(covered || !raster_full) << "seed " << r.seed;
    union_helped += covered && !raster_full;
    (covered ? occluded : visible)++;
    const CellQueryOptions plain{.max_res = 64, .free_ray_test = false}, searching{.max_res = 64};
    ASSERT_EQ(covered, r.drs.PlanarOccluded(pr, plain, nullptr)) << "seed " << r.seed;
    ASSERT_EQ(covered, r.drs.PlanarOccluded(pr, searching, nullptr)) << "seed " << r.seed;
  });
  EXPECT_GT(occluded, 50);
  EXPECT_GT(visible, 50);
  EXPECT_GT(union_helped, 5) << "blockers together never covered what none covers alone";
  EXPECT_GT(slant_helped, 5) << "trapezoids never covered a band that rectangles leave open";
}

// BandCovered is sound: where it says a band is covered, no ray in it is free.
TEST(Blockers, BandCoveredOnlyWhereNoRayIsFree) {
  int covered = 0, open = 0;
  std::vector<std::pair<double, double>> scratch;
  ForEachRandomPlanarProblem(1, 100, 3, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    for (uint32_t n : {4u, 16u, 64u}) {
      const uint32_t j = static_cast<uint32_t>(r.rng.Below(n));
      const double v0 = static_cast<double>(j) / n, v1 = (j + 1.0) / n;
      if (!blockers.BandCovered(v0, v1, &scratch)) {
        ++open;
        continue;
      }
      ++covered;
      for (int m = 0; m < 300; ++m) {
        const double u = r.rng.Uniform(0, 1), v = r.rng.Uniform(v0, v1);
        ASSERT_FALSE(blockers.FreeRay(u, v)) << "seed " << r.seed << ": ray (" << u << ", " << v << ") is free";
      }
    }
  });
  EXPECT_GT(covered, 100);
  EXPECT_GT(open, 100);
}

// BandCovered's early exit (bins marked as spans arrive) answers exactly as the plain sweep
// over every blocker's RowBounds, on bands of every height down to one row at 256.
TEST(Blockers, BandCoveredAnswersAsTheSortedSweep) {
  int covered = 0, open = 0;
  std::vector<std::pair<double, double>> scratch, spans;
  auto sweep = [&](const Blockers& blockers, double v0, double v1) {
    spans.clear();
    for (const Blocker& g : blockers.groups) {
      const auto [lo, hi] = blockers.RowBounds(g, v0, v1);
      if (lo <= hi && hi >= 0.0 && lo <= 1.0) spans.emplace_back(lo, hi);
    }
    std::sort(spans.begin(), spans.end());
    double cur = 0.0;
    for (const auto& [lo, hi] : spans) {
      if (lo > cur) return false;
      cur = std::max(cur, hi);
      if (cur >= 1.0) return true;
    }
    return false;
  };
  ForEachRandomPlanarProblem(1, 150, 3, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    for (uint32_t n : {1u, 4u, 16u, 64u, 128u, 256u}) {
      for (int k = 0; k < 4; ++k) {
        const uint32_t j = static_cast<uint32_t>(r.rng.Below(n));
        const double v0 = static_cast<double>(j) / n, v1 = (j + 1.0) / n;
        const bool expected = sweep(blockers, v0, v1);
        ASSERT_EQ(expected, blockers.BandCovered(v0, v1, &scratch)) << "seed " << r.seed << ", band " << j << "/" << n;
        (expected ? covered : open)++;
      }
    }
  });
  EXPECT_GT(covered, 300);
  EXPECT_GT(open, 300);
}

// A blocker that BandCovered skips for a band (Blocker::v1_max, v0_min) has no span there: its
// RowBounds leave nothing of [0, 1]. And skipping happens.
TEST(Blockers, BandSkipsOnlyBlockersWithoutASpan) {
  int skipped = 0, kept = 0;
  ForEachRandomPlanarProblem(1, 150, 3, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    for (const Blocker& g : blockers.groups) {
      for (uint32_t n : {16u, 128u, 256u}) {
        for (int k = 0; k < 3; ++k) {
          const uint32_t j = static_cast<uint32_t>(r.rng.Below(n));
          const double v0 = static_cast<double>(j) / n, v1 = (j + 1.0) / n;
          if (!(v1 > g.v1_max || v0 < g.v0_min)) {
            ++kept;
            continue;
          }
          ++skipped;
          const auto [lo, hi] = blockers.RowBounds(g, v0, v1);
          ASSERT_FALSE(lo <= hi && hi >= 0.0 && lo <= 1.0)
              << "seed " << r.seed << ", band " << j << "/" << n << ": span [" << lo << ", " << hi << "] skipped";
        }
      }
    }
  });
  EXPECT_GT(skipped, 500);
  EXPECT_GT(kept, 500);
}

// A hint only saves time: whatever line it names, the answer stays the same. A witness comes
// only with "visible", and as a hint it proves the same query visible again at once.
TEST(DualRaySpace, HintsNeverChangeAnAnswerAndWitnessesProveVisibility) {
  int witnessed = 0, hinted_queries = 0;
  ForEachRandomQuery(1, 120, 4, [&](const RandomQuery& r) {
    FreeLine witness;
    const bool visible = r.drs.Visible(kCell, r.b, {}, nullptr, {}, &witness);
    if (witness.valid) {
      ++witnessed;
      ASSERT_TRUE(visible) << "seed " << r.seed;
      ASSERT_TRUE(r.drs.Visible(kCell, r.b, {}, nullptr, witness)) << "seed " << r.seed;
      // It is a free ray (u, v) of the planar problem it came from: on A's face and B's.
      int free_in = 0;
      for (int axis = 0; axis < 2; ++axis) {
        for (double sign : {1.0, -1.0}) {
          PlanarProblem pr;
          if (!MakePlanarProblem(kCell, r.b, axis, sign, &pr)) continue;
          const glm::dvec2 from = pr.PlanarFromScene(witness.from), to = pr.PlanarFromScene(witness.to);
          if (std::abs(from.x - pr.x1) > 1e-9 || std::abs(to.x - pr.x2) > 1e-9) continue;
          r.drs.BuildBlockers(pr);
          free_in += r.drs.blockers().FreeRay((from.y - pr.r1) / (pr.l1 - pr.r1), (to.y - pr.r2) / (pr.l2 - pr.r2));
        }
      }
      EXPECT_EQ(free_in, 1) << "seed " << r.seed << ": the witness is no free ray";
    }
    for (int h = 0; h < 4; ++h) {
      const FreeLine hint{{r.rng.Uniform(-5, 15), r.rng.Uniform(-10, 20)},
                          {r.rng.Uniform(20, 100), r.rng.Uniform(-40, 60)}, true};
      ++hinted_queries;
      ASSERT_EQ(visible, r.drs.Visible(kCell, r.b, {}, nullptr, hint)) << "seed " << r.seed << ", hint " << h;
    }
  });
  EXPECT_GT(witnessed, 100);
  EXPECT_GT(hinted_queries, 1000);
}

// FreeOnLine finds a free ray on the line v = const whenever sampling finds one, and any ray it
// returns is free.
TEST(Blockers, FreeOnLineFindsAFreeRayWheneverOneExists) {
  int found = 0, none = 0;
  std::vector<std::pair<double, double>> scratch;
  ForEachRandomPlanarProblem(1, 100, 3, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    for (int k = 0; k < 8; ++k) {
      const double v = k < 2 ? k : r.rng.Uniform(0, 1);
      double u = -1;
      if (blockers.FreeOnLine(v, &scratch, &u)) {
        ++found;
        ASSERT_TRUE(u >= 0 && u <= 1 && blockers.FreeRay(u, v)) << "seed " << r.seed << ", v " << v << ", u " << u;
        continue;
      }
      ++none;
      for (int m = 0; m <= 400; ++m) {
        const double w = m / 400.0;
        ASSERT_FALSE(blockers.FreeRay(w, v)) << "seed " << r.seed << ": ray (" << w << ", " << v << ") is free";
      }
    }
  });
  EXPECT_GT(found, 100);
  EXPECT_GT(none, 100);
}

}  // namespace
}  // namespace vistream::visibility
