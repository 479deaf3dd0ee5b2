#pragma once
// An independent point-in-solid test for the occluder tests: parity of a random ray's crossings
// with the solid's triangles, sharing no code with the synthesis (scenes/occluder_synthesis.h).

#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/occluder_synthesis.h"
#include "scenes/random.h"

namespace vistream::testing {

// Whether `p` (scene-local metres) lies inside `solid` by the parity of a random ray's
// crossings; rays that pass too close to an edge or a face to call are retried (20 times, then
// a test failure is added and false returned).
bool InsideSolid(const scenes::SolidMesh& solid, const glm::dvec3& p, scenes::Rng* rng);

// A random point inside polygon `poly` (xy, either orientation, non-zero area): rejection
// sampling in its box.
glm::dvec2 PointIn(const std::vector<glm::dvec2>& poly, scenes::Rng* rng);

}  // namespace vistream::testing
