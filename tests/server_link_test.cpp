// The walkthrough server's link emulation (ServerOptions::link, vistream-server --emulate-link)
// and its event log: a real server on loopback, scripted clients, the log read back as JSON.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <functional>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "client/session_stream.h"
#include "server/event_log.h"
#include "server/link_model.h"
#include "server/service.h"
#include "tests/server_test_util.h"

namespace vistream::server {
namespace {

using client::SessionRecord;
using client::SessionStream;
using test::Cell;
using test::Centre;
using test::City1;
using test::Connect;
using test::ExpectStillServes;
using test::kWait;
using test::StartServer;

TEST(ServerLink, AnEmulatedLinkDelaysTheFirstCellByBothLatenciesAndItsTransmission) {
  ServerOptions o;
  LinkParams link;
  link.bandwidth_bps = 4e6;
  link.latency_s = 0.25;
  o.link = link;
  auto server = StartServer(o);
  auto client = Connect(*server);
  const auto start = std::chrono::steady_clock::now();
  const double t0 = std::chrono::duration<double>(start.time_since_epoch()).count();
  ASSERT_TRUE(client->SendPose(Centre(4, 4)));
  const CellId cell = Cell(4, 4);
  ASSERT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.CellComplete(cell); }, kWait));
  const SessionRecord r = client->Snapshot();
  // The pose went up (0.25 s), the PVS was computed, and its list and geometry came down (0.25 s
  // after each left, one after another at 4 Mbit/s): nothing of it can be here sooner.
  uint64_t wire = 0;
  for (uint32_t id : r.pvs.at(cell)) wire += WireBytes(r.geometry.at(id).ByteSizeLong());
  const double took = r.CompletedAfter(cell, t0) - t0;
  std::printf("first cell complete after %.3f s, %llu bytes on the wire\n", took, static_cast<unsigned long long>(wire));
  EXPECT_GE(took, 0.5 + static_cast<double>(wire) * 8.0 / link.bandwidth_bps) << wire << " bytes on the wire";
  // Still in the server's order: the current cell's list first.
  ASSERT_FALSE(r.pvs_order.empty());
  EXPECT_EQ(r.pvs_order.front(), cell);
  EXPECT_EQ(r.duplicates, 0u);
  EXPECT_TRUE(client->Finish().ok());
}

// The JSON log lines of a city1 server on a free loopback port (with `o`'s other options)
// while `use` runs against it, up to its shutdown (which waits until every session's end is
// logged).
std::vector<nlohmann::json> LogOf(ServerOptions o, const std::function<void(WalkthroughServer&)>& use) {
  std::FILE* out = std::tmpfile();
  EXPECT_NE(out, nullptr);
  if (out == nullptr) return {};
  {
    EventLog log(out, /*json=*/true);
    o.listen = "127.0.0.1:0";
    absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(&City1(), o, &log);
    EXPECT_TRUE(server.ok()) << server.status();
    if (server.ok()) {
      use(**server);
      (*server)->Shutdown(1.0);
    }
  }
  std::rewind(out);
  std::vector<nlohmann::json> lines;
  char line[4096];
  while (std::fgets(line, sizeof(line), out) != nullptr) {
    nlohmann::json j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (j.is_object()) lines.push_back(std::move(j));
  }
  std::fclose(out);
  return lines;
}

// The session_end "link" line of a session walked through a server that emulates `link`.
nlohmann::json LinkLineOfAWalk(const LinkParams& link) {
  ServerOptions o;
  o.link = link;
  nlohmann::json found;
  for (nlohmann::json& j : LogOf(o, [](WalkthroughServer& server) {
         auto client = Connect(server);
         for (int i = 3; i <= 6; ++i) {
           client->SendPose(Centre(i, 4), glm::dvec3(10.0, 0.0, 0.0));
           EXPECT_TRUE(client->WaitFor([&](const SessionRecord& r) { return r.CellComplete(Cell(i, 4)); }, kWait));
         }
         EXPECT_TRUE(client->Finish().ok());
       })) {
    if (j.value("event", "") == "link" && j.contains("session")) found = std::move(j);
  }
  return found;
}

// A client that goes away mid-walk (its call cancelled, as when it is killed) ends only its own
// session, and the log says it was cancelled, not that it ended as a client that finished.
TEST(ServerLog, AClientThatGoesAwayIsLoggedAsCancelledNotAsFinished) {
  std::vector<nlohmann::json> ends;
  for (nlohmann::json& j : LogOf({}, [](WalkthroughServer& server) {
         auto gone = Connect(server);
         ASSERT_TRUE(gone->SendPose(Centre(4, 4)));
         ASSERT_TRUE(gone->WaitFor([&](const SessionRecord& r) { return r.CellComplete(Cell(4, 4)); }, kWait));
         gone->Cancel();
         // Its end is logged before the next session starts (active until then).
         for (int k = 0; k < 500 && server.service().active_sessions() > 0; ++k) {
           std::this_thread::sleep_for(std::chrono::milliseconds(10));
         }
         ExpectStillServes(server, 6, 4);
       })) {
    if (j.value("event", "") == "session_end") ends.push_back(std::move(j));
  }
  ASSERT_EQ(ends.size(), 2u);
  EXPECT_EQ(ends[0].value("code", -1), static_cast<int>(grpc::StatusCode::CANCELLED)) << ends[0].dump();
  EXPECT_EQ(ends[0].value("status", ""), "error") << ends[0].dump();
  EXPECT_NE(ends[0].value("message", "").find("cancelled by the client"), std::string::npos) << ends[0].dump();
  EXPECT_EQ(ends[1].value("code", -1), 0) << ends[1].dump();
  EXPECT_EQ(ends[1].value("status", ""), "OK") << ends[1].dump();
}

// A cell's PVS is logged as computed, with its computation's time, by the session that had it
// computed, and as a cache hit costing nothing by the next one.
TEST(ServerLog, ACacheHitIsLoggedWithNoComputeTime) {
  std::vector<nlohmann::json> here;  // the pvs lines of cell 6,4, in order
  for (const nlohmann::json& j : LogOf({}, [](WalkthroughServer& server) {
         ExpectStillServes(server, 6, 4);
         ExpectStillServes(server, 6, 4);
       })) {
    if (j.value("event", "") != "pvs") continue;
    const std::string source = j.value("source", "");
    ASSERT_TRUE(source == "computed" || source == "cache") << j.dump();
    if (source == "cache") {
      EXPECT_EQ(j.value("ms", -1.0), 0.0) << j.dump();
    } else {
      EXPECT_GT(j.value("ms", -1.0), 0.0) << j.dump();
    }
    if (j.value("cell", "") == "6,4") here.push_back(j);
  }
  ASSERT_EQ(here.size(), 2u);
  EXPECT_NE(here[0].value("session", 0), here[1].value("session", 0));
  EXPECT_EQ(here[1].value("source", ""), "cache") << here[1].dump();
}

TEST(ServerLink, TheLogShowsJitterOnlyWhereTheSceneDeclaresIt) {
  // Time scale 20: the declared links, twenty times faster, so that the walk takes little time.
  absl::StatusOr<scenes::CatalogEntry> plain = scenes::FindCatalogEntry("default");
  absl::StatusOr<scenes::CatalogEntry> jittery = scenes::FindCatalogEntry("city1");
  ASSERT_TRUE(plain.ok() && jittery.ok());
  ASSERT_FALSE(plain->simulation.link->jitter_ms.has_value()) << "default declares no jitter";
  ASSERT_TRUE(jittery->simulation.link->jitter_ms.has_value()) << "city1 declares jitter";

  const nlohmann::json none = LinkLineOfAWalk(LinkParamsFrom(plain->simulation.link, 20.0));
  ASSERT_TRUE(none.is_object()) << "no link line in the log";
  EXPECT_GT(none["messages"].get<double>(), 20);
  EXPECT_GT(none["wire_bytes"].get<double>(), 1e5);
  EXPECT_EQ(none["mean_jitter_ms"].get<double>(), 0.0);
  EXPECT_EQ(none["max_jitter_ms"].get<double>(), 0.0);
  EXPECT_EQ(none["lost_segments"].get<double>(), 0.0);  // default declares no loss either
  EXPECT_GE(none["mean_delay_ms"].get<double>(), 40.0 / 20.0);

  const LinkParams city1 = LinkParamsFrom(jittery->simulation.link, 20.0);
  const nlohmann::json some = LinkLineOfAWalk(city1);
  ASSERT_TRUE(some.is_object()) << "no link line in the log";
  EXPECT_GT(some["mean_jitter_ms"].get<double>(), 0.0);
  EXPECT_LE(some["max_jitter_ms"].get<double>(), 2e3 * city1.jitter_s + 1e-3);  // draws are in [0, 2 jitter]
  EXPECT_GE(some["mean_delay_ms"].get<double>(), 1e3 * city1.latency_s);
  EXPECT_GT(some["uplink_messages"].get<double>(), 4);
}

TEST(ServerLink, AClientThatStopsReadingCostsBoundedMemoryThroughTheLinkToo) {
  std::FILE* out = std::tmpfile();
  ASSERT_NE(out, nullptr);
  uint64_t max_queued = 0, crossings = 0;
  ServerOptions o;
  o.limits.max_queued_bytes = 1 << 20;
  LinkParams link;
  link.bandwidth_bps = 1e9;  // fast: the link would take all the session has
  link.latency_s = 0.05;
  o.link = link;
  {
    EventLog log(out, /*json=*/true);
    o.listen = "127.0.0.1:0";
    absl::StatusOr<std::unique_ptr<WalkthroughServer>> server = WalkthroughServer::Start(&City1(), o, &log);
    ASSERT_TRUE(server.ok()) << server.status();
    auto stalled = Connect(**server, /*read=*/false);
    v1::Walkthrough::Stub stats_stub(grpc::CreateChannel((*server)->address(), grpc::InsecureChannelCredentials()));
    glm::dvec3 p = Centre(3, 3);
    for (int k = 0; k < 50; ++k) {
      p.x += 10.0;  // 100 m/s: a crossing every half second
      if (p.x > Centre(25, 3).x) p.x = Centre(3, 3).x;
      stalled->SendPose(p, {20, 0, 0});
      grpc::ClientContext ctx;
      v1::ServerStats s;
      ASSERT_TRUE(stats_stub.GetStats(&ctx, v1::StatsRequest(), &s).ok());
      for (const v1::SessionStats& ss : s.sessions()) {
        max_queued = std::max(max_queued, ss.queued_bytes());
        crossings = ss.crossings();
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    // Its poses still come through while the downlink waits for it to read.
    EXPECT_GE(crossings, 8u);
    stalled->Cancel();
    auto good = Connect(**server);
    ASSERT_TRUE(good->SendPose(Centre(9, 9)));
    EXPECT_TRUE(good->WaitFor([&](const SessionRecord& r) { return r.CellComplete(Cell(9, 9)); }, kWait));
    EXPECT_TRUE(good->Finish().ok());
    for (int k = 0; k < 200 && (*server)->service().active_sessions() > 0; ++k) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    (*server)->Shutdown(1.0);
  }
  EXPECT_LE(max_queued, o.limits.max_queued_bytes);
  std::rewind(out);
  char line[4096];
  uint64_t max_in_link = 0;
  int links = 0;
  while (std::fgets(line, sizeof(line), out) != nullptr) {
    nlohmann::json j = nlohmann::json::parse(line, nullptr, /*allow_exceptions=*/false);
    if (!j.is_object() || j.value("event", "") != "link" || !j.contains("session")) continue;
    ++links;
    max_in_link = std::max(max_in_link, j["max_in_link_bytes"].get<uint64_t>());
  }
  std::fclose(out);
  EXPECT_EQ(links, 2);
  // What waits in the link stops growing at the bound (plus the one message that crossed it).
  EXPECT_LE(max_in_link, o.limits.max_queued_bytes + (uint64_t{1} << 20));
  EXPECT_GT(max_in_link, 0u);
  std::printf("stalled client through the link: %llu crossings, at most %llu bytes queued, %llu in the link\n",
              static_cast<unsigned long long>(crossings), static_cast<unsigned long long>(max_queued),
              static_cast<unsigned long long>(max_in_link));
}

}  // namespace
}  // namespace vistream::server
