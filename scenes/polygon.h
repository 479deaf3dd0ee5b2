#pragma once
// Footprints with holes (a courtyard, the inner rings of a multipolygon): cleaning rings,
// checking them, triangulating them (CGAL's constrained Delaunay triangulation) and building
// the closed prism of a footprint.

#include <absl/status/statusor.h>

#include <array>
#include <glm/vec2.hpp>
#include <string>
#include <vector>

#include "scenes/mesh.h"

namespace vistream::scenes {

using Ring = std::vector<glm::dvec2>;  // open: the first point is not repeated at the end

struct PolygonWithHoles {
  Ring outer;               // counter-clockwise
  std::vector<Ring> holes;  // clockwise, inside `outer`, apart from each other (touching at
                            // shared vertices is allowed)
};

// What CleanRing changed.
struct RingRepairs {
  size_t duplicate_points = 0;  // consecutive equal points merged (the closing one included)
  size_t spikes = 0;            // points where the ring turned straight back on itself
};

// Removes consecutive duplicates (and a repeated first point at the end) and zero-width spikes
// (a, b, a), in place, until none is left.
RingRepairs CleanRing(Ring* ring);

// Whether the ring has at least 3 points, a non-zero area and no two edges meeting other than
// neighbours at their shared point (exact predicates).
bool IsSimpleRing(const Ring& ring);

// Whether simple ring `inner` lies inside simple ring `outer`, meeting it at most at shared
// vertices (OSM's multipolygon rules let an inner ring touch the outer at a node); exact
// predicates, O((n + m) log(n + m)) for rings that meet at few places.
bool RingInsideRing(const Ring& inner, const Ring& outer);

// Whether two simple rings lie outside each other, meeting at most at shared vertices.
bool RingsApart(const Ring& a, const Ring& b);

using Triangle2 = std::array<glm::dvec2, 3>;

// The footprint as counter-clockwise triangles covering exactly its area (holes left out).
// Needs simple rings, holes inside the outer ring and apart (RingInsideRing, RingsApart); an
// error otherwise, also when the triangles' area is not the outer ring's less the holes'.
absl::StatusOr<std::vector<Triangle2>> Triangulate(const PolygonWithHoles& polygon);

// Appends the closed, flat-shaded prism of `polygon` from z0 to z1 > z0: walls along every ring
// (outward, and into each courtyard), the roof and the floor from `triangles` (Triangulate's).
void AppendPrism(const PolygonWithHoles& polygon, const std::vector<Triangle2>& triangles,
                 double z0, double z1, Mesh* mesh);

}  // namespace vistream::scenes
