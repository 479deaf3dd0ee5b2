#include "visibility/viewcell_grid.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <absl/strings/str_cat.h>

#include "scenes/random.h"
#include "scenes/terrain.h"

namespace vistream::visibility {

absl::StatusOr<ViewcellGrid> ViewcellGrid::Create(const scenes::Aabb& bounds, double cell_size,
                                                  double base_z, double height) {
  if (!(std::isfinite(cell_size) && cell_size > 0.0)) {
    return absl::InvalidArgumentError(absl::StrCat("viewcell size must be positive, got ", cell_size));
  }
  if (!(std::isfinite(height) && height > 0.0) || !std::isfinite(base_z)) {
    return absl::InvalidArgumentError(
        absl::StrCat("viewcell height must be positive and its base finite, got ", height, " at ", base_z));
  }
  if (bounds.Empty()) return absl::InvalidArgumentError("viewcell grid over an empty scene");
  ViewcellGrid g;
  g.size_ = cell_size;
  g.base_z_ = base_z;
  g.height_ = height;
  const double i0 = std::floor(bounds.min.x / cell_size), j0 = std::floor(bounds.min.y / cell_size);
  const double i1 = std::floor(bounds.max.x / cell_size), j1 = std::floor(bounds.max.y / cell_size);
  const double nx = i1 - i0 + 1, ny = j1 - j0 + 1;
  if (!(nx * ny <= 2147483648.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("viewcell grid of ", nx, " x ", ny, " cells is too large; use larger cells"));
  }
  g.x0_ = i0 * cell_size;
  g.y0_ = j0 * cell_size;
  g.nx_ = static_cast<int>(nx);
  g.ny_ = static_cast<int>(ny);
  return g;
}

absl::StatusOr<ViewcellGrid> ViewcellGrid::Create(const scenes::Scene& scene, const scenes::ViewcellSpec& spec) {
  absl::StatusOr<ViewcellGrid> flat = Create(scene.bounds, spec);
  if (!flat.ok() || scene.terrain.empty()) return flat;
  const scenes::TerrainHeight terrain(scene);
  std::vector<CellBand> bands(flat->CellCount());
  for (CellId id = 0; id < bands.size(); ++id) {
    const CellCoord c = flat->Coord(id);
    const glm::dvec2 lo(flat->x0_ + c.i * flat->size_, flat->y0_ + c.j * flat->size_);
    const scenes::HeightRange g = terrain.Range(lo, lo + glm::dvec2(flat->size_));
    bands[id] = {g.min + spec.base_m, g.max + spec.base_m + spec.height_m};
  }
  return WithBands(*std::move(flat), std::move(bands));
}

absl::StatusOr<ViewcellGrid> ViewcellGrid::WithBands(ViewcellGrid flat, std::vector<CellBand> bands) {
  if (bands.size() != flat.CellCount()) {
    return absl::InvalidArgumentError(
        absl::StrCat(bands.size(), " viewcell bands for a grid of ", flat.CellCount(), " cells"));
  }
  flat.zlo_ = std::numeric_limits<double>::infinity();
  flat.zhi_ = -std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < bands.size(); ++k) {
    if (!(std::isfinite(bands[k].z0) && std::isfinite(bands[k].z1) && bands[k].z0 < bands[k].z1)) {
      return absl::InvalidArgumentError(
          absl::StrCat("viewcell ", k, "'s band [", bands[k].z0, ", ", bands[k].z1, "] is empty or not finite"));
    }
    flat.zlo_ = std::min(flat.zlo_, bands[k].z0);
    flat.zhi_ = std::max(flat.zhi_, bands[k].z1);
  }
  flat.bands_ = std::move(bands);
  return flat;
}

absl::StatusOr<ViewcellGrid> ViewcellGrid::FromLayout(const glm::dvec2& corner, double cell_size, int nx, int ny,
                                                      double base_z, double height) {
  ViewcellGrid g;
  g.base_z_ = base_z;
  g.height_ = height;
  if (!(std::isfinite(cell_size) && cell_size > 0.0 && nx > 0 && ny > 0 && std::isfinite(corner.x) &&
        std::isfinite(corner.y))) {
    return g;  // no cells
  }
  if (!(double(nx) * double(ny) <= 2147483648.0)) {
    return absl::InvalidArgumentError(
        absl::StrCat("viewcell grid of ", nx, " x ", ny, " cells is too large; use larger cells"));
  }
  g.size_ = cell_size;
  g.x0_ = corner.x;
  g.y0_ = corner.y;
  g.nx_ = nx;
  g.ny_ = ny;
  return g;
}

std::vector<CellCoord> ViewcellGrid::Sample(size_t count, uint64_t seed) const {
  count = std::min(count, CellCount());
  scenes::Rng rng(seed);
  std::vector<CellCoord> cells;
  while (cells.size() < count) {
    const CellCoord c{static_cast<int>(rng.Below(nx_)), static_cast<int>(rng.Below(ny_))};
    if (std::find(cells.begin(), cells.end(), c) == cells.end()) cells.push_back(c);
  }
  return cells;
}

scenes::Aabb ViewcellGrid::CellBox(CellCoord c) const {
  if (!bands_.empty()) {
    const CellBand b = bands_[Id(c)];
    return scenes::Aabb{glm::dvec3(x0_ + c.i * size_, y0_ + c.j * size_, b.z0),
                        glm::dvec3(x0_ + c.i * size_ + size_, y0_ + c.j * size_ + size_, b.z1)};
  }
  const glm::dvec3 lo(x0_ + c.i * size_, y0_ + c.j * size_, base_z_);
  return scenes::Aabb{lo, lo + glm::dvec3(size_, size_, height_)};
}

std::optional<CellId> ViewcellGrid::CellAt(const glm::dvec2& p) const {
  if (!std::isfinite(p.x) || !std::isfinite(p.y)) return std::nullopt;
  const double fi = std::floor((p.x - x0_) / size_), fj = std::floor((p.y - y0_) / size_);
  if (fi < 0 || fj < 0 || fi >= nx_ || fj >= ny_) return std::nullopt;
  return Id({static_cast<int>(fi), static_cast<int>(fj)});
}

std::vector<CellId> ViewcellGrid::Neighbours(CellId id) const {
  std::vector<CellId> out = Neighbourhood(id);
  std::erase(out, id);
  return out;
}

std::vector<CellId> ViewcellGrid::Neighbourhood(CellId id) const {
  const CellCoord c = Coord(id);
  std::vector<CellId> out;
  for (int dj = -1; dj <= 1; ++dj) {
    for (int di = -1; di <= 1; ++di) {
      if (const CellCoord n{c.i + di, c.j + dj}; Valid(n)) out.push_back(Id(n));
    }
  }
  return out;
}

std::vector<CellId> ViewcellGrid::NewlyAdjacent(CellId from, CellId to) const {
  const CellCoord a = Coord(from), b = Coord(to);
  if (from == to || std::abs(a.i - b.i) > 1 || std::abs(a.j - b.j) > 1) return {};
  std::vector<CellId> out;
  for (int dj = -1; dj <= 1; ++dj) {
    for (int di = -1; di <= 1; ++di) {
      const CellCoord n{b.i + di, b.j + dj};
      if (Valid(n) && (std::abs(n.i - a.i) > 1 || std::abs(n.j - a.j) > 1)) out.push_back(Id(n));
    }
  }
  return out;
}

}  // namespace vistream::visibility
