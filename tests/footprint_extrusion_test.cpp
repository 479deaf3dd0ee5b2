#include "scenes/footprint_extrusion.h"

#include <gtest/gtest.h>

#include "scenes/building.h"
#include "scenes/mesh.h"

namespace vistream::scenes {
namespace {

std::vector<glm::dvec2> Rect(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

double Volume(const Scene& s, ObjectId id) {
  double v = 0.0;
  for (const Occluder25D& o : s.occluders) {
    if (o.object == id) v += SignedArea(o.footprint) * o.height;
  }
  return v;
}

// An L-shaped building of two overlapping wings with a tower on one (a BuildingPart), a road
// and a terrain tile: the building becomes one prism of the L's footprint up to the tower's
// top, the part the prism of the tower's, the road stays, the terrain gives way to a flat
// ground over the same extent.
TEST(ExtrudeFootprints, EachBuildingBecomesItsFootprintsPrismUpToItsTop) {
  Scene s;
  s.name = "town";
  const ObjectId l = AddBuilding(&s, "L", {Prism{Rect(0, 0, 20, 8), 0.0, 10.0}, Prism{Rect(0, 0, 8, 20), 0.0, 12.0}});
  s.objects[l].type = "Building";
  const ObjectId tower = AddBuilding(&s, "tower", {Prism{Rect(2, 2, 6, 6), 12.0, 30.0}});
  s.objects[tower].type = "BuildingPart";
  Mesh road;
  AppendConvexPrism(Rect(30, 0, 40, 20), 0.0, 0.1, &road);
  const ObjectId r = s.AddObject("road", std::move(road));
  s.objects[r].type = "Road";
  Mesh tile;
  AppendConvexPrism(Rect(-10, -10, 50, 30), 0.0, 0.5, &tile);
  const ObjectId t = s.AddObject("terrain", std::move(tile));
  s.objects[t].type = "TINRelief";
  s.terrain = {t};

  ExtrusionSummary sum;
  absl::StatusOr<Scene> e = ExtrudeFootprints(s, &sum);
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_TRUE(ValidateScene(*e, "extruded").ok());
  EXPECT_EQ(e->name, "town-extruded");
  EXPECT_EQ(sum.buildings, 2u);
  EXPECT_EQ(sum.extruded, 2u);
  EXPECT_TRUE(sum.not_extruded.empty());
  EXPECT_EQ(sum.terrain_dropped, 1u);
  ASSERT_EQ(e->objects.size(), 4u);  // L, tower, road, flat ground
  EXPECT_TRUE(e->terrain.empty());
  for (ObjectId k = 0; k < e->objects.size(); ++k) EXPECT_EQ(e->objects[k].id, k);
  EXPECT_EQ(e->objects[0].type, "Building");
  EXPECT_EQ(e->objects[2].type, "Road");
  EXPECT_EQ(e->objects[3].type, "ground");
  // The L: 20 x 8 + 8 x 20 - 8 x 8 = 256 m², up to its highest vertex (12 m): the lower wing is
  // raised to it, as an OSM building of one height is.
  EXPECT_NEAR(sum.footprint_m2, 256.0 + 16.0, 1e-9);
  EXPECT_EQ(e->objects[0].bounds.min.z, 0.0);
  EXPECT_EQ(e->objects[0].bounds.max.z, 12.0);
  EXPECT_NEAR(Volume(*e, 0), 256.0 * 12.0, 1e-6);
  // The tower stands on the ground now, up to 30 m.
  EXPECT_EQ(e->objects[1].bounds.min.z, 0.0);
  EXPECT_EQ(e->objects[1].bounds.max.z, 30.0);
  EXPECT_NEAR(Volume(*e, 1), 16.0 * 30.0, 1e-6);
  EXPECT_EQ(Volume(*e, 2), 0.0) << "a road is not an occluder";
  // The flat ground spans the terrain's extent at z = 0: the same viewcell grid.
  EXPECT_EQ(e->bounds.min.x, -10.0);
  EXPECT_EQ(e->bounds.max.y, 30.0);
  EXPECT_EQ(e->objects[3].bounds.max.z, 0.0);
  // Walls, roof and floor: the L's outline keeps the wings' corners that lie on its edges,
  // (8, 0) and (0, 8), so 8 walls of 2 triangles and two caps of 6.
  EXPECT_EQ(e->objects[0].mesh.TriangleCount(), 8u * 2u + 2u * 6u);
}

// A courtyard block (four wings round a yard) keeps the yard as a hole: the occluders cover
// the wings only.
TEST(ExtrudeFootprints, ACourtyardStaysOpen) {
  Scene s;
  s.name = "block";
  const ObjectId b = AddBuilding(&s, "block", {Prism{Rect(0, 0, 30, 10), 0.0, 15.0}, Prism{Rect(0, 20, 30, 30), 0.0, 15.0},
                                               Prism{Rect(0, 10, 10, 20), 0.0, 15.0}, Prism{Rect(20, 10, 30, 20), 0.0, 15.0}});
  s.objects[b].type = "Building";
  ExtrusionSummary sum;
  absl::StatusOr<Scene> e = ExtrudeFootprints(s, &sum);
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_NEAR(sum.footprint_m2, 900.0 - 100.0, 1e-9);
  EXPECT_NEAR(Volume(*e, 0), 800.0 * 15.0, 1e-6);
  for (const Occluder25D& o : e->occluders) {
    for (const glm::dvec2& p : o.footprint) {
      EXPECT_FALSE(p.x > 10.0 && p.x < 20.0 && p.y > 10.0 && p.y < 20.0) << "an occluder corner in the yard";
    }
  }
}

TEST(ExtrudeFootprints, ASceneOfTerrainAloneIsAnError) {
  Scene s;
  s.name = "hill";
  Mesh tile;
  AppendConvexPrism(Rect(0, 0, 10, 10), 0.0, 1.0, &tile);
  s.terrain = {s.AddObject("terrain", std::move(tile))};
  absl::StatusOr<Scene> e = ExtrudeFootprints(s, nullptr);
  ASSERT_FALSE(e.ok());
  EXPECT_NE(e.status().message().find("hill"), std::string_view::npos) << e.status();
}

}  // namespace
}  // namespace vistream::scenes
