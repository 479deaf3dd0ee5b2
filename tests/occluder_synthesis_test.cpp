#include "scenes/occluder_synthesis.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <functional>
#include <map>
#include <numbers>
#include <tuple>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "scenes/city_generator.h"
#include "scenes/mesh.h"
#include "scenes/random.h"
#include "tests/solid_oracle.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

// Solids built by hand: convex planar faces (fanned into triangles) over vertices shared by
// position, so that the mesh closes exactly.
class SolidBuilder {
 public:
  uint32_t Vertex(const glm::dvec3& p) {
    const auto key = std::make_tuple(p.x, p.y, p.z);
    const auto it = index_.find(key);
    if (it != index_.end()) return it->second;
    const uint32_t i = static_cast<uint32_t>(solid_.vertices.size());
    solid_.vertices.push_back(p);
    index_.emplace(key, i);
    return i;
  }
  // A convex polygon, fanned from its first point.
  void Face(const std::vector<glm::dvec3>& polygon) {
    for (size_t i = 1; i + 1 < polygon.size(); ++i) {
      solid_.triangles.push_back({Vertex(polygon[0]), Vertex(polygon[i]), Vertex(polygon[i + 1])});
    }
  }
  const SolidMesh& solid() const { return solid_; }

 private:
  SolidMesh solid_;
  std::map<std::tuple<double, double, double>, uint32_t> index_;
};

// A box as its own closed mesh (six faces).
void AddBox(SolidBuilder* b, glm::dvec3 lo, glm::dvec3 hi) {
  const double x0 = lo.x, y0 = lo.y, z0 = lo.z, x1 = hi.x, y1 = hi.y, z1 = hi.z;
  b->Face({{x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, {x1, y0, z0}});
  b->Face({{x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}});
  b->Face({{x0, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {x0, y0, z1}});
  b->Face({{x1, y1, z0}, {x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}});
  b->Face({{x0, y1, z0}, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}});
  b->Face({{x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}});
}

SolidMesh Box(glm::dvec3 lo, glm::dvec3 hi) {
  SolidBuilder b;
  AddBox(&b, lo, hi);
  return b.solid();
}

struct Cuboid {
  glm::dvec3 lo, hi;
};

// The union of boxes as one closed mesh: the grid of all their coordinates, a quad wherever a
// cell inside meets one outside (faces between grid vertices only: no T-junctions).
SolidMesh BoxUnion(const std::vector<Cuboid>& boxes) {
  std::vector<double> c[3];
  for (const Cuboid& b : boxes) {
    for (int a = 0; a < 3; ++a) {
      c[a].push_back(b.lo[a]);
      c[a].push_back(b.hi[a]);
    }
  }
  for (auto& v : c) {
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  }
  const int n[3] = {static_cast<int>(c[0].size()) - 1, static_cast<int>(c[1].size()) - 1,
                    static_cast<int>(c[2].size()) - 1};
  auto inside = [&](int i, int j, int k) {
    if (i < 0 || j < 0 || k < 0 || i >= n[0] || j >= n[1] || k >= n[2]) return false;
    const glm::dvec3 m(0.5 * (c[0][i] + c[0][i + 1]), 0.5 * (c[1][j] + c[1][j + 1]),
                       0.5 * (c[2][k] + c[2][k + 1]));
    for (const Cuboid& b : boxes) {
      if (glm::all(glm::greaterThan(m, b.lo)) && glm::all(glm::lessThan(m, b.hi))) return true;
    }
    return false;
  };
  SolidBuilder out;
  auto p = [&](int i, int j, int k) { return glm::dvec3(c[0][i], c[1][j], c[2][k]); };
  for (int i = -1; i < n[0]; ++i) {
    for (int j = -1; j < n[1]; ++j) {
      for (int k = -1; k < n[2]; ++k) {
        const bool in = inside(i, j, k);
        // The faces towards +x, +y, +z.
        if (j >= 0 && k >= 0 && in != inside(i + 1, j, k)) {
          out.Face({p(i + 1, j, k), p(i + 1, j + 1, k), p(i + 1, j + 1, k + 1), p(i + 1, j, k + 1)});
        }
        if (i >= 0 && k >= 0 && in != inside(i, j + 1, k)) {
          out.Face({p(i, j + 1, k), p(i + 1, j + 1, k), p(i + 1, j + 1, k + 1), p(i, j + 1, k + 1)});
        }
        if (i >= 0 && j >= 0 && in != inside(i, j, k + 1)) {
          out.Face({p(i, j, k + 1), p(i + 1, j, k + 1), p(i + 1, j + 1, k + 1), p(i, j + 1, k + 1)});
        }
      }
    }
  }
  return out.solid();
}

// A house W x D (ridge along x at y = D / 2), turned by `angle` about the origin and moved by
// `at`: walls from the floor corners `floor` (four heights, so the floor may slope or bend)
// to the eaves, a gabled roof (hip = 0) or a hipped one (hip > 0: the ridge ends that far in
// from the gables).
SolidMesh House(double w, double d, const std::array<double, 4>& floor, double eaves, double ridge,
                double hip = 0.0, double angle = 0.0, glm::dvec2 at = glm::dvec2(0.0)) {
  const double cs = std::cos(angle), sn = std::sin(angle);
  auto p = [&](double x, double y, double z) {
    return glm::dvec3(at.x + cs * x - sn * y, at.y + sn * x + cs * y, z);
  };
  const glm::dvec3 b0 = p(0, 0, floor[0]), b1 = p(w, 0, floor[1]), b2 = p(w, d, floor[2]),
                   b3 = p(0, d, floor[3]);
  const glm::dvec3 e0 = p(0, 0, eaves), e1 = p(w, 0, eaves), e2 = p(w, d, eaves), e3 = p(0, d, eaves);
  const glm::dvec3 r0 = p(hip, d / 2, ridge), r1 = p(w - hip, d / 2, ridge);
  SolidBuilder b;
  // A face with four corners that need not be coplanar: two triangles.
  auto quad = [&](const glm::dvec3& a, const glm::dvec3& q, const glm::dvec3& r, const glm::dvec3& s) {
    b.Face({a, q, r});
    b.Face({a, r, s});
  };
  quad(b0, b3, b2, b1);
  quad(b0, b1, e1, e0);
  quad(b2, b3, e3, e2);
  quad(e0, e1, r1, r0);
  quad(e2, e3, r0, r1);
  if (hip == 0.0) {
    quad(b3, b0, e0, e3);
    b.Face({e3, e0, r0});
    quad(b1, b2, e2, e1);
    b.Face({e1, e2, r1});
  } else {
    quad(b3, b0, e0, e3);
    quad(b1, b2, e2, e1);
    b.Face({e3, e0, r0});
    b.Face({e1, e2, r1});
  }
  return b.solid();
}

// The oracle: tests/solid_oracle.h (InsideSolid, PointIn), sharing no code with the synthesis.

// Every prism: `samples` random points inside it lie inside the solid or at or below the
// ground. Returns the number that do not.
int PointsOutside(const SolidMesh& solid, const OccluderSynthesis& r, double ground_z, uint64_t seed,
                  int samples = 2000) {
  Rng rng(seed);
  int outside = 0;
  for (const Occluder25D& o : r.occluders) {
    for (int i = 0; i < samples; ++i) {
      const glm::dvec2 xy = testing::PointIn(o.footprint, &rng);
      const double z = rng.Uniform(0.0, o.height);
      if (z <= ground_z + 1e-9) continue;
      if (!testing::InsideSolid(solid, glm::dvec3(xy, z), &rng)) {
        if (outside++ == 0) {
          ADD_FAILURE() << "(" << xy.x << ", " << xy.y << ", " << z << ") of a prism to " << o.height
                        << " is outside the solid";
        }
      }
    }
  }
  return outside;
}

double TotalArea(const OccluderSynthesis& r, double height_lo = -INFINITY, double height_hi = INFINITY) {
  double a = 0.0;
  for (const Occluder25D& o : r.occluders) {
    if (o.height >= height_lo && o.height <= height_hi) a += SignedArea(o.footprint);
  }
  return a;
}

void ExpectCcwSimple(const OccluderSynthesis& r) {
  for (const Occluder25D& o : r.occluders) {
    EXPECT_GE(o.footprint.size(), 3u);
    EXPECT_GT(SignedArea(o.footprint), 0.0);
  }
}

TEST(OccluderSynthesis, BoxIsItsFootprintToItsTop) {
  const SolidMesh box = Box({0, 0, 0}, {10, 8, 12});
  const OccluderSynthesis r = SynthesizeOccluders(box, 0.0);
  ASSERT_EQ(r.defect, SolidDefect::kNone);
  ASSERT_EQ(r.occluders.size(), 1u);
  EXPECT_EQ(r.occluders[0].height, 12.0);
  EXPECT_DOUBLE_EQ(SignedArea(r.occluders[0].footprint), 80.0);
  EXPECT_EQ(r.occluders[0].footprint.size(), 4u);
  EXPECT_DOUBLE_EQ(r.solid_volume_m3, 960.0);
  EXPECT_DOUBLE_EQ(r.occluder_volume_m3, 960.0);
  EXPECT_EQ(PointsOutside(box, r, 0.0, 1), 0);
  // Orientation does not matter.
  SolidMesh flipped = box;
  for (auto& t : flipped.triangles) std::swap(t[1], t[2]);
  flipped.triangles[0] = box.triangles[0];
  EXPECT_DOUBLE_EQ(SynthesizeOccluders(flipped, 0.0).occluder_volume_m3, 960.0);
}

TEST(OccluderSynthesis, GabledHouseEavesTierThenNarrowerStrips) {
  const SolidMesh house = House(10, 8, {0, 0, 0, 0}, 6, 9);
  const OccluderSynthesis r = SynthesizeOccluders(house, 0.0);
  ASSERT_EQ(r.defect, SolidDefect::kNone);
  ExpectCcwSimple(r);
  std::vector<double> heights;
  for (const Occluder25D& o : r.occluders) heights.push_back(o.height);
  std::sort(heights.begin(), heights.end());
  heights.erase(std::unique(heights.begin(), heights.end()), heights.end());
  ASSERT_EQ(heights.size(), 4u);
  EXPECT_NEAR(heights[0], 6.0, 1e-9);
  EXPECT_NEAR(TotalArea(r, heights[0], heights[0]), 80.0, 1e-9);
  // The best three more levels for a roof whose section shrinks linearly: a quarter of the
  // rise apart, strips 6, 4 and 2 m wide along the ridge.
  for (int i = 1; i < 4; ++i) {
    EXPECT_NEAR(heights[i], 6.0 + 0.75 * i, 1e-9);
    EXPECT_NEAR(TotalArea(r, heights[i], heights[i]), 80.0 - 20.0 * i, 1e-6);
    for (const Occluder25D& o : r.occluders) {
      if (o.height != heights[i]) continue;
      for (const glm::dvec2& p : o.footprint) EXPECT_LE(std::abs(p.y - 4.0), 4.0 - i + 1e-6);
    }
  }
  EXPECT_NEAR(r.solid_volume_m3, 80.0 * 6 + 0.5 * 8 * 3 * 10, 1e-9);
  EXPECT_NEAR(r.occluder_volume_m3, 80.0 * 6 + (60 + 40 + 20) * 0.75, 1e-6);
  EXPECT_EQ(PointsOutside(house, r, 0.0, 2), 0);
  // One tier: the eaves.
  const OccluderSynthesis one = SynthesizeOccluders(house, 0.0, {.max_tiers = 1});
  ASSERT_EQ(one.occluders.size(), 1u);
  EXPECT_NEAR(one.occluders[0].height, 6.0, 1e-9);
}

TEST(OccluderSynthesis, TowerOnPodiumGivesTwoTiers) {
  const SolidMesh s = BoxUnion({{{0, 0, 0}, {20, 20, 5}}, {{6, 6, 5}, {14, 14, 30}}});
  const OccluderSynthesis r = SynthesizeOccluders(s, 0.0);
  ASSERT_EQ(r.defect, SolidDefect::kNone);
  ExpectCcwSimple(r);
  EXPECT_NEAR(TotalArea(r, 5.0, 5.0), 400.0, 1e-9);
  EXPECT_NEAR(TotalArea(r, 30.0, 30.0), 64.0, 1e-9);
  EXPECT_NEAR(TotalArea(r), 464.0, 1e-9);
  EXPECT_DOUBLE_EQ(r.solid_volume_m3, 400.0 * 5 + 64.0 * 25);
  EXPECT_DOUBLE_EQ(r.occluder_volume_m3, r.solid_volume_m3);
  EXPECT_EQ(PointsOutside(s, r, 0.0, 3), 0);
  // The same as separate boxes, the tower standing on the podium's roof.
  SolidBuilder b;
  AddBox(&b, {0, 0, 0}, {20, 20, 5});
  AddBox(&b, {6, 6, 5}, {14, 14, 30});
  const OccluderSynthesis stacked = SynthesizeOccluders(b.solid(), 0.0);
  ASSERT_EQ(stacked.defect, SolidDefect::kNone);
  EXPECT_DOUBLE_EQ(stacked.occluder_volume_m3, r.solid_volume_m3);
  EXPECT_EQ(PointsOutside(b.solid(), stacked, 0.0, 4), 0);
}

TEST(OccluderSynthesis, FloatingBoxIsRaised) {
  const OccluderSynthesis r = SynthesizeOccluders(Box({0, 0, 4}, {10, 10, 8}), 0.0);
  EXPECT_EQ(r.defect, SolidDefect::kRaised);
  EXPECT_TRUE(r.occluders.empty());
  EXPECT_DOUBLE_EQ(r.solid_volume_m3, 400.0);
  EXPECT_STREQ(SolidDefectName(r.defect), "raised above the ground");
  // With the ground up at its floor it stands on it.
  EXPECT_EQ(SynthesizeOccluders(Box({0, 0, 4}, {10, 10, 8}), 4.0).defect, SolidDefect::kNone);
}

TEST(OccluderSynthesis, OverhangCarriesNoPrism) {
  const SolidMesh s = BoxUnion({{{0, 0, 0}, {10, 6, 3}}, {{0, 0, 3}, {10, 10, 6}}});
  const OccluderSynthesis r = SynthesizeOccluders(s, 0.0);
  ASSERT_EQ(r.defect, SolidDefect::kNone);
  ASSERT_EQ(r.occluders.size(), 1u);
  EXPECT_EQ(r.occluders[0].height, 6.0);
  EXPECT_DOUBLE_EQ(SignedArea(r.occluders[0].footprint), 60.0);
  for (const glm::dvec2& p : r.occluders[0].footprint) EXPECT_LE(p.y, 6.0);
  EXPECT_DOUBLE_EQ(r.solid_volume_m3, 60.0 * 3 + 100.0 * 3);
  EXPECT_EQ(PointsOutside(s, r, 0.0, 5), 0);
}

TEST(OccluderSynthesis, DefectsAreNamed) {
  EXPECT_EQ(SynthesizeOccluders(SolidMesh{}, 0.0).defect, SolidDefect::kEmpty);
  SolidMesh flat;
  flat.vertices = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
  flat.triangles = {{0, 1, 2}, {0, 0, 1}};
  EXPECT_EQ(SynthesizeOccluders(flat, 0.0).defect, SolidDefect::kEmpty);

  // A box without its roof.
  SolidBuilder open;
  open.Face({{0, 0, 0}, {0, 10, 0}, {10, 10, 0}, {10, 0, 0}});
  open.Face({{0, 0, 0}, {10, 0, 0}, {10, 0, 5}, {0, 0, 5}});
  open.Face({{10, 10, 0}, {0, 10, 0}, {0, 10, 5}, {10, 10, 5}});
  open.Face({{0, 10, 0}, {0, 0, 0}, {0, 0, 5}, {0, 10, 5}});
  open.Face({{10, 0, 0}, {10, 10, 0}, {10, 10, 5}, {10, 0, 5}});
  const OccluderSynthesis r = SynthesizeOccluders(open.solid(), 0.0);
  EXPECT_EQ(r.defect, SolidDefect::kOpen);
  EXPECT_STREQ(SolidDefectName(r.defect), "open");
  EXPECT_TRUE(r.occluders.empty());

  // Two boxes through each other in one soup.
  SolidBuilder two;
  AddBox(&two, {0, 0, 0}, {10, 10, 10});
  AddBox(&two, {5, 5, 0}, {15, 15, 8});
  const OccluderSynthesis x = SynthesizeOccluders(two.solid(), 0.0);
  EXPECT_EQ(x.defect, SolidDefect::kSelfIntersecting);
  EXPECT_TRUE(x.occluders.empty());
  // A pyramid poking its tip through a slab's roof from below.
  SolidBuilder poke;
  AddBox(&poke, {0, 0, 0}, {10, 10, 2});
  poke.Face({{3, 3, 1}, {7, 3, 1}, {5, 5, 3}});
  poke.Face({{7, 3, 1}, {7, 7, 1}, {5, 5, 3}});
  poke.Face({{7, 7, 1}, {3, 7, 1}, {5, 5, 3}});
  poke.Face({{3, 7, 1}, {3, 3, 1}, {5, 5, 3}});
  poke.Face({{3, 3, 1}, {3, 7, 1}, {7, 7, 1}, {7, 3, 1}});
  EXPECT_EQ(SynthesizeOccluders(poke.solid(), 0.0).defect, SolidDefect::kSelfIntersecting);
  // Touching is not crossing: two boxes side by side sharing part of a wall.
  SolidBuilder side;
  AddBox(&side, {0, 0, 0}, {10, 10, 10});
  AddBox(&side, {10, 2, 0}, {14, 6, 4});
  const OccluderSynthesis s = SynthesizeOccluders(side.solid(), 0.0);
  EXPECT_EQ(s.defect, SolidDefect::kNone);
  EXPECT_NEAR(s.occluder_volume_m3, 1000.0 + 64.0, 1e-9);
}

TEST(OccluderSynthesis, CourtyardLeavesTheHoleOpen) {
  const SolidMesh s = BoxUnion({{{0, 0, 0}, {30, 10, 10}}, {{0, 20, 0}, {30, 30, 10}},
                                {{0, 10, 0}, {10, 20, 10}}, {{20, 10, 0}, {30, 20, 10}}});
  const OccluderSynthesis r = SynthesizeOccluders(s, 0.0);
  ASSERT_EQ(r.defect, SolidDefect::kNone);
  ExpectCcwSimple(r);
  EXPECT_NEAR(TotalArea(r), 800.0, 1e-9);
  for (const Occluder25D& o : r.occluders) {
    EXPECT_EQ(o.height, 10.0);
    EXPECT_FALSE(testing::InsidePolygon(o.footprint, {15, 15}));
  }
  EXPECT_DOUBLE_EQ(r.occluder_volume_m3, 8000.0);
  EXPECT_EQ(PointsOutside(s, r, 0.0, 6), 0);
}

TEST(OccluderSynthesis, BuildingOnASlope) {
  // The floor slopes from 1 m below the ground to the ground: all of it reaches the ground.
  // A flat roof (the ridge at the eaves: its ends are T-junctions on the gable walls' tops).
  const SolidMesh sunk = House(10, 8, {-1, 0, 0, -1}, 10, 10);
  const OccluderSynthesis a = SynthesizeOccluders(sunk, 0.0);
  ASSERT_EQ(a.defect, SolidDefect::kNone);
  EXPECT_NEAR(TotalArea(a), 80.0, 1e-9);
  for (const Occluder25D& o : a.occluders) EXPECT_EQ(o.height, 10.0);
  EXPECT_EQ(PointsOutside(sunk, a, 0.0, 7), 0);

  // From 1 m below to 1 m above: only the half where the floor is under the ground.
  const SolidMesh half = House(10, 8, {-1, 1, 1, -1}, 10, 10);
  const OccluderSynthesis b = SynthesizeOccluders(half, 0.0);
  ASSERT_EQ(b.defect, SolidDefect::kNone);
  EXPECT_NEAR(TotalArea(b), 40.0, 1e-9);
  for (const Occluder25D& o : b.occluders) {
    for (const glm::dvec2& p : o.footprint) EXPECT_LE(p.x, 5.0 + 1e-12);
  }
  EXPECT_NEAR(b.occluder_volume_m3, 400.0, 1e-9);
  EXPECT_EQ(PointsOutside(half, b, 0.0, 8), 0);

  // With terrain: the ground's lowest point under the building is 2 m up.
  const OccluderSynthesis c = SynthesizeOccluders(half, 2.0);
  EXPECT_NEAR(TotalArea(c), 80.0, 1e-9);
  EXPECT_NEAR(c.occluder_volume_m3, 80.0 * 8, 1e-9);
  EXPECT_EQ(PointsOutside(half, c, 2.0, 9), 0);
}

TEST(OccluderSynthesis, TJunctionsStillClose) {
  // The wall y = 0 in two quads; the roof's and the floor's edges along it are not split.
  SolidBuilder b;
  const double x0 = 0, x1 = 10, y0 = 0, y1 = 8, z0 = 0, z1 = 6;
  b.Face({{x0, y0, z0}, {x0, y1, z0}, {x1, y1, z0}, {x1, y0, z0}});
  b.Face({{x0, y0, z1}, {x1, y0, z1}, {x1, y1, z1}, {x0, y1, z1}});
  b.Face({{x0, y0, z0}, {5, y0, z0}, {5, y0, z1}, {x0, y0, z1}});
  b.Face({{5, y0, z0}, {x1, y0, z0}, {x1, y0, z1}, {5, y0, z1}});
  b.Face({{x1, y1, z0}, {x0, y1, z0}, {x0, y1, z1}, {x1, y1, z1}});
  b.Face({{x0, y1, z0}, {x0, y0, z0}, {x0, y0, z1}, {x0, y1, z1}});
  b.Face({{x1, y0, z0}, {x1, y1, z0}, {x1, y1, z1}, {x1, y0, z1}});
  const OccluderSynthesis r = SynthesizeOccluders(b.solid(), 0.0);
  ASSERT_EQ(r.defect, SolidDefect::kNone);
  EXPECT_NEAR(TotalArea(r), 80.0, 1e-12);
  EXPECT_DOUBLE_EQ(r.occluder_volume_m3, 480.0);
  EXPECT_EQ(PointsOutside(b.solid(), r, 0.0, 10), 0);
  // Without the second quad the wall has a hole.
  SolidMesh holed = b.solid();
  holed.triangles.erase(holed.triangles.begin() + 6, holed.triangles.begin() + 8);
  EXPECT_EQ(SynthesizeOccluders(holed, 0.0).defect, SolidDefect::kOpen);
}

TEST(OccluderSynthesis, SolidMeshFromMeshWeldsAndDropsDegenerates) {
  Mesh m;
  AppendConvexPrism(std::vector<glm::dvec2>{{0, 0}, {4, 0}, {4, 3}, {0, 3}}, 0.0, 2.0, &m);
  // A zero-area triangle on top.
  m.positions.push_back({1, 1, 2});
  m.positions.push_back({2, 2, 2});
  m.positions.push_back({3, 3, 2});
  m.normals.resize(m.positions.size(), glm::vec3(0, 0, 1));
  const uint32_t n = static_cast<uint32_t>(m.positions.size());
  m.indices.insert(m.indices.end(), {n - 3, n - 2, n - 1});
  const SolidMesh s = SolidMeshFromMesh(m);
  EXPECT_EQ(s.vertices.size(), 8u + 3u);
  EXPECT_EQ(s.triangles.size(), m.TriangleCount() - 1);
  const OccluderSynthesis r = SynthesizeOccluders(s, 0.0);
  EXPECT_EQ(r.defect, SolidDefect::kNone);
  EXPECT_DOUBLE_EQ(r.occluder_volume_m3, 24.0);
}

// A few hundred random solids: stacks of boxes with overhangs (one closed mesh, or boxes
// standing on each other), and turned houses with gabled and hipped roofs over uneven floors.
TEST(OccluderSynthesis, RandomSolidsPrismsStayInside) {
  Rng rng(20240611);
  int solids = 0, with_occluders = 0, outside = 0;
  double solid_volume = 0.0, occluder_volume = 0.0;
  for (int i = 0; i < 300; ++i) {
    SolidMesh s;
    double ground = 0.0;
    if (i % 3 != 2) {
      std::vector<Cuboid> boxes;
      const int n = 1 + static_cast<int>(rng.Below(4));
      double z = 0.0;
      for (int k = 0; k < n; ++k) {
        auto coord = [&](double lo, double hi) { return std::round(rng.Uniform(lo, hi) * 4) / 4; };
        const double x0 = coord(0, 10), y0 = coord(0, 10);
        const double x1 = x0 + coord(1, 10), y1 = y0 + coord(1, 10);
        const double top = z + coord(1, 10);
        boxes.push_back({{x0, y0, k == 0 || rng.Uniform() < 0.3 ? 0.0 : z}, {x1, y1, top}});
        z = top;
      }
      if (i % 3 == 0) {
        s = BoxUnion(boxes);
      } else {
        // Each box standing on the previous one where they overlap (or overhanging beside it).
        SolidBuilder b;
        for (size_t k = 0; k < boxes.size(); ++k) {
          Cuboid c = boxes[k];
          if (k > 0) c.lo.z = boxes[k - 1].hi.z;
          if (k > 0) {
            // Keep it inside the one below in x and y so that the soup does not cross itself.
            c.lo.x = std::max(c.lo.x, boxes[k - 1].lo.x);
            c.lo.y = std::max(c.lo.y, boxes[k - 1].lo.y);
            c.hi.x = std::min(c.hi.x, boxes[k - 1].hi.x);
            c.hi.y = std::min(c.hi.y, boxes[k - 1].hi.y);
            if (c.lo.x >= c.hi.x || c.lo.y >= c.hi.y) break;
          }
          boxes[k] = c;
          AddBox(&b, c.lo, c.hi);
        }
        s = b.solid();
      }
    } else {
      const double w = rng.Uniform(4, 20), d = rng.Uniform(4, 12);
      const std::array<double, 4> floor = {rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1),
                                           rng.Uniform(-1, 1)};
      const double eaves = rng.Uniform(2, 12);
      const double ridge = eaves + rng.Uniform(0.5, 6);
      const double hip = rng.Uniform() < 0.5 ? 0.0 : rng.Uniform(0.5, 0.45 * std::min(w, d));
      s = House(w, d, floor, eaves, ridge, hip, rng.Uniform(0, 2 * std::numbers::pi),
                rng.UniformPoint(-300, 300, -300, 300));
      ground = rng.Uniform(-0.5, 0.5);
    }
    const OccluderSynthesis r = SynthesizeOccluders(s, ground);
    ASSERT_TRUE(r.defect == SolidDefect::kNone || r.defect == SolidDefect::kRaised)
        << "solid " << i << ": " << SolidDefectName(r.defect);
    ++solids;
    with_occluders += !r.occluders.empty();
    solid_volume += r.solid_volume_m3;
    occluder_volume += r.occluder_volume_m3;
    ExpectCcwSimple(r);
    EXPECT_LE(r.occluder_volume_m3, r.solid_volume_m3 * (1 + 1e-9) + 1e-9) << "solid " << i;
    outside += PointsOutside(s, r, ground, 100 + static_cast<uint64_t>(i));
  }
  EXPECT_EQ(outside, 0);
  EXPECT_GT(with_occluders, solids / 2);
  std::printf("random solids: %d, %d with occluders, occluder volume %.1f%% of the solids'\n", solids,
              with_occluders, 100.0 * occluder_volume / solid_volume);
}

// city1's buildings are boxes and stacks of three boxes: the synthesis should find the
// scene's own prisms again.
TEST(OccluderSynthesis, City1RecoversTheGeneratorsPrisms) {
  const Scene city = GenerateTestCity(true, 1);
  // The generator's occluders of one building are nested (each tier inside the one below), so
  // their union's volume is the sum of area times the rise over the tier below.
  std::vector<std::vector<const Occluder25D*>> own(city.objects.size());
  for (const Occluder25D& o : city.occluders) own[o.object].push_back(&o);
  double want = 0.0, got = 0.0;
  int defects = 0;
  double seconds = 0.0;
  for (const Object& obj : city.objects) {
    auto& tiers = own[obj.id];
    std::sort(tiers.begin(), tiers.end(), [](auto* a, auto* b) { return a->height < b->height; });
    double below = 0.0;
    for (const Occluder25D* o : tiers) {
      want += SignedArea(o->footprint) * (o->height - below);
      below = o->height;
    }
    const auto start = std::chrono::steady_clock::now();
    const OccluderSynthesis r = SynthesizeOccluders(SolidMeshFromMesh(obj.mesh), 0.0);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    defects += r.defect != SolidDefect::kNone;
    got += r.occluder_volume_m3;
    if (obj.id % 97 == 0) {
      EXPECT_EQ(PointsOutside(SolidMeshFromMesh(obj.mesh), r, 0.0, obj.id, 200), 0);
    }
  }
  EXPECT_EQ(defects, 0);
  EXPECT_GE(got, 0.95 * want);
  EXPECT_LE(got, want * (1 + 1e-9));
  std::printf("city1: %zu buildings, occluder volume %.4f%% of the generator's, %.2f ms per solid\n",
              city.objects.size(), 100.0 * got / want, 1e3 * seconds / static_cast<double>(city.objects.size()));
}

// --- Terrain -------------------------------------------------------------------------------

struct Tin {
  int n;
  double cell;
  std::vector<std::array<glm::dvec3, 3>> triangles;
  std::function<double(double, double)> height;
};

// An n x n grid of cells, each split into two triangles; heights from `f` at the grid points.
Tin GridTin(int n, double cell, const std::function<double(double, double)>& f) {
  Tin t{n, cell, {}, nullptr};
  auto p = [&](int i, int j) { return glm::dvec3(i * cell, j * cell, f(i * cell, j * cell)); };
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      t.triangles.push_back({p(i, j), p(i + 1, j), p(i + 1, j + 1)});
      t.triangles.push_back({p(i, j), p(i + 1, j + 1), p(i, j + 1)});
    }
  }
  // The surface's height: the plane of the triangle that holds (x, y).
  t.height = [f, cell](double x, double y) {
    const int i = static_cast<int>(std::floor(x / cell)), j = static_cast<int>(std::floor(y / cell));
    const double u = x / cell - i, v = y / cell - j;
    const double h00 = f(i * cell, j * cell), h10 = f((i + 1) * cell, j * cell),
                 h11 = f((i + 1) * cell, (j + 1) * cell), h01 = f(i * cell, (j + 1) * cell);
    return u >= v ? h00 + u * (h10 - h00) + v * (h11 - h10) : h00 + v * (h01 - h00) + u * (h11 - h01);
  };
  return t;
}

void ExpectTerrainPrismsBelowSurface(const Tin& tin, const std::vector<Occluder25D>& occ, uint64_t seed) {
  Rng rng(seed);
  int above = 0;
  for (const Occluder25D& o : occ) {
    EXPECT_GT(SignedArea(o.footprint), 0.0);
    for (int i = 0; i < 200; ++i) {
      const glm::dvec2 p = testing::PointIn(o.footprint, &rng);
      const double z = rng.Uniform(0.0, o.height);
      if (z > tin.height(p.x, p.y) + 1e-9) ++above;
    }
    // The top itself, at the footprint's corners.
    for (const glm::dvec2& p : o.footprint) {
      const glm::dvec2 q = glm::clamp(p, glm::dvec2(0.0), glm::dvec2(tin.n * tin.cell * (1 - 1e-12)));
      EXPECT_LE(o.height, tin.height(q.x, q.y) + 1e-9);
    }
  }
  EXPECT_EQ(above, 0);
}

TEST(OccluderSynthesis, TerrainSlopeStaysBelowTheSurface) {
  const Tin tin = GridTin(32, 5.0, [](double x, double y) { return 10.0 + 0.3 * x + 0.1 * y; });
  const std::vector<Occluder25D> occ = TerrainOccluders(tin.triangles, 1.0, 16);
  ASSERT_FALSE(occ.empty());
  EXPECT_LT(occ.size(), tin.triangles.size());
  std::vector<double> levels;
  for (const Occluder25D& o : occ) {
    levels.push_back(o.height);
    EXPECT_EQ(o.height, std::floor(o.height));  // multiples of the quantum
  }
  std::sort(levels.begin(), levels.end());
  EXPECT_LE(std::unique(levels.begin(), levels.end()) - levels.begin(), 16);
  ExpectTerrainPrismsBelowSurface(tin, occ, 11);
  std::printf("sloped TIN: %zu triangles, %zu occluders\n", tin.triangles.size(), occ.size());
}

TEST(OccluderSynthesis, TerrainBumpsStayBelowTheSurface) {
  const Tin tin = GridTin(32, 4.0, [](double x, double y) {
    return 6.0 + 3.0 * std::sin(x / 9.0) * std::cos(y / 7.0) + 0.05 * x;
  });
  const auto start = std::chrono::steady_clock::now();
  const std::vector<Occluder25D> occ = TerrainOccluders(tin.triangles, 0.5, 16);
  const double ms = 1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_FALSE(occ.empty());
  EXPECT_LT(occ.size(), tin.triangles.size());
  ExpectTerrainPrismsBelowSurface(tin, occ, 12);
  std::printf("bumpy TIN: %zu triangles, %zu occluders, %.1f ms\n", tin.triangles.size(), occ.size(), ms);
  // Below z = 0 nothing stands.
  const Tin sunk = GridTin(4, 4.0, [](double, double) { return -1.0; });
  EXPECT_TRUE(TerrainOccluders(sunk.triangles).empty());
}

}  // namespace
}  // namespace vistream::scenes
