#include "scenes/geometry_codec.h"

#include <cstring>
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
