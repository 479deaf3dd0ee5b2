#pragma once
// Floors for floorless solids. Extruded LoD1 city models (the Dutch 3D BAG, Delft's file) often
// leave out a solid's ground surface: the walls and the roof are there, and the walls' lower
// edges form an open ring at the solid's lowest height. Such a shell bounds no volume, so the
// occluder synthesis (scenes/occluder_synthesis.h) would skip it; closing it with the obvious
// floor (the ring, triangulated, facing down) makes it the solid the file meant.
// DESIGN.md "City models and terrain".
//
// Only that case is closed: a shell whose boundary edges (used by an odd number of triangles,
// after welding equal points) form closed loops, each vertex on two boundary edges, all within
// `tolerance_m` of the shell's lowest height. Anything else that is open (a missing wall, a
// missing roof, a ring at two heights) stays open for the synthesis to report.

#include <array>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

namespace vistream::scenes {

enum class FloorClosing {
  kAlreadyClosed,  // no boundary edge: nothing to do
  kClosed,         // the floor was made: FloorResult::triangles
  kNotAFloor,      // open, but not only at the lowest height (or the loops touch): left open
  kFailed,         // floor loops that do not triangulate (crossing rings): left open, `why`
};

struct FloorResult {
  FloorClosing outcome = FloorClosing::kAlreadyClosed;
  // kClosed: the floor, the loops triangulated in xy (loops inside loops are holes), corners
  // the loops' own points (so the floor meets the walls exactly), each triangle facing down
  // (clockwise seen from above, outward normal -z).
  std::vector<std::array<glm::dvec3, 3>> triangles;
  size_t loops = 0;  // kClosed: the boundary loops closed
  std::string why;   // kFailed: the triangulation's reason
};

// The floor that closes one shell given as triangles (scene-local metres, double; any
// orientation; degenerate triangles allowed). `tolerance_m` >= 0: how far a loop's points may
// lie above the shell's lowest point (files write floors flat; 1 mm allows for their rounding).
FloorResult CloseFloor(const std::vector<std::array<glm::dvec3, 3>>& shell, double tolerance_m = 1e-3);

}  // namespace vistream::scenes
