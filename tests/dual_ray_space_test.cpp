#include "visibility/dual_ray_space.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "scenes/random.h"
#include "tests/dual_ray_space_test_util.h"
#include "tests/test_util.h"
#include "visibility/exact_cover.h"

namespace vistream::visibility {
namespace {

using scenes::Aabb;
using scenes::Occluder25D;
using scenes::Scene;

// The oracle: 3D segments against the prisms, by brute force (tests/test_util.h).
bool SegmentFree(const glm::dvec3& p, const glm::dvec3& q, const std::vector<Occluder25D>& occluders) {
  return testing::SegmentClearOfPrisms(p, q, occluders, 1e-6);
}

glm::dvec3 RandomIn(const Aabb& box, scenes::Rng& rng) {
  return {rng.Uniform(box.min.x, box.max.x), rng.Uniform(box.min.y, box.max.y), rng.Uniform(box.min.z, box.max.z)};
}

// Samples segments from A to B (corners, edges and random points); returns a free one.
std::optional<std::pair<glm::dvec3, glm::dvec3>> FindFreeSegment(const Aabb& a, const Aabb& b, const Scene& s,
                                                                 uint64_t seed, int samples) {
  scenes::Rng rng(seed);
  auto corner = [](const Aabb& box, int k) {
    return glm::dvec3(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z);
  };
  for (int i = 0; i < 8; ++i) {
    for (int j = 0; j < 8; ++j) {
      if (SegmentFree(corner(a, i), corner(b, j), s.occluders)) return std::pair{corner(a, i), corner(b, j)};
    }
  }
  for (int k = 0; k < samples; ++k) {
    glm::dvec3 p = RandomIn(a, rng), q = RandomIn(b, rng);
    p.z = a.max.z;  // the upper rims see the most (Observation 1); sample there mostly
    if (k % 3 == 0) q.z = b.max.z;
    if (SegmentFree(p, q, s.occluders)) return std::pair{p, q};
  }
  return std::nullopt;
}

Scene Translated(Scene s, const glm::dvec2& t) {
  for (auto& oc : s.occluders) {
    for (auto& p : oc.footprint) p += t;
  }
  return s;
}

using vistream::testing::Box;
using vistream::testing::Rect;
using test_queries::ForEachRandomPlanarProblem;
using test_queries::ForEachRandomQuery;
using test_queries::kCell;
using test_queries::RandomQuery;

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

std::string Describe(const Scene& s, const Aabb& a, const Aabb& b) {
  std::ostringstream out;
  out.precision(17);
  out << "A = [" << a.min.x << ", " << a.min.y << ", " << a.min.z << "] - [" << a.max.x << ", " << a.max.y << ", "
      << a.max.z << "], B = [" << b.min.x << ", " << b.min.y << ", " << b.min.z << "] - [" << b.max.x << ", "
      << b.max.y << ", " << b.max.z << "], " << s.occluders.size() << " occluders:";
  for (const auto& oc : s.occluders) {
    out << " {h " << oc.height;
    for (const auto& p : oc.footprint) out << " (" << p.x << ", " << p.y << ")";
    out << "}";
  }
  return out.str();
}

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
