#include "visibility/silhouette.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <glm/geometric.hpp>
#include <limits>
#include <numeric>
#include <unordered_map>

namespace vistream::visibility {

namespace {

using Lanes = FanSurface::Lanes;
typedef int32_t Mask __attribute__((vector_size(16)));

constexpr uint32_t kMaxPieceCorners = 64;  // more, and the piece's triangles are read instead

// The cut of one triangle by the fan's plane, in plane coordinates: corners (alpha, beta) at
// heights h above the plane.
struct Cut {
  double a[3], b[3], h[3];
};

// The general case: corners on the plane, and cuts that reach behind `from` (clipped at
// alpha_min). False if nothing in front of `from` is left. In double: near `from` a cut's λ
// is ill-conditioned (a small alpha divides).
bool CutInterval(const Cut& c, double alpha_min, double scale, double* lo, double* hi) {
  double pa[2], pb[2];
  int m = 0;
  for (int i = 0; i < 3 && m < 2; ++i) {
    const int j = i == 2 ? 0 : i + 1;
    if (c.h[i] == 0.0) {
      pa[m] = c.a[i];
      pb[m++] = c.b[i];
    } else if ((c.h[i] < 0.0 && c.h[j] > 0.0) || (c.h[i] > 0.0 && c.h[j] < 0.0)) {
      const double f = c.h[i] / (c.h[i] - c.h[j]);
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
      const double f = (alpha_min - pa[o]) / (pa[k] - pa[o]);
      pb[k] = pb[o] + f * (pb[k] - pb[o]);
      pa[k] = alpha_min;
    }
  }
  // Along the cut the projection onto the fan's segment is monotonic (alpha > 0 throughout).
  const double l0 = pb[0] / pa[0] * scale, l1 = pb[1] / pa[1] * scale;
  *lo = std::min(l0, l1);
  *hi = std::max(l0, l1);
  return true;
}

Lanes Splat(float x) { return Lanes{x, x, x, x}; }

// The fan's plane: alpha along the segment, beta along d (metres, relative to `from`), h
// normal to the plane; the ray through (alpha, beta, 0), alpha > 0, passes to + λ·radius·d with
// λ = beta·len / (alpha·radius). Single precision, like the meshes, but for `from`, which is
// `from` + `from_low` (its rounding error): corners relative to it are then as exact as their
// distance to it allows, not as the distance from the frame's origin does.
struct Frame {
  glm::vec3 s, d, n, from, from_low;
  float alpha_min, scale;
  glm::dvec3 ds, dd, dn, dfrom;  // the same in double, for the general case
  double dalpha_min, dscale;
};

// Appends the interval [lo, hi] clipped to [-1, 1], if anything is left.
void Keep(double lo, double hi, std::vector<std::pair<double, double>>* out) {
  const double clo = std::max(-1.0, lo), chi = std::min(1.0, hi);
  if (clo <= chi) out->emplace_back(clo, chi);
}

// One interval per triangle of `blocks` (the first `count` triangles) the plane cuts.
void TriangleHits(const Frame& f, std::span<const FanSurface::Block> blocks, size_t count,
                  std::vector<std::pair<double, double>>* out) {
  const float inf = std::numeric_limits<float>::infinity();
  auto select = [](Mask m, Lanes a, Lanes b) {
    return reinterpret_cast<Lanes>((reinterpret_cast<Mask>(a) & m) | (reinterpret_cast<Mask>(b) & ~m));
  };
  size_t index = 0;
  for (const FanSurface::Block& b : blocks) {
    const Lanes rx = (b.ax - Splat(f.from.x)) - Splat(f.from_low.x), ry = (b.ay - Splat(f.from.y)) - Splat(f.from_low.y),
                rz = (b.az - Splat(f.from.z)) - Splat(f.from_low.z);
    auto dot_r = [&](const glm::vec3& v) { return rx * Splat(v.x) + ry * Splat(v.y) + rz * Splat(v.z); };
    auto dot_e1 = [&](const glm::vec3& v) { return b.e1x * Splat(v.x) + b.e1y * Splat(v.y) + b.e1z * Splat(v.z); };
    auto dot_e2 = [&](const glm::vec3& v) { return b.e2x * Splat(v.x) + b.e2y * Splat(v.y) + b.e2z * Splat(v.z); };
    const Lanes h0 = dot_r(f.n), h1 = h0 + dot_e1(f.n), h2 = h0 + dot_e2(f.n);
    const Lanes a0 = dot_r(f.s), a1 = a0 + dot_e1(f.s), a2 = a0 + dot_e2(f.s);
    const Lanes b0 = dot_r(f.d), b1 = b0 + dot_e1(f.d), b2 = b0 + dot_e2(f.d);
    const Lanes zero = Splat(0.0f), amin = Splat(f.alpha_min);
    const Mask n0 = h0 < zero, n1 = h1 < zero, n2 = h2 < zero;
    // An edge (i, j) whose ends lie on either side crosses at alpha = (h_i a_j - h_j a_i) /
    // (h_i - h_j), likewise beta: its λ takes one division.
    const Mask c01 = n0 ^ n1, c12 = n1 ^ n2, c20 = n2 ^ n0;
    const Lanes l01 = (h0 * b1 - h1 * b0) / (h0 * a1 - h1 * a0) * Splat(f.scale);
    const Lanes l12 = (h1 * b2 - h2 * b1) / (h1 * a2 - h2 * a1) * Splat(f.scale);
    const Lanes l20 = (h2 * b0 - h0 * b2) / (h2 * a0 - h0 * a2) * Splat(f.scale);
    const Lanes pinf = Splat(inf), minf = Splat(-inf);
    Lanes lo = select(c01, l01, pinf), hi = select(c01, l01, minf);
    lo = select(c12 & (select(c12, l12, pinf) < lo), l12, lo);
    hi = select(c12 & (select(c12, l12, minf) > hi), l12, hi);
    lo = select(c20 & (select(c20, l20, pinf) < lo), l20, lo);
    hi = select(c20 & (select(c20, l20, minf) > hi), l20, hi);
    // Corners on the plane or behind `from` take the general path, one triangle at a time.
    const Mask special = (h0 == zero) | (h1 == zero) | (h2 == zero) | (a0 <= amin) | (a1 <= amin) | (a2 <= amin);
    const Mask cut = c01 | c12 | c20;
    const Mask any = cut | special;
    if ((any[0] | any[1] | any[2] | any[3]) == 0) {
      index += 4;
      continue;
    }
    for (int l = 0; l < 4 && index < count; ++l, ++index) {
      double tlo, thi;
      if (special[l] != 0) {
        // The triangle exactly as the mesh has it, in double.
        const glm::dvec3 a(b.ax[l], b.ay[l], b.az[l]), e1(b.e1x[l], b.e1y[l], b.e1z[l]), e2(b.e2x[l], b.e2y[l], b.e2z[l]);
        Cut c;
        const glm::dvec3 r[3] = {a - f.dfrom, a + e1 - f.dfrom, a + e2 - f.dfrom};
        for (int k = 0; k < 3; ++k) {
          c.h[k] = glm::dot(r[k], f.dn);
          c.a[k] = glm::dot(r[k], f.ds);
          c.b[k] = glm::dot(r[k], f.dd);
        }
        if (c.h[0] == 0.0 && c.h[1] == 0.0 && c.h[2] == 0.0) continue;  // in the plane: grazed
        if (!CutInterval(c, f.dalpha_min, f.dscale, &tlo, &thi)) continue;
      } else if (cut[l] != 0) {
        tlo = lo[l];
        thi = hi[l];
      } else {
        continue;
      }
      Keep(tlo, thi, out);
    }
  }
}

// A piece's interval from its corners and edges; false if they cannot settle it (a corner in
// the plane, or a crossing not in front of `from`), and its triangles must.
bool PieceHit(const Frame& f, const FanSurface& surface, const FanSurface::Piece& p,
              std::vector<std::pair<double, double>>* out) {
  alignas(16) float h[kMaxPieceCorners], a[kMaxPieceCorners], b[kMaxPieceCorners];
  const std::span<const FanSurface::Corners> blocks = surface.corners().subspan(p.corner_block, (p.corner_count + 3) / 4);
  Mask on_plane = {0, 0, 0, 0};
  for (size_t k = 0; k < blocks.size(); ++k) {
    const FanSurface::Corners& c = blocks[k];
    const Lanes rx = (c.x - Splat(f.from.x)) - Splat(f.from_low.x), ry = (c.y - Splat(f.from.y)) - Splat(f.from_low.y),
                rz = (c.z - Splat(f.from.z)) - Splat(f.from_low.z);
    const Lanes hk = rx * Splat(f.n.x) + ry * Splat(f.n.y) + rz * Splat(f.n.z);
    const Lanes ak = rx * Splat(f.s.x) + ry * Splat(f.s.y) + rz * Splat(f.s.z);
    const Lanes bk = rx * Splat(f.d.x) + ry * Splat(f.d.y) + rz * Splat(f.d.z);
    on_plane |= hk == Splat(0.0f);  // padding repeats a corner: no false alarm
    std::memcpy(h + 4 * k, &hk, sizeof hk);
    std::memcpy(a + 4 * k, &ak, sizeof ak);
    std::memcpy(b + 4 * k, &bk, sizeof bk);
  }
  if ((on_plane[0] | on_plane[1] | on_plane[2] | on_plane[3]) != 0) return false;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (const auto& [i, j] : surface.edges().subspan(p.edge, p.edge_count)) {
    if ((h[i] < 0.0f) == (h[j] < 0.0f)) continue;
    const float den = h[i] * a[j] - h[j] * a[i];  // the crossing's alpha times h_i - h_j
    if (!(den / (h[i] - h[j]) > f.alpha_min)) return false;
    const float l = (h[i] * b[j] - h[j] * b[i]) / den * f.scale;
    lo = std::min(lo, l);
    hi = std::max(hi, l);
  }
  if (lo <= hi) Keep(lo, hi, out);
  return true;
}

struct PositionHash {
  size_t operator()(const std::array<uint32_t, 3>& k) const {
    uint64_t x = (uint64_t{k[0]} << 32 | k[1]) * 0x9e3779b97f4a7c15ull ^ k[2];
    x ^= x >> 29;
    return static_cast<size_t>(x * 0xbf58476d1ce4e5b9ull);
  }
};

// A directed edge between welded corners.
uint64_t EdgeKey(uint32_t from, uint32_t to) { return uint64_t{from} << 32 | to; }

uint32_t Find(std::vector<uint32_t>& parent, uint32_t x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}


// A 30-bit Morton code of p in the box [lo, lo + ext): ten bits per axis, interleaved.
uint32_t Morton(const glm::dvec3& p, const glm::dvec3& lo, const glm::dvec3& ext) {
  auto spread = [](uint32_t v) {
    v = (v | v << 16) & 0x030000FFu;
    v = (v | v << 8) & 0x0300F00Fu;
    v = (v | v << 4) & 0x030C30C3u;
    v = (v | v << 2) & 0x09249249u;
    return v;
  };
  uint32_t code = 0;
  for (int k = 0; k < 3; ++k) {
    const double u = ext[k] > 0.0 ? (p[k] - lo[k]) / ext[k] : 0.0;
    const uint32_t q = static_cast<uint32_t>(std::clamp(u * 1024.0, 0.0, 1023.0));
    code |= spread(q) << k;
  }
  return code;
}

// The levels above `leaves`: each node a sphere around kTreeFanout nodes of the level below.
FanSurface::SphereTree BuildSphereTree(std::vector<FanSurface::Sphere> leaves) {
  FanSurface::SphereTree tree;
  if (leaves.empty()) return tree;
  tree.push_back(std::move(leaves));
  while (tree.back().size() > FanSurface::kTreeFanout) {
    const std::vector<FanSurface::Sphere>& below = tree.back();
    std::vector<FanSurface::Sphere> level((below.size() + FanSurface::kTreeFanout - 1) / FanSurface::kTreeFanout);
    for (size_t i = 0; i < level.size(); ++i) {
      const size_t first = i * FanSurface::kTreeFanout, last = std::min(below.size(), first + FanSurface::kTreeFanout);
      glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
      for (size_t c = first; c < last; ++c) {
        lo = glm::min(lo, glm::dvec3(below[c].centre) - static_cast<double>(below[c].radius));
        hi = glm::max(hi, glm::dvec3(below[c].centre) + static_cast<double>(below[c].radius));
      }
      const glm::dvec3 centre = 0.5 * (lo + hi);
      double radius = 0.0;
      for (size_t c = first; c < last; ++c) {
        radius = std::max(radius, glm::length(glm::dvec3(below[c].centre) - centre) + below[c].radius);
      }
      // Rounding the centre to float moves it: the radius takes that and a millionth more.
      const glm::vec3 fc(centre);
      level[i].centre = fc;
      level[i].radius = static_cast<float>((radius + glm::length(glm::dvec3(fc) - centre)) * (1.0 + 1e-6));
    }
    tree.push_back(std::move(level));
  }
  return tree;
}


// Calls leaf(i) for every leaf of `tree` whose sphere and whose ancestors' spheres `misses`
// does not rule out.
template <typename Misses, typename Leaf>
void VisitSphereTree(const FanSurface::SphereTree& tree, const Misses& misses, const Leaf& leaf) {
  if (tree.empty()) return;
  std::array<std::pair<uint32_t, uint32_t>, 256> stack;  // (level, node); depth * fan-out at most
  size_t top = 0;
  const uint32_t root_level = static_cast<uint32_t>(tree.size() - 1);
  for (uint32_t i = 0; i < tree[root_level].size(); ++i) stack[top++] = {root_level, i};
  while (top > 0) {
    const auto [level, node] = stack[--top];
    if (misses(tree[level][node])) continue;
    if (level == 0) {
      leaf(node);
      continue;
    }
    const uint32_t first = node * FanSurface::kTreeFanout;
    const uint32_t last = std::min<uint32_t>(static_cast<uint32_t>(tree[level - 1].size()), first + FanSurface::kTreeFanout);
    for (uint32_t c = last; c-- > first;) stack[top++] = {level - 1, c};
  }
}

}  // namespace

FanSurface::FanSurface(std::span<const glm::vec3> positions, std::span<const uint32_t> indices)
    : triangle_count_(indices.size() / 3) {
  const size_t n = triangle_count_;
  if (n == 0) return;
  // Weld equal positions (-0 is 0).
  std::unordered_map<std::array<uint32_t, 3>, uint32_t, PositionHash> ids;
  std::vector<uint32_t> weld(positions.size());
  std::vector<glm::vec3> welded;
  for (size_t i = 0; i < positions.size(); ++i) {
    std::array<uint32_t, 3> key;
    for (int k = 0; k < 3; ++k) {
      const float x = positions[i][k] + 0.0f;
      std::memcpy(&key[k], &x, sizeof x);
    }
    const auto [it, added] = ids.try_emplace(key, static_cast<uint32_t>(welded.size()));
    if (added) welded.push_back(positions[i]);
    weld[i] = it->second;
  }
  std::vector<std::array<uint32_t, 3>> tri(n);
  std::vector<bool> degenerate(n);
  for (size_t t = 0; t < n; ++t) {
    for (int k = 0; k < 3; ++k) tri[t][k] = weld[indices[3 * t + k]];
    degenerate[t] = tri[t][0] == tri[t][1] || tri[t][1] == tri[t][2] || tri[t][2] == tri[t][0];
  }
  // Directed edges with their triangles, sorted, to find each edge's triangles and its twin's.
  std::vector<std::pair<uint64_t, uint32_t>> directed;
  directed.reserve(3 * n);
  for (size_t t = 0; t < n; ++t) {
    if (degenerate[t]) continue;
    for (int k = 0; k < 3; ++k) directed.emplace_back(EdgeKey(tri[t][k], tri[t][(k + 1) % 3]), static_cast<uint32_t>(t));
  }
  std::sort(directed.begin(), directed.end());
  auto with = [&](uint32_t from, uint32_t to) {
    const auto key_less = [](const std::pair<uint64_t, uint32_t>& a, const std::pair<uint64_t, uint32_t>& b) {
      return a.first < b.first;
    };
    return std::equal_range(directed.begin(), directed.end(), std::pair<uint64_t, uint32_t>{EdgeKey(from, to), 0},
                            key_less);
  };
  // Join triangles across edges that exactly two of them share, in opposite directions.
  std::vector<uint32_t> parent(n);
  std::iota(parent.begin(), parent.end(), 0u);
  for (const auto& [key, t] : directed) {
    const uint32_t u = static_cast<uint32_t>(key >> 32), v = static_cast<uint32_t>(key);
    if (u > v) continue;  // each undirected edge once
    const auto [lo, hi] = with(u, v);
    const auto [tlo, thi] = with(v, u);
    if (hi - lo != 1 || thi - tlo != 1) continue;
    parent[Find(parent, t)] = Find(parent, tlo->second);
  }
  std::unordered_map<uint32_t, std::vector<uint32_t>> groups;
  for (size_t t = 0; t < n; ++t) {
    if (!degenerate[t]) groups[Find(parent, static_cast<uint32_t>(t))].push_back(static_cast<uint32_t>(t));
  }
  std::vector<uint32_t> roots;
  for (const auto& [root, members] : groups) roots.push_back(root);
  std::sort(roots.begin(), roots.end());  // a fixed order, whatever the hash does

  auto triangle = [&](uint32_t t) {
    const glm::vec3 a = positions[indices[3 * t]], b = positions[indices[3 * t + 1]], c = positions[indices[3 * t + 2]];
    return EdgeTriangle{a, b - a, c - a};
  };
  auto append_blocks = [&](std::span<const uint32_t> members) {
    const size_t first = blocks_.size();
    blocks_.resize(first + (members.size() + 3) / 4);
    for (size_t i = 0; i < (blocks_.size() - first) * 4; ++i) {
      const EdgeTriangle t = triangle(members[std::min(i, members.size() - 1)]);
      Block& b = blocks_[first + i / 4];
      const size_t l = i % 4;
      b.ax[l] = t.a.x, b.ay[l] = t.a.y, b.az[l] = t.a.z;
      b.e1x[l] = t.e1.x, b.e1y[l] = t.e1.y, b.e1z[l] = t.e1.z;
      b.e2x[l] = t.e2.x, b.e2y[l] = t.e2.y, b.e2z[l] = t.e2.z;
    }
    return static_cast<uint32_t>(first);
  };

  std::vector<uint32_t> loose;
  for (size_t t = 0; t < n; ++t) {
    if (degenerate[t]) loose.push_back(static_cast<uint32_t>(t));
  }
  for (uint32_t root : roots) {
    const std::vector<uint32_t>& members = groups.at(root);
    // Closed: every directed edge of the group once, and its twin once.
    std::vector<std::pair<uint64_t, uint32_t>> own;  // directed edges with their triangles
    for (uint32_t t : members) {
      for (int k = 0; k < 3; ++k) own.emplace_back(EdgeKey(tri[t][k], tri[t][(k + 1) % 3]), t);
    }
    std::sort(own.begin(), own.end());
    const auto same_edge = [](const auto& a, const auto& b) { return a.first == b.first; };
    const auto twin_key = [](uint64_t key) { return key << 32 | key >> 32; };
    const auto twin_of = [&](uint64_t key) {
      return std::lower_bound(own.begin(), own.end(), std::pair<uint64_t, uint32_t>{twin_key(key), 0});
    };
    bool closed = members.size() >= 4 && std::adjacent_find(own.begin(), own.end(), same_edge) == own.end();
    for (size_t e = 0; closed && e < own.size(); ++e) {
      const auto twin = twin_of(own[e].first);
      closed = twin != own.end() && twin->first == twin_key(own[e].first);
    }
    std::vector<uint32_t> corner;  // welded ids
    for (uint32_t t : members) corner.insert(corner.end(), tri[t].begin(), tri[t].end());
    std::sort(corner.begin(), corner.end());
    corner.erase(std::unique(corner.begin(), corner.end()), corner.end());
    bool convex = closed && corner.size() <= kMaxPieceCorners;
    glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
    for (uint32_t c : corner) {
      lo = glm::min(lo, glm::dvec3(welded[c]));
      hi = glm::max(hi, glm::dvec3(welded[c]));
    }
    // A millionth of the piece's size and of its distance from the origin (float rounding).
    const double tol = 1e-6 * (glm::length(hi - lo) + std::max(glm::length(lo), glm::length(hi)));
    for (size_t m = 0; convex && m < members.size(); ++m) {
      const glm::dvec3 a(welded[tri[members[m]][0]]), b(welded[tri[members[m]][1]]), c(welded[tri[members[m]][2]]);
      const glm::dvec3 normal = glm::cross(b - a, c - a);
      const double len = glm::length(normal);
      if (!(len > 0.0)) continue;  // a sliver adds no plane
      for (uint32_t v : corner) {
        if (glm::dot(glm::dvec3(welded[v]) - a, normal) > tol * len) {
          convex = false;
          break;
        }
      }
    }
    if (!convex) {
      loose.insert(loose.end(), members.begin(), members.end());
      continue;
    }
    Piece p;
    const glm::dvec3 centre = 0.5 * (lo + hi);
    double radius = 0.0;
    for (uint32_t c : corner) radius = std::max(radius, glm::length(glm::dvec3(welded[c]) - centre));
    p.centre = glm::vec3(centre);
    p.radius = static_cast<float>(radius * (1.0 + 1e-5) + tol);  // float rounding of the test
    p.corner_block = static_cast<uint32_t>(corners_.size());
    p.corner_count = static_cast<uint32_t>(corner.size());
    corners_.resize(corners_.size() + (corner.size() + 3) / 4);
    for (size_t i = 0; i < (corners_.size() - p.corner_block) * 4; ++i) {
      const glm::vec3 v = welded[corner[std::min(i, corner.size() - 1)]];
      Corners& c = corners_[p.corner_block + i / 4];
      c.x[i % 4] = v.x, c.y[i % 4] = v.y, c.z[i % 4] = v.z;
    }
    auto local = [&](uint32_t id) {
      return static_cast<uint8_t>(std::lower_bound(corner.begin(), corner.end(), id) - corner.begin());
    };
    // tri[t]'s corner off edge (u, v).
    const auto opposite = [&](uint32_t t, uint32_t u, uint32_t v) {
      for (uint32_t c : tri[t]) {
        if (c != u && c != v) return c;
      }
      return tri[t][0];
    };
    // The piece's edges, each once, but for those inside a face (between two triangles of one
    // plane, as a quad's diagonal): the plane crosses a face in a segment whose ends lie on the
    // face's border, so a crossing inside it is never the smallest or the largest λ.
    p.edge = static_cast<uint32_t>(edges_.size());
    for (const auto& [e, t] : own) {
      const uint32_t u = static_cast<uint32_t>(e >> 32), v = static_cast<uint32_t>(e);
      if (u > v) continue;
      const glm::dvec3 a(welded[u]), b(welded[v]), c(welded[opposite(t, u, v)]);
      const glm::dvec3 normal = glm::cross(b - a, c - a);
      const glm::dvec3 w(welded[opposite(twin_of(e)->second, u, v)]);
      const double len = glm::length(normal);
      // Slivers (no plane) keep their edges.
      const bool inside_face = len > 0.0 && glm::length(glm::cross(b - a, w - a)) > 0.0 &&
                               std::abs(glm::dot(w - a, normal)) <= tol * len;
      if (inside_face) continue;
      edges_.emplace_back(local(u), local(v));
    }
    p.edge_count = static_cast<uint32_t>(edges_.size()) - p.edge;
    p.block = append_blocks(members);
    p.triangle_count = static_cast<uint32_t>(members.size());
    pieces_.push_back(p);
  }
  // Morton order of the pieces' and loose triangles' centres over the object's box, so that
  // neighbours in the lists are neighbours in space and the sphere trees stay tight.
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const glm::vec3& v : welded) {
    lo = glm::min(lo, glm::dvec3(v));
    hi = glm::max(hi, glm::dvec3(v));
  }
  const glm::dvec3 ext = hi - lo;
  {
    std::vector<std::pair<uint32_t, uint32_t>> order(pieces_.size());
    for (uint32_t i = 0; i < pieces_.size(); ++i) order[i] = {Morton(glm::dvec3(pieces_[i].centre), lo, ext), i};
    std::sort(order.begin(), order.end());
    std::vector<Piece> sorted(pieces_.size());
    std::vector<Sphere> leaves(pieces_.size());
    for (size_t i = 0; i < order.size(); ++i) {
      sorted[i] = pieces_[order[i].second];
      leaves[i] = Sphere{sorted[i].centre, sorted[i].radius};
    }
    pieces_ = std::move(sorted);
    piece_tree_ = BuildSphereTree(std::move(leaves));
  }
  auto centroid = [&](uint32_t t) {
    return (glm::dvec3(positions[indices[3 * t]]) + glm::dvec3(positions[indices[3 * t + 1]]) +
            glm::dvec3(positions[indices[3 * t + 2]])) / 3.0;
  };
  std::vector<std::pair<uint32_t, uint32_t>> order(loose.size());
  for (size_t i = 0; i < loose.size(); ++i) order[i] = {Morton(centroid(loose[i]), lo, ext), loose[i]};
  std::sort(order.begin(), order.end());
  for (size_t i = 0; i < loose.size(); ++i) loose[i] = order[i].second;
  loose_count_ = static_cast<uint32_t>(loose.size());
  loose_block_ = static_cast<uint32_t>(blocks_.size());
  if (!loose.empty()) append_blocks(loose);
  // One sphere per cluster of kClusterBlocks blocks, around its triangles' corners (in double,
  // then widened by what rounding to float and the float test can lose, as for pieces).
  std::vector<Sphere> clusters;
  const size_t per_cluster = 4 * kClusterBlocks;
  for (size_t first = 0; first < loose.size(); first += per_cluster) {
    const size_t last = std::min(loose.size(), first + per_cluster);
    glm::dvec3 clo(std::numeric_limits<double>::infinity()), chi(-clo);
    for (size_t i = first; i < last; ++i) {
      for (int k = 0; k < 3; ++k) {
        clo = glm::min(clo, glm::dvec3(positions[indices[3 * loose[i] + k]]));
        chi = glm::max(chi, glm::dvec3(positions[indices[3 * loose[i] + k]]));
      }
    }
    const glm::dvec3 centre = 0.5 * (clo + chi);
    double radius = 0.0;
    for (size_t i = first; i < last; ++i) {
      for (int k = 0; k < 3; ++k) {
        radius = std::max(radius, glm::length(glm::dvec3(positions[indices[3 * loose[i] + k]]) - centre));
      }
    }
    const double tol = 1e-6 * (glm::length(chi - clo) + std::max(glm::length(clo), glm::length(chi)));
    clusters.push_back(Sphere{glm::vec3(centre), static_cast<float>(radius * (1.0 + 1e-5) + tol)});
  }
  loose_tree_ = BuildSphereTree(std::move(clusters));
}

FanSurface::Hot FanSurface::hot() const {
  Hot h;
  auto put = [&](int k, const void* p, size_t bytes, size_t most) {
    h.at[k] = p;
    h.bytes[k] = static_cast<uint32_t>(std::min(bytes, most));
  };
  put(0, pieces_.data(), pieces_.size() * sizeof(Piece), 192);
  put(1, corners_.data(), corners_.size() * sizeof(Corners), 192);
  if (pieces_.empty() || loose_count_ > 0) {
    put(2, blocks_.data() + loose_block_, (loose_count_ + 3) / 4 * sizeof(Block), 576);
  } else {
    put(2, edges_.data(), edges_.size() * sizeof(edges_[0]), 128);
  }
  return h;
}

void FanSurface::Prefetch(const Hot& hot) {
  for (int k = 0; k < 3; ++k) {
    const char* c = static_cast<const char*>(hot.at[k]);
    for (uint32_t o = 0; o < hot.bytes[k]; o += 64) __builtin_prefetch(c + o);
  }
}

void FanHits(const DiscoveryFan& fan, const FanSurface& surface, std::vector<std::pair<double, double>>* out) {
  const glm::dvec3 seg = fan.to - fan.from;
  const double len = glm::length(seg);
  if (!(len > 0.0) || !(fan.radius > 0.0) || surface.triangles() == 0) return;
  Frame f;
  f.ds = seg / len;
  f.dd = fan.d;
  f.dn = glm::cross(f.ds, fan.d);
  f.dfrom = fan.from;
  f.s = glm::vec3(f.ds);
  f.d = glm::vec3(f.dd);
  f.n = glm::vec3(f.dn);
  f.from = glm::vec3(fan.from);
  f.from_low = glm::vec3(fan.from - glm::dvec3(f.from));
  f.dalpha_min = 1e-6 * len;
  f.dscale = len / fan.radius;
  f.alpha_min = static_cast<float>(f.dalpha_min);
  f.scale = static_cast<float>(f.dscale);
  // The plane misses a sphere, or the sphere lies wholly behind `from`: nothing in it to read.
  auto misses = [&f](const FanSurface::Sphere& s) {
    const glm::vec3 r = s.centre - f.from;
    return std::abs(glm::dot(r, f.n)) > s.radius || glm::dot(r, f.s) < -s.radius;
  };
  std::span<const FanSurface::Piece> pieces = surface.piece_list();
  VisitSphereTree(surface.piece_tree(), misses, [&](uint32_t i) {
    const FanSurface::Piece& p = pieces[i];
    if (!PieceHit(f, surface, p, out)) {
      TriangleHits(f, surface.blocks().subspan(p.block, (p.triangle_count + 3) / 4), p.triangle_count, out);
    }
  });
  const uint32_t per_cluster = 4 * FanSurface::kClusterBlocks;
  VisitSphereTree(surface.loose_tree(), misses, [&](uint32_t c) {
    const uint32_t first = c * per_cluster, count = std::min(per_cluster, surface.loose_count() - first);
    TriangleHits(f, surface.blocks().subspan(surface.loose_block() + first / 4, (count + 3) / 4), count, out);
  });
}

std::optional<double> SilhouetteLambda(const DiscoveryFan& fan, const FanSurface& surface,
                                       std::vector<std::pair<double, double>>* scratch, double gap) {
  std::vector<std::pair<double, double>>& iv = *scratch;
  iv.clear();
  FanHits(fan, surface, &iv);
  // Runs are unions of intervals closer than `gap`. Of the intervals that start at or below 0,
  // the one reaching highest lies in the last run that starts there: the run holding 0 if any
  // does, else the run with the largest meeting λ below 0.
  double top = -std::numeric_limits<double>::infinity();
  for (const auto& [lo, hi] : iv) {
    if (hi >= 1.0) return std::nullopt;  // the far end is met: no silhouette within reach
    if (lo <= 0.0) top = std::max(top, hi);
  }
  if (!(top >= -1.0)) return std::nullopt;
  // Climb in order of the intervals' starts: once one starts past top + gap, so do the rest.
  std::sort(iv.begin(), iv.end());
  for (const auto& [lo, hi] : iv) {
    if (lo > top + gap) break;
    top = std::max(top, hi);
  }
  return top;
}

}  // namespace vistream::visibility
