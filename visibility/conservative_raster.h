#pragma once
// The blockers of one planar problem in the dual ray space RS = [0, 1]^2, and the conservative
// raster that decides whether they cover it.
//
// A blocker is a connected set of occluder points p_k; ray (u, v) passes p_k on the side given
// by the sign of g_k(u, v) = a + b u + c v (b, c >= 0), and the blocker stops exactly the rays
// with min_k g_k <= 0 <= max_k g_k. Its region is therefore {L(v) <= u <= U(v)} with
// L = min_k and U = max_k of the roots -(a + c v) / b, both non-increasing in v. Pixel
// (i, j) = [i/n, (i+1)/n] x [j/n, (j+1)/n] of an n x n raster lies wholly inside that region iff
// i/n >= L(j/n) and (i+1)/n <= U((j+1)/n), each tested with a margin `eps` in g against rounding.
// Every backend sets exactly the pixels that pass this test for some blocker (PixelBounds).

#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

namespace vistream::visibility {

struct BlockerCoeff {
  double a, b, c;  // g(u, v) = a + b u + c v
  double inv_b;    // 1 / b where b > 0, else 0: roots by multiplication, the same in every backend

  // A b so small that 1 / b overflows counts as 0: g then no longer depends on u.
  static BlockerCoeff Of(double a, double b, double c) {
    const double inv = b > 0 ? 1.0 / b : 0.0;
    return std::isfinite(inv) ? BlockerCoeff{a, b, c, inv} : BlockerCoeff{a, 0.0, c, 0.0};
  }
};

struct Blocker {
  uint32_t begin = 0, end = 0;  // its hull vertices: Blockers::coeffs[begin, end)
  double width = 0.0;           // its blocked width along u on the middle row, for ordering
  // A band [v0, v1] with v1 > v1_max or v0 < v0_min gets no span in [0, 1] from this blocker
  // (RowBounds' hi < 0 or lo > 1), by a margin far above rounding (Blockers::PrepareBands).
  double v1_max = INFINITY, v0_min = -INFINITY;
};

// A blocker's inner trapezoid over one band [v0, v1] of RS (Blockers::BandCoveredSlanted): it
// blocks every u with l(v) <= u <= h(v), l and h linear in v from (l0, h0) at v0 to (l1, h1)
// at v1; infinite ends stay infinite across the band.
struct BandTrapezoid {
  double l0, l1, h0, h1;
};

// Scratch for Blockers::BandCoveredSlanted, kept by the caller to spare allocations.
struct SlantedScratch {
  std::vector<BandTrapezoid> trapezoids;
  std::vector<std::pair<double, double>> reach;  // (at v0, at v1): [0, reach] is covered
};

struct Blockers {
  std::vector<BlockerCoeff> coeffs;
  std::vector<Blocker> groups;  // widest first: a row usually fills after a few
  double eps = 0.0;             // margin in g against rounding; makes pixels only rarer

  void Clear() {
    coeffs.clear();
    groups.clear();
  }
  // Sets each blocker's v1_max and v0_min from its coefficients and eps: call after both are
  // final. Without it no band skips a blocker.
  void PrepareBands();
  // Is ray (u, v) blocked by none of the blockers? Exact up to rounding.
  bool FreeRay(double u, double v) const;
  // Is some ray on the line v = const free? Each blocker stops the interval [L(v), U(v)] of
  // it; a gap in their union within [0, 1], confirmed by FreeRay, is returned in *u.
  // `scratch` holds the intervals.
  bool FreeOnLine(double v, std::vector<std::pair<double, double>>* scratch, double* u) const;
  // Is the whole band v0 <= v <= v1 blocked? Each blocker blocks the u in its RowBounds for
  // every v of the band; true when their union covers [0, 1]. Stronger than a full row of
  // the raster, which needs each pixel inside one blocker.
  bool BandCovered(double v0, double v1, std::vector<std::pair<double, double>>* scratch) const;
  // Is the whole band v0 <= v <= v1 blocked, with each blocker's region there taken as a
  // trapezoid instead of a rectangle? Over the band, blocker g blocks at least the u with
  // l(v) <= u <= h(v), where l is the root line -(a_k + eps + c_k v) / b_k of the vertex k that
  // gives RowBounds' lo at v0 and h that of the vertex giving its hi at v1 (L <= l and h <= U
  // as single lines; the trapezoid holds the RowBounds rectangle, since both lines fall as v
  // rises). Covered is then decided for the union of the trapezoids, with their sides checked
  // at v0 and v1 only: u = 0 reaches; a trapezoid whose l lies, at each v of the band, under
  // the h of some trapezoid reached (or under u = 0) is reached; the band is covered when
  // u = 1 lies so under the reached h. Sides are linear in v, so "under one line at v0 and
  // v1" holds over the band, and "under one line up to some v, under another from there" is
  // decided from the lines' crossings. True wherever BandCovered is, and on both halves of
  // a band where it is; weaker than the exact union (each blocker counts as one trapezoid over
  // the band). This catches the seams of steep blockers (pieces near B's face, where
  // |dU/dv| = c / b is large) whose regions overlap by less than the band's slant: there
  // BandCovered fails at every resolution up to about |dU/dv| / overlap.
  bool BandCoveredSlanted(double v0, double v1, SlantedScratch* scratch) const;
  // The wholly blocked pixels of `g` in the row [v0, v1] are those with u0 >= first and
  // u1 <= second (u0, u1 the pixel's sides).
  std::pair<double, double> RowBounds(const Blocker& g, double v0, double v1) const;
  // The same as pixel columns of an n-wide raster: pixels [first, last] of row j (empty when
  // first > last). The one definition every backend follows.
  std::pair<double, double> PixelBounds(const Blocker& g, uint32_t j, uint32_t n) const;
};

// A backend that draws blockers into an n x n raster (n a power of two, 1 to 256).
class PlanarRaster {
 public:
  virtual ~PlanarRaster() = default;
  // Whether rows `rows` (ascending) of the raster are full: the caller knows the others are (a
  // coarser raster proved them: a wholly blocked pixel's quarters are wholly blocked too), so
  // a backend may skip them. Sets *gap_rows to those of `rows` with a clear pixel, ascending;
  // true when there are none.
  virtual bool Full(const Blockers& blockers, uint32_t n, std::span<const uint32_t> rows,
                    std::vector<uint32_t>* gap_rows) = 0;
  // The whole raster, row-major from j = 0: 1 where set, 0 where clear.
  virtual void Draw(const Blockers& blockers, uint32_t n, std::vector<uint8_t>* pixels) = 0;
};

// Per-row exact intervals on the CPU, only the rows asked for; a row stops at the blocker that
// fills it.
class CpuRaster final : public PlanarRaster {
 public:
  bool Full(const Blockers& blockers, uint32_t n, std::span<const uint32_t> rows,
            std::vector<uint32_t>* gap_rows) override;
  void Draw(const Blockers& blockers, uint32_t n, std::vector<uint8_t>* pixels) override;

 private:
  // ORs the blockers into bits_ for row j; stops early once the row is full. True when full.
  bool DrawRow(const Blockers& blockers, uint32_t j, uint32_t n, bool stop_when_full);
  bool RowFull(uint32_t n) const;
  std::vector<uint64_t> bits_;
};

}  // namespace vistream::visibility
