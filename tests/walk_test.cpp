// A catalog walk as a function of time (scenes/walk.h): the one the client follows and the
// simulator models.

#include "scenes/walk.h"

#include <cmath>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "tests/terrain_test_util.h"

namespace vistream::scenes {
namespace {

TEST(Walk, FollowsTheWaypointsAtItsSpeedLookingAhead) {
  WalkPath path;
  path.name = "ell";
  path.eye_height_m = 1.5;
  path.waypoints = {{0, 0}, {100, 0}, {100, 0}, {100, 50}};
  absl::StatusOr<Walk> w = Walk::Create(path, 2.0);
  ASSERT_TRUE(w.ok()) << w.status();
  EXPECT_DOUBLE_EQ(w->length_m(), 150.0);
  EXPECT_DOUBLE_EQ(w->duration_s(), 75.0);
  const WalkPose a = w->At(10.0);
  EXPECT_NEAR(a.eye.x, 20.0, 1e-9);
  EXPECT_NEAR(a.eye.y, 0.0, 1e-9);
  EXPECT_NEAR(a.eye.z, 1.5, 1e-9);
  EXPECT_NEAR(a.velocity.x, 2.0, 1e-9);
  EXPECT_NEAR(a.yaw_rad, 0.0, 1e-9);
  const WalkPose b = w->At(60.0);  // 120 m: on the second leg, heading +y
  EXPECT_NEAR(b.eye.x, 100.0, 1e-9);
  EXPECT_NEAR(b.eye.y, 20.0, 1e-9);
  EXPECT_NEAR(b.yaw_rad, M_PI / 2, 1e-9);
  EXPECT_NEAR(b.velocity.y, 2.0, 1e-9);
  const WalkPose end = w->At(1000.0);
  EXPECT_NEAR(end.eye.y, 50.0, 1e-9);
  EXPECT_EQ(end.velocity, glm::dvec3(0.0));
  path.waypoints = {{1, 1}, {1, 1}};
  EXPECT_FALSE(Walk::Create(path, 1.0).ok());
  path.waypoints = {{0, 0}, {1, 1}};
  EXPECT_FALSE(Walk::Create(path, 0.0).ok());
  EXPECT_FALSE(Walk::Create(path, std::nan("")).ok());
}

TEST(Walk, ASegmentAlongACellEdgeStaysExactlyOnIt) {
  // city1's lot-lines walk runs along x = -500 and y = 350, viewcell edges of its 50 m grid:
  // glm::mix put the eye a rounding step off the line, flipping it between the two cells.
  WalkPath path;
  path.name = "edges";
  path.waypoints = {{-500, -350}, {-500, 350}, {200, 350}, {200, -350.25}};
  absl::StatusOr<Walk> w = Walk::Create(path, 1.4);
  ASSERT_TRUE(w.ok()) << w.status();
  for (int k = 0; k <= 5000; ++k) {
    const double t = w->duration_s() * k / 5000.0;
    const WalkPose p = w->At(t);
    const double s = t * 1.4;
    if (s < 700.0) {
      ASSERT_EQ(p.eye.x, -500.0) << "t " << t;
    } else if (s < 1400.0) {
      ASSERT_EQ(p.eye.y, 350.0) << "t " << t;
    } else {
      ASSERT_EQ(p.eye.x, 200.0) << "t " << t;
    }
  }
}

TEST(Walk, OnASlopeTheEyeKeepsItsHeightAboveTheGround) {
  // z = 2 + x / 4 + y / 8: the walk climbs the slope diagonally, then along y.
  auto slope = [](double x, double y) { return 2.0 + 0.25 * x + 0.125 * y; };
  const Scene s = testing::TerrainScene(slope, {0, 0}, {100, 100}, 5, 5);
  WalkPath path;
  path.name = "up";
  path.eye_height_m = 1.6;
  path.waypoints = {{5, 5}, {80, 60}, {80, 95}};
  absl::StatusOr<Walk> w = Walk::Create(path, 1.5, std::make_shared<const TerrainHeight>(s));
  ASSERT_TRUE(w.ok()) << w.status();
  for (int k = 0; k <= 200; ++k) {
    const WalkPose p = w->At(w->duration_s() * k / 200.0);
    ASSERT_NEAR(p.eye.z, slope(p.eye.x, p.eye.y) + 1.6, 1e-6) << k;
  }
  // On the leg along y the ground rises 1/8 m a metre: so does the eye.
  const WalkPose up = w->At((glm::distance(glm::dvec2(5, 5), glm::dvec2(80, 60)) + 10.0) / 1.5);
  EXPECT_NEAR(up.velocity.y, 1.5, 1e-9);
  EXPECT_NEAR(up.velocity.z, 1.5 * 0.125, 1e-6);
  // Flat terrain, no terrain, an empty one: the eye at its height above z = 0, as ever.
  Scene none;
  absl::StatusOr<Walk> flat = Walk::Create(path, 1.5, std::make_shared<const TerrainHeight>(none));
  ASSERT_TRUE(flat.ok());
  EXPECT_EQ(flat->At(3.0).eye.z, 1.6);
  EXPECT_EQ(flat->At(3.0).velocity.z, 0.0);
}

}  // namespace
}  // namespace vistream::scenes
