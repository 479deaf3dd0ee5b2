// The link model the simulator and the server's emulation share (server/link_model.h).

#include "server/link_model.h"

#include <cmath>

#include <gtest/gtest.h>

namespace vistream::server {
namespace {

scenes::LinkSpec Spec(std::optional<double> mbps, std::optional<double> ms, std::optional<double> jitter = std::nullopt,
                      std::optional<double> loss = std::nullopt) {
  scenes::LinkSpec s;
  s.bandwidth_mbps = mbps;
  s.latency_ms = ms;
  s.jitter_ms = jitter;
  s.loss_pct = loss;
  return s;
}

TEST(LinkModel, AnUndeclaredLinkIsIdeal) {
  const LinkParams p = LinkParamsFrom(std::nullopt);
  EXPECT_TRUE(p.ideal());
  EXPECT_EQ(p.Describe(), "ideal");
  LinkModel link(p, 1);
  for (double t : {0.0, 0.5, 0.5, 3.0}) {
    const LinkModel::Delivery d = link.Send(t, 1 << 20);
    EXPECT_EQ(d.sent_s, t);
    EXPECT_EQ(d.arrival_s, t);
    EXPECT_EQ(d.jitter_s, 0.0);
  }
}

TEST(LinkModel, WireBytesCountFramesAndSegments) {
  EXPECT_EQ(WireBytes(0), 5u + 9u + 52u);
  EXPECT_EQ(WireBytes(1000), 1005u + 9u + 52u);
  // 1448 * 10 payload bytes on the stream take 11 segments once the prefix and frame header
  // are added.
  const size_t p = 14480;
  EXPECT_EQ(WireBytes(p), p + 5 + 9 + 11 * 52);
  // Two HTTP/2 frames past 16 KiB.
  EXPECT_EQ(WireBytes(20000) - 20000 - 5, 2u * 9u + 14u * 52u);
}

TEST(LinkModel, BandwidthSerialisesMessagesAndLatencyDelaysThem) {
  const LinkParams p = LinkParamsFrom(Spec(1.0, 200.0));
  EXPECT_EQ(p.Describe(), "1 Mbit/s, 200 ms");
  LinkModel link(p, 1);
  const double t1 = WireBytes(100000) * 8.0 / 1e6;
  const LinkModel::Delivery a = link.Send(10.0, 100000);
  EXPECT_DOUBLE_EQ(a.sent_s, 10.0 + t1);
  EXPECT_DOUBLE_EQ(a.arrival_s, 10.0 + t1 + 0.2);
  // Handed over before the first has left: it waits for the link.
  const LinkModel::Delivery b = link.Send(10.0, 100000);
  EXPECT_DOUBLE_EQ(b.sent_s, 10.0 + 2 * t1);
  EXPECT_DOUBLE_EQ(b.arrival_s, 10.0 + 2 * t1 + 0.2);
  // After an idle time it starts at once.
  const LinkModel::Delivery c = link.Send(20.0, 0);
  EXPECT_DOUBLE_EQ(c.arrival_s, 20.0 + WireBytes(0) * 8.0 / 1e6 + 0.2);
  EXPECT_EQ(link.wire_bytes(), 2 * WireBytes(100000) + WireBytes(0));
}

TEST(LinkModel, JitterIsUniformUpToTwiceTheMeanAndNeverReorders) {
  LinkModel link(LinkParamsFrom(Spec(std::nullopt, 50.0, 20.0)), 7);
  double sum = 0.0, last = 0.0, min_j = 1.0, max_j = 0.0;
  constexpr int kMessages = 20000;
  for (int k = 0; k < kMessages; ++k) {
    const LinkModel::Delivery d = link.Send(k * 0.001, 100);
    EXPECT_GE(d.jitter_s, 0.0);
    EXPECT_LE(d.jitter_s, 0.040);
    EXPECT_GE(d.arrival_s, last);
    EXPECT_GE(d.arrival_s, k * 0.001 + 0.050);
    last = d.arrival_s;
    sum += d.jitter_s;
    min_j = std::min(min_j, d.jitter_s);
    max_j = std::max(max_j, d.jitter_s);
  }
  EXPECT_NEAR(sum / kMessages, 0.020, 0.0005);
  EXPECT_LT(min_j, 0.001);
  EXPECT_GT(max_j, 0.039);
}

TEST(LinkModel, ASceneWithoutJitterGetsNone) {
  LinkModel link(LinkParamsFrom(Spec(20.0, 40.0)), 7);
  for (int k = 0; k < 1000; ++k) EXPECT_EQ(link.Send(k * 0.01, 5000).jitter_s, 0.0);
}

TEST(LinkModel, LostSegmentsAreRecoveredLaterAndHoldBackWhatFollows) {
  const LinkParams p = LinkParamsFrom(Spec(1.0, 200.0, std::nullopt, 1.0));
  EXPECT_DOUBLE_EQ(p.recovery_s, 0.4);  // a round trip: more than the 200 ms minimum timeout
  LinkModel link(p, 3);
  uint64_t segments = 0, delayed = 0;
  double last = 0.0;
  for (int k = 0; k < 2000; ++k) {
    const size_t bytes = 1448 * 20;
    const double send = link.free_s() > 0 ? link.free_s() : 0.0;
    const LinkModel::Delivery d = link.Send(send, bytes);
    segments += (WireBytes(bytes) + 1499) / 1500;
    EXPECT_GE(d.arrival_s, last);
    if (d.lost_segments > 0) {
      ++delayed;
      EXPECT_GE(d.arrival_s, d.sent_s + 0.2 + 0.4 - (d.sent_s - send) - 1e-9);
    } else {
      EXPECT_GE(d.arrival_s, d.sent_s + 0.2 - 1e-12);
    }
    last = d.arrival_s;
  }
  const double lost = static_cast<double>(link.lost_segments()) / static_cast<double>(segments);
  EXPECT_NEAR(lost, 0.01, 0.002) << link.lost_segments() << " of " << segments;
  EXPECT_GT(delayed, 100u);
}

TEST(LinkModel, ATimeScaleSpeedsUpEveryEffectAlike) {
  const LinkParams p = LinkParamsFrom(Spec(1.0, 200.0, 20.0, 1.0), 10.0);
  EXPECT_DOUBLE_EQ(p.bandwidth_bps, 1e7);
  EXPECT_DOUBLE_EQ(p.latency_s, 0.02);
  EXPECT_DOUBLE_EQ(p.jitter_s, 0.002);
  EXPECT_DOUBLE_EQ(p.recovery_s, 0.048);  // (2 * 200 + 4 * 20 ms) / 10
  EXPECT_DOUBLE_EQ(p.loss, 0.01);
}

TEST(LinkModel, TheLinkOptionParsesBandwidthAndLatencyAndKeepsTheRest) {
  absl::StatusOr<scenes::LinkSpec> s = ParseLinkOption("1M,200", Spec(10.0, 80.0, 20.0, 0.5));
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_DOUBLE_EQ(*s->bandwidth_mbps, 1.0);
  EXPECT_DOUBLE_EQ(*s->latency_ms, 200.0);
  EXPECT_DOUBLE_EQ(*s->jitter_ms, 20.0);
  EXPECT_DOUBLE_EQ(*s->loss_pct, 0.5);
  s = ParseLinkOption("250000,0", std::nullopt);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_DOUBLE_EQ(*s->bandwidth_mbps, 0.25);
  EXPECT_FALSE(s->jitter_ms.has_value());
  ASSERT_TRUE(ParseLinkOption("2.5k,12.5", std::nullopt).ok());
  ASSERT_TRUE(ParseLinkOption("1G,1", std::nullopt).ok());
  for (const char* bad : {"", "1M", "1M,", ",200", "x,200", "1M,x", "1m,200", "0x10,200", "1M, 200", "+1M,200",
                          "-1M,200", "1M,-5", "nan,200", "1M,inf", "999,10", "2000G,10", "1M,200,3"}) {
    const absl::StatusOr<scenes::LinkSpec> r = ParseLinkOption(bad, std::nullopt);
    EXPECT_FALSE(r.ok()) << bad;
    if (!r.ok()) {
      EXPECT_NE(r.status().message().find("--link"), std::string::npos) << r.status();
      EXPECT_NE(r.status().message().find(std::string("'") + bad + "'"), std::string::npos) << r.status();
    }
  }
}

}  // namespace
}  // namespace vistream::server
