#pragma once
// A scripted walkthrough client for the server's end-to-end tests: opens a session, sends
// Hello, poses and credit, and records everything the server sends, with arrival times.

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

#include "proto/walkthrough.grpc.pb.h"

namespace vistream::testing {

struct Received {
  bool scene_info = false;
  vistream::v1::SceneInfo info;
  // Every message kind in arrival order: 'S' scene info, 'P' PVS, 'G' geometry, 'E' evict,
  // 'M' ε-mask; with the cell or object id.
  std::vector<std::pair<char, uint32_t>> order;
  std::map<uint32_t, std::vector<uint32_t>> pvs;  // latest list per cell
  std::vector<uint32_t> pvs_order;                // cells in arrival order
  std::map<uint32_t, vistream::v1::ObjectGeometry> geometry;  // latest per object
  std::set<uint32_t> held;                        // received and not evicted
  uint64_t duplicates = 0;                        // geometry received while held
  uint64_t geometry_bytes = 0;
  std::vector<vistream::v1::EpsilonMask> masks;
  std::vector<uint32_t> evicted;
  bool ended = false;

  // Whether the cell's PVS and the geometry of every object in it have arrived.
  bool CellComplete(uint32_t cell) const;
};

class WalkClient {
 public:
  explicit WalkClient(const std::string& address);
  ~WalkClient();

  // Opens the session and sends `hello`; with `read` false nothing is read (a stalled client).
  void Start(const vistream::v1::Hello& hello, bool read = true);
  // Opens the session with `first` as its first message, whatever it is (bad-input tests).
  void StartRaw(const vistream::v1::ClientMessage& first);
  // A Hello for `scene` with the current protocol version.
  static vistream::v1::Hello HelloFor(const std::string& scene, std::vector<uint32_t> held = {});

  bool Send(const vistream::v1::ClientMessage& m);
  bool SendPose(const glm::dvec3& position, const glm::dvec3& velocity = glm::dvec3(0.0));
  bool SendCredit(uint64_t bytes);

  // Waits up to `timeout_s` for `done(received)` to hold; false on timeout or end.
  bool WaitFor(const std::function<bool(const Received&)>& done, double timeout_s);
  // A copy of what has arrived so far.
  Received Snapshot() const;
  // Closes the client side and returns the session's status.
  grpc::Status Finish();
  // Waits for the server to end the session (without closing our side first).
  grpc::Status AwaitEnd(double timeout_s);
  void Cancel() { context_.TryCancel(); }

 private:
  void ReadLoop();

  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<vistream::v1::Walkthrough::Stub> stub_;
  grpc::ClientContext context_;
  std::unique_ptr<grpc::ClientReaderWriter<vistream::v1::ClientMessage, vistream::v1::ServerMessage>> stream_;
  std::thread reader_;
  mutable std::mutex mu_;
  std::condition_variable cv_;
  Received received_;
  double time_s_ = 0.0;
  bool finished_ = false;
  grpc::Status status_;
};

}  // namespace vistream::testing
