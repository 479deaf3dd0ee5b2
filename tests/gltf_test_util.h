#pragma once
// Helpers of the glTF input tests: a source mesh, triangle sets compared as sets, and a .glb
// written by hand (for extensions no writer here produces).
#include <algorithm>
#include <array>
#include <cstdlib>
#include <fstream>
#include <string>
#include <vector>

#include <glm/geometric.hpp>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "scenes/building.h"
#include "scenes/scene.h"

namespace vistream::scenes::gltf_test {

using nlohmann::json;
using Triangle = std::array<glm::dvec3, 3>;

// The source: two buildings' meshes, in glTF's frame (y-up): (x, y, z) z-up = (x, -z, y).
struct SourceMesh {
  std::string name;
  std::vector<float> xyz;  // glTF frame
  std::vector<uint32_t> indices;
};
inline std::vector<SourceMesh> Source() {
  Scene s;
  const glm::dvec2 u(1, 0), v(0, 1);
  AddBuilding(&s, "house", {{FrameRect({3.25, 1.5}, u, v, 0, 10, 0, 8), 0, 12}});
  AddBuilding(&s, "tower", {{FrameRect({30.25, 5.5}, u, v, 0, 20, 0, 20), 0, 30},
                            {FrameRect({30.25, 5.5}, u, v, 5, 15, 5, 15), 30, 80.5}});
  std::vector<SourceMesh> out;
  for (const Object& o : s.objects) {
    SourceMesh m{o.name, {}, o.mesh.indices};
    for (const glm::vec3& p : o.mesh.positions) m.xyz.insert(m.xyz.end(), {p.x, p.z, -p.y});
    out.push_back(std::move(m));
  }
  return out;
}

// A triangle list as a canonical set: each triangle rotated to start at its smallest corner
// (winding kept), the list sorted. z-up world coordinates.
inline bool Less(const glm::dvec3& a, const glm::dvec3& b) {
  return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
}
inline std::vector<Triangle> Canonical(std::vector<Triangle> tris) {
  for (Triangle& t : tris) {
    const int k = Less(t[1], t[0]) ? (Less(t[2], t[1]) ? 2 : 1) : (Less(t[2], t[0]) ? 2 : 0);
    std::rotate(t.begin(), t.begin() + k, t.end());
  }
  std::sort(tris.begin(), tris.end(), [](const Triangle& a, const Triangle& b) {
    for (int i = 0; i < 3; ++i) {
      if (a[i] != b[i]) return Less(a[i], b[i]);
    }
    return false;
  });
  return tris;
}
inline std::vector<Triangle> SourceTriangles(const SourceMesh& m) {
  std::vector<Triangle> tris;
  auto p = [&m](uint32_t i) { return glm::dvec3(m.xyz[3 * i], -m.xyz[3 * i + 2], m.xyz[3 * i + 1]); };
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) tris.push_back({p(m.indices[t]), p(m.indices[t + 1]), p(m.indices[t + 2])});
  return Canonical(tris);
}
inline std::vector<Triangle> LoadedTriangles(const Scene& s, size_t object) {
  std::vector<Triangle> tris;
  const Mesh& m = s.objects[object].mesh;
  auto p = [&](uint32_t i) { return s.origin + glm::dvec3(m.positions[i]); };
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) tris.push_back({p(m.indices[t]), p(m.indices[t + 1]), p(m.indices[t + 2])});
  return Canonical(tris);
}
inline void ExpectSameTriangles(const std::vector<Triangle>& want, const std::vector<Triangle>& got, double tolerance) {
  ASSERT_EQ(want.size(), got.size());
  for (size_t t = 0; t < want.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(glm::distance(want[t][k], got[t][k]), 0.0, tolerance) << "triangle " << t << " corner " << k;
    }
  }
}

// A .glb written by hand: JSON and one BIN chunk (glTF 2.0, 4.4).
struct GlbBuilder {
  json j = {{"asset", {{"version", "2.0"}, {"generator", "vistream tests"}}},
            {"scenes", {{{"nodes", json::array()}}}},
            {"scene", 0}};
  std::string bin;

  size_t Append(const void* data, size_t bytes) {
    while (bin.size() % 4) bin.push_back('\0');
    const size_t at = bin.size();
    bin.append(static_cast<const char*>(data), bytes);
    return at;
  }
  int View(size_t offset, size_t length, int buffer = 0) {
    j["bufferViews"].push_back({{"buffer", buffer}, {"byteOffset", offset}, {"byteLength", length}});
    return static_cast<int>(j["bufferViews"].size() - 1);
  }
  int Accessor(json a) {
    j["accessors"].push_back(std::move(a));
    return static_cast<int>(j["accessors"].size() - 1);
  }
  void Node(const std::string& name, json primitive) {
    j["meshes"].push_back({{"primitives", {std::move(primitive)}}});
    j["nodes"].push_back({{"name", name}, {"mesh", j["meshes"].size() - 1}});
    j["scenes"][0]["nodes"].push_back(j["nodes"].size() - 1);
  }
  void Uses(const std::string& extension, bool required) {
    j["extensionsUsed"].push_back(extension);
    if (required) j["extensionsRequired"].push_back(extension);
  }
  std::string Bytes() {
    if (!j.contains("buffers")) j["buffers"] = json::array({json::object()});
    while (bin.size() % 4) bin.push_back('\0');
    j["buffers"][0]["byteLength"] = bin.size();
    std::string text = j.dump();
    while (text.size() % 4) text.push_back(' ');
    std::string out = "glTF";
    auto u32 = [&out](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
    u32(2);
    u32(static_cast<uint32_t>(28 + text.size() + bin.size()));
    u32(static_cast<uint32_t>(text.size()));
    out += "JSON";
    out += text;
    u32(static_cast<uint32_t>(bin.size()));
    out += std::string("BIN\0", 4);
    out += bin;
    return out;
  }
};

inline json MinMax(const std::vector<float>& xyz) {
  std::vector<double> lo(3, 1e300), hi(3, -1e300);
  for (size_t i = 0; i < xyz.size(); ++i) {
    lo[i % 3] = std::min<double>(lo[i % 3], xyz[i]);
    hi[i % 3] = std::max<double>(hi[i % 3], xyz[i]);
  }
  return {{"min", lo}, {"max", hi}};
}

// Writes `bytes` as fuzz seed `name` when VISTREAM_GLTF_SEED_DIR is set, so the seeds in
// tests/fuzz/corpus/gltf are remade by:
//   VISTREAM_GLTF_SEED_DIR=tests/fuzz/corpus/gltf build/bin/scenes_test --gtest_filter='GltfDraco.*:GltfMeshopt.*:GltfSparse.*'
inline void MaybeWriteSeed(const std::string& name, const std::string& bytes) {
  const char* dir = std::getenv("VISTREAM_GLTF_SEED_DIR");
  if (dir != nullptr) std::ofstream(std::string(dir) + "/" + name, std::ios::binary) << bytes;
}

}  // namespace vistream::scenes::gltf_test
