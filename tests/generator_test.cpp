#include "scenes/city_generator.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

std::map<ObjectId, int> OccludersPerObject(const Scene& s) {
  std::map<ObjectId, int> n;
  for (const Occluder25D& oc : s.occluders) ++n[oc.object];
  return n;
}

// Every directed edge (by position) has its reverse: the mesh is closed and consistently
// oriented.
bool Closed(const Mesh& m) {
  std::map<std::pair<std::array<float, 3>, std::array<float, 3>>, int> edges;
  auto key = [&](uint32_t i) { return std::array<float, 3>{m.positions[i].x, m.positions[i].y, m.positions[i].z}; };
  for (size_t t = 0; t < m.indices.size(); t += 3) {
    for (int k = 0; k < 3; ++k) {
      const auto a = key(m.indices[t + k]), b = key(m.indices[t + (k + 1) % 3]);
      ++edges[{a, b}];
      --edges[{b, a}];
    }
  }
  return std::all_of(edges.begin(), edges.end(), [](const auto& e) { return e.second == 0; });
}

TEST(TestCities, City1And2Have2128BuildingsAQuarterOfThemStacked) {
  for (bool dense : {true, false}) {
    const Scene s = GenerateTestCity(dense, 1);
    EXPECT_EQ(s.name, dense ? "city1" : "city2");
    ASSERT_EQ(s.objects.size(), 2128u);
    int single = 0, stacked = 0;
    for (const auto& [id, n] : OccludersPerObject(s)) {
      single += n == 1;
      stacked += n == 3;
    }
    EXPECT_EQ(single + stacked, 2128);
    EXPECT_EQ(stacked, 532);  // 25%
    // Closed boxes: 12 triangles a box.
    EXPECT_EQ(s.TriangleCount(), static_cast<size_t>(12 * (single + 3 * stacked)));
    EXPECT_TRUE(ValidateScene(s, s.name).ok());
  }
}

TEST(TestCities, City2IsTheSparseOne) {
  const Scene dense = GenerateTestCity(true, 1), sparse = GenerateTestCity(false, 1);
  const glm::dvec3 a = dense.bounds.Extent(), b = sparse.bounds.Extent();
  EXPECT_GT(b.x * b.y, 3.5 * a.x * a.y);
}

TEST(TestCities, BuildingsNeverOverlapAndTiersStandOnTheirBase) {
  const Scene s = GenerateTestCity(true, 5);
  // Ground boxes of different objects are disjoint.
  std::vector<Aabb> ground(s.objects.size());
  for (const Occluder25D& oc : s.occluders) {
    for (const glm::dvec2& p : oc.footprint) ground[oc.object].Extend(glm::dvec3(p, 0.0));
  }
  for (size_t i = 0; i < ground.size(); ++i) {
    for (size_t j = i + 1; j < ground.size(); ++j) {
      ASSERT_FALSE(ground[i].Overlaps(ground[j])) << "objects " << i << " and " << j;
    }
  }
  // Each occluder lies within its object's box.
  for (const Occluder25D& oc : s.occluders) {
    const Aabb& box = s.objects[oc.object].bounds;
    for (const glm::dvec2& p : oc.footprint) EXPECT_TRUE(box.Contains(glm::dvec3(p, 0.0)));
    EXPECT_LE(oc.height, box.max.z + 1e-9);
  }
}

TEST(TestCities, MeshesAreClosed) {
  const Scene s = GenerateTestCity(false, 2);
  for (const Object& o : s.objects) ASSERT_TRUE(Closed(o.mesh)) << o.name;
}

TEST(Generator, SameSeedSameSceneOtherSeedOtherScene) {
  EXPECT_EQ(testing::SceneHash(GenerateTestCity(true, 9)), testing::SceneHash(GenerateTestCity(true, 9)));
  EXPECT_NE(testing::SceneHash(GenerateTestCity(true, 9)), testing::SceneHash(GenerateTestCity(true, 10)));
  LondonOptions small;
  small.width_m = small.depth_m = 1500;
  const uint64_t a = testing::SceneHash(GenerateLondon(small));
  EXPECT_EQ(a, testing::SceneHash(GenerateLondon(small)));
  small.seed = 2;
  EXPECT_NE(a, testing::SceneHash(GenerateLondon(small)));
}

TEST(Generator, NamedGeneratorsCheckTheirParameters) {
  GeneratorParams p;
  EXPECT_TRUE(GenerateNamed("city1", p).ok());
  absl::StatusOr<Scene> unknown = GenerateNamed("paris", p);
  ASSERT_FALSE(unknown.ok());
  EXPECT_NE(unknown.status().message().find("paris"), std::string::npos);
  p.width_m = 100;
  EXPECT_FALSE(GenerateNamed("city1", p).ok());   // fixed size
  EXPECT_FALSE(GenerateNamed("london", p).ok());  // below 200 m
  std::atomic<bool> cancel{true};
  absl::StatusOr<Scene> cancelled = GenerateNamed("london", GeneratorParams{}, {.cancel = &cancel});
  ASSERT_FALSE(cancelled.ok());
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
}

// Signed overlap of convex footprints f and g along the worst separating axis (their edge
// normals): positive when their interiors overlap by that much, zero when they only touch,
// negative when apart.
double ConvexOverlap(const std::vector<glm::dvec2>& f, const std::vector<glm::dvec2>& g) {
  double worst = INFINITY;
  for (const auto* poly : {&f, &g}) {
    for (size_t k = 0; k < poly->size(); ++k) {
      const glm::dvec2 e = (*poly)[(k + 1) % poly->size()] - (*poly)[k];
      const glm::dvec2 n = glm::dvec2(-e.y, e.x) / glm::length(e);
      double f0 = INFINITY, f1 = -INFINITY, g0 = INFINITY, g1 = -INFINITY;
      for (const glm::dvec2& p : f) f0 = std::min(f0, glm::dot(n, p)), f1 = std::max(f1, glm::dot(n, p));
      for (const glm::dvec2& p : g) g0 = std::min(g0, glm::dot(n, p)), g1 = std::max(g1, glm::dot(n, p));
      worst = std::min(worst, std::min(f1, g1) - std::max(f0, g0));
    }
  }
  return worst;
}

// Length of the part of edge [a, b] that lies on edge [c, d] (zero unless collinear).
double SharedLength(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c, const glm::dvec2& d) {
  const glm::dvec2 u = b - a;
  const double len = glm::length(u);
  auto off = [&](const glm::dvec2& p) { return std::abs(u.x * (p.y - a.y) - u.y * (p.x - a.x)) / len; };
  if (off(c) > 1e-6 || off(d) > 1e-6) return 0.0;
  const double t0 = glm::dot(c - a, u) / len, t1 = glm::dot(d - a, u) / len;
  return std::max(0.0, std::min(len, std::max(t0, t1)) - std::max(0.0, std::min(t0, t1)));
}

TEST(Streets, HousesTouchAlongPartyWallsAndNeverOverlap) {
  for (bool snap : {true, false}) {
    StreetsOptions o;
    o.seed = 12;
    o.snap = snap;
    const Scene s = GenerateStreets(o);
    ASSERT_TRUE(ValidateScene(s, "streets").ok());
    EXPECT_GT(s.objects.size(), 150u);
    for (const Object& ob : s.objects) EXPECT_TRUE(Closed(ob.mesh)) << ob.name;
    // The ground-floor footprints (an object's first occluder) of different buildings: none
    // overlaps another, and many share walls.
    std::map<ObjectId, const Occluder25D*> base;
    for (const Occluder25D& oc : s.occluders) base.emplace(oc.object, &oc);
    std::map<ObjectId, int> touching;
    size_t party_walls = 0, skewed_walls = 0;
    for (auto i = base.begin(); i != base.end(); ++i) {
      const auto& f = i->second->footprint;
      for (size_t k = 0; k < f.size(); ++k) {
        const glm::dvec2 e = f[(k + 1) % f.size()] - f[k];
        skewed_walls += std::abs(e.x) > 1e-3 && std::abs(e.y) > 1e-3;
      }
      for (auto j = std::next(i); j != base.end(); ++j) {
        const auto& g = j->second->footprint;
        // Snapping to 1/256 m moves a corner that lies inside a neighbour's turned wall (a shed
        // against a house, an end house against a row) and the wall's own corners by up to
        // 3 mm each: the corner may end up to 6 mm inside the wall.
        ASSERT_LE(ConvexOverlap(f, g), 6e-3) << s.objects[i->first].name << " overlaps " << s.objects[j->first].name;
        double shared = 0.0;
        for (size_t a = 0; a < f.size(); ++a) {
          for (size_t b = 0; b < g.size(); ++b) shared += SharedLength(f[a], f[(a + 1) % f.size()], g[b], g[(b + 1) % g.size()]);
        }
        if (shared > 1.0) {
          ++party_walls;
          ++touching[i->first];
          ++touching[j->first];
        }
      }
    }
    EXPECT_GT(party_walls, 200u);
    // End houses of closes touch both rows and the terrace behind them.
    int most = 0;
    for (const auto& [id, n] : touching) most = std::max(most, n);
    EXPECT_GE(most, 3);
    EXPECT_GT(skewed_walls, 100u) << "no block is turned off the axes";
    // Sheds and kiosks lower than eye level (the viewcells' top is 2.5 m).
    EXPECT_TRUE(std::any_of(s.objects.begin(), s.objects.end(), [](const Object& ob) { return ob.bounds.max.z < 2.5; }));
    // Snapped: every coordinate on the 1/256 m grid; unsnapped: most are off it.
    size_t on_grid = 0, coords = 0;
    for (const Occluder25D& oc : s.occluders) {
      for (const glm::dvec2& p : oc.footprint) {
        coords += 2;
        on_grid += (p.x * 256 == std::round(p.x * 256)) + (p.y * 256 == std::round(p.y * 256));
      }
    }
    if (snap) {
      EXPECT_EQ(on_grid, coords);
    } else {
      EXPECT_LT(on_grid, coords / 2);
    }
  }
}

TEST(Streets, SameSeedSameDistrictAndTheSizeIsChecked) {
  const uint64_t a = testing::SceneHash(GenerateStreets({}));
  EXPECT_EQ(a, testing::SceneHash(GenerateStreets({})));
  EXPECT_NE(a, testing::SceneHash(GenerateStreets({.seed = 2})));
  EXPECT_TRUE(GenerateNamed("streets", GeneratorParams{.seed = 3}).ok());
  absl::StatusOr<Scene> tiny = GenerateNamed("streets", GeneratorParams{.width_m = 50});
  ASSERT_FALSE(tiny.ok());
  EXPECT_NE(tiny.status().message().find("between 100 and 5000"), std::string::npos) << tiny.status();
}

class London : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { scene_ = new Scene(GenerateLondon(LondonOptions{})); }
  static void TearDownTestSuite() { delete scene_; }
  static Scene* scene_;
};
Scene* London::scene_ = nullptr;

TEST_F(London, IsLondonSized) {
  const Scene& s = *scene_;
  const glm::dvec3 e = s.bounds.Extent();
  EXPECT_GE(e.x * e.y / 1e6, 160.0);
  EXPECT_GE(s.TriangleCount(), 1'700'000u);
  EXPECT_TRUE(ValidateScene(s, "london").ok());
  // The origin is far from zero: large coordinates are exercised.
  EXPECT_GT(s.origin.y, 1e6);
}

TEST_F(London, LandmarksRiseFarAboveTheSkyline) {
  std::vector<double> heights;
  for (const Object& o : scene_->objects) heights.push_back(o.bounds.max.z);
  std::sort(heights.begin(), heights.end());
  const double median = heights[heights.size() / 2];
  const double p99 = heights[heights.size() * 99 / 100];
  EXPECT_LT(median, 25.0);
  EXPECT_GE(heights.back(), 200.0);
  // At least twenty towers above 120 m, more than twice the 99th percentile's height or not.
  const auto towers = heights.end() - std::lower_bound(heights.begin(), heights.end(), 120.0);
  EXPECT_GE(towers, 20);
  EXPECT_GT(heights.back(), 2.5 * p99);
}

TEST_F(London, StreetsAreIrregularNotOneGrid) {
  // Orientation of each building's first wall, folded to [0°, 90°): a single grid would put
  // nearly every building in one 5° bin.
  std::vector<int> bins(18, 0);
  for (const Occluder25D& oc : scene_->occluders) {
    const glm::dvec2 d = oc.footprint[1] - oc.footprint[0];
    double deg = std::atan2(d.y, d.x) * 180.0 / std::numbers::pi;
    deg = std::fmod(deg + 360.0, 90.0);
    ++bins[std::min(17, static_cast<int>(deg / 5.0))];
  }
  const int total = static_cast<int>(scene_->occluders.size());
  int populated = 0;
  for (int b : bins) populated += b > total / 100;
  EXPECT_GE(populated, 15);
  EXPECT_LT(*std::max_element(bins.begin(), bins.end()), total / 5);
}

TEST_F(London, HasTerracesOfTouchingHouses) {
  // Objects with several ground-standing prisms side by side are terrace rows.
  int rows = 0;
  for (const auto& [id, n] : OccludersPerObject(*scene_)) rows += n >= 3;
  EXPECT_GT(rows, 5000);
}

TEST_F(London, HasOpenSpaceForParksSquaresAndTheRiver) {
  // A coarse 250 m grid over the city: parks, the river and large squares leave some cells
  // wholly empty (about 2.5% with the defaults); a city without open space leaves none.
  const int n = 52;
  std::vector<int> count(n * n, 0);
  const Aabb& b = scene_->bounds;
  for (const Object& o : scene_->objects) {
    const glm::dvec3 c = o.bounds.Centre();
    const int i = std::clamp(static_cast<int>((c.x - b.min.x) / (b.max.x - b.min.x) * n), 0, n - 1);
    const int j = std::clamp(static_cast<int>((c.y - b.min.y) / (b.max.y - b.min.y) * n), 0, n - 1);
    ++count[j * n + i];
  }
  const auto empty = std::count(count.begin(), count.end(), 0);
  EXPECT_GT(empty, n * n * 3 / 200);
  EXPECT_LT(empty, n * n / 2);
}

}  // namespace
}  // namespace vistream::scenes
