// Replicas sharing the PVS store, as processes: two vistream-server executables with one real
// redis-server on loopback. What one computes the other reads (GetStats and /metrics say so);
// Redis stopped mid-walk, the sessions go on and the metric and the log say so; Redis back,
// the store is written and read again.

#include <signal.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <tuple>

#include <gtest/gtest.h>

#include "client/connection.h"
#include "tests/loopback_util.h"
#include "tests/redis_test_util.h"
#include "tests/server_process_util.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"
#include "tools/replica_set.h"

namespace vistream::server {
namespace {

using client::SessionRecord;
using client::SessionStream;
using Clock = std::chrono::steady_clock;

// /metrics of a server whose ready line names it ("...; metrics on http://HOST:PORT/metrics");
// "" when it does not answer.
std::string Scrape(const std::string& ready_line) {
  const int port = tools::MetricsPortOf(ready_line);
  return port == 0 ? "" : ::vistream::test::HttpGet(port, "/metrics").second;
}

// The value of `series` (name and labels as rendered) in a /metrics text; NaN when absent.
double Series(const std::string& text, const std::string& series) {
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind(series + " ", 0) == 0) return std::stod(line.substr(series.size() + 1));
  }
  return std::nan("");
}

v1::ServerStats Stats(const test::RunningServer& s) {
  absl::StatusOr<v1::ServerStats> stats = client::Probe(s.address(), test::kWait);
  EXPECT_TRUE(stats.ok()) << stats.status();
  return stats.ok() ? *stats : v1::ServerStats();
}

template <typename F>
bool Eventually(F ok, double seconds = 30.0) {
  const auto t0 = Clock::now();
  while (std::chrono::duration<double>(Clock::now() - t0).count() < seconds) {
    if (ok()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return ok();
}

std::unique_ptr<test::RunningServer> StartReplica(const std::string& store, const std::string& log) {
  std::string error;
  std::unique_ptr<test::RunningServer> s = test::RunningServer::Start(
      VISTREAM_SERVER_BIN,
      {"--scene", "city1", "--listen", "127.0.0.1:0", "--threads", "1", "--metrics-listen", "127.0.0.1:0", "--store",
       store, "--store-prefix", "replicas"},
      &error, log);
  EXPECT_NE(s, nullptr) << error;
  return s;
}

// A walker at the centre of cell (i, j) until its nine cells are complete.
bool WalkTo(SessionStream& c, int i, int j) {
  return c.SendPose(test::Centre(i, j)) &&
         c.WaitFor([&](const SessionRecord& r) { return r.AllComplete(test::Around(test::Cell(i, j))); }, test::kWait);
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

TEST(ServerStore, WhatOneReplicaComputesTheOtherReadsAndRedisGoingAwayStopsNoWalker) {
  std::string error;
  std::unique_ptr<::vistream::test::RedisServer> redis = ::vistream::test::RedisServer::Start(&error);
  ASSERT_NE(redis, nullptr) << error;
  const std::string log_a = testing::ProcessTempDir() + "/store_replica_a.log";
  std::unique_ptr<test::RunningServer> a = StartReplica(redis->address(), log_a);
  std::unique_ptr<test::RunningServer> b =
      StartReplica(redis->address(), testing::ProcessTempDir() + "/store_replica_b.log");
  ASSERT_NE(a, nullptr);
  ASSERT_NE(b, nullptr);
  EXPECT_NE(a->ready_line().find("with the PVS store at " + redis->address()), std::string::npos) << a->ready_line();

  // A walker on A: nine cells computed there and written to the store.
  SessionStream on_a(a->address());
  on_a.Start(SessionStream::HelloFor("city1"));
  on_a.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(WalkTo(on_a, 6, 6));
  ASSERT_TRUE(Eventually([&] { return Stats(*a).store().writes() >= 9; })) << Stats(*a).DebugString();
  EXPECT_EQ(Stats(*a).pvs_computed(), 9u);
  EXPECT_EQ(Stats(*a).pvs_store_hits(), 0u);

  // A walker on B at the same place: its nine cells are store hits, none computed.
  SessionStream on_b(b->address());
  on_b.Start(SessionStream::HelloFor("city1"));
  on_b.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(WalkTo(on_b, 6, 6));
  v1::ServerStats sb = Stats(*b);
  EXPECT_EQ(sb.pvs_computed(), 0u);
  EXPECT_EQ(sb.pvs_store_hits(), 9u);
  ASSERT_EQ(sb.scenes_size(), 1);
  EXPECT_EQ(sb.scenes(0).pvs_store_hits(), 9u);
  EXPECT_TRUE(sb.store().up());
  EXPECT_EQ(sb.store().address(), redis->address());
  EXPECT_EQ(sb.store().hits(), 9u);
  // B's log says where each PVS came from.
  const std::string log_b_path = testing::ProcessTempDir() + "/store_replica_b.log";
  EXPECT_NE(ReadFile(log_b_path).find("source=store"), std::string::npos) << ReadFile(log_b_path);
  EXPECT_EQ(ReadFile(log_b_path).find("source=computed"), std::string::npos) << ReadFile(log_b_path);
  const std::string metrics_b = Scrape(b->ready_line());
  EXPECT_EQ(Series(metrics_b, "vistream_pvs_store_hits_total{scene=\"city1\"}"), 9.0) << metrics_b;
  EXPECT_EQ(Series(metrics_b, "vistream_pvs_computations_total{scene=\"city1\"}"), 0.0) << metrics_b;
  EXPECT_EQ(Series(metrics_b, "vistream_pvs_store_up"), 1.0) << metrics_b;

  // Redis goes away mid-walk: A's walker goes on (its new cells computed), and the metric and
  // the log say the store is down.
  redis->Stop();
  ASSERT_TRUE(WalkTo(on_a, 12, 6));
  v1::ServerStats sa = Stats(*a);
  EXPECT_FALSE(sa.store().up());
  EXPECT_EQ(sa.store().outages(), 1u);
  EXPECT_EQ(sa.pvs_computed(), 18u);
  const std::string metrics_a = Scrape(a->ready_line());
  EXPECT_EQ(Series(metrics_a, "vistream_pvs_store_up"), 0.0) << metrics_a;
  EXPECT_EQ(Series(metrics_a, "vistream_pvs_store_outages_total"), 1.0) << metrics_a;
  EXPECT_NE(ReadFile(log_a).find("store unavailable"), std::string::npos) << ReadFile(log_a);

  // Redis back (empty: no persistence): A's next computations are written again, and B reads
  // them.
  ASSERT_TRUE(redis->Restart(&error)) << error;
  std::this_thread::sleep_for(std::chrono::seconds(1));  // past the first back-off steps
  const uint64_t writes_before = sa.store().writes();
  ASSERT_TRUE(WalkTo(on_a, 18, 12));
  ASSERT_TRUE(Eventually([&] { return Stats(*a).store().writes() >= writes_before + 9; })) << Stats(*a).DebugString();
  EXPECT_TRUE(Stats(*a).store().up());
  EXPECT_NE(ReadFile(log_a).find("store reconnected"), std::string::npos) << ReadFile(log_a);
  ASSERT_TRUE(WalkTo(on_b, 18, 12));
  EXPECT_EQ(Stats(*b).pvs_store_hits(), 18u);
  EXPECT_EQ(Stats(*b).pvs_computed(), 0u);

  EXPECT_TRUE(on_a.Finish().ok());
  EXPECT_TRUE(on_b.Finish().ok());
  EXPECT_EQ(a->Stop(SIGTERM), 0);
  EXPECT_EQ(b->Stop(SIGTERM), 0);
}

// A Redis that refuses the server (a password it lacks) is a configuration error at start, and
// store options without a store are named: both exit 2.
TEST(ServerStore, ARedisThatRefusesTheServerAndStoreOptionsWithoutAStoreExitTwo) {
  std::string error;
  std::unique_ptr<::vistream::test::RedisServer> redis =
      ::vistream::test::RedisServer::Start(&error, {"--requirepass", "s3cret"});
  ASSERT_NE(redis, nullptr) << error;
  auto [code, out] = test::RunServer("--scene city1 --listen 127.0.0.1:0 --store " + redis->address());
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("the PVS store at " + redis->address() + " refused this server"), std::string::npos) << out;
  EXPECT_NE(out.find("(no password given)"), std::string::npos) << out;
  std::tie(code, out) = test::RunServer("--scene city1 --store-prefix p");
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("--store-prefix: needs a PVS store"), std::string::npos) << out;
  std::tie(code, out) = test::RunServer("--scene city1 --store 127.0.0.1:1 --store-prefix ''");
  EXPECT_EQ(code, 2) << out;
  EXPECT_NE(out.find("--store-prefix"), std::string::npos) << out;
}

}  // namespace
}  // namespace vistream::server
