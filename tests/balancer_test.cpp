// Replicas behind a real HAProxy (deploy/haproxy.cfg, tests/balancer_util.h), on loopback: a
// walker whose replica is killed, drained or restarted goes on through the balancer on another,
// resuming with what it holds: no stall, nothing sent twice, pixel error 0 on checked frames.
// The walker is the thin client's headless walk (client/walkthrough.h), as in ClientWalk.*.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cctype>
#include <chrono>
#include <fstream>
#include <future>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <glm/vec3.hpp>
#include <gtest/gtest.h>

#include "client/connection.h"
#include "client/session_stream.h"
#include "client/walkthrough.h"
#include "tests/balancer_util.h"
#include "tests/redis_test_util.h"
#include "tests/temp_dir.h"

namespace vistream::server {
namespace {

using client::SessionStream;
using client::WalkthroughOptions;
using client::WalkthroughSummary;
using Clock = std::chrono::steady_clock;

constexpr double kWait = 60.0;  // seconds any one wait may take on a loaded 2-core machine

double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Two replicas of the default scene (one PVS worker each: two replicas, HAProxy and a
// rendering client share two cores) behind HAProxy; `drain` is each replica's --drain; with
// `store`, both share the PVS store at that Redis address.
std::unique_ptr<test::Balancer> StartBalanced(const std::string& test_name, const std::string& drain,
                                              std::string* error, const std::string& store = "", bool web = false) {
  test::BalancerOptions o;
  o.web = web;
  o.replicas = 2;
  o.replica_args = {"--scene", "default", "--threads", "1", "--drain", drain};
  if (!store.empty()) o.replica_args.insert(o.replica_args.end(), {"--store", store});
  o.server_bin = VISTREAM_SERVER_BIN;
  o.config_template = std::string(VISTREAM_SOURCE_DIR "/deploy/haproxy.cfg");
  o.haproxy = VISTREAM_HAPROXY;
  o.dir = testing::ProcessTempDir() + "/" + test_name;
  return test::Balancer::Start(o, error);
}

// The headless walk of ClientWalk.AServerRestartMidPath..., at 72 km/h (a crossing of the
// default scene's 100 m viewcells every 5 s, so that the replica a walker moves to must serve
// cells it did not hold), a frame checked every second of the walk, through `address` (the
// balancer).
WalkthroughOptions Walk(const std::string& address, double seconds) {
  WalkthroughOptions o;
  o.server = address;
  o.headless = true;
  o.width = 320;
  o.height = 180;
  o.max_fps = 30.0;
  o.speed_kmh = 72.0;
  o.seconds = seconds;
  o.verify = true;
  o.every_s = 1.0;
  o.log = [](const std::string& line) { std::printf("client: %s\n", line.c_str()); };
  return o;
}

// Sessions replica k has open, as its own GetStats says (asked directly, not through HAProxy);
// -1 when it does not answer.
int SessionsOn(test::Balancer& b, size_t k) {
  absl::StatusOr<v1::ServerStats> s = client::Probe(b.replica_address(k), 5.0);
  return s.ok() ? static_cast<int>(s->sessions_active()) : -1;
}

// The replica that holds the walker's one session, once it has one: its index, or -1 after
// `timeout_s`.
int WaitForHolder(test::Balancer& b, double timeout_s) {
  const Clock::time_point start = Clock::now();
  while (Since(start) < timeout_s) {
    std::vector<int> open;
    for (size_t k = 0; k < b.size(); ++k) open.push_back(SessionsOn(b, k));
    if (open[0] + open[1] == 1 && (open[0] == 1 || open[1] == 1)) return open[0] == 1 ? 0 : 1;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  return -1;
}

// Opens a session of the default scene through `s`'s address with a pose on its central square,
// and waits until `cells` viewcell PVSs have arrived.
bool OpenOnTheSquare(SessionStream& s, size_t cells) {
  s.set_keep_geometry(false);
  s.Start(SessionStream::HelloFor("default"));
  s.SendCredit(uint64_t{1} << 40);
  s.SendPose(glm::dvec3(509.4, 215.9, 1.7));
  return s.WaitFor([cells](const client::SessionRecord& r) { return r.pvs.size() >= cells; }, kWait);
}

void ExpectSeamless(const WalkthroughSummary& s) {
  std::printf("%s", client::SummaryText(s).c_str());
  EXPECT_GE(s.reconnects, 1u) << "the walker never left its replica";
  EXPECT_EQ(s.duplicates, 0u) << "objects held before the move were sent again";
  EXPECT_EQ(s.stalls, 0u);
  EXPECT_EQ(s.pixel_error, 0u);
  EXPECT_GE(s.checked_frames, 12u);
  EXPECT_GT(s.distance_m, 0.9 * s.walk_s * 20.0);
  EXPECT_GE(s.cells_visited, 3u);
}

// Replica k served a walker that moved to it: `sessions` sessions in all (the walker's and
// any other the test opened there), and geometry.
void ExpectServedTheWalker(test::Balancer& b, size_t k, uint64_t sessions = 1) {
  absl::StatusOr<v1::ServerStats> stats = client::Probe(b.replica_address(k), kWait);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->sessions_total(), sessions) << b.HaproxyLog();
  ASSERT_EQ(stats->scenes_size(), 1);
  EXPECT_GT(stats->scenes(0).geometry_bytes_sent(), 0u) << b.name(k) << " sent the walker no geometry";
}

// "2s", "500ms", "1m" (HAProxy's time units) in seconds; -1 if it is none.
double HaproxySeconds(const std::string& t) {
  size_t digits = 0;
  while (digits < t.size() && std::isdigit(static_cast<unsigned char>(t[digits]))) ++digits;
  if (digits == 0) return -1.0;
  const double n = std::stod(t.substr(0, digits));
  const std::string unit = t.substr(digits);
  if (unit == "ms" || unit.empty()) return n / 1000.0;
  if (unit == "s") return n;
  if (unit == "m") return 60.0 * n;
  if (unit == "h") return 3600.0 * n;
  return -1.0;
}

// The value after `key` on the first line of `text` that starts (after blanks) with `line`;
// empty if none.
std::string ValueOn(const std::string& text, const std::string& line, const std::string& key) {
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) {
    const size_t start = l.find_first_not_of(' ');
    if (start == std::string::npos || l.compare(start, line.size(), line) != 0) continue;
    std::istringstream words(l.substr(start));
    for (std::string w; words >> w;) {
      if (w == key && words >> w) return w;
    }
  }
  return "";
}

// deploy/haproxy.cfg as shipped: haproxy -c accepts it, it speaks HTTP/2 on both sides, checks
// /healthz over HTTP/1.1, never cuts a DOWN replica's streams or buffers a stream's body, and
// its checks take a draining replica out well within the default drain (deploy/server.toml).
TEST(Balancer, TheExampleConfigurationIsValidAndTakesADrainingReplicaOutWithinTheDefaultDrain) {
  const std::string path = std::string(VISTREAM_SOURCE_DIR "/deploy/haproxy.cfg");
  ASSERT_EQ(access(VISTREAM_HAPROXY, X_OK), 0) << "HAProxy is missing: " << VISTREAM_HAPROXY
                                                << " (Debian package haproxy; ./vistream.sh installs it)";
  std::FILE* p = popen((std::string(VISTREAM_HAPROXY " -c -f ") + path + " 2>&1").c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string out;
  char buf[512];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
  const int status = pclose(p);
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << out;
  const auto read = [](const std::string& file) {
    std::ifstream in(file);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  };
  const std::string cfg = read(path);
  // Directives only (comments dropped).
  std::string directives;
  std::istringstream lines(cfg);
  for (std::string l; std::getline(lines, l);) {
    const size_t hash = l.find('#');
    directives += l.substr(0, hash) + "\n";
  }
  EXPECT_NE(directives.find("bind :50051 proto h2"), std::string::npos);
  EXPECT_NE(directives.find("http-check send meth GET uri /healthz"), std::string::npos);
  EXPECT_EQ(directives.find("shutdown-sessions"), std::string::npos) << "a DOWN replica's walkers would be cut off";
  EXPECT_EQ(directives.find("http-buffer-request"), std::string::npos) << "a stream's body never ends";
  int servers = 0, web_servers = 0;
  std::istringstream server_lines(directives);
  std::string section;
  for (std::string l; std::getline(server_lines, l);) {
    if (l.starts_with("backend ") || l.starts_with("frontend ")) section = l;
    if (l.find("    server ") != 0) continue;
    if (section.starts_with("backend web_replicas")) {
      // The browser client's: HTTP/1.1 (a WebSocket upgrades it), checked on the metrics port.
      ++web_servers;
      EXPECT_EQ(l.find(" proto h2"), std::string::npos) << l;
      EXPECT_NE(l.find(" check port 9464"), std::string::npos) << l;
      continue;
    }
    ++servers;
    EXPECT_NE(l.find(" proto h2 "), std::string::npos) << l;
    EXPECT_NE(l.find(" check check-proto h1 port 9464"), std::string::npos) << l;
  }
  EXPECT_GE(servers, 2);
  EXPECT_GE(web_servers, 2);
  EXPECT_NE(directives.find("frontend vistream_web"), std::string::npos);
  // DOWN within inter + fastinter x (fall - 1) of the first 503, each check taking up to
  // `timeout check`; the default drain must be longer.
  const double inter = HaproxySeconds(ValueOn(directives, "default-server", "inter"));
  const double fastinter = HaproxySeconds(ValueOn(directives, "default-server", "fastinter"));
  const int fall = std::atoi(ValueOn(directives, "default-server", "fall").c_str());
  const double check = HaproxySeconds(ValueOn(directives, "timeout check", "check"));
  ASSERT_GT(inter, 0.0);
  ASSERT_GT(fastinter, 0.0);
  ASSERT_GE(fall, 1);
  ASSERT_GT(check, 0.0);
  const double down_s = inter + fastinter * (fall - 1);
  std::smatch drain;
  const std::string toml = read(std::string(VISTREAM_SOURCE_DIR "/deploy/server.toml"));
  ASSERT_TRUE(std::regex_search(toml, drain, std::regex(R"(\ndrain_s = ([0-9.]+)\n)")));
  EXPECT_GT(std::stod(drain[1]), down_s + check)
      << "HAProxy takes up to " << down_s << " s (+ " << check << " s for a slow check) to mark a replica DOWN";
}

TEST(Balancer, TheHelperStartsReplicasBehindHaproxyThatServeThroughIt) {
  std::string error;
  auto b = StartBalanced("balancer_basic", "5", &error);
  ASSERT_NE(b, nullptr) << error;
  for (size_t k = 0; k < b->size(); ++k) {
    EXPECT_EQ(b->State(k), "UP");
    EXPECT_EQ(b->Stat(k, "check_status"), "L7OK");
  }
  // Through the balancer: a vistream server of the scene.
  absl::StatusOr<v1::ServerStats> stats = client::Probe(b->address(), kWait);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->scene(), "default");
  // Two sessions at once: leastconn puts one on each replica.
  SessionStream first(b->address()), second(b->address());
  for (SessionStream* s : {&first, &second}) ASSERT_TRUE(OpenOnTheSquare(*s, 1));
  EXPECT_EQ(SessionsOn(*b, 0), 1);
  EXPECT_EQ(SessionsOn(*b, 1), 1);
  EXPECT_TRUE(first.Finish().ok());
  EXPECT_TRUE(second.Finish().ok());
}

// deploy/haproxy.cfg's web frontend: the browser client's page, and the upgrade of /session to a
// WebSocket, reach the replicas' web listeners through HAProxy.
TEST(Balancer, TheBrowsersPageAndItsWebSocketGoThroughTheWebFrontend) {
  std::string error;
  auto b = StartBalanced("balancer_web", "5", &error, "", /*web=*/true);
  ASSERT_NE(b, nullptr) << error;
  const int port = std::stoi(b->web_address().substr(b->web_address().rfind(':') + 1));
  const auto [status, body] = ::vistream::test::HttpGet(port, "/?scene=default");
  EXPECT_EQ(status, 200) << body;
  EXPECT_NE(body.find("<title>vistream</title>"), std::string::npos) << body;
  // The WebSocket handshake (RFC 6455 section 4), by hand: 101 from a replica through HAProxy
  // (which keeps the connection: its first answer is read).
  const std::string reply = tools::LoopbackExchange(
      port,
      "GET /session HTTP/1.1\r\nHost: vistream\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
      "Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n",
      /*first_read_only=*/true, /*timeout_s=*/10);
  EXPECT_EQ(reply.rfind("HTTP/1.1 101", 0), 0u) << reply;
  // The key's accept value (RFC 6455's own example).
  EXPECT_NE(reply.find("s3pPLMBiTxaQ9kYGzzhZRbK+xOo="), std::string::npos) << reply;
}

// Two replicas behind HAProxy sharing one real redis-server: the cells a walker's replica
// computed are store hits on the other, for a second walker at the same place.
TEST(Balancer, APvsComputedThroughOneReplicaIsAStoreHitThroughTheOther) {
  std::string error;
  std::unique_ptr<::vistream::test::RedisServer> redis = ::vistream::test::RedisServer::Start(&error);
  ASSERT_NE(redis, nullptr) << error;
  auto b = StartBalanced("balancer_store", "5", &error, redis->address());
  ASSERT_NE(b, nullptr) << error;
  SessionStream first(b->address());
  ASSERT_TRUE(OpenOnTheSquare(first, 9));
  const int a = WaitForHolder(*b, kWait);
  ASSERT_GE(a, 0);
  absl::StatusOr<v1::ServerStats> sa = client::Probe(b->replica_address(a), kWait);
  ASSERT_TRUE(sa.ok()) << sa.status();
  const uint64_t computed = sa->pvs_computed();
  EXPECT_GE(computed, 9u);
  // Written back (in the background) before the second walker asks.
  const Clock::time_point t0 = Clock::now();
  while (sa->store().writes() < computed && Since(t0) < kWait) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    sa = client::Probe(b->replica_address(a), kWait);
    ASSERT_TRUE(sa.ok()) << sa.status();
  }
  EXPECT_EQ(sa->store().writes(), computed);
  // leastconn: the second walker, through the balancer, lands on the other replica.
  SessionStream second(b->address());
  ASSERT_TRUE(OpenOnTheSquare(second, 9));
  const size_t other = 1 - a;
  EXPECT_EQ(SessionsOn(*b, other), 1) << "the second walker is not on " << b->name(other);
  absl::StatusOr<v1::ServerStats> sb = client::Probe(b->replica_address(other), kWait);
  ASSERT_TRUE(sb.ok()) << sb.status();
  EXPECT_EQ(sb->pvs_computed(), 0u);
  EXPECT_EQ(sb->pvs_store_hits(), computed);
  EXPECT_EQ(sb->store().hits(), computed);
  EXPECT_EQ(sb->store().address(), redis->address());
  // ... and its /metrics.
  const std::string metrics = test::HttpBody(b->metrics_port(other), "/metrics");
  EXPECT_NE(metrics.find("vistream_pvs_store_hits_total{scene=\"default\"} " + std::to_string(computed) + "\n"),
            std::string::npos)
      << metrics;
  EXPECT_NE(metrics.find("vistream_pvs_computations_total{scene=\"default\"} 0\n"), std::string::npos) << metrics;
  EXPECT_TRUE(first.Finish().ok());
  EXPECT_TRUE(second.Finish().ok());
}

TEST(Balancer, AReplicaKilledMidWalkIsReplacedWithoutAStallOrAnObjectSentTwice) {
  std::string error;
  // With the store: the replica the walker moves to reads the cells the killed one computed.
  std::unique_ptr<::vistream::test::RedisServer> redis = ::vistream::test::RedisServer::Start(&error);
  ASSERT_NE(redis, nullptr) << error;
  auto b = StartBalanced("balancer_kill", "5", &error, redis->address());
  ASSERT_NE(b, nullptr) << error;
  const WalkthroughOptions o = Walk(b->address(), 16.0);
  std::future<absl::StatusOr<WalkthroughSummary>> walk =
      std::async(std::launch::async, [&] { return client::RunWalkthrough(o); });
  const int holder = WaitForHolder(*b, kWait);
  ASSERT_GE(holder, 0) << "the walk has no session on either replica";
  std::this_thread::sleep_for(std::chrono::seconds(5));
  ASSERT_EQ(SessionsOn(*b, holder), 1) << "the walker left " << b->name(holder) << " before it was killed";
  const size_t other = 1 - holder;
  ASSERT_EQ(SessionsOn(*b, other), 0);
  EXPECT_EQ(b->StopReplica(holder, SIGKILL), 128 + SIGKILL);
  EXPECT_TRUE(b->WaitForState(holder, "DOWN", 10.0)) << b->State(holder);
  absl::StatusOr<WalkthroughSummary> s = walk.get();
  ASSERT_TRUE(s.ok()) << s.status();
  ExpectSeamless(*s);
  // The walk went on on the other replica, which sent it the geometry of cells it entered
  // after the move, and read the cells around it at the move from the store.
  ExpectServedTheWalker(*b, other);
  absl::StatusOr<v1::ServerStats> so = client::Probe(b->replica_address(other), kWait);
  ASSERT_TRUE(so.ok()) << so.status();
  EXPECT_GE(so->pvs_store_hits(), 9u) << "the replica the walker moved to computed what the store held";
}

TEST(Balancer, ADrainingReplicaIsTakenOutBeforeItsSessionsEndAndItsWalkerResumesOnTheOther) {
  std::string error;
  auto b = StartBalanced("balancer_drain", "6", &error);
  ASSERT_NE(b, nullptr) << error;
  const WalkthroughOptions o = Walk(b->address(), 20.0);
  std::future<absl::StatusOr<WalkthroughSummary>> walk =
      std::async(std::launch::async, [&] { return client::RunWalkthrough(o); });
  const int holder = WaitForHolder(*b, kWait);
  ASSERT_GE(holder, 0) << "the walk has no session on either replica";
  const size_t other = 1 - holder;
  std::this_thread::sleep_for(std::chrono::seconds(4));
  ASSERT_EQ(SessionsOn(*b, holder), 1) << "the walker left " << b->name(holder) << " before its drain";

  ASSERT_EQ(kill(b->replica(holder)->pid(), SIGTERM), 0);
  const Clock::time_point sigterm = Clock::now();
  // The replica says 503 at once, and HAProxy marks it DOWN while the walker's session is
  // still open there (drain_s 6 s; DOWN takes about 0.3 s with the test's check timers).
  int healthz = 0;
  while ((healthz = test::HttpStatus(b->metrics_port(holder), "/healthz")) != 503 && Since(sigterm) < 2.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(healthz, 503);
  ASSERT_TRUE(b->WaitForState(holder, "DOWN", 3.0)) << b->State(holder) << "\n" << b->HaproxyLog();
  const double down_s = Since(sigterm);
  EXPECT_EQ(SessionsOn(*b, holder), 1) << "the session ended before HAProxy took its replica out";
  // A session opened now lands on the other replica.
  SessionStream fresh(b->address());
  ASSERT_TRUE(OpenOnTheSquare(fresh, 1));
  EXPECT_EQ(SessionsOn(*b, other), 1) << "the new session is not on " << b->name(other);
  EXPECT_EQ(SessionsOn(*b, holder), 1) << "the new session went to the draining replica";
  const double checked_s = Since(sigterm);
  EXPECT_LT(checked_s, 5.5) << "DOWN after " << down_s << " s; the checks took too long for a 6 s drain";
  EXPECT_TRUE(fresh.Finish().ok());

  // After the drain the replica ends the walker's session and exits 0; the walker resumes on
  // the other replica.
  EXPECT_EQ(b->StopReplica(holder, 0), 0);
  EXPECT_GE(Since(sigterm), 5.8) << "the replica ended before its drain_s (6 s)";
  absl::StatusOr<WalkthroughSummary> s = walk.get();
  ASSERT_TRUE(s.ok()) << s.status();
  ExpectSeamless(*s);
  ExpectServedTheWalker(*b, other, 2);  // the walker and `fresh`
  // The walker's session ended UNAVAILABLE (code 14), the status clients resume after.
  const std::string log = b->replica_log(holder);
  EXPECT_NE(log.find("code=14 message=\"the server is shutting down\""), std::string::npos) << log;
  std::printf("HAProxy marked %s DOWN %.2f s after its SIGTERM; it ended its sessions after its 6 s drain\n",
              b->name(holder).c_str(), down_s);
}

// Both replicas restarted one after the other (SIGTERM, drain, start again on the same ports,
// UP again in HAProxy) while a walker walks, the walker's replica first: it moves to the other,
// then back to the restarted one, and loses nothing and never stalls.
TEST(Balancer, ARollingRestartLosesNoWalkerAndCausesNoStall) {
  std::string error;
  auto b = StartBalanced("balancer_rolling", "2", &error);
  ASSERT_NE(b, nullptr) << error;
  const WalkthroughOptions o = Walk(b->address(), 20.0);
  std::future<absl::StatusOr<WalkthroughSummary>> walk =
      std::async(std::launch::async, [&] { return client::RunWalkthrough(o); });
  const int holder = WaitForHolder(*b, kWait);
  ASSERT_GE(holder, 0) << "the walk has no session on either replica";
  std::this_thread::sleep_for(std::chrono::seconds(2));
  for (const size_t k : {static_cast<size_t>(holder), static_cast<size_t>(1 - holder)}) {
    ASSERT_EQ(SessionsOn(*b, k), 1) << "the walker is not on " << b->name(k) << " when it is restarted";
    const Clock::time_point stop = Clock::now();
    EXPECT_EQ(b->StopReplica(k, SIGTERM), 0) << b->replica_log(k);
    ASSERT_TRUE(b->StartReplica(k, &error)) << error;
    ASSERT_TRUE(b->WaitForState(k, "UP", 10.0)) << b->State(k) << "\n" << b->HaproxyLog();
    std::printf("%s restarted and UP again in %.2f s\n", b->name(k).c_str(), Since(stop));
  }
  ASSERT_EQ(walk.wait_for(std::chrono::seconds(0)), std::future_status::timeout)
      << "the walk ended before the restarts did: they were not under traffic";
  absl::StatusOr<WalkthroughSummary> s = walk.get();
  ASSERT_TRUE(s.ok()) << s.status();
  ExpectSeamless(*s);
  EXPECT_GE(s->reconnects, 2u) << "the walker did not move at each restart";
  ExpectServedTheWalker(*b, holder);  // restarted, it took the walker back
}

}  // namespace
}  // namespace vistream::server
