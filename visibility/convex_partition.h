#pragma once
// Convex pieces of a simple polygon, with no new vertices: ear clipping, then Hertel and
// Mehlhorn's pass that drops every diagonal whose two sides stay convex without it (at most
// four times as many pieces as the fewest possible; O'Rourke, Computational Geometry in C,
// section 2.5). A footprint from OpenStreetMap becomes a few convex pieces instead of a
// triangle per vertex: fewer pieces, points and contacts for every planar query to gather.

#include <span>
#include <vector>

#include <glm/vec2.hpp>

namespace vistream::visibility {

// Exact sign of the turn a -> b -> c (any frame, metres or not): +1 left, -1 right,
// 0 collinear.
int Orient(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c);

// Convex pieces covering a simple counter-clockwise polygon (distinct consecutive vertices,
// any frame; decisions by exact predicates), as indices into `poly`: each
// piece counter-clockwise and convex (a vertex may be straight), the pieces' interiors
// disjoint, any two pieces meeting in the hull of their shared vertices (a whole diagonal,
// one vertex, or nothing). The whole polygon when it is convex; empty when it is not simple.
std::vector<std::vector<int>> ConvexPartition(std::span<const glm::dvec2> poly);

}  // namespace vistream::visibility
