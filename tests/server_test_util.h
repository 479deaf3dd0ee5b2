#pragma once
// What the walkthrough server's tests share: city1 served with 50 m viewcells, a server on a
// free loopback port, scripted clients (client/session_stream.h) and the PVSs to expect.

#include <set>
#include <vector>

#include <glm/vec3.hpp>
#include <gtest/gtest.h>

#include "client/session_stream.h"
#include "gl/pvs_backend.h"
#include "server/service.h"
#include "visibility/kdtree.h"
#include "visibility/pvs.h"

namespace vistream::server::test {

using client::SessionStream;

inline constexpr double kWait = 120.0;  // seconds any one wait may take on a loaded 2-core machine

// city1 with 50 m viewcells (28 x 20), shared by every test: it takes a few seconds to prepare.
inline ServedScene& City1() {
  static ServedScene* scene = [] {
    ServedSceneOptions o;
    o.scene = "city1";
    o.threads = 2;
    o.idle_priority_masks = false;  // masks as they are sent, whatever else loads the machine
    absl::StatusOr<std::unique_ptr<ServedScene>> s = ServedScene::Create(o);
    EXPECT_TRUE(s.ok()) << s.status();
    return s->release();
  }();
  return *scene;
}

inline std::unique_ptr<WalkthroughServer> StartServer(ServerOptions options = {}) {
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> s = WalkthroughServer::Start(&City1(), options, nullptr);
  EXPECT_TRUE(s.ok()) << s.status();
  return std::move(*s);
}

// The eye at the centre of cell (i, j).
inline glm::dvec3 Centre(int i, int j) {
  const visibility::ViewcellGrid& g = City1().grid();
  const scenes::Aabb b = g.CellBox(visibility::CellCoord{i, j});
  return {0.5 * (b.min.x + b.max.x), 0.5 * (b.min.y + b.max.y), g.base_z() + 1.2};
}

inline CellId Cell(int i, int j) { return City1().grid().Id({i, j}); }

inline std::set<CellId> Around(CellId c) {
  std::set<CellId> s{c};
  for (CellId n : City1().grid().Neighbours(c)) s.insert(n);
  return s;
}

// The PVS `vistream pvs` computes for the cell (same backend, same options).
inline std::vector<uint32_t> ExpectedPvs(CellId cell) {
  static const visibility::KdTree tree = visibility::KdTree::Build(City1().scene());
  static const visibility::PvsComputer computer(City1().scene(), tree);
  static const absl::StatusOr<gl::PvsBackend> cpu = gl::PvsBackend::Create("cpu");
  return cpu->Compute(computer, City1().grid().CellBox(cell), gl::QueryOptionsFor(128)).objects;
}

inline std::unique_ptr<SessionStream> Connect(WalkthroughServer& server, bool read = true) {
  auto c = std::make_unique<SessionStream>(server.address());
  c->Start(SessionStream::HelloFor("city1"), read);
  c->SendCredit(uint64_t{1} << 40);
  return c;
}

// A new session is served: its cell (i, j) arrives complete and it ends cleanly. After a bad
// client was dealt with, this says the server is still whole.
inline void ExpectStillServes(WalkthroughServer& server, int i, int j) {
  auto good = Connect(server);
  ASSERT_TRUE(good->SendPose(Centre(i, j)));
  EXPECT_TRUE(good->WaitFor([&](const client::SessionRecord& r) { return r.CellComplete(Cell(i, j)); }, kWait));
  EXPECT_TRUE(good->Finish().ok());
}

}  // namespace vistream::server::test
