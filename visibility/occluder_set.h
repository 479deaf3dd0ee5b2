#pragma once
// Occluders prepared for from-region queries: every 2.5D occluder footprint as convex pieces,
// the contacts between pieces (shared walls, overlaps, a footprint's own diagonals) that let
// touching buildings fuse into one blocker, and a grid for gathering the pieces in a shaft.

#include <cstdint>
#include <span>
#include <vector>

#include <glm/vec2.hpp>

#include "scenes/scene.h"

namespace vistream::visibility {

// A convex piece of a footprint (counter-clockwise), or a degenerate one: a segment (two
// points) from a zero-area footprint. Standing from z = 0 to `height`.
struct OccluderPiece {
  std::vector<glm::dvec2> points;  // scene-local metres
  double height = 0.0;
  scenes::ObjectId object = 0;
  glm::dvec2 box_min{0.0}, box_max{0.0};
};

// Pieces `a` and `b` share the segment [w0, w1] (w0 == w1 for a single point): it lies in
// both closed pieces, so whatever part of it survives clipping both proves them connected.
struct PieceContact {
  uint32_t a = 0, b = 0;
  glm::dvec2 w0{0.0}, w1{0.0};
};

class OccluderSet {
 public:
  // Decomposes every occluder of `scene` and finds the contacts between pieces.
  static OccluderSet Build(const scenes::Scene& scene, double grid_cell_m = 64.0);

  const std::vector<OccluderPiece>& pieces() const { return pieces_; }
  const std::vector<PieceContact>& contacts() const { return contacts_; }
  // Contacts of piece i: indices into contacts().
  std::span<const uint32_t> ContactsOf(uint32_t piece) const {
    return {contact_index_.data() + contact_start_[piece], contact_start_[piece + 1] - contact_start_[piece]};
  }

  // Appends the pieces whose box overlaps the convex polygon `hull` (scene-local xy) and
  // whose height exceeds `min_height`; each piece once.
  void Gather(std::span<const glm::dvec2> hull, double min_height, std::vector<uint32_t>* out) const;

 private:
  std::vector<OccluderPiece> pieces_;
  std::vector<PieceContact> contacts_;
  std::vector<uint32_t> contact_start_, contact_index_;
  // Uniform grid: cell (i, j) lists the pieces whose box overlaps it.
  glm::dvec2 grid_min_{0.0};
  double cell_ = 64.0;
  int nx_ = 0, ny_ = 0;
  std::vector<uint32_t> cell_start_, cell_items_;
  mutable std::vector<uint32_t> stamp_;
  mutable uint32_t stamp_value_ = 0;
};

}  // namespace vistream::visibility
