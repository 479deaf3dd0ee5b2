#pragma once
// Top-view raster maps of a scene, written as PNG: footprints, viewcells, paths. Used by
// `vistream scene map` and the visibility tools' --map outputs.

#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <absl/status/status.h>
#include <glm/vec2.hpp>

#include "scenes/aabb.h"

namespace vistream::tools {

struct Rgb {
  uint8_t r = 0, g = 0, b = 0;
};

class TopViewMap {
 public:
  // An image of the xy extent of `bounds` (scene-local metres), `max_pixels` on its longer
  // side, north (+y) up, filled with `background`.
  TopViewMap(const scenes::Aabb& bounds, int max_pixels, Rgb background);

  int width() const { return width_; }
  int height() const { return height_; }
  double metres_per_pixel() const { return scale_; }

  // Fills the polygon (any orientation; even-odd rule) by pixel centres.
  void FillPolygon(std::span<const glm::dvec2> polygon, Rgb colour);
  void StrokePolygon(std::span<const glm::dvec2> polygon, Rgb colour);
  void Line(const glm::dvec2& a, const glm::dvec2& b, Rgb colour, int thickness = 1);

  absl::Status WritePng(const std::string& path) const;

 private:
  glm::dvec2 PixelFromScene(const glm::dvec2& p) const;
  void Plot(int x, int y, Rgb colour);

  glm::dvec2 min_;
  double scale_ = 1.0;  // metres per pixel
  int width_ = 1, height_ = 1;
  std::vector<Rgb> pixels_;
};

// A perceptually ordered colour ramp for t in [0, 1] (dark blue, teal, yellow).
Rgb Ramp(double t);

}  // namespace vistream::tools
