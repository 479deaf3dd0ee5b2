#include "visibility/coincident_faces.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "scenes/mesh.h"

namespace vistream::visibility {
namespace {

scenes::Mesh Box(double x0, double y0, double x1, double y1, double z0, double z1) {
  scenes::Mesh m;
  const std::vector<glm::dvec2> f = {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
  scenes::AppendConvexPrism(f, z0, z1, &m);
  return m;
}

CoincidentFaces Find(const std::vector<scenes::Mesh>& meshes, double tolerance = 0.01) {
  std::vector<MeshView> views;
  for (const scenes::Mesh& m : meshes) views.push_back({m.positions, m.indices});
  return FindCoincidentFaces(views, tolerance);
}

size_t Count(const CoincidentFaces& c) {
  size_t n = 0;
  for (const auto& e : c.of_mesh) n += e.size();
  return n;
}

// The wall of mesh m at x = `x`, facing `sign`: its triangles' indices.
std::vector<uint32_t> WallAt(const scenes::Mesh& m, double x, double sign) {
  std::vector<uint32_t> out;
  for (uint32_t t = 0; t < m.TriangleCount(); ++t) {
    const glm::vec3 n = m.normals[m.indices[3 * t]];
    bool on = n.x * sign > 0.99f;
    for (int k = 0; k < 3; ++k) on &= std::abs(m.positions[m.indices[3 * t + k]].x - x) < 1e-4;
    if (on) out.push_back(t);
  }
  return out;
}

TEST(CoincidentFaces, PartyWallsOfTouchingHousesArePartners) {
  const std::vector<scenes::Mesh> houses = {Box(0, 0, 10, 8, 0, 12), Box(10, 0, 16, 8, 0, 9)};
  const CoincidentFaces c = Find(houses);
  // The first house's east wall (x = 10, facing +x) and the second's west wall (facing -x):
  // the lower 9 m coincide, the rest of the first wall stands free.
  for (uint32_t t : WallAt(houses[0], 10, 1)) {
    for (const auto& e : c.Partners(0, t)) {
      EXPECT_EQ(e.partner.mesh, 1u);
      EXPECT_TRUE(std::find(WallAt(houses[1], 10, -1).begin(), WallAt(houses[1], 10, -1).end(), e.partner.triangle) !=
                  WallAt(houses[1], 10, -1).end());
    }
  }
  for (uint32_t t : WallAt(houses[1], 10, -1)) EXPECT_FALSE(c.Partners(1, t).empty()) << "triangle " << t;
  EXPECT_GT(Count(c), 0u);
  // Nothing else: no roof, floor or street wall has a partner.
  for (uint32_t m = 0; m < 2; ++m) {
    for (const auto& e : c.of_mesh[m]) {
      const glm::vec3 n = houses[m].normals[houses[m].indices[3 * e.triangle]];
      EXPECT_GT(std::abs(n.x), 0.99f) << "mesh " << m << " triangle " << e.triangle;
    }
  }
}

TEST(CoincidentFaces, PartialOverlapsTiersAndCracksNarrowerThanTheTolerance) {
  // A row whose side lies partly on an end house's wall (the dead end's kind).
  EXPECT_GT(Count(Find({Box(-1, -10, 0, 10, 0, 16), Box(-1, -11, 60, -10, 0, 20)})), 0u);
  // A tier standing on its base: the tier's floor lies on the base's roof.
  scenes::Mesh tiered = Box(0, 0, 20, 20, 0, 10);
  const scenes::Mesh top = Box(5, 5, 15, 15, 10, 30);
  const uint32_t base = static_cast<uint32_t>(tiered.positions.size());
  tiered.positions.insert(tiered.positions.end(), top.positions.begin(), top.positions.end());
  tiered.normals.insert(tiered.normals.end(), top.normals.begin(), top.normals.end());
  for (uint32_t i : top.indices) tiered.indices.push_back(base + i);
  const CoincidentFaces self = Find({tiered});
  EXPECT_GT(Count(self), 0u);
  for (const auto& e : self.of_mesh[0]) EXPECT_EQ(e.partner.mesh, 0u);
  // Walls 5 mm apart count as touching; 2 cm apart, or along a line only, do not.
  EXPECT_GT(Count(Find({Box(0, 0, 10, 8, 0, 12), Box(10.005, 0, 16, 8, 0, 9)})), 0u);
  EXPECT_EQ(Count(Find({Box(0, 0, 10, 8, 0, 12), Box(10.02, 0, 16, 8, 0, 9)})), 0u);
  EXPECT_EQ(Count(Find({Box(0, 0, 10, 8, 0, 12), Box(10, 8, 16, 12, 0, 9)})), 0u);  // corner to corner
  // Faces on one plane facing the same way are not partners: a box inside another, sharing
  // its front and back walls.
  EXPECT_EQ(Count(Find({Box(0, 0, 10, 8, 0, 12), Box(2, 0, 8, 8, 0, 12)})), 0u);
}

TEST(CoincidentFaces, TurnedWallsFarFromTheOriginAreFound) {
  // Two houses sharing a wall turned by 30 degrees, 600 km from the origin in float: rounding
  // moves their corners by centimetres at that distance, so the finder is given 10 cm.
  const glm::dvec2 o(600000.0, 5000.0), u(std::cos(0.5236), std::sin(0.5236)), v(-u.y, u.x);
  auto house = [&](double a0, double a1) {
    scenes::Mesh m;
    scenes::AppendConvexPrism(std::vector<glm::dvec2>{o + a0 * u, o + a1 * u, o + a1 * u + 8.0 * v, o + a0 * u + 8.0 * v},
                              0, 10, &m);
    return m;
  };
  const std::vector<scenes::Mesh> houses = {house(0, 10), house(10, 17)};
  const CoincidentFaces c = Find(houses, 0.1);
  // Each triangle of one party wall with one or both of the other's, and nothing else.
  EXPECT_GE(Count(c), 4u);
  EXPECT_LE(Count(c), 8u);
  for (uint32_t m = 0; m < 2; ++m) {
    for (const auto& e : c.of_mesh[m]) {
      const glm::vec3 n = houses[m].normals[houses[m].indices[3 * e.triangle]];
      EXPECT_NEAR(std::abs(n.x * u.x + n.y * u.y), 1.0, 1e-3) << "not a party wall";
    }
  }
}

TEST(CoincidentFaces, PointOnTriangleWithinTheTolerance) {
  const glm::dvec3 a(0, 0, 0), b(10, 0, 0), c(0, 10, 0);
  EXPECT_TRUE(PointOnTriangle({2, 2, 0}, a, b, c, 1e-3));
  EXPECT_TRUE(PointOnTriangle({2, 2, 5e-4}, a, b, c, 1e-3));
  EXPECT_FALSE(PointOnTriangle({2, 2, 2e-3}, a, b, c, 1e-3));
  EXPECT_TRUE(PointOnTriangle({5, 5, 0}, a, b, c, 1e-3));       // on the hypotenuse
  EXPECT_TRUE(PointOnTriangle({-5e-4, 3, 0}, a, b, c, 1e-3));   // just outside an edge
  EXPECT_FALSE(PointOnTriangle({6, 6, 0}, a, b, c, 1e-3));
  EXPECT_FALSE(PointOnTriangle({2, 2, 0}, a, b, b, 1e-3));      // degenerate
}


// A flat ground rectangle (two triangles facing up) under the floors of 36 houses: each ground
// triangle has dozens of partners, so PartnerLookup answers from a kd-tree of their boxes. Its
// answers are the brute-force scan's (PointOnTriangle over every partner) at points on the
// ground, on the floors' edges, in the streets and a little above and below the plane; the
// houses' own triangles, with one partner each, are answered by the scan.
TEST(CoincidentFaces, ALookupOverManyPartnersAnswersAsTheScanDoes) {
  std::vector<scenes::Mesh> meshes;
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) meshes.push_back(Box(16.0 * i + 4, 16.0 * j + 4, 16.0 * i + 14, 16.0 * j + 14, 0, 6 + (i + j) % 3));
  }
  scenes::Mesh ground;
  ground.positions = {{0, 0, 0}, {96, 0, 0}, {96, 96, 0}, {0, 96, 0}};
  ground.normals.assign(4, glm::vec3(0, 0, 1));
  ground.indices = {0, 1, 2, 0, 2, 3};
  meshes.push_back(ground);
  const uint32_t g = static_cast<uint32_t>(meshes.size() - 1);
  std::vector<MeshView> views;
  for (const scenes::Mesh& m : meshes) views.push_back({m.positions, m.indices});
  const CoincidentFaces faces = FindCoincidentFaces(views, 0.01);
  const PartnerLookup lookup(faces, views);
  ASSERT_GT(faces.Partners(g, 0).size(), PartnerLookup::kIndexedPartners);
  ASSERT_GT(faces.Partners(g, 1).size(), PartnerLookup::kIndexedPartners);
  EXPECT_EQ(lookup.IndexedTriangles(), 2u);
  auto scan = [&](uint32_t m, uint32_t t, const glm::dvec3& p, double tol) {
    for (const CoincidentFaces::Entry& e : faces.Partners(m, t)) {
      const MeshView& v = views[e.partner.mesh];
      const uint32_t* k = &v.indices[3 * e.partner.triangle];
      if (PointOnTriangle(p, glm::dvec3(v.positions[k[0]]), glm::dvec3(v.positions[k[1]]), glm::dvec3(v.positions[k[2]]), tol)) {
        return true;
      }
    }
    return false;
  };
  size_t on = 0, off = 0;
  for (int i = 0; i <= 960; ++i) {
    for (int j = 0; j <= 960; j += 7) {
      // A lattice of 0.1 m (it meets the floors' edges at x, y = 16 k + 4 and 16 k + 14), and
      // shifted off it by less and more than the tolerance (just outside a floor's box), at
      // heights on the plane, within the tolerance and beyond it.
      for (const glm::dvec3 d : {glm::dvec3(0, 0, 0), glm::dvec3(-0.005, 0.005, 0.004), glm::dvec3(0.006, -0.004, -0.009),
                                 glm::dvec3(0, 0, 0.02), glm::dvec3(-0.02, 0, 0)}) {
        const glm::dvec3 p = glm::dvec3(0.1 * i, 0.1 * j, 0.0) + d;
        for (uint32_t t = 0; t < 2; ++t) {
          const bool expected = scan(g, t, p, 0.01);
          ASSERT_EQ(lookup.OnPartner(g, t, p, 0.01), expected) << "ground triangle " << t << " at " << p.x << ", " << p.y << ", " << p.z;
          (expected ? on : off) += 1;
        }
      }
    }
  }
  EXPECT_GT(on, 10000u);
  EXPECT_GT(off, 10000u);
  // Beyond a sharp corner PointOnTriangle reaches farther than the tolerance: the three edges'
  // offset lines meet tolerance / sin(angle / 2) out (2.6 cm at a floor triangle's 45 degree
  // corners). Points around every floor corner, 1 to 3 tolerances out in 16 directions.
  size_t corner_hits = 0;
  for (int i = 0; i < 6; ++i) {
    for (int j = 0; j < 6; ++j) {
      for (const double cx : {16.0 * i + 4, 16.0 * i + 14}) {
        for (const double cy : {16.0 * j + 4, 16.0 * j + 14}) {
          for (int a = 0; a < 16; ++a) {
            for (const double r : {0.012, 0.016, 0.02, 0.025, 0.03}) {
              const double angle = a * 3.14159265358979 / 8 + 0.1;
              const glm::dvec3 p(cx + r * std::cos(angle), cy + r * std::sin(angle), 0.0);
              for (uint32_t t = 0; t < 2; ++t) {
                const bool expected = scan(g, t, p, 0.01);
                ASSERT_EQ(lookup.OnPartner(g, t, p, 0.01), expected)
                    << "ground triangle " << t << " at " << p.x << ", " << p.y << " (a floor's corner)";
                corner_hits += expected ? 1 : 0;
              }
            }
          }
        }
      }
    }
  }
  EXPECT_GT(corner_hits, 0u);
  // A house's floor (one partner, the ground triangle under it; two where a diagonal crosses).
  for (uint32_t t = 0; t < meshes[0].TriangleCount(); ++t) {
    for (const glm::dvec3 p : {glm::dvec3(5, 5, 0), glm::dvec3(13, 13, 0), glm::dvec3(9, 9, 3), glm::dvec3(9, 4, 0)}) {
      EXPECT_EQ(lookup.OnPartner(0, t, p, 0.01), scan(0, t, p, 0.01)) << "house 0 triangle " << t;
    }
  }
}

}  // namespace
}  // namespace vistream::visibility
