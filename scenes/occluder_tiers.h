#pragma once
// Tiers of ground-up prisms, shared by the solid and the terrain occluder synthesis
// (scenes/occluder_synthesis.h): choosing the height levels, and joining the convex pieces of
// a tier's footprint into fewer, larger convex pieces.

#include <cstddef>
#include <span>
#include <vector>

#include <glm/vec2.hpp>

namespace vistream::scenes {

// Of candidate levels (strictly ascending, above `base`) and the footprint area each level
// would get (non-increasing: a higher level's footprint lies inside a lower one's), the
// indices, ascending, of at most `max_tiers` levels that maximise the volume of the tiers'
// union above `base`, the sum of area(L_i) * (L_i - L_{i-1}) with L_0 = base (dynamic
// programming, O(max_tiers * n^2)). Of equal volumes, the fewest levels. Empty when n == 0 or
// max_tiers < 1.
std::vector<size_t> ChooseTierLevels(std::span<const double> levels, std::span<const double> areas,
                                     double base, int max_tiers);

// Joins convex counter-clockwise pieces (any frame) across whole shared edges, the same two
// points in both, while the union stays convex (exact predicates; Hertel and Mehlhorn's
// greedy pass over the pieces' common edges instead of a triangulation's diagonals), then
// drops straight vertices. The result covers exactly the union of the pieces; pieces with no
// area are dropped, and a piece that is not convex (rounding can leave one a hair concave) is
// kept as it is if it is simple and dropped if not.
std::vector<std::vector<glm::dvec2>> MergeConvexPieces(std::vector<std::vector<glm::dvec2>> pieces);

}  // namespace vistream::scenes
