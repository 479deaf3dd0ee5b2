#include "visibility/dual_ray_space.h"

#include <algorithm>
#include <numeric>

#include <gtest/gtest.h>

#include "scenes/random.h"
#include "tests/dual_ray_space_test_util.h"
#include "tests/test_util.h"
#include "visibility/exact_cover.h"

// The dual ray space's exact planar test (CGAL), and walls that lie on a face of the slab:
// the target's own walls and rows of houses that touch it (dual_ray_space_test.cpp has the
// known answers, the hard cases and the raster's row tests).

namespace vistream::visibility {
namespace {

using scenes::Aabb;
using scenes::Occluder25D;
using scenes::Scene;
using test_queries::Describe;
using test_queries::FindFreeSegment;
using test_queries::ForEachRandomPlanarProblem;
using test_queries::ForEachRandomQuery;
using test_queries::kCell;
using test_queries::RandomIn;
using test_queries::RandomQuery;
using test_queries::SegmentFree;
using vistream::testing::Box;
using vistream::testing::Rect;

// --- The exact planar test. ---

bool ExactVisible(const Scene& s, const Aabb& a, const Aabb& b, CellQueryStats* stats = nullptr) {
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  return drs.Visible(a, b, CellQueryOptions{.max_res = 16, .exact = true}, stats);
}

TEST(ExactCover, WallOccludesAndGapDoesNot) {
  Scene s;
  s.occluders.push_back(Rect(20, -200, 25, 200, 30));
  EXPECT_FALSE(ExactVisible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
  // Cut a 2 cm slot through the wall: far narrower than a 16-pixel raster resolves.
  s.occluders = {Rect(20, -200, 25, 5, 30), Rect(20, 5.02, 25, 200, 30)};
  CellQueryStats stats;
  EXPECT_TRUE(ExactVisible(s, kCell, Box(50, 0, 0, 60, 10, 10), &stats));
  EXPECT_GT(stats.exact_tests, 0u) << "decided before the exact test: the case tests nothing";
  // With the slot closed the two halves touch and fuse.
  s.occluders = {Rect(20, -200, 25, 5, 30), Rect(20, 5, 25, 200, 30)};
  EXPECT_FALSE(ExactVisible(s, kCell, Box(50, 0, 0, 60, 10, 10)));
}

// The raster is conservative, so it never covers what the exact test leaves open; what the
// exact test covers has no free ray among many sampled.
TEST(ExactCover, BracketsTheRasterAndAgreesWithSampledRays) {
  int exact_covered = 0, raster_full = 0, raster_missed = 0;
  CpuRaster raster;
  ForEachRandomPlanarProblem(1, 120, 1, [&](const RandomQuery& r, const PlanarProblem&, const Blockers& blockers) {
    const bool covered = ExactlyCovered(blockers);
    std::vector<uint32_t> rows(64), gap_rows;
    std::iota(rows.begin(), rows.end(), 0u);
    const bool full = raster.Full(blockers, 64, rows, &gap_rows);
    std::vector<uint8_t> pixels;
    raster.Draw(blockers, 16, &pixels);
    ASSERT_EQ(covered, ExactlyCovered(blockers, pixels, 16)) << "seed " << r.seed << ": starting from the raster's gaps";
    exact_covered += covered;
    raster_full += full;
    raster_missed += covered && !full;
    ASSERT_TRUE(covered || !full) << "seed " << r.seed << ": the raster covers what the exact test does not";
    if (!covered) return;
    for (int k = 0; k < 2000; ++k) {
      const double u = r.rng.Uniform(0, 1), v = r.rng.Uniform(0, 1);
      ASSERT_FALSE(blockers.FreeRay(u, v)) << "seed " << r.seed << ": covered, yet ray (" << u << ", " << v << ") is free";
    }
  });
  EXPECT_GT(exact_covered, 20) << "too few covered cases to mean anything";
  EXPECT_GT(raster_full, 10);
  // The exact test is worth having only if it decides cases the raster cannot.
  EXPECT_GT(raster_missed, 0);
}

TEST(ExactCover, NeverOccludedWhileAFreeSegmentExists) {
  int occluded = 0, cases = 0;
  ForEachRandomQuery(301, 400, 3, [&](const RandomQuery& r) {
    ++cases;
    const bool exact = r.drs.Visible(kCell, r.b, CellQueryOptions{.max_res = 32, .exact = true});
    // Anything the raster proves hidden, the exact test proves too.
    if (!r.drs.Visible(kCell, r.b, CellQueryOptions{.max_res = 256})) {
      ASSERT_FALSE(exact) << "seed " << r.seed << ": " << Describe(r.s, kCell, r.b);
    }
    if (exact) return;
    ++occluded;
    const auto free = FindFreeSegment(kCell, r.b, r.s, r.seed * 31 + r.q, 3000);
    ASSERT_FALSE(free.has_value()) << "seed " << r.seed << " query " << r.q << ": occluded, but a segment is free. "
                                   << Describe(r.s, kCell, r.b);
  });
  EXPECT_GT(occluded, cases / 10) << occluded << " of " << cases;
}

// --- Walls on a face of the slab: the target's own walls, and rows that touch it. ---

// The oracle for a kd node's box B: a segment from a point of A to the first point of B on
// its way, clear of every prism except those inside B (a prism inside B can meet such a
// segment only at its end, where it is B itself that is reached). So a ray that ends on the
// target's own wall counts as seeing it, as it should.
std::optional<std::pair<glm::dvec3, glm::dvec3>> FindSegmentReachingB(const Aabb& a, const Aabb& b,
                                                                      const std::vector<Occluder25D>& occluders,
                                                                      scenes::Rng& rng, int samples) {
  std::vector<Occluder25D> outside;
  for (const Occluder25D& oc : occluders) {
    bool inside = oc.height <= b.max.z;
    for (const glm::dvec2& p : oc.footprint) inside &= p.x >= b.min.x && p.x <= b.max.x && p.y >= b.min.y && p.y <= b.max.y;
    if (!inside) outside.push_back(oc);
  }
  for (int k = 0; k < samples; ++k) {
    glm::dvec3 p = RandomIn(a, rng), q = RandomIn(b, rng);
    if (k % 2 == 0) p.z = a.max.z;  // the upper rim sees the most (Observation 1)
    // Where the segment first enters B (slab intersection); p inside B cannot happen: A and B
    // are separable in the queries below.
    double t_enter = 0.0;
    const glm::dvec3 d = q - p;
    for (int axis = 0; axis < 3; ++axis) {
      if (d[axis] == 0.0) continue;
      const double t0 = (b.min[axis] - p[axis]) / d[axis], t1 = (b.max[axis] - p[axis]) / d[axis];
      t_enter = std::max(t_enter, std::min(t0, t1));
    }
    const glm::dvec3 end = p + d * t_enter;
    if (testing::SegmentClearOfPrisms(p, end, outside, 1e-6)) return std::pair{p, end};
  }
  return std::nullopt;
}

// A dead-end street of random width and depth: an end building whose sides touch two rows that
// run towards the viewer, each row split into houses sharing walls, a few free-standing
// buildings; on the integer grid, or moved off it (x 1.1 + 0.123: shared walls stay shared).
// `targets` gets the kd-node-like boxes to test: each building's, the end building with a row
// house, and random boxes.
Scene RandomCloseScene(scenes::Rng& rng, bool off_grid, std::vector<Aabb>* targets) {
  Scene s;
  const double xe = std::floor(rng.Uniform(40, 70)), half = std::floor(rng.Uniform(3, 12));
  const double yc = std::floor(rng.Uniform(-10, 10)), depth = std::floor(rng.Uniform(1, 8));
  const double row = std::floor(rng.Uniform(1, 10)), length = std::floor(rng.Uniform(10, 35));
  auto rect = [](double x0, double y0, double x1, double y1, double h) { return Rect(x0, y0, x1, y1, h); };
  s.occluders.push_back(rect(xe, yc - half, xe + depth, yc + half, std::floor(rng.Uniform(3, 30))));  // the end
  for (const double side : {-1.0, 1.0}) {
    const double y0 = side < 0 ? yc - half - row : yc + half, y1 = y0 + row;
    // The row reaches the end building's back, or stops at its front, or beyond it.
    double x = xe - length;
    const double stop = xe + (rng.Chance(0.5) ? depth : 0.0) + (rng.Chance(0.3) ? 5.0 : 0.0);
    while (x < stop) {
      const double next = std::min(stop, x + std::floor(rng.Uniform(3, 9)));
      s.occluders.push_back(rect(x, y0, next, y1, std::floor(rng.Uniform(3, 25))));
      x = next;
    }
  }
  for (int k = 0; k < 4; ++k) {
    const double x = std::floor(rng.Uniform(15, 90)), y = std::floor(rng.Uniform(-60, 60));
    const Occluder25D oc = rect(x, y, x + std::floor(rng.Uniform(1, 8)), y + std::floor(rng.Uniform(1, 8)),
                                std::floor(rng.Uniform(1, 30)));
    bool clear = true;  // free-standing: apart from everything placed so far
    for (const Occluder25D& o : s.occluders) {
      clear &= oc.footprint[1].x < o.footprint[0].x || o.footprint[1].x < oc.footprint[0].x ||
               oc.footprint[2].y < o.footprint[0].y || o.footprint[2].y < oc.footprint[0].y;
    }
    if (clear) s.occluders.push_back(oc);
  }
  if (off_grid) {
    for (Occluder25D& oc : s.occluders) {
      for (glm::dvec2& p : oc.footprint) p = p * 1.1 + glm::dvec2(0.123, -0.0456);
    }
  }
  auto box_of = [](const Occluder25D& oc) {
    Aabb box;
    for (const glm::dvec2& p : oc.footprint) box.Extend(glm::dvec3(p, 0.0));
    box.Extend(glm::dvec3(oc.footprint[0], oc.height));
    return box;
  };
  for (const Occluder25D& oc : s.occluders) targets->push_back(box_of(oc));
  Aabb pair = box_of(s.occluders[0]);
  pair.Extend(box_of(s.occluders[1]));
  targets->push_back(pair);
  for (int k = 0; k < 2; ++k) {
    Aabb b = testing::RandomGridBox(rng);
    if (off_grid) b = Aabb{b.min * glm::dvec3(1.1, 1.1, 1) + glm::dvec3(0.123, -0.0456, 0), b.max * glm::dvec3(1.1, 1.1, 1) + glm::dvec3(0.123, -0.0456, 0)};
    targets->push_back(b);
  }
  return s;
}

TEST(DualRaySpace, TheEndOfADeadEndStreetIsSeenFromTheStreet) {
  // ../shared/cases/visibility/street8's kind, by hand: W closes the street; the rows S and N
  // touch its sides. From a cell in the street, rays end on W's street-facing wall.
  Scene s;
  s.occluders = {Rect(-1, -10, 0, 10, 16), Rect(-1, -11, 60, -10, 20.5), Rect(-1, 10, 60, 11, 20.5)};
  const Aabb w = Box(-1, -10, 0, 0, 10, 16);
  for (double size : {2.0, 4.0, 8.0, 16.0}) {
    const Aabb cell = Box(24, -size, 0.5, 24 + size, 0, 2.5);
    for (bool exact : {false, true}) {
      const OccluderSet set = OccluderSet::Build(s);
      DualRaySpace drs(set);
      EXPECT_TRUE(drs.Visible(cell, w, CellQueryOptions{.max_res = 128, .exact = exact}))
          << size << " m cell, " << (exact ? "exact" : "cpu");
      EXPECT_TRUE(drs.Visible(cell, w, CellQueryOptions{.max_res = 128, .free_ray_test = false, .exact = exact}))
          << size << " m cell without free rays, " << (exact ? "exact" : "cpu");
    }
  }
  // A wall standing just in front of W's face, inside the slab, still hides it.
  s.occluders.push_back(Rect(1, -10, 1.5, 10, 16));
  const OccluderSet set = OccluderSet::Build(s);
  DualRaySpace drs(set);
  EXPECT_FALSE(drs.Visible(Box(24, -8, 0.5, 32, 0, 2.5), w, CellQueryOptions{}));
}

TEST(DualRaySpace, APieceOnAFaceOfTheSlabBlocksNothing) {
  // Pieces that lie on A's face, on B's face, or reach T only where the slab ends: no interior
  // in the open slab, so no blocker; pieces a hair inside do block.
  const Aabb a = kCell, b = Box(50, 0, 0, 60, 10, 10);
  PlanarProblem pr;
  ASSERT_TRUE(MakePlanarProblem(a, b, 0, 1.0, &pr));
  double lo, hi;
  EXPECT_FALSE(pr.PieceStrip(30, 50, 55, &lo, &hi));    // B's own wall, on B's face
  EXPECT_FALSE(pr.PieceStrip(30, 5, 10, &lo, &hi));     // behind A's face
  EXPECT_TRUE(pr.PieceStrip(30, 49.99, 55, &lo, &hi));  // reaching 1 cm into the slab
  EXPECT_FALSE(pr.PieceStrip(30, 50, 50, &lo, &hi));    // a zero-thickness wall on B's face
  EXPECT_TRUE(pr.PieceStrip(30, 30, 30, &lo, &hi));     // one across the slab
  // The ceiling rises from A's top (2.5 m) to B's (10 m): a 5 m piece reaches it only over
  // the first part of the slab; standing wholly beyond that part, it blocks nothing.
  ASSERT_TRUE(pr.BlockingStrip(5, &lo, &hi));
  EXPECT_FALSE(pr.PieceStrip(5, hi, hi + 3, &lo, &hi));
}

// The widened property: viewcells from 2 to 300 m, in front of and beside dead-end streets,
// targets that are buildings whose walls lie on the target's face and touch the rows, on the
// grid and off it, with the cpu raster at every resolution and the exact test.
TEST(DualRaySpace, NeverOccludedWhileASegmentReachesBWhateverTheCellSize) {
  int occluded = 0, cases = 0;
  for (uint64_t seed = 1; seed <= 600; ++seed) {
    scenes::Rng rng(seed);
    std::vector<Aabb> targets;
    const bool off_grid = seed % 2 == 0;
    const Scene s = RandomCloseScene(rng, off_grid, &targets);
    const OccluderSet set = OccluderSet::Build(s);
    DualRaySpace drs(set);
    static constexpr double kSizes[] = {2, 4, 8, 16, 50, 100, 300};
    for (int c = 0; c < 3; ++c) {
      const double size = kSizes[rng.Below(std::size(kSizes))];
      // Down the street towards the end building, or anywhere in front of the scene.
      const double x1 = c == 0 ? std::floor(rng.Uniform(20, 38)) : std::floor(rng.Uniform(-20, 12));
      const double y0 = c == 0 ? std::floor(rng.Uniform(-4, 2)) : std::floor(rng.Uniform(-40, 30));
      Aabb a = Box(x1 - (c == 0 ? std::min(size, 8.0) : size), y0, 0.5, x1, y0 + (c == 0 ? 2 : size), 2.5);
      if (off_grid) a = Aabb{a.min * glm::dvec3(1.1, 1.1, 1) + glm::dvec3(0.123, -0.0456, 0), a.max * glm::dvec3(1.1, 1.1, 1) + glm::dvec3(0.123, -0.0456, 0)};
      for (const Aabb& b : targets) {
        bool separable = false;
        for (int axis = 0; axis < 2; ++axis) separable |= a.max[axis] < b.min[axis] || b.max[axis] < a.min[axis];
        if (!separable) continue;
        const uint32_t res = 16u << rng.Below(5);
        for (bool exact : {false, true}) {
          ++cases;
          if (drs.Visible(a, b, CellQueryOptions{.max_res = res, .exact = exact})) continue;
          ++occluded;
          const auto free = FindSegmentReachingB(a, b, s.occluders, rng, 600);
          ASSERT_FALSE(free.has_value()) << "seed " << seed << " res " << res << (exact ? " exact" : " cpu")
                                         << ": occluded, but the segment (" << free->first.x << ", " << free->first.y
                                         << ", " << free->first.z << ") - (" << free->second.x << ", "
                                         << free->second.y << ", " << free->second.z << ") reaches B. "
                                         << Describe(s, a, b);
        }
      }
    }
  }
  // The test means something only if occlusion is found often.
  EXPECT_GT(occluded, cases / 20) << occluded << " of " << cases;
}

// A tall house and a low one share a wall along the shaft; the sloping ceiling clips the low
// one to its near part. Fused, they block as the hull of the tall house and the low house's
// clipped part: five corners, one of them the shared wall's far end, which the tall house
// must bring though the low house also holds it (and may own it) before clipping.
TEST(DualRaySpace, AFusedGroupKeepsASharedCornerThatClippingTookFromItsOwner) {
  const Aabb a = Box(-10, 0, 0, 0, 10, 2), b = Box(30, 0, 0, 40, 10, 12);
  PlanarProblem pr;
  ASSERT_TRUE(MakePlanarProblem(a, b, 0, 1.0, &pr));
  ASSERT_DOUBLE_EQ(pr.alpha, 2.0);  // T: z = 2 + p / 4 in the frame at A's corner (-10, 0)
  ASSERT_DOUBLE_EQ(pr.beta, 0.25);
  bool low_owns = false;
  for (const bool low_below : {false, true}) {
    // Planar p = x + 10: both houses span p 12..30; the low one (7 m) rises above T for p < 20.
    const double tall_y = low_below ? 4 : -1, low_y = low_below ? -1 : 4;
    Scene s;
    s.occluders = {Rect(2, tall_y, 20, tall_y + 5, 20), Rect(2, low_y, 20, low_y + 5, 7)};
    const OccluderSet set = OccluderSet::Build(s);
    ASSERT_EQ(set.pieces().size(), 2u);
    const uint32_t low = set.pieces()[0].height == 7 ? 0 : 1;
    const glm::dvec2 far_end(20, 4);
    const auto points = set.PointsOf(1 - low);
    const size_t k = static_cast<size_t>(std::find(points.begin(), points.end(), far_end) - points.begin());
    ASSERT_LT(k, points.size());
    low_owns |= set.PointOwnersOf(1 - low)[k] == low;
    DualRaySpace drs(set);
    drs.BuildBlockers(pr);
    ASSERT_EQ(drs.blockers().groups.size(), 1u) << "the houses fuse along their wall";
    const Blocker& g = drs.blockers().groups[0];
    // Hull in (p, q): (12, q0), (30, q0), (30, 4) - the far end -, (20, q1), (12, q1) and the
    // like when the low house is below.
    EXPECT_EQ(g.end - g.begin, 5u) << (low_below ? "low house below" : "low house above");
  }
  EXPECT_TRUE(low_owns) << "neither layout let the clipped house own the shared corner";
}

}  // namespace
}  // namespace vistream::visibility
