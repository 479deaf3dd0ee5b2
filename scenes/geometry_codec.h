#pragma once
// Lossless mesh encoding for the wire: meshoptimizer's vertex codec over 24-byte vertices
// (float position, float normal; scene-local metres) and its index sequence codec over the
// triangle list, in the mesh's own order and corner order, so the decoded mesh is bit-identical to the scene's.
// Decoding is safe for untrusted bytes: every malformed input is an error, never a crash.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include <absl/status/statusor.h>

#include "scenes/mesh.h"

namespace vistream::scenes {

// What a mesh of `vertex_count` vertices and `index_count` indices takes decoded: 24 bytes a
// vertex (float position and normal), 4 an index. The one memory accounting of server and
// client (Hello.memory_budget_bytes, the client's store).
inline uint64_t RawMeshBytes(uint64_t vertex_count, uint64_t index_count) { return vertex_count * 24 + index_count * 4; }

struct EncodedMesh {
  uint32_t vertex_count = 0;
  uint32_t index_count = 0;  // a multiple of 3
  std::string vertices;      // meshopt_encodeVertexBuffer, 24-byte vertices: position, normal
  std::string indices;       // meshopt_encodeIndexSequence

  // Bytes on the wire, and bytes of the same mesh unencoded (24 per vertex, 4 per index).
  size_t EncodedBytes() const { return vertices.size() + indices.size(); }
  size_t RawBytes() const { return RawMeshBytes(vertex_count, index_count); }
};

// Precondition: mesh.normals has one normal per position (or none: zero normals are sent),
// mesh.indices a multiple of 3 and each index below positions.size().
EncodedMesh EncodeMesh(const Mesh& mesh);

// The mesh back. Errors (INVALID_ARGUMENT, naming `where`): an index count that is not a
// multiple of 3, counts over the limits (2^24 vertices, 2^26 indices), bytes meshoptimizer
// rejects, an index out of range.
absl::StatusOr<Mesh> DecodeMesh(uint32_t vertex_count, uint32_t index_count, std::string_view vertices,
                                std::string_view indices, const std::string& where);

}  // namespace vistream::scenes
