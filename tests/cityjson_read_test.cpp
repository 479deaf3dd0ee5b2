#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "scenes/city_model.h"
#include "scenes/progress.h"

namespace vistream::scenes {
namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

std::string Shapes(const std::string& name) {
  return std::string(VISTREAM_SOURCE_DIR "/tests/citymodel/") + name;
}
std::string RealData(const std::string& name) {
  return std::string(VISTREAM_SOURCE_DIR "/../shared/data/citymodels/") + name;
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

CityModel Read(const std::string& path, const CityReadOptions& options = {}) {
  absl::StatusOr<CityModel> m = ReadCityJson(path, options);
  EXPECT_TRUE(m.ok()) << m.status();
  return m.ok() ? *std::move(m) : CityModel{};
}

const CityObject& Get(const CityModel& m, const std::string& id) {
  for (const CityObject& o : m.objects) {
    if (o.id == id) return o;
  }
  ADD_FAILURE() << "no object " << id;
  static const CityObject kNone;
  return kNone;
}

// The shapes' coordinates are given relative to (85000, 446000) (tests/citymodel/README.md).
glm::dvec3 P(double x, double y, double z) { return {85000.0 + x, 446000.0 + y, z}; }

void ExpectPoint(const glm::dvec3& got, const glm::dvec3& want, const std::string& what = "") {
  EXPECT_NEAR(got.x, want.x, 1e-9) << what;
  EXPECT_NEAR(got.y, want.y, 1e-9) << what;
  EXPECT_NEAR(got.z, want.z, 1e-9) << what;
}

void ExpectRing(const std::vector<glm::dvec3>& got, const std::vector<glm::dvec3>& want,
                const std::string& what) {
  ASSERT_EQ(got.size(), want.size()) << what;
  for (size_t i = 0; i < got.size(); ++i)
    ExpectPoint(got[i], want[i], what + " point " + std::to_string(i));
}

std::vector<size_t> OuterSizes(const std::vector<CitySurface>& surfaces) {
  std::vector<size_t> n;
  for (const CitySurface& s : surfaces) n.push_back(s.outer.size());
  return n;
}

std::vector<size_t> HoleCounts(const std::vector<CitySurface>& surfaces) {
  std::vector<size_t> n;
  for (const CitySurface& s : surfaces) n.push_back(s.holes.size());
  return n;
}

// The one exterior shell of an object's one Solid.
const std::vector<CitySurface>& Shell(const CityObject& o) {
  static const std::vector<CitySurface> kNone;
  if (o.geometries.size() != 1 || o.geometries[0].solids.size() != 1 ||
      o.geometries[0].solids[0].shells.size() != 1) {
    ADD_FAILURE() << o.id << ": not one solid of one shell";
    return kNone;
  }
  return o.geometries[0].solids[0].shells[0];
}

// Every point of a model, in order, with the structure around it: equal for equal models.
void ExpectSameModel(const CityModel& a, const CityModel& b) {
  EXPECT_EQ(a.crs, b.crs);
  ASSERT_EQ(a.objects.size(), b.objects.size());
  for (size_t i = 0; i < a.objects.size(); ++i) {
    const CityObject& x = a.objects[i];
    const CityObject& y = b.objects[i];
    EXPECT_EQ(x.id, y.id);
    EXPECT_EQ(x.type, y.type) << x.id;
    EXPECT_EQ(x.parent, y.parent) << x.id;
    ASSERT_EQ(x.geometries.size(), y.geometries.size()) << x.id;
    for (size_t g = 0; g < x.geometries.size(); ++g) {
      const CityGeometry& gx = x.geometries[g];
      const CityGeometry& gy = y.geometries[g];
      EXPECT_EQ(gx.type, gy.type) << x.id;
      EXPECT_EQ(gx.lod, gy.lod) << x.id;
      auto surfaces = [](const CityGeometry& geometry) {
        std::vector<const CitySurface*> out;
        for (const CitySurface& s : geometry.surfaces) out.push_back(&s);
        for (const CitySolid& solid : geometry.solids) {
          for (const auto& shell : solid.shells) {
            for (const CitySurface& s : shell) out.push_back(&s);
          }
        }
        return out;
      };
      const auto sx = surfaces(gx);
      const auto sy = surfaces(gy);
      ASSERT_EQ(sx.size(), sy.size()) << x.id;
      for (size_t s = 0; s < sx.size(); ++s) {
        ExpectRing(sx[s]->outer, sy[s]->outer, x.id + " surface " + std::to_string(s));
        ASSERT_EQ(sx[s]->holes.size(), sy[s]->holes.size()) << x.id;
        for (size_t h = 0; h < sx[s]->holes.size(); ++h) {
          ExpectRing(sx[s]->holes[h], sy[s]->holes[h], x.id + " hole");
        }
      }
    }
  }
}

// ---- the hand-made shapes (tests/citymodel/README.md) ----

TEST(CityJson, ShapesKeepTheirIdsTypesAndParentsInFileOrder) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  EXPECT_EQ(m.format, "CityJSON 2.0");
  EXPECT_EQ(m.crs, "EPSG:28992");
  std::vector<std::string> ids;
  for (const CityObject& o : m.objects) ids.push_back(o.id);
  EXPECT_EQ(ids, (std::vector<std::string>{"gabled", "tower", "stacked", "stacked-base",
                                           "stacked-top", "overhang", "open", "courtyard", "slope",
                                           "terrain", "lamp", "lamp2", "garden", "bridge"}));
  const std::map<std::string, std::string> types = {{"gabled", "Building"},
                                                    {"tower", "Building"},
                                                    {"stacked", "Building"},
                                                    {"stacked-base", "BuildingPart"},
                                                    {"stacked-top", "BuildingPart"},
                                                    {"overhang", "Building"},
                                                    {"open", "Building"},
                                                    {"courtyard", "Building"},
                                                    {"slope", "Building"},
                                                    {"terrain", "TINRelief"},
                                                    {"lamp", "CityFurniture"},
                                                    {"lamp2", "CityFurniture"},
                                                    {"garden", "LandUse"},
                                                    {"bridge", "Bridge"}};
  for (const CityObject& o : m.objects) {
    EXPECT_EQ(o.type, types.at(o.id)) << o.id;
    EXPECT_EQ(o.parent, o.id.starts_with("stacked-") ? "stacked" : "") << o.id;
    EXPECT_EQ(o.geometries.size(), o.id == "stacked" ? 0u : 1u) << o.id;
  }
  EXPECT_TRUE(m.skipped.empty());
  EXPECT_TRUE(m.repaired.empty());
}

TEST(CityJson, GabledRoofIsOneSolidOfSevenFacesInTheSharedOrder) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  const CityObject& o = Get(m, "gabled");
  ASSERT_EQ(o.geometries.size(), 1u);
  EXPECT_EQ(o.geometries[0].type, CityGeometryType::kSolid);
  EXPECT_EQ(o.geometries[0].lod, "2");
  EXPECT_TRUE(o.geometries[0].surfaces.empty());
  const auto& shell = Shell(o);
  EXPECT_EQ(OuterSizes(shell), (std::vector<size_t>{4, 4, 5, 4, 5, 4, 4}));
  EXPECT_EQ(HoleCounts(shell), (std::vector<size_t>(7, 0)));
  ExpectRing(shell[0].outer, {P(0, 0, 0), P(0, 8, 0), P(10, 8, 0), P(10, 0, 0)}, "floor");
  ExpectRing(shell[2].outer, {P(10, 0, 0), P(10, 8, 0), P(10, 8, 6), P(10, 4, 9), P(10, 0, 6)},
             "east gable");
  ExpectRing(shell[5].outer, {P(0, 0, 6), P(10, 0, 6), P(10, 4, 9), P(0, 4, 9)}, "south roof");
}

TEST(CityJson, TowerStandsInThePodiumRoofsHole) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  const auto& shell = Shell(Get(m, "tower"));
  EXPECT_EQ(OuterSizes(shell), (std::vector<size_t>(11, 4)));
  EXPECT_EQ(HoleCounts(shell), (std::vector<size_t>{0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0}));
  ASSERT_EQ(shell.size(), 11u);
  ExpectRing(shell[9].outer, {P(20, 0, 5), P(40, 0, 5), P(40, 20, 5), P(20, 20, 5)}, "podium roof");
  ExpectRing(shell[9].holes[0], {P(26, 6, 5), P(26, 14, 5), P(34, 14, 5), P(34, 6, 5)},
             "podium roof's hole");
  ExpectRing(shell[10].outer, {P(26, 6, 30), P(34, 6, 30), P(34, 14, 30), P(26, 14, 30)},
             "tower roof");
}

TEST(CityJson, StackedPartsCarryTheGeometryAndTheBuildingNone) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  EXPECT_TRUE(Get(m, "stacked").geometries.empty());
  const auto& base = Shell(Get(m, "stacked-base"));
  const auto& top = Shell(Get(m, "stacked-top"));
  EXPECT_EQ(OuterSizes(base), (std::vector<size_t>(6, 4)));
  EXPECT_EQ(OuterSizes(top), (std::vector<size_t>(6, 4)));
  ASSERT_EQ(top.size(), 6u);
  ExpectRing(top[0].outer, {P(50, 0, 4), P(50, 10, 4), P(60, 10, 4), P(60, 0, 4)}, "top's floor");
  ExpectRing(top[5].outer, {P(50, 0, 8), P(60, 0, 8), P(60, 10, 8), P(50, 10, 8)}, "top's roof");
}

TEST(CityJson, OverhangOpenCourtyardSlopeGardenAndBridge) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  EXPECT_EQ(OuterSizes(Shell(Get(m, "overhang"))), (std::vector<size_t>{4, 4, 4, 6, 4, 4, 6, 4}));
  ExpectRing(Shell(Get(m, "overhang"))[1].outer,
             {P(70, 6, 3), P(70, 10, 3), P(80, 10, 3), P(80, 6, 3)}, "overhang's underside");
  EXPECT_EQ(OuterSizes(Shell(Get(m, "open"))), (std::vector<size_t>(5, 4)));

  const CityObject& courtyard = Get(m, "courtyard");
  ASSERT_EQ(courtyard.geometries.size(), 1u);
  EXPECT_EQ(courtyard.geometries[0].lod, "1");
  const auto& c = Shell(courtyard);
  EXPECT_EQ(OuterSizes(c), (std::vector<size_t>(10, 4)));
  EXPECT_EQ(HoleCounts(c), (std::vector<size_t>{1, 0, 0, 0, 0, 0, 0, 0, 0, 1}));
  ASSERT_EQ(c.size(), 10u);
  ExpectRing(c[0].holes[0], {P(106, 6, 0), P(114, 6, 0), P(114, 14, 0), P(106, 14, 0)},
             "courtyard in the floor");
  // The courtyard's south wall faces north, into the courtyard.
  ExpectRing(c[5].outer, {P(106, 6, 0), P(106, 6, 10), P(114, 6, 10), P(114, 6, 0)},
             "courtyard's south wall");

  ExpectRing(Shell(Get(m, "slope"))[0].outer,
             {P(140, 0, 1), P(140, 10, 1), P(150, 10, 1), P(150, 0, 1)}, "slope's floor");

  const CityObject& garden = Get(m, "garden");
  ASSERT_EQ(garden.geometries.size(), 1u);
  EXPECT_EQ(garden.geometries[0].type, CityGeometryType::kMultiSurface);
  EXPECT_EQ(garden.geometries[0].lod, "1");
  EXPECT_TRUE(garden.geometries[0].solids.empty());
  ASSERT_EQ(garden.geometries[0].surfaces.size(), 1u);
  ExpectRing(garden.geometries[0].surfaces[0].outer,
             {P(0, 30, 0), P(10, 30, 0), P(10, 40, 0), P(0, 40, 0)}, "garden");

  const CityObject& bridge = Get(m, "bridge");
  ASSERT_EQ(bridge.geometries.size(), 1u);
  EXPECT_EQ(bridge.geometries[0].type, CityGeometryType::kSolid);
  EXPECT_EQ(bridge.geometries[0].lod, "1");
  ExpectRing(Shell(bridge)[0].outer, {P(0, 50, 3), P(0, 54, 3), P(20, 54, 3), P(20, 50, 3)},
             "deck's underside");
}

TEST(CityJson, TinReliefsCompositeSurfaceIsATin) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  const CityObject& t = Get(m, "terrain");
  ASSERT_EQ(t.geometries.size(), 1u);
  EXPECT_EQ(t.geometries[0].type, CityGeometryType::kTin);
  EXPECT_EQ(t.geometries[0].lod, "2");
  EXPECT_EQ(OuterSizes(t.geometries[0].surfaces), (std::vector<size_t>(18, 3)));
  ExpectRing(t.geometries[0].surfaces[0].outer,
             {P(130, -10, 0), P(140, -10, 5.0 / 3), P(140, 0, 5.0 / 3)}, "triangle 0");
  ExpectRing(t.geometries[0].surfaces[17].outer,
             {P(150, 10, 10.0 / 3), P(160, 20, 5), P(150, 20, 10.0 / 3)}, "triangle 17");
}

TEST(CityJson, TemplateInstancesArePlacedAtTheirReferencePoints) {
  const CityModel m = Read(Shapes("shapes.city.json"));
  for (const auto& [id, y] : {std::pair<std::string, double>{"lamp", 0.0}, {"lamp2", 10.0}}) {
    const CityObject& o = Get(m, id);
    ASSERT_EQ(o.geometries.size(), 1u) << id;
    const CityGeometry& g = o.geometries[0];
    EXPECT_EQ(g.type, CityGeometryType::kMultiSurface) << id;
    EXPECT_EQ(g.lod, "1") << id;
    EXPECT_EQ(OuterSizes(g.surfaces), (std::vector<size_t>(6, 4))) << id;
    ASSERT_EQ(g.surfaces.size(), 6u);
    ExpectRing(
        g.surfaces[0].outer,
        {P(124.9, y - 0.1, 0), P(124.9, y + 0.1, 0), P(125.1, y + 0.1, 0), P(125.1, y - 0.1, 0)},
        id + " base");
    ExpectRing(
        g.surfaces[5].outer,
        {P(124.9, y - 0.1, 4), P(125.1, y - 0.1, 4), P(125.1, y + 0.1, 4), P(124.9, y + 0.1, 4)},
        id + " top");
  }
}

TEST(CityJson, Versions10And11GiveTheSameModelAs20) {
  const CityModel v20 = Read(Shapes("shapes.city.json"));
  const CityModel v11 = Read(Shapes("shapes_v1_1.city.json"));
  const CityModel v10 = Read(Shapes("shapes_v1_0.city.json"));  // plain float vertices, numeric lod
  EXPECT_EQ(v11.format, "CityJSON 1.1");
  EXPECT_EQ(v10.format, "CityJSON 1.0");
  EXPECT_EQ(v10.crs, "EPSG:28992");  // urn:ogc:def:crs:EPSG::28992
  ASSERT_EQ(v20.objects.size(), 14u);
  ExpectSameModel(v20, v11);
  ExpectSameModel(v20, v10);
}

// ---- in-memory documents: one building "b12", a unit cube on 8 vertices ----

Json Cube(const std::string& version = "2.0") {
  Json doc = {{"type", "CityJSON"}, {"version", version}};
  doc["transform"] = {{"scale", {0.001, 0.001, 0.001}}, {"translate", {85000.0, 446000.0, 0.0}}};
  doc["vertices"] = Json::array();
  for (int z : {0, 1}) {
    for (auto [x, y] : {std::pair{0, 0}, {1, 0}, {1, 1}, {0, 1}})
      doc["vertices"].push_back({x * 1000, y * 1000, z * 1000});
  }
  const Json shell = {{{0, 3, 2, 1}}, {{0, 1, 5, 4}}, {{1, 2, 6, 5}},
                      {{2, 3, 7, 6}}, {{3, 0, 4, 7}}, {{4, 5, 6, 7}}};
  doc["CityObjects"]["b12"] = {
      {"type", "Building"},
      {"geometry", {{{"type", "Solid"}, {"lod", "1"}, {"boundaries", {shell}}}}}};
  return doc;
}

Json& Boundaries(Json& doc, const std::string& id = "b12") {
  return doc["CityObjects"][id]["geometry"][0]["boundaries"];
}

absl::StatusOr<CityModel> ReadDoc(const Json& doc, const CityReadOptions& options = {}) {
  return ReadCityJsonFromMemory(doc.dump(), "x.city.json", options);
}

// The error is INVALID_ARGUMENT and its message holds `want`.
void ExpectInvalid(const absl::StatusOr<CityModel>& m, const std::string& want) {
  ASSERT_FALSE(m.ok()) << "wanted an error holding: " << want;
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument) << m.status();
  EXPECT_NE(m.status().message().find(want), std::string::npos)
      << m.status().message() << "\nwanted: " << want;
}

TEST(CityJson, CubeReadsAndTransformsItsVertices) {
  absl::StatusOr<CityModel> m = ReadDoc(Cube());
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 1u);
  const auto& shell = Shell(m->objects[0]);
  ASSERT_EQ(shell.size(), 6u);
  ExpectRing(shell[5].outer, {P(0, 0, 1), P(1, 0, 1), P(1, 1, 1), P(0, 1, 1)}, "top");
  EXPECT_EQ(m->crs, "");
}

TEST(CityJson, TruncatedJsonIsRejectedAtEveryLength) {
  const std::string bytes = Cube().dump();
  for (size_t n = 0; n < bytes.size(); ++n) {
    const absl::StatusOr<CityModel> m = ReadCityJsonFromMemory(bytes.substr(0, n), "x.city.json");
    ASSERT_FALSE(m.ok()) << n;
    EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument) << n;
    EXPECT_TRUE(std::string(m.status().message()).starts_with("x.city.json: not valid JSON: "))
        << m.status();
  }
  const std::string shapes = Slurp(Shapes("shapes.city.json"));
  ExpectInvalid(ReadCityJsonFromMemory(shapes.substr(0, shapes.size() / 2), "shapes.city.json"),
                "shapes.city.json: not valid JSON: parse error at line");
}

TEST(CityJson, WrongTypeIsRejected) {
  Json doc = Cube();
  doc["type"] = "CityJSONFeature";
  ExpectInvalid(ReadDoc(doc), "x.city.json: type: \"CityJSONFeature\" is not \"CityJSON\"");
  doc.erase("type");
  ExpectInvalid(ReadDoc(doc), "x.city.json: no \"type\"");
  ExpectInvalid(ReadCityJsonFromMemory("[1, 2]", "x.city.json"),
                "x.city.json: expected a JSON object");
}

TEST(CityJson, UnknownVersionsAreRejectedNamingTheVersion) {
  for (const char* v : {"3.0", "0.2", "1.2", "2", "", "v2.0", "2.0.x"}) {
    ExpectInvalid(ReadDoc(Cube(v)),
                  std::string("x.city.json: version: CityJSON version \"") + v + "\" is not one");
  }
  Json doc = Cube();
  doc["version"] = 2.0;
  ExpectInvalid(ReadDoc(doc), "x.city.json: version: CityJSON version 2.0 is not one");
  doc.erase("version");
  ExpectInvalid(ReadDoc(doc), "x.city.json: no \"version\"");
  for (const char* v :
       {"1.0", "1.0.3", "1.1", "1.1.3", "2.0", "2.0.1", "0.9", "0.6", "0.5", "0.3"}) {
    const absl::StatusOr<CityModel> m = ReadDoc(Cube(v));
    ASSERT_TRUE(m.ok()) << v << ": " << m.status();
    EXPECT_EQ(m->format, std::string("CityJSON ") + v);
  }
}

TEST(CityJson, TransformIsRequiredFrom11AndOptionalBefore) {
  Json doc = Cube("1.1");
  doc.erase("transform");
  ExpectInvalid(ReadDoc(doc), "x.city.json: no \"transform\": CityJSON 1.1 requires one");
  doc["version"] = "1.0";
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  ExpectPoint(Shell(m->objects[0])[5].outer[2], {1000, 1000, 1000});  // the integers as they are
  doc["transform"] = {{"scale", {1, 1}}, {"translate", {0, 0, 0}}};
  ExpectInvalid(ReadDoc(doc), "x.city.json: transform.scale: expected an array of 3 numbers");
}

TEST(CityJson, VertexIndexOutOfRangeNamesObjectAndPath) {
  Json doc = Cube();
  Boundaries(doc)[0][3][0][2] = 8;
  ExpectInvalid(ReadDoc(doc),
                "x.city.json: CityObjects[\"b12\"].geometry[0].boundaries[0][3][0][2]: vertex "
                "index 8 is out of range "
                "(8 vertices)");
  Boundaries(doc)[0][3][0][2] = -1;
  ExpectInvalid(ReadDoc(doc), "boundaries[0][3][0][2]: expected a vertex index, got number -1");
  Boundaries(doc)[0][3][0][2] = 2.5;
  ExpectInvalid(ReadDoc(doc), "boundaries[0][3][0][2]: expected a vertex index, got number 2.5");
}

TEST(CityJson, EmptySolidShellSurfaceAndRingAreRejected) {
  Json doc = Cube();
  Boundaries(doc) = Json::array();
  ExpectInvalid(ReadDoc(doc),
                "x.city.json: CityObjects[\"b12\"].geometry[0].boundaries: empty: no shells");
  Boundaries(doc) = Json::array({Json::array()});
  ExpectInvalid(ReadDoc(doc), "CityObjects[\"b12\"].geometry[0].boundaries[0]: empty: no surfaces");
  doc = Cube();
  Boundaries(doc)[0][1] = Json::array();
  ExpectInvalid(ReadDoc(doc), "CityObjects[\"b12\"].geometry[0].boundaries[0][1]: empty: no rings");
  Boundaries(doc)[0][1] = Json::array({Json::array()});
  ExpectInvalid(ReadDoc(doc),
                "CityObjects[\"b12\"].geometry[0].boundaries[0][1][0]: ring of 0 points");
}

TEST(CityJson, RingOfTwoPointsIsRejectedAlsoAfterDroppingItsClosingPoint) {
  Json doc = Cube();
  Boundaries(doc)[0][2][0] = {1, 2};
  ExpectInvalid(
      ReadDoc(doc),
      "CityObjects[\"b12\"].geometry[0].boundaries[0][2][0]: ring of 2 points (at least 3 needed)");
  Boundaries(doc)[0][2][0] = {1, 2, 1};
  ExpectInvalid(ReadDoc(doc), "boundaries[0][2][0]: ring of 2 points");
}

TEST(CityJson, RepeatedClosingPointIsDroppedAndCounted) {
  Json doc = Cube();
  Boundaries(doc)[0][0][0] = {0, 3, 2, 1, 0};
  Boundaries(doc)[0][5][0] = {4, 5, 6, 7, 4};
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(OuterSizes(Shell(m->objects[0])), (std::vector<size_t>(6, 4)));
  EXPECT_EQ(m->repaired,
            (std::map<std::string, uint64_t>{{"ring closed by repeating its first point", 2}}));
}

TEST(CityJson, NonNumberCoordinateIsRejectedNamingTheVertex) {
  Json doc = Cube();
  doc["vertices"][3][1] = "1000";
  ExpectInvalid(ReadDoc(doc),
                "x.city.json: vertices[3][1]: expected a number, got string \"1000\"");
  doc["vertices"][3] = {1, 2};
  ExpectInvalid(ReadDoc(doc), "x.city.json: vertices[3]: expected [x, y, z], got array");
}

TEST(CityJson, InfiniteCoordinateAfterTransformIsRejectedWhereUsed) {
  Json doc = Cube();
  doc["transform"]["scale"] = {1e300, 1e300, 1e300};
  doc["vertices"][2] = {1, 1e10, 0};
  ExpectInvalid(
      ReadDoc(doc),
      "x.city.json: CityObjects[\"b12\"].geometry[0].boundaries[0][0][0][2]: vertex 2 is not "
      "finite after the transform");
  doc["transform"]["translate"] = {1.7e308, 0, 0};
  doc["transform"]["scale"] = {1, 1, 1};
  doc["vertices"][2] = {1e308, 1, 0};
  ExpectInvalid(ReadDoc(doc),
                "boundaries[0][0][0][2]: vertex 2 is not finite after the transform: (inf");
}

TEST(CityJson, WrongJsonTypesInAnObjectNameTheirPlace) {
  const std::vector<std::pair<std::function<void(Json&)>, std::string>> cases = {
      {[](Json& d) { d["CityObjects"]["b12"]["geometry"] = "none"; },
       "CityObjects[\"b12\"].geometry: expected an array"},
      {[](Json& d) { d["CityObjects"]["b12"]["geometry"][0]["lod"] = true; },
       "CityObjects[\"b12\"].geometry[0].lod: expected a level of detail, got boolean true"},
      {[](Json& d) { d["CityObjects"]["b12"]["geometry"][0].erase("lod"); },
       "CityObjects[\"b12\"].geometry[0]: no \"lod\""},
      {[](Json& d) { d["CityObjects"]["b12"]["type"] = 3; },
       "CityObjects[\"b12\"].type: expected a string, got number 3"},
      {[](Json& d) { d["CityObjects"]["b12"]["parents"] = "p"; },
       "CityObjects[\"b12\"].parents: expected an array of ids"},
      {[](Json& d) { d["CityObjects"]["b12"] = Json::array(); },
       "CityObjects[\"b12\"]: expected a city object, got array"},
      {[](Json& d) { Boundaries(d)[0][0] = 7; },
       "boundaries[0][0]: expected an array of rings, got number 7"},
      {[](Json& d) {
         Boundaries(d) = {{{{{0, 1, 2}}}}};
       },
       "boundaries[0][0][0][0]: expected a vertex index, got array"},
      {[](Json& d) { d["CityObjects"] = Json::array(); },
       "x.city.json: CityObjects: expected an object, got array"},
      {[](Json& d) {
         d["metadata"] = {{"referenceSystem", 28992}};
       },
       "x.city.json: metadata.referenceSystem: expected a string, got number 28992"},
  };
  for (const auto& [mutate, want] : cases) {
    Json doc = Cube();
    mutate(doc);
    ExpectInvalid(ReadDoc(doc), want);
  }
}

TEST(CityJson, DeeplyNestedValuesAreRejectedWithoutRecursion) {
  const std::string deep = std::string(100000, '[') + std::string(100000, ']');
  Json doc = Cube();
  const std::string cube = doc.dump();
  // "type" and a ring's vertex index nested 100,000 deep: rejected, naming only their JSON type.
  std::string bytes = cube;
  bytes.replace(bytes.find("\"CityJSON\""), 10, deep);
  ExpectInvalid(ReadCityJsonFromMemory(bytes, "x.city.json"),
                "x.city.json: type: array is not \"CityJSON\"");
  bytes = cube;
  bytes.replace(bytes.find("[[[[0,3,2,1]"), 12, "[[[[" + deep + ",3,2,1]");
  ExpectInvalid(ReadCityJsonFromMemory(bytes, "x.city.json"),
                "boundaries[0][0][0][0]: expected a vertex index, got array");
}

TEST(CityJson, KeepGoingLeavesMalformedObjectsOutAndCountsThem) {
  Json doc = Cube();
  doc["CityObjects"]["a-bad"] = doc["CityObjects"]["b12"];
  doc["CityObjects"]["c-bad"] = doc["CityObjects"]["b12"];
  doc["CityObjects"]["d-good"] = doc["CityObjects"]["b12"];
  Boundaries(doc, "a-bad")[0][0][0][1] = 99;
  Boundaries(doc, "c-bad")[0][1][0] = {1, 2};
  ExpectInvalid(ReadDoc(doc), "CityObjects[\"a-bad\"]");
  CityReadOptions options;
  options.keep_going = true;
  absl::StatusOr<CityModel> m = ReadDoc(doc, options);
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 2u);
  EXPECT_EQ(m->objects[0].id,
            "b12");  // nlohmann::json::dump writes keys sorted: a-bad, b12, c-bad, d-good
  EXPECT_EQ(m->objects[1].id, "d-good");
  EXPECT_EQ(m->skipped, (std::map<std::string, uint64_t>{{"malformed geometry", 2}}));
}

TEST(CityJson, PointsAndLinesAndUnknownGeometriesAreSkippedAndCounted) {
  Json doc = Cube();
  Json& g = doc["CityObjects"]["b12"]["geometry"];
  g.push_back({{"type", "MultiPoint"}, {"lod", "1"}, {"boundaries", {0, 1}}});
  g.push_back({{"type", "MultiLineString"}, {"lod", "1"}, {"boundaries", {{0, 1}}}});
  g.push_back({{"type", "MultiLineString"}, {"lod", "1"}, {"boundaries", {{1, 2}}}});
  g.push_back({{"type", "Polyhedron"}, {"lod", "1"}, {"boundaries", Json::array()}});
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->objects[0].geometries.size(), 1u);
  EXPECT_EQ(m->skipped, (std::map<std::string, uint64_t>{{"MultiPoint geometry", 1},
                                                         {"MultiLineString geometry", 2},
                                                         {"geometry with unknown type", 1}}));
}

TEST(CityJson, MultiAndCompositeSolidsAndSurfaces) {
  Json doc = Cube();
  const Json solid = Boundaries(doc);
  Json& g = doc["CityObjects"]["b12"]["geometry"];
  g.push_back({{"type", "MultiSolid"}, {"lod", "1"}, {"boundaries", {solid, solid}}});
  g.push_back({{"type", "CompositeSolid"}, {"lod", "1"}, {"boundaries", {solid}}});
  g.push_back({{"type", "CompositeSurface"}, {"lod", "2"}, {"boundaries", solid[0]}});
  g.push_back({{"type", "MultiSurface"}, {"lod", "2"}, {"boundaries", {{{0, 1, 2}, {0, 2, 3}}}}});
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  const auto& gs = m->objects[0].geometries;
  ASSERT_EQ(gs.size(), 5u);
  EXPECT_EQ(gs[1].type, CityGeometryType::kMultiSolid);
  EXPECT_EQ(gs[1].solids.size(), 2u);
  EXPECT_EQ(gs[2].type, CityGeometryType::kCompositeSolid);
  EXPECT_EQ(gs[2].solids.size(), 1u);
  EXPECT_EQ(gs[3].type, CityGeometryType::kCompositeSurface);  // not a TINRelief's
  EXPECT_EQ(gs[3].surfaces.size(), 6u);
  EXPECT_EQ(gs[4].type, CityGeometryType::kMultiSurface);
  ASSERT_EQ(gs[4].surfaces.size(), 1u);
  EXPECT_EQ(gs[4].surfaces[0].holes.size(), 1u);
}

TEST(CityJson, LodNumbersBecomeTheirTextAndExtensionTypesAreKept) {
  Json doc = Cube("1.0");
  doc["CityObjects"]["b12"]["geometry"][0]["lod"] = 2.2;
  doc["CityObjects"]["b12"]["type"] = "+NoiseBuilding";
  doc["CityObjects"]["p"] = {{"type", "BuildingPart"}, {"parents", {"b12"}}};
  doc["CityObjects"]["q"] = {{"type", "BuildingPart"}, {"parent", "b12"}};  // 0.x spelling
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 3u);
  EXPECT_EQ(m->objects[0].type, "+NoiseBuilding");
  EXPECT_EQ(m->objects[0].geometries[0].lod, "2.2");
  EXPECT_EQ(m->objects[1].parent, "b12");
  EXPECT_EQ(m->objects[2].parent, "b12");
  doc["CityObjects"]["b12"]["geometry"][0]["lod"] = 2;
  m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->objects[0].geometries[0].lod, "2");
}

TEST(CityJson, ReferenceSystemsBecomeEpsgCodes) {
  const std::vector<std::pair<Json, std::string>> cases = {
      {{{"referenceSystem", "urn:ogc:def:crs:EPSG::28992"}}, "EPSG:28992"},
      {{{"referenceSystem", "urn:ogc:def:crs:EPSG:6.6:28992"}}, "EPSG:28992"},
      {{{"referenceSystem", "https://www.opengis.net/def/crs/EPSG/0/7415"}}, "EPSG:7415"},
      {{{"referenceSystem", "http://www.opengis.net/def/crs/EPSG/0/7415"}}, "EPSG:7415"},
      {{{"referenceSystem", "EPSG:7415"}}, "EPSG:7415"},
      {{{"referenceSystem", "epsg:7415"}}, "EPSG:7415"},
      {{{"crs", {{"epsg", 7415}}}}, "EPSG:7415"},  // 0.x
      {{{"referenceSystem", "urn:ogc:def:crs,crs:EPSG::28992,crs:EPSG::5709"}},
       "urn:ogc:def:crs,crs:EPSG::28992,crs:EPSG::5709"},
      {{{"referenceSystem", "Local grid"}}, "Local grid"},
      {{{"geographicalExtent", {0, 0, 0, 1, 1, 1}}}, ""},
  };
  for (const auto& [metadata, want] : cases) {
    Json doc = Cube();
    doc["metadata"] = metadata;
    absl::StatusOr<CityModel> m = ReadDoc(doc);
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(m->crs, want) << metadata;
  }
}

TEST(CityJson, TransformationMatrixIsRowMajorThenTranslatedByTheReferencePoint) {
  Json doc = Cube();
  // A template: one triangle at local (1,0,0), (0,1,0), (0,0,1).
  doc["geometry-templates"] = {
      {"templates", {{{"type", "MultiSurface"}, {"lod", "2"}, {"boundaries", {{{0, 1, 2}}}}}}},
      {"vertices-templates", {{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}}}};
  // Rotate 90 degrees about z, scale by 2, then move by (10, 20, 30): x' = -2y + 10,
  // y' = 2x + 20, z' = 2z + 30; then add the reference point, vertex 6 = (85001, 446001, 1).
  doc["CityObjects"]["lamp"] = {
      {"type", "CityFurniture"},
      {"geometry",
       {{{"type", "GeometryInstance"},
         {"template", 0},
         {"boundaries", {6}},
         {"transformationMatrix", {0, -2, 0, 10, 2, 0, 0, 20, 0, 0, 2, 30, 0, 0, 0, 1}}}}}};
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  const CityObject& lamp = Get(*m, "lamp");
  ASSERT_EQ(lamp.geometries.size(), 1u);
  EXPECT_EQ(lamp.geometries[0].type, CityGeometryType::kMultiSurface);
  EXPECT_EQ(lamp.geometries[0].lod, "2");
  ASSERT_EQ(lamp.geometries[0].surfaces.size(), 1u);
  const glm::dvec3 ref = P(1, 1, 1);
  ExpectRing(
      lamp.geometries[0].surfaces[0].outer,
      {ref + glm::dvec3(10, 22, 30), ref + glm::dvec3(8, 20, 30), ref + glm::dvec3(10, 20, 32)},
      "placed");
}

TEST(CityJson, BadTemplateReferencesNameTheInstanceAndTheTemplate) {
  Json doc = Cube();
  doc["geometry-templates"] = {
      {"templates", {{{"type", "MultiSurface"}, {"lod", "2"}, {"boundaries", {{{0, 1, 5}}}}}}},
      {"vertices-templates", {{1.0, 0.0, 0.0}, {0.0, 1.0, 0.0}, {0.0, 0.0, 1.0}}}};
  const Json identity = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  doc["CityObjects"]["lamp"] = {{"type", "CityFurniture"},
                                {"geometry",
                                 {{{"type", "GeometryInstance"},
                                   {"template", 0},
                                   {"boundaries", {6}},
                                   {"transformationMatrix", identity}}}}};
  ExpectInvalid(
      ReadDoc(doc),
      "x.city.json: CityObjects[\"lamp\"].geometry[0]: template 0: "
      "geometry-templates.templates[0].boundaries[0][0][2]: vertex index 5 is out of range (3 "
      "template vertices)");
  doc["CityObjects"]["lamp"]["geometry"][0]["template"] = 1;
  ExpectInvalid(ReadDoc(doc),
                "CityObjects[\"lamp\"].geometry[0].template: template 1 is out of range (1 "
                "geometry templates)");
  doc["CityObjects"]["lamp"]["geometry"][0]["template"] = 0;
  doc["CityObjects"]["lamp"]["geometry"][0]["boundaries"] = {8};
  ExpectInvalid(ReadDoc(doc),
                "CityObjects[\"lamp\"].geometry[0].boundaries[0]: vertex index 8 is out of range "
                "(8 vertices)");
  doc["CityObjects"]["lamp"]["geometry"][0]["boundaries"] = {6};
  doc["CityObjects"]["lamp"]["geometry"][0]["transformationMatrix"] = {1, 0, 0};
  ExpectInvalid(
      ReadDoc(doc),
      "CityObjects[\"lamp\"].geometry[0].transformationMatrix: expected an array of 16 numbers");
  doc["CityObjects"]["lamp"]["geometry"][0]["transformationMatrix"] = identity;
  doc["CityObjects"]["lamp"]["geometry"][0]["transformationMatrix"][0] =
      1e308;  // 1e308 x + 1e308: inf at x = 1
  doc["CityObjects"]["lamp"]["geometry"][0]["transformationMatrix"][3] = 1e308;
  doc["geometry-templates"]["templates"][0]["boundaries"] = {{{0, 1, 2}}};
  ExpectInvalid(ReadDoc(doc),
                "CityObjects[\"lamp\"].geometry[0].transformationMatrix: template 0 placed at");
}

TEST(CityJson, MissingFileIsNotFound) {
  const absl::StatusOr<CityModel> m = ReadCityJson(Shapes("no-such.city.json"));
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(m.status().message().find("no-such.city.json"), std::string::npos);
}

class CountingSink : public ProgressSink {
 public:
  void Start(std::string_view, uint64_t total) override { total_ = total; }
  void Update(std::string_view, uint64_t done, uint64_t, double, std::string_view) override {
    last_ = done;
  }
  void End(std::string_view, double, bool completed) override {
    ended_ = true;
    completed_ = completed;
  }
  uint64_t total_ = 0, last_ = 0;
  bool ended_ = false, completed_ = false;
};

TEST(CityJson, ReportsProgressPerObjectAndStopsWhenCancelled) {
  CountingSink sink;
  std::atomic<bool> cancel{false};
  absl::StatusOr<CityModel> m =
      ReadCityJson(Shapes("shapes.city.json"), {}, RunControl{&sink, &cancel});
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(sink.total_, 14u);
  EXPECT_EQ(sink.last_, 14u);
  EXPECT_TRUE(sink.ended_ && sink.completed_);

  CountingSink cancelled;
  cancel = true;
  m = ReadCityJson(Shapes("shapes.city.json"), {}, RunControl{&cancelled, &cancel});
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kCancelled);
  EXPECT_TRUE(cancelled.ended_);
  EXPECT_FALSE(cancelled.completed_);
}

// ---- the earliest versions (github.com/cityjson/specs, tags 0.1 to 0.5) ----

// A CityJSON 0.1 file as its specification writes one: "type": "CityModel", the version a URL,
// the CRS in metadata.crs.epsg, no "transform" (plain coordinates), numeric "lod", semantics as
// nested strings, and the Building listing its part and installation ("Parts",
// "Installations") where later versions have the part name its parent.
Json Version01() {
  Json doc = {{"type", "CityModel"}, {"version", "http://www.cityjson.org/version/0.1"}};
  doc["metadata"] = {{"crs", {{"epsg", 7415}}}, {"bbox", {85000, 446000, 0, 85001, 446001, 1}}};
  doc["vertices"] = Json::array();
  for (int z : {0, 1}) {
    for (auto [x, y] : {std::pair{0, 0}, {1, 0}, {1, 1}, {0, 1}})
      doc["vertices"].push_back({85000.0 + x, 446000.0 + y, 0.5 * z});
  }
  const Json shell = {{{0, 3, 2, 1}}, {{0, 1, 5, 4}}, {{1, 2, 6, 5}},
                      {{2, 3, 7, 6}}, {{3, 0, 4, 7}}, {{4, 5, 6, 7}}};
  doc["CityObjects"]["b1"] = {{"type", "Building"},
                              {"attributes", {{"roofType", "flat"}}},
                              {"Parts", {"p1", "ghost"}},
                              {"Installations", {"i1"}}};
  doc["CityObjects"]["p1"] = {
      {"type", "BuildingPart"},
      {"geometry",
       {{{"type", "Solid"},
         {"lod", 2},
         {"boundaries", {shell}},
         {"semantics",
          {{"GroundSurface", "WallSurface", "WallSurface", "WallSurface", "WallSurface",
            "RoofSurface"}}},
         {"material", {{0, 0, 1, 1, 1, 1}}}}}}};
  doc["CityObjects"]["i1"] = {
      {"type", "BuildingInstallation"},
      {"geometry",
       {{{"type", "MultiSurface"},
         {"lod", 2},
         {"boundaries", {{{4, 5, 6, 7}}}},
         {"semantics", {{"RoofSurface"}}}}}}};
  return doc;
}

TEST(CityJson, Version01CityModelIsReadWithItsPartsAndEarlySemantics) {
  absl::StatusOr<CityModel> m = ReadDoc(Version01());
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->format, "CityJSON 0.1");
  EXPECT_EQ(m->crs, "EPSG:7415");
  ASSERT_EQ(m->objects.size(), 3u);
  EXPECT_EQ(Get(*m, "b1").parent, "");
  EXPECT_TRUE(Get(*m, "b1").geometries.empty());
  EXPECT_EQ(Get(*m, "p1").parent, "b1") << "listed in the Building's \"Parts\"";
  EXPECT_EQ(Get(*m, "i1").parent, "b1") << "listed in its \"Installations\"";
  const CityObject& part = Get(*m, "p1");
  ASSERT_EQ(part.geometries.size(), 1u);
  EXPECT_EQ(part.geometries[0].type, CityGeometryType::kSolid);
  EXPECT_EQ(part.geometries[0].lod, "2");
  const auto& shell = Shell(part);
  ASSERT_EQ(shell.size(), 6u);
  ExpectRing(shell[5].outer, {P(0, 0, 0.5), P(1, 0, 0.5), P(1, 1, 0.5), P(0, 1, 0.5)}, "top");
  EXPECT_EQ(Get(*m, "i1").geometries.at(0).surfaces.size(), 1u);
  EXPECT_TRUE(m->skipped.empty());

  // The URL as people wrote it: https, without "www.", with a trailing slash.
  for (const char* v : {"https://www.cityjson.org/version/0.1", "http://cityjson.org/version/0.1",
                        "http://www.cityjson.org/version/0.1/"}) {
    Json doc = Version01();
    doc["version"] = v;
    absl::StatusOr<CityModel> n = ReadDoc(doc);
    ASSERT_TRUE(n.ok()) << v << ": " << n.status();
    EXPECT_EQ(n->format, "CityJSON 0.1") << v;
  }
}

TEST(CityJson, PartsListedOnTheParentGiveWayToTheParentAPartNames) {
  Json doc = Version01();
  doc["CityObjects"]["p1"]["parent"] = "b0";  // named by the part: kept
  doc["CityObjects"]["b2"] = {{"type", "Building"}, {"Parts", {"i1", "b2"}}};  // i1 listed twice
  absl::StatusOr<CityModel> m = ReadDoc(doc);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(Get(*m, "p1").parent, "b0");
  EXPECT_EQ(Get(*m, "i1").parent, "b1") << "the first object that lists it";
  EXPECT_EQ(Get(*m, "b2").parent, "") << "an object does not become its own part";

  doc["CityObjects"]["b1"]["Parts"] = "p1";
  ExpectInvalid(ReadDoc(doc),
                "x.city.json: CityObjects[\"b1\"].Parts: expected an array of ids, got string "
                "\"p1\"");
  doc["CityObjects"]["b1"]["Parts"] = {3};
  ExpectInvalid(ReadDoc(doc),
                "x.city.json: CityObjects[\"b1\"].Parts[0]: expected an id, got number 3");
  CityReadOptions keep_going;
  keep_going.keep_going = true;
  absl::StatusOr<CityModel> m2 = ReadDoc(doc, keep_going);
  ASSERT_TRUE(m2.ok()) << m2.status();
  EXPECT_EQ(m2->skipped["malformed geometry"], 1u);
  EXPECT_EQ(Get(*m2, "i1").parent, "b2") << "b1 left out: its list with it";
}

// 0.2 kept 0.1's header, with a "transform" and semantics as objects (its Delfshaven example,
// "lod": "2"); 0.3 changed the header to "CityJSON" and "0.3", 0.5 the semantics to
// "surfaces" and "values". Parts are listed on the Building through 0.6.
TEST(CityJson, Versions02To05WithTransformAndTheirSemanticsAreRead) {
  const Json surfaces = {{{"type", "GroundSurface"}}, {{"type", "WallSurface"}},
                         {{"type", "RoofSurface"}}};
  for (const char* v : {"0.2", "0.3", "0.5"}) {
    Json doc = Cube(v);  // a "transform" and integer vertices
    if (std::string(v) == "0.2") {
      doc["type"] = "CityModel";
      doc["version"] = "http://www.cityjson.org/version/0.2";
    }
    Json& g = doc["CityObjects"]["b12"]["geometry"][0];
    g["lod"] = 2;
    if (std::string(v) == "0.5") {
      g["semantics"] = {{"surfaces", surfaces}, {"values", {{0, 1, 1, 1, 1, 2}}}};
    } else {
      g["semantics"] = {{surfaces[0], surfaces[1], surfaces[1], surfaces[1], surfaces[1],
                         surfaces[2]}};
    }
    doc["CityObjects"]["b0"] = {{"type", "Building"}, {"Parts", {"b12"}}};
    absl::StatusOr<CityModel> m = ReadDoc(doc);
    ASSERT_TRUE(m.ok()) << v << ": " << m.status();
    EXPECT_EQ(m->format, std::string("CityJSON ") + v);
    EXPECT_EQ(Get(*m, "b12").parent, "b0") << v;
    ASSERT_EQ(Get(*m, "b12").geometries.size(), 1u) << v;
    EXPECT_EQ(Get(*m, "b12").geometries[0].lod, "2") << v;
    ExpectRing(Shell(Get(*m, "b12"))[5].outer, {P(0, 0, 1), P(1, 0, 1), P(1, 1, 1), P(0, 1, 1)},
               v);
  }
}

TEST(CityJson, EarlyHeadersInOtherCombinationsAreRefusedNamingTheVersion) {
  const std::string reads =
      " is not one this reader knows: this reader reads CityJSON 0.1 and 0.2 (\"type\": "
      "\"CityModel\", \"version\": \"http://www.cityjson.org/version/0.1\" or .../0.2) and 0.3 to "
      "0.9, 1.0, 1.1 and 2.0 (\"type\": \"CityJSON\", \"version\": \"0.3\" to \"2.0\", from 1.0 "
      "with or without a patch number)";
  // "CityModel" with anything but a 0.1 or 0.2 URL: 0.3 and later wrote "CityJSON".
  for (const char* v : {"http://example.org/x", "http://www.cityjson.org/version/0.3",
                        "http://www.cityjson.org/version/1.0", "ftp://www.cityjson.org/version/0.1",
                        "http://www.cityjson.org/version/0.1//", "0.1", "0.2", "1.0", "2.0", ""}) {
    Json doc = Version01();
    doc["version"] = v;
    ExpectInvalid(
        ReadDoc(doc),
        std::string("x.city.json: version: type \"CityModel\" with version \"") + v + "\"" + reads);
  }
  Json doc = Version01();
  doc["version"] = 0.1;
  ExpectInvalid(ReadDoc(doc), "x.city.json: version: type \"CityModel\" with version 0.1" + reads);
  // "CityJSON" with a URL, with 0.1 or 0.2 (never written so), 0.0, or 0.x with a patch.
  for (const char* v : {"http://www.cityjson.org/version/0.1",
                        "http://www.cityjson.org/version/0.2", "0.1", "0.2", "0.0", "0.3.1"}) {
    doc = Version01();
    doc["type"] = "CityJSON";
    doc["version"] = v;
    ExpectInvalid(ReadDoc(doc),
                  std::string("x.city.json: version: CityJSON version \"") + v + "\"" + reads);
  }
  doc["type"] = "CityGML";
  ExpectInvalid(
      ReadDoc(doc),
      "x.city.json: type: \"CityGML\" is not \"CityJSON\" (nor \"CityModel\", CityJSON 0.1 "
      "and 0.2; CityJSONFeature streams are not read)");
}

// ---- the real files (../shared/data/citymodels/README.md) ----

std::map<std::string, size_t> CountTypes(const CityModel& m) {
  std::map<std::string, size_t> n;
  for (const CityObject& o : m.objects) ++n[o.type];
  return n;
}

TEST(CityJson, DenHaagHasItsBuildingsPartsAndTerrain) {
  const std::string path = RealData("denhaag_01.city.json");
  if (!fs::exists(path)) GTEST_SKIP() << path << " is absent";
  const auto start = std::chrono::steady_clock::now();
  const CityModel m = Read(path);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("seconds", std::to_string(seconds));
  EXPECT_EQ(m.format, "CityJSON 0.8");
  EXPECT_EQ(m.crs, "");  // its metadata holds only geographicalExtent (the README's EPSG:28992 is
                         // not in the file)
  EXPECT_EQ(CountTypes(m), (std::map<std::string, size_t>{
                               {"Building", 844}, {"BuildingPart", 1653}, {"TINRelief", 1}}));
  EXPECT_EQ(m.objects.front().id,
            "GUID_DBDABF53-7DD5-4C2F-BE7F-51F29A0CBA16_1");  // file order, not sorted
  std::set<std::string> buildings;
  size_t with_geometry = 0, parts_with_parent = 0, surfaces = 0;
  for (const CityObject& o : m.objects) {
    if (o.type == "Building") buildings.insert(o.id);
  }
  for (const CityObject& o : m.objects) {
    if (o.type == "BuildingPart") parts_with_parent += buildings.contains(o.parent);
    if (o.type == "TINRelief") continue;
    with_geometry += o.type == "Building" && !o.geometries.empty();
    for (const CityGeometry& g : o.geometries) {
      EXPECT_EQ(g.type, CityGeometryType::kSolid) << o.id;
      EXPECT_EQ(g.lod, "2") << o.id;
      for (const CitySolid& s : g.solids) surfaces += s.shells.at(0).size();
    }
  }
  EXPECT_EQ(parts_with_parent, 1653u);  // 0.8 writes "parent": "<id>"
  EXPECT_EQ(with_geometry, 337u);       // the other 507 buildings are carried by their parts
  EXPECT_EQ(surfaces, 16209u);
  EXPECT_EQ(m.repaired,
            (std::map<std::string, uint64_t>{{"ring closed by repeating its first point", 5}}));
  EXPECT_TRUE(m.skipped.empty());

  // The terrain: 5,595 triangles, 16,785 corners (the README's "16,785 vertices") on 3,059
  // distinct points.
  const auto tin = std::find_if(m.objects.begin(), m.objects.end(),
                                [](const CityObject& o) { return o.type == "TINRelief"; });
  ASSERT_NE(tin, m.objects.end());
  EXPECT_EQ(tin->id, "tin_01_Component_1");
  ASSERT_EQ(tin->geometries.size(), 1u);
  EXPECT_EQ(tin->geometries[0].type, CityGeometryType::kTin);
  const auto& triangles = tin->geometries[0].surfaces;
  EXPECT_EQ(triangles.size(), 5595u);
  std::set<std::tuple<double, double, double>> distinct;
  size_t corners = 0;
  for (const CitySurface& t : triangles) {
    corners += t.outer.size();
    for (const glm::dvec3& p : t.outer) distinct.insert({p.x, p.y, p.z});
  }
  EXPECT_EQ(corners, 16785u);
  EXPECT_EQ(distinct.size(), 3059u);
  ASSERT_FALSE(triangles.empty());
  ExpectPoint(triangles[0].outer[0], {78755.111, 457614.968, 8.391}, "the terrain's first corner");
}

TEST(CityJson, DelftHasItsObjectsByType) {
  const std::string path = RealData("delft.city.json");
  if (!fs::exists(path)) GTEST_SKIP() << path << " is absent";
  const CityModel m = Read(path);
  EXPECT_EQ(m.format, "CityJSON 2.0");
  EXPECT_EQ(m.crs, "EPSG:7415");
  EXPECT_EQ(CountTypes(m), (std::map<std::string, size_t>{{"Building", 160},
                                                          {"Road", 143},
                                                          {"LandUse", 81},
                                                          {"PlantCover", 126},
                                                          {"WaterBody", 3},
                                                          {"Bridge", 3},
                                                          {"GenericCityObject", 54}}));
  EXPECT_EQ(m.objects.front().id, "b0a8da4cc-2d2a-11e6-9a38-393caa90be70");
  for (const CityObject& o : m.objects) {
    ASSERT_EQ(o.geometries.size(), 1u) << o.id;
    EXPECT_EQ(o.geometries[0].lod, "1") << o.id;
    // Buildings are LoD1 solids; everything else, bridges too, LoD1 surfaces.
    EXPECT_EQ(o.geometries[0].type,
              o.type == "Building" ? CityGeometryType::kSolid : CityGeometryType::kMultiSurface)
        << o.id;
  }
  EXPECT_TRUE(m.skipped.empty());
  EXPECT_TRUE(m.repaired.empty());
}

TEST(CityJson, DenHaagSubsetHasFourBuildingsWithEightParts) {
  const std::string path = RealData("denhaag_subset.city.json");
  if (!fs::exists(path)) GTEST_SKIP() << path << " is absent";
  const CityModel m = Read(path);
  EXPECT_EQ(m.format, "CityJSON 1.1");
  EXPECT_EQ(m.crs, "");  // no referenceSystem in its metadata either
  EXPECT_EQ(CountTypes(m), (std::map<std::string, size_t>{{"Building", 4}, {"BuildingPart", 8}}));
  std::map<std::string, size_t> parts;
  for (const CityObject& o : m.objects) {
    if (o.type == "BuildingPart") ++parts[o.parent];
    for (const CityGeometry& g : o.geometries) {
      EXPECT_EQ(g.type, CityGeometryType::kSolid);
      EXPECT_EQ(g.lod, "2");
    }
  }
  EXPECT_EQ(parts,
            (std::map<std::string, size_t>{{"GUID_13974D93-CB4F-4B5A-AB1E-577DD9928CF2", 3},
                                           {"GUID_8CE54418-E2F7-49A7-9A8D-C3D172BA62C4", 2},
                                           {"GUID_DBDABF53-7DD5-4C2F-BE7F-51F29A0CBA16", 3}}));
  EXPECT_TRUE(Get(m, "GUID_8CE54418-E2F7-49A7-9A8D-C3D172BA62C4").geometries.empty());
  EXPECT_EQ(Get(m, "GUID_3D7D60B9-8F3A-4D3B-A3E5-CD9B5565A5B2").geometries.size(), 1u);  // no parts
}

}  // namespace
}  // namespace vistream::scenes
