#pragma once
// The overlay's minimap (client/overlay.h, M in the window): the viewcells around the eye,
// north up, each coloured by what the client holds of it, the walk followed and the eye. Its
// cell states are kept here, a bounded amount of work a frame; the panel itself is drawn by the
// overlay (client/overlay_minimap.cpp, with these).

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "client/object_store.h"

namespace vistream::client {

// A viewcell's state on the minimap.
enum class CellState : uint8_t {
  kNotListed,  // no PVS list from the server (not asked for by the eye's motion yet)
  kPending,    // its list is here, some of its geometry is not
  kComplete,   // list and every object here and uploaded
};

// What the minimap draws: the grid, each cell's state, the walk's polyline.
struct MinimapView {
  const visibility::ViewcellGrid* grid = nullptr;
  const std::vector<CellState>* cells = nullptr;  // by cell id, nx * ny (those near the eye current)
  std::vector<glm::dvec2> walk;    // the polyline of the walk followed (scene-local m); may be empty
  double radius_m = 300.0;         // the map shows this far around the eye
};

// How far around the eye the minimap shows: eight cells of `grid`, within 150 to 600 m.
double MinimapRadius(const visibility::ViewcellGrid& grid);

// The minimap's cell states, kept up to date a bounded amount of work a frame: a cell's state
// costs a lookup per object of its PVS list (thousands on london).
class MinimapCells {
 public:
  // The eye's cell every call; the other cells within `radius_m` (+ a cell) of `eye` round
  // robin, until `max_lookups` objects have been checked. `uploaded`: whether an object is
  // here and on the GPU. Each cell on the map is a few calls old at most.
  void Refresh(const ObjectStore& store, const std::function<bool(uint32_t)>& uploaded, const glm::dvec3& eye,
               double radius_m, size_t max_lookups = 4000);
  const std::vector<CellState>& states() const { return states_; }

 private:
  std::vector<CellState> states_;  // by cell id
  size_t cursor_ = 0;
};

// The colours the minimap gives each state (RGB), and the eye's marker.
std::array<uint8_t, 3> MinimapColour(CellState state);
std::array<uint8_t, 3> MinimapCurrentCellColour();

}  // namespace vistream::client
