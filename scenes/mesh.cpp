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

uint32_t AppendVertex(const glm::dvec2& p, double z, const glm::vec3& normal, Mesh* mesh) {
  mesh->positions.emplace_back(static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(z));
  mesh->normals.push_back(normal);
  return static_cast<uint32_t>(mesh->positions.size() - 1);
}

void AppendWalls(std::span<const glm::dvec2> ring, double z0, double z1, Mesh* mesh) {
  const size_t n = ring.size();
  for (size_t i = 0; i < n; ++i) {
    const glm::dvec2& a = ring[i];
    const glm::dvec2& b = ring[(i + 1) % n];
    const glm::dvec2 d = b - a;
    const double len = glm::length(d);
    const glm::vec3 normal =
        len > 0.0 ? glm::vec3(static_cast<float>(d.y / len), static_cast<float>(-d.x / len), 0.f)
                  : glm::vec3(1.f, 0.f, 0.f);
    const uint32_t a0 = AppendVertex(a, z0, normal, mesh), b0 = AppendVertex(b, z0, normal, mesh);
    const uint32_t b1 = AppendVertex(b, z1, normal, mesh), a1 = AppendVertex(a, z1, normal, mesh);
    mesh->indices.insert(mesh->indices.end(), {a0, b0, b1, a0, b1, a1});
  }
}

void AppendConvexPrism(std::span<const glm::dvec2> footprint, double z0, double z1, Mesh* mesh) {
  assert(footprint.size() >= 3 && z1 > z0);
  const size_t n = footprint.size();
  AppendWalls(footprint, z0, z1, mesh);
  // Roof (normal up, CCW from above) and floor (normal down, reversed): triangle fans.
  const uint32_t roof = static_cast<uint32_t>(mesh->positions.size());
  for (const glm::dvec2& p : footprint) AppendVertex(p, z1, glm::vec3(0.f, 0.f, 1.f), mesh);
  const uint32_t floor = static_cast<uint32_t>(mesh->positions.size());
  for (const glm::dvec2& p : footprint) AppendVertex(p, z0, glm::vec3(0.f, 0.f, -1.f), mesh);
  for (uint32_t i = 1; i + 1 < n; ++i) {
    mesh->indices.insert(mesh->indices.end(), {roof, roof + i, roof + i + 1});
    mesh->indices.insert(mesh->indices.end(), {floor, floor + i + 1, floor + i});
  }
}

}  // namespace vistream::scenes
