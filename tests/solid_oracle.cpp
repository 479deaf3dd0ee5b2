#include "tests/solid_oracle.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "tests/test_util.h"

namespace vistream::testing {

namespace {

// Möller–Trumbore; nullopt when the hit is too close to call (near an edge, the ray in the
// plane, or the point on the triangle).
enum class Hit { kNo, kYes, kUnsure };
Hit RayHitsTriangle(const glm::dvec3& o, const glm::dvec3& d, const glm::dvec3& a, const glm::dvec3& b,
                    const glm::dvec3& c) {
  const glm::dvec3 e1 = b - a, e2 = c - a;
  const glm::dvec3 h = glm::cross(d, e2);
  const double det = glm::dot(e1, h);
  const double scale = glm::length(e1) * glm::length(e2);
  if (std::abs(det) < 1e-12 * scale) {
    // Parallel: a miss unless the ray lies in the plane, which a random direction never does
    // but a point on the face might.
    const double off = glm::dot(o - a, glm::normalize(glm::cross(e1, e2)));
    return std::abs(off) < 1e-9 ? Hit::kUnsure : Hit::kNo;
  }
  const double f = 1.0 / det;
  const glm::dvec3 s = o - a;
  const double u = f * glm::dot(s, h);
  const glm::dvec3 q = glm::cross(s, e1);
  const double v = f * glm::dot(d, q);
  const double t = f * glm::dot(e2, q);
  const double tol = 1e-9;
  if (u < -tol || v < -tol || u + v > 1 + tol || t < -tol) return Hit::kNo;
  if (u < tol || v < tol || u + v > 1 - tol || t < tol) return Hit::kUnsure;
  return Hit::kYes;
}

}  // namespace

bool InsideSolid(const scenes::SolidMesh& s, const glm::dvec3& p, scenes::Rng* rng) {
  for (int attempt = 0; attempt < 20; ++attempt) {
    // A random direction, away from the axes and from the horizontal.
    const double phi = rng->Uniform(0.0, 2.0 * std::numbers::pi);
    const double z = rng->Uniform(0.2, 0.9) * (rng->Uniform() < 0.5 ? -1.0 : 1.0);
    const double r = std::sqrt(1.0 - z * z);
    const glm::dvec3 d(r * std::cos(phi), r * std::sin(phi), z);
    int crossings = 0;
    bool unsure = false;
    for (const auto& t : s.triangles) {
      const Hit h = RayHitsTriangle(p, d, s.vertices[t[0]], s.vertices[t[1]], s.vertices[t[2]]);
      if (h == Hit::kUnsure) {
        unsure = true;
        break;
      }
      crossings += h == Hit::kYes;
    }
    if (!unsure) return crossings % 2 == 1;
  }
  ADD_FAILURE() << "no clean ray from (" << p.x << ", " << p.y << ", " << p.z << ")";
  return false;
}

glm::dvec2 PointIn(const std::vector<glm::dvec2>& poly, scenes::Rng* rng) {
  glm::dvec2 lo(INFINITY), hi(-INFINITY);
  for (const glm::dvec2& q : poly) {
    lo = glm::min(lo, q);
    hi = glm::max(hi, q);
  }
  for (;;) {
    const glm::dvec2 p(rng->Uniform(lo.x, hi.x), rng->Uniform(lo.y, hi.y));
    if (InsidePolygon(poly, p)) return p;
  }
}

}  // namespace vistream::testing
