#pragma once
// Triangle meshes and the prism builder shared by the city generator and importers.

#include <cstdint>
#include <span>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/aabb.h"

namespace vistream::scenes {

// Positions and normals in scene-local metres (z up), single precision: a city of 20 km keeps
// millimetre resolution, and this is what the client uploads. Geometric decisions use the
// double-precision occluders and boxes, never these floats.
struct Mesh {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;  // one per position, unit length
  std::vector<uint32_t> indices;   // three per triangle, counter-clockwise seen from outside

  size_t TriangleCount() const { return indices.size() / 3; }
  Aabb Bounds() const;
};

// Appends one vertex (single-precision position at height z, its normal); returns its index.
uint32_t AppendVertex(const glm::dvec2& p, double z, const glm::vec3& normal, Mesh* mesh);

// Appends the walls of a ring from z0 to z1: one flat-shaded quad per edge, with its own four
// vertices, facing right of the edge's direction (outward for a counter-clockwise outer ring,
// into the courtyard for a clockwise hole).
void AppendWalls(std::span<const glm::dvec2> ring, double z0, double z1, Mesh* mesh);

// Appends a closed, flat-shaded prism: the convex footprint (counter-clockwise, xy metres,
// at least 3 vertices) extruded from z0 to z1 > z0. Walls, roof and floor; 4n - 4 triangles.
void AppendConvexPrism(std::span<const glm::dvec2> footprint, double z0, double z1, Mesh* mesh);

// Signed area of a polygon in the xy plane: positive for counter-clockwise.
double SignedArea(std::span<const glm::dvec2> polygon);

// True when the polygon is convex (collinear vertices allowed) and counter-clockwise.
bool IsConvexCcw(std::span<const glm::dvec2> polygon);

// Newell's normal of a closed ring of 3D points (the first not repeated at the end): twice the
// vector area, its direction the ring's orientation (counter-clockwise seen from its tip), for
// planar and nearly planar rings alike; zero for a ring without area (fewer than 3 distinct
// points, all on a line, or areas that cancel).
glm::dvec3 NewellNormal(std::span<const glm::dvec3> ring);

// The point of triangle abc nearest to p (Ericson, Real-Time Collision Detection, 5.1.5); a's
// corner for a degenerate triangle whose interior case is reached. Any frame, metres.
glm::dvec3 ClosestPointOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c);

}  // namespace vistream::scenes
