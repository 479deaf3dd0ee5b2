// A catalog walk as a function of time (scenes/walk.h): the one the client follows and the
// simulator models.

#include "scenes/walk.h"

#include <cmath>

#include <gtest/gtest.h>

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

}  // namespace
}  // namespace vistream::scenes
