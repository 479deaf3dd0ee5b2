#include "tools/top_view_map.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>

#include <cstring>

#include <absl/strings/str_cat.h>

#include "client/png_image.h"

namespace vistream::tools {

static_assert(sizeof(Rgb) == 3, "pixels are written to libpng as packed RGB");

TopViewMap::TopViewMap(const scenes::Aabb& bounds, int max_pixels, Rgb background) {
  const double w = std::max(bounds.max.x - bounds.min.x, 1e-6);
  const double h = std::max(bounds.max.y - bounds.min.y, 1e-6);
  max_pixels = std::clamp(max_pixels, 16, 16384);
  scale_ = std::max(w, h) / max_pixels;
  width_ = std::max(1, static_cast<int>(std::ceil(w / scale_)));
  height_ = std::max(1, static_cast<int>(std::ceil(h / scale_)));
  min_ = glm::dvec2(bounds.min.x, bounds.min.y);
  pixels_.assign(static_cast<size_t>(width_) * height_, background);
}

glm::dvec2 TopViewMap::PixelFromScene(const glm::dvec2& p) const {
  return {(p.x - min_.x) / scale_, height_ - (p.y - min_.y) / scale_};
}

void TopViewMap::Plot(int x, int y, Rgb colour) {
  if (x >= 0 && y >= 0 && x < width_ && y < height_) pixels_[static_cast<size_t>(y) * width_ + x] = colour;
}

void TopViewMap::FillPolygon(std::span<const glm::dvec2> polygon, Rgb colour) {
  if (polygon.size() < 3) return;
  std::vector<glm::dvec2> px;
  px.reserve(polygon.size());
  double top = INFINITY, bottom = -INFINITY;
  for (const glm::dvec2& p : polygon) {
    px.push_back(PixelFromScene(p));
    top = std::min(top, px.back().y);
    bottom = std::max(bottom, px.back().y);
  }
  const int y0 = std::max(0, static_cast<int>(std::ceil(top - 0.5)));
  const int y1 = std::min(height_ - 1, static_cast<int>(std::floor(bottom - 0.5)));
  std::vector<double> xs;
  for (int y = y0; y <= y1; ++y) {
    const double cy = y + 0.5;
    xs.clear();
    for (size_t i = 0, j = px.size() - 1; i < px.size(); j = i++) {
      const glm::dvec2 &a = px[i], &b = px[j];
      if ((a.y > cy) != (b.y > cy)) xs.push_back(a.x + (cy - a.y) * (b.x - a.x) / (b.y - a.y));
    }
    std::sort(xs.begin(), xs.end());
    for (size_t k = 0; k + 1 < xs.size(); k += 2) {
      const int x0 = std::max(0, static_cast<int>(std::ceil(xs[k] - 0.5)));
      const int x1 = std::min(width_ - 1, static_cast<int>(std::floor(xs[k + 1] - 0.5)));
      for (int x = x0; x <= x1; ++x) pixels_[static_cast<size_t>(y) * width_ + x] = colour;
    }
  }
}

void TopViewMap::Line(const glm::dvec2& a, const glm::dvec2& b, Rgb colour, int thickness) {
  const glm::dvec2 pa = PixelFromScene(a), pb = PixelFromScene(b);
  const double len = std::max(std::abs(pb.x - pa.x), std::abs(pb.y - pa.y));
  const int steps = std::max(1, static_cast<int>(std::ceil(len)));
  const int r = thickness / 2;
  for (int s = 0; s <= steps; ++s) {
    const glm::dvec2 p = pa + (pb - pa) * (static_cast<double>(s) / steps);
    for (int dy = -r; dy <= r; ++dy) {
      for (int dx = -r; dx <= r; ++dx) Plot(static_cast<int>(std::floor(p.x)) + dx, static_cast<int>(std::floor(p.y)) + dy, colour);
    }
  }
}

void TopViewMap::StrokePolygon(std::span<const glm::dvec2> polygon, Rgb colour) {
  for (size_t i = 0; i < polygon.size(); ++i) Line(polygon[i], polygon[(i + 1) % polygon.size()], colour);
}

absl::Status TopViewMap::WritePng(const std::string& path) const {
  client::RgbImage image;
  image.width = width_;
  image.height = height_;
  image.rgb.resize(pixels_.size() * 3);
  std::memcpy(image.rgb.data(), pixels_.data(), image.rgb.size());
  return client::WritePng(path, image);
}

Rgb Ramp(double t) {
  t = std::clamp(t, 0.0, 1.0);
  // Piecewise-linear through a few viridis-like stops.
  static constexpr double stops[5][3] = {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  const double x = t * 4.0;
  const int i = std::min(3, static_cast<int>(x));
  const double f = x - i;
  auto mix = [&](int c) { return static_cast<uint8_t>(std::lround(stops[i][c] + f * (stops[i + 1][c] - stops[i][c]))); };
  return {mix(0), mix(1), mix(2)};
}

}  // namespace vistream::tools
