// The silhouette search of AGVS's silhouette mutation (the paper's section 4.3), solved exactly.
//
// The paper shoots "discovery rays" from a fixed point s_h through points s'_t on a segment
// through the hit point s_t, normal to the sample, and keeps the nearest ray that misses the
// object (bisection or a quaternary search with packets of 4 rays). All those rays lie in one
// plane, so which of them meet the object is a union of intervals of the segment's parameter,
// one per triangle the plane cuts: one pass over the object's triangles finds the silhouette
// itself, where the search only narrows it down after 8 to 12 rays.
#pragma once

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

// An object's triangles as the search reads them: in blocks of four, coordinate by coordinate,
// so that one pass handles four triangles at a time (SSE, or whatever vectors the target has).
class FanTriangles {
 public:
  FanTriangles() = default;
  explicit FanTriangles(std::span<const EdgeTriangle> triangles);
  size_t size() const { return count_; }

  typedef float Lanes __attribute__((vector_size(16)));  // one coordinate of four triangles
  struct Block {
    Lanes ax, ay, az, e1x, e1y, e1z, e2x, e2y, e2z;
  };
  std::span<const Block> blocks() const { return blocks_; }

 private:
  std::vector<Block> blocks_;  // the last one padded with copies of the last triangle
  size_t count_ = 0;
};

// The rays from `from` through to + λ·radius·d, λ in [-1, 1]: `d` is a unit vector normal to
// to - from, radius > 0.
struct DiscoveryFan {
  glm::dvec3 from{0.0}, to{0.0}, d{0.0};
  double radius = 0.0;
};

// The closed λ-intervals (within [-1, 1]) of the fan's rays that meet a triangle strictly in
// front of `from` (beyond a millionth of the distance to `to`), in no particular order; one per
// triangle the fan's plane cuts. Triangles lying in that plane are not counted (grazed).
// Appends to `out`.
void FanHits(const DiscoveryFan& fan, const FanTriangles& triangles,
             std::vector<std::pair<double, double>>* out);

// The λ of the silhouette the search looks for, the border between rays that meet the
// triangles and rays that miss them: if the ray through `to` (λ = 0) meets them, the upper end
// of the run of meeting rays around it; else the largest λ < 0 of a meeting ray. None when the
// ray at λ = 1 meets them (no silhouette within reach) or no ray in [-1, 0] does. Intervals
// closer than `gap` (λ units) count as one: triangles sharing an edge leave no gap.
// `scratch` is reused between calls.
std::optional<double> SilhouetteLambda(const DiscoveryFan& fan, const FanTriangles& triangles,
                                       std::vector<std::pair<double, double>>* scratch,
                                       double gap = 1e-5);

}  // namespace vistream::visibility
