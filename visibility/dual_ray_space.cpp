#include "visibility/dual_ray_space.h"

#include <algorithm>
#include <cmath>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "visibility/exact_cover.h"

namespace vistream::visibility {

namespace {

struct Line {
  double slope = 0, intercept = 0;
  double At(double p) const { return intercept + slope * p; }
};

// The upper common tangent of two horizontal edges, [a0, a1] at height ha and [b0, b1] at hb,
// with a1 < b0: the line through the upper hull of their end points. Both edges lie on or
// below it.
Line UpperBridge(double a0, double a1, double ha, double b0, double b1, double hb) {
  Line l;
  if (hb > ha) {
    l.slope = (hb - ha) / (b0 - a0);
    l.intercept = ha - l.slope * a0;
  } else if (hb < ha) {
    l.slope = (hb - ha) / (b1 - a1);
    l.intercept = ha - l.slope * a1;
  } else {
    l.intercept = ha;
  }
  return l;
}

// Clips a convex polygon (or a segment, two points) to lo <= p <= hi.
void ClipStrip(const std::vector<glm::dvec2>& in, double lo, double hi, std::vector<glm::dvec2>* out,
               std::vector<glm::dvec2>* scratch) {
  out->clear();
  if (in.size() == 2) {
    glm::dvec2 a = in[0], b = in[1];
    if (a.x > b.x) std::swap(a, b);
    if (b.x < lo || a.x > hi) return;
    auto at = [&](double p) {
      if (b.x == a.x) return a;
      const double t = (p - a.x) / (b.x - a.x);
      return glm::dvec2(p, a.y + t * (b.y - a.y));
    };
    out->push_back(a.x < lo ? at(lo) : a);
    out->push_back(b.x > hi ? at(hi) : b);
    return;
  }
  std::vector<glm::dvec2>& tmp = *scratch;
  auto clip = [](const std::vector<glm::dvec2>& poly, double bound, bool keep_below, std::vector<glm::dvec2>* res) {
    res->clear();
    const size_t n = poly.size();
    for (size_t i = 0; i < n; ++i) {
      const glm::dvec2 &a = poly[i], &b = poly[(i + 1) % n];
      const bool ina = keep_below ? a.x <= bound : a.x >= bound;
      const bool inb = keep_below ? b.x <= bound : b.x >= bound;
      if (ina) res->push_back(a);
      if (ina != inb) {
        const double t = (bound - a.x) / (b.x - a.x);
        res->push_back(glm::dvec2(bound, a.y + t * (b.y - a.y)));
      }
    }
  };
  clip(in, lo, /*keep_below=*/false, &tmp);
  if (tmp.empty()) return;
  clip(tmp, hi, /*keep_below=*/true, out);
}

// Replaces `points` by the vertices of their convex hull (Andrew's monotone chain). A vertex
// lost to rounding only shrinks the blocked region: the answer stays conservative.
void ConvexHull(std::vector<glm::dvec2>* points, std::vector<glm::dvec2>* scratch) {
  auto& p = *points;
  if (p.size() <= 2) return;
  std::sort(p.begin(), p.end(), [](const glm::dvec2& a, const glm::dvec2& b) { return a.x < b.x || (a.x == b.x && a.y < b.y); });
  auto cross = [](const glm::dvec2& o, const glm::dvec2& a, const glm::dvec2& b) {
    return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
  };
  std::vector<glm::dvec2>& hull = *scratch;
  hull.resize(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(hull[k - 2], hull[k - 1], p[i]) <= 0) --k;
    hull[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(hull[k - 2], hull[k - 1], p[i - 1]) <= 0) --k;
    hull[k++] = p[i - 1];
  }
  hull.resize(k > 1 ? k - 1 : k);
  p.swap(hull);
}

}  // namespace

bool MakePlanarProblem(const scenes::Aabb& a, const scenes::Aabb& b, int axis, double sign, PlanarProblem* out) {
  const int other = 1 - axis;
  PlanarProblem& pr = *out;
  pr.axis = axis;
  pr.sign = sign;
  pr.origin = glm::dvec2(a.min.x, a.min.y);
  const double o = pr.origin[axis], oq = pr.origin[other];
  // A and B along p, in the query frame.
  double pa0, pa1, pb0, pb1;
  if (sign > 0) {
    pa0 = a.min[axis] - o, pa1 = a.max[axis] - o, pb0 = b.min[axis] - o, pb1 = b.max[axis] - o;
  } else {
    pa0 = -(a.max[axis] - o), pa1 = -(a.min[axis] - o), pb0 = -(b.max[axis] - o), pb1 = -(b.min[axis] - o);
  }
  // Separated with room between: boxes that touch leave no slab for an occluder.
  if (!(pa1 < pb0)) return false;
  pr.x1 = pa1;
  pr.x2 = pb0;
  const double aq0 = a.min[other] - oq, aq1 = a.max[other] - oq;
  const double bq0 = b.min[other] - oq, bq1 = b.max[other] - oq;
  const Line upper = UpperBridge(pa0, pa1, aq1, pb0, pb1, bq1);
  const Line lower = UpperBridge(pa0, pa1, -aq0, pb0, pb1, -bq0);  // mirrored: the lower tangent
  pr.l1 = upper.At(pr.x1);
  pr.l2 = upper.At(pr.x2);
  pr.r1 = -lower.At(pr.x1);
  pr.r2 = -lower.At(pr.x2);
  const Line ceiling = UpperBridge(pa0, pa1, a.max.z, pb0, pb1, b.max.z);
  pr.alpha = ceiling.intercept;
  pr.beta = ceiling.slope;
  return true;
}

int SeparatingPlanes(const scenes::Aabb& a, const scenes::Aabb& b, PlanarProblem (&out)[2]) {
  int count = 0;
  for (int axis = 0; axis < 2; ++axis) {
    for (double sign : {1.0, -1.0}) {
      if (MakePlanarProblem(a, b, axis, sign, &out[count])) {
        ++count;
        break;
      }
    }
  }
  return count;
}

void DualRaySpace::BuildBlockers(const PlanarProblem& pr) {
  const auto& pieces = occluders_.pieces();
  if (local_.size() != pieces.size()) local_.assign(pieces.size(), -1);
  gathered_.clear();
  // The shaft between the faces, back in scene coordinates, gathers the candidate pieces.
  const glm::dvec2 hull[4] = {pr.SceneFromPlanar(pr.x1, pr.r1), pr.SceneFromPlanar(pr.x2, pr.r2),
                              pr.SceneFromPlanar(pr.x2, pr.l2), pr.SceneFromPlanar(pr.x1, pr.l1)};
  // Pieces (and grid cells) that rise above T nowhere over the slab, or only beside the
  // shaft: rejected by their box. The frame is axis-aligned, so a box maps to a box.
  const double t_min = pr.CeilingMin(), inv_w = 1.0 / (pr.x2 - pr.x1);
  auto keep = [&](const PieceBounds& b) {
    double lo, hi;
    if (!(b.height > t_min) || !pr.BlockingStrip(b.height, &lo, &hi)) return false;
    const glm::dvec2 c0 = pr.PlanarFromScene(b.min), c1 = pr.PlanarFromScene(b.max);
    const double p0 = std::max(std::min(c0.x, c1.x), lo), p1 = std::min(std::max(c0.x, c1.x), hi);
    if (p0 > p1) return false;
    const double q0 = std::min(c0.y, c1.y), q1 = std::max(c0.y, c1.y);
    const double t0 = (p0 - pr.x1) * inv_w, t1 = (p1 - pr.x1) * inv_w;
    const double l_max = std::max(pr.l1 + t0 * (pr.l2 - pr.l1), pr.l1 + t1 * (pr.l2 - pr.l1));
    const double r_min = std::min(pr.r1 + t0 * (pr.r2 - pr.r1), pr.r1 + t1 * (pr.r2 - pr.r1));
    return q0 <= l_max && q1 >= r_min;
  };
  occluders_.Gather(hull, keep, &scratch_, &gathered_);

  // Clip each piece to the slab and to where it rises above T; keep those inside the shaft.
  // Kept pieces' points go to kept_points_, piece i's from kept_begin_[i].
  kept_.clear();
  kept_begin_.clear();
  kept_clipped_.clear();
  kept_points_.clear();
  lo_.clear();
  hi_.clear();
  for (uint32_t id : gathered_) {
    const double height = occluders_.bounds(id).height;
    const size_t begin = kept_points_.size();
    double p_min = INFINITY, p_max = -INFINITY;
    for (const glm::dvec2& w : occluders_.PointsOf(id)) {
      const glm::dvec2 p = pr.PlanarFromScene(w);
      kept_points_.push_back(p);
      p_min = std::min(p_min, p.x);
      p_max = std::max(p_max, p.x);
    }
    double lo, hi;
    if (!pr.PieceStrip(height, p_min, p_max, &lo, &hi)) {
      kept_points_.resize(begin);
      continue;
    }
    const bool clipped = p_min < lo || p_max > hi;
    if (clipped) {
      planar_.assign(kept_points_.begin() + static_cast<ptrdiff_t>(begin), kept_points_.end());
      ClipStrip(planar_, lo, hi, &clipped_, &clip_tmp_);
      kept_points_.resize(begin);
      if (clipped_.empty()) continue;
      kept_points_.insert(kept_points_.end(), clipped_.begin(), clipped_.end());
    }
    // Entirely beside the shaft: blocks no ray of RS.
    bool above = true, below = true;
    for (size_t k = begin; k < kept_points_.size(); ++k) {
      const glm::dvec2& p = kept_points_[k];
      const double t = (p.x - pr.x1) / (pr.x2 - pr.x1);
      const double l = pr.l1 + t * (pr.l2 - pr.l1), r = pr.r1 + t * (pr.r2 - pr.r1);
      above &= p.y > l;
      below &= p.y < r;
    }
    if (above || below) {
      kept_points_.resize(begin);
      continue;
    }
    local_[id] = static_cast<int32_t>(kept_.size());
    kept_.push_back(id);
    kept_begin_.push_back(static_cast<uint32_t>(begin));
    kept_clipped_.push_back(clipped);
    lo_.push_back(lo);
    hi_.push_back(hi);
  }
  kept_begin_.push_back(static_cast<uint32_t>(kept_points_.size()));
  const auto& kept = kept_;

  // Fuse: kept pieces whose contact survives both clips are one connected blocker.
  parent_.resize(kept.size());
  for (uint32_t i = 0; i < kept.size(); ++i) parent_[i] = i;
  auto find = [&](uint32_t x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  };
  bool fused = false;
  for (uint32_t i = 0; i < kept.size(); ++i) {
    const auto contacts = occluders_.ContactsOf(kept[i]);
    const auto others = occluders_.ContactOthersOf(kept[i]);
    for (size_t m = 0; m < contacts.size(); ++m) {
      const int32_t j = local_[others[m]];
      if (j < 0 || static_cast<uint32_t>(j) < i) continue;
      const PieceContact& c = occluders_.contacts()[contacts[m]];
      const double w0 = pr.PlanarFromScene(c.w0).x, w1 = pr.PlanarFromScene(c.w1).x;
      const double lo = std::max({std::min(w0, w1), lo_[i], lo_[j]});
      const double hi = std::min({std::max(w0, w1), hi_[i], hi_[j]});
      if (lo <= hi) {
        // The later piece's root under the earlier one's: i runs upwards, so a group's first
        // member stays its root and the trees stay flat (the other way round, a footprint's
        // pieces, fused in order, made a chain that every find walked).
        parent_[find(static_cast<uint32_t>(j))] = find(i);
        fused = true;
      }
    }
  }

  // Each blocker blocks exactly the rays that separate its points, so only the convex hull of
  // its points matters: g is affine in the point. Turn the hull vertices into coefficients. A
  // piece alone is convex already; its clipped points serve as they are.
  blockers_.Clear();
  auto points_of = [&](uint32_t i) {
    return std::span(kept_points_.data() + kept_begin_[i], kept_begin_[i + 1] - kept_begin_[i]);
  };
  if (!fused) {
    for (uint32_t i = 0; i < kept.size(); ++i) AddGroup(pr, points_of(i));
  } else {
    // Members of each group together, groups by root, members ascending: a counting sort by
    // root (roots are indices into kept), in the order a sort by (root, index) gives.
    for (uint32_t i = 0; i < kept.size(); ++i) parent_[i] = find(i);
    group_start_.assign(kept.size() + 1, 0);
    for (uint32_t i = 0; i < kept.size(); ++i) ++group_start_[parent_[i] + 1];
    for (size_t r = 0; r < kept.size(); ++r) group_start_[r + 1] += group_start_[r];
    order_.resize(kept.size());
    for (uint32_t i = 0; i < kept.size(); ++i) order_[group_start_[parent_[i]]++] = i;
    for (size_t n = 0; n < order_.size();) {
      size_t end = n + 1;
      while (end < order_.size() && parent_[order_[end]] == parent_[order_[n]]) ++end;
      if (end == n + 1) {
        AddGroup(pr, points_of(order_[n]));
      } else {
        // A point that the group holds twice (a vertex shared by a footprint's convex pieces)
        // is read once: where its owner is an unclipped member, from the owner only. The same
        // points, so the same hull, from fewer to sort.
        group_points_.clear();
        const uint32_t root = parent_[order_[n]];
        for (size_t m = n; m < end; ++m) {
          const uint32_t i = order_[m];
          const auto pts = points_of(i);
          if (kept_clipped_[i]) {
            group_points_.insert(group_points_.end(), pts.begin(), pts.end());
            continue;
          }
          const auto owners = occluders_.PointOwnersOf(kept[i]);
          for (size_t k = 0; k < pts.size(); ++k) {
            if (owners[k] != kept[i]) {
              const int32_t j = local_[owners[k]];
              if (j >= 0 && parent_[j] == root && !kept_clipped_[j]) continue;
            }
            group_points_.push_back(pts[k]);
          }
        }
        ConvexHull(&group_points_, &hull_scratch_);
        AddGroup(pr, group_points_);
      }
      n = end;
    }
  }
  for (uint32_t id : kept) local_[id] = -1;
  // Widest first: a row usually fills after a few blockers, and the rest are skipped.
  std::sort(blockers_.groups.begin(), blockers_.groups.end(),
            [](const Blocker& x, const Blocker& y) { return x.width > y.width; });
  blockers_.eps = 1e-9 * (1.0 + (pr.x2 - pr.x1) + (pr.l1 - pr.r1) + (pr.l2 - pr.r2) + std::abs(pr.r1) + std::abs(pr.r2));
  blockers_.PrepareBands();
}

void DualRaySpace::AddGroup(const PlanarProblem& pr, std::span<const glm::dvec2> points) {
  const double w = pr.x2 - pr.x1;
  Blocker g;
  g.begin = static_cast<uint32_t>(blockers_.coeffs.size());
  // How much of RS this blocker covers, roughly: its blocked width along u on the middle row.
  double mn = INFINITY, mx = -INFINITY;
  for (const glm::dvec2& p : points) {
    const double t = (p.x - pr.x1) / w;
    const BlockerCoeff c = BlockerCoeff::Of((1 - t) * pr.r1 + t * pr.r2 - p.y, (1 - t) * (pr.l1 - pr.r1), t * (pr.l2 - pr.r2));
    blockers_.coeffs.push_back(c);
    const double root = c.b > 0 ? -(c.a + 0.5 * c.c) / c.b : (c.a + 0.5 * c.c <= 0 ? INFINITY : -INFINITY);
    mn = std::min(mn, root);
    mx = std::max(mx, root);
  }
  g.end = static_cast<uint32_t>(blockers_.coeffs.size());
  g.width = std::min(mx, 1.0) - std::max(mn, 0.0);
  blockers_.groups.push_back(g);
}

namespace {

// Does the segment a-b (planar frame) meet the piece's points (a convex polygon of either
// orientation, a segment, or a point), boundary included?
bool SegmentMeetsPiece(const glm::dvec2& a, const glm::dvec2& b, const std::vector<glm::dvec2>& poly) {
  auto cross = [](const glm::dvec2& o, const glm::dvec2& p, const glm::dvec2& q) {
    return (p.x - o.x) * (q.y - o.y) - (p.y - o.y) * (q.x - o.x);
  };
  // The segment's line separates the piece?
  bool pos = false, neg = false;
  for (const glm::dvec2& v : poly) {
    const double c = cross(a, b, v);
    pos |= c >= 0;
    neg |= c <= 0;
  }
  if (!pos || !neg) return false;
  // The segment's extent along its own direction separates it?
  const glm::dvec2 d = b - a;
  double lo = INFINITY, hi = -INFINITY;
  for (const glm::dvec2& v : poly) {
    const double t = glm::dot(v - a, d);
    lo = std::min(lo, t);
    hi = std::max(hi, t);
  }
  if (hi < 0 || lo > glm::dot(d, d)) return false;
  // An edge of the piece separates it? (The piece's own side is where its other points are.)
  const size_t n = poly.size();
  if (n < 3) {
    // A segment piece: the segment's line already split it; test the piece's line too.
    const glm::dvec2& p = poly[0];
    const glm::dvec2& q = poly[n - 1];
    const double ca = cross(p, q, a), cb = cross(p, q, b);
    return !((ca > 0 && cb > 0) || (ca < 0 && cb < 0));
  }
  double area = 0;
  for (size_t k = 0; k < n; ++k) area += poly[k].x * poly[(k + 1) % n].y - poly[(k + 1) % n].x * poly[k].y;
  const double s = area >= 0 ? 1.0 : -1.0;
  for (size_t k = 0; k < n; ++k) {
    const glm::dvec2 &p = poly[k], &q = poly[(k + 1) % n];
    if (p == q) continue;
    if (s * cross(p, q, a) < 0 && s * cross(p, q, b) < 0) return false;
  }
  return true;
}

}  // namespace

bool DualRaySpace::FreeRayTraced(const PlanarProblem& pr, double u, double v) {
  const double q1 = pr.r1 + u * (pr.l1 - pr.r1), q2 = pr.r2 + v * (pr.l2 - pr.r2);
  const double t_min = pr.CeilingMin();
  const glm::dvec2 from = pr.SceneFromPlanar(pr.x1, q1), to = pr.SceneFromPlanar(pr.x2, q2);
  // Most pieces the ray's grid cells list lie wholly beside its line: their box says so, and
  // their points need not be read. A box corner's side, relative to `from`, is exact to well
  // under the margin (a micrometre) even far from the origin, so a box beyond it on one side
  // holds only points that SegmentMeetsPiece finds on that side too: the same answer.
  const glm::dvec2 d = to - from;
  const double margin = 1e-6 * std::hypot(d.x, d.y);
  const bool blocked = occluders_.Trace(from, to, &scratch_, [&](uint32_t id) {
    const PieceBounds& box = occluders_.bounds(id);
    const double height = box.height;
    if (height <= t_min) return false;
    const glm::dvec2 m0 = box.min - from, m1 = box.max - from;
    const double s0 = d.x * m0.y - d.y * m0.x, s1 = d.x * m1.y - d.y * m0.x;
    const double s2 = d.x * m0.y - d.y * m1.x, s3 = d.x * m1.y - d.y * m1.x;
    if (std::min({s0, s1, s2, s3}) > margin || std::max({s0, s1, s2, s3}) < -margin) return false;
    planar_.clear();
    double p_min = INFINITY, p_max = -INFINITY;
    for (const glm::dvec2& w : occluders_.PointsOf(id)) {
      planar_.push_back(pr.PlanarFromScene(w));
      p_min = std::min(p_min, planar_.back().x);
      p_max = std::max(p_max, planar_.back().x);
    }
    // The same pieces as the blockers: one on a face of the slab stops nothing.
    double lo, hi;
    if (!pr.PieceStrip(height, p_min, p_max, &lo, &hi)) return false;
    // The ray's part where the piece rises above T.
    const double k = (q2 - q1) / (pr.x2 - pr.x1);
    const glm::dvec2 a(lo, q1 + k * (lo - pr.x1)), b(hi, q1 + k * (hi - pr.x1));
    return SegmentMeetsPiece(a, b, planar_);
  });
  return !blocked;
}

namespace {

// The ray (u, v) of `pr` along `line`, if the line crosses both s1 and s2.
bool RayOnLine(const PlanarProblem& pr, const FreeLine& line, double* u, double* v) {
  if (!line.valid) return false;
  const glm::dvec2 a = pr.PlanarFromScene(line.from), b = pr.PlanarFromScene(line.to);
  if (!(b.x != a.x) || !(pr.l1 > pr.r1) || !(pr.l2 > pr.r2)) return false;
  const double k = (b.y - a.y) / (b.x - a.x);
  *u = (a.y + k * (pr.x1 - a.x) - pr.r1) / (pr.l1 - pr.r1);
  *v = (a.y + k * (pr.x2 - a.x) - pr.r2) / (pr.l2 - pr.r2);
  return *u >= 0 && *u <= 1 && *v >= 0 && *v <= 1;
}

// The line of ray (u, v) of `pr`, in scene coordinates.
FreeLine LineOf(const PlanarProblem& pr, double u, double v) {
  return FreeLine{pr.SceneFromPlanar(pr.x1, pr.r1 + u * (pr.l1 - pr.r1)), pr.SceneFromPlanar(pr.x2, pr.r2 + v * (pr.l2 - pr.r2)),
                  true};
}

}  // namespace

void DualRaySpace::SetWitness(const PlanarProblem& pr, double u, double v, FreeLine* witness) {
  free_u_ = u;
  free_v_ = v;
  if (witness != nullptr) *witness = LineOf(pr, u, v);
}

bool DualRaySpace::PlanarOccluded(const PlanarProblem& pr, const CellQueryOptions& options, CellQueryStats* stats,
                                  const FreeLine& hint, FreeLine* witness, FreeLinePool* pool) {
  if (witness != nullptr) witness->valid = false;
  // A free ray proves B visible: *witness is set, and a ray of a new line goes to the pool.
  auto found = [&](double u, double v, bool new_line) {
    if (stats != nullptr) {
      ++stats->planar_tests;
      ++stats->free_rays;
    }
    SetWitness(pr, u, v, witness);
    if (new_line && pool != nullptr) pool->Add(LineOf(pr, u, v));
    return false;
  };
  // Most B turn out visible: a few traced rays often prove it before any blocker is built,
  // and a ray costs only the grid cells it crosses, where the shaft's blockers cost its area.
  // The hint first: the line that proved a box around B visible often proves B visible too;
  // then the lines that proved other boxes visible from A and cross B's shaft (most recent
  // first: the traversal's last nodes lie near B); then fixed rays spread over RS.
  if (options.free_ray_test) {
    static constexpr double kRays[][2] = {{0.5, 0.5}, {1.0 / 6, 1.0 / 6}, {5.0 / 6, 5.0 / 6}, {1.0 / 6, 5.0 / 6},
                                          {5.0 / 6, 1.0 / 6}, {0.5, 1.0 / 6}, {0.5, 5.0 / 6}, {1.0 / 6, 0.5},
                                          {5.0 / 6, 0.5}, {0, 0}, {1, 1}, {0, 1}, {1, 0}};
    double u = 0, v = 0;
    if (RayOnLine(pr, hint, &u, &v) && FreeRayTraced(pr, u, v)) return found(u, v, false);
    if (pool != nullptr && FreeRayFromPool(pr, *pool, hint, &u, &v)) return found(u, v, false);
    if (options.probe_rays) {
      for (const auto& ray : kRays) {
        if (FreeRayTraced(pr, ray[0], ray[1])) return found(ray[0], ray[1], true);
      }
    }
  }
  BuildBlockers(pr);
  if (stats != nullptr) {
    ++stats->planar_tests;
    stats->gathered += gathered_.size();
    stats->pieces += blockers_.coeffs.size();
  }
  if (blockers_.groups.empty()) return false;
  // Row by row, depth first: a row with a gap at n is searched for a free ray along its middle
  // line, exactly, then tried with the blockers' trapezoids, then split into its two rows at
  // 2n (a row covered at n is covered at 2n). The raster is full when every row is; a row
  // still with a gap at max_res leaves B visible.
  const uint32_t n0 = std::clamp(options.min_res, 1u, std::max(1u, options.max_res));
  row_stack_.clear();
  bool undecided = false;
  for (uint32_t j = n0; j-- > 0;) row_stack_.push_back({n0, j});
  while (!row_stack_.empty()) {
    const auto [res, j] = row_stack_.back();
    row_stack_.pop_back();
    if (stats != nullptr) ++stats->raster_rows;
    // A full row of the raster is a band that the blockers cover together (each pixel lies in
    // the RowBounds of one blocker), so on the CPU the band test alone decides the same.
    // Pixels that no one blocker covers may still be covered by several together.
    if (raster_ != &cpu_raster_ && raster_->Full(blockers_, res, std::span(&j, 1), &gap_rows_)) continue;
    if (blockers_.BandCovered(static_cast<double>(j) / res, static_cast<double>(j + 1) / res, &spans_)) continue;
    double u = 0.0;
    if (options.free_ray_test && blockers_.FreeOnLine((j + 0.5) / res, &spans_, &u)) {
      if (stats != nullptr) ++stats->free_rays;
      SetWitness(pr, u, (j + 0.5) / res, witness);
      if (pool != nullptr) pool->Add(LineOf(pr, u, (j + 0.5) / res));
      return false;
    }
    // Blockers near B's face are steep in RS: where two of them meet, their rectangles over
    // the band miss a sliver that their trapezoids cover. Tried only here, where it can help.
    if (blockers_.BandCoveredSlanted(static_cast<double>(j) / res, static_cast<double>(j + 1) / res, &slanted_)) {
      continue;
    }
    if (2 * res > options.max_res) {
      undecided = true;
      break;
    }
    row_stack_.push_back({2 * res, 2 * j + 1});
    row_stack_.push_back({2 * res, 2 * j});
  }
  if (!undecided) return true;
  if (!options.exact) return false;
  // The raster is conservative, so its gaps may still be covered: only the exact union knows.
  // Every clear pixel's centre ray first: one free ray decides, at a fraction of the cost.
  const uint32_t n = std::max(1u, options.max_res);
  cpu_raster_.Draw(blockers_, n, &exact_raster_);
  for (size_t k = 0; k < exact_raster_.size(); ++k) {
    if (exact_raster_[k] == 0 && blockers_.FreeRay((k % n + 0.5) / n, (k / n + 0.5) / n)) {
      if (stats != nullptr) ++stats->free_rays;
      SetWitness(pr, (k % n + 0.5) / n, (k / n + 0.5) / n, witness);
      return false;
    }
  }
  if (stats != nullptr) ++stats->exact_tests;
  return ExactlyCovered(blockers_, exact_raster_, n);
}

bool DualRaySpace::SegmentOnCeilingFree(const PlanarProblem& pr, double p0, double q0, double p1, double q1) {
  if (!(p0 < p1)) return true;
  const auto& pieces = occluders_.pieces();
  const double k = (q1 - q0) / (p1 - p0);
  const glm::dvec2 from = pr.SceneFromPlanar(p0, q0), to = pr.SceneFromPlanar(p1, q1);
  const bool blocked = occluders_.Trace(from, to, &scratch_, [&](uint32_t id) {
    const OccluderPiece& piece = pieces[id];
    // Where the piece reaches the segment's height: z = alpha + beta p <= height.
    double lo = p0, hi = p1;
    if (pr.beta > 0) hi = std::min(hi, (piece.height - pr.alpha) / pr.beta);
    else if (pr.beta < 0) lo = std::max(lo, (piece.height - pr.alpha) / pr.beta);
    else if (piece.height < pr.alpha) return false;
    if (!(lo <= hi)) return false;
    planar_.clear();
    for (const glm::dvec2& w : piece.points) planar_.push_back(pr.PlanarFromScene(w));
    // Boundary included: a segment that grazes a piece counts as blocked here.
    return SegmentMeetsPiece(glm::dvec2(lo, q0 + k * (lo - p0)), glm::dvec2(hi, q0 + k * (hi - p0)), planar_);
  });
  return !blocked;
}

bool DualRaySpace::WitnessJoinsBoxes(const scenes::Aabb& a, const scenes::Aabb& b, const PlanarProblem& pr) {
  // The free ray runs on T from (x1, q1) to (x2, q2), above every occluder between the faces.
  // Extended along T to where T meets A's top (or A's face) and B's top (or B's face), it is
  // a segment from a point of A to a point of B; if its extensions over A and B are free too,
  // A and B see each other and no other planar test can prove B hidden.
  const int other = 1 - pr.axis;
  const double o = pr.origin[pr.axis], oq = pr.origin[other];
  double pa0, pb1;
  if (pr.sign > 0) {
    pa0 = a.min[pr.axis] - o, pb1 = b.max[pr.axis] - o;
  } else {
    pa0 = -(a.max[pr.axis] - o), pb1 = -(b.min[pr.axis] - o);
  }
  const double q1 = pr.r1 + free_u_ * (pr.l1 - pr.r1), q2 = pr.r2 + free_v_ * (pr.l2 - pr.r2);
  const double k = (q2 - q1) / (pr.x2 - pr.x1);
  auto q_at = [&](double p) { return q1 + k * (p - pr.x1); };
  auto z_at = [&](double p) { return pr.alpha + pr.beta * p; };
  const double pa = z_at(pr.x1) <= a.max.z ? pr.x1 : pa0;
  const double pb = z_at(pr.x2) <= b.max.z ? pr.x2 : pb1;
  auto inside = [&](const scenes::Aabb& box, double p, double tol) {
    const double q = q_at(p), z = z_at(p);  // in the query frame, as the box's sides below
    return q >= box.min[other] - oq - tol && q <= box.max[other] - oq + tol && z >= box.min.z - tol &&
           z <= box.max.z + tol;
  };
  // Rounding of T's intercept at the box's edge, no more.
  const double tol = 1e-9 * (1.0 + std::abs(pr.alpha) + std::abs(pr.beta) * (pr.x2 - pa0));
  if (!inside(a, pa, tol) || !inside(b, pb, tol)) return false;
  return SegmentOnCeilingFree(pr, pa, q_at(pa), pr.x1, q1) && SegmentOnCeilingFree(pr, pr.x2, q2, pb, q_at(pb));
}

bool DualRaySpace::Visible(const scenes::Aabb& a, const scenes::Aabb& b, const CellQueryOptions& options,
                           CellQueryStats* stats, const FreeLine& hint, FreeLine* witness, FreeLinePool* pool) {
  if (witness != nullptr) witness->valid = false;
  if (stats != nullptr) ++stats->queries;
  // Up to two planes separate A and B (one per axis); the one with the longer slab first:
  // its shaft holds more occluders, so it is likelier to prove B hidden.
  PlanarProblem pr[2];
  const int count = SeparatingPlanes(a, b, pr);
  if (count == 2 && pr[1].x2 - pr[1].x1 > pr[0].x2 - pr[0].x1) std::swap(pr[0], pr[1]);
  const bool separable = count > 0;
  FreeLine found, each;
  for (int k = 0; k < count; ++k) {
    const bool occluded = PlanarOccluded(pr[k], options, stats, hint, &each, pool);
    if (each.valid) found = each;
    if (occluded) {
      if (stats != nullptr) ++stats->occluded;
      return false;
    }
    // A free ray that joins A and B proves them visible: the other plane cannot hide B.
    if (each.valid && k + 1 < count && WitnessJoinsBoxes(a, b, pr[k])) break;
  }
  if (!separable && stats != nullptr) ++stats->non_separable;
  if (witness != nullptr) *witness = found;
  return true;
}

}  // namespace vistream::visibility
