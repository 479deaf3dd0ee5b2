#pragma once
// Buildings as stacks and rows of prisms, shared by the generators and importers.

#include <string>
#include <vector>

#include <glm/vec2.hpp>

#include "scenes/scene.h"

namespace vistream::scenes {

// A convex prism from z0 to z1. Its column from the ground up to z0 must be solid (the prism
// stands on the ground or on a wider prism of the same building), so that the 2.5D occluder
// from z = 0 to z1 lies inside the building.
struct Prism {
  std::vector<glm::dvec2> footprint;  // convex, counter-clockwise
  double z0 = 0.0;
  double z1 = 0.0;
};

// Adds one object made of `prisms` (closed, flat-shaded boxes) and one occluder per prism,
// from the ground to the prism's top. With `snap`, every coordinate is first snapped to
// 1/256 m so that it is exact in float; without, the float mesh rounds the double occluders
// (as imported data may). Returns the id.
ObjectId AddBuilding(Scene* scene, std::string name, const std::vector<Prism>& prisms, bool snap = true);

// The four corners, counter-clockwise, of the rectangle [u0,u1] x [v0,v1] in the frame with
// origin `o` and orthonormal axes `u`, `v` (v = u rotated by +90 degrees).
std::vector<glm::dvec2> FrameRect(const glm::dvec2& o, const glm::dvec2& u, const glm::dvec2& v,
                                  double u0, double u1, double v0, double v1);

// Shrinks a convex polygon towards its centroid by `factor` in (0, 1].
std::vector<glm::dvec2> ScaleAboutCentroid(const std::vector<glm::dvec2>& polygon, double factor,
                                           const glm::dvec2& shift = glm::dvec2(0.0));

}  // namespace vistream::scenes
