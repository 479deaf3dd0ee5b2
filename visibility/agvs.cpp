#include "visibility/agvs.h"

#include <embree3/rtcore.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <mutex>
#include <optional>
#include <unordered_map>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <glm/geometric.hpp>

#include "scenes/progress.h"
#include "scenes/random.h"
#include "visibility/bytes.h"
#include "visibility/coincident_faces.h"
#include "visibility/kdtree.h"
#include "visibility/parallel.h"
#include "visibility/pvs_file.h"
#include "visibility/silhouette.h"

namespace vistream::visibility {

namespace {

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

uint64_t Mix(uint64_t a, uint64_t b) {
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
DiskPoint UniformDiskPoint(Rng& rng) {
  for (;;) {
    const double u = 2.0 * rng.Uniform() - 1.0, v = 2.0 * rng.Uniform() - 1.0, s = u * u + v * v;
    if (s < 1.0 && s > 0.0) return {u, v, s};
  }
}

// A uniform direction of the plane: (cos φ, sin φ) for a uniform angle φ.
std::pair<double, double> UniformCircle(Rng& rng) {
  const DiskPoint p = UniformDiskPoint(rng);
  const double r = 1.0 / std::sqrt(p.s);
  return {p.u * r, p.v * r};
}

// A uniform direction of space (Marsaglia 1972: z = 1 - 2s is uniform in (-1, 1)).
glm::dvec3 UniformDirection(Rng& rng) {
  const DiskPoint p = UniformDiskPoint(rng);
  const double w = 2.0 * std::sqrt(1.0 - p.s);
  return {p.u * w, p.v * w, 1.0 - 2.0 * p.s};
}

// Two unit vectors completing unit `n` to an orthonormal basis (Duff et al. 2017: no square
// root, no branch on the direction).
void Basis(const glm::dvec3& n, glm::dvec3* b1, glm::dvec3* b2) {
  const double sign = std::copysign(1.0, n.z);
  const double a = -1.0 / (sign + n.z), b = n.x * n.y * a;
  *b1 = glm::dvec3(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
  *b2 = glm::dvec3(b, sign + n.y * n.y * a, -n.y);
}

// Two independent standard normal numbers (Marsaglia's polar method: both of its outputs).
std::pair<double, double> Gaussians(Rng& rng) {
  const DiskPoint p = UniformDiskPoint(rng);
  const double f = std::sqrt(-2.0 * std::log(p.s) / p.s);
  return {p.u * f, p.v * f};
}

double BoxRadius(const Aabb& b) { return 0.5 * glm::length(b.Extent()); }

double BoxDistance(const Aabb& a, const Aabb& b) {
  double s = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double gap = std::max({0.0, a.min[k] - b.max[k], b.min[k] - a.max[k]});
    s += gap * gap;
  }
  return std::sqrt(s);
}

struct Sample {
  glm::dvec3 origin{0.0}, dir{0.0};  // frame-relative; dir is unit length
  double t_fwd = kInf, t_rev = kInf;  // distances to the hits along +dir and -dir
  ObjectId fwd = kNoObject, rev = kNoObject;
  Distribution dist = Distribution::kViewSpaceDirection;
  bool valid = false;
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

}  // namespace

const char* StrategyName(SamplingStrategy s) {
  switch (s) {
    case SamplingStrategy::kAgvs: return "agvs";
    case SamplingStrategy::kSgvs: return "sgvs";
    case SamplingStrategy::kRef: return "ref";
  }
  return "?";
}

absl::StatusOr<SamplingStrategy> StrategyFromName(std::string_view name) {
  for (SamplingStrategy s : {SamplingStrategy::kAgvs, SamplingStrategy::kSgvs, SamplingStrategy::kRef}) {
    if (name == StrategyName(s)) return s;
  }
  return absl::InvalidArgumentError(absl::StrCat("unknown sampling strategy '", std::string(name), "' (agvs, sgvs or ref)"));
}

const char* DistributionName(Distribution d) {
  switch (d) {
    case Distribution::kViewSpaceDirection: return "view_space_direction";
    case Distribution::kObjectDirection: return "object_direction";
    case Distribution::kTwoPoint: return "two_point";
    case Distribution::kTwoPointMutation: return "two_point_mutation";
    case Distribution::kSilhouetteMutation: return "silhouette_mutation";
    case Distribution::kRef: return "ref";
  }
  return "?";
}

bool BoxMeetsShaft(const Aabb& a, const Aabb& b, const Aabb& c) {
  // hull(A ∪ B) is the union over t in [0, 1] of the boxes (1 - t) A + t B; each axis bounds t
  // by two linear inequalities.
  double lo = 0.0, hi = 1.0;
  auto need = [&](double f0, double f1) {  // f0 + t f1 <= 0
    if (f1 == 0.0) {
      if (f0 > 0.0) hi = -1.0;
      return;
    }
    const double t = -f0 / f1;
    if (f1 > 0.0) hi = std::min(hi, t);
    else lo = std::max(lo, t);
  };
  for (int k = 0; k < 3; ++k) {
    // (1 - t) a.min + t b.min <= c.max and (1 - t) a.max + t b.max >= c.min.
    need(a.min[k] - c.max[k], b.min[k] - a.min[k]);
    need(c.min[k] - a.max[k], a.max[k] - b.max[k]);
  }
  return lo <= hi;
}

EmbreeQuads PairTriangles(std::span<const uint32_t> indices) {
  EmbreeQuads q;
  const size_t triangles = indices.size() / 3;
  for (size_t t = 0; t < triangles;) {
    const uint32_t* a = &indices[3 * t];
    q.first.push_back(static_cast<uint32_t>(t));
    if (t + 1 < triangles && a[3] == a[0] && a[4] == a[2]) {
      q.indices.insert(q.indices.end(), {a[1], a[2], a[5], a[0]});
      q.pair.push_back(true);
      t += 2;
    } else {
      q.indices.insert(q.indices.end(), {a[0], a[1], a[2], a[2]});
      q.pair.push_back(false);
      t += 1;
    }
  }
  return q;
}

// --- The sampler's state beyond the header. ---

struct GlobalSampler::Impl {
  struct Object {
    std::vector<glm::vec3> verts;  // frame-relative (for Embree and edits)
    std::vector<uint32_t> indices;
    // From verts and indices, as the silhouette search reads them. Float: drawing samples and
    // searching silhouettes are heuristics; visibility itself is Embree's.
    std::vector<EdgeTriangle> tris;
    FanSurface fan;  // the same, for the silhouette search
    // Embree reads the triangles as quads (PairTriangles): each quad's first triangle, and
    // whether it has a second.
    std::vector<uint32_t> quad_first;
    std::vector<bool> quad_pair;
    // The triangle Embree hit: the quad's first (q, r, p) where u + v <= 1, its second
    // (s, p, r) beyond.
    uint32_t TriangleOf(uint32_t quad, bool second) const {
      return quad_first[quad] + (quad_pair[quad] && second ? 1 : 0);
    }
    double area = 0.0;
    Aabb bounds;                   // frame-relative, from verts
    double radius = 0.0;
    bool alive = true;
  };
  std::vector<Object> objects;
  // Surface points are drawn from a uniform alive object with surface area, then uniformly on
  // its surface: as one choice of a triangle, from Walker's alias table over every triangle of
  // those objects (one or two cache misses a point, where a search per object took several).
  struct SurfaceEntry {
    EdgeTriangle tri;
    float keep;      // the chance to keep this triangle rather than take its alias
    uint32_t alias;  // index into `surface`
    ObjectId object;
  };
  std::vector<SurfaceEntry> surface;
  glm::dvec3 frame{0.0};             // scene-local position of the frame's origin
  Aabb view_space;                   // frame-relative
  double cell_radius = 0.0;

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
  // below it), and per object whether it has one. A ray reaches such a face only from inside
  // the solid behind its partner, but Embree may report the partner's front face: the ray's
  // sample is discarded like one that hits a back face.
  CoincidentFaces coincident;
  std::vector<uint8_t> has_coincident;

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
    has_coincident.assign(objects.size(), 0);
    for (ObjectId o = 0; o < objects.size(); ++o) has_coincident[o] = !coincident.of_mesh[o].empty();
  }

  // Whether frame-relative point `p` on triangle `triangle` of `object` also lies on a face of
  // opposite orientation lying on that triangle.
  bool OnCoincidentFace(ObjectId object, uint32_t triangle, const glm::dvec3& p) const {
    for (const CoincidentFaces::Entry& e : coincident.Partners(object, triangle)) {
      const Object& o = objects[e.partner.mesh];
      const uint32_t* t = &o.indices[3 * e.partner.triangle];
      if (PointOnTriangle(p, glm::dvec3(o.verts[t[0]]), glm::dvec3(o.verts[t[1]]), glm::dvec3(o.verts[t[2]]),
                          kCoincidentTolerance)) {
        return true;
      }
    }
    return false;
  }

  ~Impl() {
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
    o.quad_first = std::move(q.first);
    o.quad_pair = std::move(q.pair);
    const std::vector<uint32_t>& quads = q.indices;
    auto* ix = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4,
                                                              4 * sizeof(uint32_t), quads.size() / 4));
    std::copy(quads.begin(), quads.end(), ix);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(rtc, g, id);
    rtcReleaseGeometry(g);
    dirty = true;
  }
  void Commit() {
    if (!dirty) return;
    rtcCommitScene(rtc);
    dirty = false;
  }
  // Vose's construction of the alias table.
  void RebuildSurface() {
    surface.clear();
    std::vector<double> weight;
    size_t sampleable = 0;
    for (ObjectId id = 0; id < objects.size(); ++id) {
      const Object& o = objects[id];
      if (!o.alive || !(o.area > 0.0)) continue;
      ++sampleable;
      const size_t first = weight.size();
      double sum = 0.0;
      for (const EdgeTriangle& t : o.tris) {
        surface.push_back({t, 1.0f, static_cast<uint32_t>(surface.size()), id});
        weight.push_back(glm::length(glm::cross(glm::dvec3(t.e1), glm::dvec3(t.e2))));
        sum += weight.back();
      }
      if (!(sum > 0.0)) {  // area too small for the float edges to show
        surface.resize(first);
        weight.resize(first);
        --sampleable;
        continue;
      }
      for (size_t i = first; i < weight.size(); ++i) weight[i] /= sum;
    }
    // Scaled so that the mean weight is 1: each object's triangles sum to n / objects.
    const double scale = static_cast<double>(surface.size()) / static_cast<double>(std::max<size_t>(sampleable, 1));
    std::vector<uint32_t> small, large;
    for (uint32_t i = 0; i < surface.size(); ++i) {
      weight[i] *= scale;
      (weight[i] < 1.0 ? small : large).push_back(i);
    }
    while (!small.empty() && !large.empty()) {
      const uint32_t s = small.back(), l = large.back();
      small.pop_back();
      surface[s].keep = static_cast<float>(weight[s]);
      surface[s].alias = l;
      weight[l] -= 1.0 - weight[s];
      if (weight[l] < 1.0) {
        large.pop_back();
        small.push_back(l);
      }
    }
    // What is left holds weight 1 up to rounding: always kept.
    for (uint32_t i : small) surface[i].keep = 1.0f;
    for (uint32_t i : large) surface[i].keep = 1.0f;
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

  // Fills `o` from scene-local positions; false if a position is not finite or an index is
  // out of range.
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
    o->indices.assign(mesh.indices.begin(), mesh.indices.end() - mesh.indices.size() % 3);
    BuildTris(o);
    o->radius = BoxRadius(o->bounds);
    o->alive = true;
    return true;
  }
};

// --- Drawing and casting samples (read-only on the sampler; one per thread). ---

namespace {

class Worker {
 public:
  using Impl = GlobalSampler::Impl;
  Worker(const Impl& impl, const ViewcellGrid& grid, const GlobalPvs& pvs, const AgvsOptions& options)
      : s_(impl), grid_(grid), pvs_(pvs), options_(options) {}

  // See GlobalSampler::SampleFromBox.
  std::vector<BoxHit> FromBox(const Aabb& box, size_t rays, uint64_t seed) {
    Rng rng(seed);
    ChunkResult scratch;
    out_ = &scratch;
    std::vector<BoxHit> hits;
    const glm::dvec3 lo = box.min - s_.frame, ext = box.Extent();
    for (size_t i = 0; i < rays; ++i) {
      const glm::dvec3 p = lo + glm::dvec3(rng.Uniform() * ext.x, rng.Uniform() * ext.y, rng.Uniform() * ext.z);
      glm::dvec3 dir;
      if (i % 2 == 0 || s_.surface.empty()) {
        dir = UniformDirection(rng);
      } else {
        glm::dvec3 n;
        ObjectId o;
        const glm::dvec3 q = SurfacePoint(rng, &o, &n) - p;
        const double len = glm::length(q);
        if (!(len > 0.0)) continue;
        dir = q / len;
      }
      const Hit h = Cast(p, dir, 0.0);
      if (h.object == kNoObject || h.back) continue;
      const uint32_t triangle = s_.objects[h.object].TriangleOf(h.quad, h.second);
      hits.push_back({h.object, triangle, s_.frame + p, s_.frame + p + h.t * dir});
    }
    return hits;
  }

  void Run(const ChunkPlan& plan, uint64_t seed, ChunkResult* out) {
    Rng rng(seed);
    out_ = out;
    if (!plan.candidates.empty()) Gather(plan);
    for (uint32_t i = 0; i < kChunk; ++i) {
      switch (plan.dist) {
        case Distribution::kViewSpaceDirection: {
          Sample smp;
          smp.dist = plan.dist;
          smp.origin = ViewSpacePoint(rng, &smp.origin_cell);
          smp.dir = UniformDirection(rng);
          CastBoth(&smp, 0.0);
          Emit(smp);
          break;
        }
        case Distribution::kRef: {
          Sample smp;
          smp.dist = plan.dist;
          smp.origin = ViewSpacePoint(rng, &smp.origin_cell);
          smp.dir = UniformDirection(rng);
          Hit h = Cast(smp.origin, smp.dir, 0.0);
          smp.valid = !h.back;
          smp.t_fwd = h.t;
          smp.fwd = h.object;
          smp.t_rev = 0.0;
          Emit(smp);
          break;
        }
        case Distribution::kObjectDirection: {
          if (s_.surface.empty()) break;
          glm::dvec3 n;
          ObjectId o;
          const glm::dvec3 p = SurfacePoint(rng, &o, &n);
          glm::dvec3 b1, b2;
          Basis(n, &b1, &b2);
          const auto [cos_phi, sin_phi] = UniformCircle(rng);
          const double cos_t = std::sqrt(rng.Uniform()), sin_t = std::sqrt(std::max(0.0, 1.0 - cos_t * cos_t));
          Sample smp;
          smp.dist = plan.dist;
          smp.origin = p;
          smp.dir = sin_t * cos_phi * b1 + sin_t * sin_phi * b2 + cos_t * n;
          const Hit h = Cast(p, smp.dir, kSurfaceOffset);
          smp.valid = !h.back;
          smp.t_fwd = h.t;
          smp.fwd = h.object;
          smp.t_rev = 0.0;
          smp.rev = o;
          Emit(smp);
          break;
        }
        case Distribution::kTwoPoint: {
          if (s_.surface.empty()) break;
          CellId cell;
          const glm::dvec3 v = ViewSpacePoint(rng, &cell);
          glm::dvec3 n;
          ObjectId o;
          const glm::dvec3 p = SurfacePoint(rng, &o, &n);
          EmitSegment(v, p, plan.dist);
          break;
        }
        case Distribution::kTwoPointMutation: {
          const Candidate& c = candidates_[i];
          const double len = glm::length(c.to - c.from);  // positive: see add_candidate in Emit
          const glm::dvec3 u = (c.to - c.from) / len;
          glm::dvec3 b1, b2;
          Basis(u, &b1, &b2);
          const auto [g1, g2] = Gaussians(rng);
          const auto [g3, g4] = Gaussians(rng);
          const glm::dvec3 from = c.from + c.r_from * (g1 * b1 + g2 * b2);
          const glm::dvec3 to = c.to + c.r_to * (g3 * b1 + g4 * b2);
          EmitSegment(from, to, plan.dist);
          break;
        }
        case Distribution::kSilhouetteMutation: {
          // The next candidate's object's surface (where it lies was gathered with the candidates).
          if (i + 1 < kChunk) FanSurface::Prefetch(fans_[i + 1]);
          const Candidate& c = candidates_[i];
          const glm::dvec3 to = Silhouette(c.from, c.to, c.r_to, c.object, rng);
          const Sample smp = EmitSegment(c.from, to, plan.dist);
          if (!smp.valid || smp.fwd == kNoObject) break;
          // A depth discontinuity behind the silhouette: search the silhouette again from the
          // far hit point back towards the view space (the reverse sampling of GVS).
          const glm::dvec3 hit = smp.origin + smp.t_fwd * smp.dir;
          if (glm::length(hit - to) > options_.depth_discontinuity_k * c.r_to) {
            const glm::dvec3 back = Silhouette(hit, to, c.r_to, c.object, rng);
            EmitSegment(hit, back, plan.dist);
          }
          break;
        }
      }
    }
  }

 private:
  // The chunk's candidates, and where their objects' surfaces are, copied in one loop before
  // the samples: they lie scattered in memory, and a loop of independent loads waits for many
  // cache misses at once where the samples would wait for each in turn.
  void Gather(const ChunkPlan& plan) {
    candidates_.resize(plan.candidates.size());
    for (size_t i = 0; i < plan.candidates.size(); ++i) candidates_[i] = s_.buffer.At(plan.candidates[i]);
    fans_.resize(plan.candidates.size());
    for (size_t i = 0; i < plan.candidates.size(); ++i) {
      const ObjectId o = candidates_[i].object;
      fans_[i] = o < s_.objects.size() ? s_.objects[o].fan.hot() : FanSurface::Hot{};
    }
  }

  struct Hit {
    double t = kInf;
    ObjectId object = kNoObject;
    uint32_t quad = 0;    // Embree's primitive
    bool second = false;  // in the quad's second triangle
    bool back = false;
  };

  glm::dvec3 ViewSpacePoint(Rng& rng, CellId* cell) {
    const CellId c = static_cast<CellId>(rng.Below(grid_.CellCount()));
    const Aabb box = grid_.CellBox(c);
    const glm::dvec3 lo = box.min - s_.frame, ext = box.Extent();
    *cell = c;
    return lo + glm::dvec3(rng.Uniform() * ext.x, rng.Uniform() * ext.y, rng.Uniform() * ext.z);
  }

  // Precondition: the alias table is not empty.
  glm::dvec3 SurfacePoint(Rng& rng, ObjectId* id, glm::dvec3* normal) {
    // One uniform picks the column and, with its fraction, whether to keep it.
    const double x = rng.Uniform() * static_cast<double>(s_.surface.size());
    const size_t column = std::min(static_cast<size_t>(x), s_.surface.size() - 1);
    const Impl::SurfaceEntry* e = &s_.surface[column];
    if (x - static_cast<double>(column) >= e->keep) e = &s_.surface[e->alias];
    *id = e->object;
    const glm::dvec3 a(e->tri.a), e1(e->tri.e1), e2(e->tri.e2);
    double u = rng.Uniform(), v = rng.Uniform();
    if (u + v > 1.0) {
      u = 1.0 - u;
      v = 1.0 - v;
    }
    const glm::dvec3 n = glm::cross(e1, e2);
    const double len = glm::length(n);
    *normal = len > 0.0 ? n / len : glm::dvec3(0, 0, 1);
    return a + u * e1 + v * e2;
  }

  Hit Cast(const glm::dvec3& origin, const glm::dvec3& dir, double tnear) {
    RTCIntersectContext ctx;
    rtcInitIntersectContext(&ctx);
    RTCRayHit rh;
    rh.ray.org_x = static_cast<float>(origin.x);
    rh.ray.org_y = static_cast<float>(origin.y);
    rh.ray.org_z = static_cast<float>(origin.z);
    rh.ray.dir_x = static_cast<float>(dir.x);
    rh.ray.dir_y = static_cast<float>(dir.y);
    rh.ray.dir_z = static_cast<float>(dir.z);
    rh.ray.tnear = static_cast<float>(tnear);
    if (!std::isfinite(rh.ray.org_x + rh.ray.org_y + rh.ray.org_z + rh.ray.dir_x + rh.ray.dir_y + rh.ray.dir_z)) {
      Hit bad;
      bad.back = true;  // discarded, as a ray Embree cannot take
      return bad;
    }
    rh.ray.tfar = std::numeric_limits<float>::infinity();
    rh.ray.mask = ~0u;
    rh.ray.flags = 0;
    rh.ray.time = 0.0f;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(s_.rtc, &ctx, &rh);
    ++out_->embree_rays;
    Hit h;
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return h;
    h.t = rh.ray.tfar;
    h.object = rh.hit.geomID;
    h.quad = rh.hit.primID;
    h.second = rh.hit.u + rh.hit.v > 1.0f;
    // Embree's geometry normal is cross(v1 - v0, v2 - v0), as the meshes' outward normals are
    // (counter-clockwise seen from outside); reading it here saves a cache miss per ray.
    h.back = options_.backface_rule && rh.hit.Ng_x * dir.x + rh.hit.Ng_y * dir.y + rh.hit.Ng_z * dir.z > 0.0;
    if (options_.backface_rule && !h.back && s_.has_coincident[h.object]) {
      const uint32_t triangle = s_.objects[h.object].TriangleOf(h.quad, h.second);
      h.back = s_.OnCoincidentFace(h.object, triangle, origin + static_cast<double>(h.t) * dir);
    }
    return h;
  }

  void CastBoth(Sample* smp, double tnear) {
    const Hit f = Cast(smp->origin, smp->dir, tnear);
    if (f.back) {
      // Starts inside a solid: discarded whatever the other way holds, so that ray is not cast.
      smp->valid = false;
      smp->t_fwd = f.t;
      smp->fwd = f.object;
      return;
    }
    const Hit r = Cast(smp->origin, -smp->dir, tnear);
    smp->valid = !r.back;
    smp->t_fwd = f.t;
    smp->fwd = f.object;
    smp->t_rev = r.t;
    smp->rev = r.object;
  }

  // The sample on the line from `a` to `b`, cast both ways from their midpoint.
  Sample EmitSegment(const glm::dvec3& a, const glm::dvec3& b, Distribution dist) {
    Sample smp;
    smp.dist = dist;
    const glm::dvec3 d = b - a;
    const double len = glm::length(d);
    smp.origin = 0.5 * (a + b);
    smp.dir = len > 0.0 && std::isfinite(len) ? d / len : glm::dvec3(0, 0, 1);
    CastBoth(&smp, 0.0);
    Emit(smp);
    return smp;
  }

  // The point near `to`, just off `object`'s silhouette seen from `from`, along a random
  // direction in the plane through `to` normal to the segment (SilhouetteLambda: exact, where
  // the paper searches with discovery rays); `to` + radius along it when there is none.
  glm::dvec3 Silhouette(const glm::dvec3& from, const glm::dvec3& to, double radius, ObjectId object, Rng& rng) {
    const glm::dvec3 seg = to - from;
    const double len = glm::length(seg);
    if (!(len > 0.0) || object >= s_.objects.size()) return to;
    glm::dvec3 b1, b2;
    Basis(seg / len, &b1, &b2);
    const auto [cos_phi, sin_phi] = UniformCircle(rng);
    const glm::dvec3 d = cos_phi * b1 + sin_phi * b2;
    const glm::dvec3 far = to + radius * d;
    if (!s_.objects[object].alive || !(radius > 0.0)) return far;
    ++out_->silhouette_searches;
    const std::optional<double> lambda = SilhouetteLambda({from, to, d, radius}, s_.objects[object].fan, &fan_);
    if (!lambda) return far;
    // Just past the silhouette, on the side of the rays that miss, by as much as the paper's
    // quaternary search of depth 3 leaves (a 64th of the radius), at random.
    return to + (*lambda + (1.0 - rng.Uniform()) / 64.0) * radius * d;
  }

  // Walks the viewcells the sample's free segment pierces and records what is new in them,
  // how often its cells and objects were sampled, and (AGVS) its mutation candidates.
  void Emit(const Sample& smp) {
    ChunkResult& out = *out_;
    ++out.samples;
    if (!smp.valid) {
      ++out.discarded;
      return;
    }
    if (counts_ != nullptr) {
      // Per-object sampling densities, for the object-space filter.
      if (smp.rev != kNoObject && smp.dist != Distribution::kRef) ++counts_->objects[smp.rev];
      if (smp.fwd != kNoObject) ++counts_->objects[smp.fwd];
    }
    if (smp.dist == Distribution::kRef) {
      if (counts_ != nullptr) ++counts_->cells[smp.origin_cell];
      // A ref ray is a camera ray too: a uniform point and direction in a uniform cell.
      ++out.estimator_rays;
      if (smp.fwd != kNoObject && !pvs_.Contains(smp.origin_cell, smp.fwd)) {
        ++out.estimator_hits;
        out.entries.push_back({smp.origin_cell, smp.fwd, WitnessOf(smp.origin_cell, smp, 0.0, smp.t_fwd)});
        ++out.contribution;
      }
      return;
    }
    if (smp.dist == Distribution::kViewSpaceDirection) {
      // The estimator's camera rays: each direction from a uniform point is one.
      out.estimator_rays += 2;
      out.estimator_hits += (smp.fwd != kNoObject && !pvs_.Contains(smp.origin_cell, smp.fwd)) +
                            (smp.rev != kNoObject && !pvs_.Contains(smp.origin_cell, smp.rev));
    }
    uint32_t c_fwd = 0, c_rev = 0;
    double t_first = 0.0, t_last = 0.0;  // the first and last cell's points along the segment
    bool walked = false;
    VisitCells(smp.origin, smp.dir, -smp.t_rev, smp.t_fwd, [&](CellId cell, double t) {
      if (!walked) t_first = t;
      t_last = t;
      walked = true;
      // Every valid segment counts towards its cells' sampling density (the object-space filter).
      if (counts_ != nullptr) ++counts_->cells[cell];
      if (smp.fwd != kNoObject && !pvs_.Contains(cell, smp.fwd)) {
        out.entries.push_back({cell, smp.fwd, WitnessOf(cell, smp, t, smp.t_fwd)});
        ++c_fwd;
      }
      if (smp.rev != kNoObject && !pvs_.Contains(cell, smp.rev)) {
        out.entries.push_back({cell, smp.rev, WitnessOf(cell, smp, t, -smp.t_rev)});
        ++c_rev;
      }
    });
    out.contribution += c_fwd + c_rev;
    if (options_.strategy != SamplingStrategy::kAgvs) return;
    // Contributing ends become mutation candidates: from the other end (a hit, or where the
    // segment leaves the view space) to the hit point.
    auto add_candidate = [&](bool fwd_end) {
      Candidate cand;
      cand.object = fwd_end ? smp.fwd : smp.rev;
      cand.to = smp.origin + (fwd_end ? smp.t_fwd : -smp.t_rev) * smp.dir;
      cand.r_to = s_.objects[cand.object].radius;
      const ObjectId other = fwd_end ? smp.rev : smp.fwd;
      if (other != kNoObject) {
        cand.from = smp.origin + (fwd_end ? -smp.t_rev : smp.t_fwd) * smp.dir;
        cand.r_from = s_.objects[other].radius;
      } else {
        cand.from = smp.origin + (fwd_end ? t_first : t_last) * smp.dir;
        cand.r_from = s_.cell_radius;
      }
      // A segment that only touches the view space at a surface point gives no direction.
      const double len = glm::length(cand.to - cand.from);
      if (len > 1e-6 && std::isfinite(len)) out.candidates.push_back(cand);
    };
    if (c_fwd > 0) add_candidate(true);
    if (c_rev > 0) add_candidate(false);
  }

  // Where `cell`, if it keeps witnesses, would see the object at parameter t_obj: the ray from
  // the sample's point at parameter t (inside the cell) to it.
  uint32_t WitnessOf(CellId cell, const Sample& smp, double t, double t_obj) {
    if (!s_.witness_cell[cell]) return kNoWitness;
    out_->witnesses.push_back({s_.frame + smp.origin + t * smp.dir, s_.frame + smp.origin + t_obj * smp.dir});
    return static_cast<uint32_t>(out_->witnesses.size() - 1);
  }

 public:
  // Calls visit(cell, t) for each viewcell the part [t0, t1] of the line origin + t dir
  // passes through, with t a parameter inside that cell, in order along the line.
  template <typename F>
  void VisitCells(const glm::dvec3& origin, const glm::dvec3& dir, double t0, double t1, F&& visit) const {
    const Aabb& vs = s_.view_space;
    for (int k = 0; k < 3; ++k) {
      if (dir[k] == 0.0) {
        if (origin[k] < vs.min[k] || origin[k] > vs.max[k]) return;
        continue;
      }
      double a = (vs.min[k] - origin[k]) / dir[k], b = (vs.max[k] - origin[k]) / dir[k];
      if (a > b) std::swap(a, b);
      t0 = std::max(t0, a);
      t1 = std::min(t1, b);
    }
    if (!(t0 <= t1)) return;
    const double size = grid_.cell_size();
    const glm::dvec3 p = origin + t0 * dir;
    int i = std::clamp(static_cast<int>(std::floor((p.x - vs.min.x) / size)), 0, grid_.nx() - 1);
    int j = std::clamp(static_cast<int>(std::floor((p.y - vs.min.y) / size)), 0, grid_.ny() - 1);
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
      visit(grid_.Id({i, j}), 0.5 * (t + exit));
      if (exit >= t1) return;
      t = exit;
      if (tx <= ty) {
        i += si;
        tx += dtx;
      } else {
        j += sj;
        ty += dty;
      }
      if (i < 0 || j < 0 || i >= grid_.nx() || j >= grid_.ny()) return;
    }
  }

 private:
  const Impl& s_;
  const ViewcellGrid& grid_;
  const GlobalPvs& pvs_;
  const AgvsOptions& options_;
  ChunkResult* out_ = nullptr;
  Counts* counts_ = nullptr;                     // this thread's samples per cell and object, if counted
  std::vector<std::pair<double, double>> fan_;   // the silhouette search's scratch
  std::vector<Candidate> candidates_;            // this chunk's, gathered
  std::vector<FanSurface::Hot> fans_;              // where their objects' surfaces lie

 public:
  void CountInto(Counts* counts) { counts_ = counts; }
};

}  // namespace

// --- GlobalSampler ---

namespace {
// Camera rays the weak law of large numbers asks for to tell a ray share e with P = 0.9,
// k = 0.5: N >= (1 - e) / (k² e (1 - P)).
double RaysToTell(double e) { return (1.0 - e) / (0.25 * e * 0.1); }

// The pixel-error estimate over the newest batches that hold enough camera rays to tell apart
// the share they show, or the target share when that is larger: a high error is told from a
// short window, one near the target needs a long one. Without enough rays in all batches
// together the estimate is over all of them and not settled.
void UpdateEstimate(const GlobalSampler::Impl& m, const AgvsOptions& options, AgvsStats* stats) {
  const double target_share = std::clamp(m.estimate_target_pixels / options.resolution, 1e-12, 0.5);
  uint64_t n = 0, nc = 0;
  bool settled = false;
  for (size_t b = m.estimator_window.size(); b-- > 0;) {
    n += m.estimator_window[b].first;
    nc += m.estimator_window[b].second;
    if (n == 0) continue;
    const double share = static_cast<double>(nc) / static_cast<double>(n);
    if (static_cast<double>(n) >= RaysToTell(std::max(share, target_share))) {
      settled = true;
      break;
    }
  }
  stats->estimated_pixel_error = n > 0 ? options.resolution * static_cast<double>(nc) / static_cast<double>(n) : 0.0;
  stats->estimate_settled = settled;
  stats->estimate_rays = n;
}
}  // namespace

GlobalSampler::GlobalSampler(const ViewcellGrid& grid, const AgvsOptions& options)
    : grid_(grid), options_(options), impl_(std::make_unique<Impl>()) {}

GlobalSampler::~GlobalSampler() = default;

absl::StatusOr<std::unique_ptr<GlobalSampler>> GlobalSampler::Create(const scenes::Scene& scene,
                                                                    const ViewcellGrid& grid,
                                                                    const AgvsOptions& options) {
  if (grid.CellCount() == 0) return absl::InvalidArgumentError("global sampling over an empty viewcell grid");
  if (scene.TriangleCount() == 0) return absl::InvalidArgumentError("global sampling over a scene without triangles");
  if (options.batch_samples == 0) return absl::InvalidArgumentError("global sampling: batch_samples must be positive");
  // The sets are one bit per cell and object: refuse what this machine cannot hold rather
  // than die allocating it (a viewcell of a centimetre over a town).
  const double set_bytes = static_cast<double>(grid.CellCount()) * 8.0 *
                           static_cast<double>((scene.objects.size() + 63) / 64);
  const double memory = static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGESIZE));
  if (memory > 0 && set_bytes > 0.5 * memory) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "global sampling: the sets of %d x %d viewcells and %d objects take %.1f GiB, over half of this "
        "machine's %.1f GiB: choose larger viewcells",
        grid.nx(), grid.ny(), scene.objects.size(), set_bytes / (1 << 30), memory / (1 << 30)));
  }
  std::unique_ptr<GlobalSampler> s(new GlobalSampler(grid, options));
  Impl& m = *s->impl_;
  // The frame's origin is the grid's corner, a multiple of the cell size: moving the scene by
  // whole cells moves the frame with it and leaves every frame-relative float as it was.
  m.frame = glm::dvec3(grid.corner(), 0.0);
  m.view_space = grid.Bounds();
  m.view_space.min -= m.frame;
  m.view_space.max -= m.frame;
  m.cell_radius = BoxRadius(grid.CellBox(CellId{0}));
  m.buffer = MutationBuffer(options.mutation_buffer);
  m.device = rtcNewDevice(nullptr);
  if (m.device == nullptr) {
    return absl::InternalError(absl::StrCat("Embree: cannot create a device (error ", rtcGetDeviceError(nullptr), ")"));
  }
  m.rtc = rtcNewScene(m.device);
  rtcSetSceneFlags(m.rtc, options.robust_traversal ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(m.rtc, RTC_BUILD_QUALITY_HIGH);
  m.objects.resize(scene.objects.size());
  for (ObjectId id = 0; id < scene.objects.size(); ++id) {
    if (!m.MakeObject(scene.objects[id].mesh, &m.objects[id])) {
      return absl::InvalidArgumentError(absl::StrCat("object ", id, " (", scene.objects[id].name,
                                                     ") has a non-finite position or an index out of range"));
    }
    if (!m.objects[id].indices.empty()) m.Attach(id);
  }
  m.Commit();
  if (const RTCError err = rtcGetDeviceError(m.device); err != RTC_ERROR_NONE) {
    return absl::InternalError(absl::StrCat("Embree: building the scene failed (error ", err, ")"));
  }
  m.Rebuild();
  s->pvs_ = GlobalPvs(grid.CellCount(), scene.objects.size());
  m.cell_samples.assign(grid.CellCount(), 0);
  m.object_hits.assign(scene.objects.size(), 0);
  m.witness_cell.assign(grid.CellCount(), false);
  return s;
}

void GlobalSampler::RunBatch() {
  const auto start = std::chrono::steady_clock::now();
  Impl& m = *impl_;
  m.Commit();

  // Which distributions, in what shares.
  std::vector<Distribution> available;
  switch (options_.strategy) {
    case SamplingStrategy::kRef: available = {Distribution::kRef}; break;
    case SamplingStrategy::kSgvs: available = {Distribution::kViewSpaceDirection}; break;
    case SamplingStrategy::kAgvs:
      available = {Distribution::kViewSpaceDirection, Distribution::kObjectDirection, Distribution::kTwoPoint};
      if (m.buffer.size() > 0) {
        available.push_back(Distribution::kTwoPointMutation);
        available.push_back(Distribution::kSilhouetteMutation);
      }
      break;
  }
  std::array<double, kDistributionCount> share{};
  {
    double sum = 0.0;
    for (Distribution d : available) {
      const auto k = static_cast<size_t>(d);
      // Until a distribution has been tried, it gets the best weight seen.
      share[k] = m.ema_cost[k] > 0.0 ? m.ema_contribution[k] / m.ema_cost[k] : -1.0;
    }
    double best = 0.0;
    for (Distribution d : available) best = std::max(best, share[static_cast<size_t>(d)]);
    for (Distribution d : available) {
      double& w = share[static_cast<size_t>(d)];
      if (w < 0.0) w = best > 0.0 ? best : 1.0;
      sum += w;
    }
    for (Distribution d : available) {
      double& w = share[static_cast<size_t>(d)];
      w = sum > 0.0 ? w / sum : 1.0 / available.size();
    }
    // The floor keeps every distribution alive (the stationary ones make the whole progressive).
    const double floor = std::min(options_.min_probability, 1.0 / available.size());
    sum = 0.0;
    for (Distribution d : available) sum += std::max(share[static_cast<size_t>(d)], floor);
    for (Distribution d : available) {
      double& w = share[static_cast<size_t>(d)];
      w = std::max(w, floor) / sum;
    }
  }
  const uint32_t chunks = (options_.batch_samples + kChunk - 1) / kChunk;
  std::vector<uint32_t> quota(kDistributionCount, 0);
  {
    uint32_t given = 0;
    std::vector<std::pair<double, size_t>> remainders;
    for (Distribution d : available) {
      const auto k = static_cast<size_t>(d);
      const double exact = share[k] * chunks;
      quota[k] = std::max<uint32_t>(1, static_cast<uint32_t>(exact));
      given += quota[k];
      remainders.emplace_back(exact - std::floor(exact), k);
    }
    std::sort(remainders.begin(), remainders.end(), [](auto& a, auto& b) {
      return a.first != b.first ? a.first > b.first : a.second < b.second;
    });
    for (size_t r = 0; given < chunks; r = (r + 1) % remainders.size(), ++given) ++quota[remainders[r].second];
  }
  for (Distribution d : available) stats_.distributions[static_cast<size_t>(d)].probability = share[static_cast<size_t>(d)];

  const uint64_t batch = stats_.batches;
  std::vector<ChunkPlan> plans;
  Rng take_rng(Mix(options_.seed, Mix(batch, 0xb0ffe7)));
  for (Distribution d : available) {
    for (uint32_t q = 0; q < quota[static_cast<size_t>(d)]; ++q) {
      ChunkPlan plan{d, {}};
      if (d == Distribution::kTwoPointMutation || d == Distribution::kSilhouetteMutation) {
        plan.candidates.reserve(kChunk);
        for (uint32_t i = 0; i < kChunk; ++i) plan.candidates.push_back(m.buffer.Take(take_rng));
        // The buffer is not changed again until the chunks have been cast.
      }
      plans.push_back(std::move(plan));
    }
  }

  // Draw and cast in parallel; the sets are only read.
  std::vector<ChunkResult> results(plans.size());
  std::mutex counts_mutex;
  std::vector<std::unique_ptr<Counts>> counts;  // per thread
  ParallelFor(plans.size(), options_.threads, [&] {
    Worker worker(m, grid_, pvs_, options_);
    {
      const std::lock_guard lock(counts_mutex);
      counts.push_back(std::make_unique<Counts>());
      counts.back()->cells.assign(grid_.CellCount(), 0);
      counts.back()->objects.assign(m.objects.size(), 0);
      worker.CountInto(counts.back().get());
    }
    return [&, worker](size_t c) mutable { worker.Run(plans[c], Mix(options_.seed, Mix(batch, c)), &results[c]); };
  });

  for (const auto& per_thread : counts) {
    for (CellId c = 0; c < grid_.CellCount(); ++c) m.cell_samples[c] += per_thread->cells[c];
    for (ObjectId o = 0; o < m.objects.size(); ++o) m.object_hits[o] += per_thread->objects[o];
  }

  // Apply in chunk order.
  std::array<uint64_t, kDistributionCount> contribution{}, cost{}, drawn{};
  uint64_t est_rays = 0, est_hits = 0;
  for (size_t c = 0; c < plans.size(); ++c) {
    const ChunkResult& r = results[c];
    const auto k = static_cast<size_t>(plans[c].dist);
    for (const NewEntry& e : r.entries) {
      if (!pvs_.Insert(e.cell, e.object)) continue;
      ++stats_.entries;
      if (e.witness != kNoWitness) m.witnesses.emplace(uint64_t{e.cell} << 32 | e.object, r.witnesses[e.witness]);
    }
    for (const Candidate& cand : r.candidates) m.buffer.Add(cand);
    contribution[k] += r.contribution;
    cost[k] += r.embree_rays + r.silhouette_searches;  // a search costs about a ray
    drawn[k] += r.samples;
    stats_.samples += r.samples;
    stats_.rays += r.embree_rays;
    stats_.discarded_samples += r.discarded;
    est_rays += r.estimator_rays;
    est_hits += r.estimator_hits;
  }
  for (size_t k = 0; k < kDistributionCount; ++k) {
    DistributionStats& d = stats_.distributions[k];
    d.samples += drawn[k];
    d.rays += cost[k];
    d.contribution += contribution[k];
    if (drawn[k] > 0) {
      // Half-life of one batch: the window is about the last two batches.
      m.ema_contribution[k] = 0.5 * m.ema_contribution[k] + static_cast<double>(contribution[k]);
      m.ema_cost[k] = 0.5 * m.ema_cost[k] + static_cast<double>(cost[k]);
    }
  }

  m.estimator_window.emplace_back(est_rays, est_hits);
  UpdateEstimate(m, options_, &stats_);
  stats_.mutation_candidates = m.buffer.size();
  ++stats_.batches;
  stats_.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void GlobalSampler::Run(const RunLimits& limits, const std::atomic<bool>* cancel, const std::string& progress_label) {
  const uint64_t start_samples = stats_.samples;
  const double start_seconds = stats_.seconds;
  if (limits.pixel_error > 0) {
    impl_->estimate_target_pixels = limits.pixel_error;
    UpdateEstimate(*impl_, options_, &stats_);
  }
  std::unique_ptr<scenes::Progress> progress;
  if (!progress_label.empty()) progress = std::make_unique<scenes::Progress>(progress_label, 1000, cancel);
  uint64_t shown = 0;
  for (;;) {
    const double ran = stats_.seconds - start_seconds;
    const uint64_t ran_samples = stats_.samples - start_samples;
    double fraction = 0.0;
    bool done = false;
    if (limits.seconds > 0) {
      fraction = std::max(fraction, ran / limits.seconds);
      done |= ran >= limits.seconds;
    }
    if (limits.samples > 0) {
      fraction = std::max(fraction, static_cast<double>(ran_samples) / static_cast<double>(limits.samples));
      done |= ran_samples >= limits.samples;
    }
    if (limits.pixel_error > 0 && stats_.batches > 0) {
      // Progress on a log scale from the first estimate down to the target.
      const double e = std::max(stats_.estimated_pixel_error, 1e-12);
      fraction = std::max(fraction, std::clamp(1.0 - std::log(e / limits.pixel_error) / std::log(1e6), 0.0, 1.0));
      done |= stats_.estimate_settled && stats_.estimated_pixel_error <= limits.pixel_error;
    }
    if (limits.seconds <= 0 && limits.samples == 0 && limits.pixel_error <= 0) done = true;
    if (progress != nullptr) {
      const uint64_t now = static_cast<uint64_t>(std::clamp(fraction, 0.0, 1.0) * 1000);
      progress->SetDetail(absl::StrFormat("%.2f M samples/s, error %.1f px",
                                          ran > 0 ? ran_samples / ran * 1e-6 : 0.0, stats_.estimated_pixel_error));
      if (now > shown) {
        progress->Advance(now - shown);
        shown = now;
      }
    }
    if (done || (cancel != nullptr && cancel->load())) break;
    RunBatch();
  }
  if (progress != nullptr) progress->Finish();
}

void GlobalSampler::RecordWitnesses(std::span<const CellId> cells) {
  for (CellId c : cells) {
    if (c < impl_->witness_cell.size()) impl_->witness_cell[c] = true;
  }
}

std::optional<Witness> GlobalSampler::WitnessOf(CellId cell, scenes::ObjectId object) const {
  const auto it = impl_->witnesses.find(uint64_t{cell} << 32 | object);
  if (it == impl_->witnesses.end()) return std::nullopt;
  return it->second;
}

std::vector<BoxHit> GlobalSampler::SampleFromBox(const scenes::Aabb& box, size_t rays, uint64_t seed) const {
  Worker w(*impl_, grid_, pvs_, options_);
  return w.FromBox(box, rays, seed);
}

// --- Filters ---

std::vector<scenes::ObjectId> GlobalSampler::Filtered(CellId cell, const FilterOptions& filter) const {
  const Impl& m = *impl_;
  std::vector<ObjectId> base = pvs_.Objects(cell);
  if (!filter.object_space && !filter.view_space) return base;
  std::vector<bool> in(pvs_.object_count(), false);
  for (ObjectId o : base) in[o] = true;
  std::vector<ObjectId> out = base;
  if (filter.view_space) {
    for (CellId n : grid_.Neighbours(cell)) {
      const std::vector<ObjectId> theirs = pvs_.Objects(n);
      size_t common = 0;
      for (ObjectId o : theirs) common += in[o];
      const size_t uni = base.size() + theirs.size() - common;
      if (uni == 0 || static_cast<double>(common) / static_cast<double>(uni) < filter.view_similarity) continue;
      for (ObjectId o : theirs) {
        if (!in[o] && m.objects[o].alive) {
          in[o] = true;
          out.push_back(o);
        }
      }
    }
  }
  if (filter.object_space && !base.empty()) {
    Aabb cell_box = grid_.CellBox(cell);
    cell_box.min -= m.frame;
    cell_box.max -= m.frame;
    const double n_v = static_cast<double>(std::max<uint64_t>(m.cell_samples[cell], 1));
    std::vector<int32_t> stack;
    for (ObjectId o : base) {
      const Impl::Object& obj = m.objects[o];
      const double e_g = 2.0 * BoxDistance(cell_box, obj.bounds) / std::sqrt(n_v);
      const double e_l = obj.radius / std::sqrt(static_cast<double>(std::max<uint64_t>(m.object_hits[o], 1)));
      const double e = filter.k * std::min(e_g, e_l);
      Aabb grown = obj.bounds;
      grown.min -= glm::dvec3(e);
      grown.max += glm::dvec3(e);
      if (m.tree.empty()) continue;
      stack.assign(1, 0);
      while (!stack.empty()) {
        const KdNode& node = m.tree.nodes()[stack.back()];
        stack.pop_back();
        if (!node.bounds.Overlaps(grown)) continue;
        if (!node.IsLeaf()) {
          stack.push_back(node.left);
          stack.push_back(node.right);
          continue;
        }
        for (ObjectId q : m.tree.LeafObjects(node)) {
          if (!in[q] && m.objects[q].bounds.Overlaps(grown)) {
            in[q] = true;
            out.push_back(q);
          }
        }
      }
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

GlobalPvs GlobalSampler::FilteredAll(const FilterOptions& filter) const {
  if (!filter.object_space && !filter.view_space) return pvs_;
  GlobalPvs out(pvs_.cell_count(), pvs_.object_count());
  for (CellId c = 0; c < pvs_.cell_count(); ++c) out.Assign(c, Filtered(c, filter));
  return out;
}

// --- Dynamic edits ---

namespace {
void EraseWitness(std::unordered_map<uint64_t, Witness>* w, CellId c, ObjectId o) {
  w->erase(uint64_t{c} << 32 | o);
}
}  // namespace

absl::Status GlobalSampler::DeleteObject(scenes::ObjectId id) {
  Impl& m = *impl_;
  if (id >= m.objects.size() || !m.objects[id].alive) {
    return absl::NotFoundError(absl::StrCat("delete: no object ", id));
  }
  if (!m.objects[id].indices.empty()) {
    rtcDetachGeometry(m.rtc, id);
    m.dirty = true;
  }
  m.objects[id].alive = false;
  for (CellId c = 0; c < pvs_.cell_count(); ++c) {
    if (pvs_.Contains(c, id)) {
      pvs_.Erase(c, id);
      EraseWitness(&m.witnesses, c, id);
      --stats_.entries;
    }
  }
  m.buffer.Forget(id);
  m.Rebuild();
  m.Commit();
  return absl::OkStatus();
}

namespace {
// Removes from every cell's set what `id` may now hide there.
void RemovePenumbra(GlobalSampler::Impl& m, const ViewcellGrid& grid, GlobalPvs* pvs, AgvsStats* stats, ObjectId id) {
  const Aabb& blocker = m.objects[id].bounds;
  for (CellId c = 0; c < pvs->cell_count(); ++c) {
    Aabb cell = grid.CellBox(c);
    cell.min -= m.frame;
    cell.max -= m.frame;
    for (ObjectId o : pvs->Objects(c)) {
      if (o == id || !BoxMeetsShaft(cell, m.objects[o].bounds, blocker)) continue;
      pvs->Erase(c, o);
      m.witnesses.erase(uint64_t{c} << 32 | o);
      --stats->entries;
    }
  }
}
}  // namespace

absl::StatusOr<scenes::ObjectId> GlobalSampler::InsertObject(const scenes::Mesh& mesh) {
  Impl& m = *impl_;
  Impl::Object o;
  if (mesh.indices.size() < 3) return absl::InvalidArgumentError("insert: the mesh has no triangle");
  if (!m.MakeObject(mesh, &o)) {
    return absl::InvalidArgumentError("insert: the mesh has a non-finite position or an index out of range");
  }
  const auto id = static_cast<ObjectId>(m.objects.size());
  m.objects.push_back(std::move(o));
  m.Attach(id);
  pvs_.ResizeObjects(m.objects.size());
  m.object_hits.push_back(0);
  RemovePenumbra(m, grid_, &pvs_, &stats_, id);
  m.Rebuild();
  m.Commit();
  return id;
}

absl::Status GlobalSampler::MoveObject(scenes::ObjectId id, const glm::dvec3& offset) {
  Impl& m = *impl_;
  if (id >= m.objects.size() || !m.objects[id].alive) return absl::NotFoundError(absl::StrCat("move: no object ", id));
  if (!std::isfinite(offset.x) || !std::isfinite(offset.y) || !std::isfinite(offset.z)) {
    return absl::InvalidArgumentError("move: the offset is not finite");
  }
  if (absl::Status st = DeleteObject(id); !st.ok()) return st;
  Impl::Object& o = m.objects[id];
  o.bounds = Aabb{};
  for (glm::vec3& v : o.verts) {
    v = glm::vec3(glm::dvec3(v) + offset);
    o.bounds.Extend(glm::dvec3(v));
  }
  Impl::BuildTris(&o);
  o.alive = true;
  if (!o.indices.empty()) m.Attach(id);
  RemovePenumbra(m, grid_, &pvs_, &stats_, id);
  m.Rebuild();
  m.Commit();
  return absl::OkStatus();
}

// --- Saved state ---

namespace {
constexpr char kStateMagic[8] = {'V', 'S', 'A', 'G', 'V', 'S', '0', '1'};
}  // namespace

std::string GlobalSampler::SaveState() const {
  const Impl& m = *impl_;
  ByteWriter w;
  w.PutRaw(std::string_view(kStateMagic, 8));
  w.Put<uint64_t>(pvs_.object_count());
  w.Put<uint64_t>(pvs_.cell_count());
  w.Put(grid_.cell_size());
  w.Put(grid_.corner().x);
  w.Put(grid_.corner().y);
  w.Put<uint32_t>(static_cast<uint32_t>(options_.strategy));
  w.Put(options_.seed);
  w.Put(stats_.batches);
  w.Put(stats_.samples);
  w.Put(stats_.rays);
  w.Put(stats_.discarded_samples);
  w.Put(stats_.seconds);
  for (const DistributionStats& d : stats_.distributions) {
    w.Put(d.samples);
    w.Put(d.rays);
    w.Put(d.contribution);
    w.Put(d.probability);
  }
  for (size_t k = 0; k < kDistributionCount; ++k) {
    w.Put(m.ema_contribution[k]);
    w.Put(m.ema_cost[k]);
  }
  w.PutVarint(m.estimator_window.size());
  for (const auto& [n, nc] : m.estimator_window) {
    w.PutVarint(n);
    w.PutVarint(nc);
  }
  for (uint64_t n : m.cell_samples) w.PutVarint(n);
  for (uint64_t n : m.object_hits) w.PutVarint(n);
  w.PutVarint(m.buffer.size());
  m.buffer.ForEach([&](const Candidate& c, uint32_t mutations) {
    w.Put(c.from);
    w.Put(c.to);
    w.Put(c.r_from);
    w.Put(c.r_to);
    w.Put(c.object);
    w.Put(mutations);
  });
  EncodeSets(pvs_, &w);
  return std::move(w.bytes());
}

absl::Status GlobalSampler::LoadState(std::string_view bytes, const std::string& where) {
  Impl& m = *impl_;
  ByteReader r(bytes, where);
  char magic[8];
  for (char& ch : magic) {
    if (absl::Status st = r.Get(&ch, "the magic"); !st.ok()) return st;
  }
  if (std::string_view(magic, 8) != std::string_view(kStateMagic, 8)) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": not a vistream sampling state (no VSAGVS01 magic)"));
  }
  uint64_t objects = 0, cells = 0;
  double size = 0, cx = 0, cy = 0;
  uint32_t strategy = 0;
  uint64_t seed = 0;
  absl::Status st = r.Get(&objects, "the object count");
  if (st.ok()) st = r.Get(&cells, "the cell count");
  if (st.ok()) st = r.Get(&size, "the cell size");
  if (st.ok()) st = r.Get(&cx, "the corner x");
  if (st.ok()) st = r.Get(&cy, "the corner y");
  if (st.ok()) st = r.Get(&strategy, "the strategy");
  if (st.ok()) st = r.Get(&seed, "the seed");
  if (!st.ok()) return st;
  if (objects != pvs_.object_count() || cells != pvs_.cell_count() || size != grid_.cell_size() ||
      cx != grid_.corner().x || cy != grid_.corner().y) {
    return r.Error(absl::StrCat("made for ", objects, " objects and ", cells, " cells of ", size,
                                " m; this scene has ", pvs_.object_count(), " objects and ", pvs_.cell_count(),
                                " cells of ", grid_.cell_size(), " m"));
  }
  if (strategy != static_cast<uint32_t>(options_.strategy) || seed != options_.seed) {
    return r.Error(absl::StrCat("made with strategy ", strategy, " and seed ", seed, "; resume with the same ones"));
  }
  AgvsStats s;
  st = r.Get(&s.batches, "batches");
  if (st.ok()) st = r.Get(&s.samples, "samples");
  if (st.ok()) st = r.Get(&s.rays, "rays");
  if (st.ok()) st = r.Get(&s.discarded_samples, "discarded samples");
  if (st.ok()) st = r.Get(&s.seconds, "seconds");
  for (DistributionStats& d : s.distributions) {
    if (st.ok()) st = r.Get(&d.samples, "distribution samples");
    if (st.ok()) st = r.Get(&d.rays, "distribution rays");
    if (st.ok()) st = r.Get(&d.contribution, "distribution contribution");
    if (st.ok()) st = r.Get(&d.probability, "distribution probability");
  }
  std::array<double, kDistributionCount> ema_c{}, ema_cost{};
  for (size_t k = 0; k < kDistributionCount && st.ok(); ++k) {
    st = r.Get(&ema_c[k], "mixture weights");
    if (st.ok()) st = r.Get(&ema_cost[k], "mixture costs");
  }
  uint64_t window = 0;
  if (st.ok()) st = r.GetVarint(&window, "the estimator window");
  if (!st.ok()) return st;
  if (window > r.remaining()) return r.Error("estimator window longer than the file");
  std::vector<std::pair<uint64_t, uint64_t>> est(window);
  for (auto& [n, nc] : est) {
    if (st.ok()) st = r.GetVarint(&n, "estimator rays");
    if (st.ok()) st = r.GetVarint(&nc, "estimator hits");
  }
  std::vector<uint64_t> cell_samples(cells), object_hits(objects);
  for (uint64_t& n : cell_samples) {
    if (st.ok()) st = r.GetVarint(&n, "cell sample counts");
  }
  for (uint64_t& n : object_hits) {
    if (st.ok()) st = r.GetVarint(&n, "object hit counts");
  }
  uint64_t candidates = 0;
  if (st.ok()) st = r.GetVarint(&candidates, "the candidate count");
  if (!st.ok()) return st;
  if (candidates > r.remaining()) return r.Error("more mutation candidates than bytes left");
  MutationBuffer buffer(options_.mutation_buffer);
  for (uint64_t i = 0; i < candidates && st.ok(); ++i) {
    Candidate c;
    st = r.Get(&c.from, "a candidate");
    if (st.ok()) st = r.Get(&c.to, "a candidate");
    if (st.ok()) st = r.Get(&c.r_from, "a candidate");
    if (st.ok()) st = r.Get(&c.r_to, "a candidate");
    if (st.ok()) st = r.Get(&c.object, "a candidate");
    if (st.ok()) st = r.Get(&c.mutations, "a candidate");
    if (st.ok() && c.object >= objects) st = r.Error(absl::StrCat("candidate ", i, " names object ", c.object));
    const double len = glm::length(c.to - c.from);
    if (st.ok() && !(len > 1e-6 && std::isfinite(len) && c.r_from >= 0 && c.r_to >= 0 && std::isfinite(c.r_from) &&
                     std::isfinite(c.r_to))) {
      st = r.Error(absl::StrCat("candidate ", i, " is not a finite segment"));
    }
    if (st.ok()) buffer.Add(c);
  }
  if (!st.ok()) return st;
  GlobalPvs sets(cells, objects);
  if (st = DecodeSets(&r, &sets); !st.ok()) return st;
  if (!r.AtEnd()) return r.Error(absl::StrCat(r.remaining(), " bytes follow the sets"));
  s.entries = sets.TotalEntries();
  s.mutation_candidates = buffer.size();
  pvs_ = std::move(sets);
  stats_ = s;
  m.ema_contribution = ema_c;
  m.ema_cost = ema_cost;
  m.estimator_window = std::move(est);
  m.cell_samples = std::move(cell_samples);
  m.object_hits = std::move(object_hits);
  m.buffer = std::move(buffer);
  m.witnesses.clear();
  UpdateEstimate(m, options_, &stats_);
  return absl::OkStatus();
}

}  // namespace vistream::visibility
