#include "server/cell_deadlines.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace vistream::server {

double CellDeadline(const visibility::ViewcellGrid& grid, CellId cell, const glm::dvec3& position,
                    const glm::dvec3& velocity, double now) {
  // The time the client needs to reach the cell at its speed (walking pace at least).
  const scenes::Aabb box = grid.CellBox(cell);
  const double dx = std::max({0.0, box.min.x - position.x, position.x - box.max.x});
  const double dy = std::max({0.0, box.min.y - position.y, position.y - box.max.y});
  const double speed = std::max(1.0, std::hypot(velocity.x, velocity.y));
  const double reach = std::hypot(dx, dy) / speed;
  if (std::hypot(velocity.x, velocity.y) < 0.1) return now + reach;
  // Moving: a cell on the line of travel is reached when the line enters it (slab test in xy).
  double enter = 0.0, leave = std::numeric_limits<double>::infinity();
  bool hit = true;
  const double p[2] = {position.x, position.y}, v[2] = {velocity.x, velocity.y};
  const double lo[2] = {box.min.x, box.min.y}, hi[2] = {box.max.x, box.max.y};
  for (int a = 0; a < 2 && hit; ++a) {
    if (std::abs(v[a]) < 1e-9) {
      hit = p[a] >= lo[a] && p[a] <= hi[a];
      continue;
    }
    const double t0 = (lo[a] - p[a]) / v[a], t1 = (hi[a] - p[a]) / v[a];
    enter = std::max(enter, std::min(t0, t1));
    leave = std::min(leave, std::max(t0, t1));
  }
  if (hit && enter <= leave) return now + enter;
  // Off the line: reached only after a turn, so after the cells on it that are as near (a
  // street running beside a cell edge does not put the cell across the edge first).
  // A cell on the line is at most a diagonal (1.41 cells) away.
  return now + 1.5 * (reach + grid.cell_size() / speed);
}

bool Turned(const glm::dvec3& velocity, const glm::dvec3& ranked) {
  const double a = std::hypot(velocity.x, velocity.y), b = std::hypot(ranked.x, ranked.y);
  if ((a < 0.1) != (b < 0.1)) return true;  // started or stopped
  if (a < 0.1) return false;
  constexpr double kCos30 = 0.8660254037844387;
  return (velocity.x * ranked.x + velocity.y * ranked.y) / (a * b) < kCos30;
}

std::vector<std::pair<double, CellId>> WantedCells(const visibility::ViewcellGrid& grid, CellId current,
                                                   const glm::dvec3& position, const glm::dvec3& velocity,
                                                   double now, bool look_ahead) {
  std::vector<std::pair<double, CellId>> order;
  order.emplace_back(now, current);
  if (look_ahead) {
    for (CellId n : grid.Neighbours(current)) order.emplace_back(CellDeadline(grid, n, position, velocity, now), n);
    std::sort(order.begin() + 1, order.end());
  } else {
    // The plain scheme: the grid's order, a millisecond apart (the scheduler serves it so).
    for (CellId n : grid.Neighbours(current)) order.emplace_back(now + 1e-3 * static_cast<double>(order.size()), n);
  }
  return order;
}

}  // namespace vistream::server
