#include "visibility/silhouette.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/geometric.hpp>
#include <limits>

namespace vistream::visibility {

namespace {

// The cut of one triangle by the fan's plane, in plane coordinates: corners (alpha, beta) at
// heights h above the plane.
struct Corners {
  float a[3], b[3], h[3];
};

// The general case: corners on the plane, and cuts that reach behind `from` (clipped at
// alpha_min). False if nothing in front of `from` is left.
bool CutInterval(const Corners& c, float alpha_min, float scale, float* lo, float* hi) {
  float pa[2], pb[2];
  int m = 0;
  for (int i = 0; i < 3 && m < 2; ++i) {
    const int j = i == 2 ? 0 : i + 1;
    if (c.h[i] == 0.0f) {
      pa[m] = c.a[i];
      pb[m++] = c.b[i];
    } else if ((c.h[i] < 0.0f && c.h[j] > 0.0f) || (c.h[i] > 0.0f && c.h[j] < 0.0f)) {
      const float f = c.h[i] / (c.h[i] - c.h[j]);
      pa[m] = c.a[i] + f * (c.a[j] - c.a[i]);
      pb[m++] = c.b[i] + f * (c.b[j] - c.b[i]);
    }
  }
  if (m == 0) return false;
  if (m == 1) {
    pa[1] = pa[0];
    pb[1] = pb[0];
  }
  if (pa[0] <= alpha_min && pa[1] <= alpha_min) return false;
  for (int k = 0; k < 2; ++k) {
    if (pa[k] <= alpha_min) {
      const int o = 1 - k;
      const float f = (alpha_min - pa[o]) / (pa[k] - pa[o]);
      pb[k] = pb[o] + f * (pb[k] - pb[o]);
      pa[k] = alpha_min;
    }
  }
  // Along the cut the projection onto the fan's segment is monotonic (alpha > 0 throughout).
  const float l0 = pb[0] / pa[0] * scale, l1 = pb[1] / pa[1] * scale;
  *lo = std::min(l0, l1);
  *hi = std::max(l0, l1);
  return true;
}

}  // namespace

FanTriangles::FanTriangles(std::span<const EdgeTriangle> triangles) : count_(triangles.size()) {
  blocks_.resize((triangles.size() + 3) / 4);
  for (size_t i = 0; i < blocks_.size() * 4; ++i) {
    const EdgeTriangle& t = triangles[std::min(i, triangles.size() - 1)];
    Block& b = blocks_[i / 4];
    const size_t l = i % 4;
    b.ax[l] = t.a.x;
    b.ay[l] = t.a.y;
    b.az[l] = t.a.z;
    b.e1x[l] = t.e1.x;
    b.e1y[l] = t.e1.y;
    b.e1z[l] = t.e1.z;
    b.e2x[l] = t.e2.x;
    b.e2y[l] = t.e2.y;
    b.e2z[l] = t.e2.z;
  }
}

void FanHits(const DiscoveryFan& fan, const FanTriangles& triangles,
             std::vector<std::pair<double, double>>* out) {
  using Lanes = FanTriangles::Lanes;
  typedef int32_t Mask __attribute__((vector_size(16)));
  const glm::dvec3 seg = fan.to - fan.from;
  const double len = glm::length(seg);
  if (!(len > 0.0) || !(fan.radius > 0.0) || triangles.size() == 0) return;
  // Coordinates in the fan's plane: alpha along the segment, beta along d (metres, relative
  // to `from`), h normal to the plane; the ray through (alpha, beta, 0), alpha > 0, passes
  // to + λ·radius·d with λ = beta·len / (alpha·radius). Single precision, like the triangles:
  // the silhouette is a heuristic's, to a fraction of a millimetre.
  const glm::vec3 s(seg / len), d(fan.d), n(glm::cross(seg / len, fan.d)), from(fan.from);
  const float alpha_min = static_cast<float>(1e-6 * len);
  const float scale = static_cast<float>(len / fan.radius);
  const float inf = std::numeric_limits<float>::infinity();
  auto splat = [](float x) { return Lanes{x, x, x, x}; };
  auto select = [](Mask m, Lanes a, Lanes b) {
    return reinterpret_cast<Lanes>((reinterpret_cast<Mask>(a) & m) |
                                   (reinterpret_cast<Mask>(b) & ~m));
  };
  const size_t first = out->size();
  out->resize(first + triangles.size());
  std::pair<double, double>* w = out->data() + first;
  size_t kept = 0, index = 0;
  for (const FanTriangles::Block& b : triangles.blocks()) {
    const Lanes rx = b.ax - splat(from.x), ry = b.ay - splat(from.y), rz = b.az - splat(from.z);
    auto dot_r = [&](const glm::vec3& v) {
      return rx * splat(v.x) + ry * splat(v.y) + rz * splat(v.z);
    };
    auto dot_e1 = [&](const glm::vec3& v) {
      return b.e1x * splat(v.x) + b.e1y * splat(v.y) + b.e1z * splat(v.z);
    };
    auto dot_e2 = [&](const glm::vec3& v) {
      return b.e2x * splat(v.x) + b.e2y * splat(v.y) + b.e2z * splat(v.z);
    };
    const Lanes h0 = dot_r(n), h1 = h0 + dot_e1(n), h2 = h0 + dot_e2(n);
    const Lanes a0 = dot_r(s), a1 = a0 + dot_e1(s), a2 = a0 + dot_e2(s);
    const Lanes b0 = dot_r(d), b1 = b0 + dot_e1(d), b2 = b0 + dot_e2(d);
    const Lanes zero = splat(0.0f), amin = splat(alpha_min);
    const Mask n0 = h0 < zero, n1 = h1 < zero, n2 = h2 < zero;
    // An edge (i, j) whose ends lie on either side crosses at alpha = (h_i a_j - h_j a_i) /
    // (h_i - h_j), likewise beta: its λ takes one division.
    const Mask c01 = n0 ^ n1, c12 = n1 ^ n2, c20 = n2 ^ n0;
    const Lanes l01 = (h0 * b1 - h1 * b0) / (h0 * a1 - h1 * a0) * splat(scale);
    const Lanes l12 = (h1 * b2 - h2 * b1) / (h1 * a2 - h2 * a1) * splat(scale);
    const Lanes l20 = (h2 * b0 - h0 * b2) / (h2 * a0 - h0 * a2) * splat(scale);
    const Lanes pinf = splat(inf), minf = splat(-inf);
    Lanes lo = select(c01, l01, pinf), hi = select(c01, l01, minf);
    lo = select(c12 & (select(c12, l12, pinf) < lo), l12, lo);
    hi = select(c12 & (select(c12, l12, minf) > hi), l12, hi);
    lo = select(c20 & (select(c20, l20, pinf) < lo), l20, lo);
    hi = select(c20 & (select(c20, l20, minf) > hi), l20, hi);
    // Corners on the plane or behind `from` take the general path, one triangle at a time.
    const Mask special =
        (h0 == zero) | (h1 == zero) | (h2 == zero) | (a0 <= amin) | (a1 <= amin) | (a2 <= amin);
    const Mask cut = c01 | c12 | c20;
    const Mask any = cut | special;
    if ((any[0] | any[1] | any[2] | any[3]) == 0) {
      index += 4;
      continue;
    }
    for (int l = 0; l < 4 && index < triangles.size(); ++l, ++index) {
      float tlo, thi;
      if (special[l] != 0) {
        if (h0[l] == 0.0f && h1[l] == 0.0f && h2[l] == 0.0f) continue;  // in the plane: grazed
        const Corners c{{a0[l], a1[l], a2[l]}, {b0[l], b1[l], b2[l]}, {h0[l], h1[l], h2[l]}};
        if (!CutInterval(c, alpha_min, scale, &tlo, &thi)) continue;
      } else if (cut[l] != 0) {
        tlo = lo[l];
        thi = hi[l];
      } else {
        continue;
      }
      const double clo = std::max(-1.0, static_cast<double>(tlo)),
                   chi = std::min(1.0, static_cast<double>(thi));
      w[kept] = {clo, chi};
      kept += clo <= chi;
    }
  }
  out->resize(first + kept);
}

std::optional<double> SilhouetteLambda(const DiscoveryFan& fan, const FanTriangles& triangles,
                                       std::vector<std::pair<double, double>>* scratch,
                                       double gap) {
  std::vector<std::pair<double, double>>& iv = *scratch;
  iv.clear();
  FanHits(fan, triangles, &iv);
  // Runs are unions of intervals closer than `gap`. Of the intervals that start at or below 0,
  // the one reaching highest lies in the last run that starts there: the run holding 0 if any
  // does, else the run with the largest meeting λ below 0. A few passes climb to its top.
  double top = -std::numeric_limits<double>::infinity();
  for (const auto& [lo, hi] : iv) {
    if (hi >= 1.0) return std::nullopt;  // the far end is met: no silhouette within reach
    if (lo <= 0.0) top = std::max(top, hi);
  }
  if (!(top >= -1.0)) return std::nullopt;
  for (bool grew = true; grew;) {
    grew = false;
    for (const auto& [lo, hi] : iv) {
      if (lo <= top + gap && hi > top) {
        top = hi;
        grew = true;
      }
    }
  }
  return top;
}

}  // namespace vistream::visibility
