#include "scenes/walk.h"

#include <algorithm>
#include <cmath>

#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>

namespace vistream::scenes {

absl::StatusOr<Walk> Walk::Create(const WalkPath& path, double speed_mps,
                                  std::shared_ptr<const TerrainHeight> terrain) {
  if (!(speed_mps > 0.0) || !std::isfinite(speed_mps)) {
    return absl::InvalidArgumentError(absl::StrCat("walk '", path.name, "': speed ", speed_mps, " m/s is not positive"));
  }
  Walk w;
  w.speed_ = speed_mps;
  w.eye_height_ = path.eye_height_m;
  if (terrain != nullptr && !terrain->empty()) w.terrain_ = std::move(terrain);
  for (const glm::dvec2& p : path.waypoints) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) {
      return absl::InvalidArgumentError(absl::StrCat("walk '", path.name, "': a waypoint is not finite"));
    }
    if (!w.points_.empty() && glm::distance(w.points_.back(), p) < 1e-9) continue;
    w.cumulative_.push_back(w.points_.empty() ? 0.0 : w.cumulative_.back() + glm::distance(w.points_.back(), p));
    w.points_.push_back(p);
  }
  if (w.points_.size() < 2) {
    return absl::InvalidArgumentError(absl::StrCat("walk '", path.name, "' has fewer than two distinct waypoints"));
  }
  return w;
}

glm::dvec2 Walk::PointAt(double s) const {
  s = std::clamp(s, 0.0, length_m());
  const size_t k = static_cast<size_t>(std::upper_bound(cumulative_.begin(), cumulative_.end(), s) - cumulative_.begin());
  if (k >= points_.size()) return points_.back();
  const double a = cumulative_[k - 1], b = cumulative_[k];
  // a + (b - a) f, not glm::mix's a (1 - f) + b f: a segment along a viewcell edge (x or y
  // constant) stays exactly on it, so the eye does not flip between the two cells.
  return points_[k - 1] + (points_[k] - points_[k - 1]) * ((s - a) / (b - a));
}

std::vector<uint32_t> Walk::CellsAlong(
    double cell_size_m, const std::function<std::optional<uint32_t>(const glm::dvec2&)>& cell_at) const {
  std::vector<uint32_t> cells;
  const double step = std::min(0.25, 0.01 * cell_size_m);
  const size_t n = static_cast<size_t>(std::ceil(length_m() / step));
  for (size_t k = 0; k <= n; ++k) {
    const std::optional<uint32_t> c = cell_at(PointAt(static_cast<double>(k) * step));
    if (c.has_value() && (cells.empty() || cells.back() != *c)) cells.push_back(*c);
  }
  return cells;
}

WalkPose Walk::At(double t) const {
  constexpr double kLookAhead = 8.0;  // metres
  const double s = std::clamp(t * speed_, 0.0, length_m());
  WalkPose pose;
  const glm::dvec2 p = PointAt(s);
  pose.eye = {p.x, p.y, terrain_ != nullptr ? terrain_->HeightAt(p) + eye_height_ : eye_height_};
  // Look at the path ahead (behind, at the very end).
  glm::dvec2 d = PointAt(s + kLookAhead) - p;
  if (glm::length(d) < 1e-6) d = p - PointAt(s - kLookAhead);
  pose.yaw_rad = std::atan2(d.y, d.x);
  if (s < length_m()) {
    const glm::dvec2 step = PointAt(s + 0.5) - p;
    const double len = glm::length(step);
    if (len > 0.0) {
      const double rise = terrain_ != nullptr ? terrain_->HeightAt(p + step) - terrain_->HeightAt(p) : 0.0;
      pose.velocity = glm::dvec3(step / len * speed_, rise / len * speed_);
    }
  }
  return pose;
}

}  // namespace vistream::scenes
