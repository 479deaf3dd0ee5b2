// The client model's rules (client/client_model.h, mask_holdings.h): what a client says in
// Hello, its pose cadence, its credit grants and what each message costs it, the ε-masks it
// keeps near its cell.
#include "client/client_model.h"

#include <cstdint>
#include <vector>

#include <gtest/gtest.h>

#include "client/mask_holdings.h"
#include "scenes/geometry_codec.h"
#include "scenes/mesh.h"
#include "visibility/mask_codec.h"

namespace vistream::client {
namespace {

namespace v1 = vistream::v1;

TEST(ClientModel, HelloCarriesTheProtocolVersionTheBudgetsAndWhatIsHeld) {
  HelloSettings s;
  s.scene = "london";
  s.memory_budget_bytes = 1 << 20;
  s.triangle_budget = 5000;
  s.epsilon_masks = true;
  s.held_objects = {7, 3};
  const v1::Hello h = MakeHello(s);
  EXPECT_EQ(h.scene(), "london");
  EXPECT_EQ(h.protocol_version(), static_cast<uint32_t>(v1::PROTOCOL_VERSION_CURRENT));
  EXPECT_EQ(h.memory_budget_bytes(), 1u << 20);
  EXPECT_EQ(h.triangle_budget(), 5000u);
  EXPECT_TRUE(h.epsilon_masks());
  EXPECT_EQ(std::vector<uint32_t>(h.held_objects().begin(), h.held_objects().end()), (std::vector<uint32_t>{7, 3}));
  // Defaults ask for nothing: no budget, no mask (the fields are left at proto3's zero).
  HelloSettings city1;
  city1.scene = "city1";
  const v1::Hello plain = MakeHello(city1);
  EXPECT_EQ(plain.ByteSizeLong(), 2 + city1.scene.size() + 2);  // the scene and the version only
  EXPECT_FALSE(plain.epsilon_masks());
  EXPECT_EQ(plain.memory_budget_bytes(), 0u);
  EXPECT_TRUE(HelloMessage(s).has_hello());
}

TEST(ClientModel, PosesGoOutAtTheRateWithoutABurstAfterALateOne) {
  PoseCadence c(kPoseRateHz);
  EXPECT_DOUBLE_EQ(c.period_s(), 0.1);
  c.Restart(5.0);
  EXPECT_TRUE(c.Due(5.0));
  c.Sent(5.0);
  EXPECT_FALSE(c.Due(5.05));
  EXPECT_TRUE(c.Due(5.1));
  c.Sent(5.1);
  // Sent late (1 s after it was due): the next is due at once, not ten to catch up.
  c.Sent(6.2);
  EXPECT_DOUBLE_EQ(c.next_s(), 6.2);
  c.Sent(6.2);
  EXPECT_DOUBLE_EQ(c.next_s(), 6.3);
  EXPECT_DOUBLE_EQ(PoseCadence(0.0).period_s(), 10.0);  // a rate below 0.1 is 0.1
  const v1::Pose p = MakePose({1, 2, 3}, {4, 5, 6}, 0.5, -0.25, 9.5);
  EXPECT_EQ(p.position().y(), 2.0);
  EXPECT_EQ(p.velocity().z(), 6.0);
  EXPECT_FLOAT_EQ(p.yaw_rad(), 0.5f);
  EXPECT_FLOAT_EQ(p.pitch_rad(), -0.25f);
  EXPECT_EQ(p.client_time_s(), 9.5);
}

TEST(ClientModel, CreditOpensWithTheWindowAndGrantsBackWhatWasConsumedAtHalf) {
  CreditWindow w(1000);
  EXPECT_EQ(w.Open(), 1000u);
  w.Consume(300);
  EXPECT_FALSE(w.GrantDue());
  w.Consume(250);
  ASSERT_TRUE(w.GrantDue());
  EXPECT_EQ(w.TakeGrant(), 550u);
  EXPECT_FALSE(w.GrantDue());
  w.Consume(100);
  EXPECT_EQ(w.Open(), 1000u);  // a new session starts the count again
  EXPECT_FALSE(w.GrantDue());
  EXPECT_EQ(CreditWindow().window_bytes(), uint64_t{8} << 20);
  EXPECT_EQ(CreditMessage(42).credit().bytes(), 42u);
}

TEST(ClientModel, GeometryAndMasksCostTheCreditAndNothingElseDoes) {
  v1::ServerMessage g;
  g.mutable_geometry()->set_vertices(std::string(100, 'v'));
  g.mutable_geometry()->set_indices(std::string(20, 'i'));
  EXPECT_EQ(ChargedBytes(g), 120u);
  v1::ServerMessage m;
  m.mutable_epsilon_mask()->set_triangles(std::string(7, 't'));
  EXPECT_EQ(ChargedBytes(m), 7u);
  v1::ServerMessage p;
  p.mutable_pvs()->add_object_ids(3);
  EXPECT_EQ(ChargedBytes(p), 0u);
  EXPECT_EQ(ChargedBytes(v1::ServerMessage()), 0u);
  EXPECT_EQ(scenes::RawMeshBytes(10, 30), 10u * 24 + 30u * 4);
}

// Cluster levels (issue 45): they cost the credit as geometry does; a cluster that keeps its
// objects' triangles decodes with each object's range; bad ones are errors naming the cluster.
TEST(ClientModel, AClusterCostsTheCreditAndDecodesWithItsObjectsRanges) {
  scenes::Mesh union_mesh;
  scenes::AppendConvexPrism(std::vector<glm::dvec2>{{0, 0}, {8, 0}, {8, 6}, {0, 6}}, 0.0, 12.5, &union_mesh);
  scenes::AppendConvexPrism(std::vector<glm::dvec2>{{20, 0}, {28, 0}, {28, 6}, {20, 6}}, 0.0, 9.0, &union_mesh);
  const scenes::EncodedLevelMesh e = scenes::EncodeLevelMesh(union_mesh);
  v1::ServerMessage m;
  v1::ClusterGeometry& g = *m.mutable_cluster();
  g.set_cluster_id(3);
  g.set_level(1);
  for (uint32_t o : {10u, 11u}) g.add_objects(o);
  g.set_vertex_count(e.vertex_count);
  g.set_index_count(e.index_count);
  g.set_vertices(e.vertices);
  g.set_indices(e.indices);
  g.set_step_log2(e.step_log2);
  g.mutable_origin()->Add(std::begin(e.origin), std::end(e.origin));
  g.set_wide(e.wide);
  g.set_keeps_triangles(true);
  g.add_object_triangles(12);
  g.add_object_triangles(12);
  g.set_full_bytes(10000);
  EXPECT_EQ(ChargedBytes(m), e.EncodedBytes());
  const absl::StatusOr<DecodedCluster> c = DecodeClusterGeometry(g);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->objects, (std::vector<uint32_t>{10, 11}));
  EXPECT_EQ(c->first_triangle, (std::vector<uint32_t>{0, 12, 24}));
  EXPECT_EQ(c->mesh.TriangleCount(), 24u);
  EXPECT_EQ(c->saved_bytes, 10000 - e.EncodedBytes());
  EXPECT_EQ(c->bounds_max, glm::dvec3(28.0, 6.0, 12.5));
  auto expect = [](const v1::ClusterGeometry& bad, const std::string& needle) {
    const absl::Status s = DecodeClusterGeometry(bad).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << needle;
    EXPECT_NE(s.message().find(needle), std::string::npos) << s;
  };
  v1::ClusterGeometry bad = g;
  bad.set_object_triangles(1, 11);
  expect(bad, "cluster 3, level 1: its objects' triangles sum to 23, its mesh has 24");
  bad = g;
  bad.add_object_triangles(0);
  expect(bad, "3 object triangle counts for 2 objects");
  bad = g;
  bad.set_objects(1, 10);
  expect(bad, "objects do not ascend (10 then 10)");
  bad = g;
  bad.set_level(0);
  expect(bad, "cluster 3, level 0: a cluster's levels start at 1");
  bad = g;
  bad.mutable_objects()->RemoveLast();
  expect(bad, "stands for 1 objects (at least 2)");
  bad = g;
  bad.mutable_origin()->RemoveLast();
  expect(bad, "2 origin values (expected 3)");
  bad = g;
  bad.set_index_count(bad.index_count() + 3);
  EXPECT_FALSE(DecodeClusterGeometry(bad).ok());
}

v1::EpsilonMask Mask(uint32_t id, uint32_t cell, double x0) {
  v1::EpsilonMask m;
  m.set_mask_id(id);
  m.set_cell_id(cell);
  m.mutable_neighbourhood_min()->set_x(x0);
  m.mutable_neighbourhood_max()->set_x(x0 + 4);
  m.mutable_neighbourhood_max()->set_y(4);
  m.mutable_neighbourhood_max()->set_z(2);
  std::vector<visibility::MaskObject> objects = {{1, {0x3}}, {2, {0x1}}};
  m.set_triangles(visibility::EncodeMaskRuns(objects));
  return m;
}

// Levels of detail (issue 45): Hello asks for them only with a screen error; a level's geometry
// decodes to its mesh, its bounds its own; a level without its origin is an error naming it.
TEST(ClientModel, HelloAsksForLevelsOnlyWithAScreenError) {
  HelloSettings s;
  s.scene = "london";
  EXPECT_FALSE(MakeHello(s).has_levels());
  s.screen_error_px = 2.0;
  const v1::Hello h = MakeHello(s);
  ASSERT_TRUE(h.has_levels());
  EXPECT_EQ(h.levels().viewport_width_px(), 1280u);
  EXPECT_EQ(h.levels().viewport_height_px(), 720u);
  EXPECT_DOUBLE_EQ(h.levels().screen_error_px(), 2.0);
}

TEST(ClientModel, ALevelsGeometryDecodesToItsMeshWithItsOwnBounds) {
  scenes::Mesh box;
  scenes::AppendConvexPrism(std::vector<glm::dvec2>{{0, 0}, {8, 0}, {8, 6}, {0, 6}}, 0.0, 12.5, &box);
  for (auto& p : box.positions) p += glm::vec3(1000.25f, -500.5f, 0.0f);
  const scenes::EncodedLevelMesh e = scenes::EncodeLevelMesh(box);
  v1::ObjectGeometry g;
  g.set_object_id(42);
  g.set_level(1);
  g.set_vertex_count(e.vertex_count);
  g.set_index_count(e.index_count);
  g.set_vertices(e.vertices);
  g.set_indices(e.indices);
  g.set_step_log2(e.step_log2);
  g.mutable_origin()->Add(std::begin(e.origin), std::end(e.origin));
  g.set_wide(e.wide);
  const absl::StatusOr<DecodedObject> o = DecodeObjectGeometry(g);
  ASSERT_TRUE(o.ok()) << o.status();
  EXPECT_EQ(o->id, 42u);
  EXPECT_EQ(o->level, 1u);
  EXPECT_EQ(o->mesh.TriangleCount(), box.TriangleCount());
  EXPECT_EQ(o->bounds_min, glm::dvec3(1000.25, -500.5, 0.0));
  EXPECT_EQ(o->bounds_max, glm::dvec3(1008.25, -494.5, 12.5));
  EXPECT_EQ(o->raw_bytes, scenes::RawMeshBytes(o->mesh.positions.size(), o->mesh.indices.size()));
  EXPECT_LT(e.EncodedBytes(), scenes::EncodeMesh(box).EncodedBytes() / 2);
  g.mutable_origin()->RemoveLast();
  const absl::StatusOr<DecodedObject> bad = DecodeObjectGeometry(g);
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(bad.status().message().find("object 42, level 1: 2 origin values"), std::string::npos) << bad.status();
}

TEST(MaskHoldings, KeepsTheMasksOfTheCellAndItsNeighboursAndChoosesAReadyOne) {
  const visibility::ViewcellGrid grid = *visibility::ViewcellGrid::FromLayout({0, 0}, 10, 5, 1, 0, 2);
  MaskHoldings h;
  ASSERT_TRUE(h.Add(Mask(1, 0, 1), 10, 100).ok());
  ASSERT_TRUE(h.Add(Mask(2, 4, 41), 10, 100).ok());
  ASSERT_EQ(h.masks().size(), 2u);
  EXPECT_EQ(h.masks().at(1).object_triangles, (std::vector<uint64_t>{2, 1}));
  EXPECT_EQ(h.masks().at(1).triangles, 3u);
  h.KeepNear(std::nullopt, grid);  // no cell known: nothing dropped for that
  EXPECT_EQ(h.masks().size(), 2u);
  h.KeepNear(1, grid);  // cell 4 is two cells away from cell 1
  ASSERT_EQ(h.masks().size(), 1u);
  EXPECT_EQ(h.TakeDropped().size(), 1u);
  const MaskChoice ready = h.Choose({2, 1, 1}, [](uint32_t) { return true; });
  ASSERT_NE(ready.mask, nullptr);
  EXPECT_EQ(ready.mask->mask_id, 1u);
  const MaskChoice unready = h.Choose({2, 1, 1}, [](uint32_t o) { return o != 2; });
  EXPECT_EQ(unready.mask, nullptr);
  EXPECT_TRUE(unready.in_box);
  EXPECT_FALSE(h.Choose({30, 1, 1}, [](uint32_t) { return true; }).in_box);
  v1::EpsilonMask bad = Mask(3, 0, 1);
  bad.set_triangles("\xff");
  EXPECT_FALSE(h.Add(bad, 10, 100).ok());
  EXPECT_EQ(h.masks().size(), 1u);
}

}  // namespace
}  // namespace vistream::client
