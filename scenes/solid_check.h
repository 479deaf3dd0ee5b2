#pragma once
// Exact checks of a solid's boundary for the occluder synthesis (scenes/occluder_synthesis.h):
// whether its triangles close a volume, and whether two of them cross. Inside and outside are
// decided by parity, so a boundary that closes modulo 2 and has no crossing triangles bounds
// a volume whose vertical stacks of faces keep their order between the faces' projected edges.

#include <array>
#include <cstdint>
#include <vector>

#include <glm/vec3.hpp>

namespace vistream::scenes {

// Whether every edge, cut at the vertices that lie on it (T-junctions: a vertex of one face
// on the edge of another), is covered an even number of times by the triangles' edges.
// Vertices distinct (welded), triangles non-degenerate, indices in range; exact predicates.
bool ClosesModTwo(const std::vector<glm::dvec3>& vertices,
                  const std::vector<std::array<uint32_t, 3>>& triangles);

// Whether two triangles that are not coplanar share a point inside both (off both
// boundaries): they cross. Touching is fine: a wall standing with its edge on a roof's inside,
// a vertex on another's edge (a T-junction). Coplanar triangles may overlap: touching solids
// in one soup (a box standing on another, building parts sharing a wall) count both faces and
// parity cancels them. Same preconditions as ClosesModTwo; exact predicates, exact
// constructions only for the few pairs that meet other than at shared vertices and edges.
bool HasCrossingTriangles(const std::vector<glm::dvec3>& vertices,
                          const std::vector<std::array<uint32_t, 3>>& triangles);

}  // namespace vistream::scenes
