#pragma once
// The gRPC side of one walkthrough session (DESIGN.md "Server and client"; STYLE.md "Streaming
// and gRPC habits"): the callback reactor of a Session stream, with one read and one write in
// flight, that hands client messages to the Session (server/session.h) and writes what its
// NextMessage gives, and never blocks on visibility work (workers wake it through its
// SessionLink). With link emulation (`vistream-server --emulate-link`) both directions go
// through an EmulatedLink (server/emulated_link.h) on the steady clock, woken by the server's
// one DueTimer. The service (server/service.h) admits sessions and makes their reactors; a
// reactor reports its end through a callback, so that it does not depend on the service.

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>

#include <absl/status/status.h>
#include <grpcpp/grpcpp.h>

#include "server/due_timer.h"
#include "server/link_model.h"
#include "server/session.h"

namespace vistream::server {

// The gRPC status of an absl status: the same code and message (the RPC edge's one mapping).
grpc::Status ToGrpcStatus(const absl::Status& status);

// Seconds on the steady clock (the reactor's and the link emulation's clock).
double SteadySeconds();

// What one session's emulated link did (its `link` log line).
struct LinkFigures {
  uint64_t messages = 0;       // downlink messages
  uint64_t wire_bytes = 0;     // their bytes on the modelled wire (server/link_model.h WireBytes)
  uint64_t lost_segments = 0;
  double jitter_sum_s = 0.0, jitter_max_s = 0.0;  // the jitter draws
  double delay_sum_s = 0.0;    // taken from the session to arrival: waiting for the link, transmission,
                               // latency, jitter, loss recovery
  uint64_t uplink_messages = 0;
  double uplink_delay_sum_s = 0.0;
  uint64_t max_in_link_bytes = 0;  // the most that waited in the link at once (bounded)
};

// The transport serving one session: the gRPC reactor below, or a WebSocket connection
// (server/web_server.h). Called through the session's SessionLink, from any thread.
class SessionEndpoint {
 public:
  virtual ~SessionEndpoint() = default;
  // Delivers due client messages and starts the next write.
  virtual void Pump() = 0;
  // Ends the session with `status` (once; later ends are ignored).
  virtual void EndWith(const grpc::Status& status) = 0;
};

// Lets worker threads (and the link timer, the Hello watchdog, a drain) wake a session's
// transport, and outlives it: the transport detaches itself when it is done, after which a wake
// does nothing. The mutex is recursive: with link emulation a wake may hand a client message to
// the session, whose handler must be free to wake the reactor again.
class SessionLink {
 public:
  void Attach(SessionEndpoint* endpoint);
  void Detach();
  // Delivers due client messages and starts the next write, if the transport is still there.
  void Pump();
  // Ends the session with `status` (once; later ends are ignored).
  void End(const grpc::Status& status);

 private:
  std::recursive_mutex mu_;
  SessionEndpoint* endpoint_ = nullptr;
};

// What a session's reactor runs with.
struct SessionReactorSettings {
  // Link emulation (ServerOptions::link, already time-scaled); none: messages are written at once.
  std::optional<LinkParams> link;
  // The session's uplink draws from this seed, its downlink from one more.
  uint64_t link_seed = 1;
  // At most this many payload bytes wait in the emulated downlink (SessionLimits::max_queued_bytes).
  size_t max_in_link_bytes = size_t{8} << 20;
  // The server's one timer (server/due_timer.h): wakes the reactor when its link has something
  // due; needed with `link`.
  DueTimer* timer = nullptr;
  // Called once, from the reactor's OnDone, with the call's final status and, with link
  // emulation, what the link did (null without). The session has ended by then.
  std::function<void(uint64_t session_id, const grpc::Status& status, const LinkFigures* link)> done;
};

// Serves `session` on the call the returned reactor belongs to (gRPC owns and deletes it);
// `link` must be the one the session's wake calls Pump on.
grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* StartSessionReactor(std::shared_ptr<Session> session,
                                                                                 std::shared_ptr<SessionLink> link,
                                                                                 SessionReactorSettings settings);

// A reactor that ends a stream that may not start (too many sessions, draining, no token) at
// once with `status`.
grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* RefuseSession(const grpc::Status& status);

}  // namespace vistream::server
