// One direction of an emulated link with what is on it (server/emulated_link.h): the server's
// link emulation puts both directions of every session through it.

#include "server/emulated_link.h"

#include <string>

#include <gtest/gtest.h>

namespace vistream::server {
namespace {

LinkParams OneMbitTenMs() {
  LinkParams p;
  p.bandwidth_bps = 1e6;
  p.latency_s = 0.010;
  return p;
}

TEST(EmulatedLink, DeliversInOrderOnlyWhenDue) {
  EmulatedLink<std::string> link(OneMbitTenMs(), 1);
  const LinkModel::Delivery a = link.Send(0.0, "a", 1000);
  const LinkModel::Delivery b = link.Send(0.0, "b", 1000);
  EXPECT_GT(b.arrival_s, a.arrival_s);
  EXPECT_EQ(link.in_flight(), 2u);
  EXPECT_EQ(link.in_flight_bytes(), 2000u);
  ASSERT_TRUE(link.next_arrival_s().has_value());
  EXPECT_EQ(*link.next_arrival_s(), a.arrival_s);
  EXPECT_FALSE(link.TakeArrived(a.arrival_s - 1e-6).has_value());
  EXPECT_EQ(link.TakeArrived(b.arrival_s), "a");  // both due: the first sent comes first
  EXPECT_EQ(link.TakeArrived(b.arrival_s), "b");
  EXPECT_FALSE(link.TakeArrived(1e9).has_value());
  EXPECT_FALSE(link.next_arrival_s().has_value());
  EXPECT_EQ(link.in_flight_bytes(), 0u);
  EXPECT_EQ(link.wire_bytes(), 2 * WireBytes(1000));
}

TEST(EmulatedLink, IsFreeWhenTheLastMessageLeftAndTheBoundAllows) {
  EmulatedLink<int> link(OneMbitTenMs(), 1, /*max_in_flight_bytes=*/1500);
  EXPECT_TRUE(link.Free(0.0));
  const LinkModel::Delivery d = link.Send(0.0, 1, 1000);
  EXPECT_FALSE(link.Free(d.sent_s - 1e-6));  // still transmitting
  EXPECT_TRUE(link.Free(d.sent_s));
  link.Send(d.sent_s, 2, 1000);
  EXPECT_FALSE(link.Free(1e9));  // 2000 bytes on the link, over the bound
  EXPECT_EQ(link.TakeArrived(1e9), 1);
  EXPECT_TRUE(link.Free(1e9));
}

TEST(EmulatedLink, DrawsAsItsLinkModelDoes) {
  LinkParams p = OneMbitTenMs();
  p.jitter_s = 0.005;
  p.loss = 0.1;
  p.recovery_s = 0.2;
  EmulatedLink<int> link(p, 7);
  LinkModel model(p, 7);
  for (int k = 0; k < 50; ++k) {
    const double t = 0.01 * k;
    const LinkModel::Delivery a = link.Send(t, k, 3000);
    const LinkModel::Delivery b = model.Send(t, 3000);
    EXPECT_EQ(a.arrival_s, b.arrival_s);
    EXPECT_EQ(a.lost_segments, b.lost_segments);
  }
  EXPECT_EQ(link.lost_segments(), model.lost_segments());
}

}  // namespace
}  // namespace vistream::server
