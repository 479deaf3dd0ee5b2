// Simple 3D Buildings (https://wiki.openstreetmap.org/wiki/Simple_3D_Buildings): parts give the
// shape and heights, the outline is drawn only where no part covers it.
#include <gtest/gtest.h>

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
using testing_osm::OccluderCount;
using testing_osm::RoofArea;
using testing_osm::WriteMetricOsm;

using testing_osm::Rect;

Scene Import(const std::vector<MetricWay>& ways, OsmImportSummary* sum,
             const std::vector<MetricRelation>& relations = {}) {
  const std::string path = WriteMetricOsm(testing::TempDir() + "/s3db.osm", {47.0, 8.0}, ways, relations);
  absl::StatusOr<Scene> s = ImportOsm(path, {}, sum);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? *std::move(s) : Scene{};
}

TEST(OsmParts, TowerPartRisesAboveItsLowOutline) {
  OsmImportSummary sum;
  const Scene s = Import({{1, Rect(0, 0, 40, 30), {{"building", "yes"}, {"height", "8"}}},
                          {2, Rect(15, 10, 25, 20), {{"building:part", "yes"}, {"height", "60"}}}},
                         &sum);
  ASSERT_EQ(s.objects.size(), 2u);
  EXPECT_EQ(sum.parts, 1u);
  EXPECT_EQ(sum.outlines_cut_by_parts, 1u);
  const Object* tower = ByName(s, "way/2");
  const Object* outline = ByName(s, "way/1");
  ASSERT_NE(tower, nullptr);
  ASSERT_NE(outline, nullptr);
  EXPECT_DOUBLE_EQ(tower->bounds.max.z, 60.0);
  EXPECT_DOUBLE_EQ(outline->bounds.max.z, 8.0);
  EXPECT_TRUE(Closed(outline->mesh));
  // The outline is drawn around the tower, not under it: 40*30 - 10*10.
  EXPECT_NEAR(RoofArea(outline->mesh, 8.0f), 1200.0 - 100.0, 0.2);
  EXPECT_NEAR(OccluderArea(s, outline->id), 1100.0, 0.2);
  EXPECT_NEAR(OccluderArea(s, tower->id), 100.0, 0.05);
}

TEST(OsmParts, BuildingDrawnOnlyAsPartsIsImported) {
  OsmImportSummary sum;
  const Scene s = Import({{5, Rect(0, 0, 20, 20), {{"building:part", "yes"}, {"height", "30"}}},
                          {6, Rect(40, 0, 50, 10), {{"building", "no"}, {"building:part", "yes"}, {"height", "12"}}}},
                         &sum);
  ASSERT_EQ(s.objects.size(), 2u);
  EXPECT_EQ(sum.parts, 2u);
  EXPECT_DOUBLE_EQ(ByName(s, "way/5")->bounds.max.z, 30.0);
  EXPECT_EQ(OccluderCount(s, ByName(s, "way/5")->id), 1u);
}

TEST(OsmParts, OutlineWhollyCoveredByItsPartsIsNotDrawn) {
  OsmImportSummary sum;
  const Scene s = Import({{1, Rect(0, 0, 20, 10), {{"building", "yes"}, {"height", "20"}}},
                          {2, Rect(0, 0, 10, 10), {{"building:part", "yes"}, {"height", "5"}}},
                          {3, Rect(10, 0, 20, 10), {{"building:part", "yes"}, {"height", "15"}}}},
                         &sum);
  ASSERT_EQ(s.objects.size(), 2u);
  EXPECT_EQ(ByName(s, "way/1"), nullptr);
  EXPECT_EQ(sum.outlines_hidden_by_parts, 1u);
  // No occluder stands for the 20 m outline: the low part occludes only up to 5 m.
  for (const Occluder25D& o : s.occluders) EXPECT_LE(o.height, 15.0);
}

TEST(OsmParts, RaisedPartHasNoOccluderAndLeavesAPassageInTheOutline) {
  // A bridge part from 5 to 10 m over a gap of the 8 m outline.
  OsmImportSummary sum;
  const Scene s = Import({{1, Rect(0, 0, 30, 10), {{"building", "yes"}, {"height", "8"}}},
                          {2, Rect(10, 0, 20, 10), {{"building:part", "yes"}, {"height", "10"}, {"min_height", "5"}}}},
                         &sum);
  ASSERT_EQ(s.objects.size(), 2u);
  const Object* bridge = ByName(s, "way/2");
  ASSERT_NE(bridge, nullptr);
  EXPECT_DOUBLE_EQ(bridge->bounds.min.z, 5.0);
  EXPECT_EQ(OccluderCount(s, bridge->id), 0u);
  EXPECT_EQ(sum.raised, 1u);
  // The outline stands on either side only: two pieces of 10 x 10 m.
  const Object* outline = ByName(s, "way/1");
  ASSERT_NE(outline, nullptr);
  EXPECT_NEAR(OccluderArea(s, outline->id), 200.0, 0.05);
  EXPECT_NEAR(RoofArea(outline->mesh, 8.0f), 200.0, 0.05);
}

TEST(OsmParts, WayAndRelationForTheSameBuildingGiveOneObject) {
  OsmImportSummary sum;
  const Scene s = Import({{1, Rect(0, 0, 20, 20), {{"building", "yes"}, {"height", "15"}}},
                          {2, Rect(5, 5, 10, 10), {}}},
                         &sum, {{7, {{1, "outer"}, {2, "inner"}}, {{"type", "multipolygon"}, {"building", "yes"}}}});
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].name, "relation/7");
  EXPECT_EQ(sum.merged_way_outlines, 1u);
  EXPECT_DOUBLE_EQ(s.objects[0].bounds.max.z, 15.0);  // the way's height, the relation has none
  EXPECT_NEAR(RoofArea(s.objects[0].mesh, 15.0f), 400.0 - 25.0, 0.05);
}

TEST(OsmParts, ImplausibleHeightDoesNotWreckTheCity) {
  OsmImportSummary sum;
  const Scene s = Import({{1, Rect(0, 0, 10, 10), {{"building", "yes"}, {"height", "99999999"}}},
                          {2, Rect(20, 0, 30, 10), {{"building", "yes"}, {"building:levels", "1000000"}}},
                          {3, Rect(40, 0, 50, 10), {{"building", "yes"}, {"height", "10"}, {"min_height", "20"}}}},
                         &sum);
  ASSERT_EQ(s.objects.size(), 3u);
  EXPECT_EQ(sum.implausible_heights, 2u);
  EXPECT_EQ(sum.min_height_above_height, 1u);
  EXPECT_LE(s.bounds.max.z, 13.0);  // the rule for "yes": 4 storeys and a roof
  EXPECT_EQ(OccluderCount(s, ByName(s, "way/3")->id), 0u);  // contradicting tags: no occluder
  EXPECT_DOUBLE_EQ(ByName(s, "way/3")->bounds.min.z, 0.0);
}

}  // namespace
}  // namespace vistream::scenes
