#pragma once
// Occluders prepared for from-region queries: every 2.5D occluder footprint as convex pieces
// (a non-convex one cut by ConvexPartition: a few pieces, not a triangle per vertex), the
// contacts between pieces (shared walls, overlaps, a footprint's own diagonals) that let
// touching buildings fuse into one blocker, and a grid for gathering the pieces in a shaft.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <glm/common.hpp>
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
// A pair's contacts are few: none lies within the xy box of another of the same pair (that
// other one survives any clip to a strip along x or y that the inner one survives).
struct PieceContact {
  uint32_t a = 0, b = 0;
  glm::dvec2 w0{0.0}, w1{0.0};
};

// A box in xy and the height of what stands on it: a piece's, or the union of a grid cell's.
struct PieceBounds {
  glm::dvec2 min{0.0}, max{0.0};
  double height = 0.0;
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

  // The other piece of each of ContactsOf(piece), in the same order: the fuse loop tests
  // these first and reads a contact itself only for pieces it kept.
  std::span<const uint32_t> ContactOthersOf(uint32_t piece) const {
    return {contact_other_.data() + contact_start_[piece], contact_start_[piece + 1] - contact_start_[piece]};
  }

  // For each of PointsOf(piece), in order, the first piece (lowest id, maybe `piece` itself)
  // that holds the very same point (equal coordinates): the convex pieces of a footprint share
  // its vertices, and a fused group that holds the owner unclipped has the point already.
  std::span<const uint32_t> PointOwnersOf(uint32_t piece) const {
    return {point_owner_.data() + point_start_[piece], point_start_[piece + 1] - point_start_[piece]};
  }

  const PieceBounds& bounds(uint32_t piece) const { return bounds_[piece]; }
  // pieces()[piece].points, from one array for all pieces (read where gathering is hot).
  std::span<const glm::dvec2> PointsOf(uint32_t piece) const {
    return {points_.data() + point_start_[piece], point_start_[piece + 1] - point_start_[piece]};
  }

  // Appends each piece, once, that is listed in a grid cell the convex polygon `hull`
  // (scene-local xy) overlaps and for whose bounds keep(bounds) is true: so at least every
  // such piece whose box meets the hull. `keep` must be monotone (true for bounds whenever
  // true for bounds inside them): a cell for whose bounds, the union of its pieces', keep is
  // false is skipped whole.
  template <typename Keep>
  void Gather(std::span<const glm::dvec2> hull, Keep&& keep, GatherScratch* scratch, std::vector<uint32_t>* out) const;

  // Calls visit(piece) once for each piece in the grid cells the segment a-b crosses, in
  // order from a, until visit returns true; returns whether it did.
  template <typename Visit>
  bool Trace(const glm::dvec2& a, const glm::dvec2& b, GatherScratch* scratch, Visit&& visit) const;

 private:
  // The cells of the grid that `hull` overlaps, as runs [i0, i1] of row j.
  template <typename Run>
  void CellRuns(std::span<const glm::dvec2> hull, Run&& run) const;

  std::vector<OccluderPiece> pieces_;
  std::vector<PieceBounds> bounds_;  // of each piece, compact for gathering
  std::vector<PieceContact> contacts_;
  std::vector<uint32_t> contact_start_, contact_index_, contact_other_;
  std::vector<glm::dvec2> points_;  // every piece's points, piece after piece
  std::vector<uint32_t> point_start_;
  std::vector<uint32_t> point_owner_;  // parallel to points_: see PointOwnersOf
  // Uniform grid: cell (i, j) lists the pieces whose box overlaps it.
  glm::dvec2 grid_min_{0.0};
  double cell_ = 64.0;
  int nx_ = 0, ny_ = 0;
  std::vector<uint32_t> cell_start_, cell_items_;
  std::vector<PieceBounds> cell_bounds_;  // the union of each cell's pieces' bounds
};

template <typename Run>
void OccluderSet::CellRuns(std::span<const glm::dvec2> hull, Run&& run) const {
  glm::dvec2 lo(INFINITY), hi(-INFINITY);
  for (const glm::dvec2& p : hull) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  const int j0 = std::clamp(static_cast<int>(std::floor((lo.y - grid_min_.y) / cell_)), 0, ny_ - 1);
  const int j1 = std::clamp(static_cast<int>(std::floor((hi.y - grid_min_.y) / cell_)), 0, ny_ - 1);
  for (int j = j0; j <= j1; ++j) {
    // The hull's x-extent within this row of cells.
    const double y0 = grid_min_.y + j * cell_, y1 = y0 + cell_;
    double xl = INFINITY, xr = -INFINITY;
    for (size_t k = 0; k < hull.size(); ++k) {
      const glm::dvec2 &a = hull[k], &b = hull[(k + 1) % hull.size()];
      if (a.y >= y0 && a.y <= y1) xl = std::min(xl, a.x), xr = std::max(xr, a.x);
      for (double y : {y0, y1}) {
        if ((a.y < y) != (b.y < y)) {
          const double x = a.x + (y - a.y) * (b.x - a.x) / (b.y - a.y);
          xl = std::min(xl, x), xr = std::max(xr, x);
        }
      }
    }
    if (xl > xr) continue;
    const int i0 = std::clamp(static_cast<int>(std::floor((xl - grid_min_.x) / cell_)), 0, nx_ - 1);
    const int i1 = std::clamp(static_cast<int>(std::floor((xr - grid_min_.x) / cell_)), 0, nx_ - 1);
    run(j, i0, i1);
  }
}

template <typename Keep>
void OccluderSet::Gather(std::span<const glm::dvec2> hull, Keep&& keep, GatherScratch* scratch,
                         std::vector<uint32_t>* out) const {
  if (pieces_.empty() || hull.empty()) return;
  auto& stamp = scratch->stamp;
  if (stamp.size() != pieces_.size() || ++scratch->value == 0) {
    stamp.assign(pieces_.size(), 0);
    scratch->value = 1;
  }
  // A piece in a skipped cell is still met in its other cells: keep is false for it there
  // too, unless another cell's bounds let it through, where it is tested itself.
  CellRuns(hull, [&](int j, int i0, int i1) {
    for (int i = i0; i <= i1; ++i) {
      const size_t c = static_cast<size_t>(j) * nx_ + i;
      if (cell_start_[c] == cell_start_[c + 1] || !keep(cell_bounds_[c])) continue;
      for (uint32_t k = cell_start_[c]; k < cell_start_[c + 1]; ++k) {
        const uint32_t id = cell_items_[k];
        if (stamp[id] == scratch->value) continue;
        stamp[id] = scratch->value;
        if (keep(bounds_[id])) out->push_back(id);
      }
    }
  });
}

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
