// Walks an OpenStreetMap import derives from its highway=* ways (scenes/osm_import.h): a
// hand-made file whose street graph is known exactly, and the Monaco extract.
#include <gtest/gtest.h>

#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <glm/geometric.hpp>
#include <set>

#include "scenes/osm_import.h"
#include "scenes/osm_read.h"

namespace vistream::scenes {
namespace {

namespace fs = std::filesystem;

const std::string kStreets = std::string(VISTREAM_SOURCE_DIR "/tests/osm/streets.osm");
const std::string kMonaco = std::string(VISTREAM_SOURCE_DIR "/../shared/data/osm/monaco.osm.pbf");

// A node's scene-local position as the import makes it: UTM in the scene's zone, less the
// origin, snapped to 1/256 m.
glm::dvec2 Local(const Scene& s, double lat, double lon, int zone) {
  int z;
  bool north;
  double x, y;
  GeographicLib::UTMUPS::Forward(lat, lon, z, north, x, y, zone);
  return {std::round((x - s.origin.x) * 256.0) / 256.0, std::round((y - s.origin.y) * 256.0) / 256.0};
}

TEST(OsmWalks, WalkableHighwaysAreTheDocumentedOnes) {
  for (const char* v : {"footway", "path", "pedestrian", "steps", "living_street", "residential", "service",
                        "unclassified", "track", "tertiary", "secondary_link", "primary", "trunk"}) {
    EXPECT_TRUE(IsWalkableHighway(v)) << v;
  }
  for (const char* v : {"motorway", "motorway_link", "proposed", "construction", "abandoned", "platform", "raceway",
                        "corridor", "elevator", "", "Footway"}) {
    EXPECT_FALSE(IsWalkableHighway(v)) << v;
  }
}

TEST(OsmWalks, HandMadeStreetsGiveTheirExactGraphAndWalks) {
  OsmImportSummary sum;
  absl::StatusOr<Scene> s = ImportOsm(kStreets, {}, &sum);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(sum.buildings, 2u);
  // Main Street, the footway and the service road; not the proposed way, the tunnel or the fence.
  EXPECT_EQ(sum.highway_ways, 3u);
  EXPECT_EQ(sum.street_edges, 4u);  // 1-2, 2-3, 2-4, 6-7
  const glm::dvec2 p1 = Local(*s, 43.73, 7.417, 32), p2 = Local(*s, 43.73, 7.42, 32), p3 = Local(*s, 43.73, 7.423, 32),
                   p4 = Local(*s, 43.732, 7.42, 32);
  ASSERT_EQ(s->paths.size(), 2u);
  ASSERT_EQ(sum.walks.size(), 2u);
  for (const std::string& n : sum.walk_notes) std::printf("note: %s\n", n.c_str());
  // The longest shortest path: along Main Street from end to end (its middle node dropped by
  // the simplification: the street is straight to well under a metre).
  const ScenePath& w1 = s->paths[0];
  EXPECT_EQ(w1.name, "street 1 (Main Street)");
  ASSERT_EQ(w1.waypoints.size(), 2u);
  const std::set<std::pair<double, double>> ends{{w1.waypoints[0].x, w1.waypoints[0].y}, {w1.waypoints[1].x, w1.waypoints[1].y}};
  EXPECT_EQ(ends, (std::set<std::pair<double, double>>{{p1.x, p1.y}, {p3.x, p3.y}}));
  EXPECT_NEAR(sum.walks[0].length_m, glm::distance(p1, p3), 1e-6);
  EXPECT_GT(sum.walks[0].length_m, 450.0);
  // Then from the footway's end, the node farthest from walk 1, to a Main Street end.
  const ScenePath& w2 = s->paths[1];
  EXPECT_EQ(w2.name, "street 2 (Main Street)");  // 241 m of its 463 m
  ASSERT_EQ(w2.waypoints.size(), 3u);
  EXPECT_EQ(w2.waypoints[0], p4);
  EXPECT_EQ(w2.waypoints[1], p2);
  EXPECT_TRUE(w2.waypoints[2] == p1 || w2.waypoints[2] == p3);
  EXPECT_EQ(sum.walks[1].name, w2.name);
  EXPECT_GE(sum.walks[1].length_m, 200.0);
  // Every node of the T lies on a walk now: no third.
  ASSERT_FALSE(sum.walk_notes.empty());
  EXPECT_NE(sum.walk_notes[0].find("every node lies on an earlier walk"), std::string::npos) << sum.walk_notes[0];

  // No walks asked for: none.
  OsmImportOptions none;
  none.walks = 0;
  OsmImportSummary sum0;
  absl::StatusOr<Scene> s0 = ImportOsm(kStreets, none, &sum0);
  ASSERT_TRUE(s0.ok());
  EXPECT_TRUE(s0->paths.empty());
  EXPECT_EQ(sum0.highway_ways, 0u);
}

TEST(OsmWalks, MonacoWalksAreLongAndLieOnItsHighways) {
  if (!fs::exists(kMonaco)) GTEST_SKIP() << kMonaco << " is absent: Monaco's walks are not tested";
  OsmImportSummary sum;
  absl::StatusOr<Scene> s = ImportOsm(kMonaco, {}, &sum);
  ASSERT_TRUE(s.ok()) << s.status();
  std::printf("%llu highway ways, %llu street edges; walks:", static_cast<unsigned long long>(sum.highway_ways),
              static_cast<unsigned long long>(sum.street_edges));
  for (const OsmWalkSummary& w : sum.walks) std::printf(" '%s' %.0f m", w.name.c_str(), w.length_m);
  std::printf("\n");
  EXPECT_GT(sum.highway_ways, 1000u);
  ASSERT_EQ(s->paths.size(), 3u);
  // The highways' nodes as the import places them (read again, projected here).
  std::vector<RawBuilding> buildings;
  std::vector<RawHighway> highways;
  OsmImportSummary again;
  ASSERT_TRUE(ReadOsmBuildings(kMonaco, std::nullopt, &buildings, &again, {}, &highways).ok());
  EXPECT_EQ(again.highway_ways, sum.highway_ways);
  std::vector<std::vector<glm::dvec2>> lines;
  for (const RawHighway& h : highways) {
    std::vector<glm::dvec2> line;
    for (const osmium::Location& l : h.nodes) line.push_back(Local(*s, l.lat(), l.lon(), 32));
    lines.push_back(std::move(line));
  }
  for (size_t i = 0; i < s->paths.size(); ++i) {
    const ScenePath& w = s->paths[i];
    EXPECT_GE(sum.walks[i].length_m, 200.0) << w.name;
    for (const glm::dvec2& p : w.waypoints) {
      EXPECT_TRUE(p.x >= s->bounds.min.x && p.x <= s->bounds.max.x && p.y >= s->bounds.min.y && p.y <= s->bounds.max.y);
      // Each waypoint is a highway node (to a millimetre).
      bool node = false;
      for (const auto& line : lines) {
        for (const glm::dvec2& q : line) node = node || glm::distance(p, q) < 1e-3;
        if (node) break;
      }
      EXPECT_TRUE(node) << w.name << ": (" << p.x << ", " << p.y << ") is not a highway node";
    }
  }
}

}  // namespace
}  // namespace vistream::scenes
