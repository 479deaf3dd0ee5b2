#include "scenes/geometry_codec.h"

#include <array>
#include <cmath>
#include <cstring>

#include <glm/geometric.hpp>
#include <vector>

#include <absl/strings/str_cat.h>
#include <meshoptimizer.h>

namespace vistream::scenes {

namespace {
constexpr size_t kVertexBytes = 24;
constexpr uint32_t kMaxVertices = 1u << 24;
constexpr uint32_t kMaxIndices = 1u << 26;

struct WireVertex {
  float px, py, pz, nx, ny, nz;
};
static_assert(sizeof(WireVertex) == kVertexBytes);
}  // namespace

EncodedMesh EncodeMesh(const Mesh& mesh) {
  EncodedMesh out;
  out.vertex_count = static_cast<uint32_t>(mesh.positions.size());
  out.index_count = static_cast<uint32_t>(mesh.indices.size());
  std::vector<WireVertex> v(mesh.positions.size());
  for (size_t i = 0; i < v.size(); ++i) {
    const glm::vec3 p = mesh.positions[i];
    const glm::vec3 n = i < mesh.normals.size() ? mesh.normals[i] : glm::vec3(0.0f);
    v[i] = {p.x, p.y, p.z, n.x, n.y, n.z};
  }
  out.vertices.resize(meshopt_encodeVertexBufferBound(v.size(), kVertexBytes));
  out.vertices.resize(meshopt_encodeVertexBuffer(reinterpret_cast<unsigned char*>(out.vertices.data()),
                                                 out.vertices.size(), v.data(), v.size(), kVertexBytes));
  // The index sequence codec, not the triangle-list one: meshopt_encodeIndexBuffer may rotate
  // a triangle's corners (same triangle, other first vertex), and the mesh must come back bit
  // for bit. It costs 0.3% of the encoded bytes (city1, monaco, london).
  out.indices.resize(meshopt_encodeIndexSequenceBound(mesh.indices.size(), mesh.positions.size()));
  out.indices.resize(meshopt_encodeIndexSequence(reinterpret_cast<unsigned char*>(out.indices.data()),
                                                 out.indices.size(), mesh.indices.data(), mesh.indices.size()));
  return out;
}

absl::StatusOr<Mesh> DecodeMesh(uint32_t vertex_count, uint32_t index_count, std::string_view vertices,
                                std::string_view indices, const std::string& where) {
  if (index_count % 3 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": index count ", index_count, " is not a multiple of 3"));
  }
  if (vertex_count > kMaxVertices || index_count > kMaxIndices) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", vertex_count, " vertices and ", index_count,
                                                   " indices exceed the limits (", kMaxVertices, ", ", kMaxIndices, ")"));
  }
  std::vector<WireVertex> v(vertex_count);
  if (vertex_count > 0 &&
      meshopt_decodeVertexBuffer(v.data(), vertex_count, kVertexBytes,
                                 reinterpret_cast<const unsigned char*>(vertices.data()), vertices.size()) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": malformed vertex bytes (", vertices.size(), " bytes for ",
                                                   vertex_count, " vertices)"));
  }
  Mesh mesh;
  mesh.indices.resize(index_count);
  if (index_count > 0 &&
      meshopt_decodeIndexSequence(mesh.indices.data(), index_count, sizeof(uint32_t),
                                  reinterpret_cast<const unsigned char*>(indices.data()), indices.size()) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": malformed index bytes (", indices.size(), " bytes for ",
                                                   index_count, " indices)"));
  }
  for (size_t k = 0; k < mesh.indices.size(); ++k) {
    if (mesh.indices[k] >= vertex_count) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": index ", k, " is ", mesh.indices[k], ", beyond the ", vertex_count, " vertices"));
    }
  }
  mesh.positions.resize(vertex_count);
  mesh.normals.resize(vertex_count);
  for (size_t i = 0; i < v.size(); ++i) {
    mesh.positions[i] = glm::vec3(v[i].px, v[i].py, v[i].pz);
    mesh.normals[i] = glm::vec3(v[i].nx, v[i].ny, v[i].nz);
  }
  return mesh;
}

}  // namespace vistream::scenes

namespace vistream::scenes {

namespace {

constexpr int kMinStepLog2 = -10;
constexpr int kMaxStepLog2 = 0;
constexpr double kCreaseCos = 0.866;  // 30 degrees

// The largest power-of-two exponent e in [kMinStepLog2, kMaxStepLog2] with v a multiple of 2^e.
int DividingStep(float v) {
  if (v == 0.0f) return kMaxStepLog2;
  for (int e = kMaxStepLog2; e > kMinStepLog2; --e) {
    const double q = std::ldexp(1.0, e);
    if (std::fmod(static_cast<double>(v), q) == 0.0) return e;
  }
  return kMinStepLog2;
}

}  // namespace

Mesh ShadeByCreases(const std::vector<glm::vec3>& positions, const std::vector<uint32_t>& indices) {
  struct Group {
    glm::dvec3 first, sum{0.0};
    uint32_t out = UINT32_MAX;
  };
  std::vector<std::vector<Group>> groups(positions.size());
  std::vector<uint32_t> corner_group(indices.size());
  for (size_t t = 0; t + 2 < indices.size(); t += 3) {
    const glm::dvec3 a(positions[indices[t]]), b(positions[indices[t + 1]]), c(positions[indices[t + 2]]);
    const glm::dvec3 n = glm::cross(b - a, c - a);
    const double len = glm::length(n);
    for (int k = 0; k < 3; ++k) {
      auto& gs = groups[indices[t + k]];
      size_t g = 0;
      if (len > 0.0) {
        const glm::dvec3 unit = n / len;
        while (g < gs.size() && glm::dot(gs[g].first, unit) < kCreaseCos) ++g;
        if (g == gs.size()) gs.push_back({unit});
        gs[g].sum += n;
      } else if (gs.empty()) {
        gs.push_back({glm::dvec3(0, 0, 1)});
      }
      corner_group[t + k] = static_cast<uint32_t>(g);
    }
  }
  Mesh mesh;
  mesh.indices.resize(indices.size());
  for (size_t k = 0; k < indices.size(); ++k) {
    Group& g = groups[indices[k]][corner_group[k]];
    if (g.out == UINT32_MAX) {
      g.out = static_cast<uint32_t>(mesh.positions.size());
      mesh.positions.push_back(positions[indices[k]]);
      const double len = glm::length(g.sum);
      mesh.normals.push_back(glm::vec3(len > 0.0 ? g.sum / len : g.first));
    }
    mesh.indices[k] = g.out;
  }
  return mesh;
}

WeldedMesh WeldPositions(const std::vector<glm::vec3>& positions, const std::vector<uint32_t>& indices) {
  std::vector<uint32_t> remap(positions.size());
  const size_t unique = meshopt_generateVertexRemap(remap.data(), indices.data(), indices.size(), positions.data(),
                                                    positions.size(), sizeof(glm::vec3));
  WeldedMesh w;
  w.positions.resize(unique);
  meshopt_remapVertexBuffer(w.positions.data(), positions.data(), positions.size(), sizeof(glm::vec3), remap.data());
  w.indices.resize(indices.size());
  meshopt_remapIndexBuffer(w.indices.data(), indices.data(), indices.size(), remap.data());
  return w;
}

EncodedLevelMesh EncodeLevelMesh(const Mesh& mesh) {
  const WeldedMesh w = WeldPositions(mesh.positions, mesh.indices);
  const std::vector<glm::vec3>& welded = w.positions;
  const std::vector<uint32_t>& indices = w.indices;
  EncodedLevelMesh out;
  out.vertex_count = static_cast<uint32_t>(welded.size());
  out.index_count = static_cast<uint32_t>(indices.size());
  int step = kMaxStepLog2;
  for (const glm::vec3& p : welded) step = std::min({step, DividingStep(p.x), DividingStep(p.y), DividingStep(p.z)});
  out.step_log2 = step;
  const double q = std::ldexp(1.0, step);
  std::vector<std::array<int64_t, 3>> k(welded.size());
  int64_t lo[3] = {INT64_MAX, INT64_MAX, INT64_MAX}, hi[3] = {INT64_MIN, INT64_MIN, INT64_MIN};
  for (size_t i = 0; i < welded.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      k[i][a] = std::llround(static_cast<double>(welded[i][a]) / q);
      lo[a] = std::min(lo[a], k[i][a]);
      hi[a] = std::max(hi[a], k[i][a]);
    }
  }
  for (int a = 0; a < 3; ++a) out.origin[a] = welded.empty() ? 0 : lo[a];
  for (int a = 0; a < 3; ++a) out.wide = out.wide || (!welded.empty() && hi[a] - lo[a] > 0xffff);
  const size_t vsize = out.wide ? 12 : 8;
  std::vector<unsigned char> raw(welded.size() * vsize, 0);
  for (size_t i = 0; i < welded.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      const auto d = static_cast<uint64_t>(k[i][a] - out.origin[a]);
      if (out.wide) {
        const auto v = static_cast<uint32_t>(d);
        std::memcpy(&raw[i * vsize + 4 * a], &v, 4);
      } else {
        const auto v = static_cast<uint16_t>(d);
        std::memcpy(&raw[i * vsize + 2 * a], &v, 2);
      }
    }
  }
  out.vertices.resize(meshopt_encodeVertexBufferBound(welded.size(), vsize));
  out.vertices.resize(meshopt_encodeVertexBuffer(reinterpret_cast<unsigned char*>(out.vertices.data()),
                                                 out.vertices.size(), raw.data(), welded.size(), vsize));
  // The triangle codec: a third of the sequence codec's bytes; it may rotate a triangle's corners
  // (the same triangle, in the same place in the list), which changes nothing drawn.
  out.indices.resize(meshopt_encodeIndexBufferBound(indices.size(), welded.size()));
  out.indices.resize(meshopt_encodeIndexBuffer(reinterpret_cast<unsigned char*>(out.indices.data()),
                                               out.indices.size(), indices.data(), indices.size()));
  return out;
}

absl::StatusOr<Mesh> DecodeLevelMesh(uint32_t vertex_count, uint32_t index_count, int32_t step_log2,
                                     const int64_t origin[3], bool wide, std::string_view vertices,
                                     std::string_view indices, const std::string& where) {
  if (step_log2 < kMinStepLog2 || step_log2 > kMaxStepLog2) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": step 2^", step_log2, " m is outside [2^", kMinStepLog2,
                                                   ", 2^", kMaxStepLog2, "] m"));
  }
  for (int a = 0; a < 3; ++a) {
    if (std::abs(origin[a]) > (int64_t{1} << 40)) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": corner ", origin[a], " steps is out of range"));
    }
  }
  if (index_count % 3 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": index count ", index_count, " is not a multiple of 3"));
  }
  if (vertex_count > kMaxVertices || index_count > kMaxIndices) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", vertex_count, " vertices and ", index_count,
                                                   " indices exceed the limits (", kMaxVertices, ", ", kMaxIndices, ")"));
  }
  const size_t vsize = wide ? 12 : 8;
  std::vector<unsigned char> raw(static_cast<size_t>(vertex_count) * vsize);
  if (vertex_count > 0 &&
      meshopt_decodeVertexBuffer(raw.data(), vertex_count, vsize, reinterpret_cast<const unsigned char*>(vertices.data()),
                                 vertices.size()) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": malformed vertex bytes (", vertices.size(), " bytes for ",
                                                   vertex_count, " vertices)"));
  }
  std::vector<uint32_t> idx(index_count);
  if (index_count > 0 &&
      meshopt_decodeIndexBuffer(idx.data(), index_count, sizeof(uint32_t),
                                  reinterpret_cast<const unsigned char*>(indices.data()), indices.size()) != 0) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": malformed index bytes (", indices.size(), " bytes for ",
                                                   index_count, " indices)"));
  }
  for (size_t k = 0; k < idx.size(); ++k) {
    if (idx[k] >= vertex_count) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": index ", k, " is ", idx[k], ", beyond the ", vertex_count, " vertices"));
    }
  }
  const double q = std::ldexp(1.0, step_log2);
  std::vector<glm::vec3> positions(vertex_count);
  for (size_t i = 0; i < vertex_count; ++i) {
    for (int a = 0; a < 3; ++a) {
      uint64_t d = 0;
      if (wide) {
        uint32_t v;
        std::memcpy(&v, &raw[i * vsize + 4 * a], 4);
        d = v;
      } else {
        uint16_t v;
        std::memcpy(&v, &raw[i * vsize + 2 * a], 2);
        d = v;
      }
      const double x = static_cast<double>(origin[a] + static_cast<int64_t>(d)) * q;
      if (!std::isfinite(x) || std::abs(x) > 1e9) {
        return absl::InvalidArgumentError(absl::StrCat(where, ": vertex ", i, " lies beyond 10^9 m"));
      }
      positions[i][a] = static_cast<float>(x);
    }
  }
  return ShadeByCreases(positions, idx);
}

}  // namespace vistream::scenes
