#include "client/client_model.h"

#include <algorithm>

#include <absl/strings/str_cat.h>

#include "proto/vec3.h"
#include "scenes/geometry_codec.h"

namespace vistream::client {

namespace v1 = vistream::v1;

v1::Hello MakeHello(const HelloSettings& settings) {
  v1::Hello h;
  h.set_scene(settings.scene);
  h.set_protocol_version(v1::PROTOCOL_VERSION_CURRENT);
  h.set_memory_budget_bytes(settings.memory_budget_bytes);
  h.set_triangle_budget(settings.triangle_budget);
  h.set_epsilon_masks(settings.epsilon_masks);
  h.set_deflated_masks(settings.epsilon_masks);  // every client that draws masks inflates them
  // A client that takes levels takes its lists as differences too (issue 45's byte budget); one
  // without keeps today's full lists (levels off: the same bytes as before levels).
  h.set_pvs_deltas(settings.screen_error_px > 0.0);
  h.mutable_held_objects()->Add(settings.held_objects.begin(), settings.held_objects.end());
  if (std::any_of(settings.held_levels.begin(), settings.held_levels.end(), [](uint32_t l) { return l != 0; })) {
    h.mutable_held_levels()->Add(settings.held_levels.begin(), settings.held_levels.end());
  }
  if (settings.screen_error_px > 0.0) {
    v1::LevelRequest* l = h.mutable_levels();
    l->set_viewport_width_px(settings.viewport_width_px);
    l->set_viewport_height_px(settings.viewport_height_px);
    l->set_vertical_fov_rad(settings.vertical_fov_rad);
    l->set_screen_error_px(settings.screen_error_px);
    l->set_clusters(settings.clusters);
    h.mutable_held_clusters()->Add(settings.held_clusters.begin(), settings.held_clusters.end());
    h.mutable_held_cluster_levels()->Add(settings.held_cluster_levels.begin(), settings.held_cluster_levels.end());
  }
  return h;
}

v1::Pose MakePose(const glm::dvec3& position, const glm::dvec3& velocity, double yaw_rad, double pitch_rad,
                  double client_time_s) {
  v1::Pose p;
  p.set_client_time_s(client_time_s);
  SetVec(position, p.mutable_position());
  SetVec(velocity, p.mutable_velocity());
  p.set_yaw_rad(static_cast<float>(yaw_rad));
  p.set_pitch_rad(static_cast<float>(pitch_rad));
  return p;
}

PoseCadence::PoseCadence(double rate_hz) : period_s_(1.0 / std::max(0.1, rate_hz)) {}

void PoseCadence::Sent(double now_s) {
  next_s_ += period_s_;
  if (next_s_ < now_s) next_s_ = now_s;
}

uint64_t ChargedBytes(const v1::ServerMessage& m) {
  switch (m.body_case()) {
    case v1::ServerMessage::kGeometry:
      return m.geometry().vertices().size() + m.geometry().indices().size();
    case v1::ServerMessage::kCluster:
      return m.cluster().vertices().size() + m.cluster().indices().size();
    case v1::ServerMessage::kEpsilonMask:
      return m.epsilon_mask().triangles().size();
    default:
      return 0;
  }
}

v1::ClientMessage HelloMessage(const HelloSettings& settings) {
  v1::ClientMessage m;
  *m.mutable_hello() = MakeHello(settings);
  return m;
}

v1::ClientMessage PoseMessage(const v1::Pose& pose) {
  v1::ClientMessage m;
  *m.mutable_pose() = pose;
  return m;
}

v1::ClientMessage CreditMessage(uint64_t bytes) {
  v1::ClientMessage m;
  m.mutable_credit()->set_bytes(bytes);
  return m;
}

namespace {

// A level mesh from the fields ObjectGeometry and ClusterGeometry name alike (EncodeLevelMesh's).
template <typename Message>
absl::StatusOr<scenes::Mesh> DecodeLevelFields(const Message& g, const std::string& where) {
  if (g.origin_size() != 3) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", g.origin_size(), " origin values (expected 3)"));
  }
  const int64_t origin[3] = {g.origin(0), g.origin(1), g.origin(2)};
  return scenes::DecodeLevelMesh(g.vertex_count(), g.index_count(), g.step_log2(), origin, g.wide(), g.vertices(),
                                 g.indices(), where);
}

// The encoded bytes a level saved against the full meshes it stands for (full_bytes).
template <typename Message>
uint64_t SavedBytes(const Message& g) {
  const uint64_t own = g.vertices().size() + g.indices().size();
  return g.full_bytes() > own ? g.full_bytes() - own : 0;
}

}  // namespace

absl::StatusOr<DecodedObject> DecodeObjectGeometry(const v1::ObjectGeometry& g) {
  const std::string where = absl::StrCat("object ", g.object_id(), g.level() > 0 ? absl::StrCat(", level ", g.level()) : "");
  DecodedObject o;
  o.id = g.object_id();
  o.level = g.level();
  if (g.level() == 0) {
    absl::StatusOr<scenes::Mesh> mesh = scenes::DecodeMesh(g.vertex_count(), g.index_count(), g.vertices(), g.indices(), where);
    if (!mesh.ok()) return mesh.status();
    o.mesh = *std::move(mesh);
    o.bounds_min = {g.bounds_min().x(), g.bounds_min().y(), g.bounds_min().z()};
    o.bounds_max = {g.bounds_max().x(), g.bounds_max().y(), g.bounds_max().z()};
  } else {
    absl::StatusOr<scenes::Mesh> mesh = DecodeLevelFields(g, where);
    if (!mesh.ok()) return mesh.status();
    o.mesh = *std::move(mesh);
    const scenes::Aabb b = o.mesh.Bounds();
    o.bounds_min = b.Empty() ? glm::dvec3(0.0) : b.min;
    o.bounds_max = b.Empty() ? glm::dvec3(0.0) : b.max;
    o.keeps_triangles = g.keeps_triangles();
    o.saved_bytes = SavedBytes(g);
  }
  o.raw_bytes = scenes::RawMeshBytes(o.mesh.positions.size(), o.mesh.indices.size());
  return o;
}

absl::StatusOr<DecodedCluster> DecodeClusterGeometry(const v1::ClusterGeometry& g) {
  const std::string where = absl::StrCat("cluster ", g.cluster_id(), ", level ", g.level());
  if (g.level() == 0) return absl::InvalidArgumentError(absl::StrCat(where, ": a cluster's levels start at 1"));
  if (g.objects_size() < 2) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": stands for ", g.objects_size(), " objects (at least 2)"));
  }
  for (int k = 1; k < g.objects_size(); ++k) {
    if (g.objects(k) <= g.objects(k - 1)) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": objects do not ascend (", g.objects(k - 1), " then ", g.objects(k), ")"));
    }
  }
  absl::StatusOr<scenes::Mesh> mesh = DecodeLevelFields(g, where);
  if (!mesh.ok()) return mesh.status();
  DecodedCluster c;
  c.id = g.cluster_id();
  c.level = g.level();
  c.objects.assign(g.objects().begin(), g.objects().end());
  c.mesh = *std::move(mesh);
  c.keeps_triangles = g.keeps_triangles();
  if (g.object_triangles_size() != g.objects_size()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": ", g.object_triangles_size(),
                                                   " object triangle counts for ", g.objects_size(), " objects"));
  }
  uint64_t sum = 0;
  for (uint32_t n : g.object_triangles()) sum += n;
  if (sum != c.mesh.TriangleCount()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": its objects' triangles sum to ", sum,
                                                   ", its mesh has ", c.mesh.TriangleCount()));
  }
  c.first_triangle.assign(1, 0);
  for (uint32_t n : g.object_triangles()) c.first_triangle.push_back(c.first_triangle.back() + n);
  const scenes::Aabb b = c.mesh.Bounds();
  c.bounds_min = b.Empty() ? glm::dvec3(0.0) : b.min;
  c.bounds_max = b.Empty() ? glm::dvec3(0.0) : b.max;
  c.saved_bytes = SavedBytes(g);
  c.raw_bytes = scenes::RawMeshBytes(c.mesh.positions.size(), c.mesh.indices.size());
  return c;
}

}  // namespace vistream::client
