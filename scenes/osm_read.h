#pragma once
// Reading an OpenStreetMap file into buildings and building parts, still in degrees: the first
// half of ImportOsm (scenes/osm_import.h), apart so that each half stays one idea.

#include <absl/status/status.h>

#include <cstdint>
#include <map>
#include <optional>
#include <osmium/osm/location.hpp>
#include <string>
#include <vector>

#include "scenes/osm_import.h"
#include "scenes/osm_tags.h"
#include "scenes/progress.h"

namespace vistream::scenes {

// One outer ring and its inner rings, open (the first node not repeated), in degrees.
struct RawPolygon {
  std::vector<osmium::Location> outer;
  std::vector<std::vector<osmium::Location>> holes;
};

// A building or building part as assembled from a closed way or a multipolygon relation.
struct RawBuilding {
  std::string name;  // "way/12", "relation/-3"
  bool from_relation = false;
  bool part = false;  // building:part=* (not "no"): Simple 3D Buildings
  std::vector<RawPolygon> polygons;
  HeightTags tags;
  uint64_t duplicate_nodes = 0;  // repaired by the assembler
};

// Reads `path` (.osm, .osm.pbf, .osm.bz2, .osm.gz) and appends every building and building
// part to `out`; those that cannot be assembled, lie outside `bbox` or are a way drawn again
// as a building relation's outline (then merged into the relation) are counted in `summary`
// (skipped by reason, merged_way_outlines). Node ids may be negative and in any order. An
// error names the file when it is not readable as OSM data, or when cancelled.
absl::Status ReadOsmBuildings(const std::string& path, const std::optional<GeoBox>& bbox,
                              std::vector<RawBuilding>* out, OsmImportSummary* summary,
                              const RunControl& run);

}  // namespace vistream::scenes
