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

TEST(Proto, GarbageDoesNotParseAsAClientMessage) {
  ClientMessage m;
  EXPECT_FALSE(m.ParseFromString(std::string("\xff\xff\xff\xff\xff", 5)));
}

}  // namespace
}  // namespace vistream::v1
