#include "tools/agvs_common.h"

#include <algorithm>
#include <cmath>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "tools/cli_common.h"
#include "tools/top_view_map.h"

namespace vistream::tools {

absl::StatusOr<SampledScene> SampledScene::Load(const std::string& scene_arg, double cell_size,
                                                const visibility::AgvsOptions& options) {
  const scenes::ViewcellSpec spec = scenes::ViewcellSpecFor(scene_arg, cell_size);
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(scene_arg);
  if (!scene.ok()) return scene.status();
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, spec);
  if (!grid.ok()) return grid.status();
  absl::StatusOr<std::unique_ptr<visibility::GlobalSampler>> sampler =
      visibility::GlobalSampler::Create(*scene, *grid, options);
  if (!sampler.ok()) return sampler.status();
  return SampledScene{std::move(*scene), *grid, std::move(*sampler)};
}

absl::StatusOr<visibility::FilterOptions> FilterFromName(const std::string& name) {
  visibility::FilterOptions f;
  if (name == "none") return f;
  if (name == "object" || name == "both") f.object_space = true;
  if (name == "view" || name == "both") f.view_space = true;
  if (!f.object_space && !f.view_space) {
    return absl::InvalidArgumentError("'" + name + "': expected none, object, view or both");
  }
  return f;
}

visibility::PvsFile MakePvsFile(const SampledScene& s, const visibility::GlobalPvs& sets) {
  const visibility::AgvsStats& st = s.sampler->stats();
  return visibility::MakePvsFile(s.scene, s.grid, sets,
                                 {visibility::StrategyName(s.sampler->options().strategy), st.samples, st.seconds,
                                  st.estimated_pixel_error});
}

double MeanTriangles(const scenes::Scene& scene, const visibility::GlobalPvs& sets) {
  if (sets.cell_count() == 0) return 0.0;
  double sum = 0.0;
  for (visibility::CellId c = 0; c < sets.cell_count(); ++c) {
    for (scenes::ObjectId o : sets.Objects(c)) {
      if (o < scene.objects.size()) sum += static_cast<double>(scene.objects[o].mesh.TriangleCount());
    }
  }
  return sum / static_cast<double>(sets.cell_count());
}

HeatmapStats WriteHeatmap(const scenes::Scene& scene, const visibility::ViewcellGrid& grid,
                          const visibility::GlobalPvs& sets, const std::string& png, const std::string& source,
                          int max_pixels) {
  HeatmapStats h;
  std::vector<uint64_t> cost(sets.cell_count(), 0);
  double sum = 0.0;
  for (visibility::CellId c = 0; c < sets.cell_count(); ++c) {
    for (scenes::ObjectId o : sets.Objects(c)) {
      if (o < scene.objects.size()) cost[c] += scene.objects[o].mesh.TriangleCount();
    }
    h.max_triangles = std::max(h.max_triangles, cost[c]);
    sum += static_cast<double>(cost[c]);
  }
  h.mean_triangles = sets.cell_count() > 0 ? sum / static_cast<double>(sets.cell_count()) : 0.0;
  scenes::Aabb area = grid.Bounds();
  area.Extend(scene.bounds);
  TopViewMap map(area, max_pixels, Rgb{250, 250, 250});
  const double top = std::log1p(static_cast<double>(std::max<uint64_t>(h.max_triangles, 1)));
  for (visibility::CellId c = 0; c < sets.cell_count(); ++c) {
    const scenes::Aabb b = grid.CellBox(c);
    const std::vector<glm::dvec2> square = {{b.min.x, b.min.y}, {b.max.x, b.min.y}, {b.max.x, b.max.y}, {b.min.x, b.max.y}};
    map.FillPolygon(square, Ramp(std::log1p(static_cast<double>(cost[c])) / top), /*antialias=*/false);
  }
  const Rgb outline{40, 40, 40};
  h.outlines = map.outlines_readable();
  if (h.outlines) {
    for (const auto& oc : scene.occluders) map.StrokePolygon(oc.footprint, outline, 0.6);
  }
  map.SetTitle(absl::StrCat(scene.name, ": PVS cost of every viewcell (", source, ")"),
               absl::StrFormat("%zu viewcells of %g m; mean %.0f, max %llu triangles per viewcell", sets.cell_count(),
                               grid.cell_size(), h.mean_triangles, static_cast<unsigned long long>(h.max_triangles)));
  if (h.outlines) {
    map.AddLegend(outline, "building footprint", Swatch::kOutline);
  } else {
    map.AddNote(absl::StrFormat("footprints outlined below %g m per pixel only", TopViewMap::kOutlineMetresPerPixel));
  }
  map.SetColourBar("PVS cost (triangles per viewcell, log scale)", static_cast<double>(std::max<uint64_t>(h.max_triangles, 1)));
  h.metres_per_pixel = map.metres_per_pixel();
  h.width = map.width();
  h.height = map.height();
  h.status = map.WritePng(png);
  return h;
}

}  // namespace vistream::tools
