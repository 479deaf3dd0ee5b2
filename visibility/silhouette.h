// The silhouette search of AGVS's silhouette mutation (the paper's section 4.3), solved exactly.
//
// The paper shoots "discovery rays" from a fixed point s_h through points s'_t on a segment
// through the hit point s_t, normal to the sample, and keeps the nearest ray that misses the
// object (bisection or a quaternary search with packets of 4 rays). All those rays lie in one
// plane, so which of them meet the object is a union of intervals of the segment's parameter,
// one per triangle the plane cuts: one pass over the object's triangles finds the silhouette
// itself, where the search only narrows it down after 8 to 12 rays.
//
// Most buildings are made of closed convex pieces (prisms), and the plane cuts a closed convex
// piece in one convex polygon whose corners are where the plane crosses the piece's edges: the
// rays that meet the piece are the one interval between the smallest and the largest λ of those
// crossings. So a piece takes its corners and edges (a box: 8 and 12) where its triangles (12,
// each cut on two of its three edges) took four times the work and memory.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <optional>
#include <span>
#include <utility>
#include <vector>

namespace vistream::visibility {

// A triangle as a corner and two edges (single precision, like the meshes).
struct EdgeTriangle {
  glm::vec3 a, e1, e2;
};

// An object's surface as the search reads it. Its triangles are grouped by welding equal
// positions and joining triangles across edges that exactly two of them share, in opposite
// directions; a group that is closed (every edge has its twin) and convex (every corner on or
// behind every face's plane, to a millionth of its size) is a piece, read by corners and edges;
// the other triangles are read one by one. Everything coordinate by coordinate in blocks of
// four, so that one pass handles four corners or triangles at a time (SSE, or whatever vectors
// the target has).
class FanSurface {
 public:
  FanSurface() = default;
  // `indices`: triangles (a multiple of three), each index < positions.size().
  FanSurface(std::span<const glm::vec3> positions, std::span<const uint32_t> indices);

  size_t triangles() const { return triangle_count_; }
  size_t pieces() const { return pieces_.size(); }  // closed convex pieces

  typedef float Lanes __attribute__((vector_size(16)));  // one coordinate of four
  struct Block {                                          // four triangles
    Lanes ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z;
  };
  struct Corners {  // four corners of a piece
    Lanes x, y, z;
  };
  struct Piece {
    glm::vec3 centre;
    float radius = 0.0f;  // of a sphere around the piece
    uint32_t corner_block = 0, corner_count = 0;
    uint32_t edge = 0, edge_count = 0;
    // The piece's triangles, for fans its corners cannot settle (a corner in the plane, or a
    // crossing not in front of the fan's point).
    uint32_t block = 0, triangle_count = 0;
  };
  std::span<const Piece> piece_list() const { return pieces_; }
  std::span<const Corners> corners() const { return corners_; }
  std::span<const std::pair<uint8_t, uint8_t>> edges() const { return edges_; }
  std::span<const Block> blocks() const { return blocks_; }
  uint32_t loose_block() const { return loose_block_; }  // the triangles in no piece start here
  uint32_t loose_count() const { return loose_count_; }

  // Bounding spheres over the pieces and over runs of kClusterBlocks blocks of loose
  // triangles (both in Morton order of their centres), so that a search reads only what the
  // fan's plane cuts: level 0 holds one sphere per leaf (a piece, or a cluster of loose
  // triangles), level k + 1 one per kTreeFanout nodes of level k; the last level is the root's
  // children. Large objects (a 50,000-node courtyard ring) then cost a search about what the
  // plane cuts, not what the object holds.
  struct Sphere {
    glm::vec3 centre;
    float radius = 0.0f;
  };
  static constexpr uint32_t kClusterBlocks = 8;
  static constexpr uint32_t kTreeFanout = 8;
  using SphereTree = std::vector<std::vector<Sphere>>;
  const SphereTree& piece_tree() const { return piece_tree_; }
  const SphereTree& loose_tree() const { return loose_tree_; }
  // Where a search reads first: taken ahead (one cache miss), so that Prefetch has no miss of
  // its own to wait for.
  struct Hot {
    const void* at[3] = {nullptr, nullptr, nullptr};
    uint32_t bytes[3] = {0, 0, 0};
  };
  Hot hot() const;
  // Asks the caches for those lines.
  static void Prefetch(const Hot& hot);

 private:
  std::vector<Piece> pieces_;
  std::vector<Corners> corners_;                     // each piece's, padded with its last one
  std::vector<std::pair<uint8_t, uint8_t>> edges_;  // corner numbers within the piece
  std::vector<Block> blocks_;  // each piece's triangles, then the loose ones; padded per group
  uint32_t loose_block_ = 0, loose_count_ = 0;
  size_t triangle_count_ = 0;
  SphereTree piece_tree_, loose_tree_;
};

// The rays from `from` through to + λ·radius·d, λ in [-1, 1]: `d` is a unit vector normal to
// to - from, radius > 0.
struct DiscoveryFan {
  glm::dvec3 from{0.0}, to{0.0}, d{0.0};
  double radius = 0.0;
};

// Closed λ-intervals (within [-1, 1]) whose union is the set of the fan's rays that meet the
// surface strictly in front of `from` (beyond a millionth of the distance to `to`), in no
// particular order: one per piece, and one per loose triangle, the fan's plane cuts. Triangles
// lying in that plane are not counted (grazed). Appends to `out`.
void FanHits(const DiscoveryFan& fan, const FanSurface& surface,
             std::vector<std::pair<double, double>>* out);

// The λ of the silhouette the search looks for, the border between rays that meet the
// surface and rays that miss it: if the ray through `to` (λ = 0) meets it, the upper end
// of the run of meeting rays around it; else the largest λ < 0 of a meeting ray. None when the
// ray at λ = 1 meets it (no silhouette within reach) or no ray in [-1, 0] does. Intervals
// closer than `gap` (λ units) count as one: triangles sharing an edge leave no gap.
// `scratch` is reused between calls.
std::optional<double> SilhouetteLambda(const DiscoveryFan& fan, const FanSurface& surface,
                                       std::vector<std::pair<double, double>>* scratch,
                                       double gap = 1e-5);

}  // namespace vistream::visibility
