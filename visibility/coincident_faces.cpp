#include "visibility/coincident_faces.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <tuple>
#include <utility>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <glm/vec2.hpp>

#include "visibility/kdtree.h"

namespace vistream::visibility {

namespace {

struct Face {
  FaceRef ref;
  glm::dvec3 v[3];
  glm::dvec3 n;       // unit normal
  double d = 0.0;     // plane: dot(n, x) = d
  glm::dvec3 lo, hi;  // box
};

// A face filed under one plane bucket and one square of that plane: faces that may coincide
// share a bucket (or lie in neighbouring offset bins) and a square.
struct Record {
  int axis;       // the normal's dominant axis
  int64_t bin;    // the plane's offset along that axis, in bins of kBin
  int64_t s, t;   // the square, in the two other axes
  int orient;     // sign of the normal's dominant component
  uint32_t face;
  auto Key() const { return std::tie(axis, bin, s, t, orient); }
};

constexpr double kBin = 1.0 / 16.0;   // plane offset bins, metres (far wider than the tolerance)
constexpr double kSquare = 32.0;      // squares within a plane, metres
// Radians two coincident faces' normals may be from opposite: a short wall whose corners
// rounding moved by millimetres turns by that much; the corners' distance to the other plane
// is the finer test.
constexpr double kAngle = 0.01;

// Every point of `f` within `tol` of the plane of `g`.
bool OnPlaneOf(const Face& f, const Face& g, double tol) {
  for (const glm::dvec3& p : f.v) {
    if (std::abs(glm::dot(g.n, p) - g.d) > tol) return false;
  }
  return true;
}

// Whether the two triangles, projected along `axis`, overlap by more than `tol` on every
// separating-axis candidate (their edge normals): then their common part is wider than tol.
bool OverlapInPlane(const Face& f, const Face& g, int axis, double tol) {
  const int i = (axis + 1) % 3, j = (axis + 2) % 3;
  glm::dvec2 p[3], q[3];
  for (int k = 0; k < 3; ++k) {
    p[k] = {f.v[k][i], f.v[k][j]};
    q[k] = {g.v[k][i], g.v[k][j]};
  }
  auto separated_by_edges_of = [&](const glm::dvec2* tri) {
    for (int k = 0; k < 3; ++k) {
      const glm::dvec2 e = tri[(k + 1) % 3] - tri[k];
      const double len = glm::length(e);
      if (!(len > 0.0)) continue;
      const glm::dvec2 m(-e.y / len, e.x / len);
      double p0 = INFINITY, p1 = -INFINITY, q0 = INFINITY, q1 = -INFINITY;
      for (int c = 0; c < 3; ++c) {
        p0 = std::min(p0, glm::dot(m, p[c]));
        p1 = std::max(p1, glm::dot(m, p[c]));
        q0 = std::min(q0, glm::dot(m, q[c]));
        q1 = std::max(q1, glm::dot(m, q[c]));
      }
      if (std::min(p1, q1) - std::max(p0, q0) <= tol) return true;
    }
    return false;
  };
  return !separated_by_edges_of(p) && !separated_by_edges_of(q);
}

bool Coincide(const Face& f, const Face& g, int axis, double tol) {
  for (int k = 0; k < 3; ++k) {
    if (f.lo[k] > g.hi[k] + tol || g.lo[k] > f.hi[k] + tol) return false;
  }
  return glm::dot(f.n, g.n) < -std::cos(kAngle) && OnPlaneOf(f, g, tol) && OnPlaneOf(g, f, tol) &&
         OverlapInPlane(f, g, axis, tol);
}

}  // namespace

std::span<const CoincidentFaces::Entry> CoincidentFaces::Partners(uint32_t m, uint32_t t) const {
  if (m >= of_mesh.size()) return {};
  const std::vector<Entry>& e = of_mesh[m];
  const auto first = std::lower_bound(e.begin(), e.end(), t, [](const Entry& x, uint32_t v) { return x.triangle < v; });
  auto last = first;
  while (last != e.end() && last->triangle == t) ++last;
  return {first, last};
}

CoincidentFaces FindCoincidentFaces(std::span<const MeshView> meshes, double tol) {
  std::vector<Face> faces;
  for (uint32_t m = 0; m < meshes.size(); ++m) {
    const MeshView& mesh = meshes[m];
    for (uint32_t t = 0; 3 * t + 2 < mesh.indices.size(); ++t) {
      Face f;
      f.ref = {m, t};
      bool in_range = true;
      for (int k = 0; k < 3; ++k) {
        const uint32_t i = mesh.indices[3 * t + k];
        in_range &= i < mesh.positions.size();
        f.v[k] = in_range ? glm::dvec3(mesh.positions[i]) : glm::dvec3(0.0);
      }
      if (!in_range) continue;
      const glm::dvec3 n = glm::cross(f.v[1] - f.v[0], f.v[2] - f.v[0]);
      const double len = glm::length(n);
      if (!(len > tol * tol) || !std::isfinite(len)) continue;  // no area to share
      f.n = n / len;
      f.d = glm::dot(f.n, f.v[0]);
      f.lo = glm::min(glm::min(f.v[0], f.v[1]), f.v[2]);
      f.hi = glm::max(glm::max(f.v[0], f.v[1]), f.v[2]);
      faces.push_back(f);
    }
  }

  // File each face under its dominant axis (and any axis within kAngle of it, so that two
  // faces of one plane always share one), its plane offset bin and the squares it covers.
  std::vector<Record> records;
  for (uint32_t id = 0; id < faces.size(); ++id) {
    const Face& f = faces[id];
    const glm::dvec3 a = glm::abs(f.n);
    const double top = std::max({a.x, a.y, a.z});
    for (int axis = 0; axis < 3; ++axis) {
      if (a[axis] < top - kAngle) continue;
      const int orient = f.n[axis] > 0 ? 1 : -1;
      // The offset of the plane along `axis` where it crosses the face: the same for both
      // orientations once signed alike.
      const double offset = orient * f.d;
      const int i = (axis + 1) % 3, j = (axis + 2) % 3;
      const auto bin = static_cast<int64_t>(std::floor(offset / kBin));
      const auto s0 = static_cast<int64_t>(std::floor(f.lo[i] / kSquare)),
                 s1 = static_cast<int64_t>(std::floor(f.hi[i] / kSquare));
      const auto t0 = static_cast<int64_t>(std::floor(f.lo[j] / kSquare)),
                 t1 = static_cast<int64_t>(std::floor(f.hi[j] / kSquare));
      for (int64_t s = s0; s <= s1; ++s) {
        for (int64_t t = t0; t <= t1; ++t) records.push_back({axis, bin, s, t, orient, id});
      }
    }
  }
  std::sort(records.begin(), records.end(), [](const Record& x, const Record& y) {
    return std::tie(x.axis, x.bin, x.s, x.t, x.orient, x.face) < std::tie(y.axis, y.bin, y.s, y.t, y.orient, y.face);
  });
  auto run = [&](int axis, int64_t bin, int64_t s, int64_t t, int orient) {
    const Record probe{axis, bin, s, t, orient, 0};
    auto less = [](const Record& x, const Record& y) { return x.Key() < y.Key(); };
    return std::equal_range(records.begin(), records.end(), probe, less);
  };

  // Each face facing +axis against the faces facing -axis in its square, in its bin and the
  // two beside it (a plane near a bin's edge may land in the next one).
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  for (size_t r = 0; r < records.size();) {
    size_t end = r + 1;
    while (end < records.size() && records[end].Key() == records[r].Key()) ++end;
    const Record& head = records[r];
    if (head.orient > 0) {
      for (int64_t bin = head.bin - 1; bin <= head.bin + 1; ++bin) {
        const auto [m0, m1] = run(head.axis, bin, head.s, head.t, -1);
        for (size_t p = r; p < end; ++p) {
          for (auto m = m0; m != m1; ++m) {
            if (Coincide(faces[records[p].face], faces[m->face], head.axis, tol)) {
              pairs.emplace_back(records[p].face, m->face);
            }
          }
        }
      }
    }
    r = end;
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());

  CoincidentFaces out;
  out.of_mesh.resize(meshes.size());
  for (const auto& [x, y] : pairs) {
    const FaceRef a = faces[x].ref, b = faces[y].ref;
    out.of_mesh[a.mesh].push_back({a.triangle, b});
    out.of_mesh[b.mesh].push_back({b.triangle, a});
  }
  for (auto& e : out.of_mesh) {
    std::sort(e.begin(), e.end(), [](const CoincidentFaces::Entry& x, const CoincidentFaces::Entry& y) {
      return std::tie(x.triangle, x.partner.mesh, x.partner.triangle) <
             std::tie(y.triangle, y.partner.mesh, y.partner.triangle);
    });
  }
  return out;
}

struct PartnerLookup::Indexed {
  std::vector<FaceRef> partners;
  KdTree tree;  // over the partners' boxes; its ids index `partners`
  // PointOnTriangle accepts a point whose projection lies within the triangle's edges offset
  // outward by the tolerance (they meet tolerance / sin(angle / 2) beyond a corner) and within
  // the tolerance of its plane: it lies within (1 + 1 / sin(smallest angle / 2)) tolerances of
  // the triangle's box, per axis. The largest such factor of the partners.
  double reach = 1.0;
};

namespace {

// 1 + 1 / sin(a / 2) for the smallest angle a of triangle (p, q, r); infinity when degenerate.
double CornerReach(const glm::dvec3& p, const glm::dvec3& q, const glm::dvec3& r) {
  const glm::dvec3* v[3] = {&p, &q, &r};
  double smallest_half_sine = 1.0;
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 a = *v[(k + 1) % 3] - *v[k], b = *v[(k + 2) % 3] - *v[k];
    const double la = glm::length(a), lb = glm::length(b);
    if (!(la > 0.0 && lb > 0.0)) return std::numeric_limits<double>::infinity();
    const double cosine = std::clamp(glm::dot(a, b) / (la * lb), -1.0, 1.0);
    smallest_half_sine = std::min(smallest_half_sine, std::sqrt(0.5 * (1.0 - cosine)));  // sin(a / 2)
  }
  return smallest_half_sine > 0.0 ? 1.0 + 1.0 / smallest_half_sine : std::numeric_limits<double>::infinity();
}

}  // namespace

PartnerLookup::PartnerLookup(const CoincidentFaces& faces, std::vector<MeshView> meshes)
    : faces_(&faces), meshes_(std::move(meshes)) {
  for (uint32_t m = 0; m < faces.of_mesh.size(); ++m) {
    const std::vector<CoincidentFaces::Entry>& entries = faces.of_mesh[m];
    for (size_t i = 0, j = 0; i < entries.size(); i = j) {
      while (j < entries.size() && entries[j].triangle == entries[i].triangle) ++j;
      if (j - i <= kIndexedPartners) continue;
      auto indexed = std::make_shared<Indexed>();
      std::vector<scenes::Aabb> boxes;
      for (size_t k = i; k < j; ++k) {
        const FaceRef f = entries[k].partner;
        const MeshView& mesh = meshes_[f.mesh];
        glm::dvec3 corner[3];
        scenes::Aabb box;
        for (int v = 0; v < 3; ++v) {
          corner[v] = glm::dvec3(mesh.positions[mesh.indices[3 * f.triangle + v]]);
          box.Extend(corner[v]);
        }
        indexed->reach = std::max(indexed->reach, CornerReach(corner[0], corner[1], corner[2]));
        indexed->partners.push_back(f);
        boxes.push_back(box);
      }
      // A sliver (its reach unbounded) leaves the triangle to the scan.
      if (!(indexed->reach < 1e6)) continue;
      indexed->tree = KdTree::Build(boxes);
      indexed_.emplace(static_cast<uint64_t>(m) << 32 | entries[i].triangle, std::move(indexed));
    }
  }
}

bool PartnerLookup::OnFace(const FaceRef& f, const glm::dvec3& p, double tolerance) const {
  const MeshView& mesh = meshes_[f.mesh];
  const uint32_t* t = &mesh.indices[3 * f.triangle];
  return PointOnTriangle(p, glm::dvec3(mesh.positions[t[0]]), glm::dvec3(mesh.positions[t[1]]),
                         glm::dvec3(mesh.positions[t[2]]), tolerance);
}

bool PartnerLookup::OnPartner(uint32_t m, uint32_t t, const glm::dvec3& p, double tolerance) const {
  if (faces_ == nullptr) return false;
  const std::span<const CoincidentFaces::Entry> partners = faces_->Partners(m, t);
  // Few partners (or a sliver among many): every one tested.
  const auto found = partners.size() > kIndexedPartners ? indexed_.find(static_cast<uint64_t>(m) << 32 | t)
                                                        : indexed_.end();
  if (found == indexed_.end()) {
    for (const CoincidentFaces::Entry& e : partners) {
      if (OnFace(e.partner, p, tolerance)) return true;
    }
    return false;
  }
  // The partners whose box, grown by their reach, holds p: PointOnTriangle is false beyond it.
  const Indexed& ix = *found->second;
  if (ix.tree.empty()) return false;
  const double grow = ix.reach * tolerance;
  auto near = [&](const scenes::Aabb& b) {
    return p.x >= b.min.x - grow && p.x <= b.max.x + grow && p.y >= b.min.y - grow && p.y <= b.max.y + grow &&
           p.z >= b.min.z - grow && p.z <= b.max.z + grow;
  };
  // Depth first: at most one pending sibling a level (KdTreeOptions::max_depth is 48).
  std::array<int32_t, 128> stack;
  size_t top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const KdNode& n = ix.tree.nodes()[static_cast<size_t>(stack[--top])];
    if (!near(n.bounds)) continue;
    if (!n.IsLeaf()) {
      stack[top++] = n.left;
      stack[top++] = n.right;
      continue;
    }
    for (const ObjectId k : ix.tree.LeafObjects(n)) {
      if (OnFace(ix.partners[k], p, tolerance)) return true;
    }
  }
  return false;
}

bool PointOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c,
                     double tol) {
  glm::dvec3 n = glm::cross(b - a, c - a);
  const double len = glm::length(n);
  if (!(len > 0.0)) return false;
  n /= len;
  if (std::abs(glm::dot(p - a, n)) > tol) return false;
  const glm::dvec3* v[3] = {&a, &b, &c};
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 e = *v[(k + 1) % 3] - *v[k];
    const glm::dvec3 inward = glm::cross(n, e);
    const double el = glm::length(inward);
    if (!(el > 0.0)) continue;
    if (glm::dot(p - *v[k], inward) / el < -tol) return false;
  }
  return true;
}

}  // namespace vistream::visibility
