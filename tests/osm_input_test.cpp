// OpenStreetMap input as users have it: files saved by editors, compressed extracts, touching
// courtyards, data by the equator and a zone edge, huge rings.
#include <bzlib.h>
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "scenes/osm_import.h"
#include "tests/osm_test_util.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

using testing_osm::ByName;
using testing_osm::Closed;
using testing_osm::MetricRelation;
using testing_osm::MetricWay;
using testing_osm::OccluderArea;
using testing_osm::RoofArea;
using testing_osm::Shoelace;
using testing_osm::WriteMetricOsm;

using testing_osm::Rect;

const glm::dvec2 kZurich(47.0, 8.0);

TEST(OsmImport, NegativeIdsImportLikePositiveOnes) {
  // As JOSM saves objects not yet uploaded: negative ids, no version/user/timestamp, and here
  // also ways before their nodes.
  const std::vector<MetricWay> ways = {{-201, Rect(0, 0, 20, 30), {{"building", "yes"}, {"height", "12"}}},
                                       {-202, Rect(40, 0, 50, 10), {{"building", "house"}}}};
  const std::string dir = testing::TempDir();
  for (const bool shuffle : {false, true}) {
    const std::string path = WriteMetricOsm(dir + "/editor.osm", kZurich, ways, {}, true, shuffle);
    OsmImportSummary sum;
    const absl::StatusOr<Scene> s = ImportOsm(path, {}, &sum);
    ASSERT_TRUE(s.ok()) << s.status();
    ASSERT_EQ(s->objects.size(), 2u);
    EXPECT_EQ(sum.Skipped(), 0u);
    const Object* a = ByName(*s, "way/-201");
    ASSERT_NE(a, nullptr);
    EXPECT_DOUBLE_EQ(a->bounds.max.z, 12.0);
    EXPECT_NEAR(RoofArea(a->mesh, 12.0f), 20.0 * 30.0, 0.2);  // 100 m of walls, 2 mm snapping
    EXPECT_NEAR(a->bounds.max.x - a->bounds.min.x, 20.0, 0.02);
  }
}

TEST(OsmImport, NothingLeftNamesEverySkipReason) {
  const std::string path = testing::TempDir() + "/broken.osm";
  std::ofstream(path) << "<?xml version='1.0'?><osm version='0.6'>"
                         "<node id='-1' lat='47' lon='8'/><node id='-2' lat='47' lon='8.001'/>"
                         "<node id='-3' lat='47.001' lon='8.001'/>"
                         "<way id='-9'><nd ref='-1'/><nd ref='-2'/><nd ref='-3'/><nd ref='-4'/>"
                         "<nd ref='-1'/><tag k='building' v='yes'/></way></osm>";
  OsmImportSummary sum;
  const absl::StatusOr<Scene> s = ImportOsm(path, {}, &sum);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("1 skipped (way with missing nodes: 1)"), std::string::npos)
      << s.status();
  EXPECT_EQ(sum.skipped["way with missing nodes"], 1u);
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Compressed with zlib and libbz2 directly, not through libosmium.
void Gzip(const std::string& text, const std::string& path) {
  gzFile f = gzopen(path.c_str(), "wb");
  ASSERT_NE(f, nullptr);
  ASSERT_EQ(gzwrite(f, text.data(), static_cast<unsigned>(text.size())), static_cast<int>(text.size()));
  ASSERT_EQ(gzclose(f), Z_OK);
}
void Bzip2(const std::string& text, const std::string& path) {
  std::string out(text.size() + text.size() / 100 + 600, '\0');
  unsigned size = static_cast<unsigned>(out.size());
  std::string in = text;
  ASSERT_EQ(BZ2_bzBuffToBuffCompress(out.data(), &size, in.data(), static_cast<unsigned>(in.size()), 9, 0, 0),
            BZ_OK);
  std::ofstream(path, std::ios::binary).write(out.data(), size);
}

TEST(OsmImport, CompressedExtractsReadLikeTheirXml) {
  const std::string dir = testing::TempDir();
  const std::string xml = WriteMetricOsm(
      dir + "/plain.osm", kZurich,
      {{1, Rect(0, 0, 20, 30), {{"building", "yes"}, {"height", "12"}}},
       {2, Rect(40, 0, 50, 10), {{"building", "garage"}}}});
  const absl::StatusOr<Scene> plain = ImportOsm(xml, {});
  ASSERT_TRUE(plain.ok()) << plain.status();
  const std::string text = ReadAll(xml);
  Gzip(text, dir + "/plain.osm.gz");
  Bzip2(text, dir + "/plain.osm.bz2");
  for (const char* ext : {".osm.gz", ".osm.bz2"}) {
    const absl::StatusOr<Scene> s = ImportOsm(dir + "/plain" + ext, {});
    ASSERT_TRUE(s.ok()) << ext << ": " << s.status();
    EXPECT_EQ(testing::SceneHash(*s), testing::SceneHash(*plain)) << ext;
    // Cut short: an error naming the file, never a crash.
    const std::string bytes = ReadAll(dir + "/plain" + ext);
    const std::string cut = dir + "/cut" + ext;
    std::ofstream(cut, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size() / 2));
    const absl::StatusOr<Scene> c = ImportOsm(cut, {});
    ASSERT_FALSE(c.ok()) << ext;
    EXPECT_NE(c.status().message().find(cut), std::string::npos) << c.status();
  }
}

TEST(OsmImport, CourtyardTouchingTheOuterRingAtOneNodeIsKept) {
  // Outer 40 x 60 m with a node in the middle of its east side; the courtyard, a square of
  // 20 m diagonals standing on a corner, touches the outer ring at that node. A second courtyard touches the
  // first at one node (also valid).
  const std::vector<glm::dvec2> outer = {{0, 0}, {40, 0}, {40, 30}, {40, 60}, {0, 60}};
  const std::vector<glm::dvec2> court1 = {{40, 30}, {30, 20}, {20, 30}, {30, 40}};
  const std::vector<glm::dvec2> court2 = {{20, 30}, {10, 25}, {10, 35}};
  const std::string path = WriteMetricOsm(
      testing::TempDir() + "/touching.osm", kZurich,
      {{11, outer, {}}, {12, court1, {}}, {13, court2, {}}},
      {{21, {{11, "outer"}, {12, "inner"}, {13, "inner"}}, {{"type", "multipolygon"}, {"building", "yes"}, {"height", "12"}}}});
  OsmImportSummary sum;
  const absl::StatusOr<Scene> s = ImportOsm(path, {}, &sum);
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->objects.size(), 1u);
  EXPECT_EQ(sum.dropped_inner_rings, 0u);
  EXPECT_EQ(sum.inner_rings, 2u);
  const double want = Shoelace(outer) - std::abs(Shoelace(court1)) - std::abs(Shoelace(court2));
  ASSERT_NEAR(want, 2400.0 - 200.0 - 50.0, 1e-9);  // by hand: 40*60, 20*20/2, 10*10/2
  EXPECT_NEAR(RoofArea(s->objects[0].mesh, 12.0f), want, 0.2);
  EXPECT_NEAR(OccluderArea(*s, 0), want, 0.2);
  EXPECT_TRUE(Closed(s->objects[0].mesh));
}

// Positions relative to the first building are the metres written, whichever hemisphere or
// UTM zone each building's own position falls in.
void ExpectOffsetsKept(const glm::dvec2& centre, const std::vector<MetricWay>& ways, const char* zone) {
  OsmImportSummary sum;
  const absl::StatusOr<Scene> s = ImportOsm(WriteMetricOsm(testing::TempDir() + "/edge.osm", centre, ways), {}, &sum);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(sum.Skipped(), 0u);
  ASSERT_EQ(s->objects.size(), ways.size());
  EXPECT_EQ(sum.utm_zone, zone);
  const Object* first = ByName(*s, "way/" + std::to_string(ways[0].id));
  ASSERT_NE(first, nullptr);
  for (const MetricWay& w : ways) {
    const Object* o = ByName(*s, "way/" + std::to_string(w.id));
    ASSERT_NE(o, nullptr) << w.id;
    EXPECT_NEAR(o->bounds.min.x - first->bounds.min.x, w.ring[0].x - ways[0].ring[0].x, 0.02) << w.id;
    EXPECT_NEAR(o->bounds.min.y - first->bounds.min.y, w.ring[0].y - ways[0].ring[0].y, 0.02) << w.id;
  }
}

TEST(OsmImport, BuildingJustSouthOfTheEquatorStaysBesideItsNeighbours) {
  // The centre 0.0005 deg (55 m) north of the equator; the last house 10 m south of it.
  const glm::dvec2 centre(0.0005, 30.0);
  ExpectOffsetsKept(centre,
                    {{1, Rect(0, 0, 10, 10), {{"building", "yes"}}},
                     {2, Rect(20, 0, 30, 10), {{"building", "yes"}}},
                     {3, Rect(40, 0, 50, 10), {{"building", "yes"}}},
                     {4, Rect(0, -75, 10, -65), {{"building", "yes"}}}},
                    "36n");
}

TEST(OsmImport, BuildingJustAcrossAZoneEdgeStaysBesideItsNeighbours) {
  // The centre 0.0005 deg east of 6 E (zone 32 begins there); the last house about 60 m west.
  const glm::dvec2 centre(45.0, 6.0005);
  ExpectOffsetsKept(centre,
                    {{1, Rect(0, 0, 10, 10), {{"building", "yes"}}},
                     {2, Rect(20, 0, 30, 10), {{"building", "yes"}}},
                     {3, Rect(40, 0, 50, 10), {{"building", "yes"}}},
                     {4, Rect(-100, 0, -90, 10), {{"building", "yes"}}}},
                    "32n");
}

TEST(OsmImport, HugeRingWithAHugeCourtyardKeepsItsArea) {
  // 20,000 nodes on a circle of 300 m around a courtyard of 20,000 nodes on 150 m (on the 4 mm
  // grid); the area is the polygons' (shoelace), not the circles'.
  const int n = 20000;
  std::vector<glm::dvec2> outer, inner;
  for (int k = 0; k < n; ++k) {
    const double a = 2.0 * M_PI * k / n;
    outer.emplace_back(std::round(300.0 * std::cos(a) * 256.0) / 256.0, std::round(300.0 * std::sin(a) * 256.0) / 256.0);
    inner.emplace_back(std::round(150.0 * std::cos(a) * 256.0) / 256.0, std::round(150.0 * std::sin(a) * 256.0) / 256.0);
  }
  const std::vector<MetricWay> ways = {{1, outer, {}}, {2, inner, {}}};
  const std::string path = WriteMetricOsm(testing::TempDir() + "/huge.osm", kZurich, ways,
                                          {{9, {{1, "outer"}, {2, "inner"}}, {{"type", "multipolygon"}, {"building", "yes"}, {"height", "20"}}}});
  OsmImportSummary sum;
  const absl::StatusOr<Scene> s = ImportOsm(path, {}, &sum);
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->objects.size(), 1u);
  EXPECT_EQ(sum.inner_rings, 1u);
  const double want = Shoelace(outer) - Shoelace(inner);
  EXPECT_NEAR(RoofArea(s->objects[0].mesh, 20.0f), want, 1e-4 * want);
}

}  // namespace
}  // namespace vistream::scenes
