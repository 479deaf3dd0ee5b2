#include "gl/id_renderer.h"

#include <algorithm>
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

TEST(IdRenderer, AViewDrawsOnlyTheFlaggedTriangles) {
  const scenes::Scene s = Boxes();
  absl::StatusOr<std::unique_ptr<IdRenderer>> r = IdRenderer::Create(s, 1);
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ((*r)->triangle_count(), s.TriangleCount());
  const size_t first = s.objects[0].mesh.TriangleCount();
  EXPECT_EQ((*r)->FirstTriangle(0), 0u);
  EXPECT_EQ((*r)->FirstTriangle(1), first);
  // Looking down +x from the origin with a 60-degree view: the near box fills the middle.
  const glm::dvec3 eye(0.0), forward(1, 0, 0), up(0, 0, 1);
  auto view = [&](const std::vector<uint8_t>* flags) {
    absl::StatusOr<std::vector<uint32_t>> v = (*r)->RenderView(eye, forward, up, std::numbers::pi / 3, 64, 48, flags);
    EXPECT_TRUE(v.ok()) << v.status();
    return v.ok() ? *v : std::vector<uint32_t>();
  };
  const std::vector<uint32_t> full = view(nullptr);
  ASSERT_EQ(full.size(), 64u * 48u);
  EXPECT_EQ(full[24 * 64 + 32], 1u);  // the centre sees the near box
  EXPECT_EQ(full[0], kNothing);       // a corner sees past it
  EXPECT_EQ(std::count(full.begin(), full.end(), 2u), 0);
  // Every triangle flagged: the same picture.
  std::vector<uint8_t> flags(s.TriangleCount(), 1);
  EXPECT_EQ(view(&flags), full);
  // The near box left out: the far one shows through where it stood.
  std::fill(flags.begin(), flags.begin() + static_cast<std::ptrdiff_t>(first), 0);
  const std::vector<uint32_t> without = view(&flags);
  EXPECT_EQ(std::count(without.begin(), without.end(), 1u), 0);
  EXPECT_GT(std::count(without.begin(), without.end(), 2u), 0);
  // One face of the near box left out: the eye sees into the box (back faces) there.
  flags.assign(s.TriangleCount(), 1);
  int dropped = 0;
  for (size_t t = 0; t < first; ++t) {
    const auto& m = s.objects[0].mesh;
    if (m.positions[m.indices[3 * t]].x == 2.0f && m.positions[m.indices[3 * t + 1]].x == 2.0f &&
        m.positions[m.indices[3 * t + 2]].x == 2.0f) {
      flags[t] = 0;
      ++dropped;
    }
  }
  ASSERT_GT(dropped, 0);
  const std::vector<uint32_t> open = view(&flags);
  EXPECT_NE(open[24 * 64 + 32] & kBackFace, 0u);
  // Bad arguments are errors, not crashes.
  flags.resize(3);
  EXPECT_FALSE((*r)->RenderView(eye, forward, up, 1.0, 64, 48, &flags).ok());
  EXPECT_FALSE((*r)->RenderView(eye, forward, up, 1.0, 0, 48, nullptr).ok());
  EXPECT_FALSE((*r)->RenderView(eye, forward, up, 0.0, 64, 48, nullptr).ok());
}

TEST(IdRenderer, RejectsBadSizes) {
  EXPECT_FALSE(IdRenderer::Create(Boxes(), 0).ok());
  EXPECT_FALSE(IdRenderer::Create(Boxes(), 5000).ok());
}

}  // namespace
}  // namespace vistream::gl
