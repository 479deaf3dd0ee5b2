#include "scenes/polygon_set.h"

#include <CGAL/Boolean_set_operations_2.h>
#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_set_2.h>
#include <CGAL/Polygon_with_holes_2.h>
#include <absl/strings/str_cat.h>

#include <iterator>

namespace vistream::scenes {

namespace {

using K = CGAL::Exact_predicates_exact_constructions_kernel;
using Polygon = CGAL::Polygon_2<K>;
using Holed = CGAL::Polygon_with_holes_2<K>;

Polygon ToCgal(const Ring& ring) {
  Polygon p;
  for (const glm::dvec2& v : ring) p.push_back(K::Point_2(v.x, v.y));
  return p;
}

Holed ToCgal(const PolygonWithHoles& poly) {
  Holed h(ToCgal(poly.outer));
  for (const Ring& hole : poly.holes) h.add_hole(ToCgal(hole));
  return h;
}

Ring FromCgal(const Polygon& p) {
  Ring out;
  out.reserve(p.size());
  for (auto v = p.vertices_begin(); v != p.vertices_end(); ++v) {
    out.emplace_back(CGAL::to_double(v->x()), CGAL::to_double(v->y()));
  }
  return out;
}

std::vector<PolygonWithHoles> FromCgal(const CGAL::Polygon_set_2<K>& set) {
  std::vector<Holed> pieces;
  set.polygons_with_holes(std::back_inserter(pieces));
  std::vector<PolygonWithHoles> out;
  for (const Holed& h : pieces) {
    PolygonWithHoles p;
    p.outer = FromCgal(h.outer_boundary());
    for (auto hole = h.holes_begin(); hole != h.holes_end(); ++hole) {
      p.holes.push_back(FromCgal(*hole));
    }
    out.push_back(std::move(p));
  }
  return out;
}

}  // namespace

absl::StatusOr<std::vector<PolygonWithHoles>> Difference(const PolygonWithHoles& from,
                                                         const std::vector<PolygonWithHoles>& cut) {
  try {
    CGAL::Polygon_set_2<K> set(ToCgal(from));
    for (const PolygonWithHoles& c : cut) set.difference(ToCgal(c));
    return FromCgal(set);
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("polygon difference failed: ", e.what()));
  }
}

absl::StatusOr<std::vector<PolygonWithHoles>> Union(const std::vector<PolygonWithHoles>& pieces) {
  try {
    std::vector<Holed> in;
    in.reserve(pieces.size());
    for (const PolygonWithHoles& p : pieces) in.push_back(ToCgal(p));
    CGAL::Polygon_set_2<K> set;
    set.join(in.begin(), in.end());  // the aggregated union: one sweep, not one join a piece
    return FromCgal(set);
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("polygon union failed: ", e.what()));
  }
}

}  // namespace vistream::scenes
