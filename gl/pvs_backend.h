#pragma once
// The dual-ray-space backends by name, for every command that computes viewcell PVSs: cpu (the
// CPU raster), gl (the same raster drawn by OpenGL through OSMesa), exact (the CPU raster, then
// CGAL's exact union test wherever it leaves a gap: the reference overestimation is measured
// by).

#include <functional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include <absl/status/statusor.h>

#include "gl/gl_planar_raster.h"
#include "scenes/progress.h"
#include "visibility/pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::gl {

// The dual ray space's options for a finest raster of `res`² (a power of two, at most 256):
// refinement from 16² (or `res`, if smaller). What `vistream pvs --res` and the server use.
inline visibility::CellQueryOptions QueryOptionsFor(uint32_t res) {
  visibility::CellQueryOptions options;
  options.max_res = res;
  options.min_res = res < 16 ? res : 16;
  return options;
}

class PvsBackend {
 public:
  // Errors: an unknown name; no OpenGL context for gl.
  static absl::StatusOr<PvsBackend> Create(const std::string& name);

  const std::string& name() const { return name_; }
  // `options` with this backend's part set (the exact test on or off).
  visibility::CellQueryOptions Options(visibility::CellQueryOptions options) const;
  // The PVS of one cell, on the calling thread (timed in the result's ms).
  visibility::PvsResult Compute(const visibility::PvsComputer& computer, const scenes::Aabb& cell,
                                const visibility::CellQueryOptions& options) const;
  // The PVS of each cell, in order: cpu and exact on every core, gl on the calling thread (its
  // context is current there).
  std::vector<visibility::PvsResult> ComputeBatch(const visibility::PvsComputer& computer,
                                                  std::span<const scenes::Aabb> cells,
                                                  const visibility::CellQueryOptions& options) const;

 private:
  std::string name_;
  std::unique_ptr<gl::GlPlanarRaster> gl_;
};

// Receives one viewcell's PVS; an error stops ComputeViewcellPvss.
using CellPvsSink = std::function<absl::Status(visibility::CellId cell, const visibility::PvsResult& pvs)>;

// The PVS of each viewcell in `cells` (ids of `grid`; any subset, in any order), computed with
// `backend` in chunks of 64 cells (ComputeBatch: every core for cpu and exact) and handed to
// `sink` in the order of `cells`, chunk by chunk, so a caller can store them as they come. The
// one loop behind `vistream pvs --all` (a whole grid or one shard of it, to a PVS file or a
// PVS store) and the session fuzzer's PVS file. Progress: one unit per cell, under `label`.
// Errors: CANCELLED when `run` is cancelled (checked between chunks; nothing more reaches the
// sink), OUT_OF_RANGE for a cell id outside `grid`, or the sink's first error.
absl::Status ComputeViewcellPvss(const PvsBackend& backend, const visibility::PvsComputer& computer,
                                 const visibility::ViewcellGrid& grid, std::span<const visibility::CellId> cells,
                                 const visibility::CellQueryOptions& options, const scenes::RunControl& run,
                                 const std::string& label, const CellPvsSink& sink);

}  // namespace vistream::gl
