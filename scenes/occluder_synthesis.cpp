#include "scenes/occluder_synthesis.h"

#include <CGAL/Constrained_triangulation_2.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_face_base_with_info_2.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <set>
#include <utility>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "scenes/occluder_tiers.h"
#include "scenes/solid_check.h"

namespace vistream::scenes {

namespace {

using Ek = CGAL::Exact_predicates_exact_constructions_kernel;
using Ik = CGAL::Exact_predicates_inexact_constructions_kernel;
using FT = Ek::FT;
using Point2 = Ek::Point_2;
using Triangle = std::array<uint32_t, 3>;

struct FaceInfo {
  int group = -1;  // faces reachable from each other without crossing a projected edge
};
using Vb = CGAL::Triangulation_vertex_base_2<Ek>;
using Fbb = CGAL::Triangulation_face_base_with_info_2<FaceInfo, Ek>;
using Fb = CGAL::Constrained_triangulation_face_base_2<Ek, Fbb>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
// Projected edges cross each other: their crossings are computed, exactly.
using Ct = CGAL::Constrained_triangulation_2<Ek, Tds, CGAL::Exact_intersections_tag>;

constexpr double kInf = std::numeric_limits<double>::infinity();
// Candidate levels for one solid's tiers, at most (the dynamic programme is quadratic in it).
constexpr size_t kMaxLevels = 256;

// Welds exactly equal positions and drops triangles that index out of range, touch a
// non-finite position or have no area (exactly collinear corners).
SolidMesh Weld(const std::vector<glm::dvec3>& vertices, const std::vector<Triangle>& triangles) {
  std::vector<uint32_t> order;
  order.reserve(vertices.size());
  for (uint32_t i = 0; i < vertices.size(); ++i) {
    const glm::dvec3& p = vertices[i];
    if (std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z)) order.push_back(i);
  }
  auto less = [&](uint32_t i, uint32_t j) {
    const glm::dvec3 &a = vertices[i], &b = vertices[j];
    return a.x != b.x ? a.x < b.x : (a.y != b.y ? a.y < b.y : a.z < b.z);
  };
  std::sort(order.begin(), order.end(), less);
  constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
  std::vector<uint32_t> remap(vertices.size(), kNone);
  SolidMesh out;
  for (size_t k = 0; k < order.size(); ++k) {
    if (k == 0 || vertices[order[k]] != vertices[order[k - 1]]) out.vertices.push_back(vertices[order[k]]);
    remap[order[k]] = static_cast<uint32_t>(out.vertices.size() - 1);
  }
  for (const Triangle& t : triangles) {
    Triangle w;
    bool ok = true;
    for (int i = 0; i < 3; ++i) {
      ok &= t[i] < remap.size() && remap[t[i]] != kNone;
      if (ok) w[i] = remap[t[i]];
    }
    if (!ok || w[0] == w[1] || w[1] == w[2] || w[2] == w[0]) continue;
    const glm::dvec3 &a = out.vertices[w[0]], &b = out.vertices[w[1]], &c = out.vertices[w[2]];
    if (CGAL::collinear(Ik::Point_3(a.x, a.y, a.z), Ik::Point_3(b.x, b.y, b.z),
                        Ik::Point_3(c.x, c.y, c.z))) {
      continue;
    }
    // Each triangle from its least vertex, the list sorted: the same solid gives the same
    // triangulation of its projected edges however its faces were listed.
    std::rotate(w.begin(), std::min_element(w.begin(), w.end()), w.end());
    out.triangles.push_back(w);
  }
  std::sort(out.triangles.begin(), out.triangles.end());
  return out;
}

// The plane of a non-vertical triangle as a height over xy, exactly.
struct Plane {
  FT a, b, c;          // z = a x + b y + c
  glm::dvec3 approx;   // a, b, c in double
  double slope = 0.0;  // |a| + |b|, at least: how fast z changes when xy is rounded

  FT At(const Point2& p) const { return a * p.x() + b * p.y() + c; }
  double At(const glm::dvec2& p) const { return approx.x * p.x + approx.y * p.y + approx.z; }
};

Plane PlaneOf(const glm::dvec3& p0, const glm::dvec3& p1, const glm::dvec3& p2) {
  const FT x0(p0.x), y0(p0.y), z0(p0.z);
  const FT ux = FT(p1.x) - x0, uy = FT(p1.y) - y0, uz = FT(p1.z) - z0;
  const FT vx = FT(p2.x) - x0, vy = FT(p2.y) - y0, vz = FT(p2.z) - z0;
  const FT nz = ux * vy - uy * vx;  // not 0: the triangle is not vertical
  Plane p;
  p.a = -(uy * vz - uz * vy) / nz;
  p.b = -(uz * vx - ux * vz) / nz;
  p.c = z0 - p.a * x0 - p.b * y0;
  auto bound = [](const FT& x) {
    const std::pair<double, double> i = CGAL::to_interval(x);
    return std::max(std::abs(i.first), std::abs(i.second));
  };
  p.approx = glm::dvec3(CGAL::to_double(p.a), CGAL::to_double(p.b), CGAL::to_double(p.c));
  p.slope = (bound(p.a) + bound(p.b)) * (1.0 + 1e-9);
  return p;
}

// An exact value as a double at most one unit in the last place away, the same double for the
// same value however it was computed (so that pieces of neighbouring faces share points).
double Round(const FT& x) {
  const std::pair<double, double> i = CGAL::to_interval(x);
  if (i.first == i.second) return i.first;
  return CGAL::to_interval(CGAL::exact(x)).first;
}

glm::dvec2 Round(const Point2& p) { return {Round(p.x()), Round(p.y())}; }

// x - margin and x + margin rounded outwards; x itself when there is no margin (a flat roof
// or floor keeps its exact height).
double Below(double x, double margin) { return margin > 0.0 ? std::nextafter(x - margin, -kInf) : x; }
double Above(double x, double margin) { return margin > 0.0 ? std::nextafter(x + margin, kInf) : x; }

glm::dvec2 Approx(const Point2& p) { return {CGAL::to_double(p.x()), CGAL::to_double(p.y())}; }

// The part of convex polygon `poly` where the affine function with values `f` at its vertices
// is >= 0, exactly.
std::vector<Point2> ClipExact(const std::vector<Point2>& poly, const std::vector<FT>& f) {
  std::vector<Point2> out;
  const size_t n = poly.size();
  std::vector<CGAL::Sign> s(n);
  for (size_t i = 0; i < n; ++i) s[i] = CGAL::sign(f[i]);
  for (size_t i = 0; i < n; ++i) {
    const size_t j = (i + 1) % n;
    if (s[i] != CGAL::NEGATIVE) out.push_back(poly[i]);
    if ((s[i] == CGAL::POSITIVE && s[j] == CGAL::NEGATIVE) ||
        (s[i] == CGAL::NEGATIVE && s[j] == CGAL::POSITIVE)) {
      const FT t = f[i] / (f[i] - f[j]);
      out.emplace_back(poly[i].x() + (poly[j].x() - poly[i].x()) * t,
                       poly[i].y() + (poly[j].y() - poly[i].y()) * t);
    }
  }
  return out;
}

// The same in double, for areas only.
std::vector<glm::dvec2> ClipApprox(const std::vector<glm::dvec2>& poly, const std::vector<double>& f) {
  std::vector<glm::dvec2> out;
  const size_t n = poly.size();
  for (size_t i = 0; i < n; ++i) {
    const size_t j = (i + 1) % n;
    if (f[i] >= 0.0) out.push_back(poly[i]);
    if ((f[i] > 0.0 && f[j] < 0.0) || (f[i] < 0.0 && f[j] > 0.0)) {
      out.push_back(poly[i] + (poly[j] - poly[i]) * (f[i] / (f[i] - f[j])));
    }
  }
  return out;
}

// A usable piece of one face of the triangulation: over it, a prism from the ground reaches
// up to the top plane.
struct Part {
  std::vector<Point2> polygon;       // convex, counter-clockwise, exact
  std::vector<FT> top;               // the top plane at the polygon's vertices
  std::vector<glm::dvec2> approx;    // the polygon in double
  const Plane* plane = nullptr;      // the top plane
  double margin = 0.0;               // how much the top may change over a rounding of xy
  double top_max = 0.0;              // an upper bound of `top`
};

double PartArea(const Part& part, double level) {
  std::vector<double> f(part.approx.size());
  for (size_t i = 0; i < f.size(); ++i) f[i] = part.plane->At(part.approx[i]) - level - part.margin;
  return SignedArea(ClipApprox(part.approx, f));
}

// The part of `part` where the top is at or above `level` (plus the margin), rounded to
// double; empty if it has no area.
std::vector<glm::dvec2> PartAtLevel(const Part& part, double level) {
  const double threshold = Above(level, part.margin);
  if (part.top_max < threshold) return {};
  const FT t(threshold);
  std::vector<FT> f(part.top.size());
  bool whole = true;
  for (size_t i = 0; i < f.size(); ++i) {
    f[i] = part.top[i] - t;
    whole &= CGAL::sign(f[i]) != CGAL::NEGATIVE;
  }
  std::vector<glm::dvec2> out;
  if (whole) {
    for (const Point2& p : part.polygon) out.push_back(Round(p));
  } else {
    for (const Point2& p : ClipExact(part.polygon, f)) out.push_back(Round(p));
  }
  return out;
}

// One margin for all parts: the threshold at a level is then the same number for every part,
// so neighbouring parts whose tops meet along an edge are cut at the same exact points there
// (and round to the same doubles, and merge). All but the near-vertical: a sliver of a face
// standing almost upright (a gable's top in double) would lower every tier by its margin, so
// parts with a margin over a nanometre keep their own.
void ShareMargin(std::vector<Part>* parts) {
  constexpr double kMostShared = 1e-9;
  double margin = 0.0;
  for (const Part& part : *parts) {
    if (part.margin <= kMostShared) margin = std::max(margin, part.margin);
  }
  for (Part& part : *parts) {
    if (part.margin <= kMostShared) part.margin = margin;
  }
}

double DivergenceVolume(const SolidMesh& s) {
  double v = 0.0;
  const glm::dvec3 o = s.vertices.front();
  for (const Triangle& t : s.triangles) {
    v += glm::dot(s.vertices[t[0]] - o, glm::cross(s.vertices[t[1]] - o, s.vertices[t[2]] - o));
  }
  return std::abs(v) / 6.0;
}

// Candidate levels: every height where a part's top has a vertex, and between them (where
// sloped tops make the area shrink gradually) evenly spaced ones; at most kMaxLevels.
std::vector<double> CandidateLevels(const std::vector<Part>& parts, double lowest) {
  std::vector<double> breaks;
  for (const Part& part : parts) {
    for (const FT& h : part.top) {
      // The highest level at which this vertex is still inside: top - margin, rounded down.
      const double top = CGAL::to_interval(h).first;
      double l = Below(top, part.margin);
      while (Above(l, part.margin) > top) l = std::nextafter(l, -kInf);  // rounding both ways
      if (l >= lowest) breaks.push_back(l);
    }
  }
  std::sort(breaks.begin(), breaks.end());
  // Levels a hair apart (one height reached through different planes) are one: the lowest.
  std::vector<double> b;
  for (const double l : breaks) {
    if (b.empty() || l > b.back() + 1e-9 * std::max(1.0, std::abs(l))) b.push_back(l);
  }
  if (b.size() > kMaxLevels) {
    std::vector<double> thin;
    for (size_t i = 0; i < kMaxLevels; ++i) thin.push_back(b[i * (b.size() - 1) / (kMaxLevels - 1)]);
    b = std::move(thin);
  }
  const size_t split = b.empty() ? 1 : std::clamp<size_t>(kMaxLevels / b.size(), 1, 8);
  std::vector<double> levels;
  for (size_t i = 0; i < b.size(); ++i) {
    levels.push_back(b[i]);
    if (i + 1 == b.size()) break;
    for (size_t k = 1; k < split; ++k) {
      levels.push_back(b[i] + (b[i + 1] - b[i]) * static_cast<double>(k) / static_cast<double>(split));
    }
  }
  return levels;
}

}  // namespace

const char* SolidDefectName(SolidDefect defect) {
  switch (defect) {
    case SolidDefect::kNone:
      return "";
    case SolidDefect::kEmpty:
      return "empty";
    case SolidDefect::kOpen:
      return "open";
    case SolidDefect::kSelfIntersecting:
      return "self-intersecting";
    case SolidDefect::kRaised:
      return "raised above the ground";
  }
  return "";
}

SolidMesh SolidMeshFromMesh(const Mesh& mesh) {
  std::vector<glm::dvec3> vertices(mesh.positions.begin(), mesh.positions.end());
  std::vector<Triangle> triangles;
  triangles.reserve(mesh.TriangleCount());
  for (size_t i = 0; i + 2 < mesh.indices.size(); i += 3) {
    triangles.push_back({mesh.indices[i], mesh.indices[i + 1], mesh.indices[i + 2]});
  }
  return Weld(vertices, triangles);
}

OccluderSynthesis SynthesizeOccluders(const SolidMesh& solid, double ground_z,
                                      const OccluderSynthesisOptions& options) {
  GroundSurface flat;
  flat.flat_z = ground_z;
  return SynthesizeOccluders(solid, ground_z, flat, options);
}

OccluderSynthesis SynthesizeOccluders(const SolidMesh& solid, double ground_z, const GroundSurface& ground,
                                      const OccluderSynthesisOptions& options) {
  OccluderSynthesis out;
  const SolidMesh s = Weld(solid.vertices, solid.triangles);
  if (s.triangles.empty()) {
    out.defect = SolidDefect::kEmpty;
    return out;
  }
  if (!ClosesModTwo(s.vertices, s.triangles)) {
    out.defect = SolidDefect::kOpen;
    return out;
  }
  if (HasCrossingTriangles(s.vertices, s.triangles)) {
    out.defect = SolidDefect::kSelfIntersecting;
    out.solid_volume_m3 = DivergenceVolume(s);
    return out;
  }

  // Rounding an exact point to double moves it by at most one unit in the last place of the
  // largest coordinate; a plane's height there moves by at most its slope times that.
  double extent = 1.0;
  for (const glm::dvec3& p : s.vertices) extent = std::max({extent, std::abs(p.x), std::abs(p.y)});

  // The triangulation of every projected edge: each of its faces lies in one region where
  // the same faces stand above one another, in the same order (no two faces cross).
  Ct ct;
  std::vector<Ct::Vertex_handle> vh(s.vertices.size());
  std::vector<Point2> xy(s.vertices.size());
  for (size_t i = 0; i < s.vertices.size(); ++i) {
    xy[i] = Point2(s.vertices[i].x, s.vertices[i].y);
    vh[i] = ct.insert(xy[i]);
  }
  // Each triangulation vertex by the first input vertex at its xy, so that constraints go in
  // (and run) in an order that depends on the input only, not on where the heap put the
  // vertices: the same solid gives the same occluders in every process.
  std::map<Ct::Vertex*, uint32_t> first_at;
  std::vector<uint32_t> canon(s.vertices.size());
  for (uint32_t i = 0; i < s.vertices.size(); ++i) canon[i] = first_at.emplace(&*vh[i], i).first->second;
  std::set<std::pair<uint32_t, uint32_t>> edges;
  for (const Triangle& t : s.triangles) {
    for (int i = 0; i < 3; ++i) {
      uint32_t a = canon[t[i]], b = canon[t[(i + 1) % 3]];
      if (a == b) continue;  // a vertical edge
      if (b < a) std::swap(a, b);
      if (edges.insert({a, b}).second) ct.insert_constraint(vh[a], vh[b]);
    }
  }
  // The terrain triangles under the solid: their edges cut the regions too, so that the
  // ground is one plane over each region.
  struct GroundTriangle {
    std::array<Point2, 3> corner;
    CGAL::Orientation orientation;
    Plane plane;
  };
  std::vector<GroundTriangle> ground_tris;
  {
    glm::dvec2 lo(kInf), hi(-kInf);
    for (const glm::dvec3& p : s.vertices) {
      lo = glm::min(lo, glm::dvec2(p));
      hi = glm::max(hi, glm::dvec2(p));
    }
    for (const auto& t : ground.triangles) {
      const glm::dvec2 tlo = glm::min(glm::dvec2(t[0]), glm::min(glm::dvec2(t[1]), glm::dvec2(t[2])));
      const glm::dvec2 thi = glm::max(glm::dvec2(t[0]), glm::max(glm::dvec2(t[1]), glm::dvec2(t[2])));
      if (thi.x < lo.x || tlo.x > hi.x || thi.y < lo.y || tlo.y > hi.y) continue;
      GroundTriangle g;
      for (int i = 0; i < 3; ++i) g.corner[i] = Point2(t[i].x, t[i].y);
      g.orientation = CGAL::orientation(g.corner[0], g.corner[1], g.corner[2]);
      if (g.orientation == CGAL::COLLINEAR) continue;  // a vertical triangle: no ground of its own
      g.plane = PlaneOf(t[0], t[1], t[2]);
      for (int i = 0; i < 3; ++i) {
        for (const glm::dvec3& p : t) extent = std::max({extent, std::abs(p.x), std::abs(p.y)});
        ct.insert_constraint(g.corner[i], g.corner[(i + 1) % 3]);
      }
      ground_tris.push_back(std::move(g));
    }
  }
  // The ground's plane over a region, from a point strictly inside it: the lowest terrain
  // triangle containing it; none where no terrain lies.
  auto ground_at = [&](const Point2& p) -> const Plane* {
    const Plane* best = nullptr;
    FT best_z = 0;
    for (const GroundTriangle& g : ground_tris) {
      bool inside = true;
      for (int i = 0; i < 3 && inside; ++i) {
        const CGAL::Orientation o = CGAL::orientation(g.corner[i], g.corner[(i + 1) % 3], p);
        inside = o == g.orientation || o == CGAL::COLLINEAR;
      }
      if (!inside) continue;
      const FT z = g.plane.At(p);
      if (best == nullptr || z < best_z) {
        best = &g.plane;
        best_z = z;
      }
    }
    return best;
  };
  const double rounding = std::ldexp(extent, -50);  // the terrain's corners counted in `extent`

  // The non-vertical triangles: their planes, orientations and boxes in xy.
  struct Face {
    uint32_t triangle;
    CGAL::Orientation orientation;
    glm::dvec2 lo, hi;
  };
  std::vector<Face> faces;
  std::vector<Plane> planes(s.triangles.size());
  for (uint32_t i = 0; i < s.triangles.size(); ++i) {
    const Triangle& t = s.triangles[i];
    const CGAL::Orientation o = CGAL::orientation(xy[t[0]], xy[t[1]], xy[t[2]]);
    if (o == CGAL::COLLINEAR) continue;
    const glm::dvec3 &a = s.vertices[t[0]], &b = s.vertices[t[1]], &c = s.vertices[t[2]];
    faces.push_back({i, o, glm::min(glm::dvec2(a), glm::min(glm::dvec2(b), glm::dvec2(c))),
                     glm::max(glm::dvec2(a), glm::max(glm::dvec2(b), glm::dvec2(c)))});
    planes[i] = PlaneOf(a, b, c);
  }

  // The faces above a point strictly inside a region, lowest first.
  auto stack_at = [&](const Point2& p) {
    const std::pair<double, double> px = CGAL::to_interval(p.x()), py = CGAL::to_interval(p.y());
    std::vector<std::pair<FT, uint32_t>> hits;
    for (const Face& f : faces) {
      if (px.second < f.lo.x || px.first > f.hi.x || py.second < f.lo.y || py.first > f.hi.y) continue;
      const Triangle& t = s.triangles[f.triangle];
      if (CGAL::orientation(xy[t[0]], xy[t[1]], p) != f.orientation ||
          CGAL::orientation(xy[t[1]], xy[t[2]], p) != f.orientation ||
          CGAL::orientation(xy[t[2]], xy[t[0]], p) != f.orientation) {
        continue;
      }
      hits.emplace_back(planes[f.triangle].At(p), f.triangle);
    }
    std::sort(hits.begin(), hits.end(),
              [](const auto& x, const auto& y) { return x.first < y.first; });
    std::vector<uint32_t> stack;
    for (const auto& h : hits) stack.push_back(h.second);
    return stack;
  };

  std::vector<std::vector<uint32_t>> stacks;
  std::vector<Part> parts;
  bool reaches_ground = false;
  double volume = 0.0;
  for (Ct::Face_handle face : ct.finite_face_handles()) {
    if (face->info().group < 0) {
      // A new region: every face reachable without crossing a projected edge.
      const int group = static_cast<int>(stacks.size());
      std::vector<Ct::Face_handle> todo{face};
      face->info().group = group;
      while (!todo.empty()) {
        Ct::Face_handle f = todo.back();
        todo.pop_back();
        for (int i = 0; i < 3; ++i) {
          Ct::Face_handle n = f->neighbor(i);
          if (ct.is_infinite(n) || n->info().group >= 0 || ct.is_constrained(Ct::Edge(f, i))) continue;
          n->info().group = group;
          todo.push_back(n);
        }
      }
      stacks.push_back(stack_at(CGAL::centroid(face->vertex(0)->point(), face->vertex(1)->point(),
                                               face->vertex(2)->point())));
    }
    const std::vector<uint32_t>& stack = stacks[static_cast<size_t>(face->info().group)];
    // Parity: inside between the first and second face above, the third and fourth, ...
    // A closed boundary has an even number of faces above every region.
    if (stack.empty() || stack.size() % 2 != 0) continue;
    const std::vector<Point2> q = {face->vertex(0)->point(), face->vertex(1)->point(),
                                   face->vertex(2)->point()};
    std::vector<glm::dvec2> qd;
    for (const Point2& p : q) qd.push_back(Approx(p));
    const double area = SignedArea(qd);
    for (size_t k = 0; k + 1 < stack.size(); k += 2) {
      double thick = 0.0;
      for (const glm::dvec2& p : qd) thick += planes[stack[k + 1]].At(p) - planes[stack[k]].At(p);
      volume += area * thick / 3.0;
    }

    // The part of the face whose bottom is at or below the ground (planes are affine: the
    // clip is exact, and within a face no other face crosses them).
    const Plane& bottom = planes[stack[0]];
    std::vector<FT> f(3);
    const Plane* terrain = ground_tris.empty() ? nullptr : ground_at(CGAL::centroid(q[0], q[1], q[2]));
    if (terrain != nullptr) {
      // Both planes move when the footprint's points are rounded: keep the margin of both.
      const FT margin(Above(0.0, (bottom.slope + terrain->slope) * rounding));
      for (int i = 0; i < 3; ++i) f[i] = terrain->At(q[i]) - margin - bottom.At(q[i]);
    } else {
      const FT flat(Below(ground.flat_z, bottom.slope * rounding));
      for (int i = 0; i < 3; ++i) f[i] = flat - bottom.At(q[i]);
    }
    Part part;
    part.polygon = ClipExact(q, f);
    for (const Point2& p : part.polygon) part.approx.push_back(Approx(p));
    if (part.polygon.size() < 3 || SignedArea(part.approx) <= 0.0) continue;
    reaches_ground = true;
    // Up through the intervals that touch the one below (a box standing on another: the
    // upper's floor is the lower's roof), on the whole face.
    size_t k = 1;
    while (k + 2 < stack.size()) {
      bool touches = true;
      for (const Point2& p : q) touches &= planes[stack[k + 1]].At(p) <= planes[stack[k]].At(p);
      if (!touches) break;
      k += 2;
    }
    part.plane = &planes[stack[k]];
    part.margin = part.plane->slope * rounding;
    part.top_max = -kInf;
    for (const Point2& p : part.polygon) {
      part.top.push_back(part.plane->At(p));
      part.top_max = std::max(part.top_max, CGAL::to_interval(part.top.back()).second);
    }
    parts.push_back(std::move(part));
  }
  out.solid_volume_m3 = std::abs(volume);
  if (!reaches_ground) {
    out.defect = SolidDefect::kRaised;
    return out;
  }

  // Tiers: the levels that keep the most volume, each with the parts' pieces up to it.
  ShareMargin(&parts);
  std::vector<double> levels = CandidateLevels(parts, ground_z + options.min_height_m);
  std::vector<double> areas(levels.size(), 0.0);
  for (size_t i = 0; i < levels.size(); ++i) {
    for (const Part& part : parts) areas[i] += PartArea(part, levels[i]);
  }
  // A level with no more area than a higher one is never worth it: the higher one keeps
  // the same footprint taller.
  {
    std::vector<double> kept_levels, kept_areas;
    double above = 0.0;
    for (size_t i = levels.size(); i-- > 0;) {
      if (areas[i] > above * (1.0 + 1e-9) + 1e-9) {
        kept_levels.push_back(levels[i]);
        kept_areas.push_back(areas[i]);
        above = areas[i];
      }
    }
    std::reverse(kept_levels.begin(), kept_levels.end());
    std::reverse(kept_areas.begin(), kept_areas.end());
    levels = std::move(kept_levels);
    areas = std::move(kept_areas);
  }
  // The volume counted is the occluders' inside the solid: above its lowest point (below it,
  // down to ground_z, the prisms stand in the ground).
  double lowest = s.vertices.front().z;
  for (const glm::dvec3& p : s.vertices) lowest = std::min(lowest, p.z);
  double below = std::max(ground_z, lowest);
  for (const size_t i : ChooseTierLevels(levels, areas, ground_z, options.max_tiers)) {
    const double level = levels[i];
    std::vector<std::vector<glm::dvec2>> pieces;
    for (const Part& part : parts) {
      std::vector<glm::dvec2> piece = PartAtLevel(part, level);
      if (piece.size() >= 3) pieces.push_back(std::move(piece));
    }
    double tier_area = 0.0;
    for (std::vector<glm::dvec2>& piece : MergeConvexPieces(std::move(pieces))) {
      const double a = SignedArea(piece);
      if (a < options.min_area_m2) continue;
      tier_area += a;
      out.occluders.push_back(Occluder25D{std::move(piece), level, 0});
    }
    if (tier_area <= 0.0) continue;
    out.occluder_volume_m3 += tier_area * std::max(0.0, level - below);
    below = std::max(below, level);
  }
  return out;
}

std::vector<Occluder25D> TerrainOccluders(const std::vector<std::array<glm::dvec3, 3>>& triangles,
                                          double quantum_m, int levels) {
  double extent = 1.0;
  for (const std::array<glm::dvec3, 3>& t : triangles) {
    for (const glm::dvec3& p : t) {
      if (std::isfinite(p.x) && std::isfinite(p.y)) extent = std::max({extent, std::abs(p.x), std::abs(p.y)});
    }
  }
  const double rounding = std::ldexp(extent, -50);
  // Every triangle a part: the ground is solid up to it, so over the part of it where it is
  // at or above a level, a prism up to that level stays in the ground.
  std::vector<Plane> planes;
  planes.reserve(triangles.size());
  std::vector<Part> parts;
  double lowest = kInf, highest = -kInf;
  for (const std::array<glm::dvec3, 3>& t : triangles) {
    bool finite = true;
    for (const glm::dvec3& p : t) finite &= std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
    if (!finite) continue;
    std::array<glm::dvec3, 3> c = t;
    const CGAL::Orientation o = CGAL::orientation(Point2(c[0].x, c[0].y), Point2(c[1].x, c[1].y),
                                                  Point2(c[2].x, c[2].y));
    if (o == CGAL::COLLINEAR) continue;  // a vertical triangle stands on no area
    if (o == CGAL::CLOCKWISE) std::swap(c[1], c[2]);
    planes.push_back(PlaneOf(c[0], c[1], c[2]));
    Part part;
    part.plane = &planes.back();
    part.margin = part.plane->slope * rounding;
    part.top_max = -kInf;
    for (const glm::dvec3& p : c) {
      part.polygon.emplace_back(p.x, p.y);
      part.approx.emplace_back(p.x, p.y);
      part.top.emplace_back(p.z);  // the plane at its own vertex, exactly
      part.top_max = std::max(part.top_max, p.z);
      lowest = std::min(lowest, p.z);
      highest = std::max(highest, p.z);
    }
    parts.push_back(std::move(part));
  }
  if (parts.empty() || !(highest > 0.0)) return {};
  ShareMargin(&parts);
  // Candidate levels: the multiples of the quantum from the lowest height (the first one above
  // z = 0 at least) to the highest; at most 2 * kMaxLevels of them, evenly thinned.
  const double q = quantum_m > 0.0 && std::isfinite(quantum_m) ? quantum_m : 1.0;
  const double first = std::max(std::floor(lowest / q), 1.0);
  const double last = std::floor(highest / q);
  std::vector<double> candidates;
  if (last >= first) {
    const double count = last - first + 1.0;
    const double step = std::max(1.0, std::ceil(count / static_cast<double>(2 * kMaxLevels)));
    for (double k = first; k <= last; k += step) candidates.push_back(k * q);
  }
  std::vector<double> heights, areas;
  double above = 0.0;
  for (size_t i = candidates.size(); i-- > 0;) {
    double area = 0.0;
    for (const Part& part : parts) area += PartArea(part, candidates[i]);
    if (area > above * (1.0 + 1e-9) + 1e-9) {
      heights.push_back(candidates[i]);
      areas.push_back(area);
      above = area;
    }
  }
  std::reverse(heights.begin(), heights.end());
  std::reverse(areas.begin(), areas.end());
  std::vector<Occluder25D> out;
  for (const size_t i : ChooseTierLevels(heights, areas, 0.0, levels)) {
    std::vector<std::vector<glm::dvec2>> pieces;
    for (const Part& part : parts) {
      std::vector<glm::dvec2> piece = PartAtLevel(part, heights[i]);
      if (piece.size() >= 3) pieces.push_back(std::move(piece));
    }
    for (std::vector<glm::dvec2>& piece : MergeConvexPieces(std::move(pieces))) {
      out.push_back(Occluder25D{std::move(piece), heights[i], 0});
    }
  }
  return out;
}

}  // namespace vistream::scenes
