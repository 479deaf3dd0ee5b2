#include "visibility/agvs.h"
#include "visibility/agvs_internal.h"

#include <gtest/gtest.h>

#include "scenes/random.h"

// The span of a line inside the view space, which decides both which cells a sample's free
// segment adds its objects to and which of its rays can be left uncast (agvs_internal.h).

namespace vistream::visibility {
namespace {

bool Inside(const Aabb& b, const glm::dvec3& p) {
  for (int k = 0; k < 3; ++k) {
    if (p[k] < b.min[k] || p[k] > b.max[k]) return false;
  }
  return true;
}

// A slab like a city's view space (wide and low) and random lines, many of them from points
// above it, on both sides of it and through it: the points the span holds are inside, the
// points past either end of it are not, and a line it says misses has no point inside.
TEST(AgvsViewSpace, SpanHoldsExactlyTheLinesPointsInsideTheBox) {
  const Aabb vs{glm::dvec3(0, 0, 0.5), glm::dvec3(400, 300, 2.5)};
  scenes::Rng rng(7);
  int met = 0, missed = 0;
  for (int n = 0; n < 20000; ++n) {
    const glm::dvec3 o(rng.Uniform() * 600 - 100, rng.Uniform() * 500 - 100, rng.Uniform() * 30 - 2);
    glm::dvec3 d = UniformDirection(rng);
    if (n % 7 == 0) d.z = 0.0;  // level lines: the span comes from x and y alone
    double a = 0.0, b = 0.0;
    if (!ViewSpaceSpan(vs, o, d, &a, &b)) {
      ++missed;
      for (double t = -1000.0; t <= 1000.0; t += 0.25) ASSERT_FALSE(Inside(vs, o + t * d)) << n << " t " << t;
      continue;
    }
    ++met;
    ASSERT_LE(a, b);
    for (int k = 0; k <= 8; ++k) {
      const double t = a + (b - a) * k / 8.0;
      const glm::dvec3 p = o + t * d;
      // Within rounding of the box at the span's ends.
      ASSERT_TRUE(Inside(Aabb{vs.min - glm::dvec3(1e-9), vs.max + glm::dvec3(1e-9)}, p)) << n << " t " << t;
    }
    ASSERT_FALSE(Inside(vs, o + (a - 1e-3) * d)) << n;
    ASSERT_FALSE(Inside(vs, o + (b + 1e-3) * d)) << n;
  }
  EXPECT_GT(met, 1000);
  EXPECT_GT(missed, 1000);
}

// VisitCells walks the cells of [t0, t1] within the span, in order, and nothing when the part
// of the line asked for lies before or after the span (what CastBoth leaves uncast).
TEST(AgvsViewSpace, WalkVisitsTheCellsOfThePartInsideTheSpanOnly) {
  const absl::StatusOr<ViewcellGrid> grid = ViewcellGrid::Create(Aabb{glm::dvec3(0), glm::dvec3(400, 300, 20)}, 100.0, 0.5, 2.0);
  ASSERT_TRUE(grid.ok());
  const Aabb vs = grid->Bounds();
  // Down from 12 m over cell (0, 1) towards the far corner: it enters the slab at z = 2.5.
  const glm::dvec3 o(50, 150, 12), d = glm::normalize(glm::dvec3(300, 100, -10));
  double a = 0.0, b = 0.0;
  ASSERT_TRUE(ViewSpaceSpan(vs, o, d, &a, &b));
  EXPECT_NEAR((o + a * d).z, 2.5, 1e-9);
  EXPECT_NEAR((o + b * d).z, 0.5, 1e-9);
  std::vector<CellId> cells;
  std::vector<double> ts;
  VisitCells(*grid, vs, o, d, 0.0, 1e9, [&](CellId c, double t) {
    cells.push_back(c);
    ts.push_back(t);
  });
  ASSERT_FALSE(cells.empty());
  for (size_t k = 0; k < ts.size(); ++k) {
    EXPECT_GE(ts[k], a);
    EXPECT_LE(ts[k], b);
    if (k > 0) {
      EXPECT_GT(ts[k], ts[k - 1]);
    }
    EXPECT_EQ(grid->CellAt(glm::dvec2(o + ts[k] * d)), cells[k]);
  }
  int visits = 0;
  VisitCells(*grid, vs, o, d, 0.0, a - 1e-6, [&](CellId, double) { ++visits; });  // ends before the slab
  VisitCells(*grid, vs, o, d, b + 1e-6, 1e9, [&](CellId, double) { ++visits; });   // starts past it
  EXPECT_EQ(visits, 0);
}

// The first ray of a sample points at the view space and asks, up to where the line enters
// it, whether anything lies in between: its points before `reach` lie outside the box, just
// past it inside (or the origin itself lies in the span and nothing is asked). Also far from
// the origin of the frame, as a translated scene's view space is.
TEST(AgvsViewSpace, FirstRayPointsAtTheViewSpaceAndReachesWhereTheLineEntersIt) {
  for (const glm::dvec3 shift : {glm::dvec3(0.0), glm::dvec3(500000.0, 5000000.0, 0.0)}) {
    const Aabb vs{glm::dvec3(0, 0, 0.5) + shift, glm::dvec3(400, 300, 2.5) + shift};
    scenes::Rng rng(11);
    int behind = 0, ahead = 0, within = 0;
    for (int n = 0; n < 20000; ++n) {
      const glm::dvec3 o = shift + glm::dvec3(rng.Uniform() * 600 - 100, rng.Uniform() * 500 - 100, rng.Uniform() * 30 - 2);
      glm::dvec3 d = UniformDirection(rng);
      if (n % 7 == 0) d.z = 0.0;
      double a = 0.0, b = 0.0;
      if (!ViewSpaceSpan(vs, o, d, &a, &b)) continue;
      const FirstRay whole = FirstRayOf(a, b, /*whole=*/true);
      ASSERT_FALSE(whole.reverse);
      ASSERT_EQ(whole.reach, 0.0);
      const FirstRay first = FirstRayOf(a, b, /*whole=*/false);
      const glm::dvec3 ray = first.reverse ? -d : d;
      if (a <= 0.0 && b >= 0.0) {
        ++within;
        ASSERT_FALSE(first.reverse) << n;
        ASSERT_LE(first.reach, 0.0) << n;  // no occlusion query: the origin is in the span
        continue;
      }
      (first.reverse ? behind : ahead) += 1;
      ASSERT_GT(first.reach, 0.0) << n;
      // Past the reach the ray runs inside the box (a margin for the box's rounding).
      const double len = b - a, tol = 1e-9 * (1.0 + first.reach);
      ASSERT_TRUE(Inside(Aabb{vs.min - 1e-6, vs.max + 1e-6}, o + (first.reach + 0.5 * len) * ray)) << n;
      ASSERT_TRUE(Inside(Aabb{vs.min - 1e-6, vs.max + 1e-6}, o + (first.reach + tol) * ray)) << n;
      // Before it, from the origin on, outside.
      for (int k = 0; k < 16; ++k) {
        const double t = first.reach * (k / 16.0) - tol;
        if (t < 0.0) continue;
        ASSERT_FALSE(Inside(Aabb{vs.min + 1e-6, vs.max - 1e-6}, o + t * ray)) << n << " k " << k;
      }
    }
    EXPECT_GT(behind, 1000);
    EXPECT_GT(ahead, 1000);
    EXPECT_GT(within, 10);
  }
}

}  // namespace
}  // namespace vistream::visibility
