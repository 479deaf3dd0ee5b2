#include "scenes/scene.h"

#include <cmath>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "scenes/building.h"
#include "scenes/city_generator.h"

namespace vistream::scenes {
namespace {

TEST(Prism, ConvexPrismIsClosedWithOutwardNormals) {
  const std::vector<glm::dvec2> hexagon = {{2, 0}, {1, 1.7}, {-1, 1.7}, {-2, 0}, {-1, -1.7}, {1, -1.7}};
  ASSERT_TRUE(IsConvexCcw(hexagon));
  Mesh m;
  AppendConvexPrism(hexagon, 0.0, 10.0, &m);
  EXPECT_EQ(m.TriangleCount(), 4u * 6 - 4);
  const glm::vec3 centre(0, 0, 5);
  for (size_t t = 0; t < m.indices.size(); t += 3) {
    const glm::vec3 a = m.positions[m.indices[t]], b = m.positions[m.indices[t + 1]], c = m.positions[m.indices[t + 2]];
    const glm::vec3 n = glm::cross(b - a, c - a);
    // Counter-clockwise seen from outside: the face normal points away from the centre,
    // and agrees with the stored vertex normal.
    EXPECT_GT(glm::dot(n, (a + b + c) / 3.f - centre), 0.f) << "triangle " << t / 3;
    EXPECT_GT(glm::dot(n, m.normals[m.indices[t]]), 0.f) << "triangle " << t / 3;
  }
  const Aabb box = m.Bounds();
  EXPECT_EQ(box.min, glm::dvec3(-2, -1.7f, 0));
  EXPECT_EQ(box.max, glm::dvec3(2, 1.7f, 10));
}

TEST(Polygon, OrientationAndConvexity) {
  const std::vector<glm::dvec2> ccw = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  const std::vector<glm::dvec2> cw = {{0, 0}, {0, 1}, {1, 1}, {1, 0}};
  const std::vector<glm::dvec2> ell = {{0, 0}, {2, 0}, {2, 1}, {1, 1}, {1, 2}, {0, 2}};
  EXPECT_DOUBLE_EQ(SignedArea(ccw), 1.0);
  EXPECT_DOUBLE_EQ(SignedArea(cw), -1.0);
  EXPECT_TRUE(IsConvexCcw(ccw));
  EXPECT_FALSE(IsConvexCcw(cw));
  EXPECT_FALSE(IsConvexCcw(ell));
}

Scene OneBox() {
  Scene s;
  AddBuilding(&s, "box", {{FrameRect({0, 0}, {1, 0}, {0, 1}, 0, 4, 0, 4), 0, 9}});
  return s;
}

TEST(ValidateScene, AcceptsAGoodSceneAndRejectsAnEmptyOne) {
  EXPECT_TRUE(ValidateScene(OneBox(), "f").ok());
  const absl::Status s = ValidateScene(Scene{}, "empty.glb");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("empty.glb"), std::string::npos);
  EXPECT_NE(s.message().find("no objects"), std::string::npos);
}

TEST(ValidateScene, NamesTheObjectAndVertexWithNan) {
  Scene s = OneBox();
  s.objects[0].mesh.positions[5].y = std::nanf("");
  const absl::Status st = ValidateScene(s, "f.glb");
  ASSERT_FALSE(st.ok());
  EXPECT_NE(st.message().find("object 0 ('box')"), std::string::npos) << st;
  EXPECT_NE(st.message().find("vertex 5"), std::string::npos) << st;
}

TEST(ValidateScene, RejectsBadIndicesAndOccluders) {
  Scene s = OneBox();
  s.objects[0].mesh.indices[7] = 1000;
  EXPECT_FALSE(ValidateScene(s, "f").ok());
  s = OneBox();
  s.occluders[0].object = 3;
  EXPECT_FALSE(ValidateScene(s, "f").ok());
  s = OneBox();
  s.occluders[0].height = std::nan("");
  EXPECT_FALSE(ValidateScene(s, "f").ok());
  s = OneBox();
  s.occluders[0].footprint.resize(2);
  EXPECT_FALSE(ValidateScene(s, "f").ok());
}

TEST(NormalizeOccluders, MakesFootprintsCounterClockwiseAndKeepsDegenerateOnes) {
  Scene s = OneBox();
  std::reverse(s.occluders[0].footprint.begin(), s.occluders[0].footprint.end());
  s.occluders.push_back({{{0, 0}, {1, 1}, {2, 2}, {0, 0}}, 5.0, 0});  // zero area, closed ring
  NormalizeOccluders(&s);
  EXPECT_GT(SignedArea(s.occluders[0].footprint), 0.0);
  EXPECT_EQ(s.occluders[1].footprint.size(), 3u);  // the repeated closing vertex is dropped
  EXPECT_TRUE(ValidateScene(s, "f").ok());
}

TEST(SceneFingerprint, SameSceneSameDigestAnyChangeAnother) {
  const Scene a = *GenerateNamed("city1", GeneratorParams{});
  Scene b = *GenerateNamed("city1", GeneratorParams{});
  EXPECT_EQ(SceneFingerprint(a), SceneFingerprint(b));
  b.name = "elsewhere";
  b.origin = glm::dvec3(500000, 5000000, 0);
  EXPECT_EQ(SceneFingerprint(a), SceneFingerprint(b));  // only what visibility reads counts
  GeneratorParams other;
  other.seed = 5;
  const Scene c = *GenerateNamed("city1", other);
  ASSERT_EQ(c.objects.size(), a.objects.size());
  EXPECT_NE(SceneFingerprint(a), SceneFingerprint(c));
  Scene d = a;
  d.objects[100].mesh.positions[3].z += 0.001f;
  EXPECT_NE(SceneFingerprint(a), SceneFingerprint(d));
  Scene e = a;
  e.occluders[5].height += 0.5;
  EXPECT_NE(SceneFingerprint(a), SceneFingerprint(e));
  EXPECT_NE(SceneFingerprint(Scene{}), 0u);
}

}  // namespace
}  // namespace vistream::scenes
