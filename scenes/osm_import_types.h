#pragma once
// What an OpenStreetMap import is bounded by and what it reports: the box of longitudes and
// latitudes it keeps (GeoBox, the catalog's "bbox" and `scene import-osm --bbox`) and its
// summary (OsmImportSummary), shared by the reader (scenes/osm_read.h, which fills the summary's
// reading counts) and the import (scenes/osm_import.h, the rest): the import calls the reader,
// and the reader needs nothing of the import's header.

#include <absl/status/statusor.h>

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace vistream::scenes {

// Longitude and latitude in degrees.
struct GeoBox {
  double min_lon = 0.0, min_lat = 0.0, max_lon = 0.0, max_lat = 0.0;
};

// "min_lon,min_lat,max_lon,max_lat" (osmium's order); an error names the problem.
absl::StatusOr<GeoBox> ParseGeoBox(std::string_view text);

// One derived walk, for the summary.
struct OsmWalkSummary {
  std::string name;
  double length_m = 0.0;
};

struct OsmImportSummary {
  uint64_t buildings = 0;  // objects in the scene
  uint64_t from_ways = 0, from_relations = 0;
  uint64_t outer_rings = 0, inner_rings = 0;
  uint64_t occluders = 0;
  uint64_t height_tagged = 0, levels_tagged = 0, height_by_rule = 0;
  uint64_t raised = 0;  // base above the ground: no occluder
  uint64_t parts = 0;   // building:part objects (also counted in buildings)
  uint64_t outlines_hidden_by_parts = 0;  // outlines wholly covered by their parts: not drawn
  uint64_t outlines_cut_by_parts = 0;     // outlines drawn only where no part covers them
  uint64_t merged_way_outlines = 0;       // ways that are also a building relation's outline
  // Repairs (the building was kept).
  uint64_t repaired_duplicate_points = 0, repaired_spikes = 0;
  uint64_t dropped_inner_rings = 0;  // not simple or not inside the outer ring after snapping
  uint64_t bad_height_tags = 0;      // unreadable height/levels values, the next rule used
  uint64_t implausible_heights = 0;  // values above max_height_m, the next rule used
  uint64_t min_height_above_height = 0;  // base at or above the top: base dropped, no occluder
  // Skipped buildings or rings, by reason.
  std::map<std::string, uint64_t> skipped;
  std::string utm_zone;  // e.g. "32N"
  uint64_t highway_ways = 0;   // walkable highway ways read (tunnels and indoor ways left out)
  uint64_t street_edges = 0;   // edges of the street graph (inside the buildings' bounds)
  std::vector<OsmWalkSummary> walks;  // the scene's paths, in order
  std::vector<std::string> walk_notes;  // why fewer or shorter walks (DerivedWalks::notes)
  double seconds = 0.0;

  uint64_t Repaired() const {
    return repaired_duplicate_points + repaired_spikes + dropped_inner_rings;
  }
  uint64_t Skipped() const;
};

}  // namespace vistream::scenes
