#include "scenes/derived_walks.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <queue>
#include <unordered_map>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <glm/geometric.hpp>

namespace vistream::scenes {

namespace {

constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
constexpr double kInf = std::numeric_limits<double>::infinity();

// An undirected graph in scene-local metres; points equal to 1 mm are one node.
class Graph {
 public:
  struct Arc {
    uint32_t to;
    double length;
    int32_t label;  // the street an edge belongs to (index into the labels), -1: none
  };

  uint32_t Node(const glm::dvec2& p) {
    const std::pair<int64_t, int64_t> key(std::llround(p.x * 1000.0), std::llround(p.y * 1000.0));
    const auto [it, inserted] = index_.emplace(key, static_cast<uint32_t>(nodes_.size()));
    if (inserted) {
      nodes_.push_back(p);
      adj_.emplace_back();
    }
    return it->second;
  }
  // A node that is never merged with another (grid points, known to be distinct).
  uint32_t NewNode(const glm::dvec2& p) {
    nodes_.push_back(p);
    adj_.emplace_back();
    return static_cast<uint32_t>(nodes_.size() - 1);
  }
  void Edge(uint32_t a, uint32_t b, int32_t label = -1) {
    if (a == b) return;
    for (const Arc& e : adj_[a]) {
      if (e.to == b) return;  // already joined (a street drawn twice, a shared triangle edge)
    }
    const double len = glm::distance(nodes_[a], nodes_[b]);
    adj_[a].push_back({b, len, label});
    adj_[b].push_back({a, len, label});
    ++edges_;
  }

  size_t size() const { return nodes_.size(); }
  size_t edges() const { return edges_; }
  const glm::dvec2& at(uint32_t n) const { return nodes_[n]; }
  const std::vector<Arc>& arcs(uint32_t n) const { return adj_[n]; }

  // Shortest distances from `sources` (each at 0) and each node's predecessor.
  void Dijkstra(const std::vector<uint32_t>& sources, std::vector<double>* dist, std::vector<uint32_t>* prev) const {
    dist->assign(nodes_.size(), kInf);
    prev->assign(nodes_.size(), kNone);
    using Item = std::pair<double, uint32_t>;
    std::priority_queue<Item, std::vector<Item>, std::greater<>> queue;
    for (uint32_t s : sources) {
      (*dist)[s] = 0.0;
      queue.emplace(0.0, s);
    }
    while (!queue.empty()) {
      const auto [d, n] = queue.top();
      queue.pop();
      if (d > (*dist)[n]) continue;
      for (const Arc& e : adj_[n]) {
        const double nd = d + e.length;
        if (nd < (*dist)[e.to]) {
          (*dist)[e.to] = nd;
          (*prev)[e.to] = n;
          queue.emplace(nd, e.to);
        }
      }
    }
  }

 private:
  std::vector<glm::dvec2> nodes_;
  std::vector<std::vector<Arc>> adj_;
  std::map<std::pair<int64_t, int64_t>, uint32_t> index_;
  size_t edges_ = 0;
};

// The reachable node farthest from the sources (the lowest index of equals); kNone if none.
uint32_t Farthest(const std::vector<double>& dist) {
  uint32_t best = kNone;
  for (uint32_t n = 0; n < dist.size(); ++n) {
    if (std::isfinite(dist[n]) && (best == kNone || dist[n] > dist[best])) best = n;
  }
  return best;
}

std::vector<uint32_t> PathTo(uint32_t end, const std::vector<uint32_t>& prev) {
  std::vector<uint32_t> path;
  for (uint32_t n = end; n != kNone; n = prev[n]) path.push_back(n);
  std::reverse(path.begin(), path.end());
  return path;
}

double PointSegmentDistance(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b) {
  const glm::dvec2 ab = b - a;
  const double len2 = glm::dot(ab, ab);
  const double t = len2 > 0.0 ? std::clamp(glm::dot(p - a, ab) / len2, 0.0, 1.0) : 0.0;
  return glm::distance(p, a + t * ab);
}

double Cross(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

bool SegmentsCross(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c, const glm::dvec2& d) {
  const double d1 = Cross(c, d, a), d2 = Cross(c, d, b), d3 = Cross(a, b, c), d4 = Cross(a, b, d);
  return ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0));
}

double SegmentSegmentDistance(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c, const glm::dvec2& d) {
  if (SegmentsCross(a, b, c, d)) return 0.0;
  return std::min({PointSegmentDistance(a, c, d), PointSegmentDistance(b, c, d), PointSegmentDistance(c, a, b),
                   PointSegmentDistance(d, a, b)});
}

bool InTriangle(const glm::dvec2& p, const Triangle2& t) {
  const double c0 = Cross(t[0], t[1], p), c1 = Cross(t[1], t[2], p), c2 = Cross(t[2], t[0], p);
  return (c0 >= 0.0 && c1 >= 0.0 && c2 >= 0.0) || (c0 <= 0.0 && c1 <= 0.0 && c2 <= 0.0);
}

// Douglas-Peucker over path[i..j]: keeps a shortcut when every point between lies within
// `tol` of it and `ok` accepts it; the kept indices are appended to *keep (j excluded).
void Simplify(const std::vector<glm::dvec2>& pts, size_t i, size_t j, double tol,
              const std::function<bool(const glm::dvec2&, const glm::dvec2&)>& ok, std::vector<size_t>* keep) {
  if (j <= i + 1) {
    keep->push_back(i);
    return;
  }
  size_t worst = i + 1;
  double worst_d = -1.0;
  for (size_t k = i + 1; k < j; ++k) {
    const double d = PointSegmentDistance(pts[k], pts[i], pts[j]);
    if (d > worst_d) {
      worst_d = d;
      worst = k;
    }
  }
  if (worst_d <= tol && (!ok || ok(pts[i], pts[j]))) {
    keep->push_back(i);
    return;
  }
  Simplify(pts, i, worst, tol, ok, keep);
  Simplify(pts, worst, j, tol, ok, keep);
}

// The walks of `g` (DeriveStreetWalks' description); `labels` names the edges' streets; `ok`
// (may be empty) vets simplification shortcuts.
DerivedWalks Derive(const Graph& g, const std::vector<std::string>& labels, const DeriveWalkOptions& options,
                    const std::function<bool(const glm::dvec2&, const glm::dvec2&)>& ok) {
  DerivedWalks out;
  out.graph_nodes = g.size();
  out.graph_edges = g.edges();
  if (g.edges() == 0 || options.max_walks == 0) {
    out.notes.push_back(options.max_walks == 0 ? "no walks asked for" : "the graph has no edges: no walks");
    return out;
  }
  // Components, and the largest by total edge length.
  std::vector<uint32_t> comp(g.size(), kNone);
  std::vector<double> comp_length;
  std::vector<size_t> comp_nodes;
  for (uint32_t s = 0; s < g.size(); ++s) {
    if (comp[s] != kNone || g.arcs(s).empty()) continue;
    const auto c = static_cast<uint32_t>(comp_length.size());
    comp_length.push_back(0.0);
    comp_nodes.push_back(0);
    std::vector<uint32_t> stack{s};
    comp[s] = c;
    while (!stack.empty()) {
      const uint32_t n = stack.back();
      stack.pop_back();
      ++comp_nodes[c];
      for (const Graph::Arc& e : g.arcs(n)) {
        comp_length[c] += 0.5 * e.length;  // each edge is seen from both ends
        if (comp[e.to] == kNone) {
          comp[e.to] = c;
          stack.push_back(e.to);
        }
      }
    }
  }
  out.components = comp_length.size();
  const auto largest = static_cast<uint32_t>(std::max_element(comp_length.begin(), comp_length.end()) - comp_length.begin());
  out.largest_component_nodes = comp_nodes[largest];
  out.largest_component_length_m = comp_length[largest];
  const auto start = static_cast<uint32_t>(std::find(comp.begin(), comp.end(), largest) - comp.begin());

  std::vector<double> dist;
  std::vector<uint32_t> prev;
  std::vector<uint32_t> covered;  // nodes on earlier walks
  for (size_t w = 0; w < options.max_walks; ++w) {
    uint32_t from;
    if (w == 0) {
      g.Dijkstra({start}, &dist, &prev);
      from = Farthest(dist);
    } else {
      g.Dijkstra(covered, &dist, &prev);
      from = Farthest(dist);
      if (dist[from] <= 0.0) {
        out.notes.push_back(absl::StrCat("every node lies on an earlier walk: ", w, " walk(s)"));
        break;
      }
    }
    g.Dijkstra({from}, &dist, &prev);
    const uint32_t to = Farthest(dist);
    const std::vector<uint32_t> path = PathTo(to, prev);
    if (path.size() < 2) break;
    std::vector<glm::dvec2> pts;
    pts.reserve(path.size());
    for (uint32_t n : path) pts.push_back(g.at(n));
    std::vector<size_t> keep;
    Simplify(pts, 0, pts.size() - 1, options.simplify_m, ok, &keep);
    keep.push_back(pts.size() - 1);
    ScenePath walk;
    for (size_t k : keep) walk.waypoints.push_back(pts[k]);
    const double length = PolylineLength(walk.waypoints);
    if (length < options.min_length_m) {
      if (w > 0) {
        out.notes.push_back(absl::StrFormat("walk %d would be only %.0f m long (under %.0f m): %d walk(s)", w + 1,
                                            length, options.min_length_m, w));
        break;
      }
      out.notes.push_back(absl::StrFormat("the longest walk the graph allows is %.0f m, shorter than %.0f m", length,
                                          options.min_length_m));
    }
    // The street it mostly follows, if one has more than half its length.
    std::map<int32_t, double> by_label;
    for (size_t k = 0; k + 1 < path.size(); ++k) {
      for (const Graph::Arc& e : g.arcs(path[k])) {
        if (e.to == path[k + 1]) {
          by_label[e.label] += e.length;
          break;
        }
      }
    }
    const double raw_length = dist[to];
    walk.name = absl::StrCat(options.name_prefix, " ", w + 1);
    for (const auto& [label, len] : by_label) {
      if (label >= 0 && static_cast<size_t>(label) < labels.size() && !labels[label].empty() && len > 0.5 * raw_length) {
        absl::StrAppend(&walk.name, " (", labels[label], ")");
      }
    }
    out.paths.push_back(std::move(walk));
    out.lengths_m.push_back(length);
    covered.insert(covered.end(), path.begin(), path.end());
  }
  if (out.paths.size() < options.max_walks && out.notes.empty()) {
    out.notes.push_back(absl::StrCat(out.paths.size(), " of ", options.max_walks, " walks"));
  }
  return out;
}

bool Inside(const glm::dvec2& p, const DeriveWalkOptions& o) {
  if (!std::isfinite(p.x) || !std::isfinite(p.y)) return false;
  if (!o.bounds) return true;
  return p.x >= o.bounds->first.x && p.y >= o.bounds->first.y && p.x <= o.bounds->second.x && p.y <= o.bounds->second.y;
}

// Projected triangles in buckets, for clearance queries.
class Obstacles {
 public:
  Obstacles(std::vector<Triangle2> triangles, double bucket_m) : tris_(std::move(triangles)), bucket_(bucket_m) {
    if (tris_.empty()) return;
    lo_ = glm::dvec2(kInf);
    glm::dvec2 hi(-kInf);
    for (const Triangle2& t : tris_) {
      for (const glm::dvec2& p : t) {
        lo_ = glm::min(lo_, p);
        hi = glm::max(hi, p);
      }
    }
    // At most kMaxBuckets² buckets, however far apart the triangles lie.
    constexpr double kMaxBuckets = 1024.0;
    bucket_ = std::max({bucket_, (hi.x - lo_.x) / kMaxBuckets, (hi.y - lo_.y) / kMaxBuckets});
    nx_ = static_cast<int64_t>((hi.x - lo_.x) / bucket_) + 1;
    ny_ = static_cast<int64_t>((hi.y - lo_.y) / bucket_) + 1;
    buckets_.resize(static_cast<size_t>(nx_ * ny_));
    boxes_.reserve(tris_.size());
    for (uint32_t k = 0; k < tris_.size(); ++k) {
      const Triangle2& t = tris_[k];
      const glm::dvec2 a = glm::min(glm::min(t[0], t[1]), t[2]), b = glm::max(glm::max(t[0], t[1]), t[2]);
      boxes_.emplace_back(a, b);
      ForBuckets(a, b, [&](size_t cell) { buckets_[cell].push_back(k); });
    }
    stamp_.assign(tris_.size(), 0);
  }

  // Whether segment ab (a point when a == b) keeps at least `clearance` from every triangle.
  bool Clear(const glm::dvec2& a, const glm::dvec2& b, double clearance) const {
    if (tris_.empty()) return true;
    const glm::dvec2 lo = glm::min(a, b) - clearance, hi = glm::max(a, b) + clearance;
    ++query_;
    bool clear = true;
    ForBuckets(lo, hi, [&](size_t cell) {
      if (!clear) return;
      for (uint32_t k : buckets_[cell]) {
        if (stamp_[k] == query_) continue;
        stamp_[k] = query_;
        const auto& [tlo, thi] = boxes_[k];
        if (thi.x < lo.x || thi.y < lo.y || tlo.x > hi.x || tlo.y > hi.y) continue;
        const Triangle2& t = tris_[k];
        const bool area = Cross(t[0], t[1], t[2]) != 0.0;
        if (area && (InTriangle(a, t) || InTriangle(b, t))) {
          clear = false;
          return;
        }
        for (int e = 0; e < 3; ++e) {
          if (SegmentSegmentDistance(a, b, t[e], t[(e + 1) % 3]) < clearance) {
            clear = false;
            return;
          }
        }
      }
    });
    return clear;
  }

 private:
  template <typename F>
  void ForBuckets(const glm::dvec2& a, const glm::dvec2& b, F f) const {
    const int64_t i0 = std::clamp<int64_t>(static_cast<int64_t>(std::floor((a.x - lo_.x) / bucket_)), 0, nx_ - 1);
    const int64_t i1 = std::clamp<int64_t>(static_cast<int64_t>(std::floor((b.x - lo_.x) / bucket_)), 0, nx_ - 1);
    const int64_t j0 = std::clamp<int64_t>(static_cast<int64_t>(std::floor((a.y - lo_.y) / bucket_)), 0, ny_ - 1);
    const int64_t j1 = std::clamp<int64_t>(static_cast<int64_t>(std::floor((b.y - lo_.y) / bucket_)), 0, ny_ - 1);
    for (int64_t j = j0; j <= j1; ++j) {
      for (int64_t i = i0; i <= i1; ++i) f(static_cast<size_t>(j * nx_ + i));
    }
  }

  std::vector<Triangle2> tris_;
  std::vector<std::pair<glm::dvec2, glm::dvec2>> boxes_;
  double bucket_;
  glm::dvec2 lo_{0.0};
  int64_t nx_ = 0, ny_ = 0;
  std::vector<std::vector<uint32_t>> buckets_;
  mutable std::vector<uint64_t> stamp_;
  mutable uint64_t query_ = 0;
};

}  // namespace

double PolylineLength(const std::vector<glm::dvec2>& points) {
  double length = 0.0;
  for (size_t k = 1; k < points.size(); ++k) length += glm::distance(points[k - 1], points[k]);
  return length;
}

DerivedWalks DeriveStreetWalks(const std::vector<StreetPolyline>& streets, const DeriveWalkOptions& options) {
  Graph g;
  std::vector<std::string> labels;
  std::map<std::string, int32_t> label_of;
  for (const StreetPolyline& s : streets) {
    int32_t label = -1;
    if (!s.name.empty()) {
      const auto [it, inserted] = label_of.emplace(s.name, static_cast<int32_t>(labels.size()));
      if (inserted) labels.push_back(s.name);
      label = it->second;
    }
    // Runs of consecutive usable points; a point outside the bounds (or not finite) cuts the street.
    uint32_t last = kNone;
    for (const glm::dvec2& p : s.points) {
      if (!Inside(p, options)) {
        last = kNone;
        continue;
      }
      const uint32_t n = g.Node(p);
      if (last != kNone) g.Edge(last, n, label);
      last = n;
    }
  }
  return Derive(g, labels, options, {});
}

DerivedWalks DeriveRoadWalks(const std::vector<PolygonWithHoles>& polygons, const DeriveWalkOptions& options) {
  Graph g;
  const Obstacles obstacles(options.obstacles, 10.0);
  const double clearance = options.clearance_m;
  auto edge = [&](uint32_t a, uint32_t b) {
    if (obstacles.Clear(g.at(a), g.at(b), clearance)) g.Edge(a, b);
  };
  size_t failed = 0;
  for (const PolygonWithHoles& poly : polygons) {
    absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(poly);
    if (!tris.ok()) {
      ++failed;
      continue;
    }
    for (const Triangle2& t : *tris) {
      if (!Inside(t[0], options) || !Inside(t[1], options) || !Inside(t[2], options)) continue;
      const uint32_t c = g.Node((t[0] + t[1] + t[2]) / 3.0);
      for (int e = 0; e < 3; ++e) {
        edge(c, g.Node(t[e]));
        edge(c, g.Node(0.5 * (t[e] + t[(e + 1) % 3])));
      }
    }
  }
  DerivedWalks out = Derive(g, {}, options, [&](const glm::dvec2& a, const glm::dvec2& b) {
    return obstacles.Clear(a, b, clearance);
  });
  if (failed > 0) out.notes.push_back(absl::StrCat(failed, " road polygon(s) did not triangulate: left out"));
  return out;
}

DerivedWalks DeriveRoadWalks(const std::vector<std::vector<glm::dvec2>>& polygons, const DeriveWalkOptions& options) {
  std::vector<PolygonWithHoles> polys;
  size_t bad = 0;
  for (const std::vector<glm::dvec2>& ring : polygons) {
    PolygonWithHoles p;
    p.outer = ring;
    CleanRing(&p.outer);
    if (!IsSimpleRing(p.outer)) {
      ++bad;
      continue;
    }
    double area2 = 0.0;
    for (size_t k = 0; k < p.outer.size(); ++k) {
      const glm::dvec2 &a = p.outer[k], &b = p.outer[(k + 1) % p.outer.size()];
      area2 += a.x * b.y - b.x * a.y;
    }
    if (area2 < 0.0) std::reverse(p.outer.begin(), p.outer.end());
    polys.push_back(std::move(p));
  }
  DerivedWalks out = DeriveRoadWalks(polys, options);
  if (bad > 0) out.notes.push_back(absl::StrCat(bad, " road polygon(s) not simple: left out"));
  return out;
}

DerivedWalks DeriveFreeSpaceWalks(const Scene& scene, const FreeSpaceOptions& options, const DeriveWalkOptions& walk) {
  std::vector<Triangle2> tris;
  std::vector<bool> terrain(scene.objects.size(), false);
  for (ObjectId t : scene.terrain) {
    if (t < terrain.size()) terrain[t] = true;
  }
  for (const Object& o : scene.objects) {
    if (terrain[o.id]) continue;
    const Mesh& m = o.mesh;
    for (size_t k = 0; k + 2 < m.indices.size(); k += 3) {
      Triangle2 t;
      for (int c = 0; c < 3; ++c) {
        const glm::vec3& p = m.positions[m.indices[k + static_cast<size_t>(c)]];
        t[static_cast<size_t>(c)] = glm::dvec2(p.x, p.y);
      }
      tris.push_back(t);
    }
  }
  for (const Occluder25D& oc : scene.occluders) {
    if (terrain.size() > oc.object && terrain[oc.object]) continue;
    // A fan from the first vertex: it covers the footprint (more where it is not convex: safe)
    // and its edges include every edge of the footprint.
    const auto& fp = oc.footprint;
    for (size_t k = 1; k + 1 < fp.size(); ++k) tris.push_back({fp[0], fp[k], fp[k + 1]});
  }
  // A millimetre more, so that rounding in anyone's distance computation keeps clearance_m.
  const double clearance = options.clearance_m + 1e-3;
  Obstacles obstacles(std::move(tris), 16.0);

  DerivedWalks none;
  if (scene.bounds.Empty()) {
    none.notes.push_back("the scene is empty: no free space");
    return none;
  }
  glm::dvec2 lo(scene.bounds.min), hi(scene.bounds.max);
  if (walk.bounds) {
    lo = glm::max(lo, walk.bounds->first);
    hi = glm::min(hi, walk.bounds->second);
  }
  double spacing = options.spacing_m;
  std::vector<std::string> notes;
  auto count = [&](double s) {
    return (static_cast<size_t>(std::max(0.0, (hi.x - lo.x) / s)) + 1) * (static_cast<size_t>(std::max(0.0, (hi.y - lo.y) / s)) + 1);
  };
  while (count(spacing) > options.max_grid_points) spacing *= 2.0;
  if (spacing != options.spacing_m) notes.push_back(absl::StrFormat("grid spacing %.0f m (the scene is large)", spacing));
  const auto nx = static_cast<int64_t>((hi.x - lo.x) / spacing) + 1;
  const auto ny = static_cast<int64_t>((hi.y - lo.y) / spacing) + 1;
  // Centre the grid in the box.
  const glm::dvec2 origin = 0.5 * (lo + hi) - 0.5 * spacing * glm::dvec2(static_cast<double>(nx - 1), static_cast<double>(ny - 1));
  Graph g;
  std::vector<uint32_t> node(static_cast<size_t>(nx * ny), kNone);
  auto at = [&](int64_t i, int64_t j) { return origin + spacing * glm::dvec2(static_cast<double>(i), static_cast<double>(j)); };
  for (int64_t j = 0; j < ny; ++j) {
    for (int64_t i = 0; i < nx; ++i) {
      const glm::dvec2 p = at(i, j);
      if (p.x < lo.x || p.y < lo.y || p.x > hi.x || p.y > hi.y) continue;
      if (obstacles.Clear(p, p, clearance)) node[static_cast<size_t>(j * nx + i)] = g.NewNode(p);
    }
  }
  const int64_t steps[4][2] = {{1, 0}, {0, 1}, {1, 1}, {-1, 1}};
  for (int64_t j = 0; j < ny; ++j) {
    for (int64_t i = 0; i < nx; ++i) {
      const uint32_t a = node[static_cast<size_t>(j * nx + i)];
      if (a == kNone) continue;
      for (const auto& s : steps) {
        const int64_t i2 = i + s[0], j2 = j + s[1];
        if (i2 < 0 || i2 >= nx || j2 >= ny) continue;
        const uint32_t b = node[static_cast<size_t>(j2 * nx + i2)];
        if (b != kNone && obstacles.Clear(g.at(a), g.at(b), clearance)) g.Edge(a, b);
      }
    }
  }
  DerivedWalks out = Derive(g, {}, walk, [&](const glm::dvec2& a, const glm::dvec2& b) {
    return obstacles.Clear(a, b, clearance);
  });
  out.notes.insert(out.notes.begin(), notes.begin(), notes.end());
  return out;
}

}  // namespace vistream::scenes
