#include "scenes/occluder_tiers.h"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_2_algorithms.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numbers>
#include <unordered_map>

#include <glm/geometric.hpp>

#include "scenes/mesh.h"
#include "scenes/polygon.h"

namespace vistream::scenes {

namespace {

using Ik = CGAL::Exact_predicates_inexact_constructions_kernel;

int Orient(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  return static_cast<int>(
      CGAL::orientation(Ik::Point_2(a.x, a.y), Ik::Point_2(b.x, b.y), Ik::Point_2(c.x, c.y)));
}

// A directed edge by its two points' bits (-0 is made +0 before any key is taken).
struct EdgeKey {
  glm::dvec2 a, b;
  bool operator==(const EdgeKey& o) const { return a == o.a && b == o.b; }
};
struct EdgeKeyHash {
  size_t operator()(const EdgeKey& k) const {
    uint64_t h = 0x9e3779b97f4a7c15ull;
    for (const double d : {k.a.x, k.a.y, k.b.x, k.b.y}) {
      h ^= std::bit_cast<uint64_t>(d) + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2);
    }
    return static_cast<size_t>(h);
  }
};

// Convex (straight vertices allowed, no spikes), counter-clockwise, winding once.
bool ConvexCcw(const std::vector<glm::dvec2>& p) {
  const size_t n = p.size();
  if (n < 3) return false;
  double turning = 0.0;
  bool some_left = false;
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2 &a = p[(i + n - 1) % n], &b = p[i], &c = p[(i + 1) % n];
    const int o = Orient(a, b, c);
    if (o < 0) return false;
    const glm::dvec2 u = b - a, w = c - b;
    if (o == 0 && glm::dot(u, w) <= 0.0) return false;  // a spike or a repeated point
    some_left |= o > 0;
    turning += std::atan2(u.x * w.y - u.y * w.x, glm::dot(u, w));
  }
  // All turns are left or straight: the polygon winds once when they add up to one full turn
  // (twice or more for a star), far from the rounding of atan2.
  return some_left && turning < 3.0 * std::numbers::pi;
}

std::vector<glm::dvec2> WithoutStraightVertices(std::vector<glm::dvec2> p) {
  for (bool changed = true; changed && p.size() > 3;) {
    changed = false;
    for (size_t i = 0; i < p.size() && p.size() > 3; ++i) {
      const size_t n = p.size();
      if (Orient(p[(i + n - 1) % n], p[i], p[(i + 1) % n]) == 0) {
        p.erase(p.begin() + static_cast<std::ptrdiff_t>(i));
        changed = true;
        --i;
      }
    }
  }
  return p;
}

}  // namespace

std::vector<size_t> ChooseTierLevels(std::span<const double> levels, std::span<const double> areas,
                                     double base, int max_tiers) {
  const size_t n = levels.size();
  if (n == 0 || max_tiers < 1) return {};
  const size_t tiers = std::min(n, static_cast<size_t>(max_tiers));
  // best[j][i]: the most volume with j + 1 levels, the highest being i; from[j][i]: the one
  // below it.
  std::vector<std::vector<double>> best(tiers, std::vector<double>(n, -1.0));
  std::vector<std::vector<size_t>> from(tiers, std::vector<size_t>(n, n));
  for (size_t i = 0; i < n; ++i) best[0][i] = areas[i] * (levels[i] - base);
  for (size_t j = 1; j < tiers; ++j) {
    for (size_t i = j; i < n; ++i) {
      for (size_t k = j - 1; k < i; ++k) {
        if (best[j - 1][k] < 0.0) continue;
        const double v = best[j - 1][k] + areas[i] * (levels[i] - levels[k]);
        if (v > best[j][i]) {
          best[j][i] = v;
          from[j][i] = k;
        }
      }
    }
  }
  size_t bj = 0, bi = 0;
  double bv = -1.0;
  for (size_t j = 0; j < tiers; ++j) {
    for (size_t i = 0; i < n; ++i) {
      // A level more must earn its place: ties (a level where the area does not change) and
      // rounding noise keep the fewer levels.
      if (best[j][i] > bv * (1.0 + 1e-9) + 1e-12) {
        bv = best[j][i];
        bj = j;
        bi = i;
      }
    }
  }
  std::vector<size_t> chosen;
  for (size_t j = bj + 1, i = bi; j-- > 0;) {
    chosen.push_back(i);
    i = from[j][i];
  }
  std::reverse(chosen.begin(), chosen.end());
  return chosen;
}

std::vector<std::vector<glm::dvec2>> MergeConvexPieces(std::vector<std::vector<glm::dvec2>> pieces) {
  // Clean: +0 for -0, no repeated points, simple and counter-clockwise or gone.
  std::vector<std::vector<glm::dvec2>> poly;
  poly.reserve(pieces.size());
  for (std::vector<glm::dvec2>& p : pieces) {
    for (glm::dvec2& q : p) q += glm::dvec2(0.0);
    Ring r = std::move(p);
    CleanRing(&r);
    if (!IsSimpleRing(r) || SignedArea(r) <= 0.0) continue;
    poly.push_back(std::move(r));
  }
  const size_t n = poly.size();
  std::vector<bool> alive(n, true), convex(n);
  for (size_t i = 0; i < n; ++i) convex[i] = ConvexCcw(poly[i]);
  std::unordered_map<EdgeKey, size_t, EdgeKeyHash> owner;
  owner.reserve(4 * n);
  auto for_edges = [&](size_t i, auto&& f) {
    const std::vector<glm::dvec2>& p = poly[i];
    for (size_t k = 0; k < p.size(); ++k) f(EdgeKey{p[k], p[(k + 1) % p.size()]});
  };
  for (size_t i = 0; i < n; ++i) for_edges(i, [&](const EdgeKey& e) { owner.emplace(e, i); });

  for (bool changed = true; changed;) {
    changed = false;
    for (size_t i = 0; i < n; ++i) {
      for (size_t e = 0; alive[i] && e < poly[i].size(); ++e) {
        const std::vector<glm::dvec2>& p = poly[i];
        const glm::dvec2 a = p[e], b = p[(e + 1) % p.size()];
        const auto it = owner.find(EdgeKey{b, a});
        if (it == owner.end()) continue;
        const size_t j = it->second;
        if (j == i || !alive[j]) continue;
        const std::vector<glm::dvec2>& q = poly[j];
        const size_t np = p.size(), nq = q.size();
        size_t f = 0;
        while (f < nq && !(q[f] == b && q[(f + 1) % nq] == a)) ++f;
        if (f == nq) continue;
        // The whole shared chain (a straight vertex of one lies on the other's boundary as a
        // vertex too): p[ps..ps+m] is q[qs..qs+m] backwards.
        size_t ps = e, qs = f, m = 1;
        while (m + 1 < std::min(np, nq) && p[(ps + m + 1) % np] == q[(qs + nq - 1) % nq]) {
          qs = (qs + nq - 1) % nq;
          ++m;
        }
        while (m + 1 < std::min(np, nq) && p[(ps + np - 1) % np] == q[(qs + m + 1) % nq]) {
          ps = (ps + np - 1) % np;
          ++m;
        }
        // Two convex pieces on either side of their shared chain: the union is convex when
        // it turns left (or goes straight on) where the chain was, at both of its ends.
        auto turns_left = [](const glm::dvec2& x, const glm::dvec2& y, const glm::dvec2& z) {
          const int o = Orient(x, y, z);
          return o > 0 || (o == 0 && glm::dot(y - x, z - y) > 0.0);
        };
        if (convex[i] && convex[j] &&
            !(turns_left(q[(qs + nq - 1) % nq], p[(ps + m) % np], p[(ps + m + 1) % np]) &&
              turns_left(p[(ps + np - 1) % np], p[ps], q[(qs + m + 1) % nq]))) {
          continue;
        }
        // p from the chain's end around to its start, then q past the chain.
        std::vector<glm::dvec2> merged;
        merged.reserve(np + nq - 2 * m);
        for (size_t k = m; k <= np; ++k) merged.push_back(p[(ps + k) % np]);
        for (size_t k = m + 1; k < nq; ++k) merged.push_back(q[(qs + k) % nq]);
        if (!(convex[i] && convex[j]) && !ConvexCcw(merged)) continue;
        for (const size_t x : {i, j}) {
          for_edges(x, [&](const EdgeKey& k) {
            const auto o = owner.find(k);
            if (o != owner.end() && o->second == x) owner.erase(o);
          });
        }
        poly[i] = std::move(merged);
        poly[j].clear();
        alive[j] = false;
        convex[i] = true;
        for_edges(i, [&](const EdgeKey& k) { owner.emplace(k, i); });
        changed = true;
        e = static_cast<size_t>(-1);  // the piece changed: walk its edges again
      }
    }
  }
  std::vector<std::vector<glm::dvec2>> out;
  for (size_t i = 0; i < n; ++i) {
    if (alive[i]) out.push_back(WithoutStraightVertices(std::move(poly[i])));
  }
  return out;
}

}  // namespace vistream::scenes
