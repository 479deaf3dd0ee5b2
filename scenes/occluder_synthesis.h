#pragma once
// Occluders synthesized from closed geometry: ground-up prisms (Occluder25D) that lie inside
// the union of a solid and the solid ground, for city models (CityGML, CityJSON) and glTF
// meshes that carry no occluders of their own. DESIGN.md "City models and terrain".
//
// A prism from z = 0 (the scene's ground level) to height h over footprint F is inside
// solid ∪ ground when, at every point (x, y) of F, the vertical segment from the ground up to
// h lies inside the solid or below the ground. The synthesis finds such prisms from the
// solid's own faces: the xy projection of its non-vertical faces is cut into regions where the
// same faces lie above one another (a constrained triangulation of the projected edges, their
// crossings exact); in each region the solid's lowest inside interval has a bottom face and a
// top face, both planes, and intervals that touch the one below (a box standing on another)
// extend it; the part of the region where the bottom is at or below the ground can carry a
// prism up to any height its top reaches there (planes are affine: cut exactly).
// Regions are grouped into tiers (one footprint per height level: the eaves, then the levels
// where the roof steps), every tier a prism from the ground, each split into simple polygons.
//
// Conservative by construction (exact predicates and constructions for the regions and cuts;
// when cut points are rounded to double, heights and ground tests allow for the rounding, and
// footprint vertices move by at most one unit in the last place); tests check it with an
// independent point-in-solid test on random points of every prism.

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "scenes/mesh.h"
#include "scenes/scene.h"

namespace vistream::scenes {

// The boundary of one solid as triangles: every shell (exterior and voids) together, in
// scene-local metres (double). Orientation does not matter (inside is decided by parity).
struct SolidMesh {
  std::vector<glm::dvec3> vertices;
  std::vector<std::array<uint32_t, 3>> triangles;
};

// Why a solid got no occluder. Only kNone solids give occluders.
enum class SolidDefect {
  kNone,
  kEmpty,             // no triangle with a non-zero area
  kOpen,              // an edge is not shared by an even number of triangles (after welding
                      // equal vertices, edges cut at vertices lying on them: T-junctions
                      // close): the boundary does not close a volume
  kSelfIntersecting,  // two triangles that are not coplanar share a point inside both (they
                      // cross); touching is fine (a wall on a roof, a T-junction), and so are
                      // overlapping coplanar triangles (touching solids in one soup: parity
                      // counts both faces)
  kRaised,            // closed, but nowhere reaches down to the ground: no prism fits
};
// "empty", "open", "self-intersecting", "raised above the ground", "" for kNone.
const char* SolidDefectName(SolidDefect defect);

struct OccluderSynthesisOptions {
  int max_tiers = 4;            // height levels per solid (the lowest is the eaves' level)
  double min_height_m = 0.5;    // a tier lower than this above the ground is not worth a prism
  double min_area_m2 = 1.0;     // footprint pieces smaller than this are dropped
};

struct OccluderSynthesis {
  SolidDefect defect = SolidDefect::kNone;
  // Footprints counter-clockwise, simple, scene-local metres; heights above z = 0. `object`
  // is left 0 for the caller to set.
  std::vector<Occluder25D> occluders;
  // Of the solid, 0 unless closed: integrated over the regions' stacks (orientation does not
  // matter); for a self-intersecting solid by the divergence theorem (orientation does).
  double solid_volume_m3 = 0.0;
  // Of the union of the prisms above the solid's lowest point (or ground_z, if higher): what
  // of the solid occludes. The sum over tiers of footprint area times the rise over the tier
  // below (exact while no piece under min_area_m2 was dropped; a lower bound otherwise).
  double occluder_volume_m3 = 0.0;
};

// Occluders for one solid. `ground_z`: a height at or below the ground everywhere under the
// solid (scene-local metres; 0 on flat ground; with terrain, the terrain's lowest height under
// the solid's footprint), so that below ground_z all is solid.
OccluderSynthesis SynthesizeOccluders(const SolidMesh& solid, double ground_z,
                                      const OccluderSynthesisOptions& options = {});

// The ground under a solid when it is terrain: solid below the surface of `triangles` (a TIN:
// scene-local metres, not overlapping in xy; those that do not reach the solid's xy box may be
// left out), and below `flat_z` wherever no triangle lies.
struct GroundSurface {
  std::vector<std::array<glm::dvec3, 3>> triangles;
  double flat_z = 0.0;
};

// Occluders for one solid standing on terrain: a region carries a prism where the solid's
// bottom lies at or below the ground's surface at every point (the terrain triangles' edges
// cut the regions, so that the test is exact there too); `ground_z` is the lowest ground under
// the solid, from which tiers are measured (min_height_m, occluder_volume_m3). Real city models
// float their floors a few centimetres above the terrain's low side: only the rest occludes.
OccluderSynthesis SynthesizeOccluders(const SolidMesh& solid, double ground_z, const GroundSurface& ground,
                                      const OccluderSynthesisOptions& options = {});

// A mesh's triangles as a solid: positions welded where they are equal (flat-shaded meshes
// repeat them per face), triangles with no area (exactly collinear corners) or out-of-range
// indices dropped. For glTF objects and city objects triangulated by the builder.
// SynthesizeOccluders welds and drops the same way (and non-finite positions) itself.
SolidMesh SolidMeshFromMesh(const Mesh& mesh);

// Terrain as occluders: the ground below a terrain surface is solid, so over the part of a
// terrain triangle where the surface is at or above a height, a prism up to that height lies
// in the ground. Triangles (scene-local metres, z above the scene's ground level 0) give at
// most `levels` tiers at multiples of `quantum_m` above 0, chosen for the most volume; each
// tier covers the part of the tile where the surface is at or above its level (cut along the
// contour exactly, not only whole triangles: more ground, and fewer convex pieces), split
// into convex pieces. Footprints simple and counter-clockwise, `object` 0.
// About a quarter of a second for 2,000 triangles of bumpy ground (less for gentle ground).
std::vector<Occluder25D> TerrainOccluders(const std::vector<std::array<glm::dvec3, 3>>& triangles,
                                          double quantum_m = 1.0, int levels = 16);

}  // namespace vistream::scenes
