#include "visibility/epsilon_superset.h"

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <optional>

#include <embree3/rtcore.h>
#include <glm/geometric.hpp>

#include "visibility/epsilon_superset_internal.h"
#include "visibility/parallel.h"

namespace vistream::visibility {

namespace {

double Ms(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// The distinct corners of a box: 8, or fewer when it is flat along some axis. Bit a of
// `bits` says whether the corner is on the max side along axis a; a corner of a flat axis is
// on both sides.
struct Corner {
  glm::dvec3 p;
  uint8_t bits;
};

int Corners(const Aabb& b, std::array<Corner, 8>* out) {
  int n = 0;
  for (uint8_t bits = 0; bits < 8; ++bits) {
    bool duplicate = false;
    for (int a = 0; a < 3; ++a) duplicate |= ((bits >> a) & 1) && b.min[a] == b.max[a];
    if (duplicate) continue;
    (*out)[n++] = {glm::dvec3((bits & 1) ? b.max.x : b.min.x, (bits & 2) ? b.max.y : b.min.y,
                              (bits & 4) ? b.max.z : b.min.z),
                   bits};
  }
  return n;
}

// Whether `c` lies on the face of `b` on side `max_side` of axis `a`.
bool OnFace(const Aabb& b, const Corner& c, int a, bool max_side) {
  return b.min[a] == b.max[a] || (((c.bits >> a) & 1) != 0) == max_side;
}

double BoxDistance2(const Aabb& a, const Aabb& b) {
  double d2 = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double gap = std::max({0.0, b.min[k] - a.max[k], a.min[k] - b.max[k]});
    d2 += gap * gap;
  }
  return d2;
}

}  // namespace

// A segment from a corner of the neighbourhood to an occludee vertex, relative to the query
// origin: e + t·d for t in [0, 1].
struct Ray {
  glm::dvec3 e, d;
};

// One neighbourhood's computation: the box's corners, the per-occludee rays, the hidden
// objects that stop being occluders, and Embree's intersect context.
struct EpsilonSuperset::Query {
  // Embree passes this back to the intersect callback; `base` must come first.
  struct TraceContext {
    RTCIntersectContext base;
    Query* query;
    const Ray* ray;
    bool stop_at_hider;  // test each crossing prism on every ray at once, stop at a hider
    uint32_t hider;
    // With stop_at_hider: rays [0, own_rays) are the traced vertex's own; a prism crossed by
    // all of them hides that vertex, which sets own_hidden and is appended to own_hiders
    // (when given).
    size_t own_rays;
    bool own_hidden;
    std::vector<uint32_t>* own_hiders;
  };
  static constexpr uint32_t kNone = ~0u;

  const EpsilonSuperset& set;
  const EpsilonOptions& options;
  Aabb box;
  glm::dvec3 q;  // query origin: geometric decisions use coordinates relative to it
  std::array<glm::dvec3, 8> corner;  // the box's distinct corners, relative to q
  // For a vertex in region r (per axis: 0 below the box, 1 within, 2 above; r = x + 3y + 9z),
  // the corners to cast from: those on a face of the box that the vertex lies strictly
  // outside of. A segment from any other corner enters the box through such a face, at a
  // point those corners imply. None for r = 13: a vertex in the box, which nothing hides.
  std::array<uint8_t, 27> corner_mask{};
  // Per object: kNear when its box meets the neighbourhood (which may then lie in its solid),
  // kDropped when it is hidden and drop_hidden_occluders is on; either stops it occluding.
  static constexpr uint8_t kNear = 1, kDropped = 2;
  std::vector<uint8_t> blocked;
  std::optional<ObjectId> skip;  // the occludee's own object, while testing its box
  std::vector<std::pair<double, uint32_t>> hits;
  std::vector<Ray> rays;
  std::array<uint32_t, 2> recent = {kNone, kNone};  // the prisms that hid the last occludees
  uint64_t* ray_tests = nullptr;
  EpsilonStats stats;

  Query(const EpsilonSuperset& s, const EpsilonOptions& o, const Aabb& b)
      : set(s), options(o), box(b), q(b.min), blocked(s.scene_.objects.size(), 0) {
    // The objects whose box meets the neighbourhood, from the scene's tree (objects with an
    // empty box are not in it, and meet nothing).
    if (!set.tree_.empty()) {
      const std::vector<KdNode>& nodes = set.tree_.nodes();
      std::vector<uint32_t> stack = {0};
      while (!stack.empty()) {
        const KdNode& node = nodes[stack.back()];
        stack.pop_back();
        if (!node.bounds.Overlaps(box)) continue;
        if (node.IsLeaf()) {
          for (ObjectId id : set.tree_.LeafObjects(node)) {
            if (set.scene_.objects[id].bounds.Overlaps(box)) blocked[id] |= kNear;
          }
        } else {
          stack.push_back(static_cast<uint32_t>(node.left));
          stack.push_back(static_cast<uint32_t>(node.right));
        }
      }
    }
    std::array<Corner, 8> c;
    const int n = Corners(box, &c);
    for (int r = 0; r < 27; ++r) {
      if (r == 13) continue;
      const int side[3] = {r % 3, (r / 3) % 3, r / 9};
      for (int k = 0; k < n; ++k) {
        bool needed = !options.silhouette_rays;
        for (int a = 0; a < 3 && !needed; ++a) {
          needed = (side[a] == 0 && OnFace(box, c[k], a, false)) || (side[a] == 2 && OnFace(box, c[k], a, true));
        }
        if (needed) corner_mask[r] |= static_cast<uint8_t>(1u << k);
      }
    }
    for (int k = 0; k < n; ++k) corner[k] = c[k].p - q;
    corner_count = n;
  }
  int corner_count = 0;

  // A prism may occlude unless its object is hidden (and so dropped), is the occludee itself
  // (testing boxes), or its box meets the neighbourhood, which may then lie in its solid.
  bool Usable(uint32_t prism) const {
    const ObjectId object = set.prisms_[prism].object;
    return blocked[object] == 0 && skip != object;
  }

  bool Crosses(uint32_t prism, const Ray& r) {
    ++*ray_tests;
    double t_in = 0.0;
    return set.Crosses(prism, q, r.e, r.d, &t_in);
  }

  static void Intersect(const RTCIntersectFunctionNArguments* args) {
    if (args->valid[0] == 0) return;
    auto* ctx = reinterpret_cast<TraceContext*>(args->context);
    Query& query = *ctx->query;
    if (ctx->hider != kNone || !query.Usable(args->primID)) return;
    ++*query.ray_tests;
    double t_in = 0.0;
    if (!query.set.Crosses(args->primID, query.q, ctx->ray->e, ctx->ray->d, &t_in)) return;
    if (!ctx->stop_at_hider) {
      // No hit is reported, so Embree goes on to every prism box along the segment.
      query.hits.emplace_back(t_in, args->primID);
      return;
    }
    for (size_t r = 1; r < query.rays.size(); ++r) {
      if (r == ctx->own_rays) {
        ctx->own_hidden = true;
        if (ctx->own_hiders != nullptr) ctx->own_hiders->push_back(args->primID);
      }
      if (!query.Crosses(args->primID, query.rays[r])) return;
    }
    // A hider: report a hit at t = 0, so that Embree gives up the rest of the segment.
    ctx->hider = args->primID;
    RTCRayN_tfar(RTCRayHitN_RayN(args->rayhit, args->N), args->N, 0) = 0.0f;
    RTCHitN* hit = RTCRayHitN_HitN(args->rayhit, args->N);
    RTCHitN_geomID(hit, args->N, 0) = args->geomID;
    RTCHitN_primID(hit, args->N, 0) = args->primID;
  }

  // Every usable prism `r` crosses, nearest first, into `hits`: one Embree all-hits
  // traversal. With `stop_at_hider`, each is tried on every ray in `rays` as it is met, and
  // the first that all cross ends the traversal and is returned (kNone if none).
  // `own_hidden`, when given, says whether a prism crossed every ray in [0, own_rays), and
  // `own_hiders`, when given, gets every such prism met (all of them when none hid every ray:
  // the traversal then went the whole segment).
  uint32_t Trace(const Ray& r, bool stop_at_hider = false, size_t own_rays = 0, bool* own_hidden = nullptr,
                 std::vector<uint32_t>* own_hiders = nullptr) {
    hits.clear();
    TraceContext ctx;
    rtcInitIntersectContext(&ctx.base);
    ctx.query = this;
    ctx.ray = &r;
    ctx.stop_at_hider = stop_at_hider;
    ctx.hider = kNone;
    ctx.own_rays = own_rays;
    ctx.own_hidden = false;
    ctx.own_hiders = own_hiders;
    const glm::dvec3 o = q + r.e - set.frame_;
    RTCRayHit rh{};
    rh.ray.org_x = static_cast<float>(o.x);
    rh.ray.org_y = static_cast<float>(o.y);
    rh.ray.org_z = static_cast<float>(o.z);
    rh.ray.dir_x = static_cast<float>(r.d.x);
    rh.ray.dir_y = static_cast<float>(r.d.y);
    rh.ray.dir_z = static_cast<float>(r.d.z);
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = 1.0f;
    rh.ray.mask = 0xFFFFFFFFu;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(set.embree_->scene, &ctx.base, &rh);
    ++stats.traversals;
    std::sort(hits.begin(), hits.end());
    if (own_hidden != nullptr) *own_hidden = ctx.own_hidden || ctx.hider != kNone;
    return ctx.hider;
  }

  // Appends to `rays` the rays to vertex `p` (absolute). False if `p` lies in the box.
  bool AddRays(const glm::dvec3& p) {
    const int r = (p.x < box.min.x ? 0 : p.x > box.max.x ? 2 : 1) + 3 * (p.y < box.min.y ? 0 : p.y > box.max.y ? 2 : 1) +
                  9 * (p.z < box.min.z ? 0 : p.z > box.max.z ? 2 : 1);
    if (r == 13) return false;
    const glm::dvec3 pq = p - q;
    unsigned mask = corner_mask[r];
    const int n = std::popcount(mask);
    stats.skipped_rays += static_cast<uint64_t>(corner_count - n);
    const size_t at = rays.size();
    rays.resize(at + static_cast<size_t>(n));
    for (Ray* out = rays.data() + at; mask != 0; mask &= mask - 1, ++out) {
      const glm::dvec3& c = corner[std::countr_zero(mask)];
      *out = Ray{c, pq - c};
    }
    return true;
  }

  // Whether box `b` is hidden; prisms of `own` (the object it bounds) are not tried.
  bool BoxHidden(const Aabb& b, std::optional<ObjectId> own, uint64_t* tests, bool* first) {
    *first = false;
    if (b.Overlaps(box)) return false;
    // The box's corners on faces that some point of the neighbourhood lies outside of: from
    // any such point, a segment to another corner enters the box through one of them.
    std::array<Corner, 8> pc;
    const int n = Corners(b, &pc);
    rays.clear();
    for (int c = 0; c < n; ++c) {
      bool needed = !options.silhouette_rays;
      for (int a = 0; a < 3 && !needed; ++a) {
        needed = (box.min[a] < b.min[a] && OnFace(b, pc[c], a, false)) ||
                 (box.max[a] > b.max[a] && OnFace(b, pc[c], a, true));
      }
      if (!needed) {
        stats.skipped_rays += corner_count;
      } else if (!AddRays(pc[c].p)) {
        return false;
      }
    }
    skip = own;
    const bool hidden = Hidden(std::nullopt, tests, first);
    skip.reset();
    return hidden;
  }

  // Puts next to rays[0] rays least like it, so that a prism that is not a hider usually
  // fails on the second or third ray rather than on a late one. Rays run over vertices and,
  // per vertex, over corners, both in the order of their coordinate bits: the last ray joins
  // the corner and vertex opposite the first's, and the middle one is halfway between.
  void SpreadRays() {
    const size_t n = rays.size();
    if (n > 2) std::swap(rays[1], rays[n - 1]);
    if (n > 4) std::swap(rays[2], rays[n / 2]);
  }

  // Whether one usable prism is crossed by every ray in `rays`. The hints (when on) are
  // tried first: the occluders that hid the last occludees, and `own`'s prisms, which hide
  // the far side of their object. Then the first ray gathers every prism it crosses and the
  // others are tried nearest first; *first says the nearest one was it.
  bool Hidden(std::optional<ObjectId> own, uint64_t* tests, bool* first) {
    *first = false;
    if (rays.empty()) return false;
    ray_tests = tests;
    if (options.hints) SpreadRays();
    size_t reached = 0;
    auto crosses_all = [&](uint32_t prism, size_t from) {
      for (size_t r = from; r < rays.size(); ++r) {
        reached = std::max(reached, r);
        if (!Crosses(prism, rays[r])) return false;
      }
      return true;
    };
    auto found = [&](uint32_t prism) {
      stats.rays += reached + 1;
      if (options.hints && recent[0] != prism) recent[1] = recent[0], recent[0] = prism;
      return true;
    };
    if (options.hints) {
      for (uint32_t prism : recent) {
        if (prism != kNone && Usable(prism) && crosses_all(prism, 0)) return found(prism);
      }
      if (own.has_value()) {
        for (uint32_t prism : set.PrismsOf(*own)) {
          if (Usable(prism) && crosses_all(prism, 0)) return found(prism);
        }
      }
    }
    if (options.hints) {
      // The hints missed: stop at the first hider met rather than sort them all.
      const uint32_t hider = Trace(rays[0], true);
      if (hider != kNone) {
        reached = rays.size() - 1;
        return found(hider);
      }
      stats.rays += rays.size();
      return false;
    }
    Trace(rays[0]);
    for (size_t h = 0; h < hits.size(); ++h) {
      if (crosses_all(hits[h].second, 1)) {
        *first = h == 0;
        return found(hits[h].second);
      }
    }
    stats.rays += reached + 1;
    return false;
  }

  // The triangles of `object` that no single prism hides, appended as ids to `out`. With
  // shared vertices, the rays of each distinct vertex are built once and what is learnt about
  // a vertex serves every triangle that has it (see EpsilonOptions::shared_vertices); a
  // triangle is hidden when one prism hides its three vertices: the same test as triangle
  // by triangle. (Collecting every hider of every vertex and intersecting the sets cost a
  // complete traversal per vertex; on london a vertex has ten hiders on average.)
  void VisibleTriangles(ObjectId object, uint64_t* tests, std::vector<uint32_t>* out) {
    const scenes::Mesh& mesh = set.scene_.objects[object].mesh;
    const auto n = static_cast<uint32_t>(mesh.TriangleCount());
    stats.tested_triangles += n;
    if (!options.shared_vertices) {
      for (uint32_t t = 0; t < n; ++t) {
        rays.clear();
        bool first = false, inside = false;
        for (int k = 0; k < 3; ++k) inside |= !AddRays(glm::dvec3(mesh.positions[mesh.indices[3 * t + k]]));
        if (inside || !Hidden(object, tests, &first)) out->push_back(set.TriangleId(object, t));
      }
      return;
    }
    ray_tests = tests;
    const uint32_t first_vertex = set.vertex_start_[object];
    const uint32_t distinct = set.vertex_start_[object + 1] - first_vertex;
    const uint32_t* corner_of = set.triangle_vertex_.data() + 3 * static_cast<size_t>(set.triangle_base_[object]);
    // Each distinct vertex's rays, built once: [vertex_ray_start[u], vertex_ray_start[u + 1]).
    vertex_state.assign(distinct, kUnknown);
    vertex_hiders_start.resize(distinct);
    vertex_hiders_end.resize(distinct);
    vertex_hiders.clear();
    vertex_hider.assign(distinct, kNone);
    vertex_miss.assign(distinct, kNone);
    vertex_ray_start.resize(distinct + 1);
    vertex_rays.clear();
    for (uint32_t u = 0; u < distinct; ++u) {
      vertex_ray_start[u] = static_cast<uint32_t>(vertex_rays.size());
      rays.clear();
      if (!AddRays(glm::dvec3(set.vertices_[first_vertex + u]))) {
        vertex_state[u] = kSeen;  // in the box: nothing hides it
      } else {
        SpreadRays();
        vertex_rays.insert(vertex_rays.end(), rays.begin(), rays.end());
      }
    }
    vertex_ray_start[distinct] = static_cast<uint32_t>(vertex_rays.size());
    auto rays_of = [&](uint32_t u) {
      return std::span<const Ray>(vertex_rays.data() + vertex_ray_start[u], vertex_ray_start[u + 1] - vertex_ray_start[u]);
    };
    for (uint32_t t = 0; t < n; ++t) {
      const uint32_t* v = corner_of + 3 * static_cast<size_t>(t);
      if (vertex_state[v[0]] == kSeen || vertex_state[v[1]] == kSeen || vertex_state[v[2]] == kSeen) {
        out->push_back(set.TriangleId(object, t));
        continue;
      }
      // The same test as intersecting the three vertices' sets of hiders: one prism crossed
      // by every ray of every vertex. Tried first (with hints) on the prisms that hid the
      // last triangles, then along one vertex's first ray, stopping at the first hider. A
      // vertex remembers the last prism found to hide it and the last found not to:
      // neighbouring triangles share vertices and are tried on the same prisms.
      auto hides = [&](uint32_t prism, uint32_t u) {
        if (vertex_hider[u] == prism) return true;
        if (vertex_miss[u] == prism) return false;
        if (vertex_state[u] == kKnown) {
          // Its list holds every usable prism that hides it (callers test usable prisms).
          const uint32_t* first = vertex_hiders.data() + vertex_hiders_start[u];
          return std::find(first, first + HiderCount(u), prism) != first + HiderCount(u);
        }
        for (const Ray& r : rays_of(u)) {
          if (!Crosses(prism, r)) {
            vertex_miss[u] = prism;
            return false;
          }
        }
        vertex_hider[u] = prism;
        return true;
      };
      uint32_t hider = kNone;
      for (uint32_t prism : recent) {
        if (!options.hints) break;
        if (prism != kNone && Usable(prism) && hides(prism, v[0]) && hides(prism, v[1]) && hides(prism, v[2])) {
          hider = prism;
          break;
        }
      }
      // A vertex whose every hider is known (a traversal from it went the whole way): the
      // triangle's hider, if any, is one of them. Of such vertices, the one with fewest.
      bool settled = hider != kNone;
      if (!settled) {
        int known = -1;
        for (int k = 0; k < 3; ++k) {
          if (vertex_state[v[k]] == kKnown && (known < 0 || HiderCount(v[k]) < HiderCount(v[known]))) known = k;
        }
        if (known >= 0) {
          settled = true;
          const uint32_t a = v[(known + 1) % 3], b = v[(known + 2) % 3];
          for (uint32_t i = vertex_hiders_start[v[known]], end = i + HiderCount(v[known]); i < end; ++i) {
            const uint32_t prism = vertex_hiders[i];
            if (Usable(prism) && hides(prism, a) && hides(prism, b)) {
              hider = prism;
              break;
            }
          }
        }
      }
      if (!settled) {
        // Traced from a vertex not yet traced, if any: a traversal that finds nothing hiding
        // it alone proves it seen, which settles every other triangle that has it; one that
        // finds no hider of the triangle lists every prism that hides the vertex alone. Of
        // those vertices, the nearest: its segments are the shortest, so Embree proposes
        // fewest prisms.
        int first = 0;
        double best = std::numeric_limits<double>::infinity();
        for (int k = 0; k < 3; ++k) {
          const glm::dvec3& d = rays_of(v[k]).front().d;
          const double key = glm::dot(d, d) + (vertex_state[v[k]] == kTraced ? 1e30 : 0.0);
          if (key < best) best = key, first = k;
        }
        rays.clear();
        for (int k = 0; k < 3; ++k) {
          const std::span<const Ray> r = rays_of(v[(first + k) % 3]);
          rays.insert(rays.end(), r.begin(), r.end());
        }
        const size_t own_rays = rays_of(v[first]).size();
        bool own_hidden = false;
        const auto listed = static_cast<uint32_t>(vertex_hiders.size());
        hider = Trace(rays[0], true, own_rays, &own_hidden, &vertex_hiders);
        if (!own_hidden) {
          vertex_state[v[first]] = kSeen;
        } else if (hider == kNone) {
          // The whole segment was traversed: these are all the vertex's hiders.
          vertex_state[v[first]] = kKnown;
          vertex_hiders_start[v[first]] = listed;
          vertex_hiders_end[v[first]] = static_cast<uint32_t>(vertex_hiders.size());
        } else {
          vertex_state[v[first]] = kTraced;
          vertex_hiders.resize(listed);  // a partial list
        }
        if (hider != kNone) vertex_hider[v[0]] = vertex_hider[v[1]] = vertex_hider[v[2]] = hider;
      }
      stats.rays += rays_of(v[0]).size() + rays_of(v[1]).size() + rays_of(v[2]).size();
      if (hider == kNone) {
        out->push_back(set.TriangleId(object, t));
      } else if (recent[0] != hider) {
        recent[1] = recent[0];
        recent[0] = hider;
      }
    }
  }
  // Per distinct vertex of the object being tested: kSeen when nothing hides it from the box
  // (it lies in the box, or a whole traversal found no prism crossed by all its rays), kTraced
  // when a traversal from it found a prism that hides it alone, kKnown when a traversal from
  // it went the whole segment and so found every prism that hides it alone, listed in
  // vertex_hiders from vertex_hiders_start up to vertex_hiders_end.
  static constexpr uint8_t kUnknown = 0, kTraced = 1, kSeen = 2, kKnown = 3;
  std::vector<uint8_t> vertex_state;
  std::vector<uint32_t> vertex_hiders_start, vertex_hiders_end, vertex_hiders;
  uint32_t HiderCount(uint32_t u) const { return vertex_hiders_end[u] - vertex_hiders_start[u]; }
  std::vector<uint32_t> vertex_hider, vertex_miss, vertex_ray_start;
  std::vector<Ray> vertex_rays;
};

void EpsilonSuperset::IntersectPrisms(const RTCIntersectFunctionNArguments* args) { Query::Intersect(args); }

bool EpsilonSuperset::Crosses(uint32_t i, const glm::dvec3& q, const glm::dvec3& e, const glm::dvec3& d,
                              double* t_in) const {
  // Clip t in [0, 1] to each half-space f0 + t·f1 >= 0 of the shrunk prism (Cyrus-Beck): a
  // constraint with f1 > 0 bounds t from below, f1 < 0 from above, f1 = 0 holds everywhere
  // or nowhere. Branch-free over the walls, which are few.
  const Prism& p = prisms_[i];
  double t0 = 0.0, t1 = 1.0;
  bool ok = true;
  auto clip = [&](double f0, double f1) {
    const double t = -f0 / f1;
    t0 = f1 > 0.0 ? std::max(t0, t) : t0;
    t1 = f1 < 0.0 ? std::min(t1, t) : t1;
    ok &= f1 != 0.0 || f0 >= 0.0;
  };
  // No floor: the ground is solid, so a prism reaches down beneath it (a segment between
  // points above the ground that runs along z = 0 through a footprint passes through the
  // building or the ground, never under the building).
  const double z = q.z + e.z;
  clip(p.height - p.shrink - z, -d.z);
  const Edge* edge = edges_.data() + p.first_edge;
  for (uint32_t k = 0; k < p.edge_count; ++k) {
    const Edge& g = edge[k];
    clip(g.nx * ((q.x - g.ax) + e.x) + g.ny * ((q.y - g.ay) + e.y) - p.shrink, g.nx * d.x + g.ny * d.y);
  }
  *t_in = t0;
  return ok && t0 < t1;
}

EpsilonResult EpsilonSuperset::Compute(const Aabb& box, const EpsilonOptions& options) const {
  std::vector<ObjectId> all(scene_.objects.size());
  for (ObjectId i = 0; i < all.size(); ++i) all[i] = i;
  return Compute(box, options, all);
}

EpsilonResult EpsilonSuperset::Compute(const Aabb& box, const EpsilonOptions& options,
                                       std::span<const ObjectId> objects) const {
  const auto start = std::chrono::steady_clock::now();
  // Embree works in floats relative to the frame: a box that is not finite, inverted, or so
  // far away that its rays would overflow hides nothing (everything is kept: conservative).
  constexpr double kFarM = 1e6;
  bool usable = true;
  for (int k = 0; k < 3; ++k) {
    usable &= std::isfinite(box.min[k]) && std::isfinite(box.max[k]) && box.min[k] <= box.max[k] &&
              std::abs(box.min[k] - frame_[k]) < kFarM && std::abs(box.max[k] - frame_[k]) < kFarM;
  }
  if (!usable) {
    EpsilonResult all;
    for (ObjectId id : objects) {
      const uint32_t n = static_cast<uint32_t>(scene_.objects[id].mesh.TriangleCount());
      for (uint32_t t = 0; t < n; ++t) all.triangles.push_back(TriangleId(id, t));
      if (n > 0) all.objects.push_back(id);
    }
    std::sort(all.triangles.begin(), all.triangles.end());
    std::sort(all.objects.begin(), all.objects.end());
    all.stats.total_triangles = all.stats.visible_triangles = all.triangles.size();
    all.stats.ms = Ms(start);
    return all;
  }
  // Viewpoints stand on or above the ground: the part of the box below it is left out (a box
  // wholly below the ground becomes its footprint on the ground).
  Aabb eye = box;
  eye.min.z = std::max(eye.min.z, 0.0);
  eye.max.z = std::max(eye.max.z, 0.0);
  Query query(*this, options, eye);
  EpsilonStats& st = query.stats;

  // Stage 1: object boxes, nearest first, so that hidden objects stop being occluders
  // before the farther boxes they might otherwise be tried on. With the hierarchy, a kd-tree
  // node's box is tested before its objects: hidden, it hides every object below it.
  std::vector<ObjectId> survivors;
  if (options.boxes) {
    auto hide = [&](ObjectId id, bool first) {
      ++st.occluded_boxes;
      st.first_occluders += first ? 1 : 0;
      if (options.drop_hidden_occluders) query.blocked[id] |= Query::kDropped;
    };
    auto test_object = [&](ObjectId id) {
      bool first = false;
      if (query.BoxHidden(scene_.objects[id].bounds, id, &st.box_ray_tests, &first)) {
        hide(id, first);
      } else {
        survivors.push_back(id);
      }
    };
    if (options.hierarchy) {
      // The scene's tree, or one over the list alone, whose leaves hold positions in it.
      KdTree subset;
      const KdTree* tree = &tree_;
      const bool whole = objects.size() == scene_.objects.size();
      if (!whole) {
        std::vector<Aabb> boxes;
        boxes.reserve(objects.size());
        for (ObjectId id : objects) boxes.push_back(scene_.objects[id].bounds);
        subset = KdTree::Build(boxes);
        tree = &subset;
      }
      auto id_of = [&](ObjectId k) { return whole ? k : objects[k]; };
      if (!tree->empty()) {
        st.total_boxes = tree->root().count;
        const std::vector<KdNode>& nodes = tree->nodes();
        std::vector<uint32_t> stack = {0};
        // A node's box is tested only where that pays: the test costs about what one object's
        // does, and saves `count` of them when the box is hidden. The odds are this query's
        // share of hidden node boxes so far: near the street, over a whole city, many far
        // nodes are hidden; over a viewcell's PVS, few (london: 8%, and under 2% of those
        // above 16 objects). Skipping a test never changes the result: a prism that hides a
        // node's box hides each box in it, which is then found hidden on its own.
        double node_tests = 0.0, nodes_hidden = 0.0;
        while (!stack.empty()) {
          const KdNode& node = nodes[stack.back()];
          stack.pop_back();
          bool first = false;
          const bool worth_testing =
              node.count > 1 && (nodes_hidden + 1.0) * node.count > 0.5 * (node_tests + 2.0);
          if (worth_testing) ++node_tests;
          if (worth_testing && query.BoxHidden(node.bounds, std::nullopt, &st.box_ray_tests, &first)) {
            ++nodes_hidden;
            for (ObjectId k : tree->ObjectsBelow(node)) hide(id_of(k), first);
            continue;
          }
          if (node.IsLeaf()) {
            for (ObjectId k : tree->LeafObjects(node)) test_object(id_of(k));
            continue;
          }
          // Nearer child on top of the stack.
          const bool left_first = BoxDistance2(box, nodes[node.left].bounds) <= BoxDistance2(box, nodes[node.right].bounds);
          stack.push_back(static_cast<uint32_t>(left_first ? node.right : node.left));
          stack.push_back(static_cast<uint32_t>(left_first ? node.left : node.right));
        }
      }
    } else {
      std::vector<std::pair<double, ObjectId>> order;
      order.reserve(objects.size());
      for (ObjectId id : objects) {
        if (!scene_.objects[id].bounds.Empty()) order.emplace_back(BoxDistance2(box, scene_.objects[id].bounds), id);
      }
      std::sort(order.begin(), order.end());
      st.total_boxes = order.size();
      for (const auto& entry : order) test_object(entry.second);
    }
    std::sort(survivors.begin(), survivors.end());
  } else {
    for (ObjectId id : objects) {
      if (!scene_.objects[id].bounds.Empty()) survivors.push_back(id);
    }
  }
  st.box_ms = Ms(start);

  // Stage 2: the triangles of the surviving objects.
  const auto t2 = std::chrono::steady_clock::now();
  EpsilonResult result;
  for (ObjectId id : objects) st.total_triangles += scene_.objects[id].mesh.TriangleCount();
  for (ObjectId id : survivors) {
    const size_t before = result.triangles.size();
    query.VisibleTriangles(id, &st.polygon_ray_tests, &result.triangles);
    if (result.triangles.size() > before) result.objects.push_back(id);
  }
  std::sort(result.triangles.begin(), result.triangles.end());
  st.visible_triangles = result.triangles.size();
  st.polygon_ms = Ms(t2);
  st.ms = Ms(start);
  result.stats = st;
  return result;
}

std::vector<EpsilonResult> EpsilonSuperset::ComputeBatch(std::span<const Aabb> boxes, const EpsilonOptions& options,
                                                         unsigned threads) const {
  std::vector<EpsilonResult> results(boxes.size());
  ParallelFor(boxes.size(), threads, [&] { return [&](size_t i) { results[i] = Compute(boxes[i], options); }; });
  return results;
}

}  // namespace vistream::visibility
