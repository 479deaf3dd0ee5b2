// Blockers::BandCoveredSlanted: a band of RS covered by the blockers' trapezoids where their
// rectangles (BandCovered) leave a sliver at each seam of steep blockers.
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "scenes/random.h"
#include "tests/dual_ray_space_test_util.h"
#include "tests/test_util.h"
#include "visibility/conservative_raster.h"
#include "visibility/dual_ray_space.h"
#include "visibility/exact_cover.h"

namespace vistream::visibility {
namespace {

using scenes::Aabb;
using scenes::Occluder25D;
using scenes::Scene;

using vistream::testing::Box;
using vistream::testing::Rect;

using test_queries::ForEachRandomPlanarProblem;
using test_queries::kCell;
using test_queries::RandomQuery;
const Aabb kB = Box(100, 0, 0, 110, 10, 1);

// Two 20 m walls just before B, staggered: the first stops at y = 5.02 (x 90 to 90.1), the
// second starts at y = 4.98 (x 90.3 to 90.4). A segment from A's face (x = 10) to B's (x = 100)
// climbs at most 10 m in 90 m, so over the 0.2 m between the walls it moves less than 0.023 m:
// one that passes the first wall above 5.02 meets the second above 4.98. Everything is hidden,
// yet in RS both seams are steep (dU/dv about -8) and overlap by only 0.026 to 0.05 in u, less
// than the 0.063 a band of 1/128 slants by.
Scene StaggeredWalls(double second_wall_x, const glm::dvec2& shift = glm::dvec2(0.0)) {
  Scene s;
  s.occluders = {Rect(90, -50, 90.1, 5.02, 20), Rect(second_wall_x, 4.98, second_wall_x + 0.1, 60, 20)};
  for (Occluder25D& oc : s.occluders) {
    for (glm::dvec2& p : oc.footprint) p += shift;
  }
  return s;
}

Aabb Shifted(const Aabb& b, const glm::dvec2& shift) {
  return Aabb{b.min + glm::dvec3(shift, 0), b.max + glm::dvec3(shift, 0)};
}

TEST(BandCoveredSlanted, StaggeredWallsNearBAreHiddenAt128WhereRectanglesLeaveGaps) {
  for (const glm::dvec2 shift : {glm::dvec2(0.0), glm::dvec2(500000, 5000000)}) {
    const Scene s = StaggeredWalls(90.3, shift);
    const OccluderSet set = OccluderSet::Build(s);
    DualRaySpace drs(set);
    const Aabb a = Shifted(kCell, shift), b = Shifted(kB, shift);
    PlanarProblem pr;
    ASSERT_TRUE(MakePlanarProblem(a, b, 0, 1.0, &pr));
    drs.BuildBlockers(pr);
    const Blockers& blockers = drs.blockers();
    ASSERT_EQ(blockers.groups.size(), 2u) << "the walls do not touch: two blockers";
    // The case is the one meant: rectangles leave bands open at 128, trapezoids close them.
    std::vector<std::pair<double, double>> spans;
    SlantedScratch slanted;
    int open_rectangles = 0;
    for (uint32_t j = 0; j < 128; ++j) {
      const double v0 = j / 128.0, v1 = (j + 1) / 128.0;
      if (blockers.BandCovered(v0, v1, &spans)) continue;
      ++open_rectangles;
      EXPECT_TRUE(blockers.BandCoveredSlanted(v0, v1, &slanted)) << "band " << j << "/128";
    }
    EXPECT_GT(open_rectangles, 3);
    EXPECT_TRUE(ExactlyCovered(blockers));
    EXPECT_TRUE(drs.PlanarOccluded(pr, CellQueryOptions{.max_res = 128}, nullptr));
    EXPECT_TRUE(drs.PlanarOccluded(pr, CellQueryOptions{.max_res = 128, .free_ray_test = false}, nullptr));
    EXPECT_FALSE(drs.Visible(a, b, CellQueryOptions{.max_res = 128}));
  }
}

// With the second wall 5 m further on, the segment from (10, 9.9) to (100, 4.5) passes the
// first wall at y = 5.09 and the second at y = 4.8, under it: B is visible, and stays so.
TEST(BandCoveredSlanted, StaggeredWallsWithRoomBetweenLeaveBVisible) {
  const Scene s = StaggeredWalls(95.0);
  ASSERT_TRUE(testing::SegmentClearOfPrisms(glm::dvec3(10, 9.9, 2), glm::dvec3(100, 4.5, 0.9), s.occluders, 1e-6));
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  for (uint32_t res : {16u, 128u, 256u}) {
    EXPECT_TRUE(drs.Visible(kCell, kB, CellQueryOptions{.max_res = res})) << res;
    EXPECT_TRUE(drs.Visible(kCell, kB, CellQueryOptions{.max_res = res, .free_ray_test = false})) << res;
  }
}

// Blockers made by hand in RS: each vertex is a root line u = -(a + c v) / b with b = 1.
Blockers HandMade(const std::vector<std::vector<std::pair<double, double>>>& blockers_ac) {
  Blockers blockers;
  for (const auto& vertices : blockers_ac) {
    Blocker g;
    g.begin = static_cast<uint32_t>(blockers.coeffs.size());
    for (const auto& [a, c] : vertices) blockers.coeffs.push_back(BlockerCoeff::Of(a, 1.0, c));
    g.end = static_cast<uint32_t>(blockers.coeffs.size());
    blockers.groups.push_back(g);
  }
  blockers.eps = 1e-12;
  blockers.PrepareBands();
  return blockers;
}

// Over the band v in [1/2, 1/2 + 1/128], s = 128 (v - 1/2): blocker P spans u from -10 to
// 0.03 - 0.12 s, blocker Q from 0.02 - 0.1 s to 10. Up to s = 1/2 P reaches Q (0.03 - 0.12 s
// >= 0.02 - 0.1 s); from s = 1/5 on Q starts at u <= 0 by itself. So [0, 1] is covered at each
// v, by P then Q below s = 1/2 and by Q alone above s = 1/5, while no one chain serves the whole
// band (at s = 1, P ends at -0.09, before Q's -0.08). With P ending at 0.05 - 0.3 s instead,
// P leaves Q at s = 0.15 before Q reaches u = 0 at s = 0.2: the rays with s = 0.175 and
// 0 <= u < 0.0025 are free.
TEST(BandCoveredSlanted, ASeamThatCrossesTheEdgeOfRsIsCoveredPiecewise) {
  const double v0 = 0.5, v1 = 0.5 + 1.0 / 128;
  // Root 0.03 - 0.12 s = 0.03 - 15.36 (v - 1/2): a = -(0.03 + 7.68), c = 15.36.
  const Blockers covered = HandMade({{{10.0, 0.0}, {-7.71, 15.36}}, {{-6.42, 12.8}, {-10.0, 0.0}}});
  std::vector<std::pair<double, double>> spans;
  SlantedScratch slanted;
  EXPECT_FALSE(covered.BandCovered(v0, v1, &spans));
  EXPECT_TRUE(covered.BandCoveredSlanted(v0, v1, &slanted));
  for (int m = 0; m <= 64; ++m) {
    double u = 0;
    EXPECT_FALSE(covered.FreeOnLine(v0 + (v1 - v0) * m / 64.0, &spans, &u)) << m;
  }
  // Root 0.05 - 0.3 s = 0.05 - 38.4 (v - 1/2): a = -(0.05 + 19.2), c = 38.4.
  const Blockers open = HandMade({{{10.0, 0.0}, {-19.25, 38.4}}, {{-6.42, 12.8}, {-10.0, 0.0}}});
  EXPECT_FALSE(open.BandCoveredSlanted(v0, v1, &slanted));
  EXPECT_TRUE(open.FreeRay(0.001, v0 + 0.175 * (v1 - v0)));
}

// Sound: where the trapezoids cover a band, no line v = const in it holds a free ray
// (FreeOnLine finds one whenever one exists), at its edges, on a grid and at random v.
TEST(BandCoveredSlanted, CoversOnlyBandsWithoutAFreeRay) {
  int covered = 0, only_slanted = 0, open = 0;
  std::vector<std::pair<double, double>> spans;
  SlantedScratch slanted;
  ForEachRandomPlanarProblem(1, 200, 3, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    const uint64_t seed = r.seed;
    scenes::Rng& rng = r.rng;
    for (uint32_t n : {1u, 4u, 16u, 64u, 128u}) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t j = static_cast<uint32_t>(rng.Below(n));
        const double v0 = static_cast<double>(j) / n, v1 = (j + 1.0) / n;
        if (!blockers.BandCoveredSlanted(v0, v1, &slanted)) {
          ++open;
          continue;
        }
        ++covered;
        only_slanted += !blockers.BandCovered(v0, v1, &spans);
        for (int m = 0; m <= 40; ++m) {
          const double v = m <= 32 ? v0 + (v1 - v0) * m / 32.0 : rng.Uniform(v0, v1);
          double u = 0;
          ASSERT_FALSE(blockers.FreeOnLine(v, &spans, &u))
              << "seed " << seed << ", band " << j << "/" << n << ": ray (" << u << ", " << v << ") is free";
        }
      }
    }
  });
  EXPECT_GT(covered, 300);
  EXPECT_GT(open, 300);
  EXPECT_GT(only_slanted, 20) << "trapezoids never covered what rectangles leave open";
}

// The trapezoids hold the rectangles, and on each half of a band they hold the band's own
// (each side is then the root line of the vertex extreme at that half's edge): covered
// wherever BandCovered is, and on both halves of a covered band. So refining never loses a
// covered row, and a finer max_res is never less precise.
TEST(BandCoveredSlanted, HoldsWhereRectanglesCoverAndOnBothHalves) {
  int rect = 0, halves = 0;
  std::vector<std::pair<double, double>> spans;
  SlantedScratch slanted;
  ForEachRandomPlanarProblem(1, 200, 3, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    const uint64_t seed = r.seed;
    scenes::Rng& rng = r.rng;
    for (uint32_t n : {1u, 2u, 8u, 32u, 128u}) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t j = static_cast<uint32_t>(rng.Below(n));
        const double v0 = static_cast<double>(j) / n, v1 = (j + 1.0) / n, vm = (j + 0.5) / n;
        if (blockers.BandCovered(v0, v1, &spans)) {
          ++rect;
          ASSERT_TRUE(blockers.BandCoveredSlanted(v0, v1, &slanted)) << "seed " << seed << ", band " << j << "/" << n;
        }
        if (!blockers.BandCoveredSlanted(v0, v1, &slanted)) continue;
        ++halves;
        ASSERT_TRUE(blockers.BandCoveredSlanted(v0, vm, &slanted)) << "seed " << seed << ", band " << j << "/" << n;
        ASSERT_TRUE(blockers.BandCoveredSlanted(vm, v1, &slanted)) << "seed " << seed << ", band " << j << "/" << n;
      }
    }
  });
  EXPECT_GT(rect, 300);
  EXPECT_GT(halves, 300);
}

}  // namespace
}  // namespace vistream::visibility
