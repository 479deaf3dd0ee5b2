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
  absl::StatusOr<Scene> cancelled = GenerateNamed("london", GeneratorParams{}, &cancel);
  ASSERT_FALSE(cancelled.ok());
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
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
