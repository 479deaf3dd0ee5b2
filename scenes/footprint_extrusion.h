#pragma once
// A city model as OpenStreetMap would draw it (issue 35, "Measure": the same city from
// footprints against its LoD2 model): each building reduced to the prism of its footprint
// from the ground up to its highest point, that prism its own occluder. Measures how much of
// the extrusions' culling the real roofs and the synthesised occluders keep.

#include <absl/status/statusor.h>

#include <cstdint>
#include <map>
#include <string>

#include "scenes/scene.h"

namespace vistream::scenes {

struct ExtrusionSummary {
  uint64_t buildings = 0;  // Building and BuildingPart objects in the input
  uint64_t extruded = 0;   // of them, replaced by their prism
  std::map<std::string, uint64_t> not_extruded;  // by reason (kept as they were, no occluder)
  uint64_t terrain_dropped = 0;                  // terrain objects left out (flat ground)
  uint64_t occluders = 0;
  double footprint_m2 = 0.0;  // of the extruded buildings
};

// `scene` with every Building and BuildingPart object (Object::type) replaced by a closed,
// flat-shaded prism: its footprint is the union of the xy projections of the object's
// triangles (overhangs included, courtyards kept as holes), from z = 0 (the scene's ground
// level) to the object's highest vertex; its occluders are that footprint's convex pieces at
// that height (the prism itself: conservative). Terrain objects are left out (OSM's ground is
// flat) and the scene's terrain list emptied; in their place one flat ground rectangle at z = 0
// over the input's xy extent (type "ground", last), so that both scenes have the same viewcell
// grid; other objects are kept as they are, without
// occluders; the input's occluders are dropped. Object ids are renumbered densely in input
// order; name, origin, CRS and paths are kept, the name gets "-extruded".
// Scene-local metres throughout. A building whose footprint CGAL or the triangulation refuses
// is kept as it is, without occluder, and counted. Errors: INVALID_ARGUMENT when no object is
// left.
absl::StatusOr<Scene> ExtrudeFootprints(const Scene& scene, ExtrusionSummary* summary);

}  // namespace vistream::scenes
