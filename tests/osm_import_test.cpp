#include "scenes/osm_import.h"

#include <gtest/gtest.h>

#include <GeographicLib/UTMUPS.hpp>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <glm/geometric.hpp>
#include <osmium/io/pbf_output.hpp>
#include <osmium/io/xml_input.hpp>
#include <set>

#include "scenes/catalog.h"
#include "scenes/mesh.h"
#include "scenes/progress.h"
#include "tests/osm_test_util.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

namespace fs = std::filesystem;

std::string Data(const std::string& name) {
  return std::string(VISTREAM_SOURCE_DIR "/tests/osm/") + name;
}
const std::string kMonaco = std::string(VISTREAM_SOURCE_DIR "/../shared/data/osm/monaco.osm.pbf");

Scene Import(const std::string& path, OsmImportSummary* sum, const OsmImportOptions& options = {}) {
  absl::StatusOr<Scene> s = ImportOsm(path, options, sum);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? *std::move(s) : Scene{};
}

using testing_osm::Closed;

using testing_osm::RoofArea;

const Object* ByName(const Scene& s, const std::string& name) {
  for (const Object& o : s.objects) {
    if (o.name == name) return &o;
  }
  return nullptr;
}

TEST(OsmImport, ParsesLengthsInTheirUnits) {
  EXPECT_DOUBLE_EQ(*ParseLength("12"), 12.0);
  EXPECT_DOUBLE_EQ(*ParseLength(" 12.5 m"), 12.5);
  EXPECT_DOUBLE_EQ(*ParseLength("12.5m"), 12.5);
  EXPECT_DOUBLE_EQ(*ParseLength("3 metres"), 3.0);
  EXPECT_DOUBLE_EQ(*ParseLength("40 ft"), 40 * 0.3048);
  EXPECT_DOUBLE_EQ(*ParseLength("40 Feet"), 40 * 0.3048);
  EXPECT_DOUBLE_EQ(*ParseLength("12'6\""), 12 * 0.3048 + 6 * 0.0254);
  EXPECT_DOUBLE_EQ(*ParseLength("12'"), 12 * 0.3048);
  EXPECT_DOUBLE_EQ(*ParseLength("250 cm"), 2.5);
  for (const char* bad : {"", "tall", "-3", "12 parsecs", "1.2.3", "12'6", "m", "nan", "inf"}) {
    EXPECT_FALSE(ParseLength(bad).has_value()) << bad;
  }
}

TEST(OsmImport, ParsesBoxesAndNamesWhatIsWrong) {
  const absl::StatusOr<GeoBox> b = ParseGeoBox("7.40, 43.72,7.44,43.75");
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_DOUBLE_EQ(b->min_lon, 7.40);
  EXPECT_DOUBLE_EQ(b->max_lat, 43.75);
  EXPECT_NE(ParseGeoBox("7.40,43.72,7.44").status().message().find("four numbers"),
            std::string::npos);
  EXPECT_NE(ParseGeoBox("7.40,x,7.44,43.75").status().message().find("'x' is not a number"),
            std::string::npos);
  EXPECT_NE(ParseGeoBox("7.44,43.72,7.40,43.75").status().message().find("min_lon < max_lon"),
            std::string::npos);
  EXPECT_FALSE(ParseGeoBox("7,43,7,91").ok());
}

TEST(OsmImport, DefaultHeightsFollowTheBuildingType) {
  EXPECT_EQ(DefaultLevels("garage"), 1);
  EXPECT_EQ(DefaultLevels("house"), 2);
  EXPECT_EQ(DefaultLevels("apartments"), 5);
  EXPECT_EQ(DefaultLevels("yes"), 4);
  EXPECT_EQ(DefaultLevels("something new"), 4);
}

TEST(OsmImport, CourtyardIsAHoleInTheRoofAndTheOccluders) {
  OsmImportSummary sum;
  const Scene s = Import(Data("courtyard.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(sum.from_relations, 1u);
  EXPECT_EQ(sum.outer_rings, 1u);
  EXPECT_EQ(sum.inner_rings, 1u);
  EXPECT_EQ(sum.Skipped(), 0u);
  const Mesh& m = s.objects[0].mesh;
  EXPECT_TRUE(Closed(m));
  EXPECT_FLOAT_EQ(static_cast<float>(s.objects[0].bounds.max.z), 20.0f);
  // Outer 0.0010 x 0.0010 degrees, inner 0.0004 x 0.0004: the roof is 84% of the outer ring.
  // UTM turns the squares a little (meridian convergence): the outer ring's corners are the
  // points lowest, rightmost, highest and leftmost, counter-clockwise.
  std::vector<glm::dvec2> corners(4, glm::dvec2(m.positions[0]));
  for (const glm::vec3& p : m.positions) {
    const glm::dvec2 q(p);
    if (q.y < corners[0].y) corners[0] = q;
    if (q.x > corners[1].x) corners[1] = q;
    if (q.y > corners[2].y) corners[2] = q;
    if (q.x < corners[3].x) corners[3] = q;
  }
  const double outer = SignedArea(corners);
  const double roof = RoofArea(m, 20.0f);
  EXPECT_NEAR(roof / outer, 0.84, 0.01);
  // The occluders cover the roof exactly, and none covers the courtyard's middle.
  double covered = 0.0;
  const glm::dvec2 middle(0.5 * (s.objects[0].bounds.min.x + s.objects[0].bounds.max.x),
                          0.5 * (s.objects[0].bounds.min.y + s.objects[0].bounds.max.y));
  for (const Occluder25D& o : s.occluders) {
    EXPECT_EQ(o.object, 0u);
    EXPECT_DOUBLE_EQ(o.height, 20.0);
    ASSERT_GT(SignedArea(o.footprint), 0.0);  // counter-clockwise
    covered += SignedArea(o.footprint);
    bool inside = true;
    for (size_t k = 0; k < o.footprint.size(); ++k) {
      const glm::dvec2 a = o.footprint[k], b = o.footprint[(k + 1) % o.footprint.size()];
      inside &= (b.x - a.x) * (middle.y - a.y) - (b.y - a.y) * (middle.x - a.x) > 0.0;
    }
    EXPECT_FALSE(inside);
  }
  EXPECT_NEAR(covered, roof, 1e-3 * roof);
}

TEST(OsmImport, MultipolygonWithTwoOutersIsOneBuilding) {
  OsmImportSummary sum;
  const Scene s = Import(Data("multipolygon.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 2u);
  EXPECT_EQ(sum.from_relations, 1u);
  EXPECT_EQ(sum.from_ways, 1u);
  EXPECT_EQ(sum.outer_rings, 3u);
  const Object* rel = ByName(s, "relation/200");
  const Object* house = ByName(s, "way/22");
  ASSERT_NE(rel, nullptr);
  ASSERT_NE(house, nullptr);
  EXPECT_TRUE(Closed(rel->mesh));
  EXPECT_EQ(rel->mesh.TriangleCount(), 24u);             // two boxes
  EXPECT_DOUBLE_EQ(rel->bounds.max.z, 2 * 3.0 + 1.0);    // 2 levels and the roof
  EXPECT_DOUBLE_EQ(house->bounds.max.z, 2 * 3.0 + 1.0);  // a house without tags: 2 storeys
  size_t rel_occluders = 0;
  for (const Occluder25D& o : s.occluders) rel_occluders += o.object == rel->id;
  EXPECT_EQ(rel_occluders, 2u);
}

TEST(OsmImport, HeightsFromTagsLevelsAndTheRule) {
  OsmImportSummary sum;
  const Scene s = Import(Data("heights.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 10u);
  const double snap = 1.0 / 256.0;
  struct Want {
    const char* name;
    double base, top;
    bool occluder;
  };
  const Want want[] = {
      {"way/30", 0, 12, true},
      {"way/31", 0, 40 * 0.3048, true},
      {"way/32", 0, 12 * 0.3048 + 6 * 0.0254, true},
      {"way/33", 0, 15.5, true},
      {"way/34", 0, 4 * 3.0 + 1.0, true},
      {"way/35", 0, 3 * 3.0 + 1 * 3.0, true},
      {"way/36", 0, 1 * 3.0 + 1.0, true},   // garage
      {"way/37", 0, 4 * 3.0 + 1.0, true},   // "tall": unreadable, so the rule
      {"way/38", 5, 10, false},             // min_height: raised, no occluder
      {"way/39", 6, 5 * 3.0 + 1.0, false},  // building:min_level 2
  };
  for (const Want& w : want) {
    const Object* o = ByName(s, w.name);
    ASSERT_NE(o, nullptr) << w.name;
    EXPECT_TRUE(Closed(o->mesh)) << w.name;
    EXPECT_NEAR(o->bounds.min.z, w.base, snap) << w.name;
    EXPECT_NEAR(o->bounds.max.z, w.top, snap) << w.name;
    size_t occluders = 0;
    for (const Occluder25D& oc : s.occluders) {
      if (oc.object != o->id) continue;
      ++occluders;
      EXPECT_NEAR(oc.height, w.top, snap) << w.name;
    }
    EXPECT_EQ(occluders, w.occluder ? 1u : 0u) << w.name;
  }
  EXPECT_EQ(sum.height_tagged, 5u);
  EXPECT_EQ(sum.levels_tagged, 3u);
  EXPECT_EQ(sum.height_by_rule, 2u);
  EXPECT_EQ(sum.bad_height_tags, 1u);
  EXPECT_EQ(sum.raised, 2u);
}

TEST(OsmImport, SelfIntersectingRingIsSkippedAndCounted) {
  OsmImportSummary sum;
  const Scene s = Import(Data("self_intersecting.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "way/41");
  EXPECT_EQ(sum.skipped["self-intersecting ring"], 1u);
  EXPECT_EQ(sum.Skipped(), 1u);
}

TEST(OsmImport, MissingNodesShortAndOpenWaysAreSkippedAndCounted) {
  OsmImportSummary sum;
  const Scene s = Import(Data("missing_nodes.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "way/50");
  EXPECT_EQ(sum.skipped["way with missing nodes"], 1u);
  EXPECT_EQ(sum.skipped["way with fewer than 4 nodes"], 1u);
  EXPECT_EQ(sum.skipped["way not closed"], 1u);
  EXPECT_EQ(sum.Skipped(), 3u);
}

TEST(OsmImport, TerracedHousesShareTheirWallsExactly) {
  OsmImportSummary sum;
  const Scene s = Import(Data("terrace.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 3u);
  ASSERT_EQ(s.occluders.size(), 3u);
  // Neighbours share two footprint corners, bit for bit (the party wall).
  for (size_t k = 0; k + 1 < 3; ++k) {
    std::set<std::pair<double, double>> a, b;
    for (const glm::dvec2& p : s.occluders[k].footprint) a.insert({p.x, p.y});
    for (const glm::dvec2& p : s.occluders[k + 1].footprint) b.insert({p.x, p.y});
    std::vector<std::pair<double, double>> shared;
    std::set_intersection(a.begin(), a.end(), b.begin(), b.end(), std::back_inserter(shared));
    EXPECT_EQ(shared.size(), 2u) << "houses " << k << " and " << k + 1;
  }
}

// A building far from the rest (found by the fuzzer: GeographicLib refuses points far outside
// the centre's UTM zone) is skipped, and the rest is imported around its own centre.
TEST(OsmImport, StrayBuildingFarAwayIsSkipped) {
  OsmImportSummary sum;
  const Scene s = Import(Data("far_away.osm"), &sum);
  ASSERT_EQ(s.objects.size(), 3u);
  EXPECT_EQ(sum.skipped["farther than 65 km from the data's centre"], 1u);
  EXPECT_EQ(sum.utm_zone, "32n");
  EXPECT_LT(glm::length(glm::dvec2(s.bounds.max)), 500.0);
}

TEST(OsmImport, BoxKeepsOnlyBuildingsWhollyInside) {
  OsmImportSummary sum;
  OsmImportOptions options;
  // The row runs east from lon 7.4200 in steps of 0.0001: keep the first house only.
  options.bbox = GeoBox{7.41995, 43.72995, 7.42015, 43.73025};
  const Scene s = Import(Data("terrace.osm"), &sum, options);
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "way/60");
  EXPECT_EQ(sum.skipped["outside the bbox"], 2u);
}

TEST(OsmImport, BadFilesGiveClearErrors) {
  const absl::StatusOr<Scene> empty = ImportOsm(Data("empty.osm"), {});
  ASSERT_FALSE(empty.ok());
  EXPECT_NE(empty.status().message().find("empty.osm: the file is empty"), std::string::npos)
      << empty.status();

  const absl::StatusOr<Scene> missing = ImportOsm(Data("no-such-file.osm"), {});
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);

  const std::string dir = testing::TempDir();
  const std::string garbage = dir + "/garbage.osm";
  std::ofstream(garbage) << "this is not XML";
  const absl::StatusOr<Scene> bad = ImportOsm(garbage, {});
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("garbage.osm: not readable as OpenStreetMap data"),
            std::string::npos)
      << bad.status();

  const std::string nothing = dir + "/nothing.osm";
  std::ofstream(nothing)
      << "<?xml version='1.0'?><osm version='0.6'><node id='1' lat='1' lon='1'/></osm>";
  const absl::StatusOr<Scene> none = ImportOsm(nothing, {});
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.status().message().find("no buildings"), std::string::npos) << none.status();
}

// Writes `xml` again as PBF with libosmium.
void XmlToPbf(const std::string& xml, const std::string& pbf) {
  osmium::io::Reader reader(xml);
  osmium::io::Header header;
  osmium::io::Writer writer(pbf, header, osmium::io::overwrite::allow);
  while (osmium::memory::Buffer buffer = reader.read()) writer(std::move(buffer));
  writer.close();
  reader.close();
}

TEST(OsmImport, PbfReadsLikeXmlAndTruncatedPbfIsAnError) {
  const std::string dir = testing::TempDir();
  const std::string pbf = dir + "/heights.osm.pbf";
  XmlToPbf(Data("heights.osm"), pbf);
  OsmImportSummary xml_sum, pbf_sum;
  const Scene from_xml = Import(Data("heights.osm"), &xml_sum);
  const Scene from_pbf = Import(pbf, &pbf_sum);
  ASSERT_EQ(from_pbf.objects.size(), from_xml.objects.size());
  EXPECT_EQ(testing::SceneHash(from_pbf), testing::SceneHash(from_xml));

  std::ifstream in(pbf, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(bytes.size(), 100u);
  int errors = 0;
  for (const size_t keep : {size_t{10}, size_t{40}, bytes.size() / 2, bytes.size() - 1}) {
    const std::string cut = dir + "/cut.osm.pbf";
    std::ofstream(cut, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(keep));
    const absl::StatusOr<Scene> s = ImportOsm(cut, {});
    ASSERT_FALSE(s.ok()) << "kept " << keep << " of " << bytes.size() << " bytes";
    ++errors;
    EXPECT_NE(s.status().message().find("cut.osm.pbf: not readable as OpenStreetMap data"),
              std::string::npos)
        << s.status();
  }
  EXPECT_EQ(errors, 4);
}

// The real extract: ../shared/data/osm/monaco.osm.pbf (OpenStreetMap, ODbL).
TEST(OsmImport, MonacoHasItsBuildingsClosedAndInsideTheExtract) {
  if (!fs::exists(kMonaco)) {
    GTEST_SKIP() << kMonaco << " is absent: the Monaco import is not tested";
  }
  OsmImportSummary sum;
  const Scene s = Import(kMonaco, &sum);
  EXPECT_GE(s.objects.size(), 20000u);
  EXPECT_EQ(sum.buildings, s.objects.size());
  EXPECT_EQ(sum.utm_zone, "32n");
  size_t open = 0;
  for (const Object& o : s.objects) open += !Closed(o.mesh);
  EXPECT_EQ(open, 0u);
  // Inside the extract's bounding box (its header), projected as the importer does.
  osmium::io::Reader reader(kMonaco, osmium::osm_entity_bits::nothing);
  const osmium::Box box = reader.header().box();
  reader.close();
  ASSERT_TRUE(box.valid());
  glm::dvec2 lo(1e300), hi(-1e300);
  for (const double lat : {box.bottom_left().lat(), box.top_right().lat()}) {
    for (const double lon : {box.bottom_left().lon(), box.top_right().lon()}) {
      int zone;
      bool north;
      double x, y;
      GeographicLib::UTMUPS::Forward(lat, lon, zone, north, x, y, 32);
      lo = glm::min(lo, glm::dvec2(x, y) - glm::dvec2(s.origin));
      hi = glm::max(hi, glm::dvec2(x, y) - glm::dvec2(s.origin));
    }
  }
  // The box's edges bow a little under UTM: a margin of a few metres.
  EXPECT_GE(s.bounds.min.x, lo.x - 5.0);
  EXPECT_GE(s.bounds.min.y, lo.y - 5.0);
  EXPECT_LE(s.bounds.max.x, hi.x + 5.0);
  EXPECT_LE(s.bounds.max.y, hi.y + 5.0);
  EXPECT_GE(s.bounds.min.z, 0.0);
  // The summary accounts for what was left out (the extract has a few broken ways), by reasons
  // the importer names.
  EXPECT_GT(sum.Skipped(), 0u);
  const std::set<std::string> known = {"self-intersecting ring", "way not closed",
                                       "way with fewer than 4 nodes", "way with missing nodes",
                                       "relation with members missing"};
  for (const auto& [reason, n] : sum.skipped)
    EXPECT_TRUE(known.count(reason)) << reason << ": " << n;
  EXPECT_EQ(sum.occluders, s.occluders.size());
}

// The catalog entry builds the same scene (its walk is checked with every shipped entry's in
// catalog_test).
TEST(OsmImport, MonacoCatalogEntryImportsTheExtract) {
  if (!fs::exists(kMonaco)) {
    GTEST_SKIP() << kMonaco << " is absent: the Monaco catalog entry is not tested";
  }
  const absl::StatusOr<CatalogEntry> e = FindCatalogEntry("monaco");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->source.kind, SceneSource::Kind::kOsm);
  const absl::StatusOr<Scene> s = BuildScene(*e);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->name, "monaco");
  EXPECT_GE(s->objects.size(), 20000u);
}

}  // namespace
}  // namespace vistream::scenes
