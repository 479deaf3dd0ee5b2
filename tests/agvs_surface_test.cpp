#include "visibility/agvs_surface.h"

#include <array>
#include <vector>

#include <gtest/gtest.h>

#include "scenes/random.h"

namespace vistream::visibility::agvs_detail {
namespace {

// A right triangle at the origin with legs a along x and b along y: |e1 x e2| = a b.
EdgeTriangle Right(float a, float b) { return {glm::vec3(0.0f), glm::vec3(a, 0, 0), glm::vec3(0, b, 0)}; }

// Object 0: two triangles, |e1 x e2| 2 and 6; object 1: one triangle; object 2: deleted (no
// triangles given); object 3: a triangle without area. Objects 0 and 1 each get half the
// picks, object 0's half shared 1 : 3 by area.
struct Fixture {
  std::array<EdgeTriangle, 2> first{Right(1, 2), Right(3, 2)};
  std::array<EdgeTriangle, 1> second{Right(50, 50)};
  std::array<EdgeTriangle, 1> flat{EdgeTriangle{glm::vec3(0.0f), glm::vec3(1, 0, 0), glm::vec3(2, 0, 0)}};
  std::vector<std::span<const EdgeTriangle>> objects{first, second, {}, flat};
};

TEST(AgvsSurfaceTable, PicksAUniformObjectThenATriangleByArea) {
  Fixture f;
  const SurfaceTable table(f.objects);
  ASSERT_EQ(table.size(), 3u);  // the deleted and the flat object have no entry
  constexpr size_t kPicks = 200000;
  scenes::Rng rng(11);
  std::vector<double> xs(kPicks);
  for (double& x : xs) x = rng.Uniform() * static_cast<double>(table.size());
  std::vector<uint32_t> picks(kPicks);
  table.PickMany(xs, picks);
  // Share of picks per (object, |e1 x e2|).
  double share_small = 0, share_large = 0, share_second = 0;
  for (uint32_t p : picks) {
    ASSERT_LT(p, table.size());
    const SurfaceTable::Entry& e = table[p];
    const double weight = glm::length(glm::cross(glm::dvec3(e.tri.e1), glm::dvec3(e.tri.e2)));
    if (e.object == 0 && weight == 2.0) share_small += 1.0 / kPicks;
    else if (e.object == 0 && weight == 6.0) share_large += 1.0 / kPicks;
    else if (e.object == 1) share_second += 1.0 / kPicks;
    else FAIL() << "picked entry " << p << " of object " << e.object;
  }
  // Standard deviation of a share: at most sqrt(0.25 / 200000) = 0.0011.
  EXPECT_NEAR(share_small, 0.125, 0.006);
  EXPECT_NEAR(share_large, 0.375, 0.006);
  EXPECT_NEAR(share_second, 0.5, 0.006);
}

TEST(AgvsSurfaceTable, PickingManyAtOncePicksWhatPickingEachInTurnDoes) {
  Fixture f;
  const SurfaceTable table(f.objects);
  scenes::Rng rng(5);
  std::vector<double> xs(4096);
  for (double& x : xs) x = rng.Uniform() * static_cast<double>(table.size());
  xs.front() = 0.0;
  xs.back() = std::nextafter(static_cast<double>(table.size()), 0.0);  // the last column's end
  std::vector<uint32_t> picks(xs.size());
  table.PickMany(xs, picks);
  for (size_t i = 0; i < xs.size(); ++i) ASSERT_EQ(picks[i], table.Pick(xs[i])) << "x = " << xs[i];
}

TEST(AgvsSurfaceTable, NoObjectWithAreaGivesAnEmptyTable) {
  const std::array<EdgeTriangle, 1> flat{EdgeTriangle{glm::vec3(0.0f), glm::vec3(1, 0, 0), glm::vec3(2, 0, 0)}};
  const std::vector<std::span<const EdgeTriangle>> objects{{}, flat};
  EXPECT_TRUE(SurfaceTable(objects).empty());
}

}  // namespace
}  // namespace vistream::visibility::agvs_detail
