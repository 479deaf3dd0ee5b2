#include "server/neighbourhood_chain.h"

#include <algorithm>
#include <cmath>

#include <glm/common.hpp>

namespace vistream::server {

namespace {

// The box's z range for an eye at `z`: height_m about it, inside `cell`'s band.
void SetZ(const visibility::ViewcellGrid& grid, visibility::CellId cell, double z, double height_m, scenes::Aabb* box) {
  const visibility::CellBand band = grid.Band(cell);
  box->min.z = std::clamp(z - 0.5 * height_m, band.z0, band.z1);
  box->max.z = std::clamp(z + 0.5 * height_m, band.z0, band.z1);
}

void ClipXy(const scenes::Aabb& cell, scenes::Aabb* box) {
  box->min.x = std::max(box->min.x, cell.min.x);
  box->min.y = std::max(box->min.y, cell.min.y);
  box->max.x = std::min(box->max.x, cell.max.x);
  box->max.y = std::min(box->max.y, cell.max.y);
}

}  // namespace

bool NeighbourhoodChain::Covered(const glm::dvec3& p) const {
  return std::any_of(boxes_.begin(), boxes_.end(), [&](const Neighbourhood& n) { return n.box.Contains(p); });
}

std::vector<uint64_t> NeighbourhoodChain::Clear() {
  std::vector<uint64_t> ids;
  for (const Neighbourhood& n : boxes_) ids.push_back(n.id);
  boxes_.clear();
  return ids;
}

std::vector<glm::dvec3> NeighbourhoodChain::PredictPath(const glm::dvec3& eye, const glm::dvec3& velocity,
                                                        double turn_rad_s, const visibility::ViewcellGrid& grid) const {
  std::vector<glm::dvec3> path{eye};
  const double v = std::hypot(velocity.x, velocity.y);
  if (v < opt_.standing_speed_mps || !std::isfinite(v)) return path;
  const double omega = std::isfinite(turn_rad_s) ? std::clamp(turn_rad_s, -opt_.max_turn_rad_s, opt_.max_turn_rad_s) : 0.0;
  // The horizon and one box beyond it: a box started before the horizon gets its full length.
  const double reach = std::clamp(v * opt_.horizon_s, opt_.min_horizon_m, opt_.max_horizon_m) +
                       std::clamp(v * opt_.box_seconds, opt_.min_length_m, opt_.max_length_m);
  const double heading = std::atan2(velocity.y, velocity.x);
  glm::dvec3 p = eye;
  for (double s = 0.0; s + opt_.step_m <= reach + 1e-9; s += opt_.step_m) {
    // The heading half a step on (the midpoint rule along the arc).
    const double t = (s + 0.5 * opt_.step_m) / v;
    const double a = heading + omega * std::min(t, opt_.turn_s);
    p += glm::dvec3(opt_.step_m * std::cos(a), opt_.step_m * std::sin(a), 0.0);
    if (!grid.CellAt(glm::dvec2(p.x, p.y)).has_value()) break;
    path.push_back(p);
  }
  return path;
}

NeighbourhoodChain::Update NeighbourhoodChain::Advance(const glm::dvec3& eye, const glm::dvec3& velocity,
                                                       double turn_rad_s, const visibility::ViewcellGrid& grid,
                                                       const std::function<bool(visibility::CellId)>& allowed) {
  Update u;
  const std::optional<visibility::CellId> here = grid.CellAt(glm::dvec2(eye.x, eye.y));
  if (!here.has_value() || !(eye.z >= grid.Band(*here).z0 && eye.z <= grid.Band(*here).z1)) {
    u.removed = Clear();
    return u;
  }
  const std::vector<glm::dvec3> path = PredictPath(eye, velocity, turn_rad_s, grid);
  if (path.size() == 1) {
    // Standing: the box it stands in, if any, else one around it.
    if (Covered(eye)) return u;
    u.removed = Clear();
    if (!allowed(*here)) return u;
    Neighbourhood n;
    n.id = next_id_++;
    n.cell = *here;
    const double half = 0.5 * opt_.standing_size_m;
    n.box.min = glm::dvec3(eye.x - half, eye.y - half, 0.0);
    n.box.max = glm::dvec3(eye.x + half, eye.y + half, 0.0);
    SetZ(grid, *here, eye.z, opt_.height_m, &n.box);
    ClipXy(grid.CellBox(*here), &n.box);
    boxes_.push_back(n);
    u.added.push_back(n);
    return u;
  }
  // Boxes the path no longer runs through (behind the eye, or off a path that turned) go.
  if (!Covered(eye)) {
    u.removed = Clear();
  } else {
    std::erase_if(boxes_, [&](const Neighbourhood& n) {
      const bool on = std::any_of(path.begin(), path.end(), [&](const glm::dvec3& p) { return n.box.Contains(p); });
      if (!on) u.removed.push_back(n.id);
      return !on;
    });
  }
  const double v = std::hypot(velocity.x, velocity.y);
  const double length = std::clamp(v * opt_.box_seconds, opt_.min_length_m, opt_.max_length_m);
  const size_t per_box = std::max<size_t>(1, static_cast<size_t>(std::lround(length / opt_.step_m)));
  const size_t horizon = static_cast<size_t>(
      std::lround(std::clamp(v * opt_.horizon_s, opt_.min_horizon_m, opt_.max_horizon_m) / opt_.step_m));
  size_t k = 0;
  for (;;) {
    while (k < path.size() && Covered(path[k])) ++k;
    if (k >= path.size() || k > horizon) break;  // boxes start within the horizon
    const visibility::CellId cell = *grid.CellAt(glm::dvec2(path[k].x, path[k].y));
    if (!allowed(cell)) break;
    // From the point before (the boxes then share a stretch of path), through the points of
    // this cell, up to the box's length and area.
    size_t first = k;
    if (k > 0 && grid.CellAt(glm::dvec2(path[k - 1].x, path[k - 1].y)) == cell) first = k - 1;
    scenes::Aabb box;
    box.min = box.max = path[first];
    size_t last = first;
    for (size_t e = first + 1; e < path.size() && e - k < per_box; ++e) {
      if (grid.CellAt(glm::dvec2(path[e].x, path[e].y)) != cell) break;
      scenes::Aabb grown = box;
      grown.min = glm::min(grown.min, path[e]);
      grown.max = glm::max(grown.max, path[e]);
      const double w = grown.max.x - grown.min.x + 2.0 * opt_.lateral_m, h = grown.max.y - grown.min.y + 2.0 * opt_.lateral_m;
      if (w * h > opt_.max_area_m2 && e > k + 1) break;
      box = grown;
      last = e;
    }
    box.min -= glm::dvec3(opt_.lateral_m, opt_.lateral_m, 0.0);
    box.max += glm::dvec3(opt_.lateral_m, opt_.lateral_m, 0.0);
    if (grid.has_bands()) {
      // Cells follow terrain: the eye rises and falls with the ground ahead, which the chain does
      // not know, so a box ahead spans its cell's whole band (it holds wherever the eye walks).
      box.min.z = grid.Band(cell).z0;
      box.max.z = grid.Band(cell).z1;
    } else {
      SetZ(grid, cell, eye.z, opt_.height_m, &box);
    }
    ClipXy(grid.CellBox(cell), &box);
    Neighbourhood n;
    n.id = next_id_++;
    n.cell = cell;
    n.box = box;
    n.along_m = static_cast<double>(k) * opt_.step_m;
    boxes_.push_back(n);
    u.added.push_back(n);
    k = std::max(k, last) + 1;
  }
  return u;
}

}  // namespace vistream::server
