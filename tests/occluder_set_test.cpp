#include "visibility/occluder_set.h"

#include <algorithm>
#include <vector>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include "scenes/osm_import.h"
#include "scenes/progress.h"
#include "tests/test_util.h"

namespace vistream::visibility {
namespace {

// Does the box meet the convex polygon (counter-clockwise)? No axis of the box or edge of the
// polygon separates them.
bool BoxMeetsPolygon(const PieceBounds& b, const std::vector<glm::dvec2>& poly) {
  glm::dvec2 lo(INFINITY), hi(-INFINITY);
  for (const glm::dvec2& p : poly) lo = glm::min(lo, p), hi = glm::max(hi, p);
  if (b.max.x < lo.x || b.min.x > hi.x || b.max.y < lo.y || b.min.y > hi.y) return false;
  for (size_t k = 0; k < poly.size(); ++k) {
    const glm::dvec2 &p = poly[k], &q = poly[(k + 1) % poly.size()];
    bool outside = true;
    for (const glm::dvec2 c : {b.min, b.max, glm::dvec2(b.min.x, b.max.y), glm::dvec2(b.max.x, b.min.y)}) {
      outside &= (q.x - p.x) * (c.y - p.y) - (q.y - p.y) * (c.x - p.x) < 0;
    }
    if (outside) return false;
  }
  return true;
}

// Gather skips whole grid cells by their bounds; it must still return every piece that meets
// the hull and that `keep` keeps, each once, and nothing that `keep` rejects.
TEST(OccluderSet, GatherReturnsEveryKeptPieceInTheHullOnce) {
  int expected_total = 0, skipped_by_keep = 0;
  for (uint64_t seed = 1; seed <= 60; ++seed) {
    scenes::Rng rng(seed);
    const scenes::Scene s = testing::RandomGridScene(rng);
    const OccluderSet set = OccluderSet::Build(s, /*grid_cell_m=*/4.0 + rng.Below(12));
    GatherScratch scratch;
    for (int q = 0; q < 8; ++q) {
      // A random thin quadrilateral like a shaft, and a monotone test: tall enough and
      // meeting a random box.
      const glm::dvec2 a(rng.Uniform(0, 30), rng.Uniform(-40, 50)), b(rng.Uniform(50, 90), rng.Uniform(-40, 50));
      const double wa = rng.Uniform(0.5, 15), wb = rng.Uniform(0.5, 30);
      const std::vector<glm::dvec2> hull = {{a.x, a.y - wa}, {b.x, b.y - wb}, {b.x, b.y + wb}, {a.x, a.y + wa}};
      const double min_height = rng.Uniform(0, 25);
      const PieceBounds region{{rng.Uniform(0, 60), rng.Uniform(-40, 40)}, {0, 0}, 0};
      const glm::dvec2 region_max = region.min + glm::dvec2(rng.Uniform(5, 60), rng.Uniform(5, 60));
      auto keep = [&](const PieceBounds& p) {
        return p.height > min_height && p.max.x >= region.min.x && p.min.x <= region_max.x &&
               p.max.y >= region.min.y && p.min.y <= region_max.y;
      };
      std::vector<uint32_t> got;
      set.Gather(hull, keep, &scratch, &got);
      std::vector<uint32_t> sorted = got;
      std::sort(sorted.begin(), sorted.end());
      ASSERT_EQ(std::adjacent_find(sorted.begin(), sorted.end()), sorted.end()) << "seed " << seed << ": a piece twice";
      for (uint32_t id : got) ASSERT_TRUE(keep(set.bounds(id))) << "seed " << seed << ": piece " << id;
      for (uint32_t id = 0; id < set.pieces().size(); ++id) {
        if (!BoxMeetsPolygon(set.bounds(id), hull)) continue;
        if (!keep(set.bounds(id))) {
          ++skipped_by_keep;
          continue;
        }
        ++expected_total;
        ASSERT_TRUE(std::binary_search(sorted.begin(), sorted.end(), id)) << "seed " << seed << ": missed piece " << id;
      }
    }
  }
  // Both kinds of piece were met often enough for the test to mean something.
  EXPECT_GT(expected_total, 200);
  EXPECT_GT(skipped_by_keep, 200);
}

TEST(OccluderSet, BoundsMatchThePieces) {
  scenes::Rng rng(7);
  const scenes::Scene s = testing::RandomGridScene(rng);
  const OccluderSet set = OccluderSet::Build(s);
  ASSERT_FALSE(set.pieces().empty());
  for (uint32_t id = 0; id < set.pieces().size(); ++id) {
    const OccluderPiece& p = set.pieces()[id];
    EXPECT_EQ(set.bounds(id).height, p.height);
    for (const glm::dvec2& w : p.points) {
      EXPECT_TRUE(w.x >= set.bounds(id).min.x && w.x <= set.bounds(id).max.x && w.y >= set.bounds(id).min.y &&
                  w.y <= set.bounds(id).max.y);
    }
  }
}

// Terraced houses from OpenStreetMap (three houses sharing party walls through shared nodes):
// their occluders touch along whole walls, so they fuse into one blocker.
TEST(OccluderSet, ImportedTerraceTouchesAlongItsPartyWalls) {
  const absl::StatusOr<scenes::Scene> scene =
      scenes::ImportOsm(std::string(VISTREAM_SOURCE_DIR) + "/tests/osm/terrace.osm", {});
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_EQ(scene->objects.size(), 3u);
  const OccluderSet set = OccluderSet::Build(*scene);
  // A wall's worth of contact (a segment, not a corner) between each pair of neighbours.
  double wall[3][3] = {};
  for (const PieceContact& c : set.contacts()) {
    const scenes::ObjectId a = set.pieces()[c.a].object, b = set.pieces()[c.b].object;
    if (a == b) continue;
    wall[a][b] = wall[b][a] = std::max(wall[a][b], glm::length(c.w1 - c.w0));
  }
  EXPECT_GT(wall[0][1], 15.0);  // the houses are 0.0002 degrees (22 m) deep
  EXPECT_GT(wall[1][2], 15.0);
  EXPECT_EQ(wall[0][2], 0.0);   // not neighbours
}

}  // namespace
}  // namespace vistream::visibility
