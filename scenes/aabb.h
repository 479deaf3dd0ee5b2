#pragma once
// Axis-aligned boxes in double precision, scene-local metres, z up.

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/vec3.hpp>

namespace vistream::scenes {

struct Aabb {
  // An empty box: min > max, so Extend() of any point makes it that point.
  glm::dvec3 min{std::numeric_limits<double>::infinity()};
  glm::dvec3 max{-std::numeric_limits<double>::infinity()};

  bool Empty() const { return min.x > max.x || min.y > max.y || min.z > max.z; }
  void Extend(const glm::dvec3& p) {
    min = glm::dvec3(std::min(min.x, p.x), std::min(min.y, p.y), std::min(min.z, p.z));
    max = glm::dvec3(std::max(max.x, p.x), std::max(max.y, p.y), std::max(max.z, p.z));
  }
  void Extend(const Aabb& b) {
    if (b.Empty()) return;
    Extend(b.min);
    Extend(b.max);
  }
  glm::dvec3 Extent() const { return Empty() ? glm::dvec3(0.0) : max - min; }
  glm::dvec3 Centre() const { return 0.5 * (min + max); }
  // True when `b` lies inside this box (boundaries included).
  bool Contains(const Aabb& b) const {
    return b.min.x >= min.x && b.min.y >= min.y && b.min.z >= min.z && b.max.x <= max.x &&
           b.max.y <= max.y && b.max.z <= max.z;
  }
  bool Contains(const glm::dvec3& p) const {
    return p.x >= min.x && p.y >= min.y && p.z >= min.z && p.x <= max.x && p.y <= max.y &&
           p.z <= max.z;
  }
  bool Overlaps(const Aabb& b) const {
    return min.x <= b.max.x && b.min.x <= max.x && min.y <= b.max.y && b.min.y <= max.y &&
           min.z <= b.max.z && b.min.z <= max.z;
  }
  friend bool operator==(const Aabb&, const Aabb&) = default;
};

// The distance in metres between the closest points of two boxes (0 when they touch or overlap).
inline double BoxDistance(const Aabb& a, const Aabb& b) {
  const double dx = std::max({0.0, a.min.x - b.max.x, b.min.x - a.max.x});
  const double dy = std::max({0.0, a.min.y - b.max.y, b.min.y - a.max.y});
  const double dz = std::max({0.0, a.min.z - b.max.z, b.min.z - a.max.z});
  return std::sqrt(dx * dx + dy * dy + dz * dz);
}

}  // namespace vistream::scenes
