#include "server/session_reactor.h"

#include <algorithm>
#include <chrono>
#include <string>

#include <absl/strings/str_cat.h>

#include "server/emulated_link.h"

namespace vistream::server {

namespace v1 = vistream::v1;

grpc::Status ToGrpcStatus(const absl::Status& status) {
  return grpc::Status(static_cast<grpc::StatusCode>(status.code()), std::string(status.message()));
}

double SteadySeconds() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

class SessionReactor : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>, public SessionEndpoint {
 public:
  SessionReactor(std::shared_ptr<Session> session, std::shared_ptr<SessionLink> link, SessionReactorSettings settings)
      : settings_(std::move(settings)), session_(std::move(session)), link_(std::move(link)) {
    if (const std::optional<LinkParams>& p = settings_.link; p.has_value()) {
      // Two streams of draws per session, reproducible from the server's seed: session 1 draws
      // as the simulator does with the same seed (uplink: seed, downlink: seed + 1).
      const uint64_t seed = settings_.link_seed + 2 * (session_->id() - 1);
      up_.emplace(*p, seed);
      down_.emplace(*p, seed + 1, settings_.max_in_link_bytes);
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
        const LinkModel::Delivery d = up_->Send(now, std::move(message), bytes.size());
        ++figures_.uplink_messages;
        figures_.uplink_delay_sum_s += d.arrival_s - now;
        WakeAt(d.arrival_s);
        // A client that floods the link waits for it, as TCP's window would make it.
        if (up_->in_flight() < kMaxUpward) {
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
      EndWith(ToGrpcStatus(st));
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
    if (settings_.done) settings_.done(session_->id(), status_, down_.has_value() ? &figures_ : nullptr);
    delete this;
  }

  // Hands due client messages to the session (emulation), starts the next write if none is in
  // flight, and finishes the call when asked to and idle.
  void Pump() override {
    if (up_.has_value()) DeliverUpward();
    PumpWrites();
  }

  void EndWith(const grpc::Status& status) override {
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
      const std::optional<double> next = up_->next_arrival_s();
      if (finish_requested_ || !next.has_value() || *next > SteadySeconds()) return;
    }
  }

  // Hands the session every client message that has arrived; false when the session ended.
  bool DeliverDue() {
    for (;;) {
      std::optional<v1::ClientMessage> m;
      {
        std::lock_guard lock(mu_);
        if (finish_requested_) return false;
        m = up_->TakeArrived(SteadySeconds());
        if (!m.has_value()) break;
      }
      const absl::Status st = session_->OnMessage(*m, SteadySeconds());
      if (!st.ok()) {
        std::lock_guard lock(mu_);
        if (!finish_requested_) {
          finish_requested_ = true;
          status_ = ToGrpcStatus(st);
        }
        return false;
      }
    }
    std::lock_guard lock(mu_);
    if (finish_requested_) return false;
    if (read_paused_ && up_->in_flight() < kMaxUpward) {
      read_paused_ = false;
      StartRead(&in_);
    }
    // The next one is due later: wake then, whatever the downlink is doing (a write to a client
    // that stopped reading must not hold its poses back).
    if (const std::optional<double> next = up_->next_arrival_s(); next.has_value()) WakeAt(*next);
    return true;
  }

  void PumpWrites() {
    std::lock_guard lock(mu_);
    if (finished_ || writing_) return;
    if (!finish_requested_) {
      if (absl::Status f = session_->failure(); !f.ok()) {
        finish_requested_ = true;
        status_ = ToGrpcStatus(f);
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
      if (!down_->Free(now)) break;
      const double send_s = std::max(next_->taken_s, down_->free_s());
      const size_t size = next_->bytes.size();
      const LinkModel::Delivery d = down_->Send(send_s, std::move(next_->bytes), size);
      ++figures_.messages;
      figures_.jitter_sum_s += d.jitter_s;
      figures_.jitter_max_s = std::max(figures_.jitter_max_s, d.jitter_s);
      figures_.delay_sum_s += d.arrival_s - next_->taken_s;
      figures_.max_in_link_bytes = std::max<uint64_t>(figures_.max_in_link_bytes, down_->in_flight_bytes());
      next_.reset();
    }
    if (std::optional<std::string> bytes = down_->TakeArrived(now); bytes.has_value()) {
      Write(*std::move(bytes));
      // OnWriteDone pumps again; only the link's own times need the timer.
      if (next_.has_value() && down_->free_s() > now) WakeAt(down_->free_s());
      return;
    }
    if (const std::optional<double> arrival = down_->next_arrival_s(); arrival.has_value()) WakeAt(*arrival);
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
    if (settings_.timer == nullptr) return;
    // Held weakly: a session that ended by then is skipped.
    settings_.timer->At(at_s, [weak = std::weak_ptr<SessionLink>(link_)] {
      if (std::shared_ptr<SessionLink> link = weak.lock(); link != nullptr) link->Pump();
    });
  }

  const SessionReactorSettings settings_;
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
  std::optional<EmulatedLink<std::string>> down_;     // serialized ServerMessages
  std::optional<EmulatedLink<v1::ClientMessage>> up_;  // client messages, seen by the session on arrival
  struct Taken {
    double taken_s;
    std::string bytes;
  };
  std::optional<Taken> next_;  // taken from the session, waiting for the link to be free
  bool read_paused_ = false;
  std::mutex deliver_mu_;
  double wake_at_ = 0.0;  // the latest wake asked of the timer
  LinkFigures figures_;
};

namespace {

class RefusedReactor : public grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer> {
 public:
  explicit RefusedReactor(const grpc::Status& status) { Finish(status); }
  void OnDone() override { delete this; }
};

}  // namespace

void SessionLink::Attach(SessionEndpoint* endpoint) {
  std::lock_guard lock(mu_);
  endpoint_ = endpoint;
}

void SessionLink::Detach() {
  std::lock_guard lock(mu_);
  endpoint_ = nullptr;
}

void SessionLink::Pump() {
  std::lock_guard lock(mu_);
  if (endpoint_ != nullptr) endpoint_->Pump();
}

void SessionLink::End(const grpc::Status& status) {
  std::lock_guard lock(mu_);
  if (endpoint_ != nullptr) endpoint_->EndWith(status);
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* StartSessionReactor(std::shared_ptr<Session> session,
                                                                                 std::shared_ptr<SessionLink> link,
                                                                                 SessionReactorSettings settings) {
  return new SessionReactor(std::move(session), std::move(link), std::move(settings));
}

grpc::ServerBidiReactor<grpc::ByteBuffer, grpc::ByteBuffer>* RefuseSession(const grpc::Status& status) {
  return new RefusedReactor(status);
}

}  // namespace vistream::server
