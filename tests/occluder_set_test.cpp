#include "visibility/occluder_set.h"

#include <algorithm>
#include <cmath>
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
      scenes::ImportOsm(std::string(VISTREAM_SOURCE_DIR "/tests/osm/terrace.osm"), {});
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

// Whether some contact of pieces a and b reaches into the closed strip lo <= w[axis] <= hi:
// the question the fuse step of a planar query asks (there along its separating axis).
bool SomeContactMeetsStrip(const OccluderSet& set, uint32_t a, uint32_t b, int axis, double lo, double hi) {
  const auto contacts = set.ContactsOf(a);
  const auto others = set.ContactOthersOf(a);
  for (size_t m = 0; m < contacts.size(); ++m) {
    if (others[m] != b) continue;
    const PieceContact& c = set.contacts()[contacts[m]];
    if (std::max(std::min(c.w0[axis], c.w1[axis]), lo) <= std::min(std::max(c.w0[axis], c.w1[axis]), hi)) return true;
  }
  return false;
}

// Random strips along x and y, some with an edge on `coords` (vertex coordinates) or of no
// width, so that a contact that only touches a strip's edge is tested too.
template <typename Check>
void ForRandomStrips(scenes::Rng& rng, const std::vector<double>& coords, double lo_bound, double hi_bound,
                     Check&& check) {
  for (int k = 0; k < 24; ++k) {
    const int axis = k % 2;
    double lo = rng.Uniform(lo_bound, hi_bound);
    if (rng.Chance(0.5)) lo = coords[rng.Below(coords.size())];
    const double hi = rng.Chance(0.3) ? lo : lo + rng.Uniform(0, 0.3 * (hi_bound - lo_bound));
    check(axis, lo, hi);
  }
}

// A guillotine partition of a rectangle into rectangles with integer corners: neighbours
// share a wall or a corner and never overlap, so two pieces meet exactly in the intersection
// of their (closed, exact) boxes. Every strip that intersection reaches into, some contact of
// the pair reaches into too, and no strip that it misses: the fuse step sees the pieces'
// connection wherever it survives a clip, even with each pair's contacts pruned to a few.
TEST(OccluderSet, ContactsOfAPartitionReachEveryStripTheSharedWallReaches) {
  int touching = 0, strips_met = 0, strips_missed = 0;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    scenes::Rng rng(seed);
    struct Rect {
      double x0, y0, x1, y1;
    };
    std::vector<Rect> todo = {{0, 0, 40, 40}}, done;
    while (!todo.empty()) {
      const Rect r = todo.back();
      todo.pop_back();
      const bool along_x = r.x1 - r.x0 >= r.y1 - r.y0;
      const double len = along_x ? r.x1 - r.x0 : r.y1 - r.y0;
      if (len < 2 || (len < 10 && rng.Chance(0.4))) {
        done.push_back(r);
        continue;
      }
      const double cut = (along_x ? r.x0 : r.y0) + 1 + static_cast<double>(rng.Below(static_cast<uint64_t>(len) - 1));
      todo.push_back(along_x ? Rect{r.x0, r.y0, cut, r.y1} : Rect{r.x0, r.y0, r.x1, cut});
      todo.push_back(along_x ? Rect{cut, r.y0, r.x1, r.y1} : Rect{r.x0, cut, r.x1, r.y1});
    }
    scenes::Scene s;
    for (const Rect& r : done) {
      s.occluders.push_back({{{r.x0, r.y0}, {r.x1, r.y0}, {r.x1, r.y1}, {r.x0, r.y1}}, 10.0, 0});
    }
    const OccluderSet set = OccluderSet::Build(s, /*grid_cell_m=*/8.0);
    ASSERT_EQ(set.pieces().size(), done.size());
    std::vector<double> coords;
    for (const Rect& r : done) coords.insert(coords.end(), {r.x0, r.y0, r.x1, r.y1});
    for (uint32_t a = 0; a < set.pieces().size(); ++a) {
      for (uint32_t b = a + 1; b < set.pieces().size(); ++b) {
        const PieceBounds &ba = set.bounds(a), &bb = set.bounds(b);
        const glm::dvec2 lo = glm::max(ba.min, bb.min), hi = glm::min(ba.max, bb.max);
        if (lo.x > hi.x || lo.y > hi.y) {
          ASSERT_FALSE(SomeContactMeetsStrip(set, a, b, 0, -1e9, 1e9)) << "seed " << seed << ": apart, yet in contact";
          continue;
        }
        ++touching;
        ForRandomStrips(rng, coords, -2, 42, [&](int axis, double s0, double s1) {
          const bool meets = std::max(lo[axis], s0) <= std::min(hi[axis], s1);
          (meets ? strips_met : strips_missed)++;
          ASSERT_EQ(SomeContactMeetsStrip(set, a, b, axis, s0, s1), meets)
              << "seed " << seed << ": pieces " << a << ", " << b << ", strip " << s0 << ".." << s1 << " along " << axis;
        });
      }
    }
  }
  EXPECT_GT(touching, 300);
  EXPECT_GT(strips_met, 1000);
  EXPECT_GT(strips_missed, 1000);
}

// A star-shaped footprint in general position is cut into convex pieces; two of them meet
// exactly in the hull of their shared vertices (a diagonal, a vertex, or nothing), and the
// contacts reach exactly the strips that hull reaches, though the pieces around a vertex
// meet there through many pairs of edges.
TEST(OccluderSet, ContactsOfAPartitionedFootprintReachEveryStripTheSharedVerticesReach) {
  int sharing = 0, strips_met = 0;
  for (uint64_t seed = 1; seed <= 40; ++seed) {
    scenes::Rng rng(seed);
    const int n = 8 + static_cast<int>(rng.Below(24));
    std::vector<double> angles(n);
    for (double& t : angles) t = rng.Uniform(0, 6.283185307179586);
    std::sort(angles.begin(), angles.end());
    scenes::Occluder25D footprint{{}, 12.0, 0};
    for (double t : angles) {
      const double r = rng.Uniform(3, 20);
      footprint.footprint.push_back({100.0 + r * std::cos(t), -50.0 + r * std::sin(t)});
    }
    scenes::Scene s;
    s.occluders.push_back(footprint);
    const OccluderSet set = OccluderSet::Build(s, /*grid_cell_m=*/6.0);
    if (set.pieces().size() < 3) continue;  // convex after all, or not simple
    std::vector<double> coords;
    for (const glm::dvec2& p : footprint.footprint) coords.insert(coords.end(), {p.x, p.y});
    for (uint32_t a = 0; a < set.pieces().size(); ++a) {
      ASSERT_TRUE(scenes::IsConvexCcw(set.pieces()[a].points)) << "seed " << seed << ": piece " << a;
      for (uint32_t b = a + 1; b < set.pieces().size(); ++b) {
        glm::dvec2 lo(INFINITY), hi(-INFINITY);
        for (const glm::dvec2& p : set.pieces()[a].points) {
          const auto& q = set.pieces()[b].points;
          if (std::find(q.begin(), q.end(), p) != q.end()) lo = glm::min(lo, p), hi = glm::max(hi, p);
        }
        if (lo.x > hi.x) {
          ASSERT_FALSE(SomeContactMeetsStrip(set, a, b, 0, -1e9, 1e9)) << "seed " << seed << ": apart, yet in contact";
          continue;
        }
        ++sharing;
        ForRandomStrips(rng, coords, 75, 125, [&](int axis, double s0, double s1) {
          const bool meets = std::max(lo[axis], s0) <= std::min(hi[axis], s1);
          strips_met += meets;
          ASSERT_EQ(SomeContactMeetsStrip(set, a, b, axis, s0, s1), meets)
              << "seed " << seed << ": pieces " << a << ", " << b << ", strip " << s0 << ".." << s1 << " along " << axis;
        });
      }
    }
  }
  EXPECT_GT(sharing, 500);
  EXPECT_GT(strips_met, 1000);
}

// Each pair's contacts are pruned: none lies within the box of another of the same pair
// (it would answer no strip differently). A fan of triangles around a vertex would otherwise
// record that vertex once for every pair of edges that meet there.
TEST(OccluderSet, NoContactLiesWithinAnotherOfTheSamePair) {
  scenes::Scene s;
  std::vector<glm::dvec2> comb;  // a comb: many reflex corners, many convex pieces
  for (int k = 0; k < 24; ++k) comb.insert(comb.end(), {{4.0 * k, 0.0}, {4.0 * k + 2, 0.0}, {4.0 * k + 2, 9.0 + k % 3}, {4.0 * k + 3, 9.0}});
  comb.push_back({96.0, -5.0});
  comb.push_back({0.0, -5.0});
  std::reverse(comb.begin(), comb.end());
  s.occluders.push_back({comb, 8.0, 0});
  scenes::Rng rng(3);
  scenes::Scene grid = testing::RandomGridScene(rng);
  s.occluders.insert(s.occluders.end(), grid.occluders.begin(), grid.occluders.end());
  const OccluderSet set = OccluderSet::Build(s);
  ASSERT_GT(set.pieces().size(), 30u);
  ASSERT_GT(set.contacts().size(), 30u);
  for (uint32_t a = 0; a < set.pieces().size(); ++a) {
    const auto contacts = set.ContactsOf(a);
    const auto others = set.ContactOthersOf(a);
    for (size_t x = 0; x < contacts.size(); ++x) {
      const PieceContact& cx = set.contacts()[contacts[x]];
      const glm::dvec2 lx = glm::min(cx.w0, cx.w1), hx = glm::max(cx.w0, cx.w1);
      for (size_t y = 0; y < contacts.size(); ++y) {
        if (y == x || others[y] != others[x]) continue;
        const PieceContact& cy = set.contacts()[contacts[y]];
        const glm::dvec2 ly = glm::min(cy.w0, cy.w1), hy = glm::max(cy.w0, cy.w1);
        EXPECT_FALSE(ly.x <= lx.x && ly.y <= lx.y && hx.x <= hy.x && hx.y <= hy.y)
            << "pieces " << a << ", " << others[x] << ": contact (" << lx.x << ", " << lx.y << ")-(" << hx.x << ", "
            << hx.y << ") within (" << ly.x << ", " << ly.y << ")-(" << hy.x << ", " << hy.y << ")";
      }
    }
  }
}

// Every point's owner is the lowest-numbered piece that holds the very same point, found here
// by brute force: the fused groups' hulls read a shared vertex from its owner only.
TEST(OccluderSet, EachPointsOwnerIsTheFirstPieceHoldingIt) {
  scenes::Scene s;
  std::vector<glm::dvec2> comb;  // a comb: its convex pieces share vertices
  for (int k = 0; k < 16; ++k) comb.insert(comb.end(), {{4.0 * k, 0.0}, {4.0 * k + 2, 0.0}, {4.0 * k + 2, 9.0}, {4.0 * k + 3, 9.0}});
  comb.push_back({64.0, -5.0});
  comb.push_back({0.0, -5.0});
  s.occluders.push_back({comb, 8.0, 0});
  scenes::Rng rng(5);
  const scenes::Scene grid = testing::RandomGridScene(rng);  // neighbours share corners
  s.occluders.insert(s.occluders.end(), grid.occluders.begin(), grid.occluders.end());
  const OccluderSet set = OccluderSet::Build(s);
  int shared = 0;
  for (uint32_t id = 0; id < set.pieces().size(); ++id) {
    const auto points = set.PointsOf(id);
    const auto owners = set.PointOwnersOf(id);
    ASSERT_EQ(owners.size(), points.size());
    for (size_t k = 0; k < points.size(); ++k) {
      uint32_t first = id;
      for (uint32_t other = 0; other < id && first == id; ++other) {
        const auto q = set.PointsOf(other);
        if (std::find(q.begin(), q.end(), points[k]) != q.end()) first = other;
      }
      EXPECT_EQ(owners[k], first) << "piece " << id << ", point " << k;
      shared += first != id;
    }
  }
  EXPECT_GT(shared, 40);  // the comb's pieces alone share dozens
}

// Pieces are stored along a space-filling curve, not in the scene's order: a grid of houses
// listed in shuffled order comes out with neighbours mostly next to each other, which keeps
// a shaft's pieces close together in memory.
TEST(OccluderSet, PiecesAreStoredInSpatialOrder) {
  scenes::Scene s;
  for (int j = 0; j < 32; ++j) {
    for (int i = 0; i < 32; ++i) {
      const double x = 10.0 * i, y = 10.0 * j;
      s.occluders.push_back({{{x, y}, {x + 6, y}, {x + 6, y + 6}, {x, y + 6}}, 5.0, 0});
    }
  }
  scenes::Rng rng(11);
  for (size_t k = s.occluders.size(); k > 1; --k) std::swap(s.occluders[k - 1], s.occluders[rng.Below(k)]);
  const OccluderSet set = OccluderSet::Build(s);
  ASSERT_EQ(set.pieces().size(), 1024u);
  // On a Z-order curve 3 steps in 4 go to a house next door, diagonals included (at most
  // 14.2 m); in shuffled order fewer than 1 in 100 do.
  int next_door = 0;
  for (size_t k = 1; k < set.pieces().size(); ++k) {
    next_door += glm::length(set.pieces()[k].box_min - set.pieces()[k - 1].box_min) <= 14.2;
  }
  EXPECT_GE(next_door, 700);
}

}  // namespace
}  // namespace vistream::visibility
