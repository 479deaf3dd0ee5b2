#include "visibility/convex_partition.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "scenes/mesh.h"
#include "scenes/polygon.h"
#include "scenes/random.h"

namespace vistream::visibility {
namespace {

std::vector<glm::dvec2> PiecePoints(const std::vector<glm::dvec2>& poly, const std::vector<int>& piece) {
  std::vector<glm::dvec2> pts;
  for (int k : piece) pts.push_back(poly[k]);
  return pts;
}

// A star-shaped polygon around (cx, cy) on a 1/16 m lattice: n vertices in angle order
// (rounding to the lattice may leave it not simple: callers check).
std::vector<glm::dvec2> RandomStar(scenes::Rng& rng, int n, double cx, double cy) {
  std::vector<double> angles(n);
  for (double& t : angles) t = rng.Uniform(0, 6.283185307179586);
  std::sort(angles.begin(), angles.end());
  std::vector<glm::dvec2> poly;
  for (double t : angles) {
    const double r = rng.Uniform(3, 20);
    const glm::dvec2 p(std::round(16 * r * std::cos(t)) / 16, std::round(16 * r * std::sin(t)) / 16);
    if (poly.empty() || p != poly.back()) poly.push_back(p + glm::dvec2(cx, cy));
  }
  return poly;
}

// A comb of `teeth` teeth 2 m wide with 2 m gaps, on a 5 m back: 2 reflex corners a gap.
std::vector<glm::dvec2> Comb(int teeth) {
  std::vector<glm::dvec2> comb = {{0.0, -5.0}, {4.0 * teeth, -5.0}};
  for (int k = teeth; k-- > 0;) comb.insert(comb.end(), {{4.0 * k + 2, 0.0}, {4.0 * k + 2, 9.0}, {4.0 * k, 9.0}, {4.0 * k, 0.0}});
  comb.pop_back();  // (0, 0) lies on the edge from (0, 9) to (0, -5)
  return comb;
}

// The partition's promises, checked on `poly`: every piece convex and counter-clockwise on
// the polygon's own vertices, the areas adding up to the polygon's, every vertex used, and
// no two pieces that share an edge mergeable into one convex piece (Hertel-Mehlhorn: each
// diagonal left is needed), so at most 2r + 1 pieces for r reflex vertices.
void ExpectConvexPartition(const std::vector<glm::dvec2>& poly, const std::vector<std::vector<int>>& pieces) {
  ASSERT_FALSE(pieces.empty());
  double area = 0;
  std::vector<int> used(poly.size(), 0);
  for (const std::vector<int>& piece : pieces) {
    const std::vector<glm::dvec2> pts = PiecePoints(poly, piece);
    ASSERT_GE(pts.size(), 3u);
    EXPECT_TRUE(scenes::IsConvexCcw(pts));
    EXPECT_GT(scenes::SignedArea(pts), 0.0);
    area += scenes::SignedArea(pts);
    for (int k : piece) used[k] = 1;
  }
  EXPECT_NEAR(area, scenes::SignedArea(poly), 1e-9 * std::abs(scenes::SignedArea(poly)));
  EXPECT_EQ(std::count(used.begin(), used.end(), 1), static_cast<long>(poly.size()));
  for (size_t a = 0; a < pieces.size(); ++a) {
    for (size_t b = 0; b < pieces.size(); ++b) {
      const std::vector<int>&pa = pieces[a], &pb = pieces[b];
      for (size_t i = 0; i < pa.size(); ++i) {
        const int u = pa[i], v = pa[(i + 1) % pa.size()];
        for (size_t j = 0; j < pb.size(); ++j) {
          if (pb[j] != v || pb[(j + 1) % pb.size()] != u) continue;
          // pa: ..., u, v, ...; pb: ..., v, u, ...: merged, the corners at u and at v.
          const int before_u = pa[(i + pa.size() - 1) % pa.size()], after_u = pb[(j + 2) % pb.size()];
          const int before_v = pb[(j + pb.size() - 1) % pb.size()], after_v = pa[(i + 2) % pa.size()];
          EXPECT_TRUE(Orient(poly[before_u], poly[u], poly[after_u]) < 0 ||
                      Orient(poly[before_v], poly[v], poly[after_v]) < 0)
              << "pieces " << a << " and " << b << " would merge across " << u << "-" << v;
        }
      }
    }
  }
  size_t reflex = 0;
  for (size_t k = 0; k < poly.size(); ++k) {
    reflex += Orient(poly[(k + poly.size() - 1) % poly.size()], poly[k], poly[(k + 1) % poly.size()]) < 0;
  }
  EXPECT_LE(pieces.size(), 2 * reflex + 1);
}

TEST(ConvexPartition, AConvexPolygonIsOnePiece) {
  // A square with a straight vertex on its bottom edge.
  const std::vector<glm::dvec2> square = {{0, 0}, {5, 0}, {10, 0}, {10, 10}, {0, 10}};
  const auto pieces = ConvexPartition(square);
  ASSERT_EQ(pieces.size(), 1u);
  EXPECT_EQ(pieces[0].size(), 5u);
  ExpectConvexPartition(square, pieces);
}

TEST(ConvexPartition, AnLIsTwoPiecesAndACombOnePerToothAndTheBack) {
  const std::vector<glm::dvec2> l = {{0, 0}, {10, 0}, {10, 4}, {4, 4}, {4, 10}, {0, 10}};
  const auto pieces = ConvexPartition(l);
  EXPECT_EQ(pieces.size(), 2u);
  ExpectConvexPartition(l, pieces);
  // Ear clipping alone makes 4 triangles a tooth; here a tooth is one piece, the back one.
  const std::vector<glm::dvec2> comb = Comb(12);
  const auto comb_pieces = ConvexPartition(comb);
  ExpectConvexPartition(comb, comb_pieces);
  EXPECT_EQ(comb_pieces.size(), 13u);
}

TEST(ConvexPartition, RandomStarPolygonsKeepOnlyNeededDiagonals) {
  int non_convex = 0;
  for (uint64_t seed = 1; seed <= 200; ++seed) {
    scenes::Rng rng(seed);
    const std::vector<glm::dvec2> poly = RandomStar(rng, 5 + static_cast<int>(rng.Below(40)), 100.0, -50.0);
    if (!scenes::IsSimpleRing(poly)) continue;
    const auto pieces = ConvexPartition(poly);
    SCOPED_TRACE(::testing::Message() << "seed " << seed);
    ExpectConvexPartition(poly, pieces);
    non_convex += !scenes::IsConvexCcw(poly);
  }
  EXPECT_GT(non_convex, 150);
}

TEST(ConvexPartition, ASelfCrossingPolygonHasNone) {
  EXPECT_TRUE(ConvexPartition(std::vector<glm::dvec2>{{0, 0}, {4, 4}, {8, 0}, {8, 4}, {4, 0}, {0, 4}}).empty());
}

// Far from the origin (UTM metres) the same lattice polygon, translated exactly, is cut into
// the same pieces: every decision is an exact orientation.
TEST(ConvexPartition, TranslatingThePolygonGivesTheSamePieces) {
  for (uint64_t seed = 1; seed <= 50; ++seed) {
    scenes::Rng rng(seed);
    const std::vector<glm::dvec2> poly = RandomStar(rng, 8 + static_cast<int>(rng.Below(30)), 0.0, 0.0);
    std::vector<glm::dvec2> far = poly;
    for (glm::dvec2& p : far) p += glm::dvec2(500000.0, 5000000.0);
    EXPECT_EQ(ConvexPartition(poly), ConvexPartition(far)) << "seed " << seed;
  }
}

}  // namespace
}  // namespace vistream::visibility
