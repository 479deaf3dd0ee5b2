#include "visibility/convex_partition.h"

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <unordered_map>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

namespace vistream::visibility {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;

bool IsEar(std::span<const glm::dvec2> poly, const std::vector<int>& idx, size_t i) {
  const size_t n = idx.size();
  const glm::dvec2 &a = poly[idx[(i + n - 1) % n]], &b = poly[idx[i]], &c = poly[idx[(i + 1) % n]];
  if (Orient(a, b, c) <= 0) return false;
  for (size_t k = 0; k < n; ++k) {
    if (k == i || k == (i + n - 1) % n || k == (i + 1) % n) continue;
    const glm::dvec2& p = poly[idx[k]];
    if (Orient(a, b, p) >= 0 && Orient(b, c, p) >= 0 && Orient(c, a, p) >= 0) return false;
  }
  return true;
}

// Ear clipping of a simple counter-clockwise polygon; empty when the polygon is not simple.
std::vector<std::vector<int>> Triangulate(std::span<const glm::dvec2> poly) {
  std::vector<int> idx(poly.size());
  std::iota(idx.begin(), idx.end(), 0);
  std::vector<std::vector<int>> tris;
  while (idx.size() > 3) {
    bool clipped = false;
    for (size_t i = 0; i < idx.size(); ++i) {
      if (!IsEar(poly, idx, i)) continue;
      const size_t n = idx.size();
      tris.push_back({idx[(i + n - 1) % n], idx[i], idx[(i + 1) % n]});
      idx.erase(idx.begin() + static_cast<long>(i));
      clipped = true;
      break;
    }
    if (!clipped) return {};
  }
  tris.push_back({idx[0], idx[1], idx[2]});
  return tris;
}

}  // namespace

int Orient(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  const auto o = CGAL::orientation(Kernel::Point_2(a.x, a.y), Kernel::Point_2(b.x, b.y), Kernel::Point_2(c.x, c.y));
  return o == CGAL::LEFT_TURN ? 1 : (o == CGAL::RIGHT_TURN ? -1 : 0);
}

std::vector<std::vector<int>> ConvexPartition(std::span<const glm::dvec2> poly) {
  std::vector<std::vector<int>> pieces = Triangulate(poly);
  if (pieces.size() <= 1) return pieces;
  // The piece left of each directed edge (a, b); a diagonal is an edge both ways round.
  const auto key = [&](int a, int b) { return static_cast<uint64_t>(a) * poly.size() + static_cast<uint64_t>(b); };
  std::unordered_map<uint64_t, int> left_of;
  for (int p = 0; p < static_cast<int>(pieces.size()); ++p) {
    const std::vector<int>& v = pieces[p];
    for (size_t k = 0; k < v.size(); ++k) left_of[key(v[k], v[(k + 1) % v.size()])] = p;
  }
  // Piece p absorbs its neighbours across diagonals while both ends of the diagonal stay
  // convex. Merging only widens angles, so a diagonal kept once is kept for good: each
  // piece's edges are scanned until none merges, in the order of the ear clipping.
  std::vector<int> merged;
  for (int p = 0; p < static_cast<int>(pieces.size()); ++p) {
    std::vector<int>& v = pieces[p];
    for (size_t k = 0; k < v.size();) {
      const size_t n = v.size();
      const int a = v[k], b = v[(k + 1) % n];
      const auto across = left_of.find(key(b, a));
      if (across == left_of.end()) {
        ++k;
        continue;
      }
      std::vector<int>& w = pieces[across->second];
      const size_t m = w.size();
      const size_t wb = static_cast<size_t>(std::find(w.begin(), w.end(), b) - w.begin());  // w: ..., b, a, ...
      const int p_before_a = v[(k + n - 1) % n], p_after_b = v[(k + 2) % n];
      const int w_after_a = w[(wb + 2) % m], w_before_b = w[(wb + m - 1) % m];
      if (Orient(poly[p_before_a], poly[a], poly[w_after_a]) < 0 || Orient(poly[w_before_b], poly[b], poly[p_after_b]) < 0) {
        ++k;
        continue;
      }
      // v from b round to a, then w's vertices strictly between a and b.
      merged.clear();
      for (size_t s = 0; s < n; ++s) merged.push_back(v[(k + 1 + s) % n]);
      for (size_t s = 2; s < m; ++s) merged.push_back(w[(wb + s) % m]);
      left_of.erase(key(a, b));
      left_of.erase(key(b, a));
      for (size_t s = 0; s < m; ++s) {
        const auto e = left_of.find(key(w[s], w[(s + 1) % m]));
        if (e != left_of.end()) e->second = p;
      }
      w.clear();
      v.swap(merged);
      k = 0;
    }
  }
  std::erase_if(pieces, [](const std::vector<int>& v) { return v.empty(); });
  return pieces;
}

}  // namespace vistream::visibility
