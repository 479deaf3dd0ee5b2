#include "gl/id_renderer.h"

#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "scenes/mesh.h"

namespace vistream::gl {
namespace {

// One box, x in [2, 4], y and z in [-1, 1], and a second one far behind it, hidden.
scenes::Scene Boxes() {
  scenes::Scene s;
  s.name = "boxes";
  for (double x0 : {2.0, 40.0}) {
    scenes::Mesh m;
    const std::vector<glm::dvec2> f = {{x0, -1}, {x0 + 2, -1}, {x0 + 2, 1}, {x0, 1}};
    scenes::AppendConvexPrism(f, -1.0, 1.0, &m);
    s.AddObject("box", std::move(m));
  }
  return s;
}

TEST(IdRenderer, PixelsSeeTheNearFrontFaceWithItsSolidAngle) {
  const scenes::Scene s = Boxes();
  absl::StatusOr<std::unique_ptr<IdRenderer>> r = IdRenderer::Create(s, 96);
  ASSERT_TRUE(r.ok()) << r.status();
  double total = 0.0;
  for (int y = 0; y < 96; ++y) {
    for (int x = 0; x < 96; ++x) total += (*r)->PixelSolidAngle(x, y);
  }
  EXPECT_NEAR(6 * total, 4 * std::numbers::pi, 1e-9);

  // From the origin the near box's face x = 2 covers 4 asin(1/5) steradians, the far box none.
  absl::StatusOr<std::array<std::vector<uint32_t>, 6>> cube = (*r)->RenderCube(glm::dvec3(0.0));
  ASSERT_TRUE(cube.ok()) << cube.status();
  double near = 0.0;
  int far = 0, back = 0;
  for (int f = 0; f < 6; ++f) {
    for (int y = 0; y < 96; ++y) {
      for (int x = 0; x < 96; ++x) {
        const uint32_t v = (*cube)[f][static_cast<size_t>(y) * 96 + x];
        if (v == 1) near += (*r)->PixelSolidAngle(x, y);
        far += v == 2;
        back += (v & kBackFace) != 0;
        if (f != 0) {
          EXPECT_EQ(v, kNothing) << "face " << f;
        }
      }
    }
  }
  EXPECT_NEAR(near, 4 * std::asin(0.2), 0.02);
  EXPECT_EQ(far, 0);
  EXPECT_EQ(back, 0);

  // From inside the near box every pixel sees a back face.
  for (const glm::dvec3 eye : {glm::dvec3(3, 0, 0), glm::dvec3(3.5, 0.5, -0.5)}) {
    cube = (*r)->RenderCube(eye);
    ASSERT_TRUE(cube.ok());
    for (int f = 0; f < 6; ++f) {
      for (uint32_t v : (*cube)[f]) ASSERT_NE(v & kBackFace, 0u) << "face " << f;
    }
  }
  // Between the boxes, looking back and forth: both, from the front.
  cube = (*r)->RenderCube(glm::dvec3(20, 0, 0));
  ASSERT_TRUE(cube.ok());
  int seen_far = 0, seen_near = 0;
  for (uint32_t v : (*cube)[0]) seen_far += v == 2;
  for (uint32_t v : (*cube)[1]) seen_near += v == 1;
  EXPECT_GT(seen_far, 0);
  EXPECT_GT(seen_near, 0);
}

TEST(IdRenderer, RejectsBadSizes) {
  EXPECT_FALSE(IdRenderer::Create(Boxes(), 0).ok());
  EXPECT_FALSE(IdRenderer::Create(Boxes(), 5000).ok());
}

}  // namespace
}  // namespace vistream::gl
