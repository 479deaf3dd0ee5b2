#pragma once
// Reading an OpenStreetMap file into buildings and building parts, still in degrees: the first
// half of ImportOsm (scenes/osm_import.h), apart so that each half stays one idea.

#include <absl/status/status.h>

#include <cstdint>
#include <map>
#include <optional>
#include <osmium/osm/location.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "scenes/osm_import_types.h"
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

// A way tagged highway=* that people can walk along (IsWalkableHighway), still in degrees: one
// run of consecutive nodes with locations (inside the bbox when one is given); a way whose
// nodes leave the extract or the bbox gives one RawHighway per run of at least 2 nodes.
struct RawHighway {
  std::string name;     // "way/12"
  std::string street;   // its name=* (may be empty)
  std::string highway;  // the highway=* value
  std::vector<osmium::Location> nodes;
};

// Whether highway=`value` is a way to walk a city along: footway, path, pedestrian, steps,
// living_street, residential, service, unclassified, road, track, cycleway, bridleway,
// tertiary, secondary, primary and trunk (and their _link roads). Not: motorways, and what is
// proposed, under construction, abandoned, disused, razed, a platform, a raceway, an indoor
// corridor or an elevator. Ways in a tunnel (tunnel=* but "no"), or indoor=yes, are left out
// by the reader whatever their value: their eye would be under the ground or inside a building.
bool IsWalkableHighway(std::string_view value);

// Reads `path` (.osm, .osm.pbf, .osm.bz2, .osm.gz) and appends every building and building
// part to `out`, and, when `highways` is not null, every walkable highway way to it (the same
// pass over the file); highway ways read are counted in summary->highway_ways; those that cannot be assembled, lie outside `bbox` or are a way drawn again
// as a building relation's outline (then merged into the relation) are counted in `summary`
// (skipped by reason, merged_way_outlines). Node ids may be negative and in any order. An
// error names the file when it is not readable as OSM data, or when cancelled.
absl::Status ReadOsmBuildings(const std::string& path, const std::optional<GeoBox>& bbox,
                              std::vector<RawBuilding>* out, OsmImportSummary* summary,
                              const RunControl& run, std::vector<RawHighway>* highways = nullptr);

}  // namespace vistream::scenes
