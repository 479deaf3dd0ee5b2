#include "client/minimap.h"

#include <algorithm>
#include <cmath>

#include "client/cell_completion.h"

namespace vistream::client {

std::array<uint8_t, 3> MinimapColour(CellState state) {
  switch (state) {
    case CellState::kComplete:
      return {64, 160, 90};
    case CellState::kPending:
      return {225, 170, 40};
    case CellState::kNotListed:
      break;
  }
  return {70, 74, 82};
}

std::array<uint8_t, 3> MinimapCurrentCellColour() { return {80, 170, 255}; }

double MinimapRadius(const visibility::ViewcellGrid& grid) { return std::clamp(8.0 * grid.cell_size(), 150.0, 600.0); }

void MinimapCells::Refresh(const ObjectStore& store, const std::function<bool(uint32_t)>& uploaded,
                           const glm::dvec3& eye, double radius_m, size_t max_lookups) {
  if (!store.has_scene_info()) return;
  const visibility::ViewcellGrid& g = store.grid();
  const double x0 = g.corner().x, y0 = g.corner().y, size = g.cell_size();
  const size_t n = g.CellCount();
  if (states_.size() != n) states_.assign(n, CellState::kNotListed);
  size_t lookups = 0;
  auto state = [&](uint32_t id) {
    const std::vector<uint32_t>* list = store.Pvs(id);
    if (list == nullptr) return CellState::kNotListed;
    // The client model's rule (client/cell_completion.h), each object looked at counted.
    const bool complete = CellComplete(list, [&](uint32_t o) {
      ++lookups;
      return uploaded(o);
    });
    return complete ? CellState::kComplete : CellState::kPending;
  };
  if (const std::optional<uint32_t> c = g.CellAt({eye.x, eye.y})) states_[*c] = state(*c);
  const double r = radius_m + size;
  const int i0 = std::max(0, static_cast<int>(std::floor((eye.x - r - x0) / size)));
  const int i1 = std::min(g.nx() - 1, static_cast<int>(std::floor((eye.x + r - x0) / size)));
  const int j0 = std::max(0, static_cast<int>(std::floor((eye.y - r - y0) / size)));
  const int j1 = std::min(g.ny() - 1, static_cast<int>(std::floor((eye.y + r - y0) / size)));
  if (i1 < i0 || j1 < j0) return;
  const size_t w = static_cast<size_t>(i1 - i0 + 1), count = w * static_cast<size_t>(j1 - j0 + 1);
  for (size_t k = 0; k < count && lookups < max_lookups; ++k) {
    const size_t at = cursor_++ % count;
    const auto id = g.Id({i0 + static_cast<int>(at % w), j0 + static_cast<int>(at / w)});
    states_[id] = state(id);
  }
}

}  // namespace vistream::client
