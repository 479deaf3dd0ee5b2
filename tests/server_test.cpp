// End-to-end tests of the walkthrough server: a real server on loopback (in this process, or
// the vistream-server executable), scripted clients that walk paths and record what arrives.

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>
#include <set>
#include <thread>

#include <glm/geometric.hpp>
#include <grpcpp/generic/generic_stub.h>
#include <absl/strings/str_cat.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "client/client_model.h"
#include "client/mask_holdings.h"
#include "gl/pvs_backend.h"
#include "scenes/geometry_codec.h"
#include "scenes/catalog.h"
#include "scenes/gltf_io.h"
#include "server/link_model.h"
#include "server/service.h"
#include "visibility/mask_codec.h"
#include "visibility/pvs_file.h"
#include "client/session_stream.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"

namespace vistream::server {
namespace {

namespace v1 = vistream::v1;
using client::SessionRecord;
using client::SessionStream;
using test::Around;
using test::Cell;
using test::Centre;
using test::City1;
using test::Connect;
using test::ExpectedPvs;
using test::ExpectStillServes;
using test::kWait;
using test::StartServer;

TEST(Server, FirstPoseBringsNineCellsCurrentFirstWithExactGeometry) {
  auto server = StartServer();
  auto client = Connect(*server);
  const CellId here = Cell(14, 10);
  ASSERT_TRUE(client->SendPose(Centre(14, 10), {1.4, 0, 0}));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(here)); }, kWait));
  const SessionRecord r = client->Snapshot();
  ASSERT_TRUE(r.scene_info);
  EXPECT_EQ(r.order.front().first, 'S');
  EXPECT_EQ(r.info.object_count(), City1().scene().objects.size());
  EXPECT_EQ(r.info.grid().nx(), 28);
  ASSERT_EQ(r.pvs_order.size(), 9u);
  EXPECT_EQ(r.pvs_order.front(), here);
  EXPECT_EQ(std::set<CellId>(r.pvs_order.begin(), r.pvs_order.end()), Around(here));
  // The current cell's geometry before any other.
  const std::vector<uint32_t>& current = r.pvs.at(here);
  bool other_seen = false;
  for (const auto& [kind, id] : r.order) {
    if (kind != 'G') continue;
    const bool in_current = std::binary_search(current.begin(), current.end(), id);
    EXPECT_FALSE(in_current && other_seen) << "object " << id << " of the current cell came after another cell's";
    other_seen |= !in_current;
  }
  // Every PVS is the one `vistream pvs` computes; every mesh decodes to the scene's, bit for bit.
  for (const auto& [cell, objects] : r.pvs) EXPECT_EQ(objects, ExpectedPvs(cell)) << "cell " << cell;
  // And the current cell's, as the command prints it.
  std::FILE* pipe = popen(VISTREAM_BIN " pvs --scene city1 --cell 14,10 --json", "r");
  ASSERT_NE(pipe, nullptr);
  std::string json;
  char buf[4096];
  while (size_t n = std::fread(buf, 1, sizeof(buf), pipe)) json.append(buf, n);
  ASSERT_EQ(pclose(pipe), 0) << json;
  EXPECT_EQ(nlohmann::json::parse(json).at("objects").get<std::vector<uint32_t>>(), r.pvs.at(here));
  EXPECT_EQ(r.duplicates, 0u);
  for (const auto& [id, g] : r.geometry) {
    absl::StatusOr<scenes::Mesh> m = scenes::DecodeMesh(g.vertex_count(), g.index_count(), g.vertices(),
                                                        g.indices(), "object " + std::to_string(id));
    ASSERT_TRUE(m.ok()) << m.status();
    const scenes::Mesh& want = City1().scene().objects[id].mesh;
    ASSERT_EQ(m->positions.size(), want.positions.size());
    EXPECT_EQ(0, std::memcmp(m->positions.data(), want.positions.data(), want.positions.size() * sizeof(glm::vec3)));
    EXPECT_EQ(0, std::memcmp(m->normals.data(), want.normals.data(), want.normals.size() * sizeof(glm::vec3)));
    EXPECT_EQ(m->indices, want.indices);
  }
  EXPECT_TRUE(client->Finish().ok());
}

// Cluster levels over the wire (issue 45): along city2's walk at 1 px a client that draws
// clusters gets the clusters its lists choose, each decoding to the scene's cluster level with
// its objects (and their triangle ranges where it keeps their triangles); every cell completes by
// the lists' rule; chosen clusters share no object of a list. Resuming with a cluster held at a
// level it could have, it is not sent again; claimed at a level past its levels, it comes again.
// A client whose memory budget is full of far clusters is told to drop them.
TEST(Server, ClusterLevelsArriveAsTheListsChooseThemAndResumeAndEvict) {
  ServedSceneOptions o;
  o.scene = "city2";
  o.threads = 2;
  o.idle_priority_masks = false;
  o.make_levels = true;
  absl::StatusOr<std::unique_ptr<ServedScene>> scene = ServedScene::Create(o);
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_FALSE((*scene)->scene().levels.clusters.empty());
  ServerOptions options;
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(scene->get(), options, nullptr);
  ASSERT_TRUE(server.ok()) << server.status();
  const visibility::ViewcellGrid& grid = (*scene)->grid();
  const scenes::SceneLevels& levels = (*scene)->scene().levels;
  client::HelloSettings settings;
  settings.scene = "city2";
  settings.screen_error_px = 1.0;
  settings.clusters = true;
  // Along the walk's first leg, a pose every cell.
  std::vector<glm::dvec3> poses;
  for (double y = -700.0; y <= 700.0; y += 50.0) poses.push_back({-1000.0, y, grid.base_z() + 1.2});
  std::map<uint32_t, uint32_t> chosen;  // cluster -> a level some list chose it at
  std::optional<CellId> chose_at;
  {
    SessionStream client((*server)->address());
    client.Start(client::MakeHello(settings), true);
    client.SendCredit(uint64_t{1} << 40);
    for (const glm::dvec3& p : poses) {
      const std::optional<CellId> cell = grid.CellAt(glm::dvec2(p));
      ASSERT_TRUE(cell.has_value());
      ASSERT_TRUE(client.SendPose(p));
      ASSERT_TRUE(client.WaitFor([&](const SessionRecord& r) { return r.CellComplete(*cell); }, kWait));
      const SessionRecord r = client.Snapshot();
      const auto& [ids, lv] = r.pvs_clusters.at(*cell);
      std::set<uint32_t> seen;
      for (size_t k = 0; k < ids.size(); ++k) {
        chosen.emplace(ids[k], lv[k]);
        if (!chose_at.has_value()) chose_at = *cell;
        for (uint32_t m : levels.clusters[ids[k]].objects) {
          const std::vector<uint32_t>& list = r.pvs.at(*cell);
          if (std::binary_search(list.begin(), list.end(), m)) {
            EXPECT_TRUE(seen.insert(m).second) << "object " << m;
          }
        }
      }
    }
    const SessionRecord r = client.Snapshot();
    EXPECT_GT(r.cluster_levels, 0u);
    EXPECT_EQ(r.duplicates, 0u);
    EXPECT_TRUE(client.Finish().ok());
  }
  ASSERT_FALSE(chosen.empty()) << "no list along the walk chose a cluster";
  // The cluster messages themselves, kept whole by a session that asks for them.
  {
    SessionStream client((*server)->address());
    client.Start(client::MakeHello(settings), true);
    client.SendCredit(uint64_t{1} << 40);
    ASSERT_TRUE(client.SendPose(poses[0]));
    for (const glm::dvec3& p : poses) {
      const CellId cell = *grid.CellAt(glm::dvec2(p));
      ASSERT_TRUE(client.SendPose(p));
      ASSERT_TRUE(client.WaitFor([&](const SessionRecord& r) { return r.CellComplete(cell); }, kWait));
      if (cell == *chose_at) break;
    }
    const SessionRecord r = client.Snapshot();
    ASSERT_FALSE(r.cluster_geometry.empty());
    for (const auto& [id, g] : r.cluster_geometry) {
      const absl::StatusOr<client::DecodedCluster> d = client::DecodeClusterGeometry(g);
      ASSERT_TRUE(d.ok()) << d.status();
      ASSERT_LT(id, levels.clusters.size());
      ASSERT_LE(g.level(), levels.clusters[id].levels.size());
      EXPECT_EQ(d->objects, levels.clusters[id].objects);
      EXPECT_EQ(d->mesh.TriangleCount(), levels.clusters[id].levels[g.level() - 1].mesh.TriangleCount());
      EXPECT_EQ(g.keeps_triangles(), (*scene)->levels()->ClusterKeepsTriangles(id, g.level()));
      if (g.keeps_triangles()) {
        for (size_t k = 0; k < d->objects.size(); ++k) {
          EXPECT_EQ(d->first_triangle[k + 1] - d->first_triangle[k],
                    (*scene)->scene().objects[d->objects[k]].mesh.TriangleCount());
        }
      }
      EXPECT_EQ(d->raw_bytes, (*scene)->ClusterRawBytes(id, g.level()));
    }
    EXPECT_TRUE(client.Finish().ok());
  }
  // Resume: the first chosen cluster held at its level is not sent again; at level 99 it is.
  const uint32_t c = chosen.begin()->first, c_level = chosen.begin()->second;
  for (const uint32_t claimed : {c_level, 99u}) {
    client::HelloSettings resume = settings;
    resume.held_clusters = {c};
    resume.held_cluster_levels = {claimed};
    SessionStream client((*server)->address());
    if (claimed == c_level) client.HoldCluster(c, claimed, levels.clusters[c].objects);
    client.Start(client::MakeHello(resume), true);
    client.SendCredit(uint64_t{1} << 40);
    for (const glm::dvec3& p : poses) {
      const CellId cell = *grid.CellAt(glm::dvec2(p));
      ASSERT_TRUE(client.SendPose(p));
      ASSERT_TRUE(client.WaitFor([&](const SessionRecord& r) { return r.CellComplete(cell); }, kWait));
    }
    const SessionRecord r = client.Snapshot();
    const bool sent =
        std::any_of(r.order.begin(), r.order.end(), [&](const auto& e) { return e.first == 'C' && e.second == c; });
    EXPECT_EQ(sent, claimed == 99u) << "cluster " << c << " claimed at level " << claimed;
    EXPECT_TRUE(client.Finish().ok());
  }
  // Eviction: far clusters held fill the budget; the walk's geometry needs the room.
  client::HelloSettings full = settings;
  uint64_t held = 0;
  for (uint32_t k = 0; k < levels.clusters.size() && full.held_clusters.size() < 8; ++k) {
    if (chosen.count(k) > 0) continue;
    full.held_clusters.push_back(k);
    full.held_cluster_levels.push_back(1);
    held += (*scene)->ClusterRawBytes(k, 1);
  }
  ASSERT_EQ(full.held_clusters.size(), 8u);
  full.memory_budget_bytes = held + held / 8;
  SessionStream client((*server)->address());
  client.Start(client::MakeHello(full), true);
  client.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(client.SendPose(poses[0]));
  ASSERT_TRUE(client.WaitFor([&](const SessionRecord& r) { return !r.evicted_clusters.empty(); }, kWait));
  const SessionRecord r = client.Snapshot();
  for (uint32_t e : r.evicted_clusters) {
    EXPECT_NE(std::find(full.held_clusters.begin(), full.held_clusters.end(), e), full.held_clusters.end()) << e;
  }
  EXPECT_TRUE(client.Finish().ok());
}

// Levels of detail over the wire (issue 45): a server that makes levels at start sends a client
// that asks for a screen error each object at a level, which decodes to the scene's level mesh;
// a client that does not ask gets full meshes from the same server.
TEST(Server, AClientAskingForAScreenErrorGetsLevelsThatDecode) {
  ServedSceneOptions o;
  o.scene = "city1";
  o.threads = 2;
  o.idle_priority_masks = false;
  o.make_levels = true;
  absl::StatusOr<std::unique_ptr<ServedScene>> scene = ServedScene::Create(o);
  ASSERT_TRUE(scene.ok()) << scene.status();
  ServerOptions options;
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(scene->get(), options, nullptr);
  ASSERT_TRUE(server.ok()) << server.status();
  const CellId here = (*scene)->grid().Id({3, 3});
  for (const bool levels : {true, false}) {
    SessionStream client((*server)->address());
    v1::Hello hello = SessionStream::HelloFor("city1");
    if (levels) {
      client::HelloSettings settings;
      settings.scene = "city1";
      settings.screen_error_px = 1.0;
      hello = client::MakeHello(settings);
    }
    client.Start(hello, true);
    client.SendCredit(uint64_t{1} << 40);
    ASSERT_TRUE(client.SendPose(Centre(3, 3)));
    ASSERT_TRUE(client.WaitFor([&](const SessionRecord& r) { return r.CellComplete(here); }, kWait));
    const SessionRecord r = client.Snapshot();
    size_t leveled = 0;
    for (const auto& [id, g] : r.geometry) {
      const absl::StatusOr<client::DecodedObject> d = client::DecodeObjectGeometry(g);
      ASSERT_TRUE(d.ok()) << d.status();
      if (g.level() == 0) continue;
      ++leveled;
      ASSERT_LE(g.level(), (*scene)->scene().levels.objects[id].size());
      const scenes::Mesh& want = (*scene)->scene().levels.objects[id][g.level() - 1].mesh;
      EXPECT_EQ(d->mesh.TriangleCount(), want.TriangleCount());
      EXPECT_EQ(d->raw_bytes, (*scene)->RawBytes(id, g.level()));
      // Mask bits apply exactly to a level with the full mesh's triangles; what it saved is
      // the full mesh's encoded bytes less its own.
      EXPECT_EQ(g.keeps_triangles(), want.TriangleCount() == (*scene)->scene().objects[id].mesh.TriangleCount());
      EXPECT_EQ(g.full_bytes(), (*scene)->geometry(id).EncodedBytes());
      EXPECT_EQ(d->saved_bytes, g.full_bytes() - (g.vertices().size() + g.indices().size()));
    }
    if (levels) {
      EXPECT_GT(leveled, r.geometry.size() / 2);
    } else {
      EXPECT_EQ(leveled, 0u);
    }
    EXPECT_TRUE(client.Finish().ok());
  }
  // A resuming client claiming levels this session cannot have sent (past an object's levels;
  // any level to a session without levels, as after a restart without them): those objects
  // count as not held and come again; one held at a level it could have is not sent again.
  const std::vector<uint32_t> pvs = [&] {
    SessionStream probe((*server)->address());
    probe.Start(SessionStream::HelloFor("city1"), true);
    probe.SendCredit(uint64_t{1} << 40);
    EXPECT_TRUE(probe.SendPose(Centre(3, 3)));
    EXPECT_TRUE(probe.WaitFor([&](const SessionRecord& r) { return r.CellComplete(here); }, kWait));
    const std::vector<uint32_t> list = probe.Snapshot().pvs.at(here);
    EXPECT_TRUE(probe.Finish().ok());
    return list;
  }();
  ASSERT_GE(pvs.size(), 2u);
  const uint32_t a = pvs[0], b = pvs[1];
  for (const bool levels : {true, false}) {
    client::HelloSettings settings;
    settings.scene = "city1";
    settings.screen_error_px = levels ? 1.0 : 0.0;
    settings.held_objects = {a, b};
    settings.held_levels = {99, levels ? 1u : 0u};
    SessionStream resumed((*server)->address());
    resumed.Start(client::MakeHello(settings), true);
    resumed.SendCredit(uint64_t{1} << 40);
    ASSERT_TRUE(resumed.SendPose(Centre(3, 3)));
    ASSERT_TRUE(resumed.WaitFor([&](const SessionRecord& r) { return r.CellComplete(here); }, kWait)) << levels;
    const SessionRecord r = resumed.Snapshot();
    EXPECT_EQ(r.geometry.count(a), 1u) << "object " << a << " claimed at level 99 was not sent again (" << levels << ")";
    if (levels && r.geometry.count(b) > 0) {
      EXPECT_LT(r.geometry.at(b).level(), 1u) << "object " << b << " held at level 1 was sent again at it";
    }
    EXPECT_TRUE(resumed.Finish().ok());
  }
  // Within a memory budget, what went far away goes first, and of that the largest holdings
  // (an object's finer levels) first: a client resuming with objects no cell around it needs,
  // half held full and half at their first level, and room for little more than those, is told
  // to drop them largest first (their held bytes never increase along the Evicts).
  std::set<uint32_t> around;
  {
    SessionStream probe((*server)->address());
    client::HelloSettings settings;
    settings.scene = "city1";
    settings.screen_error_px = 1.0;
    probe.Start(client::MakeHello(settings), true);
    probe.SendCredit(uint64_t{1} << 40);
    ASSERT_TRUE(probe.SendPose(Centre(3, 3)));
    ASSERT_TRUE(probe.WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(here)); }, kWait));
    for (const auto& [cell, list] : probe.Snapshot().pvs) around.insert(list.begin(), list.end());
    EXPECT_TRUE(probe.Finish().ok());
  }
  client::HelloSettings far;
  far.scene = "city1";
  far.screen_error_px = 1.0;
  std::map<uint32_t, uint64_t> far_bytes;  // object -> bytes held
  for (uint32_t id = 0; id < (*scene)->scene().objects.size() && far.held_objects.size() < 24; ++id) {
    if (around.count(id) > 0 || (*scene)->scene().levels.objects[id].empty()) continue;
    const uint32_t level = far.held_objects.size() % 2;  // full and first level, alternately
    far.held_objects.push_back(id);
    far.held_levels.push_back(level);
    far_bytes[id] = (*scene)->RawBytes(id, level);
  }
  ASSERT_EQ(far.held_objects.size(), 24u);
  uint64_t held = 0;
  for (const auto& [id, bytes] : far_bytes) held += bytes;
  far.memory_budget_bytes = held + (held / 4);  // less than the cell's objects need
  SessionStream resumed((*server)->address());
  resumed.Start(client::MakeHello(far), true);
  resumed.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(resumed.SendPose(Centre(3, 3)));
  ASSERT_TRUE(resumed.WaitFor([&](const SessionRecord& r) { return r.evicted.size() >= 4; }, kWait));
  const SessionRecord r = resumed.Snapshot();
  std::vector<uint64_t> dropped;  // held bytes of the far objects, in the order they were dropped
  for (uint32_t id : r.evicted) {
    if (far_bytes.count(id) > 0) dropped.push_back(far_bytes[id]);
  }
  ASSERT_GE(dropped.size(), 4u);
  EXPECT_TRUE(std::is_sorted(dropped.rbegin(), dropped.rend())) << "the far objects were not dropped largest first";
  std::vector<uint64_t> all;
  for (const auto& [id, bytes] : far_bytes) all.push_back(bytes);
  std::sort(all.rbegin(), all.rend());
  EXPECT_EQ(dropped.front(), all.front());
  EXPECT_TRUE(resumed.Finish().ok());
}

TEST(Server, AStraightCrossingBringsThreeCellsADiagonalOneFive) {
  auto server = StartServer();
  auto client = Connect(*server);
  ASSERT_TRUE(client->SendPose(Centre(10, 10), {1.4, 0, 0}));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(Cell(10, 10))); }, kWait));
  struct Step {
    int i, j;
    size_t new_cells;
  };
  for (const Step s : {Step{11, 10, 3}, Step{12, 10, 3}, Step{13, 11, 5}, Step{13, 12, 3}, Step{12, 13, 5}}) {
    const size_t before = client->Snapshot().pvs_order.size();
    // Only cells it already has around it: the one it walks into was received before.
    EXPECT_TRUE(client->Snapshot().CellComplete(Cell(s.i, s.j))) << s.i << "," << s.j;
    ASSERT_TRUE(client->SendPose(Centre(s.i, s.j), {1.4, 0, 0}));
    ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(Cell(s.i, s.j))); }, kWait));
    std::this_thread::sleep_for(std::chrono::milliseconds(200));  // nothing more may follow
    const SessionRecord r = client->Snapshot();
    EXPECT_EQ(r.pvs_order.size() - before, s.new_cells) << "crossing into " << s.i << "," << s.j;
    for (size_t k = before; k < r.pvs_order.size(); ++k) EXPECT_EQ(Around(Cell(s.i, s.j)).count(r.pvs_order[k]), 1u);
  }
  const SessionRecord r = client->Snapshot();
  EXPECT_EQ(r.duplicates, 0u);
  // Without a memory budget the client keeps what the cells left behind needed: nothing is
  // evicted, so nothing will be sent twice (DESIGN.md: geometry is never sent twice).
  EXPECT_TRUE(r.evicted.empty()) << r.evicted.size() << " objects evicted from a client without a budget";
  std::set<uint32_t> left_behind;  // objects of cells around the start that no cell around the end needs
  std::set<uint32_t> needed;
  for (CellId c : Around(Cell(12, 13))) needed.insert(r.pvs.at(c).begin(), r.pvs.at(c).end());
  for (CellId c : Around(Cell(10, 10))) {
    for (uint32_t o : r.pvs.at(c)) {
      if (needed.count(o) == 0) left_behind.insert(o);
    }
  }
  EXPECT_FALSE(left_behind.empty());  // the walk did leave buildings behind
  for (uint32_t o : left_behind) EXPECT_EQ(r.held.count(o), 1u) << "object " << o << " left behind was dropped";
  EXPECT_TRUE(client->Finish().ok());
}

TEST(Server, CellsArriveBeforeAWalkerAt54KmhEntersThem) {
  auto server = StartServer();
  auto client = Connect(*server);
  glm::dvec3 p = Centre(6, 8);
  const glm::dvec3 v(15.0, 0.0, 0.0);
  ASSERT_TRUE(client->SendPose(p, v));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(Cell(6, 8))); }, kWait));
  // Real time, 20 poses a second, across four cells.
  std::optional<CellId> last;
  int entered = 0;
  for (int k = 0; k < 4 * 50 / 15 * 20; ++k) {
    p += v * 0.05;
    const CellId c = *City1().grid().CellAt(glm::dvec2(p));
    if (c != last) {
      EXPECT_TRUE(client->Snapshot().CellComplete(c)) << "entered cell " << c << " before its PVS and geometry";
      last = c;
      ++entered;
    }
    ASSERT_TRUE(client->SendPose(p, v));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_GE(entered, 4);
  EXPECT_EQ(client->Snapshot().duplicates, 0u);
  EXPECT_TRUE(client->Finish().ok());
}

TEST(Server, GeometryFlowsOnlyWithinTheGrantedCredit) {
  auto server = StartServer();
  SessionStream client(server->address());
  client.Start(SessionStream::HelloFor("city1"));
  ASSERT_TRUE(client.SendPose(Centre(9, 6)));
  ASSERT_TRUE(client.WaitFor([](const SessionRecord& r) { return r.pvs.size() == 9; }, kWait));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_TRUE(client.Snapshot().geometry.empty()) << "geometry before any Credit";
  ASSERT_TRUE(client.SendCredit(1));  // positive: one message, then the credit is spent
  ASSERT_TRUE(client.WaitFor([](const SessionRecord& r) { return r.geometry.size() == 1; }, kWait));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_EQ(client.Snapshot().geometry.size(), 1u);
  const uint64_t spent = client.Snapshot().geometry_bytes;
  ASSERT_TRUE(client.SendCredit(spent + 20000));  // pays the debt, then about 20 kB more
  // Everything granted is used (waited for: a loaded machine may be slow to send it) ...
  EXPECT_TRUE(client.WaitFor([&](const SessionRecord& r) { return r.geometry_bytes >= spent + 20001; }, kWait));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));  // ... and nothing more comes
  const SessionRecord r = client.Snapshot();
  EXPECT_LT(r.geometry.size(), 200u);
  // Everything granted is used, and what is sent overshoots the grant by one message at most.
  uint64_t largest = 0;
  for (const auto& [id, g] : r.geometry) largest = std::max<uint64_t>(largest, g.vertices().size() + g.indices().size());
  EXPECT_GE(r.geometry_bytes, spent + 20001);  // the first message (credit 1 - spent), then 20001
  EXPECT_LE(r.geometry_bytes, spent + 20001 + largest);
  EXPECT_TRUE(client.Finish().ok());
}

TEST(Server, TheClientsMemoryBudgetIsNeverExceeded) {
  auto server = StartServer();
  constexpr uint64_t kBudget = 400 << 10;  // decoded bytes: less than one cell's PVS
  v1::Hello hello = SessionStream::HelloFor("city1");
  hello.set_memory_budget_bytes(kBudget);
  SessionStream client(server->address());
  client.Start(hello);
  client.SendCredit(uint64_t{1} << 40);
  uint64_t most = 0;
  auto held_bytes = [](const SessionRecord& r) {
    uint64_t b = 0;
    for (uint32_t o : r.held) {
      const scenes::Mesh& m = City1().scene().objects[o].mesh;
      b += m.positions.size() * 24 + m.indices.size() * 4;
    }
    return b;
  };
  // The holdings are looked at whenever a message arrives (WaitFor's predicate, never true
  // while walking), so the most held is seen, not only where the walk pauses.
  auto track = [&](const SessionRecord& r) {
    most = std::max(most, held_bytes(r));
    return false;
  };
  for (int i = 4; i < 12; ++i) {
    ASSERT_TRUE(client.SendPose(Centre(i, 8), {1.4, 0, 0}));
    client.WaitFor(track, 0.4);
  }
  // It did fill the budget (waited for: a loaded machine may be slow to send).
  EXPECT_TRUE(client.WaitFor([&](const SessionRecord& r) { return track(r) || most > kBudget / 2; }, kWait));
  EXPECT_LE(most, kBudget);
  EXPECT_TRUE(client.Finish().ok());
}

TEST(Server, ResumingWithHeldObjectsSendsOnlyWhatIsMissing) {
  auto server = StartServer();
  const CellId here = Cell(20, 5);
  std::set<uint32_t> held;
  {
    auto first = Connect(*server);
    ASSERT_TRUE(first->SendPose(Centre(20, 5)));
    ASSERT_TRUE(first->WaitFor([&](const SessionRecord& r) { return r.CellComplete(here); }, kWait));
    held = first->Snapshot().held;
    first->Cancel();  // a dropped connection
  }
  ASSERT_FALSE(held.empty());
  auto second = std::make_unique<SessionStream>(server->address());
  second->Start(SessionStream::HelloFor("city1", std::vector<uint32_t>(held.begin(), held.end())));
  second->SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(second->SendPose(Centre(20, 5)));
  ASSERT_TRUE(second->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(here)); }, kWait));
  const SessionRecord r = second->Snapshot();
  for (const auto& [id, g] : r.geometry) EXPECT_EQ(held.count(id), 0u) << "object " << id << " was held and resent";
  EXPECT_TRUE(second->Finish().ok());
}

// One bad input: what the session sends, and the status it must end with.
struct BadInput {
  const char* name;
  std::function<void(SessionStream&)> act;
  grpc::StatusCode code;
  const char* message;  // part of the status message
};

v1::ClientMessage PoseAt(double x, double y, double vx = 0) {
  v1::ClientMessage m;
  m.mutable_pose()->mutable_position()->set_x(x);
  m.mutable_pose()->mutable_position()->set_y(y);
  m.mutable_pose()->mutable_position()->set_z(1.7);
  m.mutable_pose()->mutable_velocity()->set_x(vx);
  return m;
}

void Hello(SessionStream& w, const v1::Hello& h) { w.Start(h); }

std::vector<BadInput> BadInputs() {
  const glm::dvec3 c = Centre(3, 3);
  return {
      {"nan_pose", [c](SessionStream& w) { Hello(w, SessionStream::HelloFor("city1")); w.Send(PoseAt(NAN, c.y)); },
       grpc::StatusCode::INVALID_ARGUMENT, "position.x is nan"},
      {"infinite_velocity",
       [c](SessionStream& w) { Hello(w, SessionStream::HelloFor("city1")); w.Send(PoseAt(c.x, c.y, INFINITY)); },
       grpc::StatusCode::INVALID_ARGUMENT, "velocity.x is inf"},
      {"pose_outside_grid",
       [](SessionStream& w) { Hello(w, SessionStream::HelloFor("city1")); w.Send(PoseAt(1e7, 0)); },
       grpc::StatusCode::OUT_OF_RANGE, "outside the viewcell grid"},
      {"eye_above_the_band",
       [c](SessionStream& w) {
         Hello(w, SessionStream::HelloFor("city1"));
         v1::ClientMessage m = PoseAt(c.x, c.y);
         m.mutable_pose()->mutable_position()->set_z(1e300);
         w.Send(m);
       },
       grpc::StatusCode::OUT_OF_RANGE, "outside the viewcells' band [0.50, 2.50] m"},
      {"unknown_scene", [](SessionStream& w) { Hello(w, SessionStream::HelloFor("atlantis")); },
       grpc::StatusCode::NOT_FOUND, "'atlantis' is not served here"},
      {"wrong_protocol_version",
       [](SessionStream& w) {
         v1::Hello h = SessionStream::HelloFor("city1");
         h.set_protocol_version(7);
         Hello(w, h);
       },
       grpc::StatusCode::FAILED_PRECONDITION, "protocol version 7 is not supported: this server speaks version 1"},
      {"second_hello",
       [](SessionStream& w) {
         Hello(w, SessionStream::HelloFor("city1"));
         v1::ClientMessage m;
         *m.mutable_hello() = SessionStream::HelloFor("city1");
         w.Send(m);
       },
       grpc::StatusCode::FAILED_PRECONDITION, "second Hello"},
      {"pose_before_hello",
       [c](SessionStream& w) {
         w.StartRaw(PoseAt(c.x, c.y));
       },
       grpc::StatusCode::FAILED_PRECONDITION, "Pose before Hello"},
      {"empty_message", [](SessionStream& w) { w.StartRaw(v1::ClientMessage()); }, grpc::StatusCode::INVALID_ARGUMENT,
       "empty ClientMessage"},
      {"held_object_out_of_range",
       [](SessionStream& w) { Hello(w, SessionStream::HelloFor("city1", {5, 999999})); },
       grpc::StatusCode::INVALID_ARGUMENT, "held_objects[1] = 999999"},
      {"held_levels_not_one_per_held_object",
       [](SessionStream& w) {
         v1::Hello h = SessionStream::HelloFor("city1", {5, 6});
         h.add_held_levels(1);
         Hello(w, h);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "Hello.held_levels has 1 entries for 2 held_objects"},
      {"levels_with_a_zero_viewport",
       [](SessionStream& w) {
         v1::Hello h = SessionStream::HelloFor("city1");
         h.mutable_levels()->set_screen_error_px(1.0);
         h.mutable_levels()->set_vertical_fov_rad(1.0);
         Hello(w, h);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "Hello.levels: viewport 0 x 0 px is outside 1 to 16384"},
      {"levels_with_a_negative_screen_error",
       [](SessionStream& w) {
         v1::Hello h = SessionStream::HelloFor("city1");
         h.mutable_levels()->set_screen_error_px(-2.0);
         h.mutable_levels()->set_viewport_width_px(1280);
         h.mutable_levels()->set_viewport_height_px(720);
         h.mutable_levels()->set_vertical_fov_rad(1.0);
         Hello(w, h);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "Hello.levels.screen_error_px = -2"},
      {"levels_with_a_field_of_view_of_nan",
       [](SessionStream& w) {
         v1::Hello h = SessionStream::HelloFor("city1");
         h.mutable_levels()->set_screen_error_px(1.0);
         h.mutable_levels()->set_viewport_width_px(1280);
         h.mutable_levels()->set_viewport_height_px(720);
         h.mutable_levels()->set_vertical_fov_rad(NAN);
         Hello(w, h);
       },
       grpc::StatusCode::INVALID_ARGUMENT, "Hello.levels.vertical_fov_rad = nan"},
      {"oversized_message",
       [](SessionStream& w) {
         v1::Hello h = SessionStream::HelloFor("city1");
         h.set_scene(std::string(4 << 20, 'x'));
         Hello(w, h);
       },
       grpc::StatusCode::RESOURCE_EXHAUSTED, ""},
  };
}

class ServerBadInput : public ::testing::TestWithParam<size_t> {};

TEST_P(ServerBadInput, EndsOnlyItsSessionWithAStatusNamingIt) {
  auto server = StartServer();
  // A well-behaved session, already walking.
  auto good = Connect(*server);
  ASSERT_TRUE(good->SendPose(Centre(5, 5)));
  ASSERT_TRUE(good->WaitFor([&](const SessionRecord& r) { return r.CellComplete(Cell(5, 5)); }, kWait));

  const BadInput bad = BadInputs()[GetParam()];
  SessionStream w(server->address());
  bad.act(w);
  const grpc::Status st = w.AwaitEnd(kWait);
  EXPECT_EQ(st.error_code(), bad.code) << bad.name << ": " << st.error_message();
  EXPECT_NE(st.error_message().find(bad.message), std::string::npos) << bad.name << ": " << st.error_message();

  // The good session goes on: it crosses and gets the new cells.
  ASSERT_TRUE(good->SendPose(Centre(6, 5)));
  EXPECT_TRUE(good->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(Cell(6, 5))); }, kWait));
  EXPECT_TRUE(good->Finish().ok());
}

INSTANTIATE_TEST_SUITE_P(Each, ServerBadInput, ::testing::Range(size_t{0}, BadInputs().size()),
                         [](const ::testing::TestParamInfo<size_t>& p) { return BadInputs()[p.param].name; });

TEST(Server, GarbageBytesEndTheSessionWithAStatus) {
  auto server = StartServer();
  auto channel = grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(&ctx, "/vistream.v1.Walkthrough/Session", &cq);
  void* tag;
  bool ok;
  call->StartCall(reinterpret_cast<void*>(1));
  ASSERT_TRUE(cq.Next(&tag, &ok) && ok);
  const std::string junk = "\xff\xff\xff\xff garbage that is no ClientMessage";
  grpc::Slice slice(junk);
  grpc::ByteBuffer buffer(&slice, 1);
  call->Write(buffer, reinterpret_cast<void*>(2));
  ASSERT_TRUE(cq.Next(&tag, &ok));
  grpc::Status st;
  call->Finish(&st, reinterpret_cast<void*>(3));
  while (cq.Next(&tag, &ok) && tag != reinterpret_cast<void*>(3)) {
  }
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << st.error_message();
  EXPECT_NE(st.error_message().find("message 1 (" + std::to_string(junk.size()) + " bytes) is not a ClientMessage"), std::string::npos)
      << st.error_message();
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  ExpectStillServes(*server, 5, 5);
}

TEST(Server, TooManySessionsAndTooManyPosesAreRefused) {
  ServerOptions o;
  o.max_sessions = 2;
  o.limits.max_pose_rate_hz = 20;
  auto server = StartServer(o);
  auto a = Connect(*server);
  auto b = Connect(*server);
  ASSERT_TRUE(a->SendPose(Centre(5, 5)));
  ASSERT_TRUE(b->SendPose(Centre(6, 5)));
  ASSERT_TRUE(a->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  ASSERT_TRUE(b->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  SessionStream third(server->address());
  third.Start(SessionStream::HelloFor("city1"));
  const grpc::Status refused = third.AwaitEnd(kWait);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << refused.error_message();
  EXPECT_NE(refused.error_message().find("at most 2"), std::string::npos) << refused.error_message();
  // 100 poses at once: over twice the sustained 20 per second.
  for (int k = 0; k < 100; ++k) b->SendPose(Centre(6, 5));
  const grpc::Status flood = b->AwaitEnd(kWait);
  EXPECT_EQ(flood.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << flood.error_message();
  EXPECT_NE(flood.error_message().find("poses per second"), std::string::npos) << flood.error_message();
  // a was not touched.
  ASSERT_TRUE(a->SendPose(Centre(5, 6)));
  EXPECT_TRUE(a->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(Cell(5, 6))); }, kWait));
  EXPECT_TRUE(a->Finish().ok());
}

TEST(Server, AClientThatStopsReadingCostsBoundedMemory) {
  ServerOptions o;
  o.limits.max_queued_bytes = 1 << 20;
  auto server = StartServer(o);
  auto stalled = Connect(*server, /*read=*/false);
  glm::dvec3 p = Centre(3, 3);
  uint64_t max_queued = 0, sent = 0, crossings = 0;
  const auto start = std::chrono::steady_clock::now();
  v1::Walkthrough::Stub stats_stub(grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials()));
  while (std::chrono::steady_clock::now() - start < std::chrono::seconds(10)) {
    p.x += 2.0;  // it keeps walking: crossings pile up work for it
    if (p.x > Centre(25, 3).x) p.x = Centre(3, 3).x;
    stalled->SendPose(p, {20, 0, 0});
    grpc::ClientContext ctx;
    v1::ServerStats s;
    ASSERT_TRUE(stats_stub.GetStats(&ctx, v1::StatsRequest(), &s).ok());
    for (const v1::SessionStats& ss : s.sessions()) {
      max_queued = std::max(max_queued, ss.queued_bytes());
      sent = ss.objects_sent();
      crossings = ss.crossings();
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_LE(max_queued, o.limits.max_queued_bytes);
  std::printf("stalled client: %llu crossings, %llu objects written, at most %llu bytes queued (bound %zu)\n",
              static_cast<unsigned long long>(crossings), static_cast<unsigned long long>(sent),
              static_cast<unsigned long long>(max_queued), o.limits.max_queued_bytes);
  stalled->Cancel();
  ExpectStillServes(*server, 9, 9);
}

TEST(Server, QueuedBytesOverTheLimitEndTheSession) {
  ServerOptions o;
  o.limits.max_queued_bytes = 64;  // less than SceneInfo: the limit trips at once
  auto server = StartServer(o);
  SessionStream client(server->address());
  client.Start(SessionStream::HelloFor("city1"));
  const grpc::Status st = client.AwaitEnd(kWait);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << st.error_message();
  EXPECT_NE(st.error_message().find("queued for a client that does not read them (the limit is 64)"),
            std::string::npos)
      << st.error_message();
}

TEST(Server, HundredSessionsWalkingRandomPathsEachGetEveryPvsTheyNeed) {
  ServerOptions o;
  o.max_sessions = 128;
  auto server = StartServer(o);
  constexpr int kSessions = 100;
  std::vector<std::thread> threads;
  std::atomic<int> completed{0};
  std::mutex failures_mu;
  std::vector<std::string> failures;
  for (int s = 0; s < kSessions; ++s) {
    threads.emplace_back([&, s] {
      std::mt19937 rng(s);
      auto client = Connect(*server);
      int i = 2 + static_cast<int>(rng() % 24), j = 2 + static_cast<int>(rng() % 16);
      for (int step = 0; step < 4; ++step) {
        if (step > 0) {
          i = std::clamp(i + static_cast<int>(rng() % 3) - 1, 1, 26);
          j = std::clamp(j + static_cast<int>(rng() % 3) - 1, 1, 18);
        }
        client->SendPose(Centre(i, j), {1.4, 0, 0});
        const std::set<CellId> need = Around(Cell(i, j));
        if (!client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(need); }, 300.0)) {
          std::lock_guard lock(failures_mu);
          const grpc::Status end = client->Ended() ? client->AwaitEnd(kWait) : grpc::Status::OK;
          failures.push_back("session " + std::to_string(s) + " step " + std::to_string(step) +
                             (client->Ended() ? " ended: " + end.error_message() + " (code " +
                                                    std::to_string(end.error_code()) + ")"
                                              : " timed out"));
          return;
        }
      }
      if (client->Finish().ok()) ++completed;
    });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_TRUE(failures.empty()) << failures.size() << " sessions missed a PVS, first: " << failures.front();
  EXPECT_EQ(completed.load(), kSessions);
}

TEST(Server, APortInUseOrABadAddressIsRefused) {
  auto first = StartServer();
  ServerOptions o;
  o.listen = "127.0.0.1:" + std::to_string(first->port());
  const absl::Status taken = WalkthroughServer::Start(&City1(), o, nullptr).status();
  EXPECT_EQ(taken.code(), absl::StatusCode::kUnavailable) << taken;
  EXPECT_NE(taken.message().find("in use"), std::string::npos) << taken;
  for (const char* bad : {"127.0.0.1:99999", "127.0.0.1", "garbage", ":50051", "127.0.0.1:-1", "127.0.0.1:80x"}) {
    o.listen = bad;
    const absl::Status st = WalkthroughServer::Start(&City1(), o, nullptr).status();
    EXPECT_EQ(st.code(), absl::StatusCode::kInvalidArgument) << bad << ": " << st;
    EXPECT_NE(st.message().find(bad), std::string::npos) << st;
  }
}

TEST(Server, StatsHealthAndReflectionAnswer) {
  auto server = StartServer();
  auto client = Connect(*server);
  ASSERT_TRUE(client->SendPose(Centre(8, 8)));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.CellComplete(Cell(8, 8)); }, kWait));
  auto channel = grpc::CreateChannel(server->address(), grpc::InsecureChannelCredentials());
  v1::Walkthrough::Stub stub(channel);
  grpc::ClientContext ctx;
  v1::ServerStats s;
  ASSERT_TRUE(stub.GetStats(&ctx, v1::StatsRequest(), &s).ok());
  EXPECT_EQ(s.scene(), "city1");
  EXPECT_EQ(s.protocol_version(), 1u);
  EXPECT_EQ(s.sessions_active(), 1u);
  ASSERT_EQ(s.sessions_size(), 1);
  EXPECT_EQ(s.sessions(0).cell_id(), Cell(8, 8));
  EXPECT_GT(s.sessions(0).objects_sent(), 0u);
  EXPECT_NE(s.pvs_source().find("dual ray space"), std::string::npos);

  // grpc.health.v1.Health/Check{service: "vistream.v1.Walkthrough"}: SERVING is field 1 = 1.
  grpc::GenericStub generic(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext hctx;
  const std::string service = "vistream.v1.Walkthrough";
  grpc::Slice check(std::string("\x0a") + static_cast<char>(service.size()) + service);
  auto call = generic.PrepareUnaryCall(&hctx, "/grpc.health.v1.Health/Check", grpc::ByteBuffer(&check, 1), &cq);
  call->StartCall();
  grpc::ByteBuffer reply;
  grpc::Status hst;
  call->Finish(&reply, &hst, reinterpret_cast<void*>(1));
  void* tag;
  bool ok;
  ASSERT_TRUE(cq.Next(&tag, &ok));
  ASSERT_TRUE(hst.ok()) << hst.error_message();
  std::vector<grpc::Slice> slices;
  ASSERT_TRUE(reply.Dump(&slices).ok());
  std::string bytes;
  for (const grpc::Slice& sl : slices) bytes.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
  EXPECT_EQ(bytes, std::string("\x08\x01", 2));

  // Reflection lists the service: ServerReflectionRequest{list_services: ""} is field 7.
  grpc::ClientContext rctx;
  auto refl = generic.PrepareCall(&rctx, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  refl->StartCall(reinterpret_cast<void*>(2));
  ASSERT_TRUE(cq.Next(&tag, &ok) && ok);
  grpc::Slice req(std::string("\x3a\x00", 2));
  refl->Write(grpc::ByteBuffer(&req, 1), reinterpret_cast<void*>(3));
  ASSERT_TRUE(cq.Next(&tag, &ok) && ok);
  grpc::ByteBuffer resp;
  refl->Read(&resp, reinterpret_cast<void*>(4));
  ASSERT_TRUE(cq.Next(&tag, &ok) && ok);
  slices.clear();
  ASSERT_TRUE(resp.Dump(&slices).ok());
  bytes.clear();
  for (const grpc::Slice& sl : slices) bytes.append(reinterpret_cast<const char*>(sl.begin()), sl.size());
  EXPECT_NE(bytes.find("vistream.v1.Walkthrough"), std::string::npos);
  rctx.TryCancel();
  grpc::Status rst;
  refl->Finish(&rst, reinterpret_cast<void*>(5));
  while (cq.Next(&tag, &ok) && tag != reinterpret_cast<void*>(5)) {
  }
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
  }
  EXPECT_TRUE(client->Finish().ok());
}

TEST(Server, ServesAPvsFileInsteadOfComputing) {
  // A file whose sets no computation would give: cell c sees objects c, c + 1 and c + 2.
  const visibility::ViewcellGrid& grid = City1().grid();
  const size_t objects = City1().scene().objects.size();
  visibility::GlobalPvs sets(grid.CellCount(), objects);
  for (CellId c = 0; c < grid.CellCount(); ++c) {
    sets.Assign(c, std::vector<scenes::ObjectId>{static_cast<uint32_t>(c % objects),
                                                 static_cast<uint32_t>((c + 1) % objects),
                                                 static_cast<uint32_t>((c + 2) % objects)});
  }
  visibility::PvsProvenance provenance;
  provenance.strategy = "test";
  const std::string path = vistream::testing::ProcessTempDir() + "/served.pvs";
  {
    std::ofstream out(path, std::ios::binary);
    out << visibility::EncodePvsFile(visibility::MakePvsFile(City1().scene(), grid, sets, provenance));
  }
  ServedSceneOptions o;
  o.scene = "city1";
  o.pvs_file = path;
  absl::StatusOr<std::unique_ptr<ServedScene>> scene = ServedScene::Create(o);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_EQ((*scene)->pvs_source(), "PVS file " + path + " (test)");
  ServerOptions so;
  so.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(scene->get(), so, nullptr);
  ASSERT_TRUE(server.ok()) << server.status();
  auto client = Connect(**server);
  ASSERT_TRUE(client->SendPose(Centre(7, 7)));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(Cell(7, 7))); }, kWait));
  const SessionRecord r = client->Snapshot();
  for (const auto& [cell, ids] : r.pvs) EXPECT_EQ(ids, sets.Objects(cell)) << "cell " << cell;
  EXPECT_TRUE(client->Finish().ok());

  // A file made for another grid is refused at start-up, naming it.
  o.cell_size = 25.0;
  const absl::Status other = ServedScene::Create(o).status();
  EXPECT_EQ(other.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(other.message().find(path), std::string::npos) << other;
}

// A session whose Hello asks for ε-masks (a credit window as large as Connect's).
std::unique_ptr<SessionStream> ConnectWithMasks(WalkthroughServer& server) {
  auto c = std::make_unique<SessionStream>(server.address());
  v1::Hello hello = SessionStream::HelloFor("city1");
  hello.set_epsilon_masks(true);
  c->Start(hello, true);
  c->SendCredit(uint64_t{1} << 40);
  return c;
}

// A mask's sets, decoded in arrival order (deltas applied as a client does).
std::vector<visibility::DecodedMask> DecodeAll(const std::vector<v1::EpsilonMask>& masks) {
  visibility::MaskBases bases;
  std::vector<visibility::DecodedMask> out;
  for (const v1::EpsilonMask& m : masks) {
    const auto objects = static_cast<uint32_t>(City1().scene().objects.size());
    absl::StatusOr<std::string> runs = client::MaskRunBytes(m, objects, City1().scene().TriangleCount());
    EXPECT_TRUE(runs.ok()) << runs.status();
    absl::StatusOr<visibility::DecodedMask> d =
        bases.Decode(m.cell_id(), m.mask_id(), m.base_mask_id(), runs.ok() ? *runs : std::string(), objects,
                     City1().scene().TriangleCount());
    EXPECT_TRUE(d.ok()) << d.status();
    out.push_back(d.ok() ? *std::move(d) : visibility::DecodedMask{});
  }
  return out;
}

TEST(Server, AStandingClientGetsAnEpsilonMaskOfTheBoxAroundIt) {
  auto server = StartServer();
  auto client = ConnectWithMasks(*server);
  const glm::dvec3 p = Centre(12, 9);
  const CellId here = Cell(12, 9);
  ASSERT_TRUE(client->SendPose(p));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.CellComplete(here) && !r.masks.empty(); }, kWait));
  const SessionRecord r = client->Snapshot();
  const v1::EpsilonMask& m = r.masks.front();
  EXPECT_EQ(m.cell_id(), here);
  EXPECT_LE(m.neighbourhood_min().x(), p.x);
  EXPECT_GE(m.neighbourhood_max().x(), p.x);
  EXPECT_LE(m.neighbourhood_min().y(), p.y);
  EXPECT_GE(m.neighbourhood_max().y(), p.y);
  EXPECT_LE(m.neighbourhood_min().z(), p.z);
  EXPECT_GE(m.neighbourhood_max().z(), p.z);
  EXPECT_NEAR(m.neighbourhood_max().x() - m.neighbourhood_min().x(), 4.0, 1e-9);  // ChainOptions::standing_size_m
  // Its PVS came first; its sets lie inside the PVS and hide part of it.
  const auto pvs_at = std::find(r.order.begin(), r.order.end(), std::make_pair('P', here));
  const auto mask_at = std::find(r.order.begin(), r.order.end(), std::make_pair('M', m.mask_id()));
  EXPECT_LT(pvs_at, mask_at);
  const visibility::DecodedMask d = DecodeAll(r.masks).front();
  const std::vector<uint32_t>& pvs = r.pvs.at(here);
  uint64_t total = 0;
  for (uint32_t o : pvs) total += City1().scene().objects[o].mesh.TriangleCount();
  for (const visibility::MaskObject& o : d.objects) {
    EXPECT_TRUE(std::binary_search(pvs.begin(), pvs.end(), o.object)) << o.object;
    EXPECT_LE(o.bits.size(), (City1().scene().objects[o.object].mesh.TriangleCount() + 7) / 8);
  }
  EXPECT_EQ(d.objects.size(), m.object_count());
  EXPECT_EQ(d.triangles, m.triangle_count());
  EXPECT_GT(d.triangles, 0u);
  EXPECT_LT(d.triangles, total);
  std::printf("mask: %llu of the PVS's %llu triangles, %zu bytes\n", static_cast<unsigned long long>(d.triangles),
              static_cast<unsigned long long>(total), m.triangles().size());
  EXPECT_FALSE(m.deflated());  // this client did not say it inflates
  EXPECT_TRUE(client->Finish().ok());
  // A client that inflates masks (every client model's Hello) gets the same sets in fewer bytes.
  client::HelloSettings settings;
  settings.scene = "city1";
  settings.epsilon_masks = true;
  SessionStream deflating(server->address());
  deflating.Start(client::MakeHello(settings), true);
  deflating.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(deflating.SendPose(p));
  ASSERT_TRUE(deflating.WaitFor([&](const SessionRecord& s) { return !s.masks.empty(); }, kWait));
  const v1::EpsilonMask deflated = deflating.Snapshot().masks.front();
  EXPECT_TRUE(deflated.deflated());
  EXPECT_LT(deflated.triangles().size(), m.triangles().size());
  const visibility::DecodedMask same = DecodeAll({deflated}).front();
  EXPECT_EQ(same.triangles, d.triangles);
  ASSERT_EQ(same.objects.size(), d.objects.size());
  for (size_t k = 0; k < d.objects.size(); ++k) {
    EXPECT_EQ(same.objects[k].object, d.objects[k].object);
    EXPECT_EQ(same.objects[k].bits, d.objects[k].bits);
  }
  EXPECT_TRUE(deflating.Finish().ok());
}

TEST(Server, AnEpsilonMaskNeverReachesPastTheCellWhosePvsItNarrows) {
  auto server = StartServer();
  auto client = ConnectWithMasks(*server);
  const CellId here = Cell(12, 9);
  const scenes::Aabb cell = City1().grid().CellBox(here);
  const glm::dvec3 p(cell.max.x - 0.5, cell.min.y + 0.5, Centre(12, 9).z);  // by a corner
  ASSERT_TRUE(client->SendPose(p));
  ASSERT_TRUE(client->WaitFor([](const SessionRecord& r) { return !r.masks.empty(); }, kWait));
  const v1::EpsilonMask m = client->Snapshot().masks.front();
  EXPECT_EQ(m.cell_id(), here);
  EXPECT_LE(m.neighbourhood_max().x(), cell.max.x);
  EXPECT_GE(m.neighbourhood_min().y(), cell.min.y);
  EXPECT_NEAR(m.neighbourhood_max().x() - m.neighbourhood_min().x(), 2.5, 1e-9);  // 2 m to the left, 0.5 to the edge
  EXPECT_NEAR(m.neighbourhood_max().y() - m.neighbourhood_min().y(), 2.5, 1e-9);
  EXPECT_TRUE(client->Finish().ok());
}

TEST(Server, AClientThatDoesNotAskForMasksGetsNone) {
  auto server = StartServer();
  auto client = Connect(*server);
  const CellId here = Cell(12, 9);
  ASSERT_TRUE(client->SendPose(Centre(12, 9)));
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.AllComplete(Around(here)); }, kWait));
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));  // a mask takes tens of ms
  EXPECT_TRUE(client->Snapshot().masks.empty());
  // The same place with masks asked for gets one: the wait above was long enough.
  auto with = ConnectWithMasks(*server);
  ASSERT_TRUE(with->SendPose(Centre(12, 9)));
  EXPECT_TRUE(with->WaitFor([](const SessionRecord& r) { return !r.masks.empty(); }, kWait));
  EXPECT_TRUE(client->Finish().ok());
  EXPECT_TRUE(with->Finish().ok());
}

// A walker down a street: masks of the boxes ahead arrive before the eye gets there, each after
// its cell's PVS; every box lies in its cell and no mask lists an object outside that PVS.
TEST(Server, AWalkerGetsTheMasksOfTheBoxesAheadBeforeItReachesThem) {
  auto server = StartServer();
  auto client = ConnectWithMasks(*server);
  const visibility::ViewcellGrid& g = City1().grid();
  // Along row 9 of city1's grid from cell 10 to 13 at 6 km/h, poses at 20 Hz (sped up 4x: the
  // server predicts from the velocity sent, which is the true one).
  const glm::dvec3 start = Centre(10, 9), end = Centre(13, 9);
  const double v = 6.0 / 3.6;
  const glm::dvec3 velocity = glm::normalize(end - start) * v;
  const int steps = static_cast<int>(glm::length(end - start) / v * 20.0);
  std::vector<std::pair<glm::dvec3, size_t>> poses;  // where, and how many masks were in
  for (int k = 0; k <= steps; ++k) {
    const glm::dvec3 eye = start + (end - start) * (static_cast<double>(k) / steps);
    ASSERT_TRUE(client->SendPose(eye, velocity));
    poses.emplace_back(eye, client->Snapshot().masks.size());
    std::this_thread::sleep_for(std::chrono::milliseconds(12));
  }
  const SessionRecord r = client->Snapshot();
  ASSERT_GE(r.masks.size(), 3u);
  const std::vector<visibility::DecodedMask> decoded = DecodeAll(r.masks);
  size_t ahead = 0;
  for (size_t k = 0; k < r.masks.size(); ++k) {
    const v1::EpsilonMask& m = r.masks[k];
    const scenes::Aabb box{glm::dvec3(m.neighbourhood_min().x(), m.neighbourhood_min().y(), m.neighbourhood_min().z()),
                           glm::dvec3(m.neighbourhood_max().x(), m.neighbourhood_max().y(), m.neighbourhood_max().z())};
    const scenes::Aabb cell = g.CellBox(m.cell_id());
    EXPECT_GE(box.min.x, cell.min.x - 1e-9);
    EXPECT_LE(box.max.x, cell.max.x + 1e-9);
    EXPECT_GE(box.min.y, cell.min.y - 1e-9);
    EXPECT_LE(box.max.y, cell.max.y + 1e-9);
    const auto pvs_at = std::find(r.order.begin(), r.order.end(), std::make_pair('P', m.cell_id()));
    const auto mask_at = std::find(r.order.begin(), r.order.end(), std::make_pair('M', m.mask_id()));
    EXPECT_LT(pvs_at, mask_at) << "mask " << m.mask_id();
    const std::vector<uint32_t>& pvs = r.pvs.at(m.cell_id());
    for (const visibility::MaskObject& o : decoded[k].objects) {
      EXPECT_TRUE(std::binary_search(pvs.begin(), pvs.end(), o.object)) << "mask " << m.mask_id() << " object " << o.object;
    }
    // The first pose inside the box: the mask had arrived by then.
    for (const auto& [eye, held] : poses) {
      if (eye.x < box.min.x || eye.x > box.max.x || eye.y < box.min.y || eye.y > box.max.y) continue;
      if (held > k) ++ahead;
      break;
    }
  }
  // The very first box is the one the eye starts in; the others were sent ahead.
  EXPECT_GE(ahead + 1, r.masks.size() * 3 / 4) << ahead << " of " << r.masks.size() << " ahead";
  std::printf("%zu masks, %zu arrived before the eye reached their box; %llu deltas\n", r.masks.size(), ahead,
              static_cast<unsigned long long>(std::count_if(r.masks.begin(), r.masks.end(),
                                                            [](const v1::EpsilonMask& m) { return m.base_mask_id() != 0; })));
  EXPECT_TRUE(client->Finish().ok());
}

}  // namespace
}  // namespace vistream::server

namespace vistream::server {
namespace {

// Issue 35: the scene's own walks (Scene::paths) reach the client in SceneInfo.paths; a scene
// without them sends none.
// SceneInfo.paths: every walk of the scene, the catalog entry's first (a client without the
// catalog, the browser's, follows them by name), then the scene's own.
TEST(Server, SceneInfoCarriesTheCatalogsWalksAndTheScenesOwn) {
  auto plain = StartServer();
  auto c = Connect(*plain);
  ASSERT_TRUE(c->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  const absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry("city1");
  ASSERT_TRUE(entry.ok()) << entry.status();
  ASSERT_FALSE(entry->walks.empty());
  const v1::SceneInfo catalog_info = c->Snapshot().info;
  ASSERT_EQ(catalog_info.paths_size(), static_cast<int>(entry->walks.size()));
  for (size_t k = 0; k < entry->walks.size(); ++k) {
    EXPECT_EQ(catalog_info.paths(static_cast<int>(k)).name(), entry->walks[k].name);
    EXPECT_EQ(catalog_info.paths(static_cast<int>(k)).xy_size(), static_cast<int>(2 * entry->walks[k].waypoints.size()));
    EXPECT_EQ(catalog_info.paths(static_cast<int>(k)).xy(0), entry->walks[k].waypoints.front().x);
  }
  EXPECT_TRUE(c->Finish().ok());

  scenes::Scene scene = City1().scene();
  scene.paths = {{"street 1", {{-100.5, 20.25}, {300.0, 20.25}, {300.0, 400.0}}}, {"lane", {{0, 0}, {1, 1}}}};
  const std::string glb = vistream::testing::ProcessTempDir() + "/server_paths.glb";
  ASSERT_TRUE(scenes::SaveGltf(scene, glb).ok());
  ServedSceneOptions o;
  o.scene = glb;
  o.name = "city1";  // Connect's Hello names city1
  o.threads = 1;
  absl::StatusOr<std::unique_ptr<ServedScene>> served = ServedScene::Create(o);
  ASSERT_TRUE(served.ok()) << served.status();
  ASSERT_EQ((*served)->scene_info().paths_size(), 2);
  ServerOptions so;
  so.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(served->get(), so, nullptr);
  ASSERT_TRUE(server.ok()) << server.status();
  auto d = Connect(**server);
  ASSERT_TRUE(d->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  const v1::SceneInfo info = d->Snapshot().info;
  ASSERT_EQ(info.paths_size(), 2);
  EXPECT_EQ(info.paths(0).name(), "street 1");
  EXPECT_EQ(std::vector<double>(info.paths(0).xy().begin(), info.paths(0).xy().end()),
            (std::vector<double>{-100.5, 20.25, 300.0, 20.25, 300.0, 400.0}));
  EXPECT_EQ(info.paths(1).name(), "lane");
  EXPECT_EQ(info.paths(1).xy_size(), 4);
  EXPECT_TRUE(d->Finish().ok());
}

}  // namespace
}  // namespace vistream::server
