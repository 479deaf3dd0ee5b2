#include "server/service.h"

#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <deque>
#include <queue>
#include <thread>
#include <vector>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>

#include "server/service_metrics.h"

namespace vistream::server {

namespace {

namespace v1 = vistream::v1;

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

grpc::Status ToGrpc(const absl::Status& s) {
  return grpc::Status(static_cast<grpc::StatusCode>(s.code()), std::string(s.message()));
}

class SessionReactor;

}  // namespace

// Lets worker threads (and the link timer) wake a session's reactor, and outlives it: the
// reactor detaches itself in OnDone, after which a wake does nothing. The mutex is recursive:
// with link emulation a wake may hand a client message to the session, whose handler must be
// free to wake the reactor again.
class SessionLink {
 public:
  void Attach(SessionReactor* r) {
    std::lock_guard lock(mu_);
    reactor_ = r;
  }
  void Detach() {
    std::lock_guard lock(mu_);
    reactor_ = nullptr;
  }
  void Pump();
  void End(const grpc::Status& status);

 private:
  std::recursive_mutex mu_;
  SessionReactor* reactor_ = nullptr;
};

// One thread for the whole server that wakes sessions whose emulated link has something due
// (a message arriving, the link free again). Entries hold the link weakly: a session that
// ended is skipped.
class LinkTimer {
 public:
  LinkTimer() : thread_([this] { Run(); }) {}
  ~LinkTimer() {
    {
      std::lock_guard lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
    thread_.join();
  }
  void At(double at_s, std::weak_ptr<SessionLink> link) {
    {
      std::lock_guard lock(mu_);
      due_.push(Due{at_s, std::move(link)});
    }
    cv_.notify_all();
  }

 private:
  struct Due {
    double at_s;
    std::weak_ptr<SessionLink> link;
    bool operator>(const Due& o) const { return at_s > o.at_s; }
  };
  void Run() {
    std::unique_lock lock(mu_);
    while (!stop_) {
      if (due_.empty()) {
        cv_.wait(lock);
        continue;
      }
      const double at = due_.top().at_s;
      if (at > SteadySeconds()) {
        cv_.wait_until(lock, std::chrono::steady_clock::time_point(std::chrono::duration_cast<
                                 std::chrono::steady_clock::duration>(std::chrono::duration<double>(at))));
        continue;
      }
      std::weak_ptr<SessionLink> weak = due_.top().link;
      due_.pop();
      lock.unlock();
      if (std::shared_ptr<SessionLink> link = weak.lock(); link != nullptr) link->Pump();
      lock.lock();
    }
  }

  std::mutex mu_;
  std::condition_variable cv_;
  std::priority_queue<Due, std::vector<Due>, std::greater<Due>> due_;
  bool stop_ = false;
  std::thread thread_;  // last: starts after the members above exist
};

namespace {

class SessionReactor : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  SessionReactor(WalkthroughService* service, std::shared_ptr<Session> session, std::shared_ptr<SessionLink> link)
      : service_(service), session_(std::move(session)), link_(std::move(link)) {
    if (const std::optional<LinkParams>& p = service_->options().link; p.has_value()) {
      // Two streams of draws per session, reproducible from the server's seed: session 1 draws
      // as the simulator does with the same seed (uplink: seed, downlink: seed + 1).
      const uint64_t seed = service_->options().link_seed + 2 * (session_->id() - 1);
      up_.emplace(*p, seed);
      down_.emplace(*p, seed + 1);
    }
    link_->Attach(this);
    StartRead(&in_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {  // the client closed its side, or the call was cancelled
      EndWith(grpc::Status::OK);
      return;
    }
    ++reads_;
    v1::ClientMessage message;
    std::vector<grpc::Slice> slices;
    std::string bytes;
    if (in_.Dump(&slices).ok()) {
      for (const grpc::Slice& sl : slices) bytes.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
    }
    if (!message.ParseFromString(bytes)) {
      EndWith(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                           absl::StrCat("message ", reads_, " (", bytes.size(), " bytes) is not a ClientMessage")));
      return;
    }
    if (up_.has_value()) {
      // Emulated uplink: the session sees the message at its modelled arrival, in order.
      {
        std::lock_guard lock(mu_);
        const double now = SteadySeconds();
        const LinkModel::Delivery d = up_->Send(now, bytes.size());
        ++figures_.uplink_messages;
        figures_.uplink_delay_sum_s += d.arrival_s - now;
        upward_.push_back(Upward{d.arrival_s, std::move(message)});
        WakeAt(d.arrival_s);
        // A client that floods the link waits for it, as TCP's window would make it.
        if (upward_.size() < kMaxUpward) {
          StartRead(&in_);
        } else {
          read_paused_ = true;
        }
      }
      Pump();
      return;
    }
    const absl::Status st = session_->OnMessage(message, SteadySeconds());
    if (!st.ok()) {
      EndWith(ToGrpc(st));
      return;
    }
    StartRead(&in_);
    Pump();
  }

  void OnWriteDone(bool ok) override {
    {
      std::lock_guard lock(mu_);
      writing_ = false;
      if (!ok && !finish_requested_) {  // the client is gone
        finish_requested_ = true;
        status_ = grpc::Status(grpc::StatusCode::UNAVAILABLE, "the client stopped receiving");
        write_failed_ = true;
      }
    }
    Pump();
  }

  void OnCancel() override {
    const grpc::Status cancelled(grpc::StatusCode::CANCELLED, "cancelled by the client (or its connection lost)");
    {
      // A client that goes away (killed, its connection lost) ends its reads too, which may come
      // first and end the call as a client that closed its side does, and a write in flight
      // fails before the cancel is seen: the log says which it was, a cancel.
      std::lock_guard lock(mu_);
      if (finish_requested_ && (status_.ok() || write_failed_)) status_ = cancelled;
    }
    EndWith(cancelled);
  }

  void OnDone() override {
    link_->Detach();
    session_->End();
    if (down_.has_value()) {
      figures_.wire_bytes = down_->wire_bytes();
      figures_.lost_segments = down_->lost_segments();
    }
    service_->Remove(session_->id(), status_, down_.has_value() ? &figures_ : nullptr);
    delete this;
  }

  // Hands due client messages to the session (emulation), starts the next write if none is in
  // flight, and finishes the call when asked to and idle.
  void Pump() {
    if (up_.has_value()) DeliverUpward();
    PumpWrites();
  }

  void EndWith(const grpc::Status& status) {
    {
      std::lock_guard lock(mu_);
      if (finish_requested_) return;
      finish_requested_ = true;
      status_ = status;
    }
    PumpWrites();
  }

 private:
  static constexpr size_t kMaxUpward = 64;  // client messages in the emulated uplink at most

  void DeliverUpward() {
    // One deliverer at a time, so that messages stay in order. A caller that finds another at
    // work leaves it to that one, which looks again after it lets go (a message may have come
    // due meanwhile); a re-entrant call from the session's own handler returns at once.
    for (;;) {
      {
        std::unique_lock order(deliver_mu_, std::try_to_lock);
        if (!order.owns_lock()) return;
        if (!DeliverDue()) return;
      }
      std::lock_guard lock(mu_);
      if (finish_requested_ || upward_.empty() || upward_.front().arrival_s > SteadySeconds()) return;
    }
  }

  // Hands the session every client message that has arrived; false when the session ended.
  bool DeliverDue() {
    for (;;) {
      std::optional<v1::ClientMessage> m;
      {
        std::lock_guard lock(mu_);
        if (finish_requested_) return false;
        if (upward_.empty() || upward_.front().arrival_s > SteadySeconds()) break;
        m = std::move(upward_.front().message);
        upward_.pop_front();
      }
      const absl::Status st = session_->OnMessage(*m, SteadySeconds());
      if (!st.ok()) {
        std::lock_guard lock(mu_);
        if (!finish_requested_) {
          finish_requested_ = true;
          status_ = ToGrpc(st);
        }
        return false;
      }
    }
    std::lock_guard lock(mu_);
    if (finish_requested_) return false;
    if (read_paused_ && upward_.size() < kMaxUpward) {
      read_paused_ = false;
      StartRead(&in_);
    }
    // The next one is due later: wake then, whatever the downlink is doing (a write to a client
    // that stopped reading must not hold its poses back).
    if (!upward_.empty()) WakeAt(upward_.front().arrival_s);
    return true;
  }

  void PumpWrites() {
    std::lock_guard lock(mu_);
    if (finished_ || writing_) return;
    if (!finish_requested_) {
      if (absl::Status f = session_->failure(); !f.ok()) {
        finish_requested_ = true;
        status_ = ToGrpc(f);
      }
    }
    if (finish_requested_) {
      finished_ = true;
      Finish(status_);
      return;
    }
    if (!down_.has_value()) {
      std::optional<v1::ServerMessage> next = session_->NextMessage();
      if (!next.has_value()) return;
      Write(next->SerializeAsString());
      return;
    }
    // Emulated downlink. The link takes the session's next message when it is free (the
    // previous message's sent_s); one message taken early waits for it, so that it goes on the
    // link the moment the link is free whatever the timer's delay. What waits in the link is
    // bounded: it holds what it transmitted in the last latency (plus jitter), at most
    // max_queued_bytes.
    const double now = SteadySeconds();
    for (;;) {
      if (!next_.has_value()) {
        std::optional<v1::ServerMessage> m = session_->NextMessage();
        if (!m.has_value()) break;
        next_ = Taken{now, m->SerializeAsString()};
      }
      if (down_->free_s() > now || in_link_bytes_ >= service_->options().limits.max_queued_bytes) break;
      const double send_s = std::max(next_->taken_s, down_->free_s());
      const LinkModel::Delivery d = down_->Send(send_s, next_->bytes.size());
      ++figures_.messages;
      figures_.jitter_sum_s += d.jitter_s;
      figures_.jitter_max_s = std::max(figures_.jitter_max_s, d.jitter_s);
      figures_.delay_sum_s += d.arrival_s - next_->taken_s;
      in_link_bytes_ += next_->bytes.size();
      figures_.max_in_link_bytes = std::max<uint64_t>(figures_.max_in_link_bytes, in_link_bytes_);
      in_link_.push_back(InLink{d.arrival_s, std::move(next_->bytes)});
      next_.reset();
    }
    if (!in_link_.empty() && in_link_.front().arrival_s <= now) {
      std::string bytes = std::move(in_link_.front().bytes);
      in_link_bytes_ -= bytes.size();
      in_link_.pop_front();
      Write(std::move(bytes));
      // OnWriteDone pumps again; only the link's own times need the timer.
      if (next_.has_value() && down_->free_s() > now) WakeAt(down_->free_s());
      return;
    }
    if (!in_link_.empty()) WakeAt(in_link_.front().arrival_s);
    if (next_.has_value() && down_->free_s() > now) WakeAt(down_->free_s());
  }

  void Write(std::string bytes) {  // mu_ held
    grpc::Slice slice(std::move(bytes));
    out_ = grpc::ByteBuffer(&slice, 1);
    writing_ = true;
    StartWrite(&out_);
  }

  // Asks the server's link timer to pump this session at `at_s`, unless a wake at or before
  // it is pending already. mu_ held.
  void WakeAt(double at_s) {
    const double now = SteadySeconds();
    if (wake_at_ > now && wake_at_ <= at_s) return;
    wake_at_ = at_s;
    service_->WakeAt(at_s, link_);
  }

  WalkthroughService* service_;
  std::shared_ptr<Session> session_;
  std::shared_ptr<SessionLink> link_;
  grpc::ByteBuffer in_, out_;
  uint64_t reads_ = 0;
  std::mutex mu_;
  bool writing_ = false;
  bool finish_requested_ = false;
  bool write_failed_ = false;  // status_ came from a failed write (the client gone), not the session
  bool finished_ = false;
  grpc::Status status_;

  // Link emulation (ServerOptions::link); empty without it.
  std::optional<LinkModel> down_, up_;
  struct Taken {
    double taken_s;
    std::string bytes;
  };
  std::optional<Taken> next_;  // taken from the session, waiting for the link to be free
  struct InLink {
    double arrival_s;
    std::string bytes;
  };
  std::deque<InLink> in_link_;  // on the modelled wire, in order
  size_t in_link_bytes_ = 0;
  struct Upward {
    double arrival_s;
    v1::ClientMessage message;
  };
  std::deque<Upward> upward_;  // client messages on the modelled uplink, in order
  bool read_paused_ = false;
  std::mutex deliver_mu_;
  double wake_at_ = 0.0;  // the latest wake asked of the timer
  LinkFigures figures_;
};

// Ends a session that may not start (too many, draining) with `status`.
class RefusedReactor : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  explicit RefusedReactor(const grpc::Status& status) { Finish(status); }
  void OnDone() override { delete this; }
};

}  // namespace

void SessionLink::Pump() {
  std::lock_guard lock(mu_);
  if (reactor_ != nullptr) reactor_->Pump();
}

void SessionLink::End(const grpc::Status& status) {
  std::lock_guard lock(mu_);
  if (reactor_ != nullptr) reactor_->EndWith(status);
}

WalkthroughService::WalkthroughService(std::vector<ServedScene*> scenes, const ServerOptions& options, EventLog* log)
    : scenes_{std::move(scenes)}, options_(options), log_(log), start_s_(SteadySeconds()),
      quota_(options.max_sessions_per_address, options.max_sessions_per_token) {
  if (options_.link.has_value()) timer_ = std::make_unique<LinkTimer>();
  if (options_.hello_timeout_s > 0.0) hello_watchdog_ = std::make_unique<HelloWatchdog>(options_.hello_timeout_s);
}

WalkthroughService::~WalkthroughService() = default;

void WalkthroughService::WakeAt(double at_s, const std::shared_ptr<SessionLink>& link) {
  if (timer_ != nullptr) timer_->At(at_s, link);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* WalkthroughService::Session(
    grpc::CallbackServerContext* context) {
  // Security (server/security.h, server/admission.h): the token before any work.
  std::string tenant;
  if (options_.tokens != nullptr) {
    absl::StatusOr<std::string> t = Authenticate(*options_.tokens, context->client_metadata());
    if (!t.ok()) {
      Refused(context, "Session", "unauthenticated", std::string(t.status().message()));
      return new RefusedReactor(ToGrpc(t.status()));
    }
    tenant = *std::move(t);
  }
  const std::string host = PeerHost(context->peer());
  std::lock_guard lock(mu_);
  if (draining_) {
    Refused(context, "Session", "draining", "the server is shutting down");
    return new RefusedReactor(grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
  }
  if (sessions_.size() >= options_.max_sessions) {
    Refused(context, "Session", "too_many", "too many sessions");
    return new RefusedReactor(grpc::Status(
        grpc::StatusCode::RESOURCE_EXHAUSTED,
        absl::StrCat("too many sessions: this server holds at most ", options_.max_sessions, " at once")));
  }
  if (absl::Status q = quota_.Admit(host, tenant); !q.ok()) {
    Refused(context, "Session", tenant.empty() || q.message().find("tenant") == absl::string_view::npos ? "per_address"
                                                                                                      : "per_token",
            std::string(q.message()));
    return new RefusedReactor(ToGrpc(q));
  }
  const uint64_t id = next_id_++;
  ++sessions_total_;
  auto link = std::make_shared<SessionLink>();
  // One scene: the session is bound to it (its Hello must name it); several: Hello picks.
  SessionSeams seams;
  if (options_.metrics != nullptr) options_.metrics->AddSessionSeams(&seams);
  std::shared_ptr<server::Session> session =
      scenes_.scenes.size() == 1
          ? Session::Create(id, scenes_.scenes[0], options_.limits, log_, [link] { link->Pump(); }, std::move(seams))
          : Session::Create(id, &scenes_, options_.limits, log_, [link] { link->Pump(); }, std::move(seams));
  sessions_[id] = Entry{session, link, context->peer(), host, tenant};
  if (log_ != nullptr) {
    if (tenant.empty()) {
      log_->Write(id, "session_start", {{"peer", context->peer()}});
    } else {
      log_->Write(id, "session_start", {{"peer", context->peer()}, {"tenant", tenant}});
    }
  }
  if (hello_watchdog_ != nullptr) {
    hello_watchdog_->Watch(session, [weak = std::weak_ptr<SessionLink>(link), t = options_.hello_timeout_s] {
      if (std::shared_ptr<SessionLink> l = weak.lock(); l != nullptr) {
        l->End(grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED, absl::StrFormat("no Hello within %g s", t)));
      }
    });
  }
  return new SessionReactor(this, session, link);
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
      Refused(context, "GetStats", "unauthenticated", std::string(t.status().message()));
      reactor->Finish(ToGrpc(t.status()));
      return reactor;
    }
  }
  *response = Stats();
  reactor->Finish(grpc::Status::OK);
  return reactor;
}

void WalkthroughService::Refused(grpc::CallbackServerContext* context, const char* call, const char* reason,
                                 const std::string& message) {
  if (options_.metrics != nullptr) options_.metrics->SessionRefused(reason);
  if (log_ != nullptr) {
    log_->Write(EventLog::Level::kWarn, 0, "refused",
                {{"call", call}, {"peer", context->peer()}, {"reason", reason}, {"message", message}});
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
  size_t max_receive = options.max_receive_bytes;
  if (max_receive == 0) {
    size_t objects = 0;
    for (const ServedScene* scene : scenes) objects = std::max(objects, scene->scene().objects.size());
    max_receive = (size_t{1} << 20) + 5 * objects;
  }
  builder.SetMaxReceiveMessageSize(static_cast<int>(std::min<size_t>(max_receive, 1u << 30)));
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
