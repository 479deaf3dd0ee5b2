#pragma once
// Occluders prepared for from-region queries: every 2.5D occluder footprint as convex pieces,
// the contacts between pieces (shared walls, overlaps, a footprint's own diagonals) that let
// touching buildings fuse into one blocker, and a grid for gathering the pieces in a shaft.

#include <algorithm>
#include <cmath>
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

// Per-thread scratch for Gather and Trace: marks pieces already visited in one call.
struct GatherScratch {
  std::vector<uint32_t> stamp;
  uint32_t value = 0;
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
  void Gather(std::span<const glm::dvec2> hull, double min_height, GatherScratch* scratch,
              std::vector<uint32_t>* out) const;

  // Calls visit(piece) once for each piece in the grid cells the segment a-b crosses, in
  // order from a, until visit returns true; returns whether it did.
  template <typename Visit>
  bool Trace(const glm::dvec2& a, const glm::dvec2& b, GatherScratch* scratch, Visit&& visit) const;

 private:
  std::vector<OccluderPiece> pieces_;
  std::vector<PieceContact> contacts_;
  std::vector<uint32_t> contact_start_, contact_index_;
  // Uniform grid: cell (i, j) lists the pieces whose box overlaps it.
  glm::dvec2 grid_min_{0.0};
  double cell_ = 64.0;
  int nx_ = 0, ny_ = 0;
  std::vector<uint32_t> cell_start_, cell_items_;
};

template <typename Visit>
bool OccluderSet::Trace(const glm::dvec2& a, const glm::dvec2& b, GatherScratch* scratch, Visit&& visit) const {
  if (pieces_.empty()) return false;
  auto& stamp = scratch->stamp;
  if (stamp.size() != pieces_.size() || ++scratch->value == 0) {
    stamp.assign(pieces_.size(), 0);
    scratch->value = 1;
  }
  // Amanatides-Woo through the grid; cells outside it hold nothing.
  const glm::dvec2 d = b - a;
  const glm::dvec2 start = (a - grid_min_) / cell_;
  int i = static_cast<int>(std::floor(start.x)), j = static_cast<int>(std::floor(start.y));
  const int step_i = d.x > 0 ? 1 : -1, step_j = d.y > 0 ? 1 : -1;
  const double dt_x = d.x != 0 ? std::abs(cell_ / d.x) : INFINITY;
  const double dt_y = d.y != 0 ? std::abs(cell_ / d.y) : INFINITY;
  double t_x = d.x != 0 ? (d.x > 0 ? (i + 1 - start.x) : (start.x - i)) * dt_x : INFINITY;
  double t_y = d.y != 0 ? (d.y > 0 ? (j + 1 - start.y) : (start.y - j)) * dt_y : INFINITY;
  for (int guard = 0; guard < 4 * (nx_ + ny_) + 8; ++guard) {
    if (i >= 0 && j >= 0 && i < nx_ && j < ny_) {
      const size_t c = static_cast<size_t>(j) * nx_ + i;
      for (uint32_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
        const uint32_t id = cell_items_[k];
        if (stamp[id] == scratch->value) continue;
        stamp[id] = scratch->value;
        if (visit(id)) return true;
      }
    }
    if (t_x > 1.0 && t_y > 1.0) break;
    if (t_x < t_y) {
      i += step_i;
      t_x += dt_x;
    } else {
      j += step_j;
      t_y += dt_y;
    }
  }
  return false;
}

}  // namespace vistream::visibility
