// ReadCityGml: the hand-made shapes (tests/citymodel/README.md) object by object, Den Haag's
// CityGML 1.0 tile, and bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <string>
#include <vector>

#include "scenes/city_model.h"

namespace vistream::scenes {
namespace {

const std::string kShapes = VISTREAM_SOURCE_DIR "/tests/citymodel/shapes.gml";
const std::string kShapesV1 = VISTREAM_SOURCE_DIR "/tests/citymodel/shapes_v1.gml";
const std::string kDenHaag = VISTREAM_SOURCE_DIR "/../shared/data/citymodels/denhaag_01.gml";

constexpr double kX0 = 85000.0, kY0 = 446000.0;

using Ring = std::vector<glm::dvec3>;

glm::dvec3 P(double x, double y, double z) { return {kX0 + x, kY0 + y, z}; }

// The generator's convention (make_shapes_citygml.py): a ring starts at its corner of least
// (z, x, y).
Ring StartLeast(Ring r) {
  auto least = std::min_element(r.begin(), r.end(), [](const glm::dvec3& a, const glm::dvec3& b) {
    return std::tie(a.z, a.x, a.y) < std::tie(b.z, b.x, b.y);
  });
  std::rotate(r.begin(), least, r.end());
  return r;
}

CitySurface Face(Ring outer, std::vector<Ring> holes = {}) {
  CitySurface s{StartLeast(std::move(outer)), {}};
  for (auto& h : holes) s.holes.push_back(StartLeast(std::move(h)));
  return s;
}

// Floor, walls counter-clockwise from the one at min y, roof (README's and the generator's order).
std::vector<CitySurface> BoxFaces(double x0, double y0, double z0, double x1, double y1, double z1,
                                  bool roof = true) {
  std::vector<CitySurface> f = {
      Face({P(x0, y0, z0), P(x0, y1, z0), P(x1, y1, z0), P(x1, y0, z0)}),
      Face({P(x0, y0, z0), P(x1, y0, z0), P(x1, y0, z1), P(x0, y0, z1)}),
      Face({P(x1, y0, z0), P(x1, y1, z0), P(x1, y1, z1), P(x1, y0, z1)}),
      Face({P(x1, y1, z0), P(x0, y1, z0), P(x0, y1, z1), P(x1, y1, z1)}),
      Face({P(x0, y1, z0), P(x0, y0, z0), P(x0, y0, z1), P(x0, y1, z1)})};
  if (roof) f.push_back(Face({P(x0, y0, z1), P(x1, y0, z1), P(x1, y1, z1), P(x0, y1, z1)}));
  return f;
}

void ExpectSameSurfaces(const std::vector<CitySurface>& got, const std::vector<CitySurface>& want,
                        const std::string& what) {
  ASSERT_EQ(got.size(), want.size()) << what;
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(got[i].outer, want[i].outer) << what << " face " << i;
    ASSERT_EQ(got[i].holes.size(), want[i].holes.size()) << what << " face " << i;
    for (size_t h = 0; h < want[i].holes.size(); ++h) {
      EXPECT_EQ(got[i].holes[h], want[i].holes[h]) << what << " face " << i << " hole " << h;
    }
  }
}

const CityObject* Find(const CityModel& m, const std::string& id) {
  for (const auto& o : m.objects) {
    if (o.id == id) return &o;
  }
  return nullptr;
}

// The one solid of a single-geometry object: checks type and LoD.
const std::vector<CitySurface>& OnlyShell(const CityModel& m, const std::string& id, const std::string& lod) {
  static const std::vector<CitySurface> kNone;
  const CityObject* o = Find(m, id);
  EXPECT_NE(o, nullptr) << id;
  if (o == nullptr) return kNone;
  EXPECT_EQ(o->geometries.size(), 1u) << id;
  if (o->geometries.size() != 1) return kNone;
  const CityGeometry& g = o->geometries[0];
  EXPECT_EQ(g.type, CityGeometryType::kSolid) << id;
  EXPECT_EQ(g.lod, lod) << id;
  EXPECT_EQ(g.solids.size(), 1u) << id;
  if (g.solids.size() != 1) return kNone;
  EXPECT_EQ(g.solids[0].shells.size(), 1u) << id;
  if (g.solids[0].shells.size() != 1) return kNone;
  return g.solids[0].shells[0];
}

class CityGmlShapes : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    auto m = ReadCityGml(kShapes);
    ASSERT_TRUE(m.ok()) << m.status();
    model_ = new CityModel(std::move(*m));
  }
  static void TearDownTestSuite() {
    delete model_;
    model_ = nullptr;
  }
  static CityModel* model_;
};
CityModel* CityGmlShapes::model_ = nullptr;

TEST_F(CityGmlShapes, ObjectsTypesAndParentsInFileOrder) {
  const std::vector<std::tuple<std::string, std::string, std::string>> want = {
      {"gabled", "Building", ""},        {"tower", "Building", ""},
      {"stacked", "Building", ""},       {"stacked-base", "BuildingPart", "stacked"},
      {"stacked-top", "BuildingPart", "stacked"}, {"overhang", "Building", ""},
      {"open", "Building", ""},          {"courtyard", "Building", ""},
      {"slope", "Building", ""},         {"terrain", "TINRelief", ""},
      {"lamp", "CityFurniture", ""},     {"lamp2", "CityFurniture", ""},
      {"garden", "LandUse", ""},         {"bridge", "Bridge", ""}};
  ASSERT_EQ(model_->objects.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(model_->objects[i].id, std::get<0>(want[i]));
    EXPECT_EQ(model_->objects[i].type, std::get<1>(want[i])) << std::get<0>(want[i]);
    EXPECT_EQ(model_->objects[i].parent, std::get<2>(want[i])) << std::get<0>(want[i]);
  }
  EXPECT_TRUE(model_->skipped.empty());
  EXPECT_TRUE(model_->repaired.empty());
}

TEST_F(CityGmlShapes, CrsAndFormat) {
  EXPECT_EQ(model_->crs, "EPSG:28992");
  EXPECT_EQ(model_->format, "CityGML 2.0");
}

TEST_F(CityGmlShapes, NoSemanticSurfaceObjects) {
  // The semantic surfaces (gabled-s0, ...) and the relief feature around the TIN are folded
  // away: only the README's objects remain.
  for (const auto& o : model_->objects) {
    EXPECT_EQ(o.id.find("-s"), std::string::npos) << o.id;
    EXPECT_NE(o.id, "terrain-feature");
  }
}

TEST_F(CityGmlShapes, GabledSolidIsItsSevenFacesOnceEach) {
  // The solid's members are xlinks to the boundary surfaces' polygons: each polygon once.
  const std::vector<CitySurface> want = {
      Face({P(0, 0, 0), P(0, 8, 0), P(10, 8, 0), P(10, 0, 0)}),
      Face({P(0, 0, 0), P(10, 0, 0), P(10, 0, 6), P(0, 0, 6)}),
      Face({P(10, 0, 0), P(10, 8, 0), P(10, 8, 6), P(10, 4, 9), P(10, 0, 6)}),
      Face({P(10, 8, 0), P(0, 8, 0), P(0, 8, 6), P(10, 8, 6)}),
      Face({P(0, 8, 0), P(0, 0, 0), P(0, 0, 6), P(0, 4, 9), P(0, 8, 6)}),
      Face({P(0, 0, 6), P(10, 0, 6), P(10, 4, 9), P(0, 4, 9)}),
      Face({P(10, 8, 6), P(0, 8, 6), P(0, 4, 9), P(10, 4, 9)})};
  ExpectSameSurfaces(OnlyShell(*model_, "gabled", "2"), want, "gabled");
}

TEST_F(CityGmlShapes, TowerPodiumRoofHasTheTowerAsHole) {
  std::vector<CitySurface> podium = BoxFaces(20, 0, 0, 40, 20, 5, false);
  std::vector<CitySurface> tower = BoxFaces(26, 6, 5, 34, 14, 30);
  std::vector<CitySurface> want = podium;
  want.insert(want.end(), tower.begin() + 1, tower.begin() + 5);
  want.push_back(Face({P(20, 0, 5), P(40, 0, 5), P(40, 20, 5), P(20, 20, 5)},
                      {{P(26, 6, 5), P(26, 14, 5), P(34, 14, 5), P(34, 6, 5)}}));
  want.push_back(tower[5]);
  const auto& got = OnlyShell(*model_, "tower", "2");
  ExpectSameSurfaces(got, want, "tower");
  ASSERT_EQ(got.size(), 11u);
  EXPECT_EQ(got[9].holes.size(), 1u);
  EXPECT_EQ(got[9].holes[0].size(), 4u);
}

TEST_F(CityGmlShapes, StackedBuildingHasNoGeometryItsPartsHaveBoxes) {
  const CityObject* stacked = Find(*model_, "stacked");
  ASSERT_NE(stacked, nullptr);
  EXPECT_TRUE(stacked->geometries.empty());
  ExpectSameSurfaces(OnlyShell(*model_, "stacked-base", "2"), BoxFaces(50, 0, 0, 60, 10, 4), "base");
  ExpectSameSurfaces(OnlyShell(*model_, "stacked-top", "2"), BoxFaces(50, 0, 4, 60, 10, 8), "top");
}

TEST_F(CityGmlShapes, OverhangOpenSlopeAndBridgeSolids) {
  const std::vector<CitySurface> overhang = {
      Face({P(70, 0, 0), P(70, 6, 0), P(80, 6, 0), P(80, 0, 0)}),
      Face({P(70, 6, 3), P(70, 10, 3), P(80, 10, 3), P(80, 6, 3)}),
      Face({P(70, 0, 0), P(80, 0, 0), P(80, 0, 6), P(70, 0, 6)}),
      Face({P(80, 0, 0), P(80, 6, 0), P(80, 6, 3), P(80, 10, 3), P(80, 10, 6), P(80, 0, 6)}),
      Face({P(80, 6, 0), P(70, 6, 0), P(70, 6, 3), P(80, 6, 3)}),
      Face({P(80, 10, 3), P(70, 10, 3), P(70, 10, 6), P(80, 10, 6)}),
      Face({P(70, 10, 3), P(70, 6, 3), P(70, 6, 0), P(70, 0, 0), P(70, 0, 6), P(70, 10, 6)}),
      Face({P(70, 0, 6), P(80, 0, 6), P(80, 10, 6), P(70, 10, 6)})};
  ExpectSameSurfaces(OnlyShell(*model_, "overhang", "2"), overhang, "overhang");
  ExpectSameSurfaces(OnlyShell(*model_, "open", "2"), BoxFaces(90, 0, 0, 95, 5, 5, false), "open");
  ExpectSameSurfaces(OnlyShell(*model_, "slope", "2"), BoxFaces(140, 0, 1, 150, 10, 10), "slope");
  ExpectSameSurfaces(OnlyShell(*model_, "bridge", "1"), BoxFaces(0, 50, 3, 20, 54, 4), "bridge");
}

TEST_F(CityGmlShapes, CourtyardLod1FloorAndRoofHaveHoles) {
  const double ox0 = 100, oy0 = 0, ox1 = 120, oy1 = 20, ix0 = 106, iy0 = 6, ix1 = 114, iy1 = 14;
  std::vector<CitySurface> want = {
      Face({P(ox0, oy0, 0), P(ox0, oy1, 0), P(ox1, oy1, 0), P(ox1, oy0, 0)},
           {{P(ix0, iy0, 0), P(ix1, iy0, 0), P(ix1, iy1, 0), P(ix0, iy1, 0)}})};
  const auto outer = BoxFaces(ox0, oy0, 0, ox1, oy1, 10);
  want.insert(want.end(), outer.begin() + 1, outer.begin() + 5);
  want.push_back(Face({P(ix1, iy0, 0), P(ix0, iy0, 0), P(ix0, iy0, 10), P(ix1, iy0, 10)}));
  want.push_back(Face({P(ix1, iy1, 0), P(ix1, iy0, 0), P(ix1, iy0, 10), P(ix1, iy1, 10)}));
  want.push_back(Face({P(ix0, iy1, 0), P(ix1, iy1, 0), P(ix1, iy1, 10), P(ix0, iy1, 10)}));
  want.push_back(Face({P(ix0, iy0, 0), P(ix0, iy1, 0), P(ix0, iy1, 10), P(ix0, iy0, 10)}));
  want.push_back(Face({P(ox0, oy0, 10), P(ox1, oy0, 10), P(ox1, oy1, 10), P(ox0, oy1, 10)},
                      {{P(ix0, iy0, 10), P(ix0, iy1, 10), P(ix1, iy1, 10), P(ix1, iy0, 10)}}));
  ExpectSameSurfaces(OnlyShell(*model_, "courtyard", "1"), want, "courtyard");
}

TEST_F(CityGmlShapes, TerrainIsATinOfEighteenTriangles) {
  const CityObject* t = Find(*model_, "terrain");
  ASSERT_NE(t, nullptr);
  ASSERT_EQ(t->geometries.size(), 1u);
  const CityGeometry& g = t->geometries[0];
  EXPECT_EQ(g.type, CityGeometryType::kTin);
  EXPECT_EQ(g.lod, "2");
  const double xs[] = {130, 140, 150, 160}, ys[] = {-10, 0, 10, 20};
  auto z = [](double x) { return x == 130 ? 0.0 : x == 140 ? 5.0 / 3.0 : x == 150 ? 10.0 / 3.0 : 5.0; };
  std::vector<CitySurface> want;
  for (int j = 0; j < 3; ++j) {
    for (int i = 0; i < 3; ++i) {
      const double x0 = xs[i], x1 = xs[i + 1], y0 = ys[j], y1 = ys[j + 1];
      const auto a = P(x0, y0, z(x0)), b = P(x1, y0, z(x1)), c = P(x1, y1, z(x1)), d = P(x0, y1, z(x0));
      want.push_back(Face({a, b, c}));
      want.push_back(Face({a, c, d}));
    }
  }
  ExpectSameSurfaces(g.surfaces, want, "terrain");
}

TEST_F(CityGmlShapes, LampTemplatesArePlacedAtTheirReferencePoints) {
  for (const auto& [id, y] : {std::pair<std::string, double>{"lamp", 0.0}, {"lamp2", 10.0}}) {
    const CityObject* lamp = Find(*model_, id);
    ASSERT_NE(lamp, nullptr) << id;
    ASSERT_EQ(lamp->geometries.size(), 1u) << id;
    const CityGeometry& g = lamp->geometries[0];
    EXPECT_EQ(g.type, CityGeometryType::kMultiSurface) << id;
    EXPECT_EQ(g.lod, "1") << id;
    // Identity matrix: world = template + reference point, computed as the reader does.
    const glm::dvec3 ref = P(125, y, 0);
    auto L = [&](double x, double yy, double zz) { return glm::dvec3(x + ref.x, yy + ref.y, zz + ref.z); };
    const double h = 0.1;
    // The template's rings as the generator writes them (not rotated to a least corner).
    auto F = [](Ring r) { return CitySurface{std::move(r), {}}; };
    const std::vector<CitySurface> want = {
        F({L(-h, -h, 0), L(-h, h, 0), L(h, h, 0), L(h, -h, 0)}),
        F({L(-h, -h, 0), L(h, -h, 0), L(h, -h, 4), L(-h, -h, 4)}),
        F({L(h, -h, 0), L(h, h, 0), L(h, h, 4), L(h, -h, 4)}),
        F({L(h, h, 0), L(-h, h, 0), L(-h, h, 4), L(h, h, 4)}),
        F({L(-h, h, 0), L(-h, -h, 0), L(-h, -h, 4), L(-h, h, 4)}),
        F({L(-h, -h, 4), L(h, -h, 4), L(h, h, 4), L(-h, h, 4)})};
    ExpectSameSurfaces(g.surfaces, want, id);
  }
}

TEST_F(CityGmlShapes, GardenIsALod1MultiSurface) {
  const CityObject* garden = Find(*model_, "garden");
  ASSERT_NE(garden, nullptr);
  ASSERT_EQ(garden->geometries.size(), 1u);
  EXPECT_EQ(garden->geometries[0].type, CityGeometryType::kMultiSurface);
  EXPECT_EQ(garden->geometries[0].lod, "1");
  ExpectSameSurfaces(garden->geometries[0].surfaces,
                     {Face({P(0, 30, 0), P(10, 30, 0), P(10, 40, 0), P(0, 40, 0)})}, "garden");
}

TEST(CityGmlRead, Version1FileReadsTheSameObjects) {
  auto m = ReadCityGml(kShapesV1);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->format, "CityGML 1.0");
  EXPECT_EQ(m->crs, "EPSG:28992");
  ASSERT_EQ(m->objects.size(), 4u);
  EXPECT_EQ(m->objects[0].id, "gabled");
  EXPECT_EQ(OnlyShell(*m, "gabled", "2").size(), 7u);
  EXPECT_EQ(m->objects[3].parent, "stacked");
  ExpectSameSurfaces(OnlyShell(*m, "stacked-top", "2"), BoxFaces(50, 0, 4, 60, 10, 8), "top");
}

TEST(CityGmlRead, ReadFromMemoryMatchesTheFile) {
  std::ifstream in(kShapes, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  auto a = ReadCityGmlFromMemory(bytes, "shapes");
  auto b = ReadCityGml(kShapes);
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  ASSERT_EQ(a->objects.size(), b->objects.size());
  for (size_t i = 0; i < a->objects.size(); ++i) EXPECT_EQ(a->objects[i].id, b->objects[i].id);
}

// A CityGML 2.0 document around `members` (cityObjectMember contents), `srs` on its envelope.
std::string Doc(const std::string& members, const std::string& srs = "EPSG:28992") {
  return "<?xml version=\"1.0\"?>\n"
         "<CityModel xmlns=\"http://www.opengis.net/citygml/2.0\" "
         "xmlns:bldg=\"http://www.opengis.net/citygml/building/2.0\" "
         "xmlns:gml=\"http://www.opengis.net/gml\" xmlns:xlink=\"http://www.w3.org/1999/xlink\">\n" +
         (srs.empty() ? std::string()
                      : "<gml:boundedBy><gml:Envelope srsName=\"" + srs +
                            "\"><gml:lowerCorner>0 0 0</gml:lowerCorner><gml:upperCorner>1 1 1"
                            "</gml:upperCorner></gml:Envelope></gml:boundedBy>\n") +
         members + "</CityModel>\n";
}

std::string Square(const std::string& id, const std::string& coords) {
  return "<gml:Polygon" + (id.empty() ? std::string() : " gml:id=\"" + id + "\"") +
         "><gml:exterior><gml:LinearRing><gml:posList>" + coords +
         "</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon>";
}

const std::string kSquare = "0 0 0 1 0 0 1 1 0 0 1 0 0 0 0";

std::string MultiSurfaceBuilding(const std::string& id, const std::string& coords) {
  return "<cityObjectMember><bldg:Building gml:id=\"" + id +
         "\"><bldg:lod2MultiSurface><gml:MultiSurface><gml:surfaceMember>" + Square("", coords) +
         "</gml:surfaceMember></gml:MultiSurface></bldg:lod2MultiSurface></bldg:Building></cityObjectMember>\n";
}

TEST(CityGmlRead, CrsNamesNormalised) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"urn:ogc:def:crs:EPSG::28992", "EPSG:28992"},
      {"EPSG:28992", "EPSG:28992"},
      {"urn:ogc:def:crs:EPSG:6.6:28992", "EPSG:28992"},
      {"http://www.opengis.net/def/crs/EPSG/0/7415", "EPSG:7415"},
      {"urn:ogc:def:crs,crs:EPSG::28992,crs:EPSG::5109", "EPSG:28992+5109"},
      {"urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH", "urn:adv:crs:ETRS89_UTM32*DE_DHHN92_NH"},
      {"", ""}};
  for (const auto& [srs, want] : cases) {
    auto m = ReadCityGmlFromMemory(Doc(MultiSurfaceBuilding("b", kSquare), srs), "crs.gml");
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(m->crs, want) << srs;
  }
}

TEST(CityGmlRead, MultiSurfaceAndCompositeSurfaceKeepTheirTypes) {
  const std::string members =
      MultiSurfaceBuilding("ms", kSquare) +
      "<cityObjectMember><gen:GenericCityObject xmlns:gen=\"http://www.opengis.net/citygml/generics/2.0\" "
      "gml:id=\"cs\"><gen:lod1Geometry><gml:CompositeSurface><gml:surfaceMember>" + Square("", kSquare) +
      "</gml:surfaceMember></gml:CompositeSurface></gen:lod1Geometry></gen:GenericCityObject></cityObjectMember>\n";
  auto m = ReadCityGmlFromMemory(Doc(members), "types.gml");
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 2u);
  ASSERT_EQ(m->objects[0].geometries.size(), 1u);
  EXPECT_EQ(m->objects[0].geometries[0].type, CityGeometryType::kMultiSurface);
  EXPECT_EQ(m->objects[0].geometries[0].lod, "2");
  ASSERT_EQ(m->objects[0].geometries[0].surfaces.size(), 1u);
  EXPECT_EQ(m->objects[0].geometries[0].surfaces[0].outer.size(), 4u);  // the closing point dropped
  EXPECT_EQ(m->objects[1].type, "GenericCityObject");
  ASSERT_EQ(m->objects[1].geometries.size(), 1u);
  EXPECT_EQ(m->objects[1].geometries[0].type, CityGeometryType::kCompositeSurface);
  EXPECT_EQ(m->objects[1].geometries[0].lod, "1");
}

TEST(CityGmlRead, SemanticSurfacesWithoutSolidBecomeTheBuildingsMultiSurface) {
  // CityGML 2.0 LoD2 as many exporters write it: only bldg:boundedBy surfaces, no solid.
  const std::string members =
      "<cityObjectMember><bldg:Building gml:id=\"b\">"
      "<bldg:boundedBy><bldg:WallSurface gml:id=\"w\"><bldg:lod2MultiSurface><gml:MultiSurface>"
      "<gml:surfaceMember>" + Square("p1", kSquare) + "</gml:surfaceMember></gml:MultiSurface>"
      "</bldg:lod2MultiSurface></bldg:WallSurface></bldg:boundedBy>"
      "<bldg:boundedBy><bldg:RoofSurface gml:id=\"r\"><bldg:lod2MultiSurface><gml:MultiSurface>"
      "<gml:surfaceMember>" + Square("p2", "0 0 1 1 0 1 1 1 1 0 1 1 0 0 1") + "</gml:surfaceMember></gml:MultiSurface>"
      "</bldg:lod2MultiSurface></bldg:RoofSurface></bldg:boundedBy>"
      "</bldg:Building></cityObjectMember>\n";
  auto m = ReadCityGmlFromMemory(Doc(members), "semantic.gml");
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 1u);
  ASSERT_EQ(m->objects[0].geometries.size(), 1u);
  EXPECT_EQ(m->objects[0].geometries[0].type, CityGeometryType::kMultiSurface);
  EXPECT_EQ(m->objects[0].geometries[0].lod, "2");
  EXPECT_EQ(m->objects[0].geometries[0].surfaces.size(), 2u);
}

TEST(CityGmlRead, InlineSolidAndSurfacesWithTheSameRingsGiveEachPolygonOnce) {
  // The solid's polygons written inline, the boundary surfaces repeating them by value.
  const std::string members =
      "<cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod2Solid><gml:Solid><gml:exterior>"
      "<gml:CompositeSurface><gml:surfaceMember>" + Square("a", kSquare) + "</gml:surfaceMember>"
      "</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod2Solid>"
      "<bldg:boundedBy><bldg:GroundSurface gml:id=\"g\"><bldg:lod2MultiSurface><gml:MultiSurface>"
      "<gml:surfaceMember>" + Square("a-copy", kSquare) + "</gml:surfaceMember></gml:MultiSurface>"
      "</bldg:lod2MultiSurface></bldg:GroundSurface></bldg:boundedBy>"
      "</bldg:Building></cityObjectMember>\n";
  auto m = ReadCityGmlFromMemory(Doc(members), "inline.gml");
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 1u);
  ASSERT_EQ(m->objects[0].geometries.size(), 1u);
  EXPECT_EQ(m->objects[0].geometries[0].type, CityGeometryType::kSolid);
  ASSERT_EQ(m->objects[0].geometries[0].solids.size(), 1u);
  EXPECT_EQ(m->objects[0].geometries[0].solids[0].shells[0].size(), 1u);
}

TEST(CityGmlRead, SolidInteriorShellIsKept) {
  const std::string inner = "0.2 0.2 0.2 0.2 0.8 0.2 0.8 0.8 0.2 0.2 0.2 0.2";
  const std::string members =
      "<cityObjectMember><bldg:Building gml:id=\"b\"><bldg:lod1Solid><gml:Solid>"
      "<gml:exterior><gml:CompositeSurface><gml:surfaceMember>" + Square("", kSquare) +
      "</gml:surfaceMember></gml:CompositeSurface></gml:exterior>"
      "<gml:interior><gml:CompositeSurface><gml:surfaceMember>" + Square("", inner) +
      "</gml:surfaceMember></gml:CompositeSurface></gml:interior>"
      "</gml:Solid></bldg:lod1Solid></bldg:Building></cityObjectMember>\n";
  auto m = ReadCityGmlFromMemory(Doc(members), "void.gml");
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 1u);
  const auto& solids = m->objects[0].geometries.at(0).solids;
  ASSERT_EQ(solids.size(), 1u);
  ASSERT_EQ(solids[0].shells.size(), 2u);
  EXPECT_EQ(solids[0].shells[0][0].outer.size(), 4u);
  EXPECT_EQ(solids[0].shells[1][0].outer.size(), 3u);
}

// --- bad input ---

void ExpectInvalid(const absl::StatusOr<CityModel>& m, const std::vector<std::string>& words) {
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument) << m.status();
  for (const auto& w : words) {
    EXPECT_NE(m.status().message().find(w), std::string_view::npos) << m.status() << " lacks " << w;
  }
}

TEST(CityGmlRead, MissingFileIsNotFound) {
  auto m = ReadCityGml("/nonexistent/city.gml");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(m.status().message().find("/nonexistent/city.gml"), std::string_view::npos);
}

TEST(CityGmlRead, EmptyFileIsRejected) {
  ExpectInvalid(ReadCityGmlFromMemory("", "empty.gml"), {"empty.gml", "line 1"});
}

TEST(CityGmlRead, TruncatedXmlIsRejectedWithItsLine) {
  std::ifstream in(kShapes, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string cut = bytes.substr(0, bytes.size() / 2);
  const auto line = std::count(cut.begin(), cut.end(), '\n') + 1;
  ExpectInvalid(ReadCityGmlFromMemory(cut, "cut.gml"),
                {"cut.gml", "not well-formed XML", "line " + std::to_string(line)});
}

TEST(CityGmlRead, NotXmlIsRejected) {
  ExpectInvalid(ReadCityGmlFromMemory("{\"type\": \"CityJSON\"}", "city.json"), {"city.json", "not well-formed XML"});
}

TEST(CityGmlRead, XmlThatIsNotCityGmlIsRejected) {
  ExpectInvalid(ReadCityGmlFromMemory("<?xml version=\"1.0\"?><osm version=\"0.6\"><node id=\"1\"/></osm>", "map.osm"),
                {"map.osm", "not CityGML", "<osm>"});
  ExpectInvalid(ReadCityGmlFromMemory("<CityModel xmlns=\"http://www.opengis.net/citygml/3.0\"/>", "v3.gml"),
                {"v3.gml", "not CityGML 1.0 or 2.0", "citygml/3.0"});
}

// A document on which libcitygml's own parser throws (found by citygml_fuzz): an error naming
// the file and libcitygml's reason. (libcitygml leaks what it had built when it throws; the
// sanitizer runs suppress leaks inside it and xerces: tests/lsan.supp.)
TEST(CityGmlRead, WhatLibcitygmlThrowsOnIsAnErrorNamingTheFile) {
  const std::string path = VISTREAM_SOURCE_DIR "/tests/citymodel/libcitygml_throws.gml";
  auto m = ReadCityGml(path);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(m.status().message().find(path), std::string::npos) << m.status();
  EXPECT_NE(m.status().message().find("libcitygml: DelayedChoiceElementParser"), std::string::npos) << m.status();
}

TEST(CityGmlRead, DoctypeIsRefused) {
  ExpectInvalid(ReadCityGmlFromMemory("<?xml version=\"1.0\"?><!DOCTYPE x SYSTEM \"file:///etc/passwd\">"
                                      "<CityModel xmlns=\"http://www.opengis.net/citygml/2.0\"/>", "dtd.gml"),
                {"dtd.gml", "DOCTYPE"});
}

TEST(CityGmlRead, DeepNestingIsRefused) {
  std::string deep = "<CityModel xmlns=\"http://www.opengis.net/citygml/2.0\">";
  for (int i = 0; i < 300; ++i) deep += "<a>";
  for (int i = 0; i < 300; ++i) deep += "</a>";
  deep += "</CityModel>";
  ExpectInvalid(ReadCityGmlFromMemory(deep, "deep.gml"), {"deep.gml", "nested deeper"});
}

TEST(CityGmlRead, NanCoordinateNamesTheObject) {
  const std::string doc = Doc(MultiSurfaceBuilding("good", kSquare) +
                              MultiSurfaceBuilding("bad", "0 0 0 1 0 NaN 1 1 0 0 1 0 0 0 0"));
  ExpectInvalid(ReadCityGmlFromMemory(doc, "nan.gml"), {"nan.gml", "'bad'", "NaN"});
  CityReadOptions keep_going;
  keep_going.keep_going = true;
  auto m = ReadCityGmlFromMemory(doc, "nan.gml", keep_going);
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 1u);
  EXPECT_EQ(m->objects[0].id, "good");
  EXPECT_EQ(m->skipped.at("malformed geometry"), 1u);
}

TEST(CityGmlRead, EmptySolidNamesTheObject) {
  const std::string doc = Doc(
      "<cityObjectMember><bldg:Building gml:id=\"hollow\"><bldg:lod1Solid><gml:Solid/></bldg:lod1Solid>"
      "</bldg:Building></cityObjectMember>\n");
  ExpectInvalid(ReadCityGmlFromMemory(doc, "hollow.gml"), {"hollow.gml", "'hollow'", "empty solid"});
}

TEST(CityGmlRead, ShortRingNamesTheObjectAndKeepGoingCountsIt) {
  const std::string doc = Doc(MultiSurfaceBuilding("short", "0 0 0 1 0 0 0 0 0") +
                              MultiSurfaceBuilding("ok", kSquare) +
                              MultiSurfaceBuilding("short2", "0 0 0 1 1 1 0 0 0"));
  ExpectInvalid(ReadCityGmlFromMemory(doc, "short.gml"), {"short.gml", "'short'", "ring of 2 points"});
  CityReadOptions keep_going;
  keep_going.keep_going = true;
  auto m = ReadCityGmlFromMemory(doc, "short.gml", keep_going);
  ASSERT_TRUE(m.ok()) << m.status();
  ASSERT_EQ(m->objects.size(), 1u);
  EXPECT_EQ(m->objects[0].id, "ok");
  EXPECT_EQ(m->skipped.at("malformed geometry"), 2u);
}

TEST(CityGmlRead, DuplicateIdsAreRefused) {
  const std::string doc = Doc(MultiSurfaceBuilding("twin", kSquare) + MultiSurfaceBuilding("twin", kSquare));
  ExpectInvalid(ReadCityGmlFromMemory(doc, "twins.gml"), {"twins.gml", "'twin'"});
}

TEST(CityGmlRead, CancelledBeforeLoading) {
  std::atomic<bool> cancel{true};
  RunControl run;
  run.cancel = &cancel;
  auto m = ReadCityGml(kShapes, {}, run);
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kCancelled);
}

// --- Den Haag ---

TEST(CityGmlRead, DenHaagTile) {
  if (!std::filesystem::exists(kDenHaag)) GTEST_SKIP() << kDenHaag << " is absent: Den Haag is not tested";
  const auto start = std::chrono::steady_clock::now();
  auto m = ReadCityGml(kDenHaag);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(m.ok()) << m.status();
  std::printf("denhaag_01.gml read in %.2f s\n", seconds);
  EXPECT_EQ(m->format, "CityGML 1.0");
  EXPECT_EQ(m->crs, "EPSG:28992");
  EXPECT_TRUE(m->skipped.empty());
  size_t buildings = 0, parts = 0, tins = 0, solids = 0, with_geometry = 0;
  std::set<std::string> ids;
  for (const auto& o : m->objects) {
    EXPECT_TRUE(ids.insert(o.id).second) << o.id;
    if (o.type == "Building") ++buildings;
    if (o.type == "BuildingPart") {
      ++parts;
      EXPECT_FALSE(o.parent.empty()) << o.id;
    }
    if (!o.geometries.empty()) ++with_geometry;
    if (o.type == "TINRelief") {
      ++tins;
      EXPECT_EQ(o.id, "tin_01_Component_1");
      ASSERT_EQ(o.geometries.size(), 1u);
      EXPECT_EQ(o.geometries[0].type, CityGeometryType::kTin);
      EXPECT_EQ(o.geometries[0].lod, "2");
      EXPECT_EQ(o.geometries[0].surfaces.size(), 5595u);  // the file's gml:Triangle count
      continue;
    }
    if (o.type == "Building" || o.type == "BuildingPart") {
      // Every geometry a LoD2 solid of one shell, each polygon once.
      for (const auto& g : o.geometries) {
        ++solids;
        EXPECT_EQ(g.type, CityGeometryType::kSolid) << o.id;
        EXPECT_EQ(g.lod, "2") << o.id;
        ASSERT_EQ(g.solids.size(), 1u) << o.id;
        ASSERT_EQ(g.solids[0].shells.size(), 1u) << o.id;
        std::set<std::vector<double>> rings;
        for (const auto& s : g.solids[0].shells[0]) {
          std::vector<double> key;
          for (const auto& p : s.outer) key.insert(key.end(), {p.x, p.y, p.z});
          EXPECT_TRUE(rings.insert(key).second) << o.id << ": a polygon twice";
        }
        EXPECT_GE(g.solids[0].shells[0].size(), 4u) << o.id;
      }
      EXPECT_LE(o.geometries.size(), 1u) << o.id;
    }
  }
  EXPECT_EQ(buildings, 844u);
  EXPECT_EQ(parts, 1653u);
  EXPECT_EQ(tins, 1u);
  EXPECT_EQ(solids, 1990u);  // the file's gml:Solid count: 337 buildings and all 1,653 parts
  EXPECT_EQ(m->objects.size(), 844u + 1653u + 1u);
}

}  // namespace
}  // namespace vistream::scenes
