#include "scenes/polygon.h"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_2_algorithms.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>
#include <CGAL/box_intersection_d.h>
#include <absl/strings/str_cat.h>

#include <cassert>
#include <cmath>
#include <list>
#include <set>

namespace vistream::scenes {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_2;
using Segment = K::Segment_2;

struct FaceInfo {
  int nesting = -1;  // 0 outside, 1 inside the outer ring, 2 inside a hole, ...
};
using Vb = CGAL::Triangulation_vertex_base_2<K>;
using Fbb = CGAL::Triangulation_face_base_with_info_2<FaceInfo, K>;
using Fb = CGAL::Constrained_triangulation_face_base_2<K, Fbb>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// The rings are checked first, so constraints never cross: no constructions needed.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<
    K, Tds, CGAL::No_constraint_intersection_requiring_constructions_tag>;

Point P(const glm::dvec2& p) { return Point(p.x, p.y); }

std::vector<Point> Points(const Ring& ring) {
  std::vector<Point> out;
  out.reserve(ring.size());
  for (const glm::dvec2& p : ring) out.push_back(P(p));
  return out;
}

// CGAL's nesting walk: faces reached from the infinite face without crossing a constraint are
// at level 0, each crossing adds one.
void MarkNesting(Cdt& cdt) {
  std::list<Cdt::Edge> border;
  auto flood = [&](Cdt::Face_handle start, int level) {
    if (start->info().nesting != -1) return;
    std::list<Cdt::Face_handle> queue{start};
    while (!queue.empty()) {
      Cdt::Face_handle f = queue.front();
      queue.pop_front();
      if (f->info().nesting != -1) continue;
      f->info().nesting = level;
      for (int i = 0; i < 3; ++i) {
        Cdt::Face_handle n = f->neighbor(i);
        if (n->info().nesting != -1) continue;
        if (cdt.is_constrained(Cdt::Edge(f, i))) {
          border.emplace_back(f, i);
        } else {
          queue.push_back(n);
        }
      }
    }
  };
  flood(cdt.infinite_face(), 0);
  while (!border.empty()) {
    const Cdt::Edge e = border.front();
    border.pop_front();
    Cdt::Face_handle n = e.first->neighbor(e.second);
    if (n->info().nesting == -1) flood(n, e.first->info().nesting + 1);
  }
}

// Whether the two segments share nothing but an endpoint of both, the same point.
bool MeetAtSharedEnd(const Point& a0, const Point& a1, const Point& b0, const Point& b1) {
  const Segment sa(a0, a1), sb(b0, b1);
  if (!CGAL::do_intersect(sa, sb)) return true;
  const Point* shared = nullptr;
  for (const Point* p : {&a0, &a1}) {
    if (*p == b0 || *p == b1) shared = p;
  }
  if (shared == nullptr) return false;  // crossing, or an end on the other's inside
  // They meet at `shared`: anything more (collinear overlap, or the other ends on the other
  // segment) is more than a point.
  const Point& a_other = *shared == a0 ? a1 : a0;
  const Point& b_other = *shared == b0 ? b1 : b0;
  if (a_other == b_other) return false;  // the same segment twice
  if (CGAL::collinear(a_other, *shared, b_other) &&
      CGAL::collinear_are_ordered_along_line(a_other, *shared, b_other) == false) {
    return false;  // overlap along a line from the shared end
  }
  return true;
}

// Whether rings `a` and `b` have no common point other than vertices of both (OSM's
// "touching at a node"); O((n + m) log(n + m) + k) with CGAL's box intersection.
bool TouchAtMostAtVertices(const Ring& a, const Ring& b) {
  using Box = CGAL::Box_intersection_d::Box_with_handle_d<double, 2, const size_t*>;
  const std::vector<Point> pa = Points(a), pb = Points(b);
  std::vector<size_t> ia(a.size()), ib(b.size());
  auto boxes = [](const std::vector<Point>& pts, std::vector<size_t>& ids) {
    std::vector<Box> out;
    out.reserve(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
      ids[i] = i;
      const CGAL::Bbox_2 bb = pts[i].bbox() + pts[(i + 1) % pts.size()].bbox();
      out.emplace_back(bb, &ids[i]);
    }
    return out;
  };
  std::vector<Box> ba = boxes(pa, ia), bb = boxes(pb, ib);
  bool ok = true;
  CGAL::box_intersection_d(ba.begin(), ba.end(), bb.begin(), bb.end(),
                           [&](const Box& x, const Box& y) {
                             if (!ok) return;
                             const size_t i = *x.handle(), j = *y.handle();
                             ok = MeetAtSharedEnd(pa[i], pa[(i + 1) % pa.size()], pb[j],
                                                  pb[(j + 1) % pb.size()]);
                           });
  return ok;
}

// A vertex of `ring` that is not a vertex of `other` (none if all are).
const glm::dvec2* VertexNotOn(const Ring& ring, const Ring& other) {
  std::set<std::pair<double, double>> taken;
  for (const glm::dvec2& p : other) taken.insert({p.x, p.y});
  for (const glm::dvec2& p : ring) {
    if (!taken.count({p.x, p.y})) return &p;
  }
  return nullptr;
}

CGAL::Bounded_side Side(const Ring& ring, const glm::dvec2& p) {
  const std::vector<Point> pts = Points(ring);
  return CGAL::bounded_side_2(pts.begin(), pts.end(), P(p), K());
}

}  // namespace

RingRepairs CleanRing(Ring* ring) {
  RingRepairs r;
  Ring& v = *ring;
  for (bool changed = true; changed && !v.empty();) {
    changed = false;
    Ring out;
    out.reserve(v.size());
    for (const glm::dvec2& p : v) {
      if (!out.empty() && out.back() == p) {
        ++r.duplicate_points;
        changed = true;
        continue;
      }
      out.push_back(p);
    }
    while (out.size() > 1 && out.back() == out.front()) {
      out.pop_back();
      ++r.duplicate_points;
      changed = true;
    }
    // Spikes: a point whose neighbours coincide (the ring goes out and straight back).
    for (size_t i = 0; out.size() >= 3 && i < out.size(); ++i) {
      const size_t prev = (i + out.size() - 1) % out.size(), next = (i + 1) % out.size();
      if (out[prev] == out[next]) {
        out.erase(out.begin() + static_cast<std::ptrdiff_t>(i));
        ++r.spikes;
        changed = true;
        break;  // the neighbours are now duplicates: the next pass merges them
      }
    }
    v = std::move(out);
  }
  return r;
}

bool IsSimpleRing(const Ring& ring) {
  if (ring.size() < 3) return false;
  const std::vector<Point> pts = Points(ring);
  if (CGAL::orientation_2(pts.begin(), pts.end(), K()) == CGAL::COLLINEAR) return false;
  return CGAL::is_simple_2(pts.begin(), pts.end(), K());
}

bool RingInsideRing(const Ring& inner, const Ring& outer) {
  if (!TouchAtMostAtVertices(inner, outer)) return false;
  const glm::dvec2* p = VertexNotOn(inner, outer);
  return p != nullptr && Side(outer, *p) == CGAL::ON_BOUNDED_SIDE;
}

bool RingsApart(const Ring& a, const Ring& b) {
  if (!TouchAtMostAtVertices(a, b)) return false;
  const glm::dvec2* pa = VertexNotOn(a, b);
  const glm::dvec2* pb = VertexNotOn(b, a);
  return pa != nullptr && pb != nullptr && Side(b, *pa) == CGAL::ON_UNBOUNDED_SIDE &&
         Side(a, *pb) == CGAL::ON_UNBOUNDED_SIDE;
}

absl::StatusOr<std::vector<Triangle2>> Triangulate(const PolygonWithHoles& polygon) {
  if (!IsSimpleRing(polygon.outer)) {
    return absl::InvalidArgumentError("the outer ring is not a simple polygon");
  }
  for (size_t h = 0; h < polygon.holes.size(); ++h) {
    const Ring& hole = polygon.holes[h];
    if (!IsSimpleRing(hole)) {
      return absl::InvalidArgumentError(absl::StrCat("inner ring ", h, " is not a simple polygon"));
    }
    if (!RingInsideRing(hole, polygon.outer)) {
      return absl::InvalidArgumentError(
          absl::StrCat("inner ring ", h, " is not inside the outer ring"));
    }
    for (size_t g = 0; g < h; ++g) {
      const Ring& other = polygon.holes[g];
      if (!RingsApart(hole, other)) {
        return absl::InvalidArgumentError(absl::StrCat("inner rings ", g, " and ", h, " overlap"));
      }
    }
  }
  Cdt cdt;
  try {
    auto insert = [&](const Ring& ring) {
      const std::vector<Point> pts = Points(ring);
      cdt.insert_constraint(pts.begin(), pts.end(), /*close=*/true);
    };
    insert(polygon.outer);
    for (const Ring& hole : polygon.holes) insert(hole);
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("triangulation failed: ", e.what()));
  }
  MarkNesting(cdt);
  std::vector<Triangle2> out;
  double area = 0.0;
  for (Cdt::Face_handle f : cdt.finite_face_handles()) {
    if (f->info().nesting % 2 != 1) continue;
    Triangle2 t;
    for (int i = 0; i < 3; ++i) t[i] = {f->vertex(i)->point().x(), f->vertex(i)->point().y()};
    area += SignedArea(t);
    out.push_back(t);
  }
  // Rings that touch at vertices pass the checks above even where they enclose more than the
  // footprint (a hole leaving and re-entering the outer ring through two shared points): the
  // triangles must cover exactly the outer ring less the holes.
  double want = SignedArea(polygon.outer);
  for (const Ring& hole : polygon.holes) want -= std::abs(SignedArea(hole));
  if (!(std::abs(area - want) <= 1e-9 * std::abs(SignedArea(polygon.outer)))) {
    return absl::InvalidArgumentError(
        absl::StrCat("the rings enclose ", area, " m² where the outer less the inner rings is ",
                     want, " m²"));
  }
  return out;
}

void AppendPrism(const PolygonWithHoles& polygon, const std::vector<Triangle2>& triangles, double z0,
                 double z1, Mesh* mesh) {
  assert(z1 > z0);
  // The solid lies left of every edge (outer counter-clockwise, holes clockwise).
  AppendWalls(polygon.outer, z0, z1, mesh);
  for (const Ring& hole : polygon.holes) AppendWalls(hole, z0, z1, mesh);
  // Roof (normal up, counter-clockwise from above) and floor (normal down, reversed).
  const glm::vec3 up(0.f, 0.f, 1.f), down(0.f, 0.f, -1.f);
  for (const Triangle2& t : triangles) {
    const uint32_t r0 = AppendVertex(t[0], z1, up, mesh), r1 = AppendVertex(t[1], z1, up, mesh),
                   r2 = AppendVertex(t[2], z1, up, mesh);
    const uint32_t f0 = AppendVertex(t[0], z0, down, mesh), f1 = AppendVertex(t[1], z0, down, mesh),
                   f2 = AppendVertex(t[2], z0, down, mesh);
    mesh->indices.insert(mesh->indices.end(), {r0, r1, r2, f0, f2, f1});
  }
}

}  // namespace vistream::scenes
