#include "scenes/solid_floor.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

#include <glm/geometric.hpp>

#include "scenes/polygon.h"

namespace vistream::scenes {

namespace {

struct LexLess3 {
  bool operator()(const glm::dvec3& a, const glm::dvec3& b) const {
    return a.x != b.x ? a.x < b.x : (a.y != b.y ? a.y < b.y : a.z < b.z);
  }
};

// Crossing-number test; points on the ring may go either way (rings here do not cross, so a
// loop's first point decides its nesting unless it touches the other loop there).
bool InsideRing(const Ring& ring, const glm::dvec2& p) {
  bool inside = false;
  for (size_t i = 0, j = ring.size() - 1; i < ring.size(); j = i++) {
    const glm::dvec2& a = ring[i];
    const glm::dvec2& b = ring[j];
    if ((a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x) inside = !inside;
  }
  return inside;
}

}  // namespace

FloorResult CloseFloor(const std::vector<std::array<glm::dvec3, 3>>& shell, double tolerance_m) {
  FloorResult out;
  // Weld equal points; count every undirected edge.
  std::map<glm::dvec3, uint32_t, LexLess3> index;
  std::vector<glm::dvec3> points;
  auto id_of = [&](const glm::dvec3& p) {
    auto [it, fresh] = index.emplace(p, static_cast<uint32_t>(points.size()));
    if (fresh) points.push_back(p);
    return it->second;
  };
  std::map<std::pair<uint32_t, uint32_t>, int> uses;
  double lowest = std::numeric_limits<double>::infinity();
  for (const auto& t : shell) {
    for (const glm::dvec3& p : t) lowest = std::min(lowest, p.z);
    // As SolidMeshFromMesh: triangles without area are not part of the boundary.
    if (glm::cross(t[1] - t[0], t[2] - t[0]) == glm::dvec3(0.0)) continue;
    const std::array<uint32_t, 3> v = {id_of(t[0]), id_of(t[1]), id_of(t[2])};
    for (int i = 0; i < 3; ++i) ++uses[std::minmax(v[i], v[(i + 1) % 3])];
  }
  std::map<uint32_t, std::vector<uint32_t>> next;  // boundary edges at each point
  for (const auto& [edge, n] : uses) {
    if (n % 2 == 0) continue;
    next[edge.first].push_back(edge.second);
    next[edge.second].push_back(edge.first);
  }
  if (next.empty()) return out;
  out.outcome = FloorClosing::kNotAFloor;
  for (const auto& [v, ends] : next) {
    if (ends.size() != 2 || !(points[v].z <= lowest + tolerance_m)) return out;
  }

  // The loops, each from its least point (the map's order: the same loops whichever way the
  // file listed the faces), and their points by xy.
  std::vector<Ring> loops;
  std::map<std::pair<double, double>, glm::dvec3> lift;
  std::map<uint32_t, bool> seen;
  for (const auto& [start, ends] : next) {
    if (seen[start]) continue;
    Ring loop;
    uint32_t prev = std::numeric_limits<uint32_t>::max(), at = start;
    do {
      seen[at] = true;
      const glm::dvec3& p = points[at];
      if (!lift.emplace(std::make_pair(p.x, p.y), p).second) return out;  // two points over one another
      loop.emplace_back(p.x, p.y);
      const std::vector<uint32_t>& e = next[at];
      const uint32_t step = e[0] != prev ? e[0] : e[1];
      prev = at;
      at = step;
    } while (at != start && loop.size() <= next.size());
    if (at != start) return out;
    loops.push_back(std::move(loop));
  }

  // Nesting: a loop inside an even number of others is an outer ring, inside an odd number a
  // hole of the smallest loop around it.
  const size_t n = loops.size();
  std::vector<int> depth(n, 0);
  std::vector<double> area(n);
  for (size_t i = 0; i < n; ++i) area[i] = std::abs(SignedArea(loops[i]));
  for (size_t i = 0; i < n; ++i) {
    for (size_t j = 0; j < n; ++j) depth[i] += j != i && InsideRing(loops[j], loops[i][0]);
  }
  std::vector<PolygonWithHoles> polygons;
  std::vector<size_t> polygon_of(n, n);
  for (size_t i = 0; i < n; ++i) {
    if (depth[i] % 2 != 0) continue;
    polygon_of[i] = polygons.size();
    PolygonWithHoles p;
    p.outer = loops[i];
    if (SignedArea(p.outer) < 0.0) std::reverse(p.outer.begin(), p.outer.end());
    polygons.push_back(std::move(p));
  }
  for (size_t i = 0; i < n; ++i) {
    if (depth[i] % 2 == 0) continue;
    size_t parent = n;
    for (size_t j = 0; j < n; ++j) {
      if (depth[j] != depth[i] - 1 || !InsideRing(loops[j], loops[i][0])) continue;
      if (parent == n || area[j] < area[parent]) parent = j;
    }
    if (parent == n) {
      out.outcome = FloorClosing::kFailed;
      out.why = "a hole in no outer loop";
      return out;
    }
    Ring hole = loops[i];
    if (SignedArea(hole) > 0.0) std::reverse(hole.begin(), hole.end());
    polygons[polygon_of[parent]].holes.push_back(std::move(hole));
  }
  std::vector<std::array<glm::dvec3, 3>> floor;
  for (const PolygonWithHoles& p : polygons) {
    absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(p);
    if (!tris.ok()) {
      out.outcome = FloorClosing::kFailed;
      out.why = std::string(tris.status().message());
      return out;
    }
    for (const Triangle2& t : *tris) {
      std::array<glm::dvec3, 3> t3;
      for (int k = 0; k < 3; ++k) {
        auto it = lift.find({t[k].x, t[k].y});
        if (it == lift.end()) {
          out.outcome = FloorClosing::kFailed;
          out.why = "a floor triangle's corner that is not a loop point";
          return out;
        }
        t3[k] = it->second;
      }
      // Counter-clockwise from above; the floor faces down.
      std::swap(t3[1], t3[2]);
      floor.push_back(t3);
    }
  }
  out.outcome = FloorClosing::kClosed;
  out.triangles = std::move(floor);
  out.loops = n;
  return out;
}

}  // namespace vistream::scenes
