#pragma once
// A terrain for city models that have none (no TINRelief: Delft's 3D BAG + BGT file): a 2.5D
// constrained Delaunay triangulation of the ground-level points the model does have, so that
// buildings whose floors float a little above the data's lowest point stand on a ground and
// occlude from it (the synthesis' GroundSurface test, scenes/occluder_synthesis.h).
// DESIGN.md "City models and terrain".
//
// The points, all scene-local metres:
//   - building floors (their lowest faces), lowest floor first; a floor whose xy interior
//     overlaps a lower one already taken (a part standing on another) is left out. Each floor's
//     triangles' edges are constraints, so that its footprint is exactly a set of terrain
//     triangles; its corners enter at the floor's highest z (floors are flat within a
//     millimetre), and where floors of neighbouring buildings share a corner at the highest of
//     them: every floor lies at or below the ground, so every one can occlude (a lower
//     neighbour's floor lies under the ground near the shared corners, by the floors'
//     difference: up to 0.64 m in Delft).
//   - ground-level surface points (the caller's rule: scenes/city_import.h), less those inside
//     or on a floor taken (the footprint stays the floor's); where several share an xy, the
//     lowest.
//   - the corners of `lo`..`hi` (the data's xy box), at the height of the nearest point above,
//     so that the terrain covers the whole box.
// The triangles are the triangulation's faces: they cover the box's convex hull once in xy,
// counter-clockwise seen from above (up-facing), corners the points above (no constructions).

#include <array>
#include <cstdint>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

namespace vistream::scenes {

using Triangle3 = std::array<glm::dvec3, 3>;

struct DerivedGroundInput {
  // Per building solid shell, its floor's triangles (FloorTriangles; any orientation).
  std::vector<std::vector<Triangle3>> floors;
  std::vector<glm::dvec3> points;  // ground-level points of other surfaces
  glm::dvec2 lo{0.0}, hi{0.0};     // the xy box to cover (lo <= hi)
};

struct DerivedGround {
  std::vector<Triangle3> triangles;  // up-facing, not overlapping in xy
  uint64_t floors = 0;               // floors taken
  uint64_t floors_overlapping = 0;   // left out: over a lower floor
  uint64_t floor_points = 0;         // distinct floor corners in the triangulation
  uint64_t surface_points = 0;       // surface points in it
  uint64_t points_under_floors = 0;  // surface points left out: inside or on a floor
  uint64_t corner_points = 0;        // box corners added
};

// The triangles of `shell` (scene-local metres) that are its floor: those with all three
// corners within `tolerance_m` of the shell's lowest point and a non-zero area in xy. Empty for
// an empty shell.
std::vector<Triangle3> FloorTriangles(const std::vector<Triangle3>& shell, double tolerance_m = 1e-3);

// The derived terrain. Errors: INVALID_ARGUMENT when there is no point at all (nothing to
// derive a ground from) or a coordinate is not finite; INTERNAL if the triangulation refuses
// the constraints (floors that cross, which the overlap rule leaves out).
absl::StatusOr<DerivedGround> DeriveGround(const DerivedGroundInput& input);

}  // namespace vistream::scenes
