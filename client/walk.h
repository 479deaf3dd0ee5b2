#pragma once
// A walk from the scene catalog (scenes::WalkPath) as a function of distance: where the eye is,
// where it looks and how fast it moves. The eye looks at the path a few metres ahead, so it
// turns smoothly round corners.

#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/catalog.h"

namespace vistream::client {

struct WalkPose {
  glm::dvec3 eye{0.0};       // scene-local metres
  glm::dvec3 velocity{0.0};  // m/s
  double yaw_rad = 0.0;
};

class Walk {
 public:
  // Errors (INVALID_ARGUMENT, naming the walk): fewer than two distinct waypoints, non-finite
  // points, a speed that is not positive.
  static absl::StatusOr<Walk> Create(const scenes::WalkPath& path, double speed_mps);

  double length_m() const { return cumulative_.back(); }
  double speed_mps() const { return speed_; }
  double duration_s() const { return length_m() / speed_; }
  // The pose `t` seconds after the start (clamped to the path's ends).
  WalkPose At(double t) const;

 private:
  glm::dvec2 PointAt(double s) const;
  std::vector<glm::dvec2> points_;
  std::vector<double> cumulative_;  // distance along the path at each point
  double speed_ = 1.0, eye_height_ = 1.7;
};

}  // namespace vistream::client
