#include <google/protobuf/descriptor.h>
#include <gtest/gtest.h>

#include "proto/walkthrough.grpc.pb.h"
#include "proto/walkthrough.pb.h"

namespace vistream::v1 {
namespace {

TEST(Proto, SessionIsOneBidirectionalStream) {
  const google::protobuf::ServiceDescriptor* service =
      ClientMessage::descriptor()->file()->FindServiceByName("Walkthrough");
  ASSERT_NE(service, nullptr);
  EXPECT_EQ(service->full_name(), "vistream.v1.Walkthrough");
  EXPECT_STREQ(Walkthrough::service_full_name(), "vistream.v1.Walkthrough");
  const google::protobuf::MethodDescriptor* session = service->FindMethodByName("Session");
  ASSERT_NE(session, nullptr);
  EXPECT_TRUE(session->client_streaming());
  EXPECT_TRUE(session->server_streaming());
}

TEST(Proto, ServerMessageRoundTripsThroughTheWire) {
  ServerMessage m;
  ViewcellPvs* pvs = m.mutable_pvs();
  pvs->set_cell_id(42);
  for (uint32_t id : {3u, 17u, 400000u}) pvs->add_object_ids(id);
  std::string wire;
  ASSERT_TRUE(m.SerializeToString(&wire));
  ServerMessage back;
  ASSERT_TRUE(back.ParseFromString(wire));
  ASSERT_EQ(back.body_case(), ServerMessage::kPvs);
  EXPECT_EQ(back.pvs().cell_id(), 42u);
  ASSERT_EQ(back.pvs().object_ids_size(), 3);
  EXPECT_EQ(back.pvs().object_ids(2), 400000u);
}

// Bands are new field 8 of ViewcellGrid: a flat grid (no bands) has exactly the bytes it had
// before, and an older reader skips the bands of a grid that has them (an unknown field).
TEST(Proto, AFlatGridHasItsBytesFromBeforeBandsAndBandsArePacked) {
  ViewcellGrid g;
  g.set_cell_size_m(50);
  g.set_x0_m(-100);
  g.set_y0_m(25);
  g.set_nx(3);
  g.set_ny(2);
  g.set_base_z_m(0.5);
  g.set_height_m(2);
  std::string expected;
  auto tagged = [&expected](char tag, double v) {
    expected += tag;
    expected.append(reinterpret_cast<const char*>(&v), 8);
  };
  tagged('\x09', 50);
  tagged('\x11', -100);
  tagged('\x19', 25);
  expected += std::string("\x20\x03\x28\x02", 4);
  tagged('\x31', 0.5);
  tagged('\x39', 2);
  EXPECT_EQ(g.SerializeAsString(), expected);
  for (double z : {1.0, 3.0, 2.0, 4.5}) g.add_band_z(z);
  const std::string banded = g.SerializeAsString();
  ASSERT_EQ(banded.size(), expected.size() + 2 + 4 * 8);  // tag, length, four doubles
  EXPECT_EQ(banded.substr(0, expected.size()), expected);
  EXPECT_EQ(banded[expected.size()], '\x42');  // field 8, length-delimited: packed
  ViewcellGrid back;
  ASSERT_TRUE(back.ParseFromString(banded));
  EXPECT_EQ(back.band_z_size(), 4);
  EXPECT_EQ(back.band_z(3), 4.5);
}

TEST(Proto, GarbageDoesNotParseAsAClientMessage) {
  ClientMessage m;
  EXPECT_FALSE(m.ParseFromString(std::string("\xff\xff\xff\xff\xff", 5)));
}

}  // namespace
}  // namespace vistream::v1
