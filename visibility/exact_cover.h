#pragma once
// The exact planar test: do the blockers' regions cover RS = [0, 1]^2? Decided with exact
// rational arithmetic (CGAL's exact kernel) on the blockers' coefficients taken as exact
// numbers, so it has no raster and no rounding: the reference the raster's overestimation is
// measured against.

#include "visibility/conservative_raster.h"

namespace vistream::visibility {

// True when the free rays form a set of zero area. A blocker leaves free the rays on one side
// of all its points, {all g_k > 0} and {all g_k < 0}: two convex regions. The free set is the
// intersection over blockers of those pairs, built with Boolean set operations and stopped as
// soon as it is empty. Ignores Blockers::eps.
bool ExactlyCovered(const Blockers& blockers);

// The same answer, faster: `raster` is the blockers' conservative raster (n x n, row-major,
// 1 where set, as PlanarRaster::Draw gives it). Its set pixels are covered already, so only
// the clear ones are searched for free rays.
bool ExactlyCovered(const Blockers& blockers, const std::vector<uint8_t>& raster, uint32_t n);

}  // namespace vistream::visibility
