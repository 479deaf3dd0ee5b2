#pragma once
// The thin client's network side (DESIGN.md "Server and client"): one thread that keeps a
// walkthrough session open, reconnecting with back-off after a dropped connection and telling
// the server on resume what it holds (Hello.held_objects); it sends the latest pose at a steady
// rate with its velocity, grants byte credit as geometry and ε-masks arrive (a mask costs its
// run-length triangle bytes, as the server charges it), and decodes what the server
// sends (meshoptimizer geometry, PVS lists, ε-masks, eviction hints) into events. The render
// loop takes the events with Take(), which never waits on the network: the lock it shares
// with the network thread is held only to append or swap a vector.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <variant>
#include <vector>

#include <absl/status/status.h>
#include <absl/status/statusor.h>
#include <glm/vec3.hpp>
#include <grpcpp/grpcpp.h>

#include "client/channel_security.h"
#include "client/client_model.h"
#include "proto/pvs_delta.h"
#include "proto/walkthrough.grpc.pb.h"
#include "scenes/mesh.h"

namespace vistream::client {

struct ConnectionOptions {
  std::string address;                 // host:port of vistream-server
  std::string scene;                   // Hello.scene: the name the server serves
  uint64_t memory_budget_bytes = 0;    // Hello: decoded bytes the client may hold; 0 unlimited
  uint64_t triangle_budget = 0;        // Hello: triangles per frame; 0 unlimited
  double pose_rate_hz = kPoseRateHz;   // poses sent per second (the server allows 120)
  uint64_t credit_window_bytes = CreditWindow::kDefaultBytes;  // encoded geometry and mask bytes in flight at most
  bool epsilon_masks = false;          // Hello: the client draws ε-masks (the server sends none otherwise)
  // Hello.levels (issue 45): the screen error tau in pixels the client accepts on its viewport
  // (0: full detail); with levels the lists come as differences (Hello.pvs_deltas).
  double screen_error_px = 0.0;
  bool clusters = false;              // with levels: Hello asks for cluster levels (LevelRequest.clusters)
  uint32_t viewport_width_px = 1280, viewport_height_px = 720;
  double vertical_fov_rad = 1.0471975511965976;
  double connect_timeout_s = 10.0;     // per attempt
  double max_backoff_s = 4.0;          // reconnect back-off doubles from 0.25 s up to this
  ChannelSecurity security;            // TLS and the bearer token (client/channel_security.h)
};

// One decoded object: scene-local metres (z up), triangle list as the server sent it.
struct ReceivedObject {
  uint32_t id = 0;
  scenes::Mesh mesh;
  glm::dvec3 bounds_min{0.0}, bounds_max{0.0};
  uint64_t raw_bytes = 0;  // scenes::RawMeshBytes: the server's accounting
  uint32_t level = 0;      // its level of detail (0: full)
  bool keeps_triangles = true;  // ε-mask bits apply (DecodedObject::keeps_triangles)
  uint64_t saved_bytes = 0;     // what the level saved the link (DecodedObject::saved_bytes)
};

struct SessionEnded {
  absl::Status status;  // why the session ended for good (not a dropped connection)
};

// A cluster level (issue 45): decoded, drawn as one piece per object where a list chooses it.
using ReceivedCluster = DecodedCluster;

// What the network thread hands the render loop, in arrival order.
using Event = std::variant<vistream::v1::SceneInfo, vistream::v1::ViewcellPvs, ReceivedObject, vistream::v1::Evict,
                           vistream::v1::EpsilonMask, SessionEnded, ReceivedCluster>;

struct ConnectionStats {
  uint64_t bytes_received = 0;   // serialized ServerMessage bytes
  uint64_t geometry_bytes = 0;   // encoded geometry
  uint64_t mask_bytes = 0;       // ε-masks' run-length triangle bytes (EpsilonMask.triangles): credit consumed
  uint64_t masks_received = 0;
  uint64_t objects_received = 0;
  uint64_t duplicates = 0;       // geometry received for an object already held at the same level
  uint64_t level_objects = 0;    // geometry received at a coarser level than full (issue 45)
  uint64_t level_bytes_saved = 0;  // encoded bytes those levels (and cluster levels) saved against full meshes
  uint64_t cluster_levels = 0;   // ClusterGeometry received (issue 45)
  uint64_t reconnects = 0;       // sessions after the first that the server answered
  uint64_t poses_sent = 0;
  double backoff_s = 0.0;        // the last wait before a reconnect attempt (0.25 s doubling to max_backoff_s)
};

// A channel to `address` as every client session uses it: keepalive every 30 s, 64 MiB
// messages, quick reconnects (250 ms to 2 s), its own connection (no subchannel sharing); TLS
// when security.tls_ca is set. (The token goes on each call: Authorize.)
std::shared_ptr<grpc::Channel> MakeChannel(const std::string& address, const ChannelSecurity& security = {});

// Checks that `address` answers as a vistream server of this protocol version and returns the
// scene it serves. Errors (naming the address): UNAVAILABLE when nothing answers within
// `timeout_s`, or at once when a TLS handshake is what fails (saying why: DiagnoseTls),
// FAILED_PRECONDITION when it speaks another protocol version, UNAUTHENTICATED when it wants a
// token or refuses this one (ExplainRefusal), CANCELLED as soon as `cancel` (may be null) is set.
absl::StatusOr<vistream::v1::ServerStats> Probe(const std::string& address, double timeout_s,
                                                const std::atomic<bool>* cancel = nullptr,
                                                const ChannelSecurity& security = {});

// The scene to ask for (Hello.scene) from what `stats` (Probe) says the server at `address`
// serves: `wanted` when it is one of them, else its only scene. Errors: NOT_FOUND naming the
// scenes when `wanted` is not served, or when it is empty and the server serves several.
absl::StatusOr<std::string> PickScene(const vistream::v1::ServerStats& stats, const std::string& wanted,
                                      const std::string& address);

class Connection {
 public:
  explicit Connection(ConnectionOptions options);
  ~Connection();  // closes the session and joins the thread
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  // Starts the network thread; the session opens at once, the first pose goes out when
  // SetPose is first called.
  void Start();
  // The pose to report next (scene-local metres, m/s, radians); returns at once.
  void SetPose(const glm::dvec3& position, const glm::dvec3& velocity, double yaw_rad, double pitch_rad,
               double client_time_s);
  // Everything that arrived since the last call, in order; never waits on the network.
  std::vector<Event> Take();
  // Objects the render side dropped on its own (over its memory budget): not held any more,
  // so a resumed session does not claim them.
  void Forget(const std::vector<uint32_t>& ids);
  // Ends the session (WritesDone) and stops reconnecting; returns the final status.
  absl::Status Stop();
  // Drops the current connection as a network failure would (tests): the thread reconnects.
  void DropForTest();

  ConnectionStats stats() const;
  // Whether the current session has heard from the server (false while reconnecting).
  bool connected() const { return connected_.load(); }

 private:
  void Run();
  // One session from connect to end; returns its status, and whether the server answered.
  grpc::Status RunSession(bool* answered);
  void ReadLoop(grpc::ClientReaderWriter<vistream::v1::ClientMessage, vistream::v1::ServerMessage>* stream);
  // Ends the session for good on bad data from the server (DATA_LOSS with `why`).
  void Fail(const std::string& why);
  void Push(Event e);

  ConnectionOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<vistream::v1::Walkthrough::Stub> stub_;
  std::thread thread_;

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<Event> inbox_;
  bool stop_ = false;
  bool have_pose_ = false;
  vistream::v1::Pose pose_;
  std::map<uint32_t, uint32_t> held_;  // received and not evicted, with its level: Hello.held_objects on resume
  std::map<uint32_t, uint32_t> held_clusters_;  // cluster levels likewise: Hello.held_clusters
  proto::PvsListDecoder lists_;        // the session's PVS lists (differences, with levels)
  CreditWindow credit_;                // the session's grants (client/client_model.h)
  bool reader_done_ = false;
  grpc::ClientContext* context_ = nullptr;  // of the session in progress, for Stop/Drop
  ConnectionStats stats_;
  absl::Status final_status_;
  std::atomic<bool> connected_{false};
};

}  // namespace vistream::client
