#include "scenes/derived_ground.h"

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <tuple>
#include <utility>

#include <absl/strings/str_cat.h>
#include <glm/common.hpp>

namespace vistream::scenes {

namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_2;
using Vb = CGAL::Triangulation_vertex_base_with_info_2<double, K>;  // info: the point's z
using Fb = CGAL::Constrained_triangulation_face_base_2<K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Floors taken never overlap, so constraints meet only at points: no constructions needed.
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<K, Tds, CGAL::No_constraint_intersection_requiring_constructions_tag>;

using Xy = std::pair<double, double>;

Point P(const glm::dvec3& p) { return Point(p.x, p.y); }

// A floor triangle in xy, counter-clockwise.
struct Tri2 {
  std::array<Point, 3> p;
  glm::dvec2 lo, hi;
};

Tri2 MakeTri2(const Triangle3& t) {
  Tri2 out;
  for (int i = 0; i < 3; ++i) out.p[i] = P(t[i]);
  if (CGAL::orientation(out.p[0], out.p[1], out.p[2]) == CGAL::RIGHT_TURN) std::swap(out.p[1], out.p[2]);
  out.lo = glm::min(glm::dvec2(t[0]), glm::min(glm::dvec2(t[1]), glm::dvec2(t[2])));
  out.hi = glm::max(glm::dvec2(t[0]), glm::max(glm::dvec2(t[1]), glm::dvec2(t[2])));
  return out;
}

// Whether two counter-clockwise triangles' interiors meet: no edge line of either separates
// them (exact predicates; touching along an edge or at a point is not overlapping).
bool InteriorsOverlap(const Tri2& a, const Tri2& b) {
  auto separates = [](const Tri2& s, const Tri2& o) {
    for (int i = 0; i < 3; ++i) {
      bool all_out = true;
      for (int k = 0; k < 3 && all_out; ++k) {
        all_out = CGAL::orientation(s.p[i], s.p[(i + 1) % 3], o.p[k]) != CGAL::LEFT_TURN;
      }
      if (all_out) return true;
    }
    return false;
  };
  return !separates(a, b) && !separates(b, a);
}

// Whether `q` lies inside or on the counter-clockwise triangle.
bool Covers(const Tri2& t, const Point& q) {
  for (int i = 0; i < 3; ++i) {
    if (CGAL::orientation(t.p[i], t.p[(i + 1) % 3], q) == CGAL::RIGHT_TURN) return false;
  }
  return true;
}

// Floor triangles in a uniform grid over [lo, hi] (at most kCells a side, so that a file's
// extent cannot make it large), for the overlap and cover tests.
class FloorGrid {
 public:
  static constexpr int64_t kCells = 1024;

  FloorGrid(const glm::dvec2& lo, const glm::dvec2& hi, double cell) : lo_(lo) {
    const double extent = std::max(hi.x - lo.x, hi.y - lo.y);
    cell_ = std::max(cell, extent / static_cast<double>(kCells));
    if (!std::isfinite(cell_)) cell_ = std::numeric_limits<double>::max();
    cells_.resize(static_cast<size_t>(kCells * kCells));
  }

  void Add(const Tri2& t) {
    const uint32_t id = static_cast<uint32_t>(tris_.size());
    tris_.push_back(t);
    ForCells(t.lo, t.hi, [&](size_t cell) { cells_[cell].push_back(id); });
  }

  // Whether fn(triangle) holds for a triangle whose box meets [lo, hi].
  template <typename Fn>
  bool Any(const glm::dvec2& lo, const glm::dvec2& hi, Fn&& fn) const {
    bool found = false;
    ForCells(lo, hi, [&](size_t cell) {
      for (uint32_t id : cells_[cell]) {
        if (found) return;
        const Tri2& t = tris_[id];
        if (t.hi.x < lo.x || t.lo.x > hi.x || t.hi.y < lo.y || t.lo.y > hi.y) continue;
        found = fn(t);
      }
    });
    return found;
  }

 private:
  int64_t Index(double v, double lo) const {
    const double f = (v - lo) / cell_;
    if (!(f >= 0.0)) return 0;
    if (f >= static_cast<double>(kCells - 1)) return kCells - 1;
    return static_cast<int64_t>(f);
  }
  template <typename Fn>
  void ForCells(const glm::dvec2& lo, const glm::dvec2& hi, Fn&& fn) const {
    const int64_t i0 = Index(lo.x, lo_.x), i1 = Index(hi.x, lo_.x), j0 = Index(lo.y, lo_.y), j1 = Index(hi.y, lo_.y);
    for (int64_t j = j0; j <= j1; ++j) {
      for (int64_t i = i0; i <= i1; ++i) fn(static_cast<size_t>(j * kCells + i));
    }
  }

  glm::dvec2 lo_;
  double cell_ = 1.0;
  std::vector<Tri2> tris_;
  std::vector<std::vector<uint32_t>> cells_;
};

bool Finite(const glm::dvec3& p) { return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z); }

}  // namespace

std::vector<Triangle3> FloorTriangles(const std::vector<Triangle3>& shell, double tolerance_m) {
  double lowest = std::numeric_limits<double>::infinity();
  for (const Triangle3& t : shell) {
    for (const glm::dvec3& p : t) lowest = std::min(lowest, p.z);
  }
  std::vector<Triangle3> out;
  for (const Triangle3& t : shell) {
    bool low = true;
    for (const glm::dvec3& p : t) low &= p.z <= lowest + tolerance_m;
    if (low && CGAL::orientation(P(t[0]), P(t[1]), P(t[2])) != CGAL::COLLINEAR) out.push_back(t);
  }
  return out;
}

absl::StatusOr<DerivedGround> DeriveGround(const DerivedGroundInput& input) {
  DerivedGround out;
  // 1. Floors, lowest first; one over a lower floor is left out.
  struct FloorRef {
    double low, high;
    size_t index;
  };
  std::vector<FloorRef> order;
  for (size_t i = 0; i < input.floors.size(); ++i) {
    const std::vector<Triangle3>& f = input.floors[i];
    if (f.empty()) continue;
    double low = std::numeric_limits<double>::infinity(), high = -low;
    for (const Triangle3& t : f) {
      for (const glm::dvec3& p : t) {
        if (!Finite(p)) return absl::InvalidArgumentError("a floor point that is not finite");
        low = std::min(low, p.z);
        high = std::max(high, p.z);
      }
    }
    order.push_back({low, high, i});
  }
  // By height, then by the floor's first point: the same ground whichever order the file has.
  std::sort(order.begin(), order.end(), [&](const FloorRef& a, const FloorRef& b) {
    if (a.low != b.low) return a.low < b.low;
    const glm::dvec3 &p = input.floors[a.index][0][0], &q = input.floors[b.index][0][0];
    return std::tie(p.x, p.y, p.z, a.index) < std::tie(q.x, q.y, q.z, b.index);
  });
  glm::dvec2 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
  for (const FloorRef& ref : order) {
    for (const Triangle3& t : input.floors[ref.index]) {
      for (const glm::dvec3& p : t) {
        lo = glm::min(lo, glm::dvec2(p));
        hi = glm::max(hi, glm::dvec2(p));
      }
    }
  }
  FloorGrid grid(lo, hi, 10.0);
  std::map<Xy, double> floor_z;  // corner -> height in the ground (the highest floor's)
  std::vector<std::pair<Xy, Xy>> constraints;
  for (const FloorRef& ref : order) {
    const std::vector<Triangle3>& f = input.floors[ref.index];
    std::vector<Tri2> mine;
    bool overlaps = false;
    for (const Triangle3& t : f) {
      mine.push_back(MakeTri2(t));
      overlaps = overlaps || grid.Any(mine.back().lo, mine.back().hi,
                                      [&](const Tri2& o) { return InteriorsOverlap(mine.back(), o); });
    }
    if (overlaps) {
      ++out.floors_overlapping;
      continue;
    }
    ++out.floors;
    for (const Tri2& t : mine) grid.Add(t);
    for (const Triangle3& t : f) {
      for (int i = 0; i < 3; ++i) {
        const Xy a(t[i].x, t[i].y), b(t[(i + 1) % 3].x, t[(i + 1) % 3].y);
        auto [it, fresh] = floor_z.emplace(a, ref.high);
        if (!fresh) it->second = std::max(it->second, ref.high);
        constraints.emplace_back(std::min(a, b), std::max(a, b));
      }
    }
  }
  std::sort(constraints.begin(), constraints.end());
  constraints.erase(std::unique(constraints.begin(), constraints.end()), constraints.end());

  // 2. Surface points off the floors, the lowest at each xy.
  std::map<Xy, double> surface_z;
  for (const glm::dvec3& p : input.points) {
    if (!Finite(p)) return absl::InvalidArgumentError("a ground point that is not finite");
    const Point q(p.x, p.y);
    const glm::dvec2 xy(p);
    if (floor_z.count({p.x, p.y}) > 0 || grid.Any(xy, xy, [&](const Tri2& t) { return Covers(t, q); })) {
      ++out.points_under_floors;
      continue;
    }
    auto [it, fresh] = surface_z.emplace(Xy(p.x, p.y), p.z);
    if (!fresh) it->second = std::min(it->second, p.z);
  }
  std::map<Xy, double> all = floor_z;
  all.insert(surface_z.begin(), surface_z.end());
  if (all.empty()) return absl::InvalidArgumentError("no ground-level point to derive a terrain from");
  out.floor_points = floor_z.size();
  out.surface_points = surface_z.size();

  // 3. The box's corners, at the nearest point's height.
  for (const glm::dvec2& c : {input.lo, glm::dvec2(input.hi.x, input.lo.y), input.hi, glm::dvec2(input.lo.x, input.hi.y)}) {
    if (all.count({c.x, c.y}) > 0) continue;
    if (grid.Any(c, c, [&](const Tri2& t) { return Covers(t, Point(c.x, c.y)); })) continue;
    double best = std::numeric_limits<double>::infinity(), z = 0.0;
    for (const auto& [xy, pz] : all) {
      const double d = (xy.first - c.x) * (xy.first - c.x) + (xy.second - c.y) * (xy.second - c.y);
      if (d < best) {
        best = d;
        z = pz;
      }
    }
    all.emplace(Xy(c.x, c.y), z);
    ++out.corner_points;
  }

  // 4. The triangulation: points in xy order, then the floors' edges.
  Cdt cdt;
  std::map<Xy, Cdt::Vertex_handle> handle;
  try {
    Cdt::Face_handle hint;
    for (const auto& [xy, z] : all) {
      Cdt::Vertex_handle v = cdt.insert(Point(xy.first, xy.second), hint);
      v->info() = z;
      hint = v->face();
      handle.emplace(xy, v);
    }
    for (const auto& [a, b] : constraints) cdt.insert_constraint(handle.at(a), handle.at(b));
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat("the derived terrain's triangulation failed: ", e.what()));
  }
  if (cdt.number_of_vertices() != all.size()) {
    return absl::InternalError("the derived terrain's triangulation lost points");
  }
  out.triangles.reserve(cdt.number_of_faces());
  for (Cdt::Face_handle f : cdt.finite_face_handles()) {
    Triangle3 t;
    for (int i = 0; i < 3; ++i) {
      const Cdt::Vertex_handle v = f->vertex(i);
      t[i] = glm::dvec3(v->point().x(), v->point().y(), v->info());
    }
    out.triangles.push_back(t);
  }
  return out;
}

}  // namespace vistream::scenes
