#pragma once
// One walkthrough session seen from the client side: opens the stream, sends Hello, poses and
// credit, and records on its own thread everything the server sends, with arrival times.
// Used by the server's end-to-end tests and `vistream bench server` to script sessions; the
// thin client's own network thread is client/connection.h.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <glm/vec3.hpp>
#include <grpcpp/grpcpp.h>

#include "client/cell_completion.h"
#include "client/channel_security.h"
#include "client/client_model.h"
#include "proto/pvs_delta.h"
#include "proto/walkthrough.grpc.pb.h"

namespace vistream::client {

struct SessionRecord {
  bool scene_info = false;
  vistream::v1::SceneInfo info;
  // Every message kind in arrival order: 'S' scene info, 'P' PVS, 'G' geometry, 'C' cluster
  // geometry, 'E' evict, 'M' ε-mask; with the cell, object, cluster or mask id.
  std::vector<std::pair<char, uint32_t>> order;
  std::map<uint32_t, std::vector<uint32_t>> pvs;  // latest list per cell
  std::vector<uint32_t> pvs_order;                // cells in arrival order
  std::map<uint32_t, vistream::v1::ObjectGeometry> geometry;  // latest per object
  std::set<uint32_t> held;                        // received and not evicted
  uint64_t duplicates = 0;                        // geometry received while held at the same level
  uint64_t level_objects = 0;                     // geometry received at a level of detail (issue 45)
  std::map<uint32_t, uint32_t> clusters;          // cluster levels held (not evicted): id -> level
  std::map<uint32_t, vistream::v1::ClusterGeometry> cluster_geometry;  // latest per cluster (with geometry kept)
  std::vector<uint32_t> evicted_clusters;
  uint64_t cluster_levels = 0;                    // ClusterGeometry messages received
  std::map<uint32_t, std::pair<std::vector<uint32_t>, std::vector<uint32_t>>> pvs_clusters;  // per cell: ids, levels
  // PVS lists as the server sent them may be differences (Hello.pvs_deltas); `pvs` holds them
  // whole. A list that does not decode ends the reading: why, here.
  std::string bad_data;
  uint64_t geometry_bytes = 0;
  std::vector<vistream::v1::EpsilonMask> masks;
  uint64_t mask_bytes = 0;  // the masks' run-length triangle bytes: credit they consumed
  std::vector<uint32_t> evicted;
  uint64_t raw_geometry_bytes = 0;  // what the geometry received would be unencoded
  bool ended = false;
  // Seconds (steady clock) at which each cell became complete, in order: its PVS list and every
  // object in it had arrived (a PVS list sent again starts the cell over).
  std::map<uint32_t, std::vector<double>> complete_s;
  // The first time at or after `t` that `cell` became complete; negative if it has not.
  double CompletedAfter(uint32_t cell, double t) const;

  // Whether the cell's PVS and the geometry of every object in it have arrived (and not been
  // evicted): the client model's rule (client/cell_completion.h).
  bool CellComplete(uint32_t cell) const { return completion_.Complete(cell); }
  // Whether every one of `cells` (a container of cell ids) is complete.
  template <typename Cells>
  bool AllComplete(const Cells& cells) const {
    for (uint32_t c : cells) {
      if (!CellComplete(c)) return false;
    }
    return true;
  }

 private:
  friend class SessionStream;
  CellCompletion completion_;  // the lists and objects above, as the rule keeps them
};

class SessionStream {
 public:
  // `security`: TLS and the bearer token (client/channel_security.h); none by default.
  explicit SessionStream(const std::string& address, const ChannelSecurity& security = {});
  ~SessionStream();

  // Opens the session and sends `hello`; with `read` false nothing is read (a stalled client).
  // Keepalive pings every 30 s (the server accepts them every 10 s or more). A connection
  // attempt that fails (a busy listen queue refuses some of many simultaneous connects) is
  // retried with gRPC's back-off for up to kConnectTimeoutS; past that the stream ends
  // UNAVAILABLE.
  static constexpr double kConnectTimeoutS = 10.0;
  void Start(const vistream::v1::Hello& hello, bool read = true);
  // Before Start: a cluster level the resuming client holds (as its Hello.held_clusters says),
  // with the objects it stands for (what its ClusterGeometry said), so that its record counts it.
  void HoldCluster(uint32_t cluster, uint32_t level, std::vector<uint32_t> objects);
  // Opens the session with `first` as its first message, whatever it is (bad-input tests).
  void StartRaw(const vistream::v1::ClientMessage& first);
  // A Hello for `scene` with the current protocol version (client/client_model.h MakeHello).
  static vistream::v1::Hello HelloFor(const std::string& scene, std::vector<uint32_t> held = {});

  // Whether to keep every ObjectGeometry message (tests decode them); off, only counts are kept.
  void set_keep_geometry(bool keep) { keep_geometry_ = keep; }

  bool Send(const vistream::v1::ClientMessage& m);
  bool SendPose(const glm::dvec3& position, const glm::dvec3& velocity = glm::dvec3(0.0));
  bool SendCredit(uint64_t bytes);

  // Waits up to `timeout_s` for `done(received)` to hold; false on timeout or end.
  bool WaitFor(const std::function<bool(const SessionRecord&)>& done, double timeout_s);
  // A copy of what has arrived so far.
  SessionRecord Snapshot() const;
  // Whether the server has ended the stream (or it broke).
  bool Ended() const;
  // Closes the client side and returns the session's status.
  grpc::Status Finish();
  // Waits for the server to end the session (without closing our side first).
  grpc::Status AwaitEnd(double timeout_s);
  void Cancel() { context_.TryCancel(); }

 private:
  void OpenStream();
  void ReadLoop();

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<vistream::v1::Walkthrough::Stub> stub_;
  const ChannelSecurity security_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<vistream::v1::ClientMessage, vistream::v1::ServerMessage>> stream_;
  std::thread reader_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  SessionRecord received_;
  proto::PvsListDecoder lists_;  // the session's PVS lists (differences, with levels)
  double time_s_ = 0.0;
  bool finished_ = false;
  bool keep_geometry_ = true;
  grpc::Status status_;
};

}  // namespace vistream::client
