#include "visibility/free_line_pool.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "tests/dual_ray_space_test_util.h"
#include "tests/test_util.h"
#include "visibility/dual_ray_space.h"

namespace vistream::visibility {
namespace {

using test_queries::ForEachRandomQuery;
using test_queries::kCell;
using test_queries::RandomQuery;
using vistream::testing::Box;
using vistream::testing::Rect;

glm::dvec2 Direction(double degrees) {
  const double r = degrees * std::numbers::pi / 180;
  return {std::cos(r), std::sin(r)};
}

// One line a degree, at 0.5, 1.5, ... degrees (from -179.5 up), through (7, -3), each of its own length.
FreeLinePool OneLineADegree() {
  FreeLinePool pool;
  for (int k = 0; k < 360; ++k) {
    const glm::dvec2 from(7, -3);
    pool.Add(FreeLine{from, from + (1.0 + k) * Direction(-179.5 + k), true});
  }
  return pool;
}

double DegreesOf(const FreeLine& line) {
  const glm::dvec2 d = line.to - line.from;
  return std::atan2(d.y, d.x) * 180 / std::numbers::pi;
}

// The candidates of the cone from `d0` to `d1` degrees (either way round), as angles.
std::vector<double> ConeDegrees(const FreeLinePool& pool, double d0, double d1, std::vector<uint32_t>* indices) {
  indices->clear();
  pool.Candidates(2.0 * Direction(d0), 5.0 * Direction(d1), indices);
  std::vector<double> out;
  for (uint32_t i : *indices) out.push_back(DegreesOf(pool.line(i)));
  return out;
}

TEST(FreeLinePool, CandidatesHoldEveryLineOfTheConeMostRecentFirst) {
  const FreeLinePool pool = OneLineADegree();
  ASSERT_EQ(pool.size(), 360u);
  const double bucket = 360.0 / FreeLinePool::kBuckets;
  std::vector<uint32_t> indices;
  for (const auto& [d0, d1] : {std::pair{10.0, 30.0}, {30.0, 10.0}, {-100.0, -20.0}, {-20.0, -100.0}, {95.0, 96.0}}) {
    const std::vector<double> got = ConeDegrees(pool, d0, d1, &indices);
    const double lo = std::min(d0, d1), hi = std::max(d0, d1);
    for (double a = -179.5; a < 180; a += 1) {
      const bool in = std::find_if(got.begin(), got.end(), [&](double g) { return std::abs(g - a) < 1e-9; }) != got.end();
      if (a >= lo && a <= hi) {
        EXPECT_TRUE(in) << a << " missing from the cone " << d0 << ".." << d1;
      }
      // Only whole buckets are added: nothing farther out than one.
      if (a < lo - bucket || a > hi + bucket) {
        EXPECT_FALSE(in) << a << " is outside the cone " << d0 << ".." << d1;
      }
    }
    EXPECT_TRUE(std::is_sorted(indices.rbegin(), indices.rend())) << "not most recent first";
    EXPECT_TRUE(std::adjacent_find(indices.begin(), indices.end()) == indices.end()) << "a line twice";
  }
}

TEST(FreeLinePool, ACrossTheHalfTurnConeWrapsAround) {
  const FreeLinePool pool = OneLineADegree();
  std::vector<uint32_t> indices;
  for (const auto& [d0, d1] : {std::pair{170.0, -170.0}, {-170.0, 170.0}}) {
    const std::vector<double> got = ConeDegrees(pool, d0, d1, &indices);
    // 170.5 .. 179.5 and -179.5 .. -170.5, and at most a bucket's worth of lines more.
    EXPECT_GE(got.size(), 20u);
    EXPECT_LE(got.size(), 22u);
    for (double g : got) EXPECT_GE(std::abs(g), 169.0) << g;
  }
}

TEST(FreeLinePool, IgnoresInvalidAndPointLinesAndClears) {
  FreeLinePool pool;
  pool.Add(FreeLine{{0, 0}, {1, 0}, false});
  pool.Add(FreeLine{{3, 4}, {3, 4}, true});
  EXPECT_EQ(pool.size(), 0u);
  pool.Add(FreeLine{{0, 0}, {1, 0}, true});
  std::vector<uint32_t> indices;
  pool.Candidates({1, -1}, {1, 1}, &indices);
  EXPECT_EQ(indices, std::vector<uint32_t>{0});
  pool.Clear();
  EXPECT_EQ(pool.size(), 0u);
  indices.clear();
  pool.Candidates({1, -1}, {1, 1}, &indices);
  EXPECT_TRUE(indices.empty());
}

// A wall across the shaft from kCell to B with a slot 0.3 m wide that none of the fixed
// probe rays passes: only the blockers' raster, or a line through the slot, shows B.
scenes::Scene SlottedWall(const glm::dvec2& shift) {
  scenes::Scene s;
  s.occluders.push_back(Rect(20, -200, 25, 3.0, 30));
  s.occluders.push_back(Rect(20, 3.3, 25, 200, 30));
  for (auto& oc : s.occluders) {
    for (auto& p : oc.footprint) p += shift;
  }
  return s;
}

TEST(DualRaySpace, APoolLineThroughASlotProvesBVisibleWithoutBlockers) {
  for (const glm::dvec2 shift : {glm::dvec2(0.0), glm::dvec2(500000, 5000000)}) {
    const scenes::Scene s = SlottedWall(shift);
    const OccluderSet set = OccluderSet::Build(s);
    DualRaySpace drs(set);
    const glm::dvec3 shift3(shift, 0.0);
    const scenes::Aabb a{kCell.min + shift3, kCell.max + shift3};
    const scenes::Aabb b = Box(50 + shift.x, shift.y, 0, 60 + shift.x, 10 + shift.y, 10);
    // Without a pool the raster finds the slot, from the blockers of the whole shaft.
    CellQueryStats alone;
    EXPECT_TRUE(drs.Visible(a, b, {}, &alone));
    EXPECT_GT(alone.gathered, 0u);
    // It adds the free ray it finds to a pool: the only new line.
    FreeLinePool pool;
    CellQueryStats first;
    FreeLine witness;
    EXPECT_TRUE(drs.Visible(a, b, {}, &first, {}, &witness, &pool));
    ASSERT_EQ(pool.size(), 1u);
    EXPECT_EQ(pool.line(0).from, witness.from);
    // The next query through the slot (a box beyond B) is proven by that line alone.
    const scenes::Aabb far = Box(80 + shift.x, -5 + shift.y, 0, 95 + shift.x, 12 + shift.y, 12);
    CellQueryStats pooled;
    EXPECT_TRUE(drs.Visible(a, far, {}, &pooled, {}, nullptr, &pool));
    EXPECT_EQ(pooled.gathered, 0u) << "shift " << shift.x;
    EXPECT_EQ(pooled.free_rays, 1u);
    EXPECT_EQ(pool.size(), 1u) << "a pool line found again is no new line";
    CellQueryStats unpooled;
    EXPECT_TRUE(drs.Visible(a, far, {}, &unpooled));
    EXPECT_GT(unpooled.gathered, 0u);
  }
}

TEST(DualRaySpace, PoolsNeverChangeAnAnswer) {
  int from_pool = 0;
  ForEachRandomQuery(1, 400, 4, [&](const RandomQuery& r) {
    const bool visible = r.drs.Visible(kCell, r.b, {});
    // Random lines, most of them blocked, then also the lines the query itself finds.
    FreeLinePool pool;
    for (int k = 0; k < 24; ++k) {
      pool.Add(FreeLine{{r.rng.Uniform(-5, 15), r.rng.Uniform(-10, 20)}, {r.rng.Uniform(20, 100), r.rng.Uniform(-40, 60)},
                        true});
    }
    CellQueryStats first, second;
    ASSERT_EQ(visible, r.drs.Visible(kCell, r.b, {}, &first, {}, nullptr, &pool)) << "seed " << r.seed;
    ASSERT_EQ(visible, r.drs.Visible(kCell, r.b, {}, &second, {}, nullptr, &pool)) << "seed " << r.seed;
    // A free ray that needed the blockers the first time is in the pool the second.
    from_pool += visible && first.gathered > 0 && second.gathered == 0;
  });
  EXPECT_GT(from_pool, 40);
}

// The batch skips the fixed probe rays for a node an earlier cell found hidden: the same
// answers, and the blockers decide where the probes would have.
TEST(DualRaySpace, WithoutProbeRaysTheAnswersAreTheSame) {
  CellQueryOptions unprobed;
  unprobed.probe_rays = false;
  int decided_by_blockers = 0, visible_count = 0;
  ForEachRandomQuery(1, 400, 4, [&](const RandomQuery& r) {
    CellQueryStats probed_stats, unprobed_stats;
    const bool visible = r.drs.Visible(kCell, r.b, {}, &probed_stats);
    ASSERT_EQ(visible, r.drs.Visible(kCell, r.b, unprobed, &unprobed_stats)) << "seed " << r.seed;
    visible_count += visible;
    // A query the probes proved visible without blockers needs them without the probes.
    decided_by_blockers += visible && probed_stats.gathered == 0 && probed_stats.free_rays > 0 &&
                           unprobed_stats.gathered > 0;
  });
  EXPECT_GT(visible_count, 40);
  EXPECT_GT(decided_by_blockers, 20);
}

}  // namespace
}  // namespace vistream::visibility
