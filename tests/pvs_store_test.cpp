// The shared PVS store (server/pvs_store.h) against a real redis-server on loopback: the cell
// record's checks, keys that keep scenes and settings apart, write-back and reads across
// replicas, a corrupt entry refused and recomputed, and Redis stopped, frozen and restarted.

#include "server/pvs_store.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "server/served_scene.h"
#include "tests/redis_test_util.h"
#include "tests/tls_test_util.h"
#include "tests/server_test_util.h"
#include "visibility/pvs_file.h"

namespace vistream::server {
namespace {

using Clock = std::chrono::steady_clock;
using RedisServer = ::vistream::test::RedisServer;

double SecondsSince(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// Events the store reported, for the assertions on its log lines.
class Events {
 public:
  PvsStore::EventSink Sink() {
    return [this](EventLog::Level, std::string_view event, const std::string& detail) {
      std::lock_guard lock(mu_);
      lines_.push_back(std::string(event) + ": " + detail);
    };
  }
  int Count(const std::string& event) const {
    std::lock_guard lock(mu_);
    int n = 0;
    for (const std::string& l : lines_) n += l.rfind(event + ":", 0) == 0 ? 1 : 0;
    return n;
  }
  std::string All() const {
    std::lock_guard lock(mu_);
    std::string s;
    for (const std::string& l : lines_) s += l + "\n";
    return s;
  }

 private:
  mutable std::mutex mu_;
  std::vector<std::string> lines_;
};

std::unique_ptr<PvsStore> MakeStore(const std::string& address, Events* events = nullptr) {
  PvsStoreOptions o;
  o.address = address;
  o.key_prefix = "test";
  o.max_backoff_s = 0.4;
  absl::StatusOr<std::unique_ptr<PvsStore>> s = PvsStore::Create(o, events != nullptr ? events->Sink() : nullptr);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

std::unique_ptr<RedisServer> StartRedis() {
  std::string error;
  std::unique_ptr<RedisServer> r = RedisServer::Start(&error);
  EXPECT_NE(r, nullptr) << error;
  return r;
}

// Waits up to `seconds` for `ok()`.
template <typename F>
bool Eventually(F ok, double seconds = 10.0) {
  const auto t0 = Clock::now();
  while (SecondsSince(t0) < seconds) {
    if (ok()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return ok();
}

TEST(CellRecord, RoundTripsAndRefusesEveryKindOfDamage) {
  const std::vector<uint32_t> ids = {0, 3, 4, 200, 69999};
  const std::string rec = visibility::EncodeCellRecord(17, ids);
  absl::StatusOr<std::vector<uint32_t>> back = visibility::DecodeCellRecord(rec, 17, 70000, "k");
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, ids);
  // An empty PVS is a PVS.
  EXPECT_TRUE(visibility::DecodeCellRecord(visibility::EncodeCellRecord(3, {}), 3, 10, "k").ok());

  auto refused = [](const std::string& bytes, uint32_t cell, uint64_t objects, const std::string& says) {
    absl::StatusOr<std::vector<uint32_t>> r = visibility::DecodeCellRecord(bytes, cell, objects, "store key");
    ASSERT_FALSE(r.ok()) << says;
    EXPECT_EQ(r.status().code(), absl::StatusCode::kDataLoss);
    EXPECT_NE(r.status().message().find("store key"), std::string::npos) << r.status();
    EXPECT_NE(r.status().message().find(says), std::string::npos) << r.status();
  };
  std::string flipped = rec;
  flipped[10] ^= 0x04;
  refused(flipped, 17, 70000, "checksum");
  refused(rec.substr(0, rec.size() - 1), 17, 70000, "checksum");
  refused(rec.substr(0, 5), 17, 70000, "bytes");
  refused("XXXX" + rec.substr(4), 17, 70000, "magic");
  refused(rec, 18, 70000, "cell 17");
  refused(rec, 17, 1000, "past the scene");  // ids of a bigger scene
}

TEST(PvsStore, KeysKeepScenesGridsResolutionsAndBackendsApart) {
  server::ServedScene& city1 = test::City1();
  const uint64_t fp = scenes::SceneFingerprint(city1.scene());
  const visibility::ViewcellGrid& grid = city1.grid();
  const std::string base = PvsStoreNamespace("p", fp, grid, 128, "cpu");
  EXPECT_EQ(base, PvsStoreNamespace("p", fp, grid, 128, "cpu"));
  EXPECT_NE(base, PvsStoreNamespace("q", fp, grid, 128, "cpu"));
  EXPECT_NE(base, PvsStoreNamespace("p", fp ^ 1, grid, 128, "cpu"));
  EXPECT_NE(base, PvsStoreNamespace("p", fp, grid, 64, "cpu"));
  EXPECT_NE(base, PvsStoreNamespace("p", fp, grid, 128, "exact"));
  absl::StatusOr<visibility::ViewcellGrid> other = visibility::ViewcellGrid::Create(
      city1.scene().bounds, grid.cell_size() * 0.5, grid.base_z(), grid.height());
  ASSERT_TRUE(other.ok());
  EXPECT_NE(base, PvsStoreNamespace("p", fp, *other, 128, "cpu"));
  EXPECT_EQ(PvsStore::Key(base, 42), base + ":42");
}

TEST(PvsStore, BadOptionsAreRefusedNamingWhat) {
  PvsStoreOptions o;
  o.address = "localhost";
  absl::StatusOr<std::unique_ptr<PvsStore>> s = PvsStore::Create(o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("'localhost'"), std::string::npos) << s.status();
  o.address = "127.0.0.1:6379";
  o.read_timeout_s = 0.0;
  s = PvsStore::Create(o);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("read timeout"), std::string::npos) << s.status();
}

TEST(PvsStore, WhatOneReplicaWritesAnotherReadsAndTheFirstAnswerStays) {
  std::unique_ptr<RedisServer> redis = StartRedis();
  ASSERT_NE(redis, nullptr);
  std::unique_ptr<PvsStore> a = MakeStore(redis->address()), b = MakeStore(redis->address());
  const std::string ns = "test:pvs1:ns";
  std::vector<uint32_t> got;
  EXPECT_EQ(b->Get(ns, 5, 100, &got), PvsStore::Read::kMiss);
  a->PutLater(ns, 5, std::vector<uint32_t>{1, 2, 50});
  a->Flush();
  ASSERT_EQ(b->Get(ns, 5, 100, &got), PvsStore::Read::kHit);
  EXPECT_EQ(got, (std::vector<uint32_t>{1, 2, 50}));
  // A second answer for the cell (another replica computed it at the same time) is not kept.
  b->PutLater(ns, 5, std::vector<uint32_t>{7});
  b->Flush();
  ASSERT_EQ(a->Get(ns, 5, 100, &got), PvsStore::Read::kHit);
  EXPECT_EQ(got, (std::vector<uint32_t>{1, 2, 50}));
  EXPECT_EQ(b->stats().hits, 1u);
  EXPECT_EQ(b->stats().misses, 1u);
  EXPECT_EQ(a->stats().writes, 1u);
  EXPECT_TRUE(a->stats().up);
  // The tools' calls: pipelined writes and existence.
  const std::vector<std::pair<visibility::CellId, std::string>> recs = {
      {8, visibility::EncodeCellRecord(8, std::vector<uint32_t>{3})}, {9, visibility::EncodeCellRecord(9, {})}};
  ASSERT_TRUE(a->Put(ns, recs).ok());
  absl::StatusOr<std::vector<bool>> exists = b->Exists(ns, std::vector<visibility::CellId>{5, 6, 8, 9});
  ASSERT_TRUE(exists.ok()) << exists.status();
  EXPECT_EQ(*exists, (std::vector<bool>{true, false, true, true}));
}

TEST(PvsStore, ACorruptEntryUnderARealKeyIsRefusedLoggedAndOverwrittenByTheRecomputedOne) {
  std::unique_ptr<RedisServer> redis = StartRedis();
  ASSERT_NE(redis, nullptr);
  // A replica serving city1 with the store, its cache too small to keep a second cell: every
  // request of an evicted cell goes to the store.
  Events events;
  std::unique_ptr<PvsStore> store = MakeStore(redis->address(), &events);
  ServedSceneOptions o;
  o.scene = "city1";
  o.threads = 1;
  o.cache_bytes = 1;
  o.store = store.get();
  absl::StatusOr<std::unique_ptr<ServedScene>> scene = ServedScene::Create(o);
  ASSERT_TRUE(scene.ok()) << scene.status();
  const CellId cell = test::Cell(10, 10);
  const std::string key = PvsStore::Key((*scene)->store_namespace(), cell);
  // Plant a wrong PVS under the cell's real key: a record for another cell (checksum right).
  std::string planted = visibility::EncodeCellRecord(cell + 1, std::vector<uint32_t>{0});
  ASSERT_EQ(redis->Cli("SET " + key + " garbage-not-a-record"), "OK");

  const CellPvs first = (*scene)->StoredOrComputedPvs(cell, 0);
  EXPECT_FALSE(first.from_store);  // refused, recomputed
  EXPECT_EQ(first.objects, test::ExpectedPvs(cell));
  EXPECT_EQ(store->stats().bad_entries, 1u);
  EXPECT_EQ(events.Count("store bad entry"), 1) << events.All();
  EXPECT_NE(events.All().find(key), std::string::npos) << events.All();
  store->Flush();
  // The recomputed PVS replaced the bad entry: the next read is a hit, and it is right.
  const CellPvs second = (*scene)->StoredOrComputedPvs(cell, 0);
  EXPECT_TRUE(second.from_store);
  EXPECT_EQ(second.objects, test::ExpectedPvs(cell));

  // Same again with an entry whose checksum is right but names another cell.
  ASSERT_EQ(redis->Cli("DEL " + key), "1");
  std::FILE* p = popen(("redis-cli -h 127.0.0.1 -p " + std::to_string(redis->port()) + " -x SET " + key + " >/dev/null").c_str(), "w");
  ASSERT_NE(p, nullptr);
  std::fwrite(planted.data(), 1, planted.size(), p);
  pclose(p);
  const CellPvs third = (*scene)->StoredOrComputedPvs(cell, 0);
  EXPECT_FALSE(third.from_store);
  EXPECT_EQ(third.objects, test::ExpectedPvs(cell));
  EXPECT_EQ(store->stats().bad_entries, 2u);
}

TEST(PvsStore, RedisStoppedTheCallsGoOnAtOnceThenTheStoreIsUsedAgainWhenItIsBack) {
  std::unique_ptr<RedisServer> redis = StartRedis();
  ASSERT_NE(redis, nullptr);
  Events events;
  std::unique_ptr<PvsStore> store = MakeStore(redis->address(), &events);
  const std::string ns = "test:pvs1:outage";
  std::vector<uint32_t> got;
  ASSERT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kMiss);
  EXPECT_EQ(events.Count("store connected"), 1) << events.All();

  redis->Stop();
  // Many calls while it is down: each answers at once (no crossing waits on Redis), the outage
  // is logged and counted once, and write-backs are dropped, not queued forever.
  const auto t0 = Clock::now();
  for (int k = 0; k < 200; ++k) {
    EXPECT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kUnavailable);
    store->PutLater(ns, 1, std::vector<uint32_t>{2});
  }
  store->Flush();
  EXPECT_LT(SecondsSince(t0), 2.0);
  EXPECT_FALSE(store->stats().up);
  EXPECT_EQ(store->stats().outages, 1u);
  EXPECT_EQ(events.Count("store unavailable"), 1) << events.All();
  EXPECT_GT(store->stats().writes_dropped, 0u);

  std::string error;
  ASSERT_TRUE(redis->Restart(&error)) << error;
  // Back-off (at most 0.4 s here): a later write lands and a later read hits.
  ASSERT_TRUE(Eventually([&] {
    store->PutLater(ns, 3, std::vector<uint32_t>{4, 5});
    store->Flush();
    return store->Get(ns, 3, 10, &got) == PvsStore::Read::kHit;
  })) << events.All();
  EXPECT_EQ(got, (std::vector<uint32_t>{4, 5}));
  EXPECT_TRUE(store->stats().up);
  EXPECT_EQ(events.Count("store reconnected"), 1) << events.All();
}

TEST(PvsStore, ARedisRestartBetweenReadsCostsNoRead) {
  std::unique_ptr<RedisServer> redis = StartRedis();
  ASSERT_NE(redis, nullptr);
  std::unique_ptr<PvsStore> store = MakeStore(redis->address());
  const std::string ns = "test:pvs1:restart";
  // Several connections in the pool: reads from four threads at once.
  {
    std::vector<std::jthread> readers;
    for (int t = 0; t < 4; ++t) {
      readers.emplace_back([&] {
        std::vector<uint32_t> got;
        for (int k = 0; k < 50; ++k) EXPECT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kMiss);
      });
    }
  }
  std::string error;
  ASSERT_TRUE(redis->Restart(&error)) << error;
  // Every pooled connection is closed now; the next read and write go on new ones at once.
  std::vector<uint32_t> got;
  EXPECT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kMiss);
  store->PutLater(ns, 2, std::vector<uint32_t>{3});
  store->Flush();
  EXPECT_EQ(store->Get(ns, 2, 10, &got), PvsStore::Read::kHit);
  EXPECT_EQ(store->stats().outages, 0u);
  EXPECT_EQ(store->stats().unavailable, 0u);
}

// A Redis that speaks only TLS and wants a password, reached as docs/scaling-out.md says: through a local
// stunnel (Debian stunnel4) that verifies its certificate, with the password from the options.
TEST(PvsStore, ATlsRedisWithAPasswordIsReachedThroughStunnel) {
  const testing::TestCerts& certs = testing::Certs();
  const int tls_port = ::vistream::test::FreeLoopbackPort();
  std::string error;
  std::unique_ptr<RedisServer> redis =
      RedisServer::Start(&error, {"--tls-port", std::to_string(tls_port), "--tls-cert-file", certs.server_crt,
                                  "--tls-key-file", certs.server_key, "--tls-ca-cert-file", certs.ca_crt,
                                  "--tls-auth-clients", "no", "--requirepass", "s3cret"});
  ASSERT_NE(redis, nullptr) << error;
  const int local_port = ::vistream::test::FreeLoopbackPort();
  const std::string conf = certs.dir + "/stunnel-redis.conf";
  ASSERT_TRUE(testing::WriteText(conf, "foreground = yes\npid =\n[redis]\nclient = yes\naccept = 127.0.0.1:" +
                                           std::to_string(local_port) + "\nconnect = 127.0.0.1:" +
                                           std::to_string(tls_port) + "\nCAfile = " + certs.ca_crt +
                                           "\nverifyChain = yes\ncheckHost = localhost\n"));
  const pid_t stunnel = fork();
  ASSERT_GE(stunnel, 0);
  if (stunnel == 0) {
    const int devnull = ::open("/dev/null", O_WRONLY);
    if (devnull >= 0) dup2(devnull, STDERR_FILENO);
    execlp("stunnel4", "stunnel4", conf.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  struct Reap {
    pid_t pid;
    ~Reap() {
      kill(pid, SIGTERM);
      waitpid(pid, nullptr, 0);
    }
  } reap{stunnel};
  PvsStoreOptions o;
  o.address = "127.0.0.1:" + std::to_string(local_port);
  o.key_prefix = "test";
  o.password = "s3cret";
  o.connect_timeout_s = 2.0;
  o.read_timeout_s = 2.0;
  absl::StatusOr<std::unique_ptr<PvsStore>> store = PvsStore::Create(o);
  ASSERT_TRUE(store.ok()) << store.status();
  // stunnel may take a moment to listen.
  ASSERT_TRUE(Eventually([&] {
    absl::StatusOr<std::unique_ptr<PvsStore>> probe = PvsStore::Create(o);
    return probe.ok() && (*probe)->Connect().ok();
  })) << (waitpid(stunnel, nullptr, WNOHANG) == stunnel ? "stunnel4 exited (Debian stunnel4; ./vistream.sh installs it)"
                                                         : "no PING through stunnel");
  ASSERT_TRUE((*store)->Connect().ok());
  const std::string ns = "test:pvs1:tls";
  (*store)->PutLater(ns, 4, std::vector<uint32_t>{1, 9});
  (*store)->Flush();
  std::vector<uint32_t> got;
  ASSERT_EQ((*store)->Get(ns, 4, 10, &got), PvsStore::Read::kHit);
  EXPECT_EQ(got, (std::vector<uint32_t>{1, 9}));
  // The wrong password is refused, naming AUTH (and not the password).
  o.password = "wrong";
  absl::StatusOr<std::unique_ptr<PvsStore>> wrong = PvsStore::Create(o);
  ASSERT_TRUE(wrong.ok());
  const absl::Status refused = (*wrong)->Connect();
  EXPECT_EQ(refused.code(), absl::StatusCode::kPermissionDenied);
  EXPECT_NE(refused.message().find("AUTH refused"), std::string::npos) << refused;
  EXPECT_EQ(refused.message().find("wrong"), std::string::npos) << refused;
  // No password at all: Redis says NOAUTH, also a refusal rather than an outage.
  o.password.clear();
  absl::StatusOr<std::unique_ptr<PvsStore>> none = PvsStore::Create(o);
  ASSERT_TRUE(none.ok());
  const absl::Status noauth = (*none)->Connect();
  EXPECT_EQ(noauth.code(), absl::StatusCode::kPermissionDenied) << noauth;
  EXPECT_NE(noauth.message().find("no password given"), std::string::npos) << noauth;
  // Plaintext straight to the TLS port gets nothing.
  o.address = "127.0.0.1:" + std::to_string(tls_port);
  o.password = "s3cret";
  o.read_timeout_s = 0.5;
  absl::StatusOr<std::unique_ptr<PvsStore>> plain = PvsStore::Create(o);
  ASSERT_TRUE(plain.ok());
  EXPECT_FALSE((*plain)->Connect().ok());
}

TEST(PvsStore, AFrozenRedisNeverHoldsAReadPastItsDeadline) {
  std::unique_ptr<RedisServer> redis = StartRedis();
  ASSERT_NE(redis, nullptr);
  std::unique_ptr<PvsStore> store = MakeStore(redis->address());  // read deadline 50 ms
  const std::string ns = "test:pvs1:slow";
  std::vector<uint32_t> got;
  ASSERT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kMiss);
  redis->Pause();
  const auto t0 = Clock::now();
  EXPECT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kUnavailable);
  const double first = SecondsSince(t0);
  // Then, in back-off, the store is not asked at all.
  for (int k = 0; k < 100; ++k) EXPECT_EQ(store->Get(ns, 1, 10, &got), PvsStore::Read::kUnavailable);
  const double all = SecondsSince(t0);
  redis->Resume();
  EXPECT_LT(first, 0.5);  // the 50 ms deadline, with room for a loaded machine
  EXPECT_LT(all, 1.0);
  EXPECT_TRUE(Eventually([&] { return store->Get(ns, 1, 10, &got) == PvsStore::Read::kMiss; }));
}

TEST(PvsStore, AReplicaWithTheStoreReadsWhatAnotherComputedAndCountsIt) {
  std::unique_ptr<RedisServer> redis = StartRedis();
  ASSERT_NE(redis, nullptr);
  std::unique_ptr<PvsStore> store_a = MakeStore(redis->address()), store_b = MakeStore(redis->address());
  ServedSceneOptions o;
  o.scene = "city1";
  o.threads = 1;
  o.store = store_a.get();
  absl::StatusOr<std::unique_ptr<ServedScene>> a = ServedScene::Create(o);
  ASSERT_TRUE(a.ok()) << a.status();
  o.store = store_b.get();
  absl::StatusOr<std::unique_ptr<ServedScene>> b = ServedScene::Create(o);
  ASSERT_TRUE(b.ok()) << b.status();
  EXPECT_EQ((*a)->store_namespace(), (*b)->store_namespace());

  // Through each replica's scheduler, as sessions ask: A computes, B reads.
  const std::set<CellId> cells = test::Around(test::Cell(12, 8));
  auto request_all = [&](ServedScene& s) {
    std::mutex mu;
    std::condition_variable cv;
    size_t done = 0;
    for (CellId c : cells) {
      if (s.scheduler().Request(1, c, 0.0, [&](const CellPvsPtr&) {
            std::lock_guard lock(mu);
            ++done;
            cv.notify_all();
          }) != nullptr) {
        std::lock_guard lock(mu);
        ++done;
      }
    }
    std::unique_lock lock(mu);
    return cv.wait_for(lock, std::chrono::seconds(120), [&] { return done == cells.size(); });
  };
  ASSERT_TRUE(request_all(**a));
  store_a->Flush();
  ASSERT_TRUE(request_all(**b));
  const SchedulerStats sa = (*a)->scheduler().stats(), sb = (*b)->scheduler().stats();
  EXPECT_EQ(sa.computed, cells.size());
  EXPECT_EQ(sa.store_hits, 0u);
  EXPECT_EQ(sb.computed, 0u);
  EXPECT_EQ(sb.store_hits, cells.size());
  for (CellId c : cells) {
    const CellPvsPtr p = (*b)->scheduler().Cached(c);
    ASSERT_NE(p, nullptr);
    EXPECT_TRUE(p->from_store);
    EXPECT_EQ(p->objects, test::ExpectedPvs(c)) << "cell " << c;
  }
}

}  // namespace
}  // namespace vistream::server
