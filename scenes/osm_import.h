#pragma once
// OpenStreetMap buildings as a vistream scene (libosmium).
//
// Input: .osm (XML), .osm.pbf, and XML compressed as .osm.bz2 or .osm.gz (libosmium's own
// decompression); chosen by extension. Files as editors save them import like downloaded ones:
// negative ids (objects not yet uploaded), ids out of order, no version/user/timestamp.
//
// Buildings are the closed ways and multipolygon relations tagged building=* (any value but
// "no"), and the building parts tagged building:part=* (Simple 3D Buildings), assembled by
// libosmium's area assembler (outer and inner rings, which may touch each other at single
// nodes as OSM's multipolygon rules allow). A building outline is drawn only where no part
// covers it (CGAL's Boolean difference; scenes/polygon_set.h); each part is an object of its
// own with its own heights. A closed way tagged building that is also the outline of a
// building relation gives one object, the relation's.
//
// Positions go to UTM (GeographicLib) in the zone and hemisphere of the data's centre (the
// median longitude and latitude of the buildings' nodes), for every building of the import,
// whichever side of the equator or zone edge it stands on; then to scene-local metres around
// that centre, rounded to whole metres and kept as Scene::origin. Coordinates snap to 1/256 m
// like the generators' (exact in float, and shared nodes stay shared walls). Buildings
// farther than 65 km from the centre are skipped.
//
// Heights: ReadHeights (scenes/osm_tags.h): height, building:height, building:levels, the
// building type's rule; min_height / building:min_level raise the base. Values above
// OsmImportOptions::max_height_m are implausible (counted, next rule used). An object whose
// base is above the ground, or whose tags contradict each other (base at or above the top),
// has a mesh but no occluder: only what is surely solid from the ground may occlude.
// Occluders are the footprints themselves (a footprint with courtyards as the triangles of its
// roof), so that buildings sharing OSM nodes touch exactly and fuse into one blocker
// (visibility/occluder_set.h).
//
// Walks (Scene::paths): the walkable highway=* ways (scenes/osm_read.h IsWalkableHighway), in
// the same projection, cut to the buildings' xy bounds, joined where they share a node, give
// up to OsmImportOptions::walks walks (scenes/derived_walks.h DeriveStreetWalks): "street 1"
// is the longest shortest path of the largest street network, named after the street it mostly
// follows when there is one ("street 1 (Boulevard Albert 1er)"). The eye walks above the
// street's xy at the catalog walk's eye height. No highway ways: no walks (not an error).
//
// Bad data never stops an import: rings with duplicate points or spikes are repaired; rings
// that are not simple, have fewer than 3 points, lack node locations (an extract's edge) or
// fail to assemble are skipped, each counted by reason in OsmImportSummary::skipped.

#include <absl/status/statusor.h>

#include <atomic>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "scenes/osm_import_types.h"
#include "scenes/osm_tags.h"
#include "scenes/progress.h"
#include "scenes/scene.h"

namespace vistream::scenes {

struct OsmImportOptions {
  std::optional<GeoBox> bbox;  // keep only buildings with every node inside
  double storey_m = 3.0;
  // Heights above this (metres) are bad data: counted in implausible_heights and replaced by
  // the next rule. The tallest building is 828 m.
  double max_height_m = 1000.0;
  std::string name;  // the scene's name; default: the file's stem
  size_t walks = 3;  // walks derived from the highway ways, at most; 0: none
};

// Imports `path` (.osm, .osm.pbf, .pbf, .osm.bz2, .osm.gz; by extension). Errors name the
// file and what is wrong (missing, truncated, not OSM data, no buildings left: then with the
// skip reasons, which `summary` also holds on every error path after reading).
absl::StatusOr<Scene> ImportOsm(const std::string& path, const OsmImportOptions& options,
                                OsmImportSummary* summary = nullptr,
                                const RunControl& run = {});

}  // namespace vistream::scenes
