#include "scenes/shell_closure.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <unordered_map>
#include <utility>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "scenes/mesh.h"
#include "scenes/polygon.h"
#include "scenes/polygon_set.h"

namespace vistream::scenes {

namespace {

using Tri3 = std::array<glm::dvec3, 3>;
using Ids = std::array<uint32_t, 3>;

// Union-find over point ids.
class Clusters {
 public:
  explicit Clusters(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0u); }
  uint32_t Find(uint32_t i) {
    while (parent_[i] != i) i = parent_[i] = parent_[parent_[i]];
    return i;
  }
  void Join(uint32_t a, uint32_t b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<uint32_t> parent_;
};

struct CellKey {
  int64_t x, y, z;
  bool operator==(const CellKey& o) const { return x == o.x && y == o.y && z == o.z; }
};
struct CellHash {
  size_t operator()(const CellKey& k) const {
    return static_cast<size_t>(k.x * 73856093LL ^ k.y * 19349663LL ^ k.z * 83492791LL);
  }
};

// An xy grid of items with boxes, for near-point queries. An item whose box covers more than
// kMaxCells cells is kept aside and offered to every query, and a query that covers more than
// that is offered every item (a coordinate far off the rest must not cost a cell per metre).
class Grid2 {
 public:
  explicit Grid2(double cell) : cell_(cell) {}
  void Add(uint32_t item, double x0, double y0, double x1, double y1) {
    if (Cells(x0, y0, x1, y1) > kMaxCells) {
      large_.push_back(item);
      return;
    }
    for (int64_t j = Key(y0); j <= Key(y1); ++j) {
      for (int64_t i = Key(x0); i <= Key(x1); ++i) cells_[{i, j, 0}].push_back(item);
    }
  }
  // Calls fn(item) for every item whose box may meet [x0, x1] x [y0, y1] (some more than once).
  template <typename Fn>
  void ForEachNear(double x0, double y0, double x1, double y1, Fn fn) const {
    for (uint32_t item : large_) fn(item);
    if (Cells(x0, y0, x1, y1) > kMaxCells) {
      for (const auto& [key, items] : cells_) {
        for (uint32_t item : items) fn(item);
      }
      return;
    }
    for (int64_t j = Key(y0); j <= Key(y1); ++j) {
      for (int64_t i = Key(x0); i <= Key(x1); ++i) {
        auto it = cells_.find({i, j, 0});
        if (it == cells_.end()) continue;
        for (uint32_t item : it->second) fn(item);
      }
    }
  }

 private:
  static constexpr double kMaxCells = 4096.0;
  // Cells a box covers, in double (no overflow for any finite box).
  double Cells(double x0, double y0, double x1, double y1) const {
    return (std::floor(x1 / cell_) - std::floor(x0 / cell_) + 1.0) * (std::floor(y1 / cell_) - std::floor(y0 / cell_) + 1.0);
  }
  int64_t Key(double v) const { return static_cast<int64_t>(std::floor(v / cell_)); }
  double cell_;
  std::unordered_map<CellKey, std::vector<uint32_t>, CellHash> cells_;
  std::vector<uint32_t> large_;
};

// Triangulates a polygon through 3D points by projecting it on the plane of axis `drop`'s
// normal (0 x, 1 y, 2 z). False when it does not triangulate (crossing, no area).
bool TriangulateProjected(const std::vector<glm::dvec3>& ring3, int drop, std::vector<Tri3>* out) {
  const int u = drop == 0 ? 1 : 0, v = drop == 2 ? 1 : 2;
  std::map<std::pair<double, double>, glm::dvec3> lift;
  PolygonWithHoles poly;
  for (const glm::dvec3& p : ring3) {
    poly.outer.emplace_back(p[u], p[v]);
    if (!lift.emplace(std::make_pair(p[u], p[v]), p).second) return false;  // two corners project together
  }
  CleanRing(&poly.outer);
  if (poly.outer.size() < 3) return false;
  const double area = SignedArea(poly.outer);
  if (area == 0.0) return false;
  if (area < 0.0) std::reverse(poly.outer.begin(), poly.outer.end());
  absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(poly);
  if (!tris.ok()) return false;
  for (const Triangle2& t : *tris) {
    Tri3 t3;
    for (int i = 0; i < 3; ++i) t3[i] = lift.at({t[i].x, t[i].y});
    out->push_back(t3);
  }
  return true;
}

// The axis to drop when projecting a polygon of normal `n` on a coordinate plane: its largest.
int drop_axis(const glm::dvec3& n) {
  const glm::dvec3 an = glm::abs(n);
  return an.z >= an.x && an.z >= an.y ? 2 : (an.y >= an.x ? 1 : 0);
}

// Caps a loop that stands vertically over a path in xy (a party wall with a bend): the loop's
// points, seen from above, go along a path and back within `tol`. The cap is the vertical
// surface over the path: the loop unrolled to (arc length, z), cut into one strip per leg of
// the path, each strip triangulated and rolled back onto its leg. `off` is how far a loop
// point lies from the path. False when the loop is not of that kind.
bool CurtainCap(const std::vector<glm::dvec3>& ring, double tol, std::vector<Tri3>* out, double* off) {
  const size_t n = ring.size();
  if (n < 4) return false;
  auto xy = [](const glm::dvec3& p) { return glm::dvec2(p.x, p.y); };
  // The path's ends: the two points farthest apart in xy.
  size_t ea = 0, eb = 0;
  double far = -1.0;
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = i + 1; j < n; ++j) {
      const double d = glm::distance(xy(ring[i]), xy(ring[j]));
      if (d > far) {
        far = d;
        ea = i;
        eb = j;
      }
    }
  }
  if (!(far > tol)) return false;
  // The path: the points from ea forward to eb, near repeats merged.
  std::vector<glm::dvec2> path;
  for (size_t k = ea;; k = (k + 1) % n) {
    const glm::dvec2 p = xy(ring[k]);
    if (path.empty() || glm::distance(path.back(), p) > tol) path.push_back(p);
    if (k == eb) break;
  }
  if (glm::distance(path.back(), xy(ring[eb])) > 0.0) path.back() = xy(ring[eb]);
  std::vector<double> at(path.size(), 0.0);  // arc length of each path point
  for (size_t i = 1; i < path.size(); ++i) {
    const double leg = glm::distance(path[i - 1], path[i]);
    if (!(leg > 0.0)) return false;
    at[i] = at[i - 1] + leg;
  }
  // Every loop point on the path: its arc length, and how far off it is; the loop's edges
  // along the path too (their quarter points), or the surface over the path does not meet them.
  std::vector<glm::dvec2> unrolled(n);
  *off = 0.0;
  for (size_t k = 0; k < 4 * n; ++k) {
    const double f = (k % 4) / 4.0;
    const glm::dvec2 p = xy(ring[k / 4]) * (1.0 - f) + xy(ring[(k / 4 + 1) % n]) * f;
    double best = std::numeric_limits<double>::infinity(), s = 0.0;
    for (size_t i = 0; i + 1 < path.size(); ++i) {
      const glm::dvec2 d = path[i + 1] - path[i];
      const double u = std::clamp(glm::dot(p - path[i], d) / glm::dot(d, d), 0.0, 1.0);
      const double dist = glm::distance(p, path[i] + d * u);
      if (dist < best) {
        best = dist;
        s = at[i] + u * (at[i + 1] - at[i]);
      }
    }
    if (best > tol) return false;
    *off = std::max(*off, best);
    if (k % 4 == 0) unrolled[k / 4] = glm::dvec2(s, ring[k / 4].z);
  }
  // The unrolled polygon, one strip per leg.
  PolygonWithHoles poly;
  std::map<std::pair<double, double>, glm::dvec3> lift;
  for (size_t k = 0; k < n; ++k) {
    if (!poly.outer.empty() && poly.outer.back() == unrolled[k]) continue;
    poly.outer.push_back(unrolled[k]);
    lift.emplace(std::make_pair(unrolled[k].x, unrolled[k].y), ring[k]);
  }
  CleanRing(&poly.outer);
  if (poly.outer.size() < 3 || !IsSimpleRing(poly.outer)) return false;
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const glm::dvec2& a : poly.outer) {
    lo = std::min(lo, a.y);
    hi = std::max(hi, a.y);
  }
  if (SignedArea(poly.outer) < 0.0) std::reverse(poly.outer.begin(), poly.outer.end());
  const double margin = 1.0 + (hi - lo);
  for (size_t i = 0; i + 1 < path.size(); ++i) {
    std::vector<PolygonWithHoles> outside;
    if (i > 0) outside.push_back({{{at[0] - margin, lo - margin}, {at[i], lo - margin}, {at[i], hi + margin},
                                   {at[0] - margin, hi + margin}}, {}});
    if (i + 2 < path.size()) {
      outside.push_back({{{at[i + 1], lo - margin}, {at.back() + margin, lo - margin},
                          {at.back() + margin, hi + margin}, {at[i + 1], hi + margin}}, {}});
    }
    absl::StatusOr<std::vector<PolygonWithHoles>> strip = outside.empty()
                                                              ? absl::StatusOr<std::vector<PolygonWithHoles>>(
                                                                    std::vector<PolygonWithHoles>{poly})
                                                              : Difference(poly, outside);
    if (!strip.ok()) return false;
    for (const PolygonWithHoles& piece : *strip) {
      absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(piece);
      if (!tris.ok()) return false;
      for (const Triangle2& t : *tris) {
        Tri3 t3;
        for (int c = 0; c < 3; ++c) {
          auto it = lift.find({t[c].x, t[c].y});
          if (it != lift.end()) {
            t3[c] = it->second;
          } else {
            const double u = std::clamp((t[c].x - at[i]) / (at[i + 1] - at[i]), 0.0, 1.0);
            const glm::dvec2 p = path[i] + (path[i + 1] - path[i]) * u;
            t3[c] = glm::dvec3(p.x, p.y, t[c].y);
          }
        }
        out->push_back(t3);
      }
    }
  }
  return true;
}

}  // namespace

const char* ShellClosureName(ShellClosureOutcome outcome) {
  switch (outcome) {
    case ShellClosureOutcome::kNotOpen:
    case ShellClosureOutcome::kClosed:
    case ShellClosureOutcome::kClosedAsBlock:
      return "";
    case ShellClosureOutcome::kOpenToAir:
      return "open to the air";
    case ShellClosureOutcome::kOpeningsTouch:
      return "open: openings touch";
    case ShellClosureOutcome::kCapNotPlanar:
      return "open: opening not planar";
    case ShellClosureOutcome::kCapFailed:
      return "open: opening not triangulated";
  }
  return "";
}

double GroundHeightAt(const GroundSurface& ground, double x, double y) {
  double best = -std::numeric_limits<double>::infinity();
  for (const Tri3& t : ground.triangles) {
    const glm::dvec3 &a = t[0], &b = t[1], &c = t[2];
    const double det = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
    if (det == 0.0) continue;
    const double l1 = ((x - a.x) * (c.y - a.y) - (c.x - a.x) * (y - a.y)) / det;
    const double l2 = ((b.x - a.x) * (y - a.y) - (x - a.x) * (b.y - a.y)) / det;
    const double l0 = 1.0 - l1 - l2;
    constexpr double kEdge = -1e-9;
    if (l0 < kEdge || l1 < kEdge || l2 < kEdge) continue;
    best = std::max(best, l0 * a.z + l1 * b.z + l2 * c.z);
  }
  return std::isfinite(best) ? best : ground.flat_z;
}

std::vector<ShellClosure> CloseShellsByNeighbours(const std::vector<ShellToClose>& shells,
                                                  const ShellClosureOptions& options) {
  std::vector<ShellClosure> result(shells.size());
  const double tol = options.weld_m;
  std::vector<uint32_t> open;
  for (uint32_t s = 0; s < shells.size(); ++s) {
    if (shells[s].open && shells[s].triangles != nullptr && !shells[s].triangles->empty()) open.push_back(s);
  }
  if (open.empty()) return result;

  // 1. Weld the open shells' corners within `tol`: clusters by a grid of cell `tol`, each to
  // its lowest point (then the least in x, y).
  std::vector<glm::dvec3> points;
  std::map<std::array<double, 3>, uint32_t> point_id;
  std::vector<std::vector<Ids>> corner_ids(shells.size());
  for (uint32_t s : open) {
    for (const Tri3& t : *shells[s].triangles) {
      Ids ids;
      for (int i = 0; i < 3; ++i) {
        auto [it, added] = point_id.emplace(std::array<double, 3>{t[i].x, t[i].y, t[i].z},
                                            static_cast<uint32_t>(points.size()));
        if (added) points.push_back(t[i]);
        ids[i] = it->second;
      }
      corner_ids[s].push_back(ids);
    }
  }
  Clusters clusters(points.size());
  {
    std::unordered_map<CellKey, std::vector<uint32_t>, CellHash> cells;
    auto key = [&](const glm::dvec3& p) {
      return CellKey{static_cast<int64_t>(std::floor(p.x / tol)), static_cast<int64_t>(std::floor(p.y / tol)),
                     static_cast<int64_t>(std::floor(p.z / tol))};
    };
    for (uint32_t i = 0; i < points.size(); ++i) cells[key(points[i])].push_back(i);
    for (uint32_t i = 0; i < points.size(); ++i) {
      const CellKey k = key(points[i]);
      for (int64_t dz = -1; dz <= 1; ++dz) {
        for (int64_t dy = -1; dy <= 1; ++dy) {
          for (int64_t dx = -1; dx <= 1; ++dx) {
            auto it = cells.find({k.x + dx, k.y + dy, k.z + dz});
            if (it == cells.end()) continue;
            for (uint32_t j : it->second) {
              if (j > i && glm::distance(points[i], points[j]) <= tol) clusters.Join(i, j);
            }
          }
        }
      }
    }
  }
  std::vector<uint32_t> rep(points.size());
  std::iota(rep.begin(), rep.end(), 0u);
  auto lower = [&](uint32_t a, uint32_t b) {
    const glm::dvec3 &p = points[a], &q = points[b];
    return p.z != q.z ? p.z < q.z : (p.x != q.x ? p.x < q.x : p.y < q.y);
  };
  for (uint32_t i = 0; i < points.size(); ++i) {
    const uint32_t root = clusters.Find(i);
    if (lower(i, rep[root])) rep[root] = i;
  }
  // Welded vertices: one per cluster, numbered by cluster root.
  std::vector<uint32_t> vertex_of(points.size());
  std::vector<glm::dvec3> vertices;
  {
    std::unordered_map<uint32_t, uint32_t> of_root;
    for (uint32_t i = 0; i < points.size(); ++i) {
      const uint32_t root = clusters.Find(i);
      auto [it, added] = of_root.emplace(root, static_cast<uint32_t>(vertices.size()));
      if (added) vertices.push_back(points[rep[root]]);
      vertex_of[i] = it->second;
    }
  }
  std::vector<double> moved(shells.size(), 0.0);
  for (uint32_t s : open) {
    for (const Ids& ids : corner_ids[s]) {
      for (uint32_t i : ids) moved[s] = std::max(moved[s], glm::distance(points[i], vertices[vertex_of[i]]));
    }
  }

  // 2. T-junctions: an edge passing within `tol` of a welded vertex is cut there (its triangle
  // split in two).
  constexpr double kCell = 2.0;
  Grid2 vertex_grid(kCell);
  for (uint32_t v = 0; v < vertices.size(); ++v) {
    vertex_grid.Add(v, vertices[v].x, vertices[v].y, vertices[v].x, vertices[v].y);
  }
  std::vector<std::vector<Ids>> welded(shells.size());
  for (uint32_t s : open) {
    std::vector<Ids> queue;
    for (const Ids& ids : corner_ids[s]) queue.push_back({vertex_of[ids[0]], vertex_of[ids[1]], vertex_of[ids[2]]});
    size_t budget = 64 * queue.size() + 1024;
    while (!queue.empty()) {
      const Ids t = queue.back();
      queue.pop_back();
      if (t[0] == t[1] || t[1] == t[2] || t[2] == t[0]) continue;
      bool split = false;
      for (int e = 0; e < 3 && !split && budget > 0; ++e) {
        const uint32_t ia = t[e], ib = t[(e + 1) % 3], ic = t[(e + 2) % 3];
        const glm::dvec3 &a = vertices[ia], &b = vertices[ib];
        const glm::dvec3 ab = b - a;
        const double len2 = glm::dot(ab, ab);
        uint32_t best = UINT32_MAX;
        double best_t = 2.0, best_d = 0.0;
        vertex_grid.ForEachNear(std::min(a.x, b.x) - tol, std::min(a.y, b.y) - tol, std::max(a.x, b.x) + tol,
                                std::max(a.y, b.y) + tol, [&](uint32_t v) {
                                  if (v == ia || v == ib) return;
                                  const double u = glm::dot(vertices[v] - a, ab) / len2;
                                  if (!(u > 0.0 && u < 1.0)) return;
                                  const double d = glm::distance(vertices[v], a + ab * u);
                                  if (d <= tol && u < best_t) {
                                    best = v;
                                    best_t = u;
                                    best_d = d;
                                  }
                                });
        if (best == UINT32_MAX) continue;
        split = true;
        --budget;
        moved[s] = std::max(moved[s], best_d);
        queue.push_back({ia, best, ic});
        queue.push_back({best, ib, ic});
      }
      if (!split) welded[s].push_back(t);
    }
  }

  // 3. Odd edges, per shell and over all the open shells.
  using Edge = std::pair<uint32_t, uint32_t>;
  auto edge = [](uint32_t a, uint32_t b) { return a < b ? Edge{a, b} : Edge{b, a}; };
  std::map<Edge, int> union_uses;
  std::vector<std::vector<Edge>> odd(shells.size());
  for (uint32_t s : open) {
    std::map<Edge, int> uses;
    for (const Ids& t : welded[s]) {
      for (int e = 0; e < 3; ++e) ++uses[edge(t[e], t[(e + 1) % 3])];
    }
    for (const auto& [e, n] : uses) {
      union_uses[e] += n;
      if (n % 2 == 1) odd[s].push_back(e);
    }
  }

  // Every shell's triangles as the data gives them, for "lies on another shell's face".
  Grid2 face_grid(4.0);
  std::vector<std::pair<uint32_t, uint32_t>> faces;  // shell, triangle
  for (uint32_t s = 0; s < shells.size(); ++s) {
    if (shells[s].triangles == nullptr) continue;
    for (uint32_t k = 0; k < shells[s].triangles->size(); ++k) {
      const Tri3& t = (*shells[s].triangles)[k];
      const double x0 = std::min({t[0].x, t[1].x, t[2].x}), x1 = std::max({t[0].x, t[1].x, t[2].x});
      const double y0 = std::min({t[0].y, t[1].y, t[2].y}), y1 = std::max({t[0].y, t[1].y, t[2].y});
      face_grid.Add(static_cast<uint32_t>(faces.size()), x0 - tol, y0 - tol, x1 + tol, y1 + tol);
      faces.emplace_back(s, k);
    }
  }
  auto on_other_face = [&](uint32_t s, const glm::dvec3& p) {
    bool on = false;
    face_grid.ForEachNear(p.x, p.y, p.x, p.y, [&](uint32_t f) {
      if (on || faces[f].first == s) return;
      const Tri3& t = (*shells[faces[f].first].triangles)[faces[f].second];
      on = glm::distance(p, ClosestPointOnTriangle(p, t[0], t[1], t[2])) <= 2.0 * tol;
    });
    return on;
  };

  // Openings shared by open shells (an edge odd in several, even over all: neither has a wall
  // there), and how each open shell's triangles run along their edges (for the caps' winding).
  std::map<Edge, std::vector<uint32_t>> shared;
  for (uint32_t s : open) {
    for (const Edge& e : odd[s]) {
      if (union_uses[e] % 2 == 0) shared[e].push_back(s);
    }
  }
  auto runs_along = [&](const std::vector<uint32_t>& members, uint32_t a, uint32_t b) {
    int n = 0;
    for (uint32_t s : members) {
      for (const Ids& t : welded[s]) {
        for (int e = 0; e < 3; ++e) n += (t[e] == a && t[(e + 1) % 3] == b) ? 1 : 0;
      }
    }
    return n;
  };
  // A cap over a wall's opening: its polygon (welded vertex ids) and its triangles [first, last)
  // among the caps made.
  struct CapPolygon {
    std::vector<uint32_t> ids;
    size_t first = 0, last = 0;
  };
  // Caps the loops of `odd_edges` (edges of one shell's or a block's triangles used an odd
  // number of times): kClosed with `caps`, `count` polygons, `walls` (the caps over walls'
  // openings, which may have to be drawn: below) and `deviation` (how far a cap lies off the
  // loop's points), or why not.
  auto cap_openings = [&](const std::vector<Edge>& odd_edges, const auto& on_ground, std::vector<Tri3>* caps,
                          std::vector<CapPolygon>* walls, size_t* count, double* deviation) -> ShellClosureOutcome {
    std::unordered_map<uint32_t, std::vector<uint32_t>> next;
    for (const Edge& e : odd_edges) {
      next[e.first].push_back(e.second);
      next[e.second].push_back(e.first);
    }
    for (const auto& [v, n] : next) {
      if (n.size() != 2) return ShellClosureOutcome::kOpeningsTouch;
    }
    std::vector<std::vector<uint32_t>> loops;
    std::unordered_map<uint32_t, bool> seen;
    for (const Edge& e : odd_edges) {
      if (seen[e.first]) continue;
      std::vector<uint32_t> loop{e.first};
      seen[e.first] = true;
      uint32_t prev = e.first, cur = next[e.first][0];
      while (cur != e.first) {
        loop.push_back(cur);
        seen[cur] = true;
        const uint32_t n = next[cur][0] == prev ? next[cur][1] : next[cur][0];
        prev = cur;
        cur = n;
      }
      loops.push_back(std::move(loop));
    }
    auto planar_cap_of = [&](const std::vector<uint32_t>& ids) {
      std::vector<glm::dvec3> ring;
      for (uint32_t v : ids) ring.push_back(vertices[v]);
      const glm::dvec3 n = NewellNormal(ring);
      const double len = glm::length(n);
      if (!(len > 0.0)) return ShellClosureOutcome::kCapFailed;
      const glm::dvec3 unit = n / len;
      glm::dvec3 centre(0.0);
      for (const glm::dvec3& p : ring) centre += p;
      centre /= static_cast<double>(ring.size());
      double dev = 0.0;
      for (const glm::dvec3& p : ring) dev = std::max(dev, std::abs(glm::dot(p - centre, unit)));
      if (dev > options.cap_planarity_m) {
        // A party wall that bends: vertical, over a path in xy; capped by the vertical
        // surface over that path, one plane per leg.
        double off = 0.0;
        if (CurtainCap(ring, options.cap_planarity_m, caps, &off)) {
          *deviation = std::max(*deviation, off);
          ++*count;
          return ShellClosureOutcome::kClosed;
        }
        // Otherwise not capped: the shells on either side are closed together (step 4).
        // (Triangulating such a loop on its mean plane, even checked inside the two houses by
        // winding numbers at sample points, let Rotterdam's ε-masks hide a wall seen through
        // the crack between the two: issue 46's note.)
        return ShellClosureOutcome::kCapNotPlanar;
      }
      *deviation = std::max(*deviation, dev);
      if (!TriangulateProjected(ring, drop_axis(n), caps)) return ShellClosureOutcome::kCapFailed;
      ++*count;
      return ShellClosureOutcome::kClosed;
    };
    auto planar_cap = [&](const std::vector<uint32_t>& ids) {
      const size_t first = caps->size();
      const ShellClosureOutcome o = planar_cap_of(ids);
      if (o == ShellClosureOutcome::kClosed) walls->push_back({ids, first, caps->size()});
      return o;
    };
    for (const std::vector<uint32_t>& loop : loops) {
      std::vector<bool> grounded(loop.size());
      size_t on = 0;
      for (size_t i = 0; i < loop.size(); ++i) on += grounded[i] = on_ground(vertices[loop[i]]);
      if (on < 2) {
        const ShellClosureOutcome o = planar_cap(loop);
        if (o != ShellClosureOutcome::kClosed) return o;
        continue;
      }
      // From a ground point: each run that leaves the ground and comes back is a wall's opening,
      // capped with its chord; the ground points in order are the floor's.
      const size_t first = static_cast<size_t>(std::find(grounded.begin(), grounded.end(), true) - grounded.begin());
      std::vector<glm::dvec3> floor;
      std::vector<uint32_t> run;
      size_t i = first;
      do {
        size_t j = (i + 1) % loop.size();
        while (!grounded[j]) j = (j + 1) % loop.size();
        floor.push_back(vertices[loop[i]]);
        if (j != (i + 1) % loop.size()) {
          run.clear();
          for (size_t k = i;; k = (k + 1) % loop.size()) {
            run.push_back(loop[k]);
            if (k == j) break;
          }
          const ShellClosureOutcome o = planar_cap(run);
          if (o != ShellClosureOutcome::kClosed) return o;
        }
        i = j;
      } while (i != first);
      if (floor.size() < 3) continue;
      std::vector<glm::dvec2> plan;
      for (const glm::dvec3& p : floor) plan.emplace_back(p.x, p.y);
      if (std::abs(SignedArea(plan)) <= 0.5 * tol * tol) continue;  // the chords alone: no floor to make
      if (!TriangulateProjected(floor, 2, caps)) return ShellClosureOutcome::kCapFailed;
      ++*count;
    }
    return ShellClosureOutcome::kClosed;
  };
  auto on_ground_of = [&](uint32_t s, const glm::dvec3& p) {
    return p.z <= GroundHeightAt(shells[s].ground, p.x, p.y) + tol;
  };

  std::vector<std::vector<Tri3>> caps_of(shells.size());             // closed ones' (a block's: its first's)
  std::vector<std::vector<CapPolygon>> walls_of(shells.size());      // of those, the walls'

  // Classify: any air edge leaves the shell open to the air.
  for (uint32_t s : open) {
    ShellClosure& r = result[s];
    for (const Ids& t : welded[s]) r.drawn.push_back({vertices[t[0]], vertices[t[1]], vertices[t[2]]});
    bool air = false;
    for (const Edge& e : odd[s]) {
      if (union_uses[e] % 2 == 0) continue;  // another open shell is open on it too
      const glm::dvec3 &a = vertices[e.first], &b = vertices[e.second];
      if (on_ground_of(s, a) && on_ground_of(s, b) && on_ground_of(s, (a + b) * 0.5)) continue;
      bool covered = true;
      for (double u : {0.0, 0.25, 0.5, 0.75, 1.0}) covered = covered && on_other_face(s, a + (b - a) * u);
      if (!covered) {
        air = true;
        break;
      }
    }
    if (air) {
      r.outcome = ShellClosureOutcome::kOpenToAir;
    }
  }
  for (uint32_t s : open) {
    ShellClosure& r = result[s];
    if (r.outcome != ShellClosureOutcome::kNotOpen) continue;  // open to the air
    if (odd[s].empty()) {  // closed by the weld alone
      r.outcome = ShellClosureOutcome::kClosed;
      r.triangles = r.drawn;
      r.moved_m = moved[s];
      continue;
    }
    auto on_ground = [&](const glm::dvec3& p) { return on_ground_of(s, p); };
    std::vector<Tri3>& caps = caps_of[s];
    double deviation = 0.0;
    r.outcome = cap_openings(odd[s], on_ground, &caps, &walls_of[s], &r.caps, &deviation);
    if (r.outcome != ShellClosureOutcome::kClosed) {
      r.caps = 0;
      caps.clear();
      walls_of[s].clear();
      continue;
    }
    r.triangles = r.drawn;
    r.triangles.insert(r.triangles.end(), caps.begin(), caps.end());
    r.moved_m = moved[s] + deviation;
  }

  // 4. Blocks: shells left open only by openings towards each other that do not cap (a party
  // wall bent out of any plane and off the vertical) are closed together: their triangles
  // side by side, where those openings cancel, and the block's other openings capped as above.
  std::vector<uint32_t> stuck;
  for (uint32_t s : open) {
    const ShellClosureOutcome o = result[s].outcome;
    if (o == ShellClosureOutcome::kCapNotPlanar || o == ShellClosureOutcome::kCapFailed ||
        o == ShellClosureOutcome::kOpeningsTouch) {
      stuck.push_back(s);
    }
  }
  if (stuck.size() >= 2) {
    Clusters blocks(shells.size());
    std::map<Edge, uint32_t> first_with;
    for (uint32_t s : stuck) {
      for (const Edge& e : odd[s]) {
        auto [it, added] = first_with.emplace(e, s);
        if (!added) blocks.Join(it->second, s);
      }
    }
    std::map<uint32_t, std::vector<uint32_t>> members;
    for (uint32_t s : stuck) members[blocks.Find(s)].push_back(s);
    for (const auto& entry : members) {
      const std::vector<uint32_t>& block = entry.second;  // (not a structured binding: lambdas use it)
      if (block.size() < 2) continue;
      std::map<Edge, int> uses;
      for (uint32_t s : block) {
        for (const Edge& e : odd[s]) ++uses[e];
      }
      std::vector<Edge> block_odd;
      for (const auto& [e, n] : uses) {
        if (n % 2 == 1) block_odd.push_back(e);
      }
      auto on_ground = [&](const glm::dvec3& p) {
        for (uint32_t s : block) {
          if (on_ground_of(s, p)) return true;
        }
        return false;
      };
      std::vector<Tri3> caps;
      std::vector<CapPolygon> walls;
      size_t count = 0;
      double deviation = 0.0;
      if (cap_openings(block_odd, on_ground, &caps, &walls, &count, &deviation) != ShellClosureOutcome::kClosed) {
        continue;
      }
      double moved_m = 0.0;
      for (uint32_t s : block) moved_m = std::max(moved_m, moved[s]);
      for (uint32_t s : block) {
        ShellClosure& r = result[s];
        r.outcome = ShellClosureOutcome::kClosedAsBlock;
        r.block = block;
        r.caps = count;
        r.moved_m = moved_m + deviation;
      }
      ShellClosure& lead = result[block.front()];
      for (uint32_t s : block) lead.triangles.insert(lead.triangles.end(), result[s].drawn.begin(), result[s].drawn.end());
      lead.triangles.insert(lead.triangles.end(), caps.begin(), caps.end());
      caps_of[block.front()] = std::move(caps);
      walls_of[block.front()] = std::move(walls);
    }
  }

  // 5. A closed shell draws each cap over an opening it shares with a neighbour that is not
  // closed (open to the air, or open for want of a cap): nothing else closes it as drawn there,
  // and a viewer looking in through that neighbour would see past its occluders into it. Wound
  // to face out of it (as its triangles along the opening run), owned by the shell whose
  // opening it is (in a block, the member).
  auto closed = [&](uint32_t s) {
    return result[s].outcome == ShellClosureOutcome::kClosed || result[s].outcome == ShellClosureOutcome::kClosedAsBlock;
  };
  for (uint32_t s : open) {
    if (walls_of[s].empty()) continue;
    const std::vector<uint32_t> members =
        result[s].outcome == ShellClosureOutcome::kClosedAsBlock ? result[s].block : std::vector<uint32_t>{s};
    auto member = [&](uint32_t n) { return std::find(members.begin(), members.end(), n) != members.end(); };
    for (const CapPolygon& wall : walls_of[s]) {
      bool draw = false;
      uint32_t owner = s;
      for (size_t i = 0; i < wall.ids.size(); ++i) {
        auto it = shared.find(edge(wall.ids[i], wall.ids[(i + 1) % wall.ids.size()]));
        if (it == shared.end()) continue;
        for (uint32_t n : it->second) {
          if (member(n)) owner = n;
          draw = draw || (!member(n) && !closed(n));
        }
      }
      if (!draw) continue;
      int along = 0;  // > 0: the members' triangles run the polygon's edges the other way
      for (size_t i = 0; i < wall.ids.size(); ++i) {
        const uint32_t a = wall.ids[i], b = wall.ids[(i + 1) % wall.ids.size()];
        along += runs_along(members, b, a) - runs_along(members, a, b);
      }
      std::vector<glm::dvec3> ring;
      for (uint32_t v : wall.ids) ring.push_back(vertices[v]);
      const glm::dvec3 want = NewellNormal(ring) * (along >= 0 ? 1.0 : -1.0);
      for (size_t k = wall.first; k < wall.last; ++k) {
        Tri3 t = caps_of[s][k];
        if (glm::dot(glm::cross(t[1] - t[0], t[2] - t[0]), want) < 0.0) std::swap(t[1], t[2]);
        result[owner].drawn.push_back(t);
        ++result[owner].drawn_caps;
      }
    }
  }
  return result;
}

namespace {

// Whether CGAL may take the ring (simple and counter-clockwise: it may crash on others).
bool SimpleCcw(const Ring& ring) { return ring.size() >= 3 && IsSimpleRing(ring) && SignedArea(ring) > 0.0; }

}  // namespace

std::vector<Occluder25D> ShrinkOccluders(const std::vector<Occluder25D>& occluders, double by_m, double min_area_m2,
                                         double min_top_m) {
  if (!(by_m > 0.0)) return occluders;
  std::vector<Occluder25D> out;
  for (const Occluder25D& oc : occluders) {
    const double height = oc.height - by_m;
    if (!(height > min_top_m)) continue;
    if (!SimpleCcw(oc.footprint)) continue;  // dropped: conservative
    std::vector<PolygonWithHoles> band;
    const size_t n = oc.footprint.size();
    for (size_t i = 0; i < n; ++i) {
      const glm::dvec2 a = oc.footprint[i], b = oc.footprint[(i + 1) % n];
      const double len = glm::length(b - a);
      if (!(len > 0.0)) continue;
      // The edge's band: a rectangle reaching by_m beyond it on every side (it holds every
      // point within by_m of the edge).
      const glm::dvec2 u = (b - a) / len * by_m, w(-u.y, u.x);
      band.push_back({{a - u - w, b + u - w, b + u + w, a - u + w}, {}});
    }
    absl::StatusOr<std::vector<PolygonWithHoles>> left = Difference({oc.footprint, {}}, band);
    if (!left.ok()) continue;  // dropped: conservative
    for (PolygonWithHoles& piece : *left) {
      if (!piece.holes.empty()) continue;
      if (SignedArea(piece.outer) < min_area_m2) continue;
      if (!IsSimpleRing(piece.outer)) continue;  // rounded to double into a crossing: dropped
      out.push_back({std::move(piece.outer), height, oc.object});
    }
  }
  return out;
}

std::vector<Occluder25D> ClipOccluders(const std::vector<Occluder25D>& occluders, const glm::dvec2& lo,
                                       const glm::dvec2& hi, double min_area_m2) {
  std::vector<Occluder25D> out;
  for (const Occluder25D& oc : occluders) {
    glm::dvec2 a = oc.footprint.empty() ? lo : oc.footprint[0], b = a;
    for (const glm::dvec2& p : oc.footprint) {
      a = glm::min(a, p);
      b = glm::max(b, p);
    }
    if (a.x >= lo.x && a.y >= lo.y && b.x <= hi.x && b.y <= hi.y) {  // within already
      out.push_back(oc);
      continue;
    }
    if (b.x <= lo.x || b.y <= lo.y || a.x >= hi.x || a.y >= hi.y) continue;  // outside
    if (!SimpleCcw(oc.footprint)) continue;  // dropped: conservative
    // The box's outside near the footprint: four bands around it.
    const glm::dvec2 m0 = glm::min(a, lo) - 1.0, m1 = glm::max(b, hi) + 1.0;
    const std::vector<PolygonWithHoles> outside = {
        {{{m0.x, m0.y}, {lo.x, m0.y}, {lo.x, m1.y}, {m0.x, m1.y}}, {}},
        {{{hi.x, m0.y}, {m1.x, m0.y}, {m1.x, m1.y}, {hi.x, m1.y}}, {}},
        {{{m0.x, m0.y}, {m1.x, m0.y}, {m1.x, lo.y}, {m0.x, lo.y}}, {}},
        {{{m0.x, hi.y}, {m1.x, hi.y}, {m1.x, m1.y}, {m0.x, m1.y}}, {}},
    };
    absl::StatusOr<std::vector<PolygonWithHoles>> left = Difference({oc.footprint, {}}, outside);
    if (!left.ok()) continue;  // dropped: conservative
    for (PolygonWithHoles& piece : *left) {
      if (!piece.holes.empty() || SignedArea(piece.outer) < min_area_m2 || !IsSimpleRing(piece.outer)) continue;
      out.push_back({std::move(piece.outer), oc.height, oc.object});
    }
  }
  return out;
}

}  // namespace vistream::scenes

