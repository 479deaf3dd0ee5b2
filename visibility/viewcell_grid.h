#pragma once
// The viewcell grid: square cells of `size` metres over the scene's ground footprint, each an
// eye-level box. Cell (i, j) covers x in [x0 + i size, x0 + (i+1) size], y likewise, where x0,
// y0 are multiples of the size, so the grid depends only on scene-local coordinates.
//
// The box's z range is the cell's band. Over flat ground (a scene without terrain) every cell
// has the same band, base_z to base_z + height. Over terrain each cell has its own (bands()):
// the ground within its square plus the eye band, [g_min + base_z, g_max + base_z + height]
// where g_min, g_max are the lowest and highest ground over the square (scenes/terrain.h).

#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>

#include "scenes/aabb.h"
#include "scenes/catalog.h"
#include "scenes/scene.h"

namespace vistream::visibility {

using CellId = uint32_t;

// A cell's z range, scene-local metres; z0 < z1.
struct CellBand {
  double z0 = 0.0, z1 = 0.0;
  friend bool operator==(const CellBand&, const CellBand&) = default;
};

struct CellCoord {
  int i = 0, j = 0;
  friend bool operator==(const CellCoord&, const CellCoord&) = default;
};

class ViewcellGrid {
 public:
  // Covers the xy extent of `bounds`. Errors: non-positive or non-finite sizes, an empty box,
  // or a grid of more than 2^31 cells.
  static absl::StatusOr<ViewcellGrid> Create(const scenes::Aabb& bounds, double cell_size,
                                             double base_z, double height);
  // The grid of a scene's viewcell band (a catalog entry's `viewcell`) over `bounds` (the
  // scene's). Errors as above.
  static absl::StatusOr<ViewcellGrid> Create(const scenes::Aabb& bounds, const scenes::ViewcellSpec& spec) {
    return Create(bounds, spec.size_m, spec.base_m, spec.height_m);
  }
  // The grid of `scene` (over its bounds) whose cells follow its terrain: each cell's band spans
  // the ground over its square (scenes::TerrainHeight::Range) plus the spec's band above it. A
  // scene without terrain gets exactly the bounds-based grid (no bands). Errors as above.
  static absl::StatusOr<ViewcellGrid> Create(const scenes::Scene& scene, const scenes::ViewcellSpec& spec);
  // `flat` with per-cell bands (one per cell, in id order): what a reader of stored bands (a PVS
  // file, the protocol) rebuilds, and tests. Errors (INVALID_ARGUMENT): a count other than
  // CellCount(), a band not finite or with z0 >= z1.
  static absl::StatusOr<ViewcellGrid> WithBands(ViewcellGrid flat, std::vector<CellBand> bands);
  // The grid laid out as stated rather than derived from bounds: cell (0, 0)'s corner, square
  // cells of `cell_size` metres, nx by ny of them, the band base_z to base_z + height (what the
  // protocol's SceneInfo states; proto/scene_info.h GridFromSceneInfo). A layout without cells
  // (a size or a count not positive, or not finite) gives an empty grid: no point is in a cell.
  // Errors (INVALID_ARGUMENT): more than 2^31 cells.
  static absl::StatusOr<ViewcellGrid> FromLayout(const glm::dvec2& corner, double cell_size, int nx, int ny,
                                                 double base_z, double height);

  int nx() const { return nx_; }
  int ny() const { return ny_; }
  size_t CellCount() const { return static_cast<size_t>(nx_) * static_cast<size_t>(ny_); }
  double cell_size() const { return size_; }
  // The spec's band: with no per-cell bands every cell's z range is base_z to base_z + height
  // (scene-local metres); with bands, base_z is the height above the ground where each band
  // starts, and height its depth above the highest ground.
  double base_z() const { return base_z_; }
  double height() const { return height_; }
  // Per-cell bands, one per cell in id order; empty: every cell's is [base_z, base_z + height].
  bool has_bands() const { return !bands_.empty(); }
  const std::vector<CellBand>& bands() const { return bands_; }
  // Cell `id`'s z range. Precondition: id < CellCount().
  CellBand Band(CellId id) const { return bands_.empty() ? CellBand{base_z_, base_z_ + height_} : bands_[id]; }
  // Whether an eye at height `z` (scene-local metres) is inside cell `id`'s band, ends included:
  // the poses the server takes for that cell. Precondition: id < CellCount().
  bool InBand(CellId id, double z) const {
    const CellBand b = Band(id);
    return z >= b.z0 && z <= b.z1;
  }
  // Scene-local corner of cell (0, 0) in xy.
  glm::dvec2 corner() const { return {x0_, y0_}; }
  // The box all cells together cover (the union of their bands in z).
  scenes::Aabb Bounds() const {
    if (!bands_.empty()) return {glm::dvec3(x0_, y0_, zlo_), glm::dvec3(x0_ + nx_ * size_, y0_ + ny_ * size_, zhi_)};
    return {glm::dvec3(x0_, y0_, base_z_), glm::dvec3(x0_ + nx_ * size_, y0_ + ny_ * size_, base_z_ + height_)};
  }

  bool Valid(CellCoord c) const { return c.i >= 0 && c.j >= 0 && c.i < nx_ && c.j < ny_; }
  // Preconditions: Valid(c), id < CellCount().
  CellId Id(CellCoord c) const { return static_cast<CellId>(c.j) * static_cast<CellId>(nx_) + c.i; }
  CellCoord Coord(CellId id) const { return {static_cast<int>(id % nx_), static_cast<int>(id / nx_)}; }
  scenes::Aabb CellBox(CellCoord c) const;
  scenes::Aabb CellBox(CellId id) const { return CellBox(Coord(id)); }

  // A fixed sample of `count` distinct cells (all of them if fewer), the same for the same
  // seed and grid: what benchmarks average over.
  std::vector<CellCoord> Sample(size_t count, uint64_t seed) const;

  // The cell whose ground square contains p (scene-local metres); none outside the grid.
  // Points on a shared edge belong to the cell above and to the right.
  std::optional<CellId> CellAt(const glm::dvec2& p) const;

  // The up to eight cells around `id`, in row-major order.
  std::vector<CellId> Neighbours(CellId id) const;
  // `id` and the up to eight cells around it, in row-major order: the cells whose PVSs a
  // client at `id` holds (DESIGN.md "Server and client").
  std::vector<CellId> Neighbourhood(CellId id) const;
  // Whether `a` and `b` are the same cell or neighbours (Chebyshev distance at most 1).
  bool Near(CellId a, CellId b) const {
    const CellCoord ca = Coord(a), cb = Coord(b);
    return ca.i - cb.i <= 1 && cb.i - ca.i <= 1 && ca.j - cb.j <= 1 && cb.j - ca.j <= 1;
  }
  // The cells a client needs anew after moving from `from` to an adjacent `to`: `to`'s
  // neighbourhood (itself and its neighbours) less `from`'s. Three for an edge crossing,
  // five for a corner crossing; empty when `to` is not adjacent to `from`.
  std::vector<CellId> NewlyAdjacent(CellId from, CellId to) const;

 private:
  double size_ = 1.0, base_z_ = 0.0, height_ = 1.0;
  double x0_ = 0.0, y0_ = 0.0;
  int nx_ = 0, ny_ = 0;
  std::vector<CellBand> bands_;  // empty: flat
  double zlo_ = 0.0, zhi_ = 0.0;  // the bands' union, when there are bands
};

}  // namespace vistream::visibility
