#pragma once
// Closing the open shells of city models published as surfaces, by their neighbours and the
// ground, for the occluder synthesis (scenes/occluder_synthesis.h). DESIGN.md "City models and
// terrain"; issue 46.
//
// Many cities publish LoD2 as surfaces: terraced houses leave out the walls they share, building
// parts the faces where they touch, some buildings their floor; coordinates of neighbours differ
// by a millimetre where they meet. Such a shell bounds no volume on its own, but the matter it
// stands for is closed: by the neighbour whose shell is open on the same face, by a neighbour's
// face it stands against, or by the ground. An opening towards the air (a missing wall on a
// street side) is not closed by anything, and such a shell gets no occluder.
//
// For each open shell (weld and T-junctions first, within `weld_m`):
//   1. vertices of all the shells given within `weld_m` of each other are welded (to the lowest
//      of them, so that floors never rise off the ground), and every edge that passes within
//      `weld_m` of a vertex is cut there (a T-junction: its triangle is split at the vertex);
//   2. the shell's odd edges (used by an odd number of its triangles) are classed: *covered*
//      when another open shell has the same edge odd (the block's union is closed there: two
//      houses without their party wall) or the edge lies on another shell's face (a part standing
//      on a closed part); *ground* when its ends and middle lie within `weld_m` of the ground;
//      *air* otherwise. Any air edge: the shell stays open (kOpenToAir);
//   3. the odd edges are chained into loops, and each loop is capped: the runs that leave the
//      ground and come back (a party wall's opening) by a planar polygon through the run and its
//      chord on the ground; the loop's ground points (a missing floor) by a polygon triangulated
//      in xy. A run that is not planar within `cap_planarity_m` is capped by the vertical
//      surface over its path when it stands vertically over one (a party wall with a bend);
//      otherwise it is not capped (kCapNotPlanar);
//   4. shells left open only by openings towards each other that do not cap (a party wall
//      bent out of any plane and off the vertical, as between some of Rotterdam's houses) are
//      closed together as a block (kClosedAsBlock): their triangles side by side, where those
//      openings cancel, and the block's other openings capped as in 3. The block's occluders
//      lie in the union of its houses; the caller gives each house the pieces within its box
//      (ClipOccluders);
//   5. a closed shell draws each cap over an opening it shares with a neighbour left open (to
//      the air, or for want of a cap): a viewer can look in through that neighbour, and nothing
//      else closes this shell as drawn there (`drawn`).
// The closed shell (welded, split, capped) then lies within `moved_m` of the union of the data's
// shells and the ground: the caller shrinks its occluders by that much (ShrinkOccluders).
//
// Conservative as far as the data is what it says: an opening is closed only where another
// building's boundary or the ground closes it. Exact predicates are not used for the
// tolerances (they are tolerances); the synthesis afterwards is exact on the closed shell.

#include <array>
#include <string>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/occluder_synthesis.h"
#include "scenes/scene.h"

namespace vistream::scenes {

struct ShellClosureOptions {
  double weld_m = 2e-3;           // points closer than this are one; edges this near a point are cut there
  double cap_planarity_m = 1e-2;  // how far a cap's corners may lie off its plane
};

enum class ShellClosureOutcome {
  kNotOpen,        // closed already (or not asked to close): untouched, `triangles` empty
  kClosed,         // closed by neighbours and ground: `triangles`
  kOpenToAir,      // an opening no neighbour and no ground closes
  kOpeningsTouch,  // openings that meet at a point (a vertex on four odd edges): not capped
  kCapNotPlanar,   // an opening towards a neighbour that is not planar within cap_planarity_m
  kCapFailed,      // a cap that does not triangulate (its outline crosses itself in its plane)
  kClosedAsBlock,  // closed together with the other shells of `block`: `triangles` in block's first
};
// "open to the air", "open: openings touch", "open: opening not planar", "open: opening not
// triangulated"; "" for kNotOpen and kClosed.
const char* ShellClosureName(ShellClosureOutcome outcome);

// One shell to close, or a closed neighbour that may close others (open false): triangles in
// scene-local metres (double), any orientation; `ground` the ground under it (its `triangles`
// may be empty: flat at flat_z).
struct ShellToClose {
  const std::vector<std::array<glm::dvec3, 3>>* triangles = nullptr;
  bool open = false;
  GroundSurface ground;
};

struct ShellClosure {
  ShellClosureOutcome outcome = ShellClosureOutcome::kNotOpen;
  std::vector<std::array<glm::dvec3, 3>> triangles;  // kClosed: the shell welded, split and capped
  // Every open shell, closed or not: its own triangles welded and split, each wound as the
  // data's triangle it comes from, then (closed ones) the caps over openings shared with a
  // neighbour left open (`drawn_caps` of them, last): what to draw, so that the drawn
  // surface has no opening where the closed shell has none (a millimetre gap between a wall
  // and its ground surface lets a rasterizer see into the building at the odd pixel, past the
  // occluder inside; a row whose end house lacks a wall lets a viewer see into every house).
  std::vector<std::array<glm::dvec3, 3>> drawn;
  size_t caps = 0;       // kClosed, kClosedAsBlock: polygons added (party walls, floors)
  // kClosed, kClosedAsBlock: triangles of caps also in `drawn` (over openings shared with a
  // neighbour left open: the party wall the data leaves out, drawn facing that neighbour).
  size_t drawn_caps = 0;
  double moved_m = 0.0;  // kClosed, kClosedAsBlock: farthest any point of `triangles` lies from the data's surfaces
  // kClosedAsBlock: the shells closed together (indices into the shells given, ascending, this
  // one among them); `triangles` is the block's closed shell in the first of them, empty in
  // the others.
  std::vector<uint32_t> block;
};

// Closes the open shells of `shells` (one result per shell, in order; closed ones kNotOpen).
// O(n log n) in the triangles, with grids of the shells' xy extent.
std::vector<ShellClosure> CloseShellsByNeighbours(const std::vector<ShellToClose>& shells,
                                                  const ShellClosureOptions& options = {});

// The ground's height at (x, y): the highest of `ground`'s triangles over that point, flat_z
// where none is.
double GroundHeightAt(const GroundSurface& ground, double x, double y);

// Occluders shrunk by `by_m` >= 0: each footprint less a band of `by_m` along its edges (so
// every point left is at least by_m inside), its height lowered by `by_m`; pieces under
// `min_area_m2` or not above `min_top_m` dropped. Footprints CCW and simple in, CCW and simple
// out (a piece that would have a hole is dropped). For shells that lie within by_m of the data.
std::vector<Occluder25D> ShrinkOccluders(const std::vector<Occluder25D>& occluders, double by_m, double min_area_m2,
                                         double min_top_m);

// Occluders cut to the xy box [lo, hi] (scene-local metres): each footprint's part within it,
// in pieces (CCW, simple; a piece with a hole dropped), pieces under `min_area_m2` dropped;
// heights and objects kept. For a block's occluders given to each of its houses.
std::vector<Occluder25D> ClipOccluders(const std::vector<Occluder25D>& occluders, const glm::dvec2& lo,
                                       const glm::dvec2& hi, double min_area_m2);

}  // namespace vistream::scenes
