#include "server/service.h"

#include <chrono>
#include <cstdlib>
#include <thread>
#include <vector>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>

#include "server/service_metrics.h"
#include "server/session_reactor.h"

namespace vistream::server {

namespace v1 = vistream::v1;

WalkthroughService::WalkthroughService(std::vector<ServedScene*> scenes, const ServerOptions& options, EventLog* log)
    : scenes_{std::move(scenes)}, options_(options), log_(log), start_s_(SteadySeconds()),
      quota_(options.max_sessions_per_address, options.max_sessions_per_token) {
  if (options_.link.has_value()) timer_ = std::make_unique<DueTimer>();
  if (options_.hello_timeout_s > 0.0) hello_watchdog_ = std::make_unique<HelloWatchdog>(options_.hello_timeout_s);
}

WalkthroughService::~WalkthroughService() = default;

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* WalkthroughService::Session(
    grpc::CallbackServerContext* context) {
  // Security (server/security.h, server/admission.h): the token before any work.
  std::string tenant;
  if (options_.tokens != nullptr) {
    absl::StatusOr<std::string> t = Authenticate(*options_.tokens, context->client_metadata());
    if (!t.ok()) {
      Refused(context->peer(), "Session", "unauthenticated", std::string(t.status().message()));
      return RefuseSession(ToGrpcStatus(t.status()));
    }
    tenant = *std::move(t);
  }
  absl::StatusOr<Admitted> admitted = Admit(context->peer(), tenant, "grpc");
  if (!admitted.ok()) return RefuseSession(ToGrpcStatus(admitted.status()));
  SessionReactorSettings settings;
  settings.link = options_.link;
  settings.link_seed = options_.link_seed;
  settings.max_in_link_bytes = options_.limits.max_queued_bytes;
  settings.timer = timer_.get();
  settings.done = [this](uint64_t session_id, const grpc::Status& status, const LinkFigures* figures) {
    Remove(session_id, status, figures);
  };
  return StartSessionReactor(admitted->session, admitted->link, std::move(settings));
}

absl::StatusOr<WalkthroughService::Admitted> WalkthroughService::Admit(const std::string& peer,
                                                                     const std::string& tenant,
                                                                     const std::string& transport) {
  const std::string host = PeerHost(peer);
  std::lock_guard lock(mu_);
  if (draining_) {
    Refused(peer, "Session", "draining", "the server is shutting down");
    return absl::UnavailableError("the server is shutting down");
  }
  if (sessions_.size() >= options_.max_sessions) {
    Refused(peer, "Session", "too_many", "too many sessions");
    return absl::ResourceExhaustedError(
        absl::StrCat("too many sessions: this server holds at most ", options_.max_sessions, " at once"));
  }
  if (absl::Status q = quota_.Admit(host, tenant); !q.ok()) {
    Refused(peer, "Session", tenant.empty() || q.message().find("tenant") == absl::string_view::npos ? "per_address"
                                                                                                   : "per_token",
            std::string(q.message()));
    return q;
  }
  const uint64_t id = next_id_++;
  ++sessions_total_;
  auto link = std::make_shared<SessionLink>();
  // One scene: the session is bound to it (its Hello must name it); several: Hello picks.
  SessionSeams seams;
  if (options_.metrics != nullptr) {
    options_.metrics->AddSessionSeams(&seams);
    options_.metrics->SessionStarted(transport);
  }
  std::shared_ptr<server::Session> session =
      scenes_.scenes.size() == 1
          ? Session::Create(id, scenes_.scenes[0], options_.limits, log_, [link] { link->Pump(); }, std::move(seams))
          : Session::Create(id, &scenes_, options_.limits, log_, [link] { link->Pump(); }, std::move(seams));
  sessions_[id] = Entry{session, link, peer, host, tenant, transport};
  if (log_ != nullptr) {
    if (tenant.empty()) {
      log_->Write(id, "session_start", {{"peer", peer}, {"transport", transport}});
    } else {
      log_->Write(id, "session_start", {{"peer", peer}, {"transport", transport}, {"tenant", tenant}});
    }
  }
  if (hello_watchdog_ != nullptr) {
    hello_watchdog_->Watch(session, [weak = std::weak_ptr<SessionLink>(link), t = options_.hello_timeout_s] {
      if (std::shared_ptr<SessionLink> l = weak.lock(); l != nullptr) {
        l->End(grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, absl::StrFormat("no Hello within %g s", t)));
      }
    });
  }
  return Admitted{std::move(session), std::move(link)};
}

void WalkthroughService::Remove(uint64_t id, const grpc::Status& status, const LinkFigures* link) {
  v1::SessionStats stats;
  {
    std::lock_guard lock(mu_);
    auto it = sessions_.find(id);
    if (it == sessions_.end()) return;
    stats = it->second.session->Stats();
    quota_.Release(it->second.host, it->second.tenant);
    bytes_sent_ended_ += stats.bytes_sent();
    if (!stats.scene().empty()) {
      SceneTotals& t = scene_totals_[stats.scene()];
      ++t.ended;
      t.bytes_sent += stats.bytes_sent();
      t.geometry_bytes_sent += stats.geometry_bytes_sent();
    }
    sessions_.erase(it);
    ++ending_;
  }
  if (log_ != nullptr) {
    const grpc::StatusCode code = status.error_code();
    if (options_.metrics != nullptr) options_.metrics->SessionEnded(stats.scene(), static_cast<int>(code));
    const bool fine = code == grpc::StatusCode::OK || code == grpc::StatusCode::CANCELLED;
    log_->Write(fine ? EventLog::Level::kInfo : EventLog::Level::kWarn, id, "session_end",
                {{"scene", stats.scene()},
                 {"status", grpc::StatusCode(status.error_code()) == grpc::StatusCode::OK ? "OK" : "error"},
                 {"code", static_cast<int>(status.error_code())},
                 {"message", status.error_message()},
                 {"seconds", stats.seconds()},
                 {"crossings", stats.crossings()},
                 {"objects_sent", stats.objects_sent()},
                 {"bytes_sent", stats.bytes_sent()},
                 {"epsilon_masks", stats.epsilon_masks()},
                 {"epsilon_mask_bytes", stats.epsilon_mask_bytes()}});
    if (link != nullptr) {
      const double n = std::max<double>(1.0, static_cast<double>(link->messages));
      const double up = std::max<double>(1.0, static_cast<double>(link->uplink_messages));
      log_->Write(id, "link",
                  {{"messages", link->messages},
                   {"wire_bytes", link->wire_bytes},
                   {"lost_segments", link->lost_segments},
                   {"mean_jitter_ms", 1e3 * link->jitter_sum_s / n},
                   {"max_jitter_ms", 1e3 * link->jitter_max_s},
                   {"mean_delay_ms", 1e3 * link->delay_sum_s / n},
                   {"uplink_messages", link->uplink_messages},
                   {"uplink_mean_delay_ms", 1e3 * link->uplink_delay_sum_s / up},
                   {"max_in_link_bytes", link->max_in_link_bytes}});
    }
    log_->ForgetSession(id);
  }
  std::lock_guard lock(mu_);
  --ending_;
}

grpc::ServerUnaryReactor* WalkthroughService::GetStats(grpc::CallbackServerContext* context,
                                                       const v1::StatsRequest*, v1::ServerStats* response) {
  grpc::ServerUnaryReactor* reactor = context->DefaultReactor();
  if (options_.tokens != nullptr) {
    if (absl::StatusOr<std::string> t = Authenticate(*options_.tokens, context->client_metadata()); !t.ok()) {
      Refused(context->peer(), "GetStats", "unauthenticated", std::string(t.status().message()));
      reactor->Finish(ToGrpcStatus(t.status()));
      return reactor;
    }
  }
  *response = Stats();
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

void WalkthroughService::Refused(const std::string& peer, const char* call, const char* reason,
                                 const std::string& message) {
  if (options_.metrics != nullptr) options_.metrics->SessionRefused(reason);
  if (log_ != nullptr) {
    log_->Write(EventLog::Level::kWarn, 0, "refused",
                {{"call", call}, {"peer", peer}, {"reason", reason}, {"message", message}});
  }
}

void WalkthroughService::Drain() {
  std::map<uint64_t, Entry> open;
  {
    std::lock_guard lock(mu_);
    draining_ = true;
    open = sessions_;
  }
  for (auto& [id, e] : open) e.link->End(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
}

size_t WalkthroughService::max_receive_bytes() const {
  if (options_.max_receive_bytes != 0) return options_.max_receive_bytes;
  size_t objects = 0;
  for (const ServedScene* scene : scenes_.scenes) objects = std::max(objects, scene->scene().objects.size());
  return (size_t{1} << 20) + 5 * objects;
}

size_t WalkthroughService::active_sessions() const {
  std::lock_guard lock(mu_);
  return sessions_.size() + ending_;
}

v1::ServerStats WalkthroughService::Stats() const {
  v1::ServerStats s;
  // Protocol version 1's single scene: the first (default) one.
  s.set_scene(scenes_.scenes.front()->name());
  s.set_protocol_version(v1::PROTOCOL_VERSION_CURRENT);
  s.set_pvs_source(scenes_.scenes.front()->pvs_source());
  s.set_uptime_s(SteadySeconds() - start_s_);
  std::map<std::string, v1::SceneStats*> by_name;
  for (ServedScene* scene : scenes_.scenes) {
    const SchedulerStats sched = scene->scheduler().stats();
    s.set_pvs_computed(s.pvs_computed() + sched.computed);
    s.set_pvs_cache_hits(s.pvs_cache_hits() + sched.cache_hits);
    s.set_pvs_dropped(s.pvs_dropped() + sched.dropped);
    s.set_cache_bytes(s.cache_bytes() + sched.cache_bytes);
    s.set_pvs_compute_s(s.pvs_compute_s() + sched.compute_s);
    s.set_pvs_store_hits(s.pvs_store_hits() + sched.store_hits);
    v1::SceneStats* ss = s.add_scenes();
    ss->set_name(scene->name());
    ss->set_pvs_source(scene->pvs_source());
    ss->set_pvs_computed(sched.computed);
    ss->set_pvs_cache_hits(sched.cache_hits);
    ss->set_pvs_dropped(sched.dropped);
    ss->set_cache_bytes(sched.cache_bytes);
    ss->set_pvs_compute_s(sched.compute_s);
    ss->set_pvs_store_hits(sched.store_hits);
    ss->set_pvs_queued(sched.queued);
    const TaskStats masks = scene->masks().stats();
    ss->set_epsilon_masks_computed(masks.computed);
    ss->set_epsilon_mask_compute_s(masks.cpu_s);
    s.set_epsilon_masks_computed(s.epsilon_masks_computed() + masks.computed);
    s.set_epsilon_mask_compute_s(s.epsilon_mask_compute_s() + masks.cpu_s);
    if (const PvsStore* store = scene->store(); store != nullptr && !s.has_store()) {
      const PvsStoreStats st = store->stats();
      v1::StoreStats* out = s.mutable_store();
      out->set_address(store->address());
      out->set_up(st.up);
      out->set_hits(st.hits);
      out->set_misses(st.misses);
      out->set_bad_entries(st.bad_entries);
      out->set_unavailable(st.unavailable);
      out->set_writes(st.writes);
      out->set_writes_dropped(st.writes_dropped);
      out->set_outages(st.outages);
    }
    ss->set_object_count(static_cast<uint32_t>(scene->scene().objects.size()));
    ss->set_cells(static_cast<uint32_t>(scene->grid().CellCount()));
    by_name[scene->name()] = ss;
  }
  std::lock_guard lock(mu_);
  s.set_sessions_active(sessions_.size());
  s.set_sessions_total(sessions_total_);
  for (const auto& [name, t] : scene_totals_) {
    if (auto it = by_name.find(name); it != by_name.end()) {
      it->second->set_sessions_total(t.ended);
      it->second->set_bytes_sent(t.bytes_sent);
      it->second->set_geometry_bytes_sent(t.geometry_bytes_sent);
    }
  }
  uint64_t bytes = bytes_sent_ended_;
  for (const auto& [id, e] : sessions_) {
    v1::SessionStats* ss = s.add_sessions();
    *ss = e.session->Stats();
    ss->set_peer(e.peer);
    ss->set_transport(e.transport);
    ss->set_tenant(e.tenant);
    bytes += ss->bytes_sent();
    if (auto it = by_name.find(ss->scene()); it != by_name.end()) {
      v1::SceneStats* scene = it->second;
      scene->set_sessions_active(scene->sessions_active() + 1);
      scene->set_sessions_total(scene->sessions_total() + 1);
      scene->set_bytes_sent(scene->bytes_sent() + ss->bytes_sent());
      scene->set_geometry_bytes_sent(scene->geometry_bytes_sent() + ss->geometry_bytes_sent());
    }
  }
  s.set_bytes_sent(bytes);
  return s;
}

absl::StatusOr<std::unique_ptr<WalkthroughServer>> WalkthroughServer::Start(ServedScene* scene,
                                                                            const ServerOptions& options,
                                                                            EventLog* log) {
  return Start(std::vector<ServedScene*>{scene}, options, log);
}

absl::StatusOr<std::unique_ptr<WalkthroughServer>> WalkthroughServer::Start(std::vector<ServedScene*> scenes,
                                                                            const ServerOptions& options,
                                                                            EventLog* log) {
  if (scenes.empty()) return absl::InvalidArgumentError("no scene to serve");
  for (size_t a = 0; a < scenes.size(); ++a) {
    for (size_t b = 0; b < a; ++b) {
      if (scenes[a]->name() == scenes[b]->name()) {
        return absl::InvalidArgumentError(absl::StrCat("two scenes are named '", scenes[a]->name(), "'"));
      }
    }
  }
  // host:port with a port number in [0, 65535] (0: any free one); gRPC would take a port
  // modulo 2^16, or none at all, without a word.
  const size_t colon = options.listen.rfind(':');
  const std::string port = colon == std::string::npos ? "" : options.listen.substr(colon + 1);
  char* end = nullptr;
  const long number = port.empty() ? -1 : std::strtol(port.c_str(), &end, 10);
  if (colon == std::string::npos || colon == 0 || port.empty() || *end != '\0' || number < 0 || number > 65535) {
    return absl::InvalidArgumentError(absl::StrCat("--listen '", options.listen,
                                                   "': expected HOST:PORT with a port from 0 to 65535 "
                                                   "(0: any free port), e.g. 127.0.0.1:50051"));
  }
  if (options.max_sessions == 0) return absl::InvalidArgumentError("--max-sessions must be at least 1");
  if (!(options.hello_timeout_s >= 0.0 && options.hello_timeout_s < 1e9)) {
    return absl::InvalidArgumentError("--hello-timeout must be a number of seconds from 0 (none) up");
  }
  std::unique_ptr<WalkthroughServer> s(new WalkthroughServer());
  s->service_ = std::make_unique<WalkthroughService>(scenes, options, log);
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  builder.AddListeningPort(options.listen,
                           options.credentials != nullptr ? options.credentials : grpc::InsecureServerCredentials(),
                           &s->port_);
  builder.RegisterService(s->service_.get());
  builder.SetMaxReceiveMessageSize(static_cast<int>(std::min<size_t>(s->service_->max_receive_bytes(), 1u << 30)));
  // Keepalive: ping an idle client every 20 s, drop it after 10 s without an answer; accept
  // client pings no more often than every 10 s (clients must keep their interval above it).
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 20000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 10000);
  builder.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  builder.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, 10000);
  // A port in use is an error, not shared with another server (gRPC allows SO_REUSEPORT).
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  s->server_ = builder.BuildAndStart();
  if (s->server_ == nullptr || s->port_ == 0) {
    return absl::UnavailableError(absl::StrCat("cannot listen on ", options.listen,
                                               ": the port is in use or the host is not an address of this machine"));
  }
  const std::string host = options.listen.substr(0, options.listen.rfind(':'));
  s->address_ = absl::StrCat(host, ":", s->port_);
  if (grpc::HealthCheckServiceInterface* health = s->server_->GetHealthCheckService(); health != nullptr) {
    health->SetServingStatus(true);
    health->SetServingStatus("vistream.v1.Walkthrough", true);
  }
  return s;
}

void WalkthroughServer::StopServingHealth() {
  if (grpc::HealthCheckServiceInterface* health = server_->GetHealthCheckService(); health != nullptr) {
    health->SetServingStatus(false);
  }
}

double WalkthroughServer::HoldDrain(double drain_s) {
  const auto start = std::chrono::steady_clock::now();
  if (shut_down_) return 0.0;
  StopServingHealth();
  const auto until = start + std::chrono::microseconds(static_cast<int64_t>(std::max(0.0, drain_s) * 1e6));
  while (service_->active_sessions() > 0 && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void WalkthroughServer::Shutdown(double grace_s) {
  if (shut_down_) return;
  shut_down_ = true;
  StopServingHealth();
  service_->Drain();
  // Sessions end as soon as what is being written goes out; give them the grace to, then stop.
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<int64_t>(grace_s * 1000));
  while (service_->active_sessions() > 0 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  server_->Shutdown(std::chrono::system_clock::now() +
                    std::chrono::duration_cast<std::chrono::milliseconds>(
                        std::max(std::chrono::steady_clock::duration::zero(), deadline - std::chrono::steady_clock::now())));
  server_->Wait();
}

WalkthroughServer::~WalkthroughServer() {
  if (server_ != nullptr) Shutdown(1.0);
}

}  // namespace vistream::server
