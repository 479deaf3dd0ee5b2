#pragma once
// A walk from the scene catalog (WalkPath) as a function of distance: where the eye is,
// where it looks and how fast it moves. The eye looks at the path a few metres ahead, so it
// turns smoothly round corners. Over terrain the eye keeps its height above the ground.

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/catalog.h"
#include "scenes/terrain.h"

namespace vistream::scenes {

struct WalkPose {
  glm::dvec3 eye{0.0};       // scene-local metres
  glm::dvec3 velocity{0.0};  // m/s
  double yaw_rad = 0.0;
};

class Walk {
 public:
  // Errors (INVALID_ARGUMENT, naming the walk): fewer than two distinct waypoints, non-finite
  // points, a speed that is not positive. `terrain`: the scene's ground (the eye is
  // path.eye_height_m above TerrainHeight::HeightAt); null or empty: flat ground at z = 0.
  static absl::StatusOr<Walk> Create(const WalkPath& path, double speed_mps,
                                     std::shared_ptr<const TerrainHeight> terrain = nullptr);

  double length_m() const { return cumulative_.back(); }
  double speed_mps() const { return speed_; }
  double duration_s() const { return length_m() / speed_; }
  // The pose `t` seconds after the start (clamped to the path's ends): the eye at the walk's
  // eye height above the ground, the velocity along the path (its z: the ground's rise) at
  // the walk's speed over the ground's plan.
  WalkPose At(double t) const;
  // The point `s` metres along the path (clamped to its ends), scene-local metres.
  glm::dvec2 PointAt(double s) const;
  // The viewcells the walk passes through, in order, each once per visit: `cell_at` (a grid's
  // lookup of a scene-local point; none outside the grid) of points every 0.25 m along the path,
  // or every hundredth of `cell_size_m` if that is smaller. The first is the cell the walk starts
  // in, the next the first one it enters.
  std::vector<uint32_t> CellsAlong(double cell_size_m,
                                   const std::function<std::optional<uint32_t>(const glm::dvec2&)>& cell_at) const;

 private:
  std::vector<glm::dvec2> points_;
  std::vector<double> cumulative_;  // distance along the path at each point
  double speed_ = 1.0, eye_height_ = 1.7;
  std::shared_ptr<const TerrainHeight> terrain_;  // null: flat
};

}  // namespace vistream::scenes
