// The silhouette search of AGVS's silhouette mutation (Bittner et al. 2009, section 4.3) as the
// paper does it: discovery rays, each an Embree query against the object alone, so that its cost
// grows with the logarithm of the object's size. silhouette.h solves the same search exactly,
// reading every triangle the fan's plane cuts: better for the small objects of a city, too slow
// for one of tens of thousands of thin triangles (a courtyard ring's roof).
#pragma once

#include <cstdint>
#include <optional>

#include <embree3/rtcore.h>

#include "visibility/silhouette.h"

namespace vistream::visibility {

// The λ of the last ray found to meet `object` (a committed Embree scene holding that object
// only, in the fan's frame) at the border nearest λ = 0 on the side the ray through `to` picks:
// if that ray meets it, the border above 0 (none when the ray at λ = 1 meets it too); else the
// border below 0 (none when the ray at λ = -1 misses). `depth` bisection steps leave the border
// within 2^-depth of the answer, on the meeting side; a border that lies between two rays tried
// at the first steps can be missed (the paper's search has the same blind spot). Adds the rays
// cast to `*rays`.
std::optional<double> DiscoveryLambda(const DiscoveryFan& fan, RTCScene object, uint64_t* rays, int depth = 6);

}  // namespace vistream::visibility
