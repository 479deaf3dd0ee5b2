#pragma once
// The gRPC edge of the server: the vistream.v1.Walkthrough service, its start (the standard
// health service and reflection, keepalive and message-size limits), the admission of sessions
// (tokens, quotas, the Hello watchdog), their statistics, and draining on shutdown. Each
// admitted session is served by its reactor (server/session_reactor.h: one read and one write
// in flight, never blocking on visibility work, the emulated link).

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include <absl/status/statusor.h>
#include <grpcpp/grpcpp.h>

#include "proto/walkthrough.grpc.pb.h"
#include "server/admission.h"
#include "server/event_log.h"
#include "server/link_model.h"
#include "server/security.h"
#include "server/served_scene.h"
#include "server/session.h"
#include "server/session_reactor.h"

namespace vistream::server {

class ServiceMetrics;

struct ServerOptions {
  std::string listen = "127.0.0.1:50051";  // host:port; port 0 picks a free one
  size_t max_sessions = 256;
  SessionLimits limits;
  // Client messages larger than this are refused (RESOURCE_EXHAUSTED); 0: 1 MiB plus room for
  // a Hello that lists every object of the scene.
  size_t max_receive_bytes = 0;
  // Link emulation (vistream-server --emulate-link): every session's messages go through this
  // link, already time-scaled (server/link_model.h), on the steady clock, in both directions
  // (a model each way). None: written at once.
  std::optional<LinkParams> link;
  // Server metrics (server/service_metrics.h; not owned, must outlive the server); null: none.
  ServiceMetrics* metrics = nullptr;
  // Session n's uplink draws from link_seed + 2(n - 1), its downlink from one more (session 1
  // as `vistream simulate --seed link_seed`).
  uint64_t link_seed = 1;
  // Security (server/security.h). Credentials: what ServerCredentialsFor gives; null: plaintext.
  std::shared_ptr<grpc::ServerCredentials> credentials;
  // Null: no authentication; else Session and GetStats need one of its tokens (UNAUTHENTICATED
  // otherwise, before any work). Health is open either way.
  std::shared_ptr<TokenStore> tokens;
  size_t max_sessions_per_address = 0;  // sessions at once from one client IP address; 0: no limit
  size_t max_sessions_per_token = 0;    // sessions at once per tenant; 0: no limit
  double hello_timeout_s = 30.0;        // a stream without Hello this long ends DEADLINE_EXCEEDED; 0: never
};

// Session is served raw (bytes in, bytes out) so that bytes that are no ClientMessage end the
// session with INVALID_ARGUMENT naming them, rather than looking like a closed stream.
class WalkthroughService final
    : public vistream::v1::Walkthrough::WithRawCallbackMethod_Session<
          vistream::v1::Walkthrough::WithCallbackMethod_GetStats<vistream::v1::Walkthrough::Service>> {
 public:
  // Serves `scenes` (not owned; at least one; distinct names): a session's Hello picks one.
  WalkthroughService(std::vector<ServedScene*> scenes, const ServerOptions& options, EventLog* log);
  ~WalkthroughService() override;

  grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* Session(grpc::CallbackServerContext* context) override;
  grpc::ServerUnaryReactor* GetStats(grpc::CallbackServerContext* context, const vistream::v1::StatsRequest* request,
                                     vistream::v1::ServerStats* response) override;

  // Refuses new sessions and ends every open one with UNAVAILABLE.
  void Drain();
  vistream::v1::ServerStats Stats() const;
  // Sessions open, and ended ones whose end is not yet logged (so that once this is 0, every
  // `session_end` line is written).
  size_t active_sessions() const;

  // A session admitted: what its transport serves it with.
  struct Admitted {
    std::shared_ptr<server::Session> session;
    std::shared_ptr<SessionLink> link;  // the transport attaches itself (SessionLink::Attach)
  };
  // Admits a session from `peer` (a gRPC peer string, "ipv4:HOST:PORT" or "ipv6:[HOST]:PORT")
  // for `tenant` (its token already checked; empty without authentication) over `transport`
  // ("grpc", "websocket": the session_start line and vistream_sessions_started_total{transport}).
  // The same rules for every transport: refused while draining (UNAVAILABLE), beyond
  // max_sessions or a per-address or per-tenant quota (RESOURCE_EXHAUSTED, naming the limit);
  // a refusal is logged and counted (Refused). The Hello watchdog ends an admitted session
  // whose Hello does not come in time (through its link). The transport calls Remove when the
  // session is done.
  absl::StatusOr<Admitted> Admit(const std::string& peer, const std::string& tenant, const std::string& transport);
  // A call refused before any work: logged (warn, "refused") and counted
  // (vistream_sessions_refused_total{reason}). `peer` as for Admit.
  void Refused(const std::string& peer, const char* call, const char* reason, const std::string& message);
  // Called by a session's reactor when it is done (SessionReactorSettings::done); `link` is
  // null without emulation.
  void Remove(uint64_t id, const grpc::Status& status, const LinkFigures* link = nullptr);
  const ServerOptions& options() const { return options_; }
  // The largest client message taken (ServerOptions::max_receive_bytes, or its default: 1 MiB
  // plus room for a Hello that lists every object of the largest scene). Every transport's limit.
  size_t max_receive_bytes() const;

 private:
  SceneDirectory scenes_;
  ServerOptions options_;
  EventLog* log_;
  const double start_s_;
  std::atomic<bool> draining_{false};
  mutable std::mutex mu_;
  uint64_t next_id_ = 1;
  uint64_t sessions_total_ = 0;
  uint64_t bytes_sent_ended_ = 0;  // of sessions that ended
  struct SceneTotals {
    uint64_t ended = 0;      // sessions of the scene that ended
    uint64_t bytes_sent = 0;  // by them
    uint64_t geometry_bytes_sent = 0;
  };
  std::map<std::string, SceneTotals> scene_totals_;  // by scene name
  size_t ending_ = 0;              // removed from sessions_, their end not yet logged
  struct Entry {
    std::shared_ptr<server::Session> session;
    std::shared_ptr<SessionLink> link;
    std::string peer;
    std::string host, tenant;  // as counted by quota_
    std::string transport;     // "grpc", "websocket"
  };
  std::map<uint64_t, Entry> sessions_;
  SessionQuota quota_;
  std::unique_ptr<HelloWatchdog> hello_watchdog_;  // none without a Hello timeout
  std::unique_ptr<DueTimer> timer_;  // with link emulation: wakes sessions when their link is due
};

// A running server: the service on its port, with health and reflection.
class WalkthroughServer {
 public:
  // Errors: UNAVAILABLE when the address cannot be bound (naming it).
  static absl::StatusOr<std::unique_ptr<WalkthroughServer>> Start(ServedScene* scene, const ServerOptions& options,
                                                                  EventLog* log);
  // Serves every scene of `scenes` (not owned; at least one, distinct names).
  static absl::StatusOr<std::unique_ptr<WalkthroughServer>> Start(std::vector<ServedScene*> scenes,
                                                                  const ServerOptions& options, EventLog* log);
  ~WalkthroughServer();

  int port() const { return port_; }
  const std::string& address() const { return address_; }
  WalkthroughService& service() { return *service_; }
  // The first step of a drain, for load balancers: the standard health service says
  // NOT_SERVING (vistream-server's /healthz says 503 from the signal on), while every session,
  // and every new one, goes on being served for `drain_s` seconds, so that the balancer's
  // health checks take this server out before its sessions end; returns early once no session
  // is open (nothing left to protect). Returns the seconds waited. Shutdown follows.
  double HoldDrain(double drain_s);
  // Drains: health NOT_SERVING, every session ended with UNAVAILABLE (the client reconnects,
  // through a balancer to another replica, and resumes with what it holds), then the server
  // stops, cancelling what has not finished after `grace_s` seconds.
  void Shutdown(double grace_s);

 private:
  WalkthroughServer() = default;
  void StopServingHealth();
  std::unique_ptr<WalkthroughService> service_;
  std::unique_ptr<grpc::Server> server_;
  int port_ = 0;
  std::string address_;
  bool shut_down_ = false;
};

}  // namespace vistream::server
