// Surface models closed by their neighbours and the ground (scenes/shell_closure.h) through the
// city import (scenes/city_import.h): each kind of model LoD2 data publishes, built in memory,
// and every prism checked inside the buildings' union and the ground by an independent
// point-in-solid test (tests/solid_oracle.h: parity of random rays, no code shared).
#include "scenes/shell_closure.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "scenes/city_import.h"
#include "scenes/mesh.h"
#include "tests/solid_oracle.h"

namespace vistream::scenes {
namespace {

using Ring3 = std::vector<glm::dvec3>;

// The faces of a box, outward, as polygons; `leave_out` names the faces the model omits:
// "floor", "roof", "south" (y0), "east" (x1), "north" (y1), "west" (x0).
std::vector<CitySurface> Box(double x0, double y0, double z0, double x1, double y1, double z1,
                             const std::vector<std::string>& leave_out = {}) {
  auto out = [&](const char* name) { return std::find(leave_out.begin(), leave_out.end(), name) != leave_out.end(); };
  std::vector<CitySurface> faces;
  if (!out("floor")) faces.push_back({{{x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, {x1, y0, z0}}, {}});
  if (!out("roof")) faces.push_back({{{x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}}, {}});
  if (!out("south")) faces.push_back({{{x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}}, {}});
  if (!out("east")) faces.push_back({{{x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}}, {}});
  if (!out("north")) faces.push_back({{{x1, y1, z0}, {x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}}, {}});
  if (!out("west")) faces.push_back({{{x0, y1, z0}, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}}, {}});
  return faces;
}

CityObject Building(const std::string& id, std::vector<CitySurface> surfaces, const std::string& type = "Building") {
  CityGeometry g;
  g.type = CityGeometryType::kMultiSurface;
  g.lod = "2";
  g.surfaces = std::move(surfaces);
  return {id, type, "", {g}};
}

struct Imported {
  Scene scene;
  CityImportSummary summary;
};

Imported Import(std::vector<CityObject> objects) {
  CityModel model;
  model.format = "test";
  model.objects = std::move(objects);
  CityImportOptions options;
  options.walks = 0;
  Imported out;
  absl::StatusOr<Scene> s = BuildCityScene(model, "closure", options, &out.summary);
  EXPECT_TRUE(s.ok()) << s.status();
  if (s.ok()) out.scene = std::move(*s);
  return out;
}

size_t OccludersOf(const Scene& scene, const std::string& name) {
  size_t n = 0;
  for (const Occluder25D& o : scene.occluders) n += scene.objects[o.object].name == name;
  return n;
}

// Every prism of the scene, at random points, inside the union of the buildings as drawn and
// a ground block under z = 0 (the solid ground): parity of random rays over all of them.
// `inner` (world coordinates, as the model's): faces parity needs where the union's boundary is
// not the drawn faces' sum: a second copy of a wall a neighbour's open side stands on, the
// floor of a floorless building (where it meets the ground block's top).
// `open` names buildings left out of the union (open to the air: their drawn surface bounds
// nothing, and each of their neighbours must be closed as drawn without them).
void ExpectPrismsInsideTheBuildingsAndGround(const Scene& scene, const std::vector<CitySurface>& inner = {},
                                             const std::vector<std::string>& open = {}) {
  constexpr int points_per_prism = 200;
  Mesh all;
  for (const Object& o : scene.objects) {
    if (o.type != "Building" && o.type != "BuildingPart") continue;
    if (std::find(open.begin(), open.end(), o.name) != open.end()) continue;
    const uint32_t base = static_cast<uint32_t>(all.positions.size());
    all.positions.insert(all.positions.end(), o.mesh.positions.begin(), o.mesh.positions.end());
    all.normals.insert(all.normals.end(), o.mesh.normals.begin(), o.mesh.normals.end());
    for (uint32_t i : o.mesh.indices) all.indices.push_back(base + i);
  }
  // The ground: a closed block from z = -20 to 0 reaching 100 m past every building.
  const Aabb b = scene.bounds;
  const double x0 = b.min.x - 100, y0 = b.min.y - 100, x1 = b.max.x + 100, y1 = b.max.y + 100;
  std::vector<CitySurface> extra = Box(x0, y0, -20.0, x1, y1, 0.0);
  for (CitySurface f : inner) {
    for (glm::dvec3& p : f.outer) p -= scene.origin;
    extra.push_back(f);
  }
  for (const CitySurface& f : extra) {
    const uint32_t base = static_cast<uint32_t>(all.positions.size());
    for (const glm::dvec3& p : f.outer) {
      all.positions.emplace_back(p);
      all.normals.emplace_back(0.0f, 0.0f, 1.0f);
    }
    for (uint32_t i : {0u, 1u, 2u, 0u, 2u, 3u}) all.indices.push_back(base + i);
  }
  const SolidMesh solid = SolidMeshFromMesh(all);
  Rng rng(46);
  ASSERT_FALSE(scene.occluders.empty());
  for (size_t k = 0; k < scene.occluders.size(); ++k) {
    const Occluder25D& o = scene.occluders[k];
    for (int i = 0; i < points_per_prism; ++i) {
      const glm::dvec2 xy = testing::PointIn(o.footprint, &rng);
      const glm::dvec3 p(xy, rng.Uniform(0.001, o.height));
      ASSERT_TRUE(testing::InsideSolid(solid, p, &rng))
          << "prism " << k << " of " << scene.objects[o.object].name << " at " << p.x << "," << p.y << "," << p.z;
    }
  }
}

TEST(ShellClosure, TerracedHousesWithoutPartyWallsOccludeEachClosedByItsNeighbours) {
  // Three houses in a row; neither side of a shared wall is in the data.
  Imported r = Import({Building("a", Box(0, 0, 0, 6, 10, 9, {"east"})),
                       Building("b", Box(6, 0, 0, 12, 10, 11, {"west", "east"})),
                       Building("c", Box(12, 0, 0, 18, 10, 9, {"west"}))});
  // b is taller, and its walls above a's and c's roofs are missing too: open to the air there,
  // and a and c with it (their roofs' edges along b meet no wall).
  EXPECT_EQ(r.summary.buildings_with_occluder, 0u);
  EXPECT_EQ(r.summary.without_occluder["open to the air"], 3u);

  Imported same = Import({Building("a", Box(0, 0, 0, 6, 10, 9, {"east"})),
                          Building("b", Box(6, 0, 0, 12, 10, 9, {"west", "east"})),
                          Building("c", Box(12, 0, 0, 18, 10, 9, {"west"}))});
  EXPECT_EQ(same.summary.buildings_with_occluder, 3u);
  EXPECT_EQ(same.summary.repaired["shells closed by neighbours and ground"], 3u);
  for (const char* name : {"a", "b", "c"}) EXPECT_GT(OccludersOf(same.scene, name), 0u) << name;
  ExpectPrismsInsideTheBuildingsAndGround(same.scene);
}

TEST(ShellClosure, ATallerHouseWithItsWallAboveTheLowerRoofClosesAtATJunction) {
  // b's west wall is there only above a's roof, in one polygon; a's roof is two polygons, so
  // a's opening has a corner half-way along the edge b's wall meets it (a T-junction).
  std::vector<CitySurface> a = Box(0, 0, 0, 6, 10, 9, {"east", "roof"});
  a.push_back({{{0, 0, 9}, {6, 0, 9}, {6, 5, 9}, {0, 5, 9}}, {}});
  a.push_back({{{0, 5, 9}, {6, 5, 9}, {6, 10, 9}, {0, 10, 9}}, {}});
  std::vector<CitySurface> b = Box(6, 0, 0, 12, 10, 12, {"west"});
  b.push_back({{{6, 10, 9}, {6, 0, 9}, {6, 0, 12}, {6, 10, 12}}, {}});
  Imported r = Import({Building("a", a), Building("b", b)});
  EXPECT_EQ(r.summary.buildings_with_occluder, 2u) << r.summary.without_occluder.size();
  ExpectPrismsInsideTheBuildingsAndGround(r.scene);
}

TEST(ShellClosure, ABuildingWithoutAFloorIsClosedByTheGround) {
  Imported r = Import({Building("a", Box(0, 0, 0, 8, 6, 7, {"floor"})),
                       Building("b", Box(8, 0, 0, 14, 6, 7, {"floor", "west"})),
                       Building("c", Box(0, 20, 0, 8, 26, 7, {"floor", "east"})),
                       Building("d", Box(8, 20, 0, 14, 26, 7, {"floor", "west"}))});
  // a has its east wall (b's is missing): b's opening lies on a's face. c and d: no floor and no
  // party wall, one opening each reaching from the party wall down to the ground all round.
  EXPECT_EQ(r.summary.buildings_with_occluder, 4u);
  // The oracle's union: b's west wall stands on a's east wall (twice there: parity cancels it),
  // and each building meets the ground in its footprint (the floors the data leaves out).
  std::vector<CitySurface> inner{{{{8, 0, 0}, {8, 6, 0}, {8, 6, 7}, {8, 0, 7}}, {}}};
  for (const auto& [x0, y0, x1, y1] : std::vector<std::array<double, 4>>{{0, 0, 8, 6}, {8, 0, 14, 6}, {0, 20, 8, 26},
                                                                       {8, 20, 14, 26}}) {
    inner.push_back({{{x0, y0, 0}, {x0, y1, 0}, {x1, y1, 0}, {x1, y0, 0}}, {}});
  }
  ExpectPrismsInsideTheBuildingsAndGround(r.scene, inner);
}

TEST(ShellClosure, APartStandingOnAPartClosesTheLowerOne) {
  // The lower part's roof has a hole where the upper part stands; the upper part has no floor.
  std::vector<CitySurface> lower = Box(0, 0, 0, 10, 10, 6, {"roof"});
  lower.push_back({{{0, 0, 6}, {10, 0, 6}, {10, 10, 6}, {0, 10, 6}}, {{{2, 2, 6}, {2, 8, 6}, {8, 8, 6}, {8, 2, 6}}}});
  Imported r = Import({Building("lower", lower, "BuildingPart"),
                       Building("upper", Box(2, 2, 6, 8, 8, 12, {"floor"}), "BuildingPart")});
  EXPECT_GT(OccludersOf(r.scene, "lower"), 0u);
  // The upper part, closed on the lower one, stands above the ground: no prism of its own.
  EXPECT_EQ(OccludersOf(r.scene, "upper"), 0u);
  EXPECT_EQ(r.summary.without_occluder["raised above the ground once closed by neighbours and ground"], 1u);
  ExpectPrismsInsideTheBuildingsAndGround(r.scene);
}

TEST(ShellClosure, AShellWithAMissingStreetWallGetsNoOccluder) {
  Imported r = Import({Building("open", Box(0, 0, 0, 8, 6, 7, {"south"})), Building("shut", Box(20, 0, 0, 28, 6, 7))});
  EXPECT_EQ(OccludersOf(r.scene, "open"), 0u);
  EXPECT_GT(OccludersOf(r.scene, "shut"), 0u);
  EXPECT_EQ(r.summary.without_occluder["open to the air"], 1u);
  // The same with the missing wall shared by no neighbour at the end of a row.
  Imported row = Import({Building("a", Box(0, 0, 0, 6, 10, 9, {"east"})),
                         Building("b", Box(6, 0, 0, 12, 10, 9, {"west", "east"}))});
  EXPECT_EQ(OccludersOf(row.scene, "b"), 0u);
  EXPECT_EQ(row.summary.without_occluder["open to the air"], 1u);
}

TEST(ShellClosure, RingsWithoutAreaAreDroppedAndOpenNothing) {
  std::vector<CitySurface> faces = Box(0, 0, 0, 8, 6, 7);
  faces.push_back({{{8, 0, 0}, {8, 0, 0}, {8, 0, 7}, {8, 0, 7}}, {}});  // [a, a, b, b]
  faces.push_back({{{0, 0, 0}, {4, 0, 0}, {8, 0, 0}}, {}});            // on a line
  Imported r = Import({Building("a", faces)});
  EXPECT_EQ(r.summary.repaired["rings without area dropped"], 2u);
  EXPECT_EQ(r.summary.buildings_with_occluder, 1u);
  EXPECT_TRUE(r.summary.skipped.empty());
  ExpectPrismsInsideTheBuildingsAndGround(r.scene);
}

TEST(ShellClosure, AMillimetreGapIsWeldedAndFiveAreNot) {
  for (double gap : {0.001, 0.005}) {
    Imported r = Import({Building("a", Box(0, 0, 0, 6, 10, 9, {"east"})),
                         Building("b", Box(6 + gap, 0, 0, 12, 10, 9, {"west"}))});
    if (gap < 0.002) {
      EXPECT_EQ(r.summary.buildings_with_occluder, 2u) << gap;
      // Drawn welded: the two meshes meet exactly, and the prisms lie inside them.
      ExpectPrismsInsideTheBuildingsAndGround(r.scene);
    } else {
      EXPECT_EQ(r.summary.buildings_with_occluder, 0u) << gap;
      EXPECT_EQ(r.summary.without_occluder["open to the air"], 2u) << gap;
    }
  }
}

TEST(ShellClosure, AClosedShellIsLeftAsItIs) {
  std::vector<ShellToClose> shells(1);
  std::vector<std::array<glm::dvec3, 3>> tris;
  for (const CitySurface& f : Box(0, 0, 0, 1, 1, 1)) {
    tris.push_back({f.outer[0], f.outer[1], f.outer[2]});
    tris.push_back({f.outer[0], f.outer[2], f.outer[3]});
  }
  shells[0].triangles = &tris;
  std::vector<ShellClosure> c = CloseShellsByNeighbours(shells);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].outcome, ShellClosureOutcome::kNotOpen);
  EXPECT_TRUE(c[0].drawn.empty());
  // Given as open (the import only gives those the synthesis found open): closed by the weld
  // alone, nothing capped, nothing moved.
  shells[0].open = true;
  c = CloseShellsByNeighbours(shells);
  EXPECT_EQ(c[0].outcome, ShellClosureOutcome::kClosed);
  EXPECT_EQ(c[0].caps, 0u);
  EXPECT_EQ(c[0].moved_m, 0.0);
  EXPECT_EQ(c[0].drawn.size(), tris.size());
}

TEST(ShellClosure, ShrunkOccludersLieTheDistanceInsideAndLower) {
  const std::vector<Occluder25D> in{{{{0, 0}, {10, 0}, {10, 4}, {0, 4}}, 6.0, 3}};
  const std::vector<Occluder25D> out = ShrinkOccluders(in, 0.01, 1.0, 0.0);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].object, 3u);
  EXPECT_DOUBLE_EQ(out[0].height, 5.99);
  for (const glm::dvec2& p : out[0].footprint) {
    EXPECT_GE(p.x, 0.01 - 1e-12);
    EXPECT_LE(p.x, 9.99 + 1e-12);
    EXPECT_GE(p.y, 0.01 - 1e-12);
    EXPECT_LE(p.y, 3.99 + 1e-12);
  }
  EXPECT_TRUE(ShrinkOccluders(in, 2.5, 1.0, 0.0).empty()) << "4 m wide, shrunk by 2.5 m on each side";
}

// Two houses whose shared opening is bent out of any plane and off the vertical (as between
// some of Rotterdam's): its ground edge is straight along x = 5, its roof edge goes out to
// (6, 4); neither house has a wall there. East of x = 10 the second house has its wall, or not.
std::vector<CityObject> BentPartyWallPair(bool east_wall) {
  std::vector<CitySurface> a = {
      {{{0, 0, 0}, {0, 8, 0}, {5, 8, 0}, {5, 0, 0}}, {}},                 // floor
      {{{0, 0, 6}, {5, 0, 6}, {6, 4, 6}, {5, 8, 6}, {0, 8, 6}}, {}},      // roof, out to the bend
      {{{0, 0, 0}, {5, 0, 0}, {5, 0, 6}, {0, 0, 6}}, {}},                 // south
      {{{5, 8, 0}, {0, 8, 0}, {0, 8, 6}, {5, 8, 6}}, {}},                 // north
      {{{0, 8, 0}, {0, 0, 0}, {0, 0, 6}, {0, 8, 6}}, {}},                 // west
  };
  std::vector<CitySurface> b = {
      {{{5, 0, 0}, {5, 8, 0}, {10, 8, 0}, {10, 0, 0}}, {}},               // floor
      {{{5, 0, 6}, {10, 0, 6}, {10, 8, 6}, {5, 8, 6}, {6, 4, 6}}, {}},    // roof, in from the bend
      {{{5, 0, 0}, {10, 0, 0}, {10, 0, 6}, {5, 0, 6}}, {}},               // south
      {{{10, 8, 0}, {5, 8, 0}, {5, 8, 6}, {10, 8, 6}}, {}},               // north
  };
  if (east_wall) b.push_back({{{10, 0, 0}, {10, 8, 0}, {10, 8, 6}, {10, 0, 6}}, {}});
  return {Building("a", a), Building("b", b)};
}

TEST(ShellClosure, HousesWhosePartyOpeningBendsOutOfAnyPlaneAreClosedTogether) {
  Imported r = Import(BentPartyWallPair(true));
  EXPECT_EQ(r.summary.buildings_with_occluder, 2u);
  EXPECT_EQ(r.summary.repaired["shells closed together with a neighbour (a bent party wall)"], 2u);
  EXPECT_TRUE(r.summary.without_occluder.empty());
  for (const char* name : {"a", "b"}) EXPECT_GT(OccludersOf(r.scene, name), 0u) << name;
  // Each house holds the block's prisms within its own box only (the occluder set clips an
  // occluder to its object's box).
  for (const Occluder25D& o : r.scene.occluders) {
    const Aabb& box = r.scene.objects[o.object].bounds;
    for (const glm::dvec2& p : o.footprint) {
      EXPECT_GE(p.x, box.min.x - 1e-4);
      EXPECT_LE(p.x, box.max.x + 1e-4);
      EXPECT_GE(p.y, box.min.y - 1e-4);
      EXPECT_LE(p.y, box.max.y + 1e-4);
    }
  }
  ExpectPrismsInsideTheBuildingsAndGround(r.scene);
}

TEST(ShellClosure, ABentPartyOpeningIsNotClosedWhenTheNeighbourIsOpenToTheAir) {
  Imported r = Import(BentPartyWallPair(false));
  EXPECT_EQ(r.summary.buildings_with_occluder, 0u);
  EXPECT_TRUE(r.scene.occluders.empty());
  EXPECT_EQ(r.summary.without_occluder["open to the air"], 1u);
  EXPECT_EQ(r.summary.without_occluder["open: opening not planar"], 1u);
}

TEST(ShellClosure, ClippedOccludersKeepTheirPartWithinTheBox) {
  const std::vector<Occluder25D> in = {{{{0, 0}, {10, 0}, {10, 4}, {0, 4}}, 6.0, 3},   // half in
                                       {{{1, 1}, {2, 1}, {2, 2}, {1, 2}}, 5.0, 4},     // within
                                       {{{20, 0}, {30, 0}, {30, 4}, {20, 4}}, 6.0, 5},  // outside
                                       {{{0, 0}, {8, 4}, {8, 0}, {0, 4}}, 6.0, 6}};     // crosses itself, half in
  const std::vector<Occluder25D> out = ClipOccluders(in, {-1.0, -1.0}, {5.0, 5.0}, 1.0);
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].object, 3u);
  EXPECT_DOUBLE_EQ(out[0].height, 6.0);
  EXPECT_DOUBLE_EQ(SignedArea(out[0].footprint), 20.0);
  for (const glm::dvec2& p : out[0].footprint) EXPECT_LE(p.x, 5.0);
  EXPECT_EQ(out[1].object, 4u);
  EXPECT_EQ(out[1].footprint, in[1].footprint);
  EXPECT_TRUE(ClipOccluders(in, {-1.0, -1.0}, {1.5, 5.0}, 1.0).size() == 1u) << "the 1.5 m strip of the first only";
}

TEST(ShellClosure, AHouseWhoseNeighbourIsOpenToTheAirDrawsThePartyWallTheyShare) {
  // A row of three without party walls whose end house also lacks its end wall (its neighbour
  // is not in the data): the air reaches b's inside through c, so b draws the wall it shares
  // with c (facing c) and is closed as drawn; a is closed by b.
  Imported r = Import({Building("a", Box(0, 0, 0, 6, 10, 9, {"east"})),
                       Building("b", Box(6, 0, 0, 12, 10, 9, {"west", "east"})),
                       Building("c", Box(12, 0, 0, 18, 10, 9, {"west", "east"}))});
  EXPECT_EQ(r.summary.buildings_with_occluder, 2u);
  EXPECT_EQ(r.summary.without_occluder["open to the air"], 1u);
  EXPECT_EQ(r.summary.repaired["party walls drawn towards a neighbour left open"], 1u);
  EXPECT_EQ(OccludersOf(r.scene, "c"), 0u);
  const Object* b = nullptr;
  for (const Object& o : r.scene.objects) b = o.name == "b" ? &o : b;
  ASSERT_NE(b, nullptr);
  // b's data: floor, roof, south and north walls (8 triangles), and the party wall with c (2),
  // facing c (+x).
  ASSERT_EQ(b->mesh.TriangleCount(), 10u);
  int facing_c = 0;
  for (size_t k = 0; k < b->mesh.indices.size(); k += 3) {
    const glm::dvec3 p0(b->mesh.positions[b->mesh.indices[k]]), p1(b->mesh.positions[b->mesh.indices[k + 1]]),
        p2(b->mesh.positions[b->mesh.indices[k + 2]]);
    const glm::dvec3 n = glm::cross(p1 - p0, p2 - p0);
    const double x = p0.x + r.scene.origin.x;
    if (std::abs(x - 12.0) < 1e-6 && std::abs(p1.x - p0.x) < 1e-6 && std::abs(p2.x - p0.x) < 1e-6) {
      facing_c += n.x > 0.0 ? 1 : -1;
    }
  }
  EXPECT_EQ(facing_c, 2) << "the party wall's two triangles face c";
  // Without c, a and b (with the wall it draws) are closed as drawn: every prism lies inside.
  ExpectPrismsInsideTheBuildingsAndGround(r.scene, {}, {"c"});
}

TEST(ShellClosure, AHouseWhoseNeighbourIsLeftOpenForWantOfACapDrawsThePartyWallToo) {
  // c, then the bent pair with b open to the air: a cannot be capped (its bent opening) nor
  // closed with b, so it stays open; the air reaches a's inside through b, and c's through a
  // unless c draws the wall it shares with a.
  std::vector<CityObject> objects = BentPartyWallPair(false);
  std::vector<CitySurface>& a = objects[0].geometries[0].surfaces;
  a.pop_back();  // a's west wall: c's opening
  objects.push_back(Building("c", Box(-6, 0, 0, 0, 8, 6, {"east"})));
  Imported r = Import(objects);
  EXPECT_EQ(r.summary.without_occluder["open to the air"], 1u) << "b";
  EXPECT_EQ(r.summary.without_occluder["open: opening not planar"], 1u) << "a";
  EXPECT_EQ(r.summary.buildings_with_occluder, 1u) << "c";
  EXPECT_EQ(r.summary.repaired["party walls drawn towards a neighbour left open"], 1u);
  ExpectPrismsInsideTheBuildingsAndGround(r.scene, {}, {"a", "b"});
}

// The terraces file (tests/citymodel/terraces.city.json, make_terraces_cityjson.py): each kind
// at once, from CityJSON, as the CLI and the walk tests read it.
TEST(ShellClosure, TheTerracesFileOccludesWhereItsMatterIsClosedAndNotAtTheOpenEnd) {
  CityImportOptions options;
  options.walks = 0;
  CityImportSummary sum;
  absl::StatusOr<Scene> scene = ImportCity(VISTREAM_SOURCE_DIR "/tests/citymodel/terraces.city.json", options, &sum);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_EQ(sum.buildings_drawn, 9u);
  EXPECT_EQ(sum.buildings_with_occluder, 8u);
  EXPECT_EQ(sum.without_occluder, (std::map<std::string, uint64_t>{{"open to the air", 1}}));
  EXPECT_EQ(OccludersOf(*scene, "r4"), 0u);
  for (const char* name : {"r1", "r2", "r3", "b1", "b2", "f", "h", "w"}) {
    EXPECT_GT(OccludersOf(*scene, name), 0u) << name;
  }
  EXPECT_EQ(sum.repaired["shells closed by neighbours and ground"], 6u) << "r1, r2, r3, b1, b2, f";
  EXPECT_EQ(sum.repaired["shells closed together with a neighbour (a bent party wall)"], 2u);
  EXPECT_EQ(sum.repaired["party walls drawn towards a neighbour left open"], 1u) << "r3's, with r4";
  EXPECT_EQ(sum.terrain_from, "derived");
  // f has no floor: the ground closes it, and the union's boundary there is the ground block's
  // top (parity needs that face, as in ABuildingWithoutAFloorIsClosedByTheGround).
  const glm::dvec3 o(85000.0, 446000.0, 0.0);
  const CitySurface f_floor{{o + glm::dvec3(60, 0, 0), o + glm::dvec3(60, 8, 0), o + glm::dvec3(68, 8, 0),
                             o + glm::dvec3(68, 0, 0)},
                            {}};
  ExpectPrismsInsideTheBuildingsAndGround(*scene, {f_floor}, {"r4"});
}

}  // namespace
}  // namespace vistream::scenes
