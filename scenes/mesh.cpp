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

glm::dvec3 NewellNormal(std::span<const glm::dvec3> ring) {
  glm::dvec3 n(0.0);
  for (size_t i = 0; i < ring.size(); ++i) {
    const glm::dvec3& a = ring[i];
    const glm::dvec3& b = ring[(i + 1) % ring.size()];
    n.x += (a.y - b.y) * (a.z + b.z);
    n.y += (a.z - b.z) * (a.x + b.x);
    n.z += (a.x - b.x) * (a.y + b.y);
  }
  return n;
}

glm::dvec3 ClosestPointOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  if (!(denom > 0.0)) return a;
  return a + ab * (vb / denom) + ac * (vc / denom);
}

}  // namespace vistream::scenes
