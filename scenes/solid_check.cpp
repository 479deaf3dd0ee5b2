#include "scenes/solid_check.h"

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/box_intersection_d.h>
#include <CGAL/intersections.h>
#include <glm/common.hpp>

#include <algorithm>
#include <numeric>
#include <utility>

namespace vistream::scenes {

namespace {

using Ik = CGAL::Exact_predicates_inexact_constructions_kernel;  // exact predicates
using Ek = CGAL::Exact_predicates_exact_constructions_kernel;    // exact constructions
using Triangle = std::array<uint32_t, 3>;

uint64_t EdgeKey(uint32_t a, uint32_t b) {
  if (a > b) std::swap(a, b);
  return uint64_t{a} << 32 | b;
}

// The keys that occur an odd number of times, sorted.
std::vector<uint64_t> OddKeys(std::vector<uint64_t> keys) {
  std::sort(keys.begin(), keys.end());
  std::vector<uint64_t> odd;
  for (size_t i = 0; i < keys.size();) {
    size_t j = i;
    while (j < keys.size() && keys[j] == keys[i]) ++j;
    if ((j - i) % 2 == 1) odd.push_back(keys[i]);
    i = j;
  }
  return odd;
}

Ik::Point_3 Ip(const glm::dvec3& p) { return {p.x, p.y, p.z}; }
Ek::Point_3 Ep(const glm::dvec3& p) { return {p.x, p.y, p.z}; }

bool OnBoundary(const Ek::Triangle_3& t, const Ek::Point_3& p) {
  for (int i = 0; i < 3; ++i) {
    if (Ek::Segment_3(t.vertex(i), t.vertex((i + 1) % 3)).has_on(p)) return true;
  }
  return false;
}

bool WithinOneEdge(const Ek::Triangle_3& t, const Ek::Segment_3& s) {
  for (int i = 0; i < 3; ++i) {
    const Ek::Segment_3 e(t.vertex(i), t.vertex((i + 1) % 3));
    if (e.has_on(s.source()) && e.has_on(s.target())) return true;
  }
  return false;
}

// Two non-coplanar triangles meet in a point or a segment on the line where their planes
// meet. No point of it lies inside both when it is a point on either boundary, or a segment
// within an edge of either (a segment on a boundary lies within one edge: a triangle meets
// the line through one of its edges in that edge only, and any other line in at most two
// boundary points).
bool CrossExactly(const std::array<glm::dvec3, 3>& a, const std::array<glm::dvec3, 3>& b) {
  const Ek::Triangle_3 ta(Ep(a[0]), Ep(a[1]), Ep(a[2])), tb(Ep(b[0]), Ep(b[1]), Ep(b[2]));
  const auto meet = CGAL::intersection(ta, tb);
  if (!meet) return false;
  if (const Ek::Point_3* p = boost::get<Ek::Point_3>(&*meet)) {
    return !OnBoundary(ta, *p) && !OnBoundary(tb, *p);
  }
  if (const Ek::Segment_3* s = boost::get<Ek::Segment_3>(&*meet)) {
    return !WithinOneEdge(ta, *s) && !WithinOneEdge(tb, *s);
  }
  return true;  // an area: only coplanar triangles, which the caller has let through
}

bool Cross(const std::vector<glm::dvec3>& v, const Triangle& ia, const Triangle& ib) {
  int shared = 0;
  int a_at = -1, b_at = -1;  // where the (last) shared vertex is in each
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      if (ia[i] == ib[j]) {
        ++shared;
        a_at = i;
        b_at = j;
      }
    }
  }
  // Sharing an edge: they meet in it alone unless coplanar, and coplanar is allowed.
  if (shared >= 2) return false;
  const Ik::Point_3 a0 = Ip(v[ia[0]]), a1 = Ip(v[ia[1]]), a2 = Ip(v[ia[2]]);
  const Ik::Point_3 b0 = Ip(v[ib[0]]), b1 = Ip(v[ib[1]]), b2 = Ip(v[ib[2]]);
  if (CGAL::coplanar(a0, a1, a2, b0) && CGAL::coplanar(a0, a1, a2, b1) &&
      CGAL::coplanar(a0, a1, a2, b2)) {
    return false;
  }
  const Ik::Triangle_3 ta(a0, a1, a2), tb(b0, b1, b2);
  if (shared == 1) {
    // Both meet the line of their planes' intersection in a segment from the shared vertex
    // to the opposite edge (or only in the vertex): they share more than the vertex exactly
    // when one's opposite edge touches the other.
    const Ik::Segment_3 ea(Ip(v[ia[(a_at + 1) % 3]]), Ip(v[ia[(a_at + 2) % 3]]));
    const Ik::Segment_3 eb(Ip(v[ib[(b_at + 1) % 3]]), Ip(v[ib[(b_at + 2) % 3]]));
    if (!CGAL::do_intersect(ea, tb) && !CGAL::do_intersect(eb, ta)) return false;
  } else if (!CGAL::do_intersect(ta, tb)) {
    return false;
  }
  return CrossExactly({v[ia[0]], v[ia[1]], v[ia[2]]}, {v[ib[0]], v[ib[1]], v[ib[2]]});
}

}  // namespace

bool ClosesModTwo(const std::vector<glm::dvec3>& vertices, const std::vector<Triangle>& triangles) {
  std::vector<uint64_t> keys;
  keys.reserve(3 * triangles.size());
  for (const Triangle& t : triangles) {
    for (int i = 0; i < 3; ++i) keys.push_back(EdgeKey(t[i], t[(i + 1) % 3]));
  }
  // Parity is additive, so edges used an even number of times drop out before any cutting:
  // what is left are the open edges and those with T-junctions.
  const std::vector<uint64_t> odd = OddKeys(std::move(keys));
  if (odd.empty()) return true;

  std::vector<uint32_t> by_x(vertices.size());
  std::iota(by_x.begin(), by_x.end(), 0u);
  std::sort(by_x.begin(), by_x.end(),
            [&](uint32_t i, uint32_t j) { return vertices[i].x < vertices[j].x; });
  std::vector<uint64_t> pieces;
  std::vector<std::pair<double, uint32_t>> on;
  for (const uint64_t e : odd) {
    const uint32_t a = static_cast<uint32_t>(e >> 32), b = static_cast<uint32_t>(e);
    const glm::dvec3 &pa = vertices[a], &pb = vertices[b];
    const glm::dvec3 lo = glm::min(pa, pb), hi = glm::max(pa, pb);
    // Along the axis of the largest extent, the order of points on the line is their order.
    const glm::dvec3 ext = hi - lo;
    const int axis = ext.x >= ext.y && ext.x >= ext.z ? 0 : (ext.y >= ext.z ? 1 : 2);
    on.clear();
    on.emplace_back(pa[axis], a);
    on.emplace_back(pb[axis], b);
    auto first = std::lower_bound(by_x.begin(), by_x.end(), lo.x,
                                  [&](uint32_t i, double x) { return vertices[i].x < x; });
    for (auto it = first; it != by_x.end() && vertices[*it].x <= hi.x; ++it) {
      const glm::dvec3& p = vertices[*it];
      if (*it == a || *it == b || p.y < lo.y || p.y > hi.y || p.z < lo.z || p.z > hi.z) continue;
      // On the line and inside the segment's box: on the segment, strictly between its ends
      // (vertices are distinct).
      if (CGAL::collinear(Ip(pa), Ip(pb), Ip(p))) on.emplace_back(p[axis], *it);
    }
    std::sort(on.begin(), on.end());
    for (size_t i = 0; i + 1 < on.size(); ++i) pieces.push_back(EdgeKey(on[i].second, on[i + 1].second));
  }
  return OddKeys(std::move(pieces)).empty();
}

bool HasCrossingTriangles(const std::vector<glm::dvec3>& vertices,
                          const std::vector<Triangle>& triangles) {
  using Box = CGAL::Box_intersection_d::Box_with_handle_d<double, 3, const Triangle*>;
  std::vector<Box> boxes;
  boxes.reserve(triangles.size());
  for (const Triangle& t : triangles) {
    const CGAL::Bbox_3 bb =
        Ip(vertices[t[0]]).bbox() + Ip(vertices[t[1]]).bbox() + Ip(vertices[t[2]]).bbox();
    boxes.emplace_back(bb, &t);
  }
  bool crossing = false;
  CGAL::box_self_intersection_d(boxes.begin(), boxes.end(), [&](const Box& x, const Box& y) {
    if (!crossing) crossing = Cross(vertices, *x.handle(), *y.handle());
  });
  return crossing;
}

}  // namespace vistream::scenes
