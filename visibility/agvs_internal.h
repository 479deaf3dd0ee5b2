#pragma once
// What the parts of the global sampler share (agvs.cpp, agvs_sampling.cpp, agvs_edit.cpp,
// agvs_state.cpp): the sampler's state (GlobalSampler::Impl) and the helpers it is written
// with. Internal: included by those files and their tests only.

#include <embree3/rtcore.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <unordered_map>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <glm/geometric.hpp>

#include "scenes/progress.h"
#include "scenes/random.h"
#include "scenes/terrain.h"
#include "visibility/agvs_surface.h"
#include "visibility/bytes.h"
#include "visibility/coincident_faces.h"
#include "visibility/kdtree.h"
#include "visibility/parallel.h"
#include "visibility/pvs_file.h"
#include "visibility/silhouette.h"
#include "visibility/viewcell_grid.h"

namespace vistream::visibility {

namespace agvs_detail {

using scenes::ObjectId;
using scenes::Rng;

constexpr uint32_t kChunk = 512;  // samples per chunk: one distribution, one random stream
constexpr ObjectId kNoObject = std::numeric_limits<ObjectId>::max();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kSurfaceOffset = 1e-3;  // metres a ray leaves a surface point before it counts
// Metres within which two faces of opposite orientation coincide, and a hit lies on such a
// face: walls that touch in the source data come a few millimetres apart after rounding to
// float or to a grid (1 mm at 20 km; up to 6 mm where a turned wall's corners snap to 1/256
// m). A ray through a crack narrower than this is discarded, which only makes the sampled
// sets smaller.
constexpr double kCoincidentTolerance = 0.01;
constexpr uint32_t kMaxMutationCount = 63;

inline uint64_t Mix(uint64_t a, uint64_t b) {
  uint64_t z = a * 0x9e3779b97f4a7c15ULL + b + 0x632be59bd9b4e019ULL;
  z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
  z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
  return z ^ (z >> 31);
}

// A uniform point (u, v) of the open unit disk without its centre, and s = u² + v²: by
// rejection from the square (a try is kept with chance π/4), which costs less than the sine
// and cosine of an angle.
struct DiskPoint {
  double u, v, s;
};
inline DiskPoint UniformDiskPoint(Rng& rng) {
  for (;;) {
    const double u = 2.0 * rng.Uniform() - 1.0, v = 2.0 * rng.Uniform() - 1.0, s = u * u + v * v;
    if (s < 1.0 && s > 0.0) return {u, v, s};
  }
}

// A uniform direction of the plane: (cos φ, sin φ) for a uniform angle φ.
inline std::pair<double, double> UniformCircle(Rng& rng) {
  const DiskPoint p = UniformDiskPoint(rng);
  const double r = 1.0 / std::sqrt(p.s);
  return {p.u * r, p.v * r};
}

// A uniform direction of space (Marsaglia 1972: z = 1 - 2s is uniform in (-1, 1)).
inline glm::dvec3 UniformDirection(Rng& rng) {
  const DiskPoint p = UniformDiskPoint(rng);
  const double w = 2.0 * std::sqrt(1.0 - p.s);
  return {p.u * w, p.v * w, 1.0 - 2.0 * p.s};
}

// Two unit vectors completing unit `n` to an orthonormal basis (Duff et al. 2017: no square
// root, no branch on the direction).
inline void Basis(const glm::dvec3& n, glm::dvec3* b1, glm::dvec3* b2) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z), b = n.x * n.y * a;
  *b1 = glm::dvec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
  *b2 = glm::dvec3(b, sign + n.y * n.y * a, -n.y);
}

// Two independent standard normal numbers (Marsaglia's polar method: both of its outputs).
inline std::pair<double, double> Gaussians(Rng& rng) {
  const DiskPoint p = UniformDiskPoint(rng);
  const double f = std::sqrt(-2.0 * std::log(p.s) / p.s);
  return {p.u * f, p.v * f};
}

inline double BoxRadius(const Aabb& b) { return 0.5 * glm::length(b.Extent()); }

using scenes::BoxDistance;

// The part [*a, *b] of the line origin + t dir inside box `vs` (the view space, frame-relative
// metres; dir need not be unit length, t is in its units); false, leaving them unspecified,
// if it misses. Emit's walk and the rays a sample casts decide with this same span.
inline bool ViewSpaceSpan(const Aabb& vs, const glm::dvec3& origin, const glm::dvec3& dir, double* a, double* b) {
  double lo = -kInf, hi = kInf;
  for (int k = 0; k < 3; ++k) {
    if (dir[k] == 0.0) {
      if (origin[k] < vs.min[k] || origin[k] > vs.max[k]) return false;
      continue;
    }
    double t0 = (vs.min[k] - origin[k]) / dir[k], t1 = (vs.max[k] - origin[k]) / dir[k];
    if (t0 > t1) std::swap(t0, t1);
    lo = std::max(lo, t0);
    hi = std::min(hi, t1);
  }
  *a = lo;
  *b = hi;
  return lo <= hi;
}

// The first ray a sample casts (GlobalSampler's CastBoth), for the line origin + t dir whose
// view-space span is [a, b] (ViewSpaceSpan): the ray towards the span (`reverse`: along -dir,
// when the span lies wholly behind the origin), and `reach`, the distance along that ray to
// where the line enters the span, up to which an occlusion query first asks whether anything
// lies before the view space (at most 0, no query, when the origin lies in the span). With
// `whole`, both rays are cast in full: forward first, no query.
struct FirstRay {
  bool reverse = false;
  double reach = 0.0;
};
inline FirstRay FirstRayOf(double a, double b, bool whole) {
  if (whole) return {};
  const bool reverse = b < 0.0;
  return {reverse, reverse ? -b : a};
}

// Calls visit(cell, t) for each viewcell of `grid` the part [t0, t1] of the line origin + t dir
// passes through, with t a parameter inside that cell (its band too, when cells have their
// own), in order along the line; `vs` is the grid's box, frame-relative (the sampler's view space).
template <typename F>
void VisitCells(const ViewcellGrid& grid, const Aabb& vs, const glm::dvec3& origin, const glm::dvec3& dir, double t0,
              double t1, F&& visit) {
  double a = 0.0, b = 0.0;
  if (!ViewSpaceSpan(vs, origin, dir, &a, &b)) return;
  t0 = std::max(t0, a);
  t1 = std::min(t1, b);
  if (!(t0 <= t1)) return;
  const double size = grid.cell_size();
  const glm::dvec3 p = origin + t0 * dir;
  int i = std::clamp(static_cast<int>(std::floor((p.x - vs.min.x) / size)), 0, grid.nx() - 1);
  int j = std::clamp(static_cast<int>(std::floor((p.y - vs.min.y) / size)), 0, grid.ny() - 1);
  const int si = dir.x > 0 ? 1 : (dir.x < 0 ? -1 : 0), sj = dir.y > 0 ? 1 : (dir.y < 0 ? -1 : 0);
  auto next = [&](int s, int idx, double lo, double o, double d) {
    if (s == 0) return kInf;
    const double edge = lo + (s > 0 ? idx + 1 : idx) * size;
    return (edge - o) / d;
  };
  double tx = next(si, i, vs.min.x, origin.x, dir.x), ty = next(sj, j, vs.min.y, origin.y, dir.y);
  const double dtx = si != 0 ? size / std::abs(dir.x) : kInf, dty = sj != 0 ? size / std::abs(dir.y) : kInf;
  double t = t0;
  for (;;) {
    const double exit = std::min({tx, ty, t1});
    if (!grid.has_bands()) {
      visit(grid.Id({i, j}), 0.5 * (t + exit));
    } else {
      // Cells follow the terrain: the line is in this cell only where it is in its band (the
      // frame's z is 0, so bands are frame-relative as they are).
      const CellId id = grid.Id({i, j});
      const CellBand band = grid.Band(id);
      double from = t, to = exit;
      if (dir.z == 0.0) {
        if (origin.z < band.z0 || origin.z > band.z1) from = kInf;
      } else {
        double za = (band.z0 - origin.z) / dir.z, zb = (band.z1 - origin.z) / dir.z;
        if (za > zb) std::swap(za, zb);
        from = std::max(from, za);
        to = std::min(to, zb);
      }
      if (from <= to) visit(id, 0.5 * (from + to));
    }
    if (exit >= t1) return;
    t = exit;
    if (tx <= ty) {
      i += si;
      tx += dtx;
    } else {
      j += sj;
      ty += dty;
    }
    if (i < 0 || j < 0 || i >= grid.nx() || j >= grid.ny()) return;
  }
}

struct Sample {
  glm::dvec3 origin{0.0}, dir{0.0};  // frame-relative; dir is unit length
  double t_fwd = kInf, t_rev = kInf;  // distances to the hits along +dir and -dir
  ObjectId fwd = kNoObject, rev = kNoObject;
  Distribution dist = Distribution::kViewSpaceDirection;
  bool valid = false;
  // Its free segment cannot meet the view space, so it adds nothing; rays left uncast
  // (Worker::CastBoth), and valid, t and the objects are not known.
  bool misses = false;
  CellId origin_cell = 0;  // view space-direction and ref samples
};

struct Candidate {
  ObjectId object = kNoObject;  // first: read ahead of the rest (see Worker::Gather)
  uint32_t mutations = 0;
  glm::dvec3 from{0.0}, to{0.0};  // the segment's origin and the point where `object` was hit
  double r_from = 0.0, r_to = 0.0;  // radii of what lies at each end
};

// The mutation candidates, by how often each was mutated: the least mutated is taken first,
// the most mutated dropped first when full.
class MutationBuffer {
 public:
  explicit MutationBuffer(size_t capacity) : capacity_(capacity), buckets_(kMaxMutationCount + 1) {}

  size_t size() const { return size_; }
  void Add(Candidate c) {
    if (capacity_ == 0) return;
    if (size_ == capacity_) DropMostMutated();
    c.mutations = std::min(c.mutations, kMaxMutationCount);
    uint32_t slot;
    if (!free_.empty()) {
      slot = free_.back();
      free_.pop_back();
      pool_[slot] = c;
    } else {
      slot = static_cast<uint32_t>(pool_.size());
      pool_.push_back(c);
    }
    buckets_[c.mutations].push_back(slot);  // the count lives in the bucket from now on
    lowest_ = std::min<size_t>(lowest_, c.mutations);
    ++size_;
  }
  // Precondition: size() > 0. The slot of a least-mutated candidate (random among equals);
  // its count goes up by one. The slot stays valid until the next Add or Forget.
  uint32_t Take(Rng& rng) {
    while (buckets_[lowest_].empty()) ++lowest_;
    std::vector<uint32_t>& bucket = buckets_[lowest_];
    const size_t i = rng.Below(bucket.size());
    const uint32_t slot = bucket[i];
    bucket[i] = bucket.back();
    bucket.pop_back();
    buckets_[std::min<size_t>(lowest_ + 1, kMaxMutationCount)].push_back(slot);
    return slot;
  }
  const Candidate& At(uint32_t slot) const { return pool_[slot]; }
  // Drops every candidate whose end lies on `object`.
  void Forget(ObjectId object) {
    for (std::vector<uint32_t>& bucket : buckets_) {
      std::erase_if(bucket, [&](uint32_t slot) {
        if (pool_[slot].object != object) return false;
        free_.push_back(slot);
        --size_;
        return true;
      });
    }
  }
  // f(candidate, times mutated).
  template <typename F>
  void ForEach(F&& f) const {
    for (uint32_t b = 0; b < buckets_.size(); ++b) {
      for (uint32_t slot : buckets_[b]) f(pool_[slot], b);
    }
  }

 private:
  void DropMostMutated() {
    for (size_t b = buckets_.size(); b-- > 0;) {
      if (buckets_[b].empty()) continue;
      free_.push_back(buckets_[b].back());
      buckets_[b].pop_back();
      --size_;
      return;
    }
  }
  size_t capacity_;
  size_t size_ = 0, lowest_ = 0;
  std::vector<Candidate> pool_;
  std::vector<uint32_t> free_;
  std::vector<std::vector<uint32_t>> buckets_;
};

struct NewEntry {
  CellId cell;
  ObjectId object;
  uint32_t witness;  // index in its chunk's witnesses, for cells that keep them; else kNoWitness
};
constexpr uint32_t kNoWitness = std::numeric_limits<uint32_t>::max();

struct ChunkPlan {
  Distribution dist;
  std::vector<uint32_t> candidates;  // mutation chunks: one per sample, a slot of the buffer
};

// Valid samples per cell they pierce and per object they end on, one thread's.
struct Counts {
  std::vector<uint64_t> cells, objects;
};

// What a chunk found, in the order its samples were drawn: all the serial part applies.
struct ChunkResult {
  std::vector<NewEntry> entries;
  std::vector<Witness> witnesses;
  std::vector<Candidate> candidates;  // mutation candidates (AGVS), in order
  uint64_t samples = 0;
  uint64_t embree_rays = 0, silhouette_searches = 0, discarded = 0;
  uint64_t contribution = 0;
  uint64_t estimator_rays = 0, estimator_hits = 0;
};

}  // namespace agvs_detail

// The sampler's parts read these as if they were their own.
using namespace agvs_detail;  // NOLINT(google-build-using-namespace): internal header

struct GlobalSampler::Impl {
  struct Object {
    std::vector<glm::vec3> verts;  // frame-relative (for Embree and edits)
    std::vector<uint32_t> indices;
    // From verts and indices, as the silhouette search reads them. Float: drawing samples and
    // searching silhouettes are heuristics; visibility itself is Embree's.
    std::vector<EdgeTriangle> tris;
    FanSurface fan;  // the same, for the silhouette search
    // Embree reads the triangles as quads (PairTriangles): per quad, one word holding its
    // first triangle, whether it has a second, and which of its triangles lie on a coincident
    // face (set by Rebuild). One word, so that a hit reads one cache line to learn all three.
    std::vector<uint32_t> quads;
    static constexpr uint32_t kQuadPair = 1u << 29, kFirstCoincident = 1u << 30, kSecondCoincident = 1u << 31;
    static constexpr uint32_t kMaxTriangles = kQuadPair;  // first triangles below this fit the word
    // The triangle Embree hit: the quad's first (q, r, p) where u + v <= 1, its second
    // (s, p, r) beyond.
    static uint32_t TriangleOfWord(uint32_t quad_word, bool second) {
      return (quad_word & (kQuadPair - 1)) + ((quad_word & kQuadPair) != 0 && second ? 1 : 0);
    }
    uint32_t TriangleOf(uint32_t quad, bool second) const { return TriangleOfWord(quads[quad], second); }
    // Whether that triangle lies on a face of opposite orientation (CoincidentFaces).
    static bool HitsCoincident(uint32_t quad_word, bool second) {
      return (quad_word & ((quad_word & kQuadPair) != 0 && second ? kSecondCoincident : kFirstCoincident)) != 0;
    }
    double area = 0.0;
    Aabb bounds;                   // frame-relative, from verts
    double radius = 0.0;
    bool alive = true;
    // An object of more than AgvsOptions::discovery_triangles triangles, alone in its own Embree scene: its
    // silhouettes are searched with discovery rays (the paper's way, logarithmic in its size)
    // rather than by reading every triangle the fan's plane cuts (which, for a ring of thin
    // roof triangles, is most of them). Owned by Impl; null for the others.
    RTCScene alone = nullptr;
  };
  std::vector<Object> objects;
  // Where surface points are drawn (agvs_surface.h): from a uniform alive object with
  // surface area, then uniformly on its surface.
  SurfaceTable surface;
  glm::dvec3 frame{0.0};             // scene-local position of the frame's origin
  Aabb view_space;                   // frame-relative
  // The scene's terrain, solid beneath its surface: a free segment below it is not a view
  // (it never crosses the surface, so its origin tells). Null without terrain.
  std::shared_ptr<const scenes::TerrainHeight> terrain;
  double cell_radius = 0.0;

  size_t discovery_triangles = 2048;  // AgvsOptions::discovery_triangles
  RTCDevice device = nullptr;
  RTCScene rtc = nullptr;
  bool dirty = false;  // edits not yet committed

  MutationBuffer buffer{0};
  std::array<double, kDistributionCount> ema_contribution{}, ema_cost{};
  std::array<double, kDistributionCount> probability{};
  std::vector<std::pair<uint64_t, uint64_t>> estimator_window;  // per batch: rays, new-entry rays
  double estimate_target_pixels = 1.0;  // the error the estimator's window is sized to tell
  std::vector<uint64_t> cell_samples;  // valid samples that pierced each cell
  std::vector<uint64_t> object_hits;   // valid sample ends on each object

  std::vector<bool> witness_cell;
  std::unordered_map<uint64_t, Witness> witnesses;  // key: cell << 32 | object

  KdTree tree;  // over the boxes of live objects, for the object-space filter

  // Faces that lie on a face of opposite orientation (party walls, a tier's floor on the roof
  // below it), and per object its quad words (Object::quads) if it has one, else null: a hit
  // on an object without reads nothing more, one on an object with reads one word to learn
  // whether its triangle has a partner. A ray reaches such a face only from inside the solid
  // behind its partner, but Embree may report the partner's front face: the ray's sample is
  // discarded like one that hits a back face.
  CoincidentFaces coincident;
  PartnerLookup partners;  // over `coincident`
  std::vector<const uint32_t*> coincident_quads;

  // The surface table, the kd-tree and the coincident faces, rebuilt after every edit, never
  // lazily, so that const calls stay thread-safe.
  void Rebuild() {
    RebuildSurface();
    std::vector<Aabb> boxes(objects.size());
    std::vector<MeshView> meshes(objects.size());
    for (ObjectId o = 0; o < objects.size(); ++o) {
      if (!objects[o].alive) continue;
      boxes[o] = objects[o].bounds;
      meshes[o] = MeshView{objects[o].verts, objects[o].indices};
    }
    tree = KdTree::Build(boxes);
    coincident = FindCoincidentFaces(meshes, kCoincidentTolerance);
    partners = PartnerLookup(coincident, std::move(meshes));
    coincident_quads.assign(objects.size(), nullptr);
    for (ObjectId o = 0; o < objects.size(); ++o) {
      std::vector<uint32_t>& q = objects[o].quads;
      for (uint32_t& w : q) w &= ~(Object::kFirstCoincident | Object::kSecondCoincident);
      if (coincident.of_mesh[o].empty() || q.empty()) continue;
      for (const CoincidentFaces::Entry& e : coincident.of_mesh[o]) {
        // The quad holding triangle e.triangle: the last whose first triangle is not past it.
        const auto it = std::upper_bound(q.begin(), q.end(), e.triangle, [](uint32_t t, uint32_t w) {
          return t < (w & (Object::kQuadPair - 1));
        });
        if (it == q.begin()) continue;
        uint32_t& w = *(it - 1);
        w |= e.triangle == (w & (Object::kQuadPair - 1)) ? Object::kFirstCoincident : Object::kSecondCoincident;
      }
      coincident_quads[o] = q.data();
    }
  }

  // Whether frame-relative point `p` on triangle `triangle` of `object` also lies on a face of
  // opposite orientation lying on that triangle.
  bool OnCoincidentFace(ObjectId object, uint32_t triangle, const glm::dvec3& p) const {
    return partners.OnPartner(object, triangle, p, kCoincidentTolerance);
  }

  ~Impl() {
    for (Object& o : objects) ReleaseAlone(&o);
    if (rtc != nullptr) rtcReleaseScene(rtc);
    if (device != nullptr) rtcReleaseDevice(device);
  }

  void Attach(ObjectId id) {
    Object& o = objects[id];
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_QUAD);
    auto* v = static_cast<float*>(
        rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), o.verts.size()));
    for (size_t i = 0; i < o.verts.size(); ++i) {
      v[3 * i] = o.verts[i].x;
      v[3 * i + 1] = o.verts[i].y;
      v[3 * i + 2] = o.verts[i].z;
    }
    EmbreeQuads q = PairTriangles(o.indices);
    o.quads.resize(q.first.size());
    for (size_t i = 0; i < q.first.size(); ++i) o.quads[i] = q.first[i] | (q.pair[i] ? Object::kQuadPair : 0u);
    const std::vector<uint32_t>& quads = q.indices;
    auto* ix = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4,
                                                              4 * sizeof(uint32_t), quads.size() / 4));
    std::copy(quads.begin(), quads.end(), ix);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(rtc, g, id);
    ReleaseAlone(&o);
    if (o.indices.size() / 3 > discovery_triangles) {
      // Embree lets one geometry belong to several scenes.
      o.alone = rtcNewScene(device);
      rtcSetSceneFlags(o.alone, RTC_SCENE_FLAG_ROBUST);
      rtcAttachGeometry(o.alone, g);
      rtcCommitScene(o.alone);
    }
    rtcReleaseGeometry(g);
    dirty = true;
  }
  static void ReleaseAlone(Object* o) {
    if (o->alone != nullptr) rtcReleaseScene(o->alone);
    o->alone = nullptr;
  }
  void Commit() {
    if (!dirty) return;
    rtcCommitScene(rtc);
    dirty = false;
  }
  void RebuildSurface() {
    std::vector<std::span<const EdgeTriangle>> tris(objects.size());
    for (ObjectId id = 0; id < objects.size(); ++id) {
      if (objects[id].alive && objects[id].area > 0.0) tris[id] = objects[id].tris;
    }
    surface = SurfaceTable(tris);
  }

  static void BuildTris(Object* o) {
    o->tris.clear();
    double sum = 0.0;
    for (size_t t = 0; t + 2 < o->indices.size(); t += 3) {
      const glm::vec3 a = o->verts[o->indices[t]], b = o->verts[o->indices[t + 1]], c = o->verts[o->indices[t + 2]];
      sum += 0.5 * glm::length(glm::cross(glm::dvec3(b) - glm::dvec3(a), glm::dvec3(c) - glm::dvec3(a)));
      o->tris.push_back({a, b - a, c - a});
    }
    o->area = sum;
    o->fan = FanSurface(o->verts, o->indices);
  }

  // Fills `o` from scene-local positions; false if a position is not finite, an index is out
  // of range or the mesh has 2^29 triangles or more.
  bool MakeObject(const scenes::Mesh& mesh, Object* o) const {
    o->verts.clear();
    o->bounds = Aabb{};
    for (const glm::vec3& p : mesh.positions) {
      const glm::dvec3 q = glm::dvec3(p) - frame;
      if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z)) return false;
      o->verts.emplace_back(q);
      o->bounds.Extend(glm::dvec3(o->verts.back()));
    }
    for (uint32_t i : mesh.indices) {
      if (i >= mesh.positions.size()) return false;
    }
    if (mesh.indices.size() / 3 >= Object::kMaxTriangles) return false;  // Object::quads holds 29 bits
    o->indices.assign(mesh.indices.begin(), mesh.indices.end() - mesh.indices.size() % 3);
    BuildTris(o);
    o->radius = BoxRadius(o->bounds);
    o->alive = true;
    return true;
  }
};

namespace agvs_detail {
// Updates the pixel-error estimate from the sampler's window of camera rays (agvs.cpp).
void UpdateEstimate(const GlobalSampler::Impl& m, const AgvsOptions& options, AgvsStats* stats);

// A batch's mixture (the paper's section 4.2): the distributions it draws from, each one's
// share (contribution per ray over the last batches, floored at options.min_probability) and
// its number of chunks out of the batch's (at least one each).
struct Mixture {
  std::vector<Distribution> available;
  std::array<double, kDistributionCount> share{};
  std::vector<uint32_t> quota;  // by Distribution
};
Mixture PlanMixture(const GlobalSampler::Impl& m, const AgvsOptions& options);
}  // namespace agvs_detail

}  // namespace vistream::visibility
