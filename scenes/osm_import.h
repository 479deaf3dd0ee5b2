#pragma once
// OpenStreetMap buildings as a vistream scene (libosmium).
//
// Buildings are the closed ways and multipolygon relations tagged building=* (any value but
// "no"), assembled by libosmium's area assembler (outer and inner rings). Positions go to UTM
// (GeographicLib, the zone of the data's centre: the median longitude and latitude of the
// buildings' nodes) and then to scene-local metres around that centre, rounded to whole metres
// and kept as Scene::origin; coordinates snap to 1/256 m like the generators' (exact in float,
// and shared nodes stay shared walls). Buildings farther than 65 km from the centre are skipped.
//
// Heights, in this order:
//   1. height, else building:height: a number with an optional unit (m, metres, ft, feet, ',
//      and feet-inches like 12'6"); a bare number is metres.
//   2. building:levels x 3 m, plus the roof: roof:height, else roof:levels x 3 m, else 1 m.
//   3. No usable tag: by the building tag's value (DefaultLevels below) x 3 m + 1 m. A rule
//      of the tag alone: the same building always gets the same height.
// The base: min_height, else building:min_level x 3 m; zero otherwise. A building whose base
// is above the ground has a mesh from its base up but no occluder (only what is solid from the
// ground may occlude). Occluders are the footprints themselves (a footprint with courtyards
// as the triangles of its roof), so that buildings sharing OSM nodes touch exactly and fuse
// into one blocker (visibility/occluder_set.h).
//
// Bad data never stops an import: rings with duplicate points or spikes are repaired; rings
// that are not simple, have fewer than 3 points, lack node locations (an extract's edge) or
// fail to assemble are skipped, each counted by reason in OsmImportSummary.

#include <absl/status/statusor.h>

#include <atomic>
#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>

#include "scenes/progress.h"
#include "scenes/scene.h"

namespace vistream::scenes {

// Longitude and latitude in degrees.
struct GeoBox {
  double min_lon = 0.0, min_lat = 0.0, max_lon = 0.0, max_lat = 0.0;
};

// "min_lon,min_lat,max_lon,max_lat" (osmium's order); an error names the problem.
absl::StatusOr<GeoBox> ParseGeoBox(std::string_view text);

struct OsmImportOptions {
  std::optional<GeoBox> bbox;  // keep only buildings with every node inside
  double storey_m = 3.0;
  std::string name;  // the scene's name; default: the file's stem
};

struct OsmImportSummary {
  uint64_t buildings = 0;  // objects in the scene
  uint64_t from_ways = 0, from_relations = 0;
  uint64_t outer_rings = 0, inner_rings = 0;
  uint64_t occluders = 0;
  uint64_t height_tagged = 0, levels_tagged = 0, height_by_rule = 0;
  uint64_t raised = 0;  // base above the ground: no occluder
  // Repairs (the building was kept).
  uint64_t repaired_duplicate_points = 0, repaired_spikes = 0;
  uint64_t dropped_inner_rings = 0;  // not simple or not inside the outer ring after snapping
  uint64_t bad_height_tags = 0;      // unreadable height/levels values, the next rule used
  // Skipped buildings or rings, by reason.
  std::map<std::string, uint64_t> skipped;
  std::string utm_zone;  // e.g. "32N"
  double seconds = 0.0;

  uint64_t Repaired() const {
    return repaired_duplicate_points + repaired_spikes + dropped_inner_rings;
  }
  uint64_t Skipped() const;
};

// The building type's storeys when no tag gives a height: e.g. 1 for garage or shed, 2 for
// house, 5 for apartments, 4 for anything else ("yes").
int DefaultLevels(std::string_view building);

// Parses a length tag ("12", "12.5 m", "40 ft", "12'6\""): metres, or none if unreadable.
std::optional<double> ParseLength(std::string_view text);

// Imports `path` (.osm, .osm.pbf, .pbf; by extension). Errors name the file and what is wrong
// (missing, truncated, not OSM data, no buildings left).
absl::StatusOr<Scene> ImportOsm(const std::string& path, const OsmImportOptions& options,
                                OsmImportSummary* summary = nullptr,
                                const RunControl& run = {});

}  // namespace vistream::scenes
