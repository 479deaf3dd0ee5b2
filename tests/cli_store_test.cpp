// `vistream pvs --all --store ADDRESS [--shard K/N]` against a real redis-server: shards fill
// the store with exactly the sets of one whole run, a rerun resumes, bad options are named.

#include <fstream>
#include <iterator>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "server/pvs_store.h"
#include "tests/cli_test_util.h"
#include "tests/redis_test_util.h"
#include "visibility/pvs_file.h"

namespace vistream::testing {
namespace {

TEST(Cli, PvsAllShardsFillTheStoreWithExactlyTheSingleRunsSets) {
  std::string error;
  std::unique_ptr<vistream::test::RedisServer> redis = vistream::test::RedisServer::Start(&error);
  ASSERT_NE(redis, nullptr) << error;
  // The reference: one whole run, as a PVS file.
  const std::string file = Tmp("city1_store_reference.pvs");
  ASSERT_EQ(Vistream("pvs --scene city1 --all -o " + file).exit_code, 0);
  std::ifstream in(file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const absl::StatusOr<visibility::PvsFile> f = visibility::DecodePvsFile(bytes, file);
  ASSERT_TRUE(f.ok()) << f.status();

  // Two independent shards fill the store.
  std::string ns;
  size_t stored = 0;
  for (const char* shard : {"0/2", "1/2"}) {
    const RunResult r = Vistream("pvs --scene city1 --all --store " + redis->address() + " --store-prefix t --shard " +
                                 shard + " --json");
    ASSERT_EQ(r.exit_code, 0) << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j.at("shard"), shard);
    EXPECT_EQ(j.at("shard_cells"), 280);
    EXPECT_EQ(j.at("cells_computed"), 280);
    EXPECT_EQ(j.at("cells_already_stored"), 0);
    if (!ns.empty()) {
      EXPECT_EQ(j.at("store_namespace"), ns);
    }
    ns = j.at("store_namespace").get<std::string>();
    stored += j.at("cells_computed").get<size_t>();
  }
  EXPECT_EQ(stored, f->sets.cell_count());
  // Exactly the grid's cells are stored, and each holds the whole run's set.
  EXPECT_EQ(redis->Cli("--scan --pattern '" + ns + ":*' | wc -l"), std::to_string(f->sets.cell_count()));
  server::PvsStoreOptions o;
  o.address = redis->address();
  o.key_prefix = "t";
  o.read_timeout_s = 5.0;
  absl::StatusOr<std::unique_ptr<server::PvsStore>> store = server::PvsStore::Create(o);
  ASSERT_TRUE(store.ok()) << store.status();
  for (visibility::CellId c = 0; c < f->sets.cell_count(); ++c) {
    std::vector<uint32_t> got;
    ASSERT_EQ((*store)->Get(ns, c, f->sets.object_count(), &got), server::PvsStore::Read::kHit) << "cell " << c;
    ASSERT_EQ(got, f->sets.Objects(c)) << "cell " << c;
  }
  // A rerun (a shard's job restarted) finds its cells stored and computes nothing.
  const RunResult again =
      Vistream("pvs --scene city1 --all --store " + redis->address() + " --store-prefix t --shard 1/2 --json");
  ASSERT_EQ(again.exit_code, 0) << again.out;
  EXPECT_EQ(nlohmann::json::parse(again.out).at("cells_computed"), 0);
  EXPECT_EQ(nlohmann::json::parse(again.out).at("cells_already_stored"), 280);
  // A corrupt entry under a real key is not taken for a stored cell: the rerun redoes it.
  ASSERT_EQ(redis->Cli("SET " + ns + ":1 garbage"), "OK");
  const RunResult repair =
      Vistream("pvs --scene city1 --all --store " + redis->address() + " --store-prefix t --shard 1/2 --json");
  ASSERT_EQ(repair.exit_code, 0) << repair.out;
  EXPECT_NE(repair.out.find("1 stored entries failed their checks"), std::string::npos) << repair.out;
  const nlohmann::json fixed = nlohmann::json::parse(repair.out.substr(repair.out.find('{')));
  EXPECT_EQ(fixed.at("cells_computed"), 1);
  std::vector<uint32_t> got;
  ASSERT_EQ((*store)->Get(ns, 1, f->sets.object_count(), &got), server::PvsStore::Read::kHit);
  EXPECT_EQ(got, f->sets.Objects(1));
}

TEST(Cli, PvsAllStoreOptionsAreChecked) {
  ExpectBadOption("pvs --scene city1 --all", "--all: writes a PVS file or fills a PVS store: give -o FILE or --store");
  ExpectBadOption("pvs --scene city1 --all -o " + Tmp("x.pvs") + " --shard 0/2", "--shard: fills part of a PVS store");
  ExpectBadOption("pvs --scene city1 --all --store 127.0.0.1:1 --shard 2/2", "--shard: '2/2' is not K/N with 0 <= K < N");
  ExpectBadOption("pvs --scene city1 --all --store 127.0.0.1:1 --shard x", "--shard: 'x' is not K/N");
  ExpectBadOption("pvs --scene city1 --all --store 127.0.0.1:1 -o " + Tmp("x.pvs") + " --shard 0/2",
                  "--shard: a PVS file holds every viewcell");
  ExpectBadOption("pvs --scene city1 --all --store nowhere", "--store: store address 'nowhere'");
  ExpectBadOption("pvs --scene city1 --all --store 127.0.0.1:1 --store-prefix 'a b'",
                  "--store-prefix: 'a b' is not a non-empty word");
  ExpectBadOption("pvs --scene city1 --all -o " + Tmp("x.pvs") + " --store-prefix p",
                  "--store-prefix: names keys in a PVS store: give --store");
  ExpectBadOption("pvs --scene city1 --cell 1,1 --store 127.0.0.1:1", "--store: fills a PVS store with every viewcell");
  ExpectBadOption("pvs --scene city1 --all --store 127.0.0.1:1 --store-password-file " + Tmp(""),
                  "--store-password-file: " + Tmp("") + ": is a folder, not a file");
  // Nobody listens there: said before any work, naming the address.
  const int port = vistream::test::FreeLoopbackPort();
  ExpectRunTimeError("pvs --scene city1 --all --store 127.0.0.1:" + std::to_string(port),
                     "the PVS store at 127.0.0.1:" + std::to_string(port) + " is unavailable");
}

// Two replicas behind a real HAProxy sharing a PVS store of the run's own, warmed first by the
// same walks: the measured replicas compute nothing, and the JSON keeps today's keys.
TEST(Cli, BenchServerWithReplicasBehindHaproxyAndAWarmStoreComputesNothing) {
  const RunResult r = Vistream(
      "bench server --scene city1 --sessions 4 --seconds 6 --replicas 2 --balancer haproxy --store redis --warm --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"late_cells", "crossing_p50_ms", "crossing_p99_ms", "startup_p50_s", "bytes_sent",
                          "sessions_started", "cache_hit_rate"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j.at("replicas"), 2);
  EXPECT_EQ(j.at("balancer"), "haproxy");
  EXPECT_EQ(j.at("store"), "redis");
  EXPECT_EQ(j.at("store_warm"), true);
  EXPECT_EQ(j.at("sessions_started"), 4);
  EXPECT_EQ(j.at("pvs_computations"), 0);
  EXPECT_EQ(j.at("pvs_computations_per_replica"), nlohmann::json::array({0, 0}));
  EXPECT_GE(j.at("store_hits").get<int>(), 4 * 9);
  EXPECT_EQ(j.at("store_hit_rate"), 1.0);
  ASSERT_EQ(j.at("per_replica").size(), 2u);
  // leastconn spreads the four walkers over both replicas.
  EXPECT_EQ(j.at("per_replica")[0].at("sessions_total"), 2);
  EXPECT_EQ(j.at("per_replica")[1].at("sessions_total"), 2);
  EXPECT_EQ(j.at("late_cells"), 0);
}

TEST(Cli, BenchServerReplicaOptionsAreChecked) {
  ExpectBadOption("bench server --replicas 2", "--replicas: several replicas need a balancer in front");
  ExpectBadOption("bench server --store nowhere", "--store: 'nowhere' is not none, redis or HOST:PORT");
  ExpectBadOption("bench server --warm", "--warm: warms the PVS store: give --store");
  ExpectBadOption("bench server --balancer nginx", "--balancer");
  // A store nobody answers at: said before anything is measured.
  const int port = vistream::test::FreeLoopbackPort();
  ExpectRunTimeError("bench server --scene city1 --store 127.0.0.1:" + std::to_string(port),
                     "the PVS store at 127.0.0.1:" + std::to_string(port) + " is unavailable");
}

}  // namespace
}  // namespace vistream::testing
