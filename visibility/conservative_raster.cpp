#include "visibility/conservative_raster.h"

#include <algorithm>
#include <cmath>

namespace vistream::visibility {

bool Blockers::FreeRay(double u, double v) const {
  for (const Blocker& g : groups) {
    double mn = INFINITY, mx = -INFINITY;
    for (uint32_t k = g.begin; k < g.end; ++k) {
      const BlockerCoeff& c = coeffs[k];
      const double val = c.a + c.b * u + c.c * v;
      mn = std::min(mn, val);
      mx = std::max(mx, val);
    }
    if (mn <= 0.0 && mx >= 0.0) return false;
  }
  return true;
}

bool Blockers::FreeOnLine(double v, std::vector<std::pair<double, double>>* scratch, double* u) const {
  auto& spans = *scratch;
  spans.clear();
  for (const Blocker& g : groups) {
    // min_k g_k <= 0 iff u <= max_k root_k, and max_k g_k >= 0 iff u >= min_k root_k.
    double lo = INFINITY, hi = -INFINITY;
    for (uint32_t k = g.begin; k < g.end; ++k) {
      const BlockerCoeff& c = coeffs[k];
      const double rest = c.a + c.c * v;
      if (c.b > 0) {
        const double root = -rest * c.inv_b;
        lo = std::min(lo, root);
        hi = std::max(hi, root);
      } else {
        if (rest <= 0) hi = INFINITY;
        if (rest >= 0) lo = -INFINITY;
      }
    }
    if (lo <= hi && hi >= 0.0 && lo <= 1.0) spans.emplace_back(lo, hi);
  }
  std::sort(spans.begin(), spans.end());
  // Sweep: [0, cur] is covered so far, up to a gap; a gap's middle is where rounding matters
  // least, and FreeRay has the last word.
  double cur = 0.0;
  for (const auto& [lo, hi] : spans) {
    if (lo > cur && FreeRay(*u = 0.5 * (cur + lo), v)) return true;
    cur = std::max(cur, hi);
    if (cur >= 1.0) return false;
  }
  return FreeRay(*u = 0.5 * (cur + 1.0), v);
}

bool Blockers::BandCovered(double v0, double v1, std::vector<std::pair<double, double>>* scratch) const {
  auto& spans = *scratch;
  spans.clear();
  // Early exit without sorting: 64 bins of u, bin k = [k/64, (k+1)/64]. A bin is marked when
  // one span holds it whole, or when a span through its left edge reaches as far as a span
  // through its right edge starts (two spans overlapping inside it). Marks stand for covered
  // u only, and k/64 and u * 64 are exact, so a full mask implies what the sweep below would
  // find from the same spans: the answer is the sweep's, only sooner.
  constexpr int kBins = 64;
  uint64_t mask = 0;
  double reach[kBins], start[kBins];  // per bin: the farthest hi through its left edge, the
  uint64_t touched = 0;               // nearest lo through its right edge (valid where touched)
  auto mark = [&](int k) {
    if ((touched >> k & 1) != 0 && reach[k] >= start[k]) mask |= uint64_t{1} << k;
  };
  for (const Blocker& g : groups) {
    if (v1 > g.v1_max || v0 < g.v0_min) continue;
    const auto [lo, hi] = RowBounds(g, v0, v1);
    if (!(lo <= hi && hi >= 0.0 && lo <= 1.0)) continue;
    spans.emplace_back(lo, hi);
    // Bin edges e0..e1 lie in [lo, hi]: bins e0..e1-1 whole, e1 from its left, e0-1 from its right.
    const double e0d = std::max(0.0, std::ceil(lo * kBins)), e1d = std::min<double>(kBins, std::floor(hi * kBins));
    if (!(e0d <= e1d)) continue;
    const int e0 = static_cast<int>(e0d), e1 = static_cast<int>(e1d);
    if (e1 > e0) mask |= (e1 - e0 == 64 ? ~uint64_t{0} : ((uint64_t{1} << (e1 - e0)) - 1)) << e0;
    if (e1 < kBins) {
      const uint64_t bit = uint64_t{1} << e1;
      if ((touched & bit) == 0) touched |= bit, reach[e1] = hi, start[e1] = INFINITY;
      else reach[e1] = std::max(reach[e1], hi);
      mark(e1);
    }
    if (e0 > 0) {
      const uint64_t bit = uint64_t{1} << (e0 - 1);
      if ((touched & bit) == 0) touched |= bit, reach[e0 - 1] = -INFINITY, start[e0 - 1] = lo;
      else start[e0 - 1] = std::min(start[e0 - 1], lo);
      mark(e0 - 1);
    }
    if (mask == ~uint64_t{0}) return true;
  }
  std::sort(spans.begin(), spans.end());
  double cur = 0.0;  // [0, cur] is covered
  for (const auto& [lo, hi] : spans) {
    if (lo > cur) return false;
    cur = std::max(cur, hi);
    if (cur >= 1.0) return true;
  }
  return false;
}

bool Blockers::BandCoveredSlanted(double v0, double v1, SlantedScratch* scratch) const {
  auto& traps = scratch->trapezoids;
  traps.clear();
  for (const Blocker& g : groups) {
    // Skipped where RowBounds' hi is below 0 already at v0 (h0 < 0: h < 0 over the band) or
    // its lo above 1 still at v1 (l1 > 1).
    if (v0 > g.v1_max || v1 < g.v0_min) continue;
    // RowBounds' lo at v0 and hi at v1, and the vertices that give them.
    double lo = INFINITY, hi = -INFINITY;
    uint32_t k_lo = g.end, k_hi = g.end;
    for (uint32_t k = g.begin; k < g.end; ++k) {
      const BlockerCoeff& c = coeffs[k];
      const double ra = -eps - c.a - c.c * v1;
      const double rb = eps - c.a - c.c * v0;
      if (c.b > 0) {
        if (ra * c.inv_b > hi) hi = ra * c.inv_b, k_hi = k;
        if (rb * c.inv_b < lo) lo = rb * c.inv_b, k_lo = k;
      } else {
        if (ra >= 0) hi = INFINITY, k_hi = g.end;
        if (rb <= 0) lo = -INFINITY, k_lo = g.end;
      }
    }
    // Nothing blocked at v0 from below or at v1 from above: no trapezoid worth having. An
    // infinite end stays so over the band (b = 0: the sign of eps - a - c v only falls as v
    // rises, c >= 0), a finite one is a vertex's root line.
    if (lo == INFINITY || hi == -INFINITY) continue;
    BandTrapezoid t{lo, -INFINITY, INFINITY, hi};
    if (k_lo != g.end) t.l1 = (eps - coeffs[k_lo].a - coeffs[k_lo].c * v1) * coeffs[k_lo].inv_b;
    if (k_hi != g.end) t.h0 = (-eps - coeffs[k_hi].a - coeffs[k_hi].c * v0) * coeffs[k_hi].inv_b;
    if (t.h0 < 0.0 || t.l1 > 1.0) continue;
    traps.push_back(t);
  }
  // Likeliest order of a chain first: by the lower side at the band's middle; the passes
  // below repeat until nothing joins, so the order only saves passes.
  std::sort(traps.begin(), traps.end(),
            [](const BandTrapezoid& x, const BandTrapezoid& y) { return x.l0 + x.l1 < y.l0 + y.l1; });
  // Reachability: `reach` holds the upper sides (at v0, at v1) of the trapezoids joined so far
  // (first the line u = 0), none dominated by another; [0, h(v)] is covered for each at every
  // v of the band. A line x lies under the reach at every v of the band when the v where it
  // lies under one reach line cover the band: each such set is the whole band, a prefix or a
  // suffix (x and the reach line are linear), so a prefix and a suffix that meet will do (in
  // the band's own fraction s = (v - v0) / (v1 - v0)). A trapezoid whose l lies under the
  // reach joins, and its h becomes a reach line; the band is covered once u = 1 lies under.
  auto& reach = scratch->reach;
  reach.assign(1, {0.0, 0.0});
  auto under_reach = [&reach](double x0, double x1) {
    double prefix = -1.0, suffix = 2.0;
    for (const auto& [r0, r1] : reach) {
      const double d0 = r0 - x0, d1 = r1 - x1;  // never inf - inf: l < inf and h > -inf
      if (d0 >= 0.0 && d1 >= 0.0) return true;
      if (d0 >= 0.0) prefix = std::max(prefix, d0 / (d0 - d1));
      else if (d1 >= 0.0) suffix = std::min(suffix, d0 / (d0 - d1));
    }
    return prefix >= suffix;
  };
  for (bool grew = true; grew;) {
    grew = false;
    for (BandTrapezoid& t : traps) {
      if (t.l0 == INFINITY || !under_reach(t.l0, t.l1)) continue;
      t.l0 = INFINITY;  // joined: never again
      bool dominated = false;
      for (const auto& [r0, r1] : reach) dominated |= r0 >= t.h0 && r1 >= t.h1;
      if (dominated) continue;
      std::erase_if(reach, [&](const std::pair<double, double>& r) { return t.h0 >= r.first && t.h1 >= r.second; });
      reach.emplace_back(t.h0, t.h1);
      if (under_reach(1.0, 1.0)) return true;
      grew = true;
    }
  }
  return false;
}

void Blockers::PrepareBands() {
  // RowBounds' hi at v1 is max_k (A_k - c_k v1) / b_k with A_k = -eps - a_k, and lo at v0 is
  // min_k (B_k - c_k v0) / b_k with B_k = eps - a_k (b_k = 0: +-infinity by the sign of the
  // numerator). Both fall as v rises. Vertex k gives hi >= 0 only for v1 up to about
  // A_k / c_k, and lo <= 1 only from v0 about (B_k - b_k) / c_k (B_k / c_k where b_k = 0). Each
  // threshold is widened by 1e-9 of the magnitudes involved, far above the rounding of
  // RowBounds' few operations; a vertex with c_k = 0 is decided as RowBounds computes it, and
  // one with a c_k too small for the margin to mean anything keeps its blocker in every band.
  constexpr double kTiny = 1e-100;
  for (Blocker& g : groups) {
    double v1_max = -INFINITY, v0_min = INFINITY;
    for (uint32_t k = g.begin; k < g.end; ++k) {
      const BlockerCoeff& c = coeffs[k];
      const double ca = -eps - c.a, cb = eps - c.a;
      if (c.c == 0.0) {
        if (c.b > 0 ? ca * c.inv_b >= 0.0 : ca >= 0.0) v1_max = INFINITY;
        if (c.b > 0 ? cb * c.inv_b <= 1.0 : cb <= 0.0) v0_min = -INFINITY;
        continue;
      }
      if (!(c.c > kTiny)) {
        v1_max = INFINITY;
        v0_min = -INFINITY;
        continue;
      }
      const double vh = ca / c.c;
      const double bb = c.b > 0 ? c.b : 0.0;
      const double vl = (cb - bb) / c.c;
      const double mh = 1e-9 * (1.0 + std::abs(vh)), ml = 1e-9 * (1.0 + (std::abs(cb) + bb) / c.c);
      v1_max = std::isfinite(vh) ? std::max(v1_max, vh + mh) : INFINITY;
      v0_min = std::isfinite(vl) && std::isfinite(ml) ? std::min(v0_min, vl - ml) : -INFINITY;
    }
    g.v1_max = v1_max;
    g.v0_min = v0_min;
  }
}

std::pair<double, double> Blockers::RowBounds(const Blocker& g, double v0, double v1) const {
  // Pixel [u0, u1] x [v0, v1] is wholly blocked iff min_k g_k(u1, v1) <= 0 and
  // max_k g_k(u0, v0) >= 0 (each g_k rises with u and v), with the margin eps:
  // iff u0 >= lo and u1 <= hi.
  double hi = -INFINITY, lo = INFINITY;
  for (uint32_t k = g.begin; k < g.end; ++k) {
    const BlockerCoeff& c = coeffs[k];
    const double ra = -eps - c.a - c.c * v1;  // need b u1 <= ra
    const double rb = eps - c.a - c.c * v0;   // need b u0 >= rb
    if (c.b > 0) {
      hi = std::max(hi, ra * c.inv_b);
      lo = std::min(lo, rb * c.inv_b);
    } else {
      if (ra >= 0) hi = INFINITY;
      if (rb <= 0) lo = -INFINITY;
    }
  }
  return {lo, hi};
}

std::pair<double, double> Blockers::PixelBounds(const Blocker& g, uint32_t j, uint32_t n) const {
  const double nd = n;
  const auto [lo, hi] = RowBounds(g, j / nd, (j + 1) / nd);
  return {std::ceil(lo * nd), std::floor(hi * nd) - 1};
}

bool CpuRaster::RowFull(uint32_t n) const {
  const uint32_t whole = n / 64;
  for (uint32_t w = 0; w < whole; ++w) {
    if (bits_[w] != ~0ULL) return false;
  }
  const uint32_t rest = n % 64;
  return rest == 0 || bits_[whole] == (1ULL << rest) - 1;
}

bool CpuRaster::DrawRow(const Blockers& blockers, uint32_t j, uint32_t n, bool stop_when_full) {
  bits_.assign((n + 63) / 64, 0);
  const double last_column = n - 1;
  for (const Blocker& g : blockers.groups) {
    const auto [f, l] = blockers.PixelBounds(g, j, n);
    const double first = std::max(0.0, f), last = std::min(last_column, l);
    if (!(first <= last)) continue;
    const auto i0 = static_cast<uint32_t>(first), i1 = static_cast<uint32_t>(last);
    for (uint32_t wi = i0 / 64; wi <= i1 / 64; ++wi) {
      const uint32_t s = wi == i0 / 64 ? i0 % 64 : 0, e = wi == i1 / 64 ? i1 % 64 : 63;
      const uint64_t mask = (e == 63 ? ~0ULL : ((1ULL << (e + 1)) - 1)) & ~((1ULL << s) - 1);
      bits_[wi] |= mask;
    }
    if (stop_when_full && RowFull(n)) return true;
  }
  return RowFull(n);
}

bool CpuRaster::Full(const Blockers& blockers, uint32_t n, std::span<const uint32_t> rows,
                     std::vector<uint32_t>* gap_rows) {
  gap_rows->clear();
  for (uint32_t j : rows) {
    if (!DrawRow(blockers, j, n, /*stop_when_full=*/true)) gap_rows->push_back(j);
  }
  return gap_rows->empty();
}

void CpuRaster::Draw(const Blockers& blockers, uint32_t n, std::vector<uint8_t>* pixels) {
  pixels->assign(static_cast<size_t>(n) * n, 0);
  for (uint32_t j = 0; j < n; ++j) {
    DrawRow(blockers, j, n, /*stop_when_full=*/false);
    for (uint32_t i = 0; i < n; ++i) (*pixels)[static_cast<size_t>(j) * n + i] = bits_[i / 64] >> (i % 64) & 1;
  }
}

}  // namespace vistream::visibility
