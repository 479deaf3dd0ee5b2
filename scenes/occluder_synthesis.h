#pragma once
// Occluders synthesized from closed geometry: ground-up prisms (Occluder25D) that lie inside
// the union of a solid and the solid ground, for city models (CityGML, CityJSON) and glTF
// meshes that carry no occluders of their own. DESIGN.md "City models and terrain".
//
// A prism from z = 0 (the scene's ground level) to height h over footprint F is inside
// solid ∪ ground when, at every point (x, y) of F, the vertical segment from the ground up to
// h lies inside the solid or below the ground. The synthesis finds such prisms from the
// solid's own faces: the xy projection of its non-vertical faces is cut into regions where the
// same faces lie above one another; in each region the solid's lowest inside interval has a
// bottom face and a top face, both planes; the region can carry a prism up to the lowest
// height of its top face if the highest height of its bottom face is at or below the ground.
// Regions are grouped into tiers (one footprint per height level: the eaves, then the levels
// where the roof steps), every tier a prism from the ground, each split into simple polygons.
//
// Conservative by construction (exact predicates for the region arrangement, heights taken at
// region vertices, which bound a plane over a polygon); tests check it with an independent
// point-in-solid test on random points of every prism.

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
                      // equal vertices): the boundary does not close a volume
  kSelfIntersecting,  // two triangles cross other than at shared edges or vertices
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
  double solid_volume_m3 = 0.0;     // of the solid (0 unless closed)
  double occluder_volume_m3 = 0.0;  // of the union of the prisms above ground_z
};

// Occluders for one solid. `ground_z`: a height at or below the ground everywhere under the
// solid (scene-local metres; 0 on flat ground; with terrain, the terrain's lowest height under
// the solid's footprint), so that below ground_z all is solid.
OccluderSynthesis SynthesizeOccluders(const SolidMesh& solid, double ground_z,
                                      const OccluderSynthesisOptions& options = {});

// A mesh's triangles as a solid: positions welded where they are equal (flat-shaded meshes
// repeat them per face). For glTF objects and city objects triangulated by the builder.
SolidMesh SolidMeshFromMesh(const Mesh& mesh);

// Terrain as occluders: the ground below a terrain surface is solid, so over the part of a
// terrain triangle where the surface is at or above a height, a prism up to that height lies
// in the ground. Triangles (scene-local metres, z above the scene's ground level 0) give at
// most `levels` tiers at multiples of `quantum_m` above 0, chosen for the most volume; each
// tier covers the part of the tile where the surface is at or above its level (cut along the
// contour exactly, not only whole triangles: more ground, and far fewer convex pieces than
// triangles), split into convex pieces. Footprints simple and counter-clockwise, `object` 0.
// About 0.1 s for 2,000 triangles.
std::vector<Occluder25D> TerrainOccluders(const std::vector<std::array<glm::dvec3, 3>>& triangles,
                                          double quantum_m = 1.0, int levels = 16);

}  // namespace vistream::scenes
