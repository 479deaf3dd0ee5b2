#include "visibility/occluder_set.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "scenes/mesh.h"
#include "visibility/convex_partition.h"

namespace vistream::visibility {

namespace {

// p on the closed segment [a, b], exactly.
bool OnSegment(const glm::dvec2& p, const glm::dvec2& a, const glm::dvec2& b) {
  return Orient(a, b, p) == 0 && std::min(a.x, b.x) <= p.x && p.x <= std::max(a.x, b.x) &&
         std::min(a.y, b.y) <= p.y && p.y <= std::max(a.y, b.y);
}

std::vector<glm::dvec2> Distinct(const std::vector<glm::dvec2>& fp) {
  std::vector<glm::dvec2> out;
  for (const glm::dvec2& p : fp) {
    if (out.empty() || p != out.back()) out.push_back(p);
  }
  while (out.size() > 1 && out.front() == out.back()) out.pop_back();
  return out;
}

// Clips a convex piece (counter-clockwise polygon, or a segment) to the closed box [lo, hi]
// in xy; false when no part with an interior (a length, for a segment) is left. Points on a
// clipping line get that line's coordinate exactly, so a clipped wall lies exactly on the
// box's face.
bool ClipToBox(const glm::dvec2& lo, const glm::dvec2& hi, std::vector<glm::dvec2>* points) {
  auto& pts = *points;
  bool inside = true;
  for (const glm::dvec2& p : pts) inside &= p.x >= lo.x && p.y >= lo.y && p.x <= hi.x && p.y <= hi.y;
  if (inside) return true;
  // One half-plane at a time: coordinate `axis` on the side `sign` of `bound`.
  std::vector<glm::dvec2> out;
  auto clip = [&](int axis, double bound, double sign) {
    out.clear();
    const size_t n = pts.size();
    const bool segment = n == 2;
    for (size_t i = 0; i < n; ++i) {
      const glm::dvec2 &a = pts[i], &b = pts[(i + 1) % n];
      const bool ina = sign * (a[axis] - bound) >= 0, inb = sign * (b[axis] - bound) >= 0;
      if (ina) out.push_back(a);
      if (ina != inb && !(segment && i == 1)) {
        const double t = (bound - a[axis]) / (b[axis] - a[axis]);
        glm::dvec2 x = a + t * (b - a);
        x[axis] = bound;
        out.push_back(x);
      }
    }
    pts.swap(out);
  };
  for (int axis = 0; axis < 2 && !pts.empty(); ++axis) {
    clip(axis, lo[axis], 1.0);
    if (!pts.empty()) clip(axis, hi[axis], -1.0);
  }
  pts = Distinct(pts);
  if (pts.size() == 2) return true;
  return pts.size() >= 3 && scenes::SignedArea(pts) > 0.0;
}

// Interleaves the bits of x and y (x in the even bits): the Z-order curve's index.
uint64_t MortonCode(uint32_t x, uint32_t y) {
  auto spread = [](uint64_t v) {
    v &= 0xffffffffu;
    v = (v | v << 16) & 0x0000ffff0000ffffull;
    v = (v | v << 8) & 0x00ff00ff00ff00ffull;
    v = (v | v << 4) & 0x0f0f0f0f0f0f0f0full;
    v = (v | v << 2) & 0x3333333333333333ull;
    v = (v | v << 1) & 0x5555555555555555ull;
    return v;
  };
  return spread(x) | spread(y) << 1;
}

void Boxes(OccluderPiece* p) {
  p->box_min = glm::dvec2(INFINITY);
  p->box_max = glm::dvec2(-INFINITY);
  for (const glm::dvec2& q : p->points) {
    p->box_min = glm::min(p->box_min, q);
    p->box_max = glm::max(p->box_max, q);
  }
}

// The edges of a piece: one for a segment, n for a polygon.
template <typename F>
void ForEdges(const OccluderPiece& p, F&& f) {
  const size_t n = p.points.size();
  if (n == 2) {
    f(p.points[0], p.points[1]);
    return;
  }
  for (size_t i = 0; i < n; ++i) f(p.points[i], p.points[(i + 1) % n]);
}

bool StrictlyInside(const OccluderPiece& piece, const glm::dvec2& q) {
  if (piece.points.size() < 3) return false;
  bool inside = true;
  ForEdges(piece, [&](const glm::dvec2& a, const glm::dvec2& b) { inside &= Orient(a, b, q) > 0; });
  return inside;
}

// Among one pair's contacts out[begin..], drops each whose box (in xy) lies within another's
// (of two with equal boxes, the later). The fuse test of a planar query asks whether some
// contact's extent along the separating axis meets a strip; a contact's extent then lies
// within the other's, and the planar frame's map of a coordinate is monotone even in
// floating point, so the other one answers yes whenever the dropped one would: the same
// blockers, from far fewer contacts (a footprint's convex pieces meet at shared vertices
// through many edge pairs, each recording the same point).
void DropCoveredContacts(std::vector<PieceContact>* out, size_t begin) {
  auto& c = *out;
  const size_t end = c.size();
  auto covers = [&](size_t y, size_t x) {  // contact y's box holds contact x's
    const glm::dvec2 lx = glm::min(c[x].w0, c[x].w1), hx = glm::max(c[x].w0, c[x].w1);
    const glm::dvec2 ly = glm::min(c[y].w0, c[y].w1), hy = glm::max(c[y].w0, c[y].w1);
    return ly.x <= lx.x && ly.y <= lx.y && hx.x <= hy.x && hx.y <= hy.y;
  };
  // Decided for all first, then compacted: every contact is compared with all the others.
  std::vector<uint8_t> drop(end - begin, 0);
  for (size_t x = begin; x < end; ++x) {
    for (size_t y = begin; y < end && drop[x - begin] == 0; ++y) {
      // Of two contacts with equal boxes, the earlier one stays.
      drop[x - begin] = y != x && covers(y, x) && (y < x || !covers(x, y));
    }
  }
  size_t kept = begin;
  for (size_t x = begin; x < end; ++x) {
    if (drop[x - begin] == 0) c[kept++] = c[x];
  }
  c.resize(kept);
}

// Every way two pieces touch, as witnesses lying in both: collinear overlaps of edges,
// crossings and touchings of edges, and containment.
void FindContacts(uint32_t ia, uint32_t ib, const OccluderPiece& a, const OccluderPiece& b,
                  std::vector<PieceContact>* out) {
  const size_t before = out->size();
  ForEdges(a, [&](const glm::dvec2& p0, const glm::dvec2& p1) {
    ForEdges(b, [&](const glm::dvec2& q0, const glm::dvec2& q1) {
      const int o0 = Orient(p0, p1, q0), o1 = Orient(p0, p1, q1);
      const int o2 = Orient(q0, q1, p0), o3 = Orient(q0, q1, p1);
      if (o0 == 0 && o1 == 0 && p0 != p1) {
        // Collinear: the overlap of the two segments along the line, between original vertices.
        const glm::dvec2 d = p1 - p0;
        auto t = [&](const glm::dvec2& x) { return glm::dot(x - p0, d); };
        struct At {
          double t;
          glm::dvec2 p;
        };
        auto less = [](const At& x, const At& y) { return x.t < y.t; };
        const At e[4] = {{t(p0), p0}, {t(p1), p1}, {t(q0), q0}, {t(q1), q1}};
        const At lo = std::max(std::min(e[0], e[1], less), std::min(e[2], e[3], less), less);
        const At hi = std::min(std::max(e[0], e[1], less), std::max(e[2], e[3], less), less);
        if (lo.t <= hi.t) out->push_back({ia, ib, lo.p, hi.p});
        return;
      }
      if (o0 * o1 < 0 && o2 * o3 < 0) {
        // A proper crossing: the computed point is within rounding of both boundaries.
        const glm::dvec2 r = p1 - p0, s = q1 - q0;
        const double den = r.x * s.y - r.y * s.x;
        const double u = ((q0.x - p0.x) * s.y - (q0.y - p0.y) * s.x) / den;
        const glm::dvec2 x = p0 + r * u;
        out->push_back({ia, ib, x, x});
        return;
      }
      for (const glm::dvec2* v : {&q0, &q1}) {
        if (OnSegment(*v, p0, p1)) out->push_back({ia, ib, *v, *v});
      }
      for (const glm::dvec2* v : {&p0, &p1}) {
        if (OnSegment(*v, q0, q1)) out->push_back({ia, ib, *v, *v});
      }
    });
  });
  if (out->size() != before) {
    DropCoveredContacts(out, before);
    return;
  }
  if (StrictlyInside(a, b.points[0])) out->push_back({ia, ib, b.points[0], b.points[0]});
  else if (StrictlyInside(b, a.points[0])) out->push_back({ia, ib, a.points[0], a.points[0]});
}

}  // namespace

OccluderSet OccluderSet::Build(const scenes::Scene& scene, double grid_cell_m) {
  OccluderSet set;
  for (size_t oi = 0; oi < scene.occluders.size(); ++oi) {
    const scenes::Occluder25D& oc = scene.occluders[oi];
    if (!(oc.height > 0.0)) continue;
    std::vector<glm::dvec2> fp = Distinct(oc.footprint);
    // A point blocks no set of rays with an area: nothing to add.
    if (fp.size() < 2) continue;
    // The occluder lies inside its object's solid, so inside its box; the box is of the
    // single-precision mesh, which rounding may leave a hair inside the double footprint.
    // Clip to it, so a wall on a kd node's face is exactly on it and never reaches into the
    // slab before the node (an object with no box keeps its occluders as they are).
    const scenes::Aabb* box = nullptr;
    if (oc.object < scene.objects.size() && !scene.objects[oc.object].bounds.Empty()) {
      box = &scene.objects[oc.object].bounds;
    }
    const double height = box != nullptr ? std::min(oc.height, box->max.z) : oc.height;
    if (!(height > 0.0)) continue;
    auto add = [&](std::vector<glm::dvec2> pts) {
      if (box != nullptr && !ClipToBox(glm::dvec2(box->min), glm::dvec2(box->max), &pts)) return;
      OccluderPiece p;
      p.points = std::move(pts);
      p.height = height;
      p.object = oc.object;
      Boxes(&p);
      set.pieces_.push_back(std::move(p));
    };
    if (scenes::SignedArea(fp) < 0.0) std::reverse(fp.begin(), fp.end());
    const bool degenerate = fp.size() < 3 || scenes::SignedArea(fp) == 0.0;
    const bool convex = !degenerate && scenes::IsConvexCcw(fp);
    std::vector<std::vector<int>> parts;
    if (!degenerate && !convex) parts = ConvexPartition(fp);
    if (convex) {
      add(fp);
    } else if (!parts.empty()) {
      // Convex pieces of a non-convex footprint, fused along their shared diagonals below.
      for (const std::vector<int>& part : parts) {
        std::vector<glm::dvec2> pts;
        for (int k : part) pts.push_back(fp[k]);
        add(std::move(pts));
      }
    } else {
      // Zero area or not simple: the boundary as segments, joined at their shared vertices.
      for (size_t i = 0; i < fp.size(); ++i) {
        if (fp.size() == 2 && i == 1) break;
        add({fp[i], fp[(i + 1) % fp.size()]});
      }
    }
  }

  // Pieces in the order of a Z-order curve over their box centres (ties by their order so
  // far): a shaft's pieces then lie close together in memory, where a scene's order (an OSM
  // file's way ids, say) scatters them over the whole arrays.
  {
    glm::dvec2 lo(INFINITY), hi(-INFINITY);
    for (const OccluderPiece& p : set.pieces_) {
      lo = glm::min(lo, p.box_min);
      hi = glm::max(hi, p.box_max);
    }
    const double span = std::max({hi.x - lo.x, hi.y - lo.y, 1e-9});
    std::vector<std::pair<uint64_t, uint32_t>> keys(set.pieces_.size());
    for (uint32_t id = 0; id < keys.size(); ++id) {
      const OccluderPiece& p = set.pieces_[id];
      const glm::dvec2 c = 0.5 * (p.box_min + p.box_max);
      auto cell = [&](double v, double v0) {
        return static_cast<uint32_t>(std::clamp((v - v0) / span * 65535.0, 0.0, 65535.0));
      };
      keys[id] = {MortonCode(cell(c.x, lo.x), cell(c.y, lo.y)), id};
    }
    std::sort(keys.begin(), keys.end());
    std::vector<OccluderPiece> sorted;
    sorted.reserve(keys.size());
    for (const auto& k : keys) sorted.push_back(std::move(set.pieces_[k.second]));
    set.pieces_.swap(sorted);
  }

  // The grid over all pieces.
  const size_t n = set.pieces_.size();
  glm::dvec2 lo(INFINITY), hi(-INFINITY);
  for (const OccluderPiece& p : set.pieces_) {
    lo = glm::min(lo, p.box_min);
    hi = glm::max(hi, p.box_max);
  }
  if (n == 0) lo = hi = glm::dvec2(0.0);
  set.cell_ = grid_cell_m;
  set.grid_min_ = lo;
  set.nx_ = std::max(1, static_cast<int>(std::ceil((hi.x - lo.x) / set.cell_ + 1e-9)));
  set.ny_ = std::max(1, static_cast<int>(std::ceil((hi.y - lo.y) / set.cell_ + 1e-9)));
  auto cell_range = [&](const OccluderPiece& p, int* i0, int* i1, int* j0, int* j1) {
    *i0 = std::clamp(static_cast<int>(std::floor((p.box_min.x - lo.x) / set.cell_)), 0, set.nx_ - 1);
    *i1 = std::clamp(static_cast<int>(std::floor((p.box_max.x - lo.x) / set.cell_)), 0, set.nx_ - 1);
    *j0 = std::clamp(static_cast<int>(std::floor((p.box_min.y - lo.y) / set.cell_)), 0, set.ny_ - 1);
    *j1 = std::clamp(static_cast<int>(std::floor((p.box_max.y - lo.y) / set.cell_)), 0, set.ny_ - 1);
  };
  std::vector<uint32_t> count(static_cast<size_t>(set.nx_) * set.ny_ + 1, 0);
  for (const OccluderPiece& p : set.pieces_) {
    int i0, i1, j0, j1;
    cell_range(p, &i0, &i1, &j0, &j1);
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) ++count[static_cast<size_t>(j) * set.nx_ + i + 1];
    }
  }
  std::partial_sum(count.begin(), count.end(), count.begin());
  set.cell_start_ = count;
  set.cell_items_.resize(count.back());
  std::vector<uint32_t> fill(count.begin(), count.end() - 1);
  for (uint32_t id = 0; id < n; ++id) {
    int i0, i1, j0, j1;
    cell_range(set.pieces_[id], &i0, &i1, &j0, &j1);
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) set.cell_items_[fill[static_cast<size_t>(j) * set.nx_ + i]++] = id;
    }
  }

  set.bounds_.resize(n);
  for (uint32_t id = 0; id < n; ++id) {
    const OccluderPiece& p = set.pieces_[id];
    set.bounds_[id] = {p.box_min, p.box_max, p.height};
  }
  set.cell_bounds_.assign(count.size() - 1, PieceBounds{glm::dvec2(INFINITY), glm::dvec2(-INFINITY), 0.0});
  for (size_t c = 0; c + 1 < count.size(); ++c) {
    PieceBounds& cb = set.cell_bounds_[c];
    for (uint32_t k = count[c]; k < count[c + 1]; ++k) {
      const PieceBounds& pb = set.bounds_[set.cell_items_[k]];
      cb.min = glm::min(cb.min, pb.min);
      cb.max = glm::max(cb.max, pb.max);
      cb.height = std::max(cb.height, pb.height);
    }
  }

  // Contacts between pieces whose boxes touch (closed boxes: shared walls count).
  for (size_t c = 0; c + 1 < set.cell_start_.size(); ++c) {
    for (uint32_t x = set.cell_start_[c]; x < set.cell_start_[c + 1]; ++x) {
      for (uint32_t y = x + 1; y < set.cell_start_[c + 1]; ++y) {
        uint32_t a = set.cell_items_[x], b = set.cell_items_[y];
        if (a > b) std::swap(a, b);
        const OccluderPiece &pa = set.pieces_[a], &pb = set.pieces_[b];
        if (pa.box_min.x > pb.box_max.x || pb.box_min.x > pa.box_max.x || pa.box_min.y > pb.box_max.y ||
            pb.box_min.y > pa.box_max.y) {
          continue;
        }
        // A pair sharing several cells is handled in the first cell of their overlap only.
        const glm::dvec2 m = glm::max(pa.box_min, pb.box_min);
        const int ci = std::clamp(static_cast<int>(std::floor((m.x - lo.x) / set.cell_)), 0, set.nx_ - 1);
        const int cj = std::clamp(static_cast<int>(std::floor((m.y - lo.y) / set.cell_)), 0, set.ny_ - 1);
        if (static_cast<size_t>(cj) * set.nx_ + ci != c) continue;
        FindContacts(a, b, pa, pb, &set.contacts_);
      }
    }
  }
  std::vector<uint32_t> per(n + 1, 0);
  for (const PieceContact& k : set.contacts_) ++per[k.a + 1], ++per[k.b + 1];
  std::partial_sum(per.begin(), per.end(), per.begin());
  set.contact_start_ = per;
  set.contact_index_.resize(per.back());
  set.contact_other_.resize(per.back());
  std::vector<uint32_t> at(per.begin(), per.end() - 1);
  for (uint32_t k = 0; k < set.contacts_.size(); ++k) {
    const PieceContact& c = set.contacts_[k];
    set.contact_other_[at[c.a]] = c.b;
    set.contact_index_[at[c.a]++] = k;
    set.contact_other_[at[c.b]] = c.a;
    set.contact_index_[at[c.b]++] = k;
  }
  set.point_start_.assign(1, 0);
  for (const OccluderPiece& p : set.pieces_) {
    set.points_.insert(set.points_.end(), p.points.begin(), p.points.end());
    set.point_start_.push_back(static_cast<uint32_t>(set.points_.size()));
  }
  // Each point's first holder: point slots sorted by (x, y, piece), one run per distinct
  // point (the keys sorted by value, not through an index: a million of them on london).
  struct Slot {
    glm::dvec2 w;
    uint32_t piece, slot;
  };
  std::vector<Slot> slots;
  slots.reserve(set.points_.size());
  for (uint32_t id = 0; id < n; ++id) {
    for (uint32_t k = set.point_start_[id]; k < set.point_start_[id + 1]; ++k) slots.push_back({set.points_[k], id, k});
  }
  std::sort(slots.begin(), slots.end(), [](const Slot& a, const Slot& b) {
    return a.w.x < b.w.x || (a.w.x == b.w.x && (a.w.y < b.w.y || (a.w.y == b.w.y && a.piece < b.piece)));
  });
  set.point_owner_.resize(set.points_.size());
  for (size_t r = 0; r < slots.size();) {
    size_t e = r + 1;
    while (e < slots.size() && slots[e].w == slots[r].w) ++e;
    for (size_t k = r; k < e; ++k) set.point_owner_[slots[k].slot] = slots[r].piece;
    r = e;
  }
  return set;
}

}  // namespace vistream::visibility
