#pragma once
// The client's side of the walkthrough protocol (proto/walkthrough.proto; DESIGN.md "The client
// model and the web client"), written once: what a client says in Hello, how often it reports
// its pose, how it grants byte credit and what each server message costs it. The native
// client's network thread (client/connection.h), the scripted sessions of the tests and of
// `vistream bench server` (client/session_stream.h) and the simulator (simulation/simulator.h)
// all follow these rules by calling them. The rest of the model: which ε-masks a client holds
// and which one a frame draws (client/mask_holdings.h), when a viewcell is complete
// (client/cell_completion.h), the viewcell grid (visibility::ViewcellGrid from SceneInfo,
// proto/scene_info.h GridFromSceneInfo), the memory accounting of a decoded object
// (scenes/geometry_codec.h RawMeshBytes).
//
// Nothing here does input or output, waits or takes a lock: callers own the clock (steady
// seconds for a real client, simulated seconds for the simulator) and the stream.

#include <cstdint>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include <absl/status/statusor.h>

#include "proto/walkthrough.pb.h"
#include "scenes/mesh.h"

namespace vistream::client {

// ---- Hello ----

// What a client asks for when a session opens (proto Hello).
struct HelloSettings {
  std::string scene;                 // the served scene's name (ServerStats.scenes)
  uint64_t memory_budget_bytes = 0;  // decoded bytes the client may hold (RawMeshBytes); 0 unlimited
  uint64_t triangle_budget = 0;      // triangles a frame; 0 unlimited
  bool epsilon_masks = false;        // the client draws ε-masks (the server sends none otherwise)
  std::vector<uint32_t> held_objects;  // on resume: the objects it still holds, any order
  std::vector<uint32_t> held_levels;   // with levels: each held object's level (0 full); empty: all full
  // Levels of detail (Hello.levels; issue 45): the screen error tau in pixels the client accepts
  // on its viewport; 0: off (every object at full detail). With levels the client also takes PVS
  // lists as differences (Hello.pvs_deltas, proto/pvs_delta.h).
  double screen_error_px = 0.0;
  // With levels: the client draws cluster levels too (LevelRequest.clusters; ClusterGeometry in
  // place of the objects a cell's list lets it stand for).
  bool clusters = false;
  std::vector<uint32_t> held_clusters;        // on resume: the clusters it still holds
  std::vector<uint32_t> held_cluster_levels;  // the level of each (one per held cluster)
  uint32_t viewport_width_px = 1280;
  uint32_t viewport_height_px = 720;
  double vertical_fov_rad = 1.0471975511965976;  // 60 degrees
};

// The Hello of the current protocol version (PROTOCOL_VERSION_CURRENT) with `settings`.
vistream::v1::Hello MakeHello(const HelloSettings& settings);

// ---- Pose ----

// Poses a client reports a second (the server accepts up to 120).
inline constexpr double kPoseRateHz = 10.0;

// The pose message: eye in scene-local metres (z up), velocity in m/s (the server's
// look-ahead), yaw counter-clockwise from +x and pitch up from the horizontal in radians,
// `client_time_s` the client's clock in seconds since its session started.
vistream::v1::Pose MakePose(const glm::dvec3& position, const glm::dvec3& velocity, double yaw_rad, double pitch_rad,
                            double client_time_s);

// When the next pose is due, on the caller's clock (seconds): one every 1 / rate_hz seconds
// from the first, never a burst to catch up after a late one (a pose sent late moves the next
// to the time it was sent, as a steady rate would).
class PoseCadence {
 public:
  // `rate_hz` below 0.1 is taken as 0.1.
  explicit PoseCadence(double rate_hz = kPoseRateHz);
  double period_s() const { return period_s_; }
  // Starts the cadence again: the next pose is due at `now_s`.
  void Restart(double now_s) { next_s_ = now_s; }
  double next_s() const { return next_s_; }
  bool Due(double now_s) const { return now_s >= next_s_; }
  // A pose went out at `now_s` (at or after next_s()): the next is due one period after the
  // one that was due, or at `now_s` if that is already past.
  void Sent(double now_s);

 private:
  double period_s_;
  double next_s_ = 0.0;
};

// ---- Credit ----

// Byte credit as a client grants it (proto Credit): the whole window when the session opens;
// then, each time half the window has been consumed (ChargedBytes of what arrived), a grant of
// exactly what was consumed. So at most `window_bytes` are in flight, and a client that stops
// reading stops the server.
class CreditWindow {
 public:
  static constexpr uint64_t kDefaultBytes = uint64_t{8} << 20;
  explicit CreditWindow(uint64_t window_bytes = kDefaultBytes) : window_bytes_(window_bytes) {}
  uint64_t window_bytes() const { return window_bytes_; }
  // A session opens: what it grants first (the window); nothing is consumed yet.
  uint64_t Open() {
    consumed_ = 0;
    return window_bytes_;
  }
  // `bytes` of what the server charged arrived.
  void Consume(uint64_t bytes) { consumed_ += bytes; }
  // Whether a grant is due (half the window consumed since the last one).
  bool GrantDue() const { return consumed_ >= window_bytes_ / 2; }
  // The grant due (what was consumed), starting the count again. Precondition: GrantDue().
  uint64_t TakeGrant() {
    const uint64_t g = consumed_;
    consumed_ = 0;
    return g;
  }

 private:
  uint64_t window_bytes_;
  uint64_t consumed_ = 0;
};

// Bytes a server message costs the credit: an object's or a cluster's encoded geometry (its
// vertex and index bytes) and an ε-mask's run-length triangle bytes; every other message is free.
uint64_t ChargedBytes(const vistream::v1::ServerMessage& m);

// ---- Geometry ----

// An ObjectGeometry decoded: the mesh to draw (scene-local metres), its bounds, the level of
// detail it is (0: full) and what it takes in memory (RawMeshBytes of the decoded mesh).
struct DecodedObject {
  uint32_t id = 0;
  uint32_t level = 0;
  // Whether an ε-mask's triangle bits apply to this mesh (the full mesh, or a level that keeps
  // its triangles in order: ObjectGeometry.keeps_triangles); false: a masked frame draws it whole.
  bool keeps_triangles = true;
  // A level: the encoded bytes it saved the link against the full mesh (ObjectGeometry.full_bytes
  // less its own; 0 for the full mesh).
  uint64_t saved_bytes = 0;
  scenes::Mesh mesh;
  glm::dvec3 bounds_min{0.0}, bounds_max{0.0};
  uint64_t raw_bytes = 0;
};
// Full meshes by scenes::DecodeMesh with the message's bounds; levels by DecodeLevelMesh, their
// bounds their mesh's. Errors (INVALID_ARGUMENT) name the object: bytes that are no mesh, a
// level without its three origin values.
absl::StatusOr<DecodedObject> DecodeObjectGeometry(const vistream::v1::ObjectGeometry& g);

// A ClusterGeometry decoded (issue 45): one mesh standing for `objects` (ascending).
struct DecodedCluster {
  uint32_t id = 0;
  uint32_t level = 0;  // >= 1
  std::vector<uint32_t> objects;
  // objects[k]'s piece: the mesh's triangles from first_triangle[k] to first_triangle[k + 1]
  // (objects.size() + 1 entries). keeps_triangles: each piece is its object's full triangles in
  // order (an ε-mask's bits apply); else a simplified piece, drawn whole.
  std::vector<uint32_t> first_triangle;
  bool keeps_triangles = false;
  uint64_t saved_bytes = 0;  // ClusterGeometry.full_bytes less its own encoded bytes
  scenes::Mesh mesh;
  glm::dvec3 bounds_min{0.0}, bounds_max{0.0};  // its mesh's
  uint64_t raw_bytes = 0;
};
// By DecodeLevelMesh. Errors (INVALID_ARGUMENT) name the cluster: level 0, fewer than 2 objects
// or objects that do not ascend, no three origin values, bytes that are no mesh, object_triangles
// not one per object or not summing to the mesh's triangles.
absl::StatusOr<DecodedCluster> DecodeClusterGeometry(const vistream::v1::ClusterGeometry& g);

vistream::v1::ClientMessage HelloMessage(const HelloSettings& settings);
vistream::v1::ClientMessage PoseMessage(const vistream::v1::Pose& pose);
vistream::v1::ClientMessage CreditMessage(uint64_t bytes);

}  // namespace vistream::client
