#include "proto/scene_info.h"

#include <absl/strings/str_cat.h>

#include "proto/vec3.h"

namespace vistream {

v1::SceneInfo MakeSceneInfo(const scenes::Scene& scene, const visibility::ViewcellGrid& grid, const std::string& name) {
  v1::SceneInfo info;
  info.set_name(name);
  SetVec(scene.origin, info.mutable_origin());
  SetVec(scene.bounds.min, info.mutable_bounds_min());
  SetVec(scene.bounds.max, info.mutable_bounds_max());
  info.set_object_count(static_cast<uint32_t>(scene.objects.size()));
  info.set_triangle_count(scene.TriangleCount());
  v1::ViewcellGrid* g = info.mutable_grid();
  g->set_cell_size_m(grid.cell_size());
  g->set_x0_m(grid.corner().x);
  g->set_y0_m(grid.corner().y);
  g->set_nx(grid.nx());
  g->set_ny(grid.ny());
  g->set_base_z_m(grid.base_z());
  g->set_height_m(grid.height());
  for (const scenes::ScenePath& p : scene.paths) {
    v1::ScenePathInfo* out = info.add_paths();
    out->set_name(p.name);
    for (const glm::dvec2& w : p.waypoints) {
      out->add_xy(w.x);
      out->add_xy(w.y);
    }
  }
  for (const visibility::CellBand& b : grid.bands()) {
    g->add_band_z(b.z0);
    g->add_band_z(b.z1);
  }
  return info;
}

absl::StatusOr<visibility::ViewcellGrid> GridFromSceneInfo(const v1::ViewcellGrid& g) {
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::FromLayout(
      glm::dvec2(g.x0_m(), g.y0_m()), g.cell_size_m(), g.nx(), g.ny(), g.base_z_m(), g.height_m());
  if (!grid.ok() || g.band_z().empty()) return grid;
  const uint64_t cells = g.nx() > 0 && g.ny() > 0 ? uint64_t(g.nx()) * uint64_t(g.ny()) : 0;
  if (uint64_t(g.band_z().size()) != 2 * cells) {
    return absl::InvalidArgumentError(absl::StrCat("the viewcell grid lists ", g.band_z().size(), " band values for ",
                                                   cells, " cells (", 2 * cells, " expected)"));
  }
  std::vector<visibility::CellBand> bands(cells);
  for (size_t k = 0; k < bands.size(); ++k) bands[k] = {g.band_z(2 * int(k)), g.band_z(2 * int(k) + 1)};
  return visibility::ViewcellGrid::WithBands(*std::move(grid), std::move(bands));
}

}  // namespace vistream
