#pragma once
// Helpers shared by the test suites.

#include <string>

#include "scenes/random.h"
#include "scenes/scene.h"

namespace vistream::testing {

// A fresh empty directory under the system temp dir, unique to this test process and removed
// at its exit (ProcessTempDir, tests/temp_dir.h).
std::string TempDir();

// Whether `p` lies inside polygon `poly` (xy, either orientation; crossing parity, so a point
// on an edge may go either way).
bool InsidePolygon(const std::vector<glm::dvec2>& poly, const glm::dvec2& p);

// True when the polygon footprints of the scene's occluders keep at least `clearance` metres
// from the segment a-b (scene-local xy).
bool SegmentClearOfOccluders(const scenes::Scene& scene, const glm::dvec2& a, const glm::dvec2& b,
                             double clearance);

// The oracle for conservative visibility: true when the 3D segment p-q clears every prism
// (footprint from z = 0 to its height) by more than `margin` metres, tested by brute force
// (a box test first). A conservative "free": grazing segments count as blocked.
bool SegmentClearOfPrisms(const glm::dvec3& p, const glm::dvec3& q, const std::vector<scenes::Occluder25D>& prisms,
                          double margin);

// A random 2.5D scene on an integer grid in x 12..82, y -40..62, so that collinear edges, rays
// through vertices and shared walls are common, not rare: boxes, thin walls, neighbours.
scenes::Scene RandomGridScene(scenes::Rng& rng);

// A random box B for RandomGridScene queries from a cell at the origin: x 30..100, y -30..50,
// whole metres, from the ground up to 1..24 m.
scenes::Aabb RandomGridBox(scenes::Rng& rng);

// The box [x0, x1] x [y0, y1] x [z0, z1] (scene-local metres).
scenes::Aabb Box(double x0, double y0, double z0, double x1, double y1, double z1);

// The rectangle [x0, x1] x [y0, y1] as a 2.5D occluder of height h (counter-clockwise).
scenes::Occluder25D Rect(double x0, double y0, double x1, double y1, double h);

// A hash of every position, normal, index and occluder: equal scenes hash equal.
uint64_t SceneHash(const scenes::Scene& scene);

}  // namespace vistream::testing
