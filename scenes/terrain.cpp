#include "scenes/terrain.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <glm/common.hpp>

#include "scenes/polygon_set.h"

namespace vistream::scenes {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr int kMaxBuckets = 2048;  // per axis

struct Vertex {
  double x, y, z;
};

double Cross(const glm::dvec2& a, const glm::dvec2& b, const glm::dvec2& c) {
  return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
}

// One Sutherland-Hodgman step: the part of `in` where sign * (coord - bound) >= 0, with z
// interpolated linearly along each cut edge (the triangle's plane, so exact up to rounding).
void ClipAxis(const std::vector<Vertex>& in, int axis, double bound, double sign, std::vector<Vertex>* out) {
  out->clear();
  auto coord = [axis](const Vertex& v) { return axis == 0 ? v.x : v.y; };
  for (size_t k = 0; k < in.size(); ++k) {
    const Vertex& a = in[k];
    const Vertex& b = in[(k + 1) % in.size()];
    const double da = sign * (coord(a) - bound), db = sign * (coord(b) - bound);
    if (da >= 0.0) out->push_back(a);
    if ((da > 0.0 && db < 0.0) || (da < 0.0 && db > 0.0)) {
      const double t = da / (da - db);
      Vertex v{a.x + t * (b.x - a.x), a.y + t * (b.y - a.y), a.z + t * (b.z - a.z)};
      (axis == 0 ? v.x : v.y) = bound;  // on the border exactly
      out->push_back(v);
    }
  }
}

double PolygonArea(const std::vector<Vertex>& poly) {
  double a = 0.0;
  for (size_t k = 0; k < poly.size(); ++k) {
    const Vertex& p = poly[k];
    const Vertex& q = poly[(k + 1) % poly.size()];
    a += p.x * q.y - q.x * p.y;
  }
  return 0.5 * a;
}

}  // namespace

TerrainHeight::TerrainHeight(const Scene& scene) {
  glm::dvec2 lo(kInf), hi(-kInf);
  for (ObjectId id : scene.terrain) {
    const Mesh& m = scene.objects[id].mesh;
    for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
      Tri tri;
      tri.object = id;
      for (int k = 0; k < 3; ++k) {
        const glm::vec3& v = m.positions[m.indices[t + k]];
        tri.p[k] = glm::dvec2(v.x, v.y);
        tri.z[k] = v.z;
      }
      if (!(Cross(tri.p[0], tri.p[1], tri.p[2]) > 0.0)) continue;  // faces down or is vertical
      tri.lo = glm::min(glm::min(tri.p[0], tri.p[1]), tri.p[2]);
      tri.hi = glm::max(glm::max(tri.p[0], tri.p[1]), tri.p[2]);
      lo = glm::min(lo, tri.lo);
      hi = glm::max(hi, tri.hi);
      tris_.push_back(tri);
    }
  }
  if (tris_.empty()) return;
  // About one triangle a bucket, at most kMaxBuckets a side.
  const glm::dvec2 ext = glm::max(hi - lo, glm::dvec2(1e-6));
  bucket_ = std::sqrt(ext.x * ext.y / static_cast<double>(tris_.size()));
  bucket_ = std::max({bucket_, ext.x / kMaxBuckets, ext.y / kMaxBuckets});
  origin_ = lo;
  nbx_ = std::clamp(static_cast<int>(std::ceil(ext.x / bucket_)), 1, kMaxBuckets);
  nby_ = std::clamp(static_cast<int>(std::ceil(ext.y / bucket_)), 1, kMaxBuckets);
  auto range = [&](const Tri& t, int* i0, int* i1, int* j0, int* j1) {
    *i0 = std::clamp(static_cast<int>(std::floor((t.lo.x - origin_.x) / bucket_)), 0, nbx_ - 1);
    *i1 = std::clamp(static_cast<int>(std::floor((t.hi.x - origin_.x) / bucket_)), 0, nbx_ - 1);
    *j0 = std::clamp(static_cast<int>(std::floor((t.lo.y - origin_.y) / bucket_)), 0, nby_ - 1);
    *j1 = std::clamp(static_cast<int>(std::floor((t.hi.y - origin_.y) / bucket_)), 0, nby_ - 1);
  };
  std::vector<uint32_t> counts(static_cast<size_t>(nbx_) * nby_ + 1, 0);
  for (const Tri& t : tris_) {
    int i0, i1, j0, j1;
    range(t, &i0, &i1, &j0, &j1);
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) ++counts[static_cast<size_t>(j) * nbx_ + i + 1];
    }
  }
  for (size_t k = 1; k < counts.size(); ++k) counts[k] += counts[k - 1];
  bucket_start_ = counts;
  bucket_tris_.resize(counts.back());
  for (uint32_t n = 0; n < tris_.size(); ++n) {
    int i0, i1, j0, j1;
    range(tris_[n], &i0, &i1, &j0, &j1);
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) bucket_tris_[counts[static_cast<size_t>(j) * nbx_ + i]++] = n;
    }
  }
}

void TerrainHeight::Candidates(const glm::dvec2& lo, const glm::dvec2& hi, std::vector<uint32_t>* out) const {
  out->clear();
  if (tris_.empty()) return;
  const double fi0 = std::floor((lo.x - origin_.x) / bucket_), fi1 = std::floor((hi.x - origin_.x) / bucket_);
  const double fj0 = std::floor((lo.y - origin_.y) / bucket_), fj1 = std::floor((hi.y - origin_.y) / bucket_);
  if (fi1 < 0 || fj1 < 0 || fi0 >= nbx_ || fj0 >= nby_) return;
  const int i0 = static_cast<int>(std::max(fi0, 0.0)), i1 = static_cast<int>(std::min<double>(fi1, nbx_ - 1));
  const int j0 = static_cast<int>(std::max(fj0, 0.0)), j1 = static_cast<int>(std::min<double>(fj1, nby_ - 1));
  for (int j = j0; j <= j1; ++j) {
    for (int i = i0; i <= i1; ++i) {
      const size_t b = static_cast<size_t>(j) * nbx_ + i;
      for (uint32_t k = bucket_start_[b]; k < bucket_start_[b + 1]; ++k) {
        const Tri& t = tris_[bucket_tris_[k]];
        if (t.lo.x <= hi.x && t.hi.x >= lo.x && t.lo.y <= hi.y && t.hi.y >= lo.y) out->push_back(bucket_tris_[k]);
      }
    }
  }
  std::sort(out->begin(), out->end());
  out->erase(std::unique(out->begin(), out->end()), out->end());
}

double TerrainHeight::HeightAt(const glm::dvec2& p) const {
  if (!std::isfinite(p.x) || !std::isfinite(p.y)) return 0.0;
  std::vector<uint32_t> cand;
  Candidates(p, p, &cand);
  double best = -kInf;
  for (uint32_t n : cand) {
    const Tri& t = tris_[n];
    const double d = Cross(t.p[0], t.p[1], t.p[2]);
    const double w0 = Cross(t.p[1], t.p[2], p) / d, w1 = Cross(t.p[2], t.p[0], p) / d;
    const double w2 = 1.0 - w0 - w1;
    // A point on an edge is on both triangles that share it, whatever the rounding.
    constexpr double kEdge = -1e-12;
    if (w0 < kEdge || w1 < kEdge || w2 < kEdge) continue;
    best = std::max(best, w0 * t.z[0] + w1 * t.z[1] + w2 * t.z[2]);
  }
  return best == -kInf ? 0.0 : best;
}

HeightRange TerrainHeight::Range(const glm::dvec2& lo, const glm::dvec2& hi) const {
  std::vector<uint32_t> cand;
  Candidates(lo, hi, &cand);
  double zmin = kInf, zmax = -kInf, covered = 0.0;
  bool several = false;  // pieces of more than one object: they may overlap
  std::vector<Vertex> poly, tmp;
  for (uint32_t n : cand) {
    const Tri& t = tris_[n];
    poly = {{t.p[0].x, t.p[0].y, t.z[0]}, {t.p[1].x, t.p[1].y, t.z[1]}, {t.p[2].x, t.p[2].y, t.z[2]}};
    ClipAxis(poly, 0, lo.x, 1.0, &tmp);
    ClipAxis(tmp, 0, hi.x, -1.0, &poly);
    ClipAxis(poly, 1, lo.y, 1.0, &tmp);
    ClipAxis(tmp, 1, hi.y, -1.0, &poly);
    if (poly.empty()) continue;
    several = several || t.object != tris_[cand.front()].object;
    for (const Vertex& v : poly) {
      zmin = std::min(zmin, v.z);
      zmax = std::max(zmax, v.z);
    }
    covered += PolygonArea(poly);
  }
  if (zmin == kInf) return {0.0, 0.0};  // no terrain here: flat ground
  const double area = (hi.x - lo.x) * (hi.y - lo.y);
  bool uncovered = covered < area * (1.0 - 1e-9);
  if (!uncovered && several) {
    // Pieces of several objects may overlap, so their areas' sum proves nothing: ask whether the
    // square less them all is empty. A failure of the exact Boolean operation counts as
    // uncovered (a larger band).
    PolygonWithHoles square{{lo, {hi.x, lo.y}, hi, {lo.x, hi.y}}, {}};
    std::vector<PolygonWithHoles> cut;
    for (uint32_t n : cand) cut.push_back({{tris_[n].p[0], tris_[n].p[1], tris_[n].p[2]}, {}});
    absl::StatusOr<std::vector<PolygonWithHoles>> rest = Difference(square, cut);
    uncovered = !rest.ok();
    if (rest.ok()) {
      double left = 0.0;
      for (const PolygonWithHoles& r : *rest) {
        left += SignedArea(r.outer);
        for (const Ring& h : r.holes) left += SignedArea(h);
      }
      uncovered = left > area * 1e-9;
    }
  }
  if (uncovered) {
    zmin = std::min(zmin, 0.0);
    zmax = std::max(zmax, 0.0);
  }
  return {zmin, zmax};
}

}  // namespace vistream::scenes
