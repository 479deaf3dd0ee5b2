#include "gl/pvs_backend.h"

#include <algorithm>

#include <absl/strings/str_cat.h>

namespace vistream::gl {

absl::StatusOr<PvsBackend> PvsBackend::Create(const std::string& name) {
  PvsBackend b;
  b.name_ = name;
  if (name == "gl") {
    absl::StatusOr<std::unique_ptr<gl::GlPlanarRaster>> r = gl::GlPlanarRaster::Create();
    if (!r.ok()) return r.status();
    b.gl_ = std::move(*r);
  } else if (name != "cpu" && name != "exact") {
    return absl::InvalidArgumentError("unknown backend '" + name + "' (cpu, gl or exact)");
  }
  return b;
}

visibility::CellQueryOptions PvsBackend::Options(visibility::CellQueryOptions options) const {
  options.exact = name_ == "exact";
  return options;
}

visibility::PvsResult PvsBackend::Compute(const visibility::PvsComputer& computer, const scenes::Aabb& cell,
                                          const visibility::CellQueryOptions& options) const {
  visibility::DualRaySpace engine(computer.occluders(), gl_.get());
  return computer.Compute(cell, Options(options), &engine);
}

std::vector<visibility::PvsResult> PvsBackend::ComputeBatch(const visibility::PvsComputer& computer,
                                                            std::span<const scenes::Aabb> cells,
                                                            const visibility::CellQueryOptions& options) const {
  if (gl_ == nullptr) return computer.ComputeBatch(cells, Options(options));
  visibility::DualRaySpace engine(computer.occluders(), gl_.get());
  std::vector<visibility::PvsResult> out;
  for (const scenes::Aabb& cell : cells) out.push_back(computer.Compute(cell, Options(options), &engine));
  return out;
}

absl::Status ComputeViewcellPvss(const PvsBackend& backend, const visibility::PvsComputer& computer,
                                 const visibility::ViewcellGrid& grid, std::span<const visibility::CellId> cells,
                                 const visibility::CellQueryOptions& options, const scenes::RunControl& run,
                                 const std::string& label, const CellPvsSink& sink) {
  for (visibility::CellId c : cells) {
    if (c >= grid.CellCount()) {
      return absl::OutOfRangeError(absl::StrCat("viewcell ", c, " is outside the grid of ", grid.CellCount(), " cells"));
    }
  }
  scenes::Progress progress(run, label, cells.size());
  constexpr size_t kChunk = 64;
  std::vector<scenes::Aabb> boxes;
  for (size_t first = 0; first < cells.size(); first += kChunk) {
    if (progress.Cancelled()) return absl::CancelledError(absl::StrCat(label, ": stopped"));
    const std::span<const visibility::CellId> chunk = cells.subspan(first, std::min(kChunk, cells.size() - first));
    boxes.clear();
    for (visibility::CellId c : chunk) boxes.push_back(grid.CellBox(c));
    const std::vector<visibility::PvsResult> r = backend.ComputeBatch(computer, boxes, options);
    for (size_t k = 0; k < chunk.size(); ++k) {
      if (absl::Status st = sink(chunk[k], r[k]); !st.ok()) return st;
    }
    progress.Advance(chunk.size());
  }
  progress.Finish();
  return absl::OkStatus();
}

}  // namespace vistream::gl
