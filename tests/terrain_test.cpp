// The terrain's height (scenes/terrain.h): what walks stand on and viewcell bands span.

#include "scenes/terrain.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "tests/terrain_test_util.h"

namespace vistream::scenes {
namespace {

using testing::TerrainScene;
using testing::TinMesh;

// z = 2 + x / 4 + y / 8 over [0, 100]^2 in 20 m quads: exact in float at every vertex.
double Slope(double x, double y) { return 2.0 + 0.25 * x + 0.125 * y; }

TEST(TerrainHeight, NoTerrainIsFlatGroundAtZero) {
  Scene s;
  s.AddObject("box", TinMesh(Slope, {0, 0}, {10, 10}, 1, 1));  // not terrain
  const TerrainHeight t(s);
  EXPECT_TRUE(t.empty());
  EXPECT_EQ(t.HeightAt({5, 5}), 0.0);
  EXPECT_EQ(t.Range({0, 0}, {10, 10}), (HeightRange{0.0, 0.0}));
}

TEST(TerrainHeight, HeightAtInterpolatesTheSurface) {
  const TerrainHeight t(TerrainScene(Slope, {0, 0}, {100, 100}, 5, 5));
  EXPECT_EQ(t.triangle_count(), 50u);
  for (const glm::dvec2 p : {glm::dvec2(0, 0), glm::dvec2(33.3, 71.2), glm::dvec2(20, 20), glm::dvec2(100, 100),
                             glm::dvec2(40, 55), glm::dvec2(99.99, 0.01)}) {
    EXPECT_NEAR(t.HeightAt(p), Slope(p.x, p.y), 1e-9) << p.x << "," << p.y;
  }
  EXPECT_EQ(t.HeightAt({-1, 50}), 0.0);   // off the terrain
  EXPECT_EQ(t.HeightAt({50, 101}), 0.0);
  EXPECT_EQ(t.HeightAt({NAN, 50}), 0.0);
}

TEST(TerrainHeight, RangeOfASlopeIsAtTheSquaresCorners) {
  const TerrainHeight t(TerrainScene(Slope, {0, 0}, {100, 100}, 5, 5));
  // Corners inside triangles (30 is mid-quad), not at vertices: the extremes are there.
  const HeightRange r = t.Range({30, 30}, {55, 55});
  EXPECT_NEAR(r.min, Slope(30, 30), 1e-9);
  EXPECT_NEAR(r.max, Slope(55, 55), 1e-9);
  // Partly off the terrain: the ground there is z = 0.
  const HeightRange off = t.Range({90, 10}, {120, 40});
  EXPECT_EQ(off.min, 0.0);
  EXPECT_NEAR(off.max, Slope(100, 40), 1e-9);
  // Wholly off: flat.
  EXPECT_EQ(t.Range({200, 200}, {210, 210}), (HeightRange{0.0, 0.0}));
}

// A peak of 8 m at (10, 10) in a 2 m plain over [0, 20]^2 (10 m quads).
double Peak(double x, double y) { return x == 10.0 && y == 10.0 ? 8.0 : 2.0; }

TEST(TerrainHeight, RangeFindsAPeakInsideAndEdgesCrossingTheBorder) {
  const TerrainHeight t(TerrainScene(Peak, {0, 0}, {20, 20}, 2, 2));
  // The peak vertex inside the square.
  EXPECT_EQ(t.Range({5, 5}, {15, 15}).max, 8.0);
  // The peak outside: the highest ground is where the edge (0,10)-(10,10) crosses x = 6, at
  // 2 + 0.6 * 6; the lowest is the vertex (0, 10).
  const HeightRange ridge = t.Range({0, 8}, {6, 12});
  EXPECT_NEAR(ridge.max, 5.6, 1e-9);
  EXPECT_EQ(ridge.min, 2.0);
  // A square inside one triangle, away from the peak's edges: a plane, extremes at corners.
  const HeightRange inner = t.Range({16, 1}, {18, 3});  // triangle (10,0),(20,0),(20,10): flat 2 m
  EXPECT_EQ(inner.min, 2.0);
  EXPECT_EQ(inner.max, 2.0);
}

TEST(TerrainHeight, RangeHoldsEverySampledHeightOfABumpyTin) {
  auto bumpy = [](double x, double y) {
    return 3.0 + 2.0 * std::sin(0.21 * x) * std::cos(0.17 * y) + std::fmod(std::abs(x * 7.0 + y * 3.0), 1.5);
  };
  const TerrainHeight t(TerrainScene(bumpy, {-30, -20}, {50, 60}, 17, 13));
  for (const auto& [lo, size] : {std::pair{glm::dvec2(-25, -15), 11.0}, std::pair{glm::dvec2(3.7, 8.1), 17.0},
                                 std::pair{glm::dvec2(40, 50), 10.0}}) {
    const HeightRange r = t.Range(lo, lo + glm::dvec2(size));
    double smin = 1e9, smax = -1e9;
    constexpr int kN = 200;
    for (int j = 0; j <= kN; ++j) {
      for (int i = 0; i <= kN; ++i) {
        const double z = t.HeightAt(lo + glm::dvec2(size * i / kN, size * j / kN));
        smin = std::min(smin, z);
        smax = std::max(smax, z);
      }
    }
    // Every sample inside the range; the range no wider than the samples by more than the
    // slope over a sample step.
    EXPECT_LE(r.min, smin + 1e-9);
    EXPECT_GE(r.max, smax - 1e-9);
    EXPECT_NEAR(r.min, smin, 0.2);
    EXPECT_NEAR(r.max, smax, 0.2);
  }
}

TEST(TerrainHeight, AClosedSolidsTopIsTheSurface) {
  Scene s;
  s.terrain.push_back(s.AddObject("ground", TinMesh(Slope, {0, 0}, {100, 100}, 5, 5, -10.0)));
  const TerrainHeight t(s);
  EXPECT_EQ(t.triangle_count(), 50u);  // walls and floor do not count
  EXPECT_NEAR(t.HeightAt({50, 50}), Slope(50, 50), 1e-9);
  const HeightRange r = t.Range({0, 0}, {100, 100});
  EXPECT_NEAR(r.min, Slope(0, 0), 1e-9);
  EXPECT_NEAR(r.max, Slope(100, 100), 1e-9);
}

TEST(TerrainHeight, OverlappingTilesCoverOrLeaveGroundAtZero) {
  // Two tiles overlapping over x in [40, 60]: together they cover [0, 100] x [0, 50].
  Scene s;
  auto h = [](double, double) { return 5.0; };
  s.terrain.push_back(s.AddObject("west", TinMesh(h, {0, 0}, {60, 50}, 3, 2)));
  s.terrain.push_back(s.AddObject("east", TinMesh(h, {40, 0}, {100, 50}, 3, 2)));
  const TerrainHeight t(s);
  EXPECT_EQ(t.Range({10, 10}, {90, 40}), (HeightRange{5.0, 5.0}));
  // A square reaching past the tiles (y > 50): the ground there is 0.
  EXPECT_EQ(t.Range({30, 30}, {70, 70}), (HeightRange{0.0, 5.0}));
  // Their areas together as large as the square's, yet a strip (y > 50) uncovered.
  EXPECT_EQ(t.Range({10, 10}, {90, 60}), (HeightRange{0.0, 5.0}));
}

}  // namespace
}  // namespace vistream::scenes
