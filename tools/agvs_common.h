#pragma once
// What the sampling tools (agvs, agvs heatmap, check-conservative, bench agvs) share: a
// scene with its viewcell grid and a sampler over it, filters by name, PVS files, heatmaps.

#include <memory>
#include <string>

#include <absl/status/statusor.h>

#include "scenes/scene.h"
#include "visibility/agvs.h"
#include "visibility/global_pvs.h"
#include "visibility/pvs_file.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

struct SampledScene {
  scenes::Scene scene;
  visibility::ViewcellGrid grid;
  std::unique_ptr<visibility::GlobalSampler> sampler;

  // Loads `scene_arg` (catalog name, .json or glTF), its grid (cell edge `cell_size` when
  // positive, else the catalog's) and a sampler with `options`.
  static absl::StatusOr<SampledScene> Load(const std::string& scene_arg, double cell_size,
                                           const visibility::AgvsOptions& options);
};

// none, object, view, both.
absl::StatusOr<visibility::FilterOptions> FilterFromName(const std::string& name);

// The PVS file of `sets` for the scene and grid, with the sampler's provenance.
visibility::PvsFile MakePvsFile(const SampledScene& s, const visibility::GlobalPvs& sets);

// Mean over cells of the triangles of the objects in each cell's set.
double MeanTriangles(const scenes::Scene& scene, const visibility::GlobalPvs& sets);

struct HeatmapStats {
  absl::Status status;
  uint64_t max_triangles = 0;
  double mean_triangles = 0.0;
  int width = 0, height = 0;  // the whole image, pixels
  double metres_per_pixel = 0.0;
  bool outlines = false;  // footprints outlined (only where a pixel is fine enough to read them)
};
// Writes a PNG of every cell coloured by its PVS cost (triangles, on a log ramp), the map
// `max_pixels` (16..16384) on its longer side. The building footprints are outlined over it
// where a pixel is under TopViewMap::kOutlineMetresPerPixel; on a coarser map the legend says
// they are left out. `source` says where the sets came from (for the map's title: "AGVS,
// 10 s", "PVS file x.pvs"). Errors (in `status`) name the PNG.
HeatmapStats WriteHeatmap(const scenes::Scene& scene, const visibility::ViewcellGrid& grid,
                          const visibility::GlobalPvs& sets, const std::string& png, const std::string& source,
                          int max_pixels);

}  // namespace vistream::tools
