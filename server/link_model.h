#pragma once
// A network link as a catalog entry declares it (`simulation.link`), one direction of it: the
// one model that both the simulator (`vistream simulate`, simulation/simulator.h) and the server's
// link emulation (`vistream-server --emulate-link`) put messages through, so that a simulated
// run and a real one over loopback differ only in what the model leaves out.
//
// What is modelled, and only when the entry declares it (an undeclared effect is ideal):
// - bandwidth: messages leave one after another; a message takes WireBytes(payload) * 8 /
//   bandwidth seconds to transmit, starting when the link is free;
// - latency: one-way propagation delay, added to every message;
// - jitter: every message is delayed by a further draw, uniform in [0, 2 * jitter] (mean
//   jitter), but never overtakes the message before it (TCP delivers in order);
// - loss: each TCP segment (1448 payload bytes) is lost with the declared probability; a lost
//   segment is retransmitted one recovery time later (max(200 ms, 2 * latency + 4 * jitter):
//   Linux's minimum retransmission timeout, or a round trip with its jitter), and what follows
//   it waits (head-of-line blocking). Congestion control's back-off is not modelled.
// Times are seconds on the caller's clock (simulated or steady). A time scale k (for real runs
// that replay a long walk quickly) multiplies the bandwidth by k and divides every time by k.

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <string_view>

#include <absl/status/statusor.h>

#include "scenes/catalog.h"
#include "scenes/random.h"

namespace vistream::server {

// A link's effects, resolved: an undeclared effect is ideal.
struct LinkParams {
  double bandwidth_bps = std::numeric_limits<double>::infinity();  // bits per second
  double latency_s = 0.0;                                          // one way
  double jitter_s = 0.0;                                           // mean extra delay
  double loss = 0.0;                                               // per TCP segment, [0, 1)
  double recovery_s = 0.0;  // delay a lost segment adds (set by LinkParamsFrom)

  bool ideal() const;
  // "1 Mbit/s, 200 ms, jitter 20 ms, loss 1%" or "ideal".
  std::string Describe() const;
};

// The declared link (absent: ideal), its times divided and its bandwidth multiplied by
// `time_scale` (> 0). The recovery time is computed before scaling, then scaled.
LinkParams LinkParamsFrom(const std::optional<scenes::LinkSpec>& spec, double time_scale = 1.0);

// Parses `--link BPS,LATENCY_MS` (BPS: bits per second, a plain decimal with an optional k, M
// or G suffix for 10^3, 10^6, 10^9; LATENCY_MS: one-way milliseconds) into a declared link that
// keeps `declared`'s jitter and loss. Errors (INVALID_ARGUMENT) name `option` and the text.
absl::StatusOr<scenes::LinkSpec> ParseLinkOption(std::string_view text, const std::optional<scenes::LinkSpec>& declared,
                                                 std::string_view option = "--link");

// Bytes on the wire for a gRPC message of `payload` bytes on a stream: the 5-byte gRPC prefix,
// a 9-byte HTTP/2 frame header per 16 KiB frame, and 52 bytes of TCP/IP headers per 1448-byte
// segment.
size_t WireBytes(size_t payload);

// One direction of a link. Not thread-safe; deterministic for a seed and a sequence of calls.
class LinkModel {
 public:
  LinkModel(const LinkParams& params, uint64_t seed);

  struct Delivery {
    double sent_s = 0.0;     // when the last bit left: the link is free again
    double arrival_s = 0.0;  // when the whole message is at the other end
    double jitter_s = 0.0;   // the jitter draw this message got (0 without declared jitter)
    uint32_t lost_segments = 0;
  };
  // A message of `payload` bytes handed to the link at `send_s` (not before the previous
  // call's send_s). Arrivals never go backwards.
  Delivery Send(double send_s, size_t payload);

  // When the link is free to take the next message.
  double free_s() const { return free_s_; }
  const LinkParams& params() const { return params_; }
  uint64_t wire_bytes() const { return wire_bytes_; }
  uint64_t lost_segments() const { return lost_segments_; }

 private:
  LinkParams params_;
  scenes::Rng rng_;
  double free_s_ = -std::numeric_limits<double>::infinity();
  double last_arrival_s_ = -std::numeric_limits<double>::infinity();
  uint64_t wire_bytes_ = 0;
  uint64_t lost_segments_ = 0;
};

}  // namespace vistream::server
