#include "server/link_model.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <vector>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

namespace vistream::server {

namespace {

constexpr size_t kSegmentPayload = 1448;  // TCP MSS on a 1500-byte MTU with timestamps
constexpr size_t kSegmentHeaders = 52;    // IPv4 20 + TCP 20 + timestamps 12
constexpr size_t kFramePayload = 16384;   // HTTP/2's default SETTINGS_MAX_FRAME_SIZE
constexpr size_t kFrameHeader = 9;
constexpr size_t kGrpcPrefix = 5;         // compressed flag + length
constexpr double kMinRto = 0.2;           // Linux's TCP_RTO_MIN

// A whole finite decimal (from_chars: no hex, no spaces, no '+', no inf/nan).
bool ParseDecimal(std::string_view text, double* v) {
  if (text.empty()) return false;
  const char* end = text.data() + text.size();
  auto [ptr, ec] = std::from_chars(text.data(), end, *v, std::chars_format::fixed);
  return ec == std::errc() && ptr == end && std::isfinite(*v);
}

}  // namespace

bool LinkParams::ideal() const {
  return std::isinf(bandwidth_bps) && latency_s == 0.0 && jitter_s == 0.0 && loss == 0.0;
}

std::string LinkParams::Describe() const {
  if (ideal()) return "ideal";
  std::vector<std::string> parts;
  if (std::isinf(bandwidth_bps)) {
    parts.push_back("unlimited bandwidth");
  } else if (bandwidth_bps >= 1e6) {
    parts.push_back(absl::StrFormat("%g Mbit/s", bandwidth_bps / 1e6));
  } else {
    parts.push_back(absl::StrFormat("%g kbit/s", bandwidth_bps / 1e3));
  }
  parts.push_back(absl::StrFormat("%g ms", latency_s * 1e3));
  if (jitter_s > 0.0) parts.push_back(absl::StrFormat("jitter %g ms", jitter_s * 1e3));
  if (loss > 0.0) parts.push_back(absl::StrFormat("loss %g%%", loss * 100.0));
  std::string out = parts[0];
  for (size_t k = 1; k < parts.size(); ++k) absl::StrAppend(&out, ", ", parts[k]);
  return out;
}

LinkParams LinkParamsFrom(const std::optional<scenes::LinkSpec>& spec, double time_scale) {
  LinkParams p;
  if (spec.has_value()) {
    if (spec->bandwidth_mbps.has_value()) p.bandwidth_bps = *spec->bandwidth_mbps * 1e6;
    if (spec->latency_ms.has_value()) p.latency_s = *spec->latency_ms * 1e-3;
    if (spec->jitter_ms.has_value()) p.jitter_s = *spec->jitter_ms * 1e-3;
    if (spec->loss_pct.has_value()) p.loss = std::min(0.999, *spec->loss_pct * 1e-2);
  }
  p.recovery_s = p.loss > 0.0 ? std::max(kMinRto, 2.0 * p.latency_s + 4.0 * p.jitter_s) : 0.0;
  const double k = time_scale > 0.0 ? time_scale : 1.0;
  p.bandwidth_bps *= k;
  p.latency_s /= k;
  p.jitter_s /= k;
  p.recovery_s /= k;
  return p;
}

absl::StatusOr<scenes::LinkSpec> ParseLinkOption(std::string_view text, const std::optional<scenes::LinkSpec>& declared,
                                                 std::string_view option) {
  auto bad = [&](std::string_view why) {
    return absl::InvalidArgumentError(absl::StrCat(std::string(option), ": '", std::string(text), "': ", std::string(why),
                                                   " (expected BPS,LATENCY_MS, e.g. 1M,200: bits per second with an "
                                                   "optional k, M or G, and one-way milliseconds)"));
  };
  const size_t comma = text.find(',');
  if (comma == std::string_view::npos) return bad("no comma");
  if (text.find(',', comma + 1) != std::string_view::npos) {
    return bad("more than two fields (jitter and loss come from the scene's declared link)");
  }
  std::string_view bps = text.substr(0, comma), ms = text.substr(comma + 1);
  if (bps.find_first_of("eE") != std::string_view::npos) return bad("the bandwidth has an exponent: write a plain decimal");
  if (ms.find_first_of("eE") != std::string_view::npos) return bad("the latency has an exponent: write a plain decimal");
  double scale = 1.0;
  if (!bps.empty()) {
    switch (bps.back()) {
      case 'k': scale = 1e3; break;
      case 'M': scale = 1e6; break;
      case 'G': scale = 1e9; break;
      default: break;
    }
    if (scale != 1.0) bps.remove_suffix(1);
  }
  double b = 0.0, l = 0.0;
  if (!ParseDecimal(bps, &b)) return bad("the bandwidth is not a number");
  b *= scale;
  if (!(b >= 1e3 && b <= 1e12)) return bad("the bandwidth must be from 1k to 1000G bits per second");
  if (!ParseDecimal(ms, &l)) return bad("the latency is not a number");
  if (!(l >= 0.0 && l <= 1e5)) return bad("the latency must be from 0 to 100000 ms");
  scenes::LinkSpec spec;
  if (declared.has_value()) spec = *declared;
  spec.bandwidth_mbps = b / 1e6;
  spec.latency_ms = l;
  return spec;
}

size_t WireBytes(size_t payload) {
  const size_t stream = payload + kGrpcPrefix;
  const size_t frames = std::max<size_t>(1, (stream + kFramePayload - 1) / kFramePayload);
  const size_t tcp = stream + frames * kFrameHeader;
  const size_t segments = std::max<size_t>(1, (tcp + kSegmentPayload - 1) / kSegmentPayload);
  return tcp + segments * kSegmentHeaders;
}

LinkModel::LinkModel(const LinkParams& params, uint64_t seed) : params_(params), rng_(seed) {}

LinkModel::Delivery LinkModel::Send(double send_s, size_t payload) {
  Delivery d;
  const size_t wire = WireBytes(payload);
  wire_bytes_ += wire;
  const double start = std::max(send_s, free_s_);
  const double transmit = std::isinf(params_.bandwidth_bps) ? 0.0 : static_cast<double>(wire) * 8.0 / params_.bandwidth_bps;
  d.sent_s = start + transmit;
  free_s_ = d.sent_s;
  double arrival = d.sent_s + params_.latency_s;
  if (params_.jitter_s > 0.0) {
    d.jitter_s = rng_.Uniform(0.0, 2.0 * params_.jitter_s);
    arrival += d.jitter_s;
  }
  if (params_.loss > 0.0) {
    // Each segment independently; a lost one arrives a recovery time after it would have.
    const size_t segments = (wire + kSegmentPayload + kSegmentHeaders - 1) / (kSegmentPayload + kSegmentHeaders);
    for (size_t s = 0; s < segments; ++s) {
      if (!rng_.Chance(params_.loss)) continue;
      ++d.lost_segments;
      const double segment_sent = start + transmit * static_cast<double>(s + 1) / static_cast<double>(segments);
      arrival = std::max(arrival, segment_sent + params_.latency_s + d.jitter_s + params_.recovery_s);
    }
    lost_segments_ += d.lost_segments;
  }
  d.arrival_s = std::max(arrival, last_arrival_s_);
  last_arrival_s_ = d.arrival_s;
  return d;
}

}  // namespace vistream::server
