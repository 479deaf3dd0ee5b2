#pragma once
// Cell-to-cell visibility among 2.5D occluders in the dual ray space (Koltun, Chrysanthou,
// Cohen-Or 2001). For boxes A and B separated by a vertical plane, the question reduces to a
// planar one on the shaft's ceiling T: can the segment s1 (on A's face) see s2 (on B's face)
// among the occluder parts that rise above T? A ray from s1(u) to s2(v) is a point (u, v) of
// the unit square RS. A connected blocker with points p_k blocks exactly the rays with
// min_k g_k(u, v) <= 0 <= max_k g_k(u, v), g_k affine and increasing in u and v, so a pixel
// of RS is wholly blocked iff min_k g_k at its upper corner <= 0 <= max_k g_k at its lower.
// Touching occluders fuse into one connected blocker through their contacts.

#include <algorithm>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "scenes/aabb.h"
#include "visibility/conservative_raster.h"
#include "visibility/free_line_pool.h"
#include "visibility/occluder_set.h"

namespace vistream::visibility {

struct CellQueryOptions {
  uint32_t min_res = 16;   // first raster resolution
  // Refined by doubling up to this; a power of two, at most 256. At max_res n, B is hidden
  // when every row of RS, split from min_res as long as a row is undecided and at most down to
  // height 1/n, is covered: by the blockers' rectangles over it (Blockers::BandCovered; what a
  // full raster row at n would also show) or by their trapezoids (BandCoveredSlanted: each
  // blocker as the region between two of its root lines over the row). Never less precise at
  // 2n than at n: the rows tried at n are tried at 2n, and a covered row's halves are covered.
  uint32_t max_res = 128;
  bool free_ray_test = true;  // test uncovered pixel centres exactly: a free ray ends the query
  // Trace the fixed probe rays (13 spread over RS) before building blockers. Only a speed-up,
  // the answer is the same without: where B is likely hidden (hidden from a neighbouring
  // viewcell, say) they are mostly traced in vain.
  bool probe_rays = true;
  // Where the raster at max_res still leaves a gap, decide with the exact union test (CGAL's
  // exact kernel) instead: the reference for overestimation, not for speed.
  bool exact = false;
};

struct CellQueryStats {
  uint64_t queries = 0;        // Visible() calls
  uint64_t non_separable = 0;  // answered visible without a planar test
  uint64_t planar_tests = 0;   // planar problems set up
  uint64_t gathered = 0;       // occluder pieces gathered from the grid, summed over planar tests
  uint64_t pieces = 0;         // blocker hull vertices kept, summed over planar tests
  uint64_t raster_rows = 0;    // raster rows tested, summed over resolutions
  uint64_t free_rays = 0;      // planar tests ended by a free ray
  uint64_t exact_tests = 0;    // planar tests decided by the exact union test
  uint64_t occluded = 0;       // Visible() answers false

  CellQueryStats& operator+=(const CellQueryStats& o) {
    queries += o.queries, non_separable += o.non_separable, planar_tests += o.planar_tests;
    gathered += o.gathered, pieces += o.pieces, raster_rows += o.raster_rows, free_rays += o.free_rays;
    exact_tests += o.exact_tests, occluded += o.occluded;
    return *this;
  }
};

// The planar problem of one separating direction, in a query-relative frame (p along the
// separating axis from A towards B, q across it; origin at A's lower corner).
struct PlanarProblem {
  int axis = 0;      // 0: x separates, 1: y
  double sign = 1;   // +1: B on the positive side of A
  glm::dvec2 origin{0.0};
  double x1 = 0, x2 = 0;          // slab between A's face (p = x1) and B's face (p = x2)
  double r1 = 0, l1 = 0;          // s1 = [r1, l1] in q at p = x1 (the shaft's cross-section)
  double r2 = 0, l2 = 0;          // s2 at p = x2
  double alpha = 0, beta = 0;     // the ceiling T: z = alpha + beta p

  glm::dvec2 PlanarFromScene(const glm::dvec2& w) const {
    return {sign * (w[axis] - origin[axis]), w[1 - axis] - origin[1 - axis]};
  }
  glm::dvec2 SceneFromPlanar(double p, double q) const {
    glm::dvec2 w(0.0);
    w[axis] = origin[axis] + sign * p;
    w[1 - axis] = origin[1 - axis] + q;
    return w;
  }
  // The lowest point of T over the slab: prisms no taller block nothing.
  double CeilingMin() const { return std::min(alpha + beta * x1, alpha + beta * x2); }
  // The part [lo, hi] of the slab where a prism of `height` reaches T; false when that part
  // has no length (a prism that reaches T only at a face of the slab blocks nothing there).
  bool BlockingStrip(double height, double* lo, double* hi) const {
    *lo = x1;
    *hi = x2;
    if (beta > 0) *hi = std::min(*hi, (height - alpha) / beta);
    else if (beta < 0) *lo = std::max(*lo, (height - alpha) / beta);
    else if (height < alpha) return false;
    return *lo < *hi;
  }
  // Whether a piece whose points span [p_min, p_max] along p, standing to `height`, blocks a
  // set of rays with an area, and the strip [lo, hi] it blocks in. A ray of RS runs in the
  // open slab x1 < p < x2 and ends on the faces, so only a piece's interior there stops it:
  // a piece (or what is left of it in the strip) that lies on a face of the slab, such as a
  // wall of one of B's own objects on B's face, has no interior in the slab and stops no ray
  // that ends on it; it must not become a zero-width blocker. A segment piece (a wall of zero
  // thickness) across p blocks if it crosses the open strip; one along q (a single p) if it
  // stands strictly inside the slab.
  bool PieceStrip(double height, double p_min, double p_max, double* lo, double* hi) const {
    if (!BlockingStrip(height, lo, hi)) return false;
    if (p_min < p_max) return std::max(p_min, *lo) < std::min(p_max, *hi);
    return p_min >= *lo && p_min <= *hi && p_min > x1 && p_min < x2;
  }
};

// Sets up the planar problem for A and B separated along `axis` with B on side `sign`;
// false when that plane does not separate them.
bool MakePlanarProblem(const scenes::Aabb& a, const scenes::Aabb& b, int axis, double sign, PlanarProblem* out);

// The planar problems of the vertical planes that separate A and B, at most one per axis (x
// first), in out[0, count); returns count, 0 when no plane separates them (boxes that touch
// or overlap in x and in y). Boxes as for MakePlanarProblem.
int SeparatingPlanes(const scenes::Aabb& a, const scenes::Aabb& b, PlanarProblem (&out)[2]);

// One query engine per thread: it keeps scratch buffers between queries.
class DualRaySpace {
 public:
  // `raster` draws the bitmaps (not owned; null: the CPU raster). Both must outlive this.
  explicit DualRaySpace(const OccluderSet& occluders, PlanarRaster* raster = nullptr)
      : occluders_(occluders), raster_(raster != nullptr ? raster : &cpu_raster_) {}
  // raster_ may point into this object.
  DualRaySpace(const DualRaySpace&) = delete;
  DualRaySpace& operator=(const DualRaySpace&) = delete;

  // Conservative: false only when every segment from A to B meets an occluder (decided on the
  // shaft's ceiling with a conservative raster). Boxes in scene-local metres.
  //
  // `hint`, when valid, is a line worth tracing first (a free one found for a box around B,
  // say): it only saves time. When B is visible and a free ray proved it, *witness (if not
  // null) is set to that ray's line; otherwise it is marked invalid.
  //
  // `pool`, when not null, holds free lines found before from A (for other boxes): those
  // that cross B's shaft are traced before any blocker is built, and the free rays this query
  // finds itself are added to it. Only a speed-up: every line is traced again on B's shaft.
  bool Visible(const scenes::Aabb& a, const scenes::Aabb& b, const CellQueryOptions& options,
               CellQueryStats* stats = nullptr, const FreeLine& hint = {}, FreeLine* witness = nullptr,
               FreeLinePool* pool = nullptr);

  // True only when Visible(a, b) is sure to answer true, proven at the cost of a ray or two:
  // A and B share no separating plane, or the ray of `line` (a FreeLine found for another box
  // near A, say) on the ceiling of a separating plane's shaft is free and, extended along the
  // ceiling, joins a point of A to a point of B (or is free on every separating plane). False
  // when unsure. Boxes in scene-local metres, `line` in scene-local xy; section 5 of Koltun et
  // al. 2001 (the shaft's ceiling), as Visible. In *stats: each free ray it traced, as a planar
  // test ended by a free ray, and one query when it proves.
  bool ProvenVisibleAlong(const scenes::Aabb& a, const scenes::Aabb& b, const FreeLine& line,
                          CellQueryStats* stats = nullptr);

  // The planar test of one separating direction: true when the raster proves every ray of RS
  // blocked. `hint`, `witness` and `pool` as for Visible.
  bool PlanarOccluded(const PlanarProblem& problem, const CellQueryOptions& options, CellQueryStats* stats,
                      const FreeLine& hint = {}, FreeLine* witness = nullptr, FreeLinePool* pool = nullptr);

  // Gathers, clips and fuses the occluders of `problem` into blockers(); no raster yet.
  void BuildBlockers(const PlanarProblem& problem);
  const Blockers& blockers() const { return blockers_; }

 private:
  // The same question for ray (u, v), answered by tracing it through the occluder grid:
  // no blockers need building. Exact up to rounding; used to prove visibility early.
  bool FreeRayTraced(const PlanarProblem& problem, double u, double v);
  // A ray of `problem` along a line of `pool` (but `hint`'s) that FreeRayTraced finds free:
  // true with it in (*u, *v), false when none is.
  bool FreeRayFromPool(const PlanarProblem& problem, const FreeLinePool& pool, const FreeLine& hint, double* u,
                       double* v);
  // *witness = the line of ray (u, v), if witness is not null.
  // Also keeps (u, v) for WitnessJoinsBoxes.
  void SetWitness(const PlanarProblem& problem, double u, double v, FreeLine* witness);
  // Whether the free ray (free_u_, free_v_) of `problem`, extended along the ceiling T into A
  // and B, joins a point of A to a point of B without meeting an occluder: then A and B are
  // mutually visible (not merely undecided), and Visible may skip the other separating plane.
  // Boxes as for Visible; false when unsure.
  bool WitnessJoinsBoxes(const scenes::Aabb& a, const scenes::Aabb& b, const PlanarProblem& problem);
  // Whether the segment on T from (p0, q0) to (p1, q1) (planar frame, p0 <= p1) meets no
  // occluder, boundary included.
  bool SegmentOnCeilingFree(const PlanarProblem& problem, double p0, double q0, double p1, double q1);
  double free_u_ = 0, free_v_ = 0;  // the last free ray SetWitness saw

  const OccluderSet& occluders_;
  CpuRaster cpu_raster_;
  PlanarRaster* raster_;
  GatherScratch scratch_;  // per engine, so engines on different threads never share state
  std::vector<uint32_t> gathered_;
  std::vector<double> lo_, hi_;           // blocking strip of each gathered piece
  std::vector<uint32_t> parent_;          // union-find over gathered pieces
  std::vector<int32_t> local_;            // piece id -> index in gathered_, or -1
  void AddGroup(const PlanarProblem& problem, std::span<const glm::dvec2> points);  // one blocker
  Blockers blockers_;
  std::vector<uint8_t> exact_raster_;  // the raster the exact test starts from
  std::vector<std::pair<double, double>> spans_;  // FreeOnLine's scratch
  SlantedScratch slanted_;                        // BandCoveredSlanted's
  std::vector<std::pair<uint32_t, uint32_t>> row_stack_;  // (resolution, row) still in question
  std::vector<uint32_t> gap_rows_;
  std::vector<uint32_t> pool_lines_;  // FreeLinePool::Candidates' answer
  // Scratch, kept between queries to spare allocations.
  std::vector<glm::dvec2> planar_, clipped_, clip_tmp_, group_points_, hull_scratch_;
  std::vector<glm::dvec2> kept_points_;  // the kept pieces' clipped points, one after another
  std::vector<uint32_t> kept_, kept_begin_, order_, group_start_;
  std::vector<uint8_t> kept_clipped_;  // whether kept piece i was clipped to its strip
};

}  // namespace vistream::visibility
