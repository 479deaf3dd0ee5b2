#pragma once
// The gRPC edge of the server: the vistream.v1.Walkthrough service (callback API: one read and
// one write in flight per session, never blocking a reactor on visibility work), the standard
// health service and reflection, keepalive and message-size limits, and draining on shutdown.

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include <absl/status/statusor.h>
#include <grpcpp/grpcpp.h>

#include "proto/walkthrough.grpc.pb.h"
#include "server/event_log.h"
#include "server/served_scene.h"
#include "server/session.h"

namespace vistream::server {

struct ServerOptions {
  std::string listen = "127.0.0.1:50051";  // host:port; port 0 picks a free one
  size_t max_sessions = 256;
  SessionLimits limits;
  // Client messages larger than this are refused (RESOURCE_EXHAUSTED); 0: 1 MiB plus room for
  // a Hello that lists every object of the scene.
  size_t max_receive_bytes = 0;
};

class SessionLink;

// Session is served raw (bytes in, bytes out) so that bytes that are no ClientMessage end the
// session with INVALID_ARGUMENT naming them, rather than looking like a closed stream.
class WalkthroughService final
    : public vistream::v1::Walkthrough::WithRawCallbackMethod_Session<
          vistream::v1::Walkthrough::WithCallbackMethod_GetStats<vistream::v1::Walkthrough::Service>> {
 public:
  WalkthroughService(ServedScene* scene, const ServerOptions& options, EventLog* log);

  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Session(grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context, const vistream::v1::StatsRequest* request,
                                     vistream::v1::ServerStats* response) override;

  // Refuses new sessions and ends every open one with UNAVAILABLE.
  void Drain();
  vistream::v1::ServerStats Stats() const;
  size_t active_sessions() const;

  // Called by a session's reactor when it is done.
  void Remove(uint64_t id, const grpc::Status& status);

 private:
  ServedScene* scene_;
  ServerOptions options_;
  EventLog* log_;
  const double start_s_;
  std::atomic<bool> draining_{false};
  mutable std::mutex mu_;
  uint64_t next_id_ = 1;
  uint64_t sessions_total_ = 0;
  uint64_t bytes_sent_ended_ = 0;  // of sessions that ended
  struct Entry {
    std::shared_ptr<server::Session> session;
    std::shared_ptr<SessionLink> link;
    std::string peer;
  };
  std::map<uint64_t, Entry> sessions_;
};

// A running server: the service on its port, with health and reflection.
class WalkthroughServer {
 public:
  // Errors: UNAVAILABLE when the address cannot be bound (naming it).
  static absl::StatusOr<std::unique_ptr<WalkthroughServer>> Start(ServedScene* scene, const ServerOptions& options,
                                                                  EventLog* log);
  ~WalkthroughServer();

  int port() const { return port_; }
  const std::string& address() const { return address_; }
  WalkthroughService& service() { return *service_; }
  // Drains: health NOT_SERVING, every session ended with UNAVAILABLE, then the server stops,
  // cancelling what has not finished after `grace_s` seconds.
  void Shutdown(double grace_s);

 private:
  WalkthroughServer() = default;
  std::unique_ptr<WalkthroughService> service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::string address_;
  bool shut_down_ = false;
};

}  // namespace vistream::server
