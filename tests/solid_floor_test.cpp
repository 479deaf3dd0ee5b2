// Floors for floorless solids (scenes/solid_floor.h) and the ground derived from them and from
// ground-level surfaces (scenes/derived_ground.h).
#include "scenes/solid_floor.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "scenes/derived_ground.h"
#include "scenes/polygon.h"

namespace vistream::scenes {
namespace {

using Tris = std::vector<Triangle3>;

// The closed prism of a footprint (outer counter-clockwise, holes clockwise) from z0 to z1 as
// triangles, through AppendPrism; `floor` false leaves out the floor (the triangles facing down).
Tris Prism(const PolygonWithHoles& p, double z0, double z1, bool floor) {
  absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(p);
  EXPECT_TRUE(tris.ok()) << tris.status();
  Mesh mesh;
  AppendPrism(p, *tris, z0, z1, &mesh);
  Tris out;
  for (size_t k = 0; k + 2 < mesh.indices.size(); k += 3) {
    Triangle3 t;
    for (int i = 0; i < 3; ++i) t[i] = glm::dvec3(mesh.positions[mesh.indices[k + i]]);
    const bool down = t[0].z == z0 && t[1].z == z0 && t[2].z == z0;
    if (floor || !down) out.push_back(t);
  }
  return out;
}

PolygonWithHoles Rect(double x0, double y0, double x1, double y1) {
  return {{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}, {}};
}

// Area in xy, and whether every triangle faces down (clockwise seen from above).
double AreaFacingDown(const Tris& tris, bool* all_down) {
  double area = 0.0;
  *all_down = true;
  for (const Triangle3& t : tris) {
    const double a = SignedArea(std::vector<glm::dvec2>{glm::dvec2(t[0]), glm::dvec2(t[1]), glm::dvec2(t[2])});
    *all_down = *all_down && a < 0.0;
    area -= a;
  }
  return area;
}

TEST(CloseFloor, FloorlessBoxGetsItsFloorFacingDown) {
  const FloorResult r = CloseFloor(Prism(Rect(0, 0, 10, 8), 0.5, 6.0, false));
  ASSERT_EQ(r.outcome, FloorClosing::kClosed) << r.why;
  EXPECT_EQ(r.loops, 1u);
  EXPECT_EQ(r.triangles.size(), 2u);
  bool down = false;
  EXPECT_DOUBLE_EQ(AreaFacingDown(r.triangles, &down), 80.0);
  EXPECT_TRUE(down);
  for (const Triangle3& t : r.triangles) {
    for (const glm::dvec3& p : t) EXPECT_EQ(p.z, 0.5);
  }
}

TEST(CloseFloor, CourtyardLoopIsAHole) {
  PolygonWithHoles p = Rect(0, 0, 20, 20);
  p.holes.push_back({{6, 6}, {6, 14}, {14, 14}, {14, 6}});
  const FloorResult r = CloseFloor(Prism(p, 0.0, 10.0, false));
  ASSERT_EQ(r.outcome, FloorClosing::kClosed) << r.why;
  EXPECT_EQ(r.loops, 2u);
  bool down = false;
  EXPECT_DOUBLE_EQ(AreaFacingDown(r.triangles, &down), 400.0 - 64.0);
  EXPECT_TRUE(down);
}

TEST(CloseFloor, ClosedSolidIsLeftAlone) {
  EXPECT_EQ(CloseFloor(Prism(Rect(0, 0, 10, 8), 0.0, 6.0, true)).outcome, FloorClosing::kAlreadyClosed);
}

TEST(CloseFloor, OpenAnywhereButTheLowestRingStaysOpen) {
  // Roofless: the open ring is at the top.
  Tris roofless;
  for (const Triangle3& t : Prism(Rect(0, 0, 10, 8), 0.0, 6.0, true)) {
    if (!(t[0].z == 6.0 && t[1].z == 6.0 && t[2].z == 6.0)) roofless.push_back(t);
  }
  EXPECT_EQ(CloseFloor(roofless).outcome, FloorClosing::kNotAFloor);
  // Floorless and a wall missing (the one along x = 10).
  Tris wall_missing;
  for (const Triangle3& t : Prism(Rect(0, 0, 10, 8), 0.0, 6.0, false)) {
    if (!(t[0].x == 10.0 && t[1].x == 10.0 && t[2].x == 10.0)) wall_missing.push_back(t);
  }
  EXPECT_EQ(CloseFloor(wall_missing).outcome, FloorClosing::kNotAFloor);
  // Floorless with its lower edge at two heights (more than the tolerance apart).
  Tris stepped = Prism(Rect(0, 0, 10, 8), 0.0, 6.0, false);
  for (Triangle3& t : stepped) {
    for (glm::dvec3& p : t) {
      if (p.x == 10.0 && p.z == 0.0) p.z = 0.01;
    }
  }
  EXPECT_EQ(CloseFloor(stepped).outcome, FloorClosing::kNotAFloor);
  // Within the tolerance it is a floor.
  for (Triangle3& t : stepped) {
    for (glm::dvec3& p : t) {
      if (p.z == 0.01) p.z = 0.0005;
    }
  }
  EXPECT_EQ(CloseFloor(stepped).outcome, FloorClosing::kClosed);
}

TEST(DeriveGround, FloorsAreTerrainTrianglesAndSurfacePointsUnderThemAreLeftOut) {
  DerivedGroundInput in;
  const Tris a = CloseFloor(Prism(Rect(10, 10, 20, 20), 1.0, 5.0, false)).triangles;
  // A part standing on `a` (its floor over a's footprint): left out, a's floor stays the ground.
  const Tris on_a = CloseFloor(Prism(Rect(12, 12, 18, 18), 5.0, 8.0, false)).triangles;
  in.floors = {on_a, a};
  in.points = {{0, 0, 0.0}, {40, 0, 2.0}, {40, 30, 2.0}, {0, 30, 0.0}, {15, 15, -3.0}, {20, 12, -3.0},
               {40, 30, 1.5}};
  in.lo = {0, 0};
  in.hi = {40, 30};
  absl::StatusOr<DerivedGround> g = DeriveGround(in);
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_EQ(g->floors, 1u);
  EXPECT_EQ(g->floors_overlapping, 1u);
  EXPECT_EQ(g->floor_points, 4u);
  EXPECT_EQ(g->points_under_floors, 2u) << "one inside the footprint, one on its edge";
  EXPECT_EQ(g->surface_points, 4u) << "(40, 30) once, at its lowest";
  EXPECT_EQ(g->corner_points, 0u);
  // 8 points, 4 on the hull: 2 * 8 - 2 - 4 triangles.
  ASSERT_EQ(g->triangles.size(), 10u);
  double area = 0.0, floor_area = 0.0;
  for (const Triangle3& t : g->triangles) {
    const double s = SignedArea(std::vector<glm::dvec2>{glm::dvec2(t[0]), glm::dvec2(t[1]), glm::dvec2(t[2])});
    EXPECT_GT(s, 0.0) << "up-facing";
    area += s;
    bool in_floor = true;
    for (const glm::dvec3& p : t) {
      in_floor = in_floor && p.x >= 10 && p.x <= 20 && p.y >= 10 && p.y <= 20;
      if (p.x == 40 && p.y == 30) {
        EXPECT_EQ(p.z, 1.5);
      }
    }
    if (in_floor) {
      floor_area += s;
      for (const glm::dvec3& p : t) EXPECT_EQ(p.z, 1.0);
    }
  }
  EXPECT_DOUBLE_EQ(area, 40.0 * 30.0);
  EXPECT_DOUBLE_EQ(floor_area, 100.0) << "the footprint is exactly terrain triangles at the floor's height";
}

TEST(DeriveGround, BoxCornersTakeTheNearestHeightAndNothingIsAnError) {
  DerivedGroundInput in;
  in.points = {{5, 5, 1.0}, {30, 20, 2.0}};
  in.lo = {0, 0};
  in.hi = {40, 30};
  absl::StatusOr<DerivedGround> g = DeriveGround(in);
  ASSERT_TRUE(g.ok()) << g.status();
  EXPECT_EQ(g->corner_points, 4u);
  for (const Triangle3& t : g->triangles) {
    for (const glm::dvec3& p : t) {
      if (p.x == 0 && p.y == 0) {
        EXPECT_EQ(p.z, 1.0);
      }
      if (p.x == 40 && p.y == 30) {
        EXPECT_EQ(p.z, 2.0);
      }
    }
  }
  EXPECT_FALSE(DeriveGround({}).ok());
  in.points.push_back({1, 1, std::nan("")});
  EXPECT_FALSE(DeriveGround(in).ok());
}

}  // namespace
}  // namespace vistream::scenes
