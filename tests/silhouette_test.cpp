#include "visibility/silhouette.h"

#include <embree3/rtcore.h>

#include <gtest/gtest.h>

#include <cmath>
#include <glm/geometric.hpp>
#include <numbers>
#include <vector>

#include "scenes/mesh.h"
#include "scenes/polygon.h"
#include "scenes/random.h"
#include "visibility/discovery_rays.h"

namespace vistream::visibility {
namespace {

std::vector<EdgeTriangle> Triangles(const scenes::Mesh& m) {
  std::vector<EdgeTriangle> t;
  for (size_t i = 0; i + 2 < m.indices.size(); i += 3) {
    const glm::vec3 a = m.positions[m.indices[i]], b = m.positions[m.indices[i + 1]],
                    c = m.positions[m.indices[i + 2]];
    t.push_back({a, b - a, c - a});
  }
  return t;
}

// The oracle: whether the ray from `from` through `through` meets a triangle beyond a millionth
// of the way (Moeller-Trumbore in double, one triangle after another).
bool RayMeets(const glm::dvec3& from, const glm::dvec3& through,
              const std::vector<EdgeTriangle>& tris) {
  const glm::dvec3 d = through - from;
  for (const EdgeTriangle& t : tris) {
    const glm::dvec3 e1(t.e1), e2(t.e2), p = glm::cross(d, e2);
    const double det = glm::dot(e1, p);
    if (det == 0.0) continue;
    const glm::dvec3 sv = from - glm::dvec3(t.a);
    const double u = glm::dot(sv, p) / det;
    if (u < 0.0 || u > 1.0) continue;
    const glm::dvec3 q = glm::cross(sv, e1);
    const double v = glm::dot(d, q) / det;
    if (v < 0.0 || u + v > 1.0) continue;
    if (glm::dot(e2, q) / det > 1e-6) return true;
  }
  return false;
}

glm::dvec3 At(const DiscoveryFan& f, double lambda) { return f.to + lambda * f.radius * f.d; }

// The fan with `towards` made normal to the segment.
DiscoveryFan Fan(const glm::dvec3& from, const glm::dvec3& to, const glm::dvec3& towards,
                 double radius) {
  const glm::dvec3 s = glm::normalize(to - from);
  return {from, to, glm::normalize(towards - glm::dot(towards, s) * s), radius};
}

TEST(Silhouette, BoxSeenHeadOnHasItsEdgeWhereTheAnglesSay) {
  // A 1 m cube 10 m away; the fan sweeps sideways through the middle of its front face: rays
  // through (10, 0.5 + 2λ, 0.5) enter the front face for |2λ| <= 0.5 and nothing else.
  scenes::Mesh m;
  const std::vector<glm::dvec2> square = {{10, 0}, {11, 0}, {11, 1}, {10, 1}};
  scenes::AppendConvexPrism(square, 0.0, 1.0, &m);
  const FanSurface tris(m.positions, m.indices);
  const DiscoveryFan fan{{0.0, 0.5, 0.5}, {10.0, 0.5, 0.5}, {0.0, 1.0, 0.0}, 2.0};
  std::vector<std::pair<double, double>> scratch;
  const std::optional<double> lambda = SilhouetteLambda(fan, tris, &scratch);
  ASSERT_TRUE(lambda.has_value());
  EXPECT_NEAR(*lambda, 0.25, 1e-5);  // single precision: micrometres
  // Swept the other way, the other edge.
  const DiscoveryFan back{fan.from, fan.to, {0.0, -1.0, 0.0}, 2.0};
  ASSERT_TRUE(SilhouetteLambda(back, tris, &scratch).has_value());
  EXPECT_NEAR(*SilhouetteLambda(back, tris, &scratch), 0.25,
              1e-5);  // single precision: micrometres
  // A radius too small to get past the edge: no silhouette within reach.
  const DiscoveryFan small{fan.from, fan.to, fan.d, 0.2};
  EXPECT_FALSE(SilhouetteLambda(small, tris, &scratch).has_value());
  // Aimed past the cube, with the cube on the negative side: the edge from there (the ray
  // through y = 1 at x = 10, which by similar triangles is λ = -0.25 again).
  const DiscoveryFan past = Fan(fan.from, {10.0, 1.5, 0.5}, {0.0, 1.0, 0.0}, 2.0);
  ASSERT_TRUE(SilhouetteLambda(past, tris, &scratch).has_value());
  EXPECT_NEAR(*SilhouetteLambda(past, tris, &scratch), -0.25, 1e-5);
  // Nothing on either side: none.
  const DiscoveryFan away = Fan(fan.from, {10.0, 5.0, 0.5}, {0.0, 1.0, 0.0}, 1.0);
  EXPECT_FALSE(SilhouetteLambda(away, tris, &scratch).has_value());
}

// Compares the search on `m` with the brute-force oracle for `fans` random fans: every λ the
// intervals hold is a meeting ray and every other one a missing ray, away from the interval
// ends; the silhouette has meeting rays just below it and missing rays just above. Fans start
// at street level in front of the buildings, or (`from_surface`) on their surface, where the
// pieces' crossings reach behind the fan's point and their triangles must answer.
void CheckFans(const scenes::Mesh& m, bool from_surface, int fans, scenes::Rng& rng, int* found,
               int* checked) {
  const std::vector<EdgeTriangle> raw = Triangles(m);
  const FanSurface tris(m.positions, m.indices);
  ASSERT_EQ(tris.triangles(), raw.size());
  std::vector<std::pair<double, double>> scratch, hits;
  auto surface_point = [&] {
    const EdgeTriangle& t = raw[rng.Below(raw.size())];
    const double u = rng.Uniform(0, 0.5), v = rng.Uniform(0, 0.5);
    return glm::dvec3(t.a) + u * glm::dvec3(t.e1) + v * glm::dvec3(t.e2);
  };
  for (int q = 0; q < fans; ++q) {
    DiscoveryFan fan;
    fan.from = from_surface ? surface_point()
                            : glm::dvec3(rng.Uniform(-20, 20), rng.Uniform(-20, 20), rng.Uniform(0.5, 3));
    fan.to = surface_point();
    if (glm::length(fan.to - fan.from) < 0.5) continue;
    const glm::dvec3 s = glm::normalize(fan.to - fan.from);
    glm::dvec3 b1 = glm::cross(s, glm::dvec3(0, 0, 1));
    if (glm::length(b1) < 1e-3) b1 = glm::cross(s, glm::dvec3(1, 0, 0));
    b1 = glm::normalize(b1);
    const glm::dvec3 b2 = glm::cross(s, b1);
    const double phi = rng.Uniform(0, 2 * std::numbers::pi);
    fan.d = std::cos(phi) * b1 + std::sin(phi) * b2;
    fan.radius = rng.Uniform(2, 30);

    hits.clear();
    FanHits(fan, tris, &hits);
    constexpr double kTol = 1e-4;
    for (int k = 0; k <= 400; ++k) {
      const double lambda = -1.0 + k / 200.0;
      bool inside = false, near_end = false;
      for (const auto& [lo, hi] : hits) {
        inside |= lo <= lambda && lambda <= hi;
        near_end |= std::abs(lambda - lo) < kTol || std::abs(lambda - hi) < kTol;
      }
      if (near_end) continue;
      ++*checked;
      ASSERT_EQ(inside, RayMeets(fan.from, At(fan, lambda), raw)) << "fan " << q << " λ " << lambda;
    }

    const std::optional<double> sil = SilhouetteLambda(fan, tris, &scratch);
    const bool meets0 = RayMeets(fan.from, At(fan, 0.0), raw);
    if (!sil) {
      // None: the far end is met, or nothing in [-1, 0] is.
      bool any_below = false;
      for (int k = 0; k <= 200; ++k) any_below |= RayMeets(fan.from, At(fan, -k / 200.0), raw);
      EXPECT_TRUE(RayMeets(fan.from, At(fan, 1.0), raw) || !any_below) << "fan " << q;
      continue;
    }
    ++*found;
    EXPECT_FALSE(RayMeets(fan.from, At(fan, 1.0), raw));
    EXPECT_TRUE(RayMeets(fan.from, At(fan, *sil - 1e-3), raw)) << "fan " << q;
    EXPECT_FALSE(RayMeets(fan.from, At(fan, *sil + 1e-3), raw)) << "fan " << q;
    if (std::abs(*sil) < kTol) {
      // The ray through `to` runs along the silhouette (from a point on the same face): whether
      // it meets is rounding's call, as at the intervals' ends above.
    } else if (meets0) {
      EXPECT_GE(*sil, 0.0);
    } else {
      EXPECT_LT(*sil, 0.0);
      for (double l = *sil + 1e-3; l <= 0.0; l += 1e-2) EXPECT_FALSE(RayMeets(fan.from, At(fan, l), raw));
    }
  }
}

// 30 fans from the street, then 10 from the surface.
void CheckAgainstRayCasting(const scenes::Mesh& m, scenes::Rng& rng, int* found, int* checked) {
  CheckFans(m, /*from_surface=*/false, 30, rng, found, checked);
  CheckFans(m, /*from_surface=*/true, 10, rng, found, checked);
}

std::vector<glm::dvec2> ConvexFootprint(scenes::Rng& rng) {
  const double x = rng.Uniform(30, 60), y = rng.Uniform(-20, 20), w = rng.Uniform(3, 15), dp = rng.Uniform(3, 15);
  std::vector<glm::dvec2> f;
  const int corners = 3 + static_cast<int>(rng.Below(5));
  for (int k = 0; k < corners; ++k) {
    const double a = 2 * std::numbers::pi * k / corners;
    f.push_back({x + w * std::cos(a), y + dp * std::sin(a)});
  }
  return f;
}

// Random buildings (rows of convex prisms, some stacked): each prism is a piece.
TEST(Silhouette, AgreesWithRayCastingOnRandomBuildings) {
  scenes::Rng rng(42);
  int found = 0, checked = 0;
  for (int scene = 0; scene < 60; ++scene) {
    scenes::Mesh m;
    const int parts = 1 + static_cast<int>(rng.Below(4));
    for (int p = 0; p < parts; ++p) {
      const double z0 = rng.Below(3) == 0 ? rng.Uniform(2, 10) : 0.0;
      scenes::AppendConvexPrism(ConvexFootprint(rng), z0, z0 + rng.Uniform(5, 40), &m);
    }
    EXPECT_EQ(FanSurface(m.positions, m.indices).pieces(), static_cast<size_t>(parts)) << "scene " << scene;
    SCOPED_TRACE(testing::Message() << "scene " << scene);
    CheckAgainstRayCasting(m, rng, &found, &checked);
  }
  // The random fans did find silhouettes, and the oracle compared many rays.
  EXPECT_GT(found, 600);
  EXPECT_GT(checked, 900000);
}

// Terraces: boxes in a row sharing their party walls exactly. An edge of a shared wall belongs
// to four triangles, so it joins nothing, and each box is still a closed convex piece.
TEST(Silhouette, TerraceHousesAreOnePieceEach) {
  scenes::Rng rng(7);
  int found = 0, checked = 0;
  for (int scene = 0; scene < 10; ++scene) {
    scenes::Mesh m;
    const int houses = 2 + static_cast<int>(rng.Below(4));
    double x = 30.0;
    for (int h = 0; h < houses; ++h) {
      const double w = rng.Uniform(4, 9);
      scenes::AppendConvexPrism(std::vector<glm::dvec2>{{x, 0}, {x + w, 0}, {x + w, 10}, {x, 10}}, 0.0,
                                rng.Uniform(6, 20), &m);
      x += w;
    }
    EXPECT_EQ(FanSurface(m.positions, m.indices).pieces(), static_cast<size_t>(houses));
    SCOPED_TRACE(testing::Message() << "terrace " << scene);
    CheckAgainstRayCasting(m, rng, &found, &checked);
  }
  EXPECT_GT(found, 100);
}

// A piece keeps the edges where two of its faces meet, not the diagonals that split a face
// into triangles: an n-sided prism has 3n (its walls' diagonals and its roof's and floor's
// fans are dropped), and each is still read as ray casting reads it.
TEST(Silhouette, PiecesKeepOnlyTheEdgesBetweenFaces) {
  scenes::Rng rng(11);
  for (int sides = 3; sides <= 8; ++sides) {
    std::vector<glm::dvec2> footprint;
    for (int k = 0; k < sides; ++k) {
      const double a = 2.0 * std::numbers::pi * k / sides;
      footprint.emplace_back(40.0 + 8.0 * std::cos(a), 5.0 + 8.0 * std::sin(a));
    }
    scenes::Mesh m;
    scenes::AppendConvexPrism(footprint, 0.0, 12.0, &m);
    const FanSurface surface(m.positions, m.indices);
    ASSERT_EQ(surface.pieces(), 1u) << sides << " sides";
    EXPECT_EQ(surface.piece_list()[0].edge_count, static_cast<uint32_t>(3 * sides)) << sides << " sides";
    EXPECT_GT(surface.triangles(), static_cast<size_t>(2 * sides));  // split faces: there were diagonals
    int found = 0, checked = 0;
    SCOPED_TRACE(testing::Message() << sides << " sides");
    CheckAgainstRayCasting(m, rng, &found, &checked);
    EXPECT_GT(found, 0);
  }
}

// L-shaped and courtyard footprints are closed but not convex: their triangles are read one
// by one, and agree with the oracle too.
TEST(Silhouette, NonConvexBuildingsAreReadByTriangles) {
  scenes::Rng rng(9);
  int found = 0, checked = 0;
  for (int scene = 0; scene < 20; ++scene) {
    const double x = rng.Uniform(30, 50), y = rng.Uniform(-20, 0), w = rng.Uniform(10, 20), d = rng.Uniform(10, 20);
    scenes::PolygonWithHoles poly;
    if (scene % 2 == 0) {
      poly.outer = {{x, y}, {x + w, y}, {x + w, y + 4}, {x + 4, y + 4}, {x + 4, y + d}, {x, y + d}};
    } else {
      poly.outer = {{x, y}, {x + w, y}, {x + w, y + d}, {x, y + d}};
      poly.holes = {{{x + 3, y + 3}, {x + 3, y + d - 3}, {x + w - 3, y + d - 3}, {x + w - 3, y + 3}}};
    }
    const auto triangles = scenes::Triangulate(poly);
    ASSERT_TRUE(triangles.ok()) << triangles.status();
    scenes::Mesh m;
    scenes::AppendPrism(poly, *triangles, 0.0, rng.Uniform(5, 30), &m);
    const FanSurface surface(m.positions, m.indices);
    EXPECT_EQ(surface.pieces(), 0u);
    EXPECT_EQ(surface.loose_count(), surface.triangles());
    SCOPED_TRACE(testing::Message() << "footprint " << scene);
    CheckAgainstRayCasting(m, rng, &found, &checked);
  }
  EXPECT_GT(found, 200);
}

// A mesh alone in an Embree scene, as the sampler holds a large object.
class EmbreeMesh {
 public:
  explicit EmbreeMesh(const scenes::Mesh& m) : device_(rtcNewDevice(nullptr)), scene_(rtcNewScene(device_)) {
    RTCGeometry g = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), m.positions.size()));
    for (size_t i = 0; i < m.positions.size(); ++i) {
      v[3 * i] = m.positions[i].x, v[3 * i + 1] = m.positions[i].y, v[3 * i + 2] = m.positions[i].z;
    }
    auto* ix = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                                              3 * sizeof(uint32_t), m.indices.size() / 3));
    std::copy(m.indices.begin(), m.indices.end(), ix);
    rtcCommitGeometry(g);
    rtcAttachGeometry(scene_, g);
    rtcReleaseGeometry(g);
    rtcSetSceneFlags(scene_, RTC_SCENE_FLAG_ROBUST);
    rtcCommitScene(scene_);
  }
  ~EmbreeMesh() {
    rtcReleaseScene(scene_);
    rtcReleaseDevice(device_);
  }
  RTCScene scene() const { return scene_; }

 private:
  RTCDevice device_;
  RTCScene scene_;
};

// The paper's search with discovery rays finds, on a convex prism (one run of meeting rays),
// the border the exact search finds, to the 64th of the radius its bisection leaves, from
// below; and it says "none" where the exact search does.
TEST(DiscoveryRays, FindTheExactSilhouetteOfConvexPrismsToABisectionStep) {
  scenes::Rng rng(7);
  int compared = 0, disagree = 0;
  uint64_t rays = 0;
  std::vector<std::pair<double, double>> scratch;
  for (int scene = 0; scene < 40; ++scene) {
    scenes::Mesh m;
    scenes::AppendConvexPrism(ConvexFootprint(rng), 0.0, rng.Uniform(5, 40), &m);
    const FanSurface tris(m.positions, m.indices);
    const EmbreeMesh embree(m);
    for (int q = 0; q < 50; ++q) {
      const size_t t = rng.Below(m.indices.size() / 3);
      const glm::dvec3 a(m.positions[m.indices[3 * t]]), b(m.positions[m.indices[3 * t + 1]]),
          c(m.positions[m.indices[3 * t + 2]]);
      const double u = rng.Uniform(0, 0.5), v = rng.Uniform(0, 0.5);
      const glm::dvec3 from(rng.Uniform(-20, 20), rng.Uniform(-20, 20), rng.Uniform(0.5, 3));
      const glm::dvec3 to = a + u * (b - a) + v * (c - a);
      const glm::dvec3 s = glm::normalize(to - from);
      glm::dvec3 b1 = glm::normalize(glm::cross(s, glm::dvec3(0, 0, 1)));
      const glm::dvec3 b2 = glm::cross(s, b1);
      const double phi = rng.Uniform(0, 2 * std::numbers::pi);
      const DiscoveryFan fan{from, to, std::cos(phi) * b1 + std::sin(phi) * b2, rng.Uniform(2, 30)};
      const std::optional<double> exact = SilhouetteLambda(fan, tris, &scratch);
      const std::optional<double> found = DiscoveryLambda(fan, embree.scene(), &rays);
      // A border within rounding of λ = 0 or ±1 may be judged either way.
      if (exact && (std::abs(*exact) < 1e-4 || std::abs(std::abs(*exact) - 1.0) < 1e-4)) continue;
      ++compared;
      if (exact.has_value() != found.has_value()) {
        ++disagree;
        continue;
      }
      if (!exact) continue;
      EXPECT_LE(*found, *exact + 1e-4) << "scene " << scene << ", fan " << q;
      EXPECT_GE(*found, *exact - 1.0 / 64 - 1e-4) << "scene " << scene << ", fan " << q;
    }
  }
  EXPECT_GT(compared, 1800);
  EXPECT_LE(disagree, compared / 100) << disagree << " of " << compared;
  EXPECT_GT(rays, 2u * compared);
}

// A ring of 15,000 thin roof and wall triangles, not convex: the sphere trees over its loose
// triangles leave the search's answers as they were (checked against ray casting as above).
TEST(Silhouette, LargeNonConvexRingAgreesWithRayCasting) {
  scenes::Mesh m;
  const int n = 2500;
  // Per k: outer bottom, outer top, inner bottom, inner top.
  for (int k = 0; k < n; ++k) {
    const double a = 2 * std::numbers::pi * k / n;
    for (double r : {30.0, 20.0}) {
      for (double z : {0.0, 12.0}) m.positions.emplace_back(40 + r * std::cos(a), r * std::sin(a), z);
    }
  }
  auto tri = [&](uint32_t a, uint32_t b, uint32_t c) { m.indices.insert(m.indices.end(), {a, b, c}); };
  for (uint32_t k = 0; k < static_cast<uint32_t>(n); ++k) {
    const uint32_t p = 4 * k, q = 4 * ((k + 1) % n);
    tri(p, q, q + 1), tri(p, q + 1, p + 1);              // outer wall
    tri(p + 2, p + 3, q + 3), tri(p + 2, q + 3, q + 2);  // inner wall
    tri(p + 1, q + 1, q + 3), tri(p + 1, q + 3, p + 3);  // roof: thin, 10 m across, 5 cm along
  }
  m.normals.assign(m.positions.size(), glm::vec3(0, 0, 1));
  const FanSurface tris(m.positions, m.indices);
  EXPECT_EQ(tris.triangles(), 6u * n);
  EXPECT_GT(tris.loose_tree().size(), 1u) << "a tree of more than one level";
  scenes::Rng rng(11);
  int found = 0, checked = 0;
  CheckAgainstRayCasting(m, rng, &found, &checked);
  EXPECT_GT(found, 5);
  EXPECT_GT(checked, 10000);
}

}  // namespace
}  // namespace vistream::visibility
