#pragma once
// The terrain's height: an index over the triangles of a scene's terrain objects
// (Scene::terrain) answering "how high is the ground here" (walks put the eye above it) and
// "how low and how high is it over this square" (viewcells follow the ground, DESIGN.md "City
// models and terrain").
//
// The surface is the upper side of the terrain: the triangles that face up (counter-clockwise
// seen from above, non-zero area in xy). A closed terrain solid's walls and floor do not count,
// so the top of a closed solid is its surface. Where no terrain triangle covers a point, the
// ground there is flat at z = 0 (every scene without terrain). Heights are scene-local metres.

#include <cstdint>
#include <vector>

#include <glm/vec2.hpp>

#include "scenes/scene.h"

namespace vistream::scenes {

// The lowest and highest ground over a region, scene-local metres; min <= max.
struct HeightRange {
  double min = 0.0, max = 0.0;
  friend bool operator==(const HeightRange&, const HeightRange&) = default;
};

class TerrainHeight {
 public:
  // Indexes the up-facing triangles of `scene`'s terrain objects (their float positions, in
  // double). Precondition: ValidateScene(scene) holds (terrain ids exist). No terrain: empty().
  explicit TerrainHeight(const Scene& scene);

  // No terrain triangle: the ground is z = 0 everywhere.
  bool empty() const { return tris_.empty(); }
  size_t triangle_count() const { return tris_.size(); }

  // The highest terrain surface at `p` (scene-local xy metres; a point on a triangle's edge is
  // on it), or 0 where no terrain triangle covers `p` or p is not finite.
  double HeightAt(const glm::dvec2& p) const;

  // The exact lowest and highest ground over the closed rectangle [lo, hi] (scene-local xy
  // metres; precondition lo <= hi componentwise, finite): the extremes of the piecewise-linear
  // surface clipped to it (at triangle vertices inside it, where triangle edges cross its border,
  // or at its corners), and 0 when terrain leaves any part of it uncovered (by more than a
  // 10^-9 share of its area). Coverage is decided from areas, so the up-facing triangles of one
  // terrain object must not overlap in xy (a TIN); those of different objects may (tiles that
  // overlap: then decided exactly, scenes/polygon_set.h). Where pieces overlap the range is that
  // of every piece: the upper surface's max exactly, and a min that may be lower than the upper
  // surface's (a larger band, never a smaller one).
  HeightRange Range(const glm::dvec2& lo, const glm::dvec2& hi) const;

 private:
  struct Tri {
    glm::dvec2 p[3];
    double z[3];
    glm::dvec2 lo, hi;  // xy bounds
    ObjectId object = 0;
  };
  // The triangles whose xy bounds overlap [lo, hi], ascending, each once.
  void Candidates(const glm::dvec2& lo, const glm::dvec2& hi, std::vector<uint32_t>* out) const;

  std::vector<Tri> tris_;
  // A uniform bucket grid over the triangles' xy bounds: bucket (i, j) lists the triangles whose
  // bounds overlap it (compressed rows: bucket_start_ has nbx_ * nby_ + 1 entries).
  glm::dvec2 origin_{0.0};
  double bucket_ = 1.0;
  int nbx_ = 0, nby_ = 0;
  std::vector<uint32_t> bucket_start_, bucket_tris_;
};

}  // namespace vistream::scenes
