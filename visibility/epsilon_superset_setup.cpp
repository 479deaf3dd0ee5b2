// The ε-superset's preparation (Cohen-Or and Zadicario 1998, section 4): each object's
// distinct vertices, the occluders as convex prisms in Embree's scene, the kd-tree of the
// occludees; and the sampling of neighbourhoods for the benchmarks. The queries are in
// epsilon_superset.cpp.

#include <algorithm>
#include <cmath>
#include <tuple>

#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>

#include "scenes/random.h"
#include "scenes/terrain.h"
#include "visibility/epsilon_superset_internal.h"
#include "visibility/occluder_set.h"

namespace vistream::visibility {

absl::StatusOr<EpsilonOptions> EpsilonOptions::FromName(std::string_view name) {
  if (name == "none") return EpsilonOptions{false, false, false, false, false, false};
  if (name == "boxes") return EpsilonOptions{true, false, false, false, false, false};
  if (name == "occluders") return EpsilonOptions{true, true, false, false, false, false};
  if (name == "rays") return EpsilonOptions{true, false, true, false, false, false};
  if (name == "paper") return EpsilonOptions{true, true, true, false, false, false};
  if (name == "all") return EpsilonOptions{true, true, true, true, true, true};
  return absl::InvalidArgumentError(
      absl::StrCat("optimisation '", std::string(name), "': expected none, boxes, occluders, rays, paper or all"));
}

namespace {

// How far beneath the ground a prism's box reaches for Embree (metres, scene-local): segments
// end on or above the ground, or at an occludee's vertex below it (a basement); deeper than
// this a crossing is not proposed, which keeps the occludee (conservative).
constexpr double kBelowGroundM = -1000.0;

}  // namespace

EpsilonSuperset::EpsilonSuperset(const scenes::Scene& scene) : scene_(scene) {}

EpsilonSuperset::~EpsilonSuperset() = default;

absl::StatusOr<std::unique_ptr<EpsilonSuperset>> EpsilonSuperset::Create(const scenes::Scene& scene) {
  std::unique_ptr<EpsilonSuperset> s(new EpsilonSuperset(scene));
  s->triangle_base_.reserve(scene.objects.size() + 1);
  uint32_t base = 0;
  for (const scenes::Object& o : scene.objects) {
    s->triangle_base_.push_back(base);
    base += static_cast<uint32_t>(o.mesh.TriangleCount());
  }
  s->triangle_base_.push_back(base);

  // Distinct vertex positions per object: flat-shaded meshes repeat each corner once per face.
  s->vertex_start_.reserve(scene.objects.size() + 1);
  s->triangle_vertex_.reserve(3 * static_cast<size_t>(base));
  std::vector<uint32_t> order, distinct_of;
  for (const scenes::Object& o : scene.objects) {
    s->vertex_start_.push_back(static_cast<uint32_t>(s->vertices_.size()));
    const std::vector<glm::vec3>& pos = o.mesh.positions;
    auto key = [&](uint32_t i) { return std::tuple(pos[i].x, pos[i].y, pos[i].z); };
    order.resize(pos.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return key(a) < key(b); });
    distinct_of.resize(pos.size());
    uint32_t distinct = 0;
    for (size_t i = 0; i < order.size(); ++i) {
      if (i == 0 || key(order[i]) != key(order[i - 1])) {
        if (i > 0) ++distinct;
        s->vertices_.push_back(pos[order[i]]);
      }
      distinct_of[order[i]] = distinct;
    }
    for (uint32_t index : o.mesh.indices) s->triangle_vertex_.push_back(distinct_of[index]);
  }
  s->vertex_start_.push_back(static_cast<uint32_t>(s->vertices_.size()));

  // Convex prisms: the occluder set's convex pieces; a degenerate piece (a segment from a
  // zero-area footprint) has no interior and hides nothing.
  const OccluderSet occluders = OccluderSet::Build(scene);
  for (const OccluderPiece& piece : occluders.pieces()) {
    if (piece.points.size() < 3 || !(piece.height > 0.0)) continue;
    Prism prism;
    prism.first_edge = static_cast<uint32_t>(s->edges_.size());
    prism.height = piece.height;
    prism.object = piece.object;
    // The mesh stores these corners in float: a face of the object may lie that far inside
    // the prism, and must not be hidden by its own occluder for it.
    // (One running maximum, not std::max of an initializer list: GCC 12 at -O2 folds
    // double(float(x)) - x to zero inside such a list in a loop.)
    double round_off = 0.0;
    auto note = [&round_off](double x) {
      round_off = std::max(round_off, std::fabs(static_cast<double>(static_cast<float>(x)) - x));
    };
    note(piece.height);
    for (const glm::dvec2& p : piece.points) {
      note(p.x);
      note(p.y);
    }
    prism.shrink = kShrinkM + 2.0 * round_off;
    const size_t n = piece.points.size();
    for (size_t k = 0; k < n; ++k) {
      const glm::dvec2 a = piece.points[k], b = piece.points[(k + 1) % n];
      const double len = glm::length(b - a);
      if (!(len > 0.0)) continue;
      s->edges_.push_back(Edge{-(b.y - a.y) / len, (b.x - a.x) / len, a.x, a.y});
    }
    prism.edge_count = static_cast<uint32_t>(s->edges_.size()) - prism.first_edge;
    if (prism.edge_count < 3) {
      s->edges_.resize(prism.first_edge);
      continue;
    }
    s->prisms_.push_back(prism);
    s->prism_min_.emplace_back(piece.box_min, kBelowGroundM);
    s->prism_max_.emplace_back(piece.box_max, piece.height);
  }
  s->object_prism_start_.assign(scene.objects.size() + 1, 0);
  for (const Prism& p : s->prisms_) ++s->object_prism_start_[p.object + 1];
  for (size_t i = 0; i < scene.objects.size(); ++i) s->object_prism_start_[i + 1] += s->object_prism_start_[i];
  s->object_prisms_.resize(s->prisms_.size());
  std::vector<uint32_t> fill(s->object_prism_start_.begin(), s->object_prism_start_.end() - 1);
  for (uint32_t i = 0; i < s->prisms_.size(); ++i) s->object_prisms_[fill[s->prisms_[i].object]++] = i;
  s->tree_ = KdTree::Build(scene);
  if (!scene.bounds.Empty()) s->frame_ = 0.5 * (scene.bounds.min + scene.bounds.max);

  s->embree_ = std::make_unique<Embree>();
  Embree& em = *s->embree_;
  em.device = rtcNewDevice(nullptr);
  if (em.device == nullptr) {
    return absl::InternalError(absl::StrCat("Embree: cannot create a device (error ", rtcGetDeviceError(nullptr), ")"));
  }
  em.scene = rtcNewScene(em.device);
  rtcSetSceneFlags(em.scene, RTC_SCENE_FLAG_ROBUST);
  if (!s->prisms_.empty()) {
    RTCGeometry geom = rtcNewGeometry(em.device, RTC_GEOMETRY_TYPE_USER);
    rtcSetGeometryUserPrimitiveCount(geom, static_cast<unsigned>(s->prisms_.size()));
    rtcSetGeometryUserData(geom, s.get());
    // Boxes in floats relative to frame_, grown so that rounding never loses a prism the
    // exact segment reaches: Embree only proposes, Crosses decides.
    rtcSetGeometryBoundsFunction(
        geom,
        [](const RTCBoundsFunctionArguments* args) {
          const auto* self = static_cast<const EpsilonSuperset*>(args->geometryUserPtr);
          const glm::dvec3 lo = self->prism_min_[args->primID] - self->frame_;
          const glm::dvec3 hi = self->prism_max_[args->primID] - self->frame_;
          const double m = 1e-2 + 1e-5 * std::max({std::abs(lo.x), std::abs(lo.y), std::abs(hi.x), std::abs(hi.y),
                                                   std::abs(hi.z)});
          RTCBounds* b = args->bounds_o;
          b->lower_x = static_cast<float>(lo.x - m);
          b->lower_y = static_cast<float>(lo.y - m);
          b->lower_z = static_cast<float>(lo.z - m);
          b->upper_x = static_cast<float>(hi.x + m);
          b->upper_y = static_cast<float>(hi.y + m);
          b->upper_z = static_cast<float>(hi.z + m);
        },
        nullptr);
    rtcSetGeometryIntersectFunction(geom, &IntersectPrisms);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(em.scene, geom);
    rtcReleaseGeometry(geom);
  }
  rtcCommitScene(em.scene);
  if (const RTCError err = rtcGetDeviceError(em.device); err != RTC_ERROR_NONE) {
    return absl::InternalError(absl::StrCat("Embree: building the occluder scene failed (error ", err, ")"));
  }
  return s;
}

ObjectId EpsilonSuperset::ObjectOfTriangle(uint32_t id) const {
  return static_cast<ObjectId>(std::upper_bound(triangle_base_.begin(), triangle_base_.end(), id) -
                               triangle_base_.begin() - 1);
}

double TypicalObjectSize(const scenes::Scene& scene) {
  std::vector<double> sizes;
  for (const scenes::Object& o : scene.objects) {
    if (!o.bounds.Empty()) sizes.push_back(0.5 * ((o.bounds.max.x - o.bounds.min.x) + (o.bounds.max.y - o.bounds.min.y)));
  }
  if (sizes.empty()) return 0.0;
  std::nth_element(sizes.begin(), sizes.begin() + static_cast<long>(sizes.size() / 2), sizes.end());
  return sizes[sizes.size() / 2];
}

std::vector<Aabb> SampleNeighbourhoods(const scenes::Scene& scene, size_t count, double size, double base,
                                       uint64_t seed) {
  std::vector<Aabb> out;
  if (scene.bounds.Empty()) return out;
  scenes::Rng rng(seed);
  const glm::dvec2 lo(scene.bounds.min), hi(scene.bounds.max);
  const scenes::TerrainHeight terrain(scene);
  for (size_t tries = 0; out.size() < count && tries < 1000 * count; ++tries) {
    glm::dvec3 c(rng.Uniform(lo.x, hi.x), rng.Uniform(lo.y, hi.y), base + 0.5 * size);
    if (!terrain.empty()) {
      // Above the highest ground under the box: it stands on the terrain, not in it.
      const glm::dvec2 corner(c.x - 0.5 * size, c.y - 0.5 * size);
      c.z += terrain.Range(corner, corner + glm::dvec2(size)).max;
    }
    const Aabb box{c - 0.5 * size, c + 0.5 * size};
    bool free = true;
    for (const scenes::Object& o : scene.objects) {
      if (std::binary_search(scene.terrain.begin(), scene.terrain.end(), o.id)) continue;  // under the box
      if (!o.bounds.Empty() && o.bounds.Overlaps(box)) {
        free = false;
        break;
      }
    }
    if (free) out.push_back(box);
  }
  return out;
}

}  // namespace vistream::visibility
