#include "scenes/mesh.h"

#include <cassert>

#include <glm/geometric.hpp>

namespace vistream::scenes {

Aabb Mesh::Bounds() const {
  Aabb box;
  for (const glm::vec3& p : positions) box.Extend(glm::dvec3(p));
  return box;
}

double SignedArea(std::span<const glm::dvec2> polygon) {
  double twice = 0.0;
  const size_t n = polygon.size();
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2& a = polygon[i];
    const glm::dvec2& b = polygon[(i + 1) % n];
    twice += a.x * b.y - a.y * b.x;
  }
  return 0.5 * twice;
}

bool IsConvexCcw(std::span<const glm::dvec2> polygon) {
  const size_t n = polygon.size();
  if (n < 3 || SignedArea(polygon) <= 0.0) return false;
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2 a = polygon[(i + 1) % n] - polygon[i];
    const glm::dvec2 b = polygon[(i + 2) % n] - polygon[(i + 1) % n];
    if (a.x * b.y - a.y * b.x < 0.0) return false;
  }
  return true;
}

void AppendConvexPrism(std::span<const glm::dvec2> footprint, double z0, double z1, Mesh* mesh) {
  assert(footprint.size() >= 3 && z1 > z0);
  const size_t n = footprint.size();
  auto vertex = [&](const glm::dvec2& p, double z, const glm::vec3& normal) {
    mesh->positions.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y),
                                 static_cast<float>(z));
    mesh->normals.push_back(normal);
    return static_cast<uint32_t>(mesh->positions.size() - 1);
  };
  // Walls: one quad per edge, its own four vertices so that shading stays flat.
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2& a = footprint[i];
    const glm::dvec2& b = footprint[(i + 1) % n];
    const glm::dvec2 d = b - a;
    const double len = glm::length(d);
    const glm::vec3 normal =
        len > 0.0 ? glm::vec3(static_cast<float>(d.y / len), static_cast<float>(-d.x / len), 0.f)
                  : glm::vec3(1.f, 0.f, 0.f);
    const uint32_t a0 = vertex(a, z0, normal), b0 = vertex(b, z0, normal);
    const uint32_t b1 = vertex(b, z1, normal), a1 = vertex(a, z1, normal);
    mesh->indices.insert(mesh->indices.end(), {a0, b0, b1, a0, b1, a1});
  }
  // Roof (normal up, CCW from above) and floor (normal down, reversed): triangle fans.
  const uint32_t roof = static_cast<uint32_t>(mesh->positions.size());
  for (const glm::dvec2& p : footprint) vertex(p, z1, glm::vec3(0.f, 0.f, 1.f));
  const uint32_t floor = static_cast<uint32_t>(mesh->positions.size());
  for (const glm::dvec2& p : footprint) vertex(p, z0, glm::vec3(0.f, 0.f, -1.f));
  for (uint32_t i = 1; i + 1 < n; ++i) {
    mesh->indices.insert(mesh->indices.end(), {roof, roof + i, roof + i + 1});
    mesh->indices.insert(mesh->indices.end(), {floor, floor + i + 1, floor + i});
  }
}

}  // namespace vistream::scenes
