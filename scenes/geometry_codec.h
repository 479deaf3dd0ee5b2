#pragma once
// Lossless mesh encoding for the wire: meshoptimizer's vertex codec over 24-byte vertices
// (float position, float normal; scene-local metres) and its index sequence codec over the
// triangle list, in the mesh's own order and corner order, so the decoded mesh is bit-identical to the scene's.
// Decoding is safe for untrusted bytes: every malformed input is an error, never a crash.

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

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

// ---- levels of detail (issue 45) ----
// A level's mesh goes without normals: positions welded (one vertex per distinct place), as
// integer multiples of a power-of-two step from a corner (meshoptimizer's vertex codec over 8-byte
// vertices of three uint16, or 12-byte vertices of three uint32 when the range needs them), and
// the triangle list over the welded vertices (meshopt_encodeIndexBuffer, which may rotate a
// triangle's corners). The receiver rebuilds the normals with ShadeByCreases, as the level's
// maker did, so a level's mesh comes back with the same triangles in the same order, each the
// same three points (its first corner perhaps another of them), the same normals at each point.

// Positions and a triangle list welded: one vertex per distinct position (normals ignored),
// numbered in order of first use by the triangles; the triangles in the same order and corner
// order (meshoptimizer's vertex remap). What the simplifiers see of a mesh's connectivity, and
// what a level's wire form holds.
struct WeldedMesh {
  std::vector<glm::vec3> positions;
  std::vector<uint32_t> indices;
};
WeldedMesh WeldPositions(const std::vector<glm::vec3>& positions, const std::vector<uint32_t>& indices);

// The drawable mesh of welded `positions` and the triangle list `indices` (indices below
// positions.size()): triangles in the same order and corner order; one vertex per welded position
// and group of its corners whose faces' normals lie within 30 degrees of the group's first
// (normals area-weighted, unit), vertices numbered in order of first use by the triangles.
// Zero-area triangles are kept (they draw nothing) and join their corners' first group.
Mesh ShadeByCreases(const std::vector<glm::vec3>& positions, const std::vector<uint32_t>& indices);

struct EncodedLevelMesh {
  uint32_t vertex_count = 0;  // welded
  uint32_t index_count = 0;
  int32_t step_log2 = 0;      // the step is 2^step_log2 metres
  int64_t origin[3] = {0, 0, 0};  // the corner, in steps, scene-local
  bool wide = false;          // 12-byte vertices (uint32) instead of 8-byte (uint16)
  std::string vertices;       // meshopt_encodeVertexBuffer
  std::string indices;        // meshopt_encodeIndexBuffer
  size_t EncodedBytes() const { return vertices.size() + indices.size(); }
};

// Precondition: indices a multiple of 3, each below positions.size(). Positions are written as
// multiples of the largest power-of-two step (at most 1 m, at least 2^-10 m) that divides every
// coordinate; a coordinate no such step divides is rounded to 2^-10 m.
EncodedLevelMesh EncodeLevelMesh(const Mesh& mesh);

// The drawable mesh back (ShadeByCreases of the decoded positions and triangles). Errors
// (INVALID_ARGUMENT, naming `where`) as DecodeMesh's, and a step outside [2^-10, 1] m.
absl::StatusOr<Mesh> DecodeLevelMesh(uint32_t vertex_count, uint32_t index_count, int32_t step_log2,
                                     const int64_t origin[3], bool wide, std::string_view vertices,
                                     std::string_view indices, const std::string& where);

}  // namespace vistream::scenes
