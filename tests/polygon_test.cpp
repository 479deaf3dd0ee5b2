#include "scenes/polygon.h"

#include <gtest/gtest.h>

namespace vistream::scenes {
namespace {

TEST(Polygon, CleanRingMergesDuplicatesAndCutsSpikes) {
  // A square with a repeated corner, the first point again at the end, and a spike out of the
  // top edge (out to (5, 20) and straight back).
  Ring r = {{0, 0}, {10, 0}, {10, 0}, {10, 10}, {5, 10}, {5, 20}, {5, 10}, {0, 10}, {0, 0}};
  const RingRepairs fix = CleanRing(&r);
  EXPECT_EQ(fix.duplicate_points, 3u);  // (10, 0), the closing (0, 0), the spike's (5, 10)
  EXPECT_EQ(fix.spikes, 1u);
  const Ring want = {{0, 0}, {10, 0}, {10, 10}, {5, 10}, {0, 10}};
  EXPECT_EQ(r, want);
  EXPECT_TRUE(IsSimpleRing(r));
}

TEST(Polygon, SimpleRingsAndNot) {
  EXPECT_TRUE(IsSimpleRing({{0, 0}, {4, 0}, {4, 4}, {0, 4}}));
  EXPECT_FALSE(IsSimpleRing({{0, 0}, {4, 4}, {4, 0}, {0, 4}}));  // a bow tie
  EXPECT_FALSE(IsSimpleRing({{0, 0}, {4, 0}}));                  // too few points
  EXPECT_FALSE(IsSimpleRing({{0, 0}, {2, 0}, {4, 0}}));          // no area
  // Touching itself at a point (a figure eight through (2, 2)).
  EXPECT_FALSE(IsSimpleRing({{0, 0}, {2, 2}, {4, 0}, {4, 4}, {2, 2}, {0, 4}}));
}

TEST(Polygon, TriangulateCoversTheAreaLessTheHoles) {
  PolygonWithHoles p;
  p.outer = {{0, 0}, {10, 0}, {10, 10}, {0, 10}};
  p.holes = {{{2, 2}, {2, 4}, {4, 4}, {4, 2}}, {{6, 6}, {6, 8}, {8, 8}, {8, 6}}};
  const absl::StatusOr<std::vector<Triangle2>> t = Triangulate(p);
  ASSERT_TRUE(t.ok()) << t.status();
  double area = 0.0;
  for (const Triangle2& tri : *t) {
    const double a = SignedArea(tri);
    EXPECT_GT(a, 0.0);
    area += a;
  }
  EXPECT_DOUBLE_EQ(area, 100.0 - 4.0 - 4.0);
  Mesh m;
  AppendPrism(p, *t, 0.0, 5.0, &m);
  EXPECT_EQ(m.TriangleCount(), 2 * (4 + 4 + 4) + 2 * t->size());  // walls, roof, floor
  EXPECT_EQ(m.normals.size(), m.positions.size());

  PolygonWithHoles outside = p;
  outside.holes = {{{12, 2}, {12, 4}, {14, 4}, {14, 2}}};
  EXPECT_NE(Triangulate(outside).status().message().find("not inside the outer ring"), std::string::npos);
  PolygonWithHoles overlapping = p;
  overlapping.holes = {{{2, 2}, {2, 5}, {5, 5}, {5, 2}}, {{4, 4}, {4, 6}, {6, 6}, {6, 4}}};
  EXPECT_NE(Triangulate(overlapping).status().message().find("overlap"), std::string::npos);
  PolygonWithHoles bowtie;
  bowtie.outer = {{0, 0}, {4, 4}, {4, 0}, {0, 4}};
  EXPECT_FALSE(Triangulate(bowtie).ok());
}

}  // namespace
}  // namespace vistream::scenes
