// Several scenes in one server: Hello picks one, each scene keeps its own grid, PVSs and cache,
// and one pool of PVS workers is shared fairly (a flood on one scene does not starve another).
#include <memory>
#include <set>
#include <vector>

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include "client/connection.h"
#include "client/session_stream.h"
#include "gl/pvs_backend.h"
#include "server/service.h"
#include "tests/server_test_util.h"
#include "visibility/kdtree.h"
#include "visibility/pvs.h"

namespace vistream::server {
namespace {

using client::SessionRecord;
using client::SessionStream;
using test::kWait;

// city1 (50 m cells) and streets (the catalog's small terraced district) on one pool.
struct TwoScenes {
  std::unique_ptr<PvsWorkerPool> pool;
  std::unique_ptr<ServedScene> city1, streets;
};

std::unique_ptr<ServedScene> Load(const char* name, PvsWorkerPool* pool) {
  ServedSceneOptions o;
  o.scene = name;
  o.pool = pool;
  absl::StatusOr<std::unique_ptr<ServedScene>> s = ServedScene::Create(o);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

// One worker: what the pool does for one scene it cannot do for the other at the same time.
TwoScenes& Scenes() {
  static TwoScenes* s = [] {
    auto* t = new TwoScenes;
    t->pool = std::make_unique<PvsWorkerPool>(1);
    t->city1 = Load("city1", t->pool.get());
    t->streets = Load("streets", t->pool.get());
    return t;
  }();
  return *s;
}

std::unique_ptr<WalkthroughServer> StartBoth() {
  ServerOptions options;
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> s =
      WalkthroughServer::Start({Scenes().city1.get(), Scenes().streets.get()}, options, nullptr);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

glm::dvec3 CentreOf(const ServedScene& scene, int i, int j) {
  const scenes::Aabb b = scene.grid().CellBox(visibility::CellCoord{i, j});
  return {0.5 * (b.min.x + b.max.x), 0.5 * (b.min.y + b.max.y), scene.grid().base_z() + 1.2};
}

std::vector<uint32_t> ExpectedPvsOf(const ServedScene& scene, CellId cell) {
  const visibility::KdTree tree = visibility::KdTree::Build(scene.scene());
  const visibility::PvsComputer computer(scene.scene(), tree);
  const absl::StatusOr<gl::PvsBackend> cpu = gl::PvsBackend::Create("cpu");
  return cpu->Compute(computer, scene.grid().CellBox(cell), gl::QueryOptionsFor(128)).objects;
}

std::unique_ptr<SessionStream> Open(WalkthroughServer& server, const std::string& scene) {
  auto c = std::make_unique<SessionStream>(server.address());
  c->Start(SessionStream::HelloFor(scene));
  c->SendCredit(uint64_t{1} << 40);
  return c;
}

TEST(ServerScenes, SessionsOnBothScenesAtOnceEachGetTheirOwnScene) {
  std::unique_ptr<WalkthroughServer> server = StartBoth();
  ASSERT_NE(server, nullptr);
  const ServedScene& city1 = *Scenes().city1;
  const ServedScene& streets = *Scenes().streets;
  auto a = Open(*server, "city1");
  auto b = Open(*server, "streets");
  ASSERT_TRUE(a->SendPose(CentreOf(city1, 14, 10)));
  ASSERT_TRUE(b->SendPose(CentreOf(streets, 1, 1)));
  const CellId ca = city1.grid().Id({14, 10}), cb = streets.grid().Id({1, 1});
  ASSERT_TRUE(a->WaitFor([&](const SessionRecord& r) { return r.CellComplete(ca); }, kWait));
  ASSERT_TRUE(b->WaitFor([&](const SessionRecord& r) { return r.CellComplete(cb); }, kWait));
  const SessionRecord ra = a->Snapshot(), rb = b->Snapshot();
  EXPECT_EQ(ra.info.name(), "city1");
  EXPECT_EQ(rb.info.name(), "streets");
  EXPECT_EQ(ra.info.object_count(), city1.scene().objects.size());
  EXPECT_EQ(rb.info.object_count(), streets.scene().objects.size());
  EXPECT_EQ(rb.info.grid().nx(), streets.grid().nx());
  // Each its own scene's sets, and geometry of its own scene's objects (the same ids mean
  // different objects in the two scenes: the meshes must be the right scene's).
  EXPECT_EQ(ra.pvs.at(ca), ExpectedPvsOf(city1, ca));
  EXPECT_EQ(rb.pvs.at(cb), ExpectedPvsOf(streets, cb));
  for (const auto& [id, g] : rb.geometry) {
    ASSERT_LT(id, streets.scene().objects.size());
    EXPECT_EQ(g.vertex_count(), streets.geometry(id).vertex_count) << "object " << id;
  }
  for (const auto& [id, g] : ra.geometry) {
    ASSERT_LT(id, city1.scene().objects.size());
    EXPECT_EQ(g.vertex_count(), city1.geometry(id).vertex_count) << "object " << id;
  }
  // GetStats: protocol version 1's `scene` is the first one, and both are listed with their
  // own sessions.
  const v1::ServerStats stats = server->service().Stats();
  EXPECT_EQ(stats.scene(), "city1");
  ASSERT_EQ(stats.scenes_size(), 2);
  EXPECT_EQ(stats.scenes(0).name(), "city1");
  EXPECT_EQ(stats.scenes(1).name(), "streets");
  EXPECT_EQ(stats.scenes(0).sessions_active(), 1u);
  EXPECT_EQ(stats.scenes(1).sessions_active(), 1u);
  EXPECT_EQ(stats.scenes(1).object_count(), streets.scene().objects.size());
  EXPECT_GT(stats.scenes(1).bytes_sent(), 0u);
  EXPECT_TRUE(a->Finish().ok());
  EXPECT_TRUE(b->Finish().ok());
}

TEST(ServerScenes, AHelloForAnotherSceneIsNotFoundNamingTheScenesServed) {
  std::unique_ptr<WalkthroughServer> server = StartBoth();
  ASSERT_NE(server, nullptr);
  auto c = Open(*server, "london");
  const grpc::Status st = c->AwaitEnd(kWait);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(st.error_message(), "scene 'london' is not served here: this server serves 'city1', 'streets'");
  // The client picks among what GetStats lists.
  const v1::ServerStats stats = server->service().Stats();
  EXPECT_EQ(client::PickScene(stats, "streets", "A").value(), "streets");
  const absl::StatusOr<std::string> none = client::PickScene(stats, "", "A");
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.status().message(), "the server at A serves 2 scenes: choose one with --scene (city1, streets)");
  EXPECT_EQ(client::PickScene(stats, "london", "A").status().message(),
            "the server at A does not serve scene 'london'; it serves: city1, streets");
  // A server of one scene that lists none (an older one) still names it.
  v1::ServerStats old;
  old.set_scene("city1");
  EXPECT_EQ(client::PickScene(old, "", "A").value(), "city1");
}

// One worker, a flood of requests on city1: a crossing on streets is served while the flood
// still waits, not after it.
TEST(ServerScenes, AFloodOnOneSceneDoesNotStarveTheOther) {
  std::unique_ptr<WalkthroughServer> server = StartBoth();
  ASSERT_NE(server, nullptr);
  ServedScene& city1 = *Scenes().city1;
  const ServedScene& streets = *Scenes().streets;
  // Sessions across the whole of city1 ask for most of its 560 cells, not yet computed... (the
  // cache may hold some from the test before; those are few).
  std::vector<std::unique_ptr<SessionStream>> flood;
  for (int i = 2; i < city1.grid().nx(); i += 3) {
    for (int j = 2; j < city1.grid().ny(); j += 3) {
      flood.push_back(Open(*server, "city1"));
      ASSERT_TRUE(flood.back()->SendPose(CentreOf(city1, i, j)));
    }
  }
  auto queued = [&] { return city1.scheduler().stats().queued; };
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(static_cast<int>(kWait));
  while (queued() < 100 && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_GE(queued(), 100u) << "the flood did not queue";
  // A walker on streets crosses from (0, 0) into (1, 0).
  auto walker = Open(*server, "streets");
  ASSERT_TRUE(walker->SendPose(CentreOf(streets, 0, 0)));
  const CellId start = streets.grid().Id({0, 0}), next = streets.grid().Id({1, 0});
  uint64_t left_at_start = 0, left_at_crossing = 0;
  ASSERT_TRUE(walker->WaitFor([&](const SessionRecord& r) { return r.CellComplete(start); }, kWait));
  left_at_start = queued();
  ASSERT_TRUE(walker->SendPose(CentreOf(streets, 1, 0), glm::dvec3(1.4, 0.0, 0.0)));
  ASSERT_TRUE(walker->WaitFor([&](const SessionRecord& r) { return r.CellComplete(next); }, kWait));
  left_at_crossing = queued();
  // Round robin: each of streets' jobs waited for at most one of city1's. Had the flood been
  // served first, nothing of it would be left.
  EXPECT_GT(left_at_start, 0u);
  EXPECT_GT(left_at_crossing, 0u);
  EXPECT_TRUE(walker->Finish().ok());
  for (auto& f : flood) f->Cancel();
}

// The pool alone: two schedulers, one worker; one scheduler's queue of many jobs and the
// other's one job: the one job runs second, not last.
TEST(PvsWorkerPool, SchedulersTakeTurnsOnSharedWorkers) {
  PvsWorkerPool pool(1);
  std::mutex mu;
  std::vector<std::pair<char, CellId>> ran;
  std::atomic<bool> release{false};
  auto compute_for = [&](char which) {
    return [&, which](CellId cell, unsigned) {
      while (which == 'a' && cell == 0 && !release) std::this_thread::sleep_for(std::chrono::milliseconds(1));
      std::lock_guard lock(mu);
      ran.emplace_back(which, cell);
      return CellPvs{cell, {}, 0.0};
    };
  };
  PvsScheduler a(compute_for('a'), &pool, 1 << 20), b(compute_for('b'), &pool, 1 << 20);
  std::atomic<int> done{0};
  auto count = [&](const CellPvsPtr&) { ++done; };
  a.Request(1, 0, 0.0, count);  // holds the worker until released
  while (a.stats().queued != 0) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  for (CellId c = 1; c <= 10; ++c) a.Request(1, c, static_cast<double>(c), count);
  b.Request(2, 0, 100.0, count);  // a later deadline than all of a's
  release = true;
  while (done < 12) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  std::lock_guard lock(mu);
  ASSERT_EQ(ran.size(), 12u);
  EXPECT_EQ(ran[0], std::make_pair('a', CellId{0}));
  EXPECT_EQ(ran[1], std::make_pair('b', CellId{0}));  // its turn, whatever the deadlines
  EXPECT_EQ(ran[2], std::make_pair('a', CellId{1}));
}

}  // namespace
}  // namespace vistream::server
