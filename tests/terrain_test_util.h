#pragma once
// Hand-made terrain for tests: a TIN over a rectangle with heights from a function, optionally
// closed into a solid (the ground is solid beneath the terrain, scenes/scene.h).

#include <cmath>
#include <functional>
#include <optional>
#include <utility>
#include <vector>

#include <glm/vec2.hpp>

#include "scenes/mesh.h"
#include "scenes/scene.h"

namespace vistream::testing {

// A TIN over [lo, hi] of nx x ny quads with height h(x, y) at each vertex (scene-local metres),
// each quad split along its lower-left to upper-right diagonal, triangles counter-clockwise
// seen from above. With `bottom`: closed into a solid by walls down to z = *bottom round its
// edge and a floor there facing down.
inline scenes::Mesh TinMesh(const std::function<double(double, double)>& h, glm::dvec2 lo, glm::dvec2 hi, int nx,
                            int ny, std::optional<double> bottom = std::nullopt) {
  scenes::Mesh m;
  auto at = [&](int i, int j) {
    return glm::dvec2(lo.x + (hi.x - lo.x) * i / nx, lo.y + (hi.y - lo.y) * j / ny);
  };
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const glm::dvec2 p = at(i, j);
      scenes::AppendVertex(p, h(p.x, p.y), glm::vec3(0, 0, 1), &m);
    }
  }
  auto v = [&](int i, int j) { return static_cast<uint32_t>(j * (nx + 1) + i); };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      m.indices.insert(m.indices.end(), {v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j), v(i + 1, j + 1), v(i, j + 1)});
    }
  }
  if (!bottom.has_value()) return m;
  // The edge, counter-clockwise from above: each step a wall quad facing out.
  std::vector<std::pair<int, int>> ring;
  for (int i = 0; i < nx; ++i) ring.emplace_back(i, 0);
  for (int j = 0; j < ny; ++j) ring.emplace_back(nx, j);
  for (int i = nx; i > 0; --i) ring.emplace_back(i, ny);
  for (int j = ny; j > 0; --j) ring.emplace_back(0, j);
  for (size_t k = 0; k < ring.size(); ++k) {
    const auto [ai, aj] = ring[k];
    const auto [bi, bj] = ring[(k + 1) % ring.size()];
    const glm::dvec2 a = at(ai, aj), b = at(bi, bj);
    const glm::vec3 n(static_cast<float>(b.y - a.y), static_cast<float>(a.x - b.x), 0.0f);
    const glm::vec3 unit = n / std::sqrt(n.x * n.x + n.y * n.y);
    const uint32_t a0 = scenes::AppendVertex(a, *bottom, unit, &m), b0 = scenes::AppendVertex(b, *bottom, unit, &m);
    const uint32_t b1 = scenes::AppendVertex(b, h(b.x, b.y), unit, &m), a1 = scenes::AppendVertex(a, h(a.x, a.y), unit, &m);
    m.indices.insert(m.indices.end(), {a0, b0, b1, a0, b1, a1});
  }
  const glm::vec3 down(0, 0, -1);
  const uint32_t f0 = scenes::AppendVertex(lo, *bottom, down, &m), f1 = scenes::AppendVertex({hi.x, lo.y}, *bottom, down, &m);
  const uint32_t f2 = scenes::AppendVertex(hi, *bottom, down, &m), f3 = scenes::AppendVertex({lo.x, hi.y}, *bottom, down, &m);
  m.indices.insert(m.indices.end(), {f0, f2, f1, f0, f3, f2});
  return m;
}

// A scene of one terrain object (object 0) made by TinMesh, and nothing else.
inline scenes::Scene TerrainScene(const std::function<double(double, double)>& h, glm::dvec2 lo, glm::dvec2 hi,
                                  int nx, int ny) {
  scenes::Scene s;
  s.name = "terrain";
  s.terrain.push_back(s.AddObject("ground", TinMesh(h, lo, hi, nx, ny)));
  return s;
}

}  // namespace vistream::testing
