#include "gl/pvs_backend.h"

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

}  // namespace vistream::gl
