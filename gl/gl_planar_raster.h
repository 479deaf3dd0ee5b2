#pragma once
// The paper's hardware path for the planar test: each blocker's region in the dual ray space
// is drawn as the trapezes and double triangles of its hull edges, white on black, and any
// black pixel left means a gap. The paper shrinks the polygons by sqrt(2) half pixels so that a
// pixel centre inside means the whole pixel inside; here the fragment shader makes that test
// exactly, in double precision, with the same arithmetic as the CPU raster, so both backends
// set the same pixels (the polygons are drawn a quarter pixel too large, so that no pixel
// that passes is missed). Needs a GL 4.5 context (client/gl_context.h).

#include <array>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "gl/gl_context.h"
#include "visibility/conservative_raster.h"

namespace vistream::gl {

class GlPlanarRaster final : public visibility::PlanarRaster {
 public:
  // Makes its own off-screen context, current on the calling thread; use it on that thread.
  static absl::StatusOr<std::unique_ptr<GlPlanarRaster>> Create();
  ~GlPlanarRaster() override;

  bool Full(const visibility::Blockers& blockers, uint32_t n, std::span<const uint32_t> rows,
            std::vector<uint32_t>* gap_rows) override;
  void Draw(const visibility::Blockers& blockers, uint32_t n, std::vector<uint8_t>* pixels) override;

 private:
  GlPlanarRaster() = default;
  absl::Status Init();
  // The n x n raster of the blockers: drawn into the framebuffer and read back, unless drawn
  // already for the same blockers (the caller asks row by row, from resolution to resolution).
  const std::vector<uint8_t>& Render(const visibility::Blockers& blockers, uint32_t n);

  std::unique_ptr<GlContext> context_;
  unsigned program_ = 0, vao_ = 0, vbo_ = 0, ssbo_ = 0, fbo_ = 0, texture_ = 0;
  struct Vertex {
    float u, v;
    uint32_t begin, end;
  };
  std::vector<Vertex> vertices_;
  std::vector<double> coeffs_;  // the shader's storage buffer: eps, n, then a, b, c, 1 / b each
  std::vector<std::pair<uint32_t, uint32_t>> groups_;  // each blocker's range of coeffs
  std::vector<double> next_coeffs_;
  std::vector<std::pair<uint32_t, uint32_t>> next_groups_;
  std::array<std::vector<uint8_t>, 9> rasters_;  // of coeffs_ and groups_ at n = 2^k, once drawn
};

}  // namespace vistream::gl
