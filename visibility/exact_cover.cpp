#include "visibility/exact_cover.h"

#include <vector>

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Polygon_2.h>
#include <CGAL/Polygon_set_2.h>

namespace vistream::visibility {

namespace {

using Kernel = CGAL::Exact_predicates_exact_constructions_kernel;
using FT = Kernel::FT;
using Point = Kernel::Point_2;
using Polygon = CGAL::Polygon_2<Kernel>;
using PolygonSet = CGAL::Polygon_set_2<Kernel>;

// RS clipped to {side * g_k >= 0 for every k of g}: a convex polygon, counter-clockwise,
// empty when it has no area.
Polygon OneSide(const Blockers& blockers, const Blocker& g, int side) {
  std::vector<Point> poly = {Point(0, 0), Point(1, 0), Point(1, 1), Point(0, 1)};
  std::vector<Point> out;
  std::vector<FT> val;
  for (uint32_t k = g.begin; k < g.end && poly.size() >= 3; ++k) {
    const BlockerCoeff& c = blockers.coeffs[k];
    const FT a(c.a), b(c.b), cc(c.c);
    val.clear();
    for (const Point& p : poly) val.push_back(side * (a + b * p.x() + cc * p.y()));
    out.clear();
    for (size_t i = 0; i < poly.size(); ++i) {
      const size_t n = (i + 1) % poly.size();
      const CGAL::Sign si = CGAL::sign(val[i]), sn = CGAL::sign(val[n]);
      if (si != CGAL::NEGATIVE) out.push_back(poly[i]);
      if ((si == CGAL::POSITIVE && sn == CGAL::NEGATIVE) || (si == CGAL::NEGATIVE && sn == CGAL::POSITIVE)) {
        const FT t = val[i] / (val[i] - val[n]);
        out.push_back(Point(poly[i].x() + t * (poly[n].x() - poly[i].x()), poly[i].y() + t * (poly[n].y() - poly[i].y())));
      }
    }
    poly.swap(out);
  }
  Polygon result(poly.begin(), poly.end());
  if (poly.size() < 3 || CGAL::sign(result.area()) != CGAL::POSITIVE) return Polygon();
  return result;
}

bool FreeSetEmpties(const Blockers& blockers, PolygonSet free_rays) {
  // Widest blockers first: they empty the free set soonest.
  for (const Blocker& g : blockers.groups) {
    if (free_rays.is_empty()) return true;
    PolygonSet passing;
    for (int side : {1, -1}) {
      const Polygon p = OneSide(blockers, g, side);
      if (!p.is_empty()) passing.join(p);
    }
    free_rays.intersection(passing);
  }
  return free_rays.is_empty();
}

}  // namespace

bool ExactlyCovered(const Blockers& blockers) {
  if (blockers.groups.empty()) return false;
  const Point square[] = {Point(0, 0), Point(1, 0), Point(1, 1), Point(0, 1)};
  return FreeSetEmpties(blockers, PolygonSet(Polygon(std::begin(square), std::end(square))));
}

bool ExactlyCovered(const Blockers& blockers, const std::vector<uint8_t>& raster, uint32_t n) {
  if (blockers.groups.empty()) return false;
  // The clear pixels, one rectangle per run along a row.
  std::vector<Polygon> runs;
  for (uint32_t j = 0; j < n; ++j) {
    for (uint32_t i = 0; i < n;) {
      if (raster[static_cast<size_t>(j) * n + i] != 0) {
        ++i;
        continue;
      }
      uint32_t e = i;
      while (e < n && raster[static_cast<size_t>(j) * n + e] == 0) ++e;
      // n is a power of two, so these quotients are exact doubles.
      const double nd = n;
      const FT u0(i / nd), u1(e / nd), v0(j / nd), v1((j + 1) / nd);
      const Point r[] = {Point(u0, v0), Point(u1, v0), Point(u1, v1), Point(u0, v1)};
      runs.emplace_back(std::begin(r), std::end(r));
      i = e;
    }
  }
  if (runs.empty()) return true;
  PolygonSet free_rays;
  free_rays.join(runs.begin(), runs.end());
  return FreeSetEmpties(blockers, std::move(free_rays));
}

}  // namespace vistream::visibility
