// vistream-server's drain (server/server_process.cpp, WalkthroughServer::HoldDrain): from the first
// SIGTERM, /healthz says 503 and gRPC health NOT_SERVING while every session, new ones too, is
// served on for drain_s seconds (a load balancer takes the replica out meanwhile); then the
// sessions end with UNAVAILABLE, which clients answer by reconnecting and resuming, and the
// process exits 0. A second signal stops it at once; an idle server does not wait.
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>

#include <glm/vec3.hpp>
#include <gtest/gtest.h>

#include "client/session_stream.h"
#include "tests/balancer_util.h"
#include "tests/server_process_util.h"
#include "tests/temp_dir.h"

namespace vistream::server {
namespace {

using client::SessionStream;
using Clock = std::chrono::steady_clock;

constexpr double kWait = 60.0;  // seconds any one wait may take on a loaded 2-core machine
// The default scene's walk starts here (scenes/default.json), eye height 1.7 m.
const glm::dvec3 kStart(509.4, 215.9, 1.7);

double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

std::unique_ptr<test::RunningServer> StartDefault(const std::string& drain_s, const std::string& log_name,
                                                  std::string* error) {
  return test::RunningServer::Start(VISTREAM_SERVER_BIN,
                                    {"--scene", "default", "--threads", "1", "--listen", "127.0.0.1:0",
                                     "--metrics-listen", "127.0.0.1:0", "--drain", drain_s},
                                    error, testing::ProcessTempDir() + "/" + log_name);
}

// A session that has its first PVS list: the server serves it.
std::unique_ptr<SessionStream> ServedSession(const std::string& address) {
  auto s = std::make_unique<SessionStream>(address);
  s->set_keep_geometry(false);
  s->Start(SessionStream::HelloFor("default"));
  s->SendCredit(uint64_t{1} << 40);
  s->SendPose(kStart);
  return s;
}

bool HasPvs(const client::SessionRecord& r) { return !r.pvs.empty(); }

TEST(Drain, ASigtermedServerServesOnBehindA503ForDrainSecondsThenEndsItsSessionsUnavailable) {
  std::string error;
  const std::string log = testing::ProcessTempDir() + "/drain_hold.log";
  auto server = StartDefault("4", "drain_hold.log", &error);
  ASSERT_NE(server, nullptr) << error;
  const int metrics = test::MetricsPortOf(server->ready_line());
  ASSERT_EQ(test::HttpStatus(metrics, "/healthz"), 200);
  EXPECT_EQ(test::GrpcHealth(server->address()), "SERVING");
  std::unique_ptr<SessionStream> open = ServedSession(server->address());
  ASSERT_TRUE(open->WaitFor(HasPvs, kWait));

  ASSERT_EQ(kill(server->pid(), SIGTERM), 0);
  const Clock::time_point sigterm = Clock::now();
  int healthz = 0;
  while ((healthz = test::HttpStatus(metrics, "/healthz")) != 503 && Since(sigterm) < 2.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(healthz, 503) << "/healthz after SIGTERM";
  // The standard health service follows within the main loop's 50 ms poll.
  std::string health;
  while ((health = test::GrpcHealth(server->address())) != "NOT_SERVING" && Since(sigterm) < 2.0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_EQ(health, "NOT_SERVING");
  // A session opened during the drain is taken and served (a balancer that has not yet seen
  // the 503 sends it here): it gets its PVS, not a refusal.
  std::unique_ptr<SessionStream> late = ServedSession(server->address());
  EXPECT_TRUE(late->WaitFor(HasPvs, kWait)) << "a session opened during the drain was not served";
  EXPECT_FALSE(late->Ended());
  EXPECT_LT(Since(sigterm), 3.5) << "the machine is too slow for this test's timing";
  EXPECT_FALSE(open->Ended()) << "the open session ended during the drain";

  // Then both end with UNAVAILABLE, not before drain_s, and the server exits 0.
  for (SessionStream* s : {open.get(), late.get()}) {
    const grpc::Status st = s->AwaitEnd(kWait);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAVAILABLE) << st.error_message();
    EXPECT_NE(st.error_message().find("shutting down"), std::string::npos) << st.error_message();
  }
  EXPECT_GE(Since(sigterm), 3.8) << "the sessions ended before drain_s (4 s)";
  EXPECT_EQ(server->Stop(0), 0);
  EXPECT_LT(Since(sigterm), 4.0 + 5.0 + 2.0) << "not within drain_s + grace_s";
  const std::string text = [&] {
    std::ifstream in(log);
    std::stringstream ss;
    ss << in.rdbuf();
    return ss.str();
  }();
  EXPECT_NE(text.find("draining signal=SIGTERM sessions="), std::string::npos) << text;
  EXPECT_NE(text.find(" drain_s=4\n"), std::string::npos) << text;
  EXPECT_NE(text.find("ending_sessions held_s=4"), std::string::npos) << text;
}

// A second SIGTERM (a second or more after the first) cuts a long drain short: exit 1 at once.
TEST(Drain, ASecondSigtermDuringTheDrainStopsAtOnce) {
  std::string error;
  auto server = StartDefault("60", "drain_second.log", &error);
  ASSERT_NE(server, nullptr) << error;
  std::unique_ptr<SessionStream> open = ServedSession(server->address());
  ASSERT_TRUE(open->WaitFor(HasPvs, kWait));
  ASSERT_EQ(kill(server->pid(), SIGTERM), 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(1300));
  EXPECT_FALSE(open->Ended()) << "the drain did not hold the session";
  const Clock::time_point second = Clock::now();
  EXPECT_EQ(server->Stop(SIGTERM), 1);
  EXPECT_LT(Since(second), 2.0);
}

// With no session open there is nothing to hold: the server ends at once, whatever drain_s.
TEST(Drain, AnIdleServerDoesNotWaitForTheDrain) {
  std::string error;
  auto server = StartDefault("60", "drain_idle.log", &error);
  ASSERT_NE(server, nullptr) << error;
  const Clock::time_point sigterm = Clock::now();
  EXPECT_EQ(server->Stop(SIGTERM), 0);
  EXPECT_LT(Since(sigterm), 5.0);
}

// --drain 0: the sessions end at once, as before there was a drain.
TEST(Drain, DrainZeroEndsTheSessionsAtOnce) {
  std::string error;
  auto server = StartDefault("0", "drain_zero.log", &error);
  ASSERT_NE(server, nullptr) << error;
  std::unique_ptr<SessionStream> open = ServedSession(server->address());
  ASSERT_TRUE(open->WaitFor(HasPvs, kWait));
  ASSERT_EQ(kill(server->pid(), SIGTERM), 0);
  const Clock::time_point sigterm = Clock::now();
  const grpc::Status st = open->AwaitEnd(kWait);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAVAILABLE) << st.error_message();
  EXPECT_LT(Since(sigterm), 2.0);
  EXPECT_EQ(server->Stop(0), 0);
}

}  // namespace
}  // namespace vistream::server
