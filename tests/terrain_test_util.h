#pragma once
// Hand-made terrain for tests: a TIN over a rectangle with heights from a function, optionally
// closed into a solid (the ground is solid beneath the terrain, scenes/scene.h).

#include <cmath>
#include <functional>
#include <limits>
#include <optional>
#include <utility>
#include <vector>

#include <glm/vec2.hpp>

#include "scenes/mesh.h"
#include "scenes/scene.h"
#include "scenes/terrain.h"

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

// The simplest conservative terrain occluders: a ground-up prism for each up-facing triangle of
// each terrain object, its footprint the triangle, its height the triangle's lowest vertex
// (inside the solid ground beneath it).
inline void AddTerrainOccluders(scenes::Scene* scene) {
  for (scenes::ObjectId id : scene->terrain) {
    const scenes::Mesh& m = scene->objects[id].mesh;
    for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
      scenes::Occluder25D o;
      o.object = id;
      o.height = std::numeric_limits<double>::infinity();
      for (int k = 0; k < 3; ++k) {
        const glm::vec3& v = m.positions[m.indices[t + k]];
        o.footprint.emplace_back(v.x, v.y);
        o.height = std::min(o.height, static_cast<double>(v.z));
      }
      if (scenes::SignedArea(o.footprint) > 0.0 && o.height > 0.0) scene->occluders.push_back(std::move(o));
    }
  }
}

// A ridge 20 m high along x = 0 between two valleys about 1.5 to 3.5 m up, over [-140, 140]^2 in
// 10 m quads: the ground of the hilly test town.
inline double Ridge(double x, double y) {
  return 1.5 + 20.0 * std::exp(-(x / 22.0) * (x / 22.0)) + 1.0 + std::sin(0.17 * x + 0.3) * std::cos(0.13 * y);
}

// Two 4 x 4 m sheds 3 m high on flat ground, "west shed" at x -90 and "east shed" at x 90, each
// in one of the ridge's valleys once OnTheRidge sets them there.
inline scenes::Scene TwoSheds() {
  scenes::Scene flat;
  flat.name = "sheds";
  for (const double x : {-90.0, 90.0}) {
    scenes::Mesh m;
    const std::vector<glm::dvec2> square{{x - 2, -2}, {x + 2, -2}, {x + 2, 2}, {x - 2, 2}};
    scenes::AppendConvexPrism(square, 0.0, 3.0, &m);
    flat.AddObject(x < 0 ? "west shed" : "east shed", std::move(m));
  }
  return flat;
}

// `flat` (buildings standing on z = 0) set on the ridge: a closed terrain solid (down to z = -5)
// added as the last object and the terrain; every other object's vertices above z = 0 raised by
// the highest ground under its block (the objects whose boxes touch it, and theirs: a terrace,
// a tower on its building), so floors stay at 0, below the ground, and walls reach above it;
// their occluders raised with them (one raise a block: a tower still stands on its building),
// and the terrain's occluders (AddTerrainOccluders).
inline scenes::Scene OnTheRidge(const scenes::Scene& flat) {
  scenes::Scene s;
  s.name = flat.name + "-on-a-ridge";
  s.origin = flat.origin;
  scenes::Scene ground;
  ground.terrain.push_back(ground.AddObject("ground", TinMesh(Ridge, {-140, -140}, {140, 140}, 28, 28, -5.0)));
  const scenes::TerrainHeight height(ground);
  // Blocks: objects whose boxes touch (within 1 cm), joined.
  const size_t n = flat.objects.size();
  std::vector<size_t> root(n);
  for (size_t k = 0; k < n; ++k) root[k] = k;
  auto find = [&root](size_t k) {
    while (root[k] != k) k = root[k] = root[root[k]];
    return k;
  };
  for (size_t a = 0; a < n; ++a) {
    scenes::Aabb grown = flat.objects[a].bounds;
    grown.min -= glm::dvec3(0.01);
    grown.max += glm::dvec3(0.01);
    for (size_t b = a + 1; b < n; ++b) {
      if (grown.Overlaps(flat.objects[b].bounds)) root[find(a)] = find(b);
    }
  }
  std::vector<scenes::Aabb> block(n);
  for (size_t k = 0; k < n; ++k) block[find(k)].Extend(flat.objects[k].bounds);
  std::vector<double> raise(n, 0.0);
  for (const scenes::Object& o : flat.objects) {
    const scenes::Aabb& b = block[find(o.id)];
    // On the 1/256 m grid: the raised float tops stay exactly where the occluders' tops go.
    raise[o.id] = std::ceil(height.Range(glm::dvec2(b.min), glm::dvec2(b.max)).max * 256.0) / 256.0;
    scenes::Mesh m = o.mesh;
    for (glm::vec3& v : m.positions) {
      if (v.z > 0.0f) v.z += static_cast<float>(raise[o.id]);
    }
    s.AddObject(o.name, std::move(m));
  }
  for (scenes::Occluder25D o : flat.occluders) {
    o.height += raise[o.object];
    s.occluders.push_back(std::move(o));
  }
  s.terrain.push_back(s.AddObject("ground", ground.objects[0].mesh));
  AddTerrainOccluders(&s);
  return s;
}
}  // namespace vistream::testing
