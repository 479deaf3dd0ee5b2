#pragma once
// One direction of an emulated link with what is on it: the LinkModel (server/link_model.h:
// bandwidth, latency, jitter, loss) and the messages it carries, in order, each delivered when
// its modelled arrival is due. The one emulation that the server's link emulation
// (`vistream-server --emulate-link`, server/session_reactor.h, both directions) puts its
// messages through, and that a discrete-event simulator can drive on its own clock: the clock
// is the caller's, in seconds (steady or simulated); nothing here reads a clock or sleeps.
//
// Not thread-safe (the caller locks); deterministic for a seed and a sequence of calls.

#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <optional>
#include <utility>

#include "server/link_model.h"

namespace vistream::server {

template <typename Payload>
class EmulatedLink {
 public:
  // `params` already time-scaled (LinkParamsFrom); `seed` seeds the model's jitter and loss
  // draws. `max_in_flight_bytes` bounds what Free() lets onto the link: payload bytes sent and
  // not yet taken out (the server's downlink: SessionLimits::max_queued_bytes).
  EmulatedLink(const LinkParams& params, uint64_t seed,
               size_t max_in_flight_bytes = std::numeric_limits<size_t>::max())
      : model_(params, seed), max_in_flight_bytes_(max_in_flight_bytes) {}

  // Whether the link takes a message at `now_s`: the previous message has left (free_s() <=
  // now_s) and fewer than max_in_flight_bytes payload bytes are on it.
  bool Free(double now_s) const { return model_.free_s() <= now_s && in_flight_bytes_ < max_in_flight_bytes_; }

  // Puts `payload` (`payload_bytes` bytes of serialized message; the model adds the wire's
  // framing) on the link at `send_s` seconds, not before the previous Send's `send_s`. It goes
  // out once the link is free (LinkModel::Send) and arrives at the returned arrival_s; arrivals
  // never go backwards. Send does not check Free(): a caller that bounds the link asks first.
  LinkModel::Delivery Send(double send_s, Payload payload, size_t payload_bytes) {
    const LinkModel::Delivery d = model_.Send(send_s, payload_bytes);
    in_flight_.push_back(InFlight{d.arrival_s, payload_bytes, std::move(payload)});
    in_flight_bytes_ += payload_bytes;
    return d;
  }

  // The oldest message on the link when it has arrived by `now_s` (taken off the link); none
  // while the link is empty or its oldest message is not yet due. Messages come out in the
  // order they were sent.
  std::optional<Payload> TakeArrived(double now_s) {
    if (in_flight_.empty() || in_flight_.front().arrival_s > now_s) return std::nullopt;
    InFlight front = std::move(in_flight_.front());
    in_flight_.pop_front();
    in_flight_bytes_ -= front.bytes;
    return std::move(front.payload);
  }

  // When the oldest message on the link arrives (seconds, the caller's clock); none when empty.
  std::optional<double> next_arrival_s() const {
    if (in_flight_.empty()) return std::nullopt;
    return in_flight_.front().arrival_s;
  }
  // When the link is free to take the next message (the previous one's LinkModel sent_s).
  double free_s() const { return model_.free_s(); }
  // Messages and payload bytes on the link: sent, not yet taken out.
  size_t in_flight() const { return in_flight_.size(); }
  size_t in_flight_bytes() const { return in_flight_bytes_; }
  // Bytes on the modelled wire so far (server/link_model.h WireBytes of every message sent).
  uint64_t wire_bytes() const { return model_.wire_bytes(); }
  uint64_t lost_segments() const { return model_.lost_segments(); }
  const LinkParams& params() const { return model_.params(); }

 private:
  struct InFlight {
    double arrival_s;
    size_t bytes;
    Payload payload;
  };
  LinkModel model_;
  const size_t max_in_flight_bytes_;
  std::deque<InFlight> in_flight_;  // in the order sent (arrivals ascending)
  size_t in_flight_bytes_ = 0;
};

}  // namespace vistream::server
