#include "tests/test_util.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "tests/temp_dir.h"

namespace vistream::testing {

std::string TempDir() { return ProcessTempDir(); }

namespace {

double SegmentDistance(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b) {
  const glm::dvec2 d = b - a;
  const double len2 = glm::dot(d, d);
  const double t = len2 > 0.0 ? std::clamp(glm::dot(p - a, d) / len2, 0.0, 1.0) : 0.0;
  return glm::length(p - (a + d * t));
}

bool SegmentsCross(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c, const glm::dvec2& d) {
  auto orient = [](const glm::dvec2& p, const glm::dvec2& q, const glm::dvec2& r) {
    return (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x);
  };
  const double o1 = orient(a, b, c), o2 = orient(a, b, d), o3 = orient(c, d, a), o4 = orient(c, d, b);
  return ((o1 > 0) != (o2 > 0)) && ((o3 > 0) != (o4 > 0));
}

}  // namespace

bool InsidePolygon(const std::vector<glm::dvec2>& poly, const glm::dvec2& p) {
  bool in = false;
  for (size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++) {
    const glm::dvec2 &u = poly[i], &v = poly[j];
    if ((u.y > p.y) != (v.y > p.y) && p.x < (v.x - u.x) * (p.y - u.y) / (v.y - u.y) + u.x) in = !in;
  }
  return in;
}

bool SegmentClearOfOccluders(const scenes::Scene& scene, const glm::dvec2& a, const glm::dvec2& b,
                             double clearance) {
  for (const scenes::Occluder25D& oc : scene.occluders) {
    const auto& fp = oc.footprint;
    if (InsidePolygon(fp, a) || InsidePolygon(fp, b)) return false;
    for (size_t i = 0; i < fp.size(); ++i) {
      const glm::dvec2 &u = fp[i], &v = fp[(i + 1) % fp.size()];
      if (SegmentsCross(a, b, u, v)) return false;
      if (SegmentDistance(u, a, b) < clearance || SegmentDistance(a, u, v) < clearance ||
          SegmentDistance(b, u, v) < clearance) {
        return false;
      }
    }
  }
  return true;
}

bool SegmentClearOfPrisms(const glm::dvec3& p, const glm::dvec3& q, const std::vector<scenes::Occluder25D>& prisms,
                          double margin) {
  const glm::dvec2 lo = glm::min(glm::dvec2(p), glm::dvec2(q)) - margin;
  const glm::dvec2 hi = glm::max(glm::dvec2(p), glm::dvec2(q)) + margin;
  for (const scenes::Occluder25D& oc : prisms) {
    const auto& fp = oc.footprint;
    glm::dvec2 bmin(INFINITY), bmax(-INFINITY);
    for (const glm::dvec2& v : fp) bmin = glm::min(bmin, v), bmax = glm::max(bmax, v);
    if (bmin.x > hi.x || bmax.x < lo.x || bmin.y > hi.y || bmax.y < lo.y) continue;
    // The part of the segment below the prism's top (plus the margin).
    const double h = oc.height + margin;
    if (p.z > h && q.z > h) continue;
    double t0 = 0, t1 = 1;
    if (p.z > h) t0 = (h - p.z) / (q.z - p.z);
    if (q.z > h) t1 = (h - p.z) / (q.z - p.z);
    const glm::dvec2 a = glm::dvec2(p) + (glm::dvec2(q) - glm::dvec2(p)) * t0;
    const glm::dvec2 b = glm::dvec2(p) + (glm::dvec2(q) - glm::dvec2(p)) * t1;
    if (fp.size() >= 3 && (InsidePolygon(fp, a) || InsidePolygon(fp, b))) return false;
    for (size_t i = 0; i < fp.size(); ++i) {
      const glm::dvec2 &u = fp[i], &v = fp[(i + 1) % fp.size()];
      if (SegmentsCross(a, b, u, v)) return false;
      if (SegmentDistance(u, a, b) <= margin || SegmentDistance(a, u, v) <= margin ||
          SegmentDistance(b, u, v) <= margin) {
        return false;
      }
    }
  }
  return true;
}

uint64_t SceneHash(const scenes::Scene& scene) {
  uint64_t h = 1469598103934665603ULL;
  auto mix = [&h](const void* data, size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (size_t i = 0; i < n; ++i) h = (h ^ p[i]) * 1099511628211ULL;
  };
  for (const auto& o : scene.objects) {
    mix(o.mesh.positions.data(), o.mesh.positions.size() * sizeof(glm::vec3));
    mix(o.mesh.normals.data(), o.mesh.normals.size() * sizeof(glm::vec3));
    mix(o.mesh.indices.data(), o.mesh.indices.size() * sizeof(uint32_t));
  }
  for (const auto& oc : scene.occluders) {
    mix(oc.footprint.data(), oc.footprint.size() * sizeof(glm::dvec2));
    mix(&oc.height, sizeof(double));
    mix(&oc.object, sizeof(oc.object));
  }
  mix(&scene.origin, sizeof(scene.origin));
  return h;
}

scenes::Scene RandomGridScene(scenes::Rng& rng) {
  auto rect = [](double x0, double y0, double x1, double y1, double h) {
    return scenes::Occluder25D{{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}, h, 0};
  };
  scenes::Scene s;
  const int n = 5 + static_cast<int>(rng.Below(40));
  for (int k = 0; k < n; ++k) {
    const double x = std::floor(rng.Uniform(12, 70)), y = std::floor(rng.Uniform(-40, 50));
    const double w = 1 + std::floor(rng.Uniform(0, 12)), d = 1 + std::floor(rng.Uniform(0, 12));
    const double h = std::floor(rng.Uniform(1, 30));
    if (rng.Chance(0.15)) {
      s.occluders.push_back(scenes::Occluder25D{{{x, y}, {x + w, y + d}, {x, y}}, h, 0});  // a thin wall
    } else {
      s.occluders.push_back(rect(x, y, x + w, y + d, h));
    }
    if (rng.Chance(0.3)) s.occluders.push_back(rect(x + w, y, x + 2 * w, y + d, h + 3));  // a neighbour
  }
  return s;
}

scenes::Aabb RandomGridBox(scenes::Rng& rng) {
  const double x = std::floor(rng.Uniform(30, 90)), y = std::floor(rng.Uniform(-30, 40));
  const double w = 1 + std::floor(rng.Uniform(0, 10)), d = 1 + std::floor(rng.Uniform(0, 10));
  const double h = std::floor(rng.Uniform(1, 25));
  return scenes::Aabb{glm::dvec3(x, y, 0), glm::dvec3(x + w, y + d, h)};
}

scenes::Aabb Box(double x0, double y0, double z0, double x1, double y1, double z1) {
  return scenes::Aabb{glm::dvec3(x0, y0, z0), glm::dvec3(x1, y1, z1)};
}

scenes::Occluder25D Rect(double x0, double y0, double x1, double y1, double h) {
  return scenes::Occluder25D{{{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}}, h, 0};
}

}  // namespace vistream::testing
