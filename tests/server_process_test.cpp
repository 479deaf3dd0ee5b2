// The vistream-server executable: its options, checked before the scene loads, and SIGTERM.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include <fstream>

#include "client/connection.h"
#include "client/session_stream.h"
#include "tests/server_process_util.h"
#include "tests/server_test_util.h"
#include "tests/temp_dir.h"

namespace vistream::server {
namespace {

using client::SessionRecord;
using client::SessionStream;
using test::Centre;
using test::kWait;

using test::RunServer;

// Bad options exit 2 in the tool's form, naming the option, before any scene is looked for:
// the scene named here does not exist, and the error is about the option all the same.
TEST(ServerProcess, BadOptionsExitTwoBeforeTheSceneLoadsNamingThem) {
  const std::pair<const char*, const char*> cases[] = {
      {"--res 100", "vistream-server: error: --res: '100' is not a power of two from 1 to 256"},
      {"--res 512", "vistream-server: error: --res: '512' is not a power of two from 1 to 256"},
      {"--listen 127.0.0.1:99999", "vistream-server: error: --listen: '127.0.0.1:99999' is not host:port"},
      {"--listen 50051", "vistream-server: error: --listen: '50051' is not host:port"},
      {"--listen localhost:", "vistream-server: error: --listen: 'localhost:' is not host:port"},
      {"--port 99999", "vistream-server: error: --port: not an option of vistream-server (the address is --listen"},
      {"stray", "vistream-server: error: 'stray': not expected by vistream-server"},
      {"--cache-mb -1", "vistream-server: error: --cache-mb: '-1' is not a number from 1 to 1e+06"},
      {"--max-sessions 0", "vistream-server: error: --max-sessions: '0' is not a whole number from 1 to 100000"},
      {"--max-sessions 1.5", "vistream-server: error: --max-sessions: '1.5' is not a whole number from 1 to 100000"},
  };
  for (const auto& [args, message] : cases) {
    const auto [rc, out] = RunServer(std::string("--scene no-such-scene ") + args);
    EXPECT_EQ(rc, 2) << args << ": " << out;
    EXPECT_NE(out.find(message), std::string::npos) << args << ": " << out;
    EXPECT_NE(out.find("Run 'vistream-server --help' for the options."), std::string::npos) << args << ": " << out;
    EXPECT_EQ(out.find("no-such-scene"), std::string::npos) << args << ": " << out;
  }
  // An unknown option is named before the missing --scene it may hide.
  {
    const auto [rc, out] = RunServer("--port 5");
    EXPECT_EQ(rc, 2) << out;
    EXPECT_NE(out.find("vistream-server: error: --port: not an option of vistream-server (the address is --listen"),
              std::string::npos)
        << out;
  }
  // Good values pass the checks: the scene is what fails then.
  const auto [rc, out] = RunServer("--scene no-such-scene --res 64 --listen 127.0.0.1:0 --max-sessions 3");
  EXPECT_EQ(rc, 1) << out;
  EXPECT_NE(out.find("no-such-scene"), std::string::npos) << out;
}

// The executable's link options: bad values exit 2 before the scene loads, naming the option.
TEST(ServerProcess, MalformedLinkOptionsAreRefusedNamingThem) {
  auto run = [](const std::string& args) { return RunServer("--scene city1 --listen 127.0.0.1:0 " + args); };
  for (const char* k : {"0", "-2", "abc", "nan", "inf", "1e9", "''", "2x"}) {
    const auto [rc, out] = run(std::string("--emulate-link --time-scale ") + k);
    EXPECT_EQ(rc, 2) << k << ": " << out;
    EXPECT_NE(out.find("vistream-server: error: --time-scale: "), std::string::npos) << k << ": " << out;
  }
  for (const char* l : {"1M", "1M,", ",200", "fast,200", "1M,-5", "1T,200", "0,200", "1M,nan", "1M,200,3"}) {
    const auto [rc, out] = run(std::string("--link '") + l + "'");
    EXPECT_EQ(rc, 2) << l << ": " << out;
    EXPECT_NE(out.find(std::string("vistream-server: error: --link: '") + l + "'"), std::string::npos)
        << l << ": " << out;
  }
  for (const char* k : {"-1", "abc", "1.5", "1e300"}) {
    const auto [rc, out] = run(std::string("--emulate-link --link-seed ") + k);
    EXPECT_EQ(rc, 2) << k << ": " << out;
    EXPECT_NE(out.find("--link-seed"), std::string::npos) << k << ": " << out;
  }
  const auto [rc, out] = run("--time-scale 10");
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("--time-scale and --link-seed need --emulate-link or --link"), std::string::npos) << out;
}

// The executable: started on a free port, stopped with SIGTERM while sessions are open.
TEST(ServerProcess, SigtermEndsOpenSessionsCleanlyAndExitsZero) {
  std::string error;
  std::unique_ptr<test::RunningServer> server = test::RunningServer::Start(
      VISTREAM_SERVER_BIN, {"--scene", "city1", "--listen", "127.0.0.1:0", "--threads", "1"}, &error);
  ASSERT_NE(server, nullptr) << error;
  const std::string& ready = server->ready_line();
  const std::string address = server->address();
  EXPECT_NE(ready.find("560 viewcells"), std::string::npos) << ready;
  EXPECT_NE(ready.find("2128 objects"), std::string::npos) << ready;
  std::vector<std::unique_ptr<SessionStream>> clients;
  for (int k = 0; k < 2; ++k) {
    clients.push_back(std::make_unique<SessionStream>(address));
    clients.back()->Start(SessionStream::HelloFor("city1"));
    clients.back()->SendCredit(uint64_t{1} << 40);
    clients.back()->SendPose(Centre(4 + k, 4));
    ASSERT_TRUE(clients.back()->WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  }
  ASSERT_EQ(kill(server->pid(), SIGTERM), 0);
  for (auto& c : clients) {
    const grpc::Status st = c->AwaitEnd(kWait);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::UNAVAILABLE) << st.error_message();
    EXPECT_NE(st.error_message().find("shutting down"), std::string::npos) << st.error_message();
  }
  EXPECT_EQ(server->Stop(0), 0);  // it exits by itself
}

// A configuration file written to the test's folder.
std::string WriteConfig(const std::string& name, const std::string& text) {
  const std::string path = vistream::testing::ProcessTempDir() + "/" + name;
  std::ofstream(path) << text;
  return path;
}

// A bad configuration fails before any scene loads: exit 2, "FILE:LINE: KEY: what".
TEST(ServerProcess, ABadConfigurationExitsTwoNamingFileLineAndKeyBeforeAnySceneLoads) {
  const std::string path = WriteConfig("bad.toml",
                                       "[[scenes]]\n"
                                       "name = \"no-such-scene\"\n"
                                       "res = 100\n");
  auto [rc, out] = RunServer("--config " + path);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("vistream-server: error: " + path + ":3: scenes[1].res: 100 is not a power of two"),
            std::string::npos)
      << out;
  EXPECT_EQ(out.find("loading"), std::string::npos) << out;
  std::tie(rc, out) = RunServer("--config /no/such.toml");
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("vistream-server: error: /no/such.toml: cannot read"), std::string::npos) << out;
  // A scene name the catalog does not have: exit 2 before any scene loads (city1 is first).
  const std::string unknown = WriteConfig("unknown_scene.toml",
                                          "[[scenes]]\nname = \"city1\"\n[[scenes]]\nname = \"city9\"\n");
  std::tie(rc, out) = RunServer("--config " + unknown);
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("vistream-server: error: " + unknown + ":3: scenes[2].name: no scene 'city9' in the catalog"),
            std::string::npos)
      << out;
  EXPECT_EQ(out.find("loading"), std::string::npos) << out;
  // Neither a configuration nor --scene: nothing to serve.
  std::tie(rc, out) = RunServer("--listen 127.0.0.1:0");
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("no scene to serve: give --scene NAME or [[scenes]] tables"), std::string::npos) << out;
  // A configuration whose scenes are fine but with no scene at all.
  std::tie(rc, out) = RunServer("--config " + WriteConfig("empty.toml", "threads = 1\n"));
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("no scene to serve"), std::string::npos) << out;
  // Link emulation is for one scene.
  const std::string two = WriteConfig("two.toml", "[[scenes]]\nname = \"a\"\n[[scenes]]\nname = \"b\"\n");
  std::tie(rc, out) = RunServer("--config " + two + " --emulate-link");
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("--emulate-link and --link serve one scene only"), std::string::npos) << out;
  std::tie(rc, out) = RunServer("--config " + two + " --pvs-file x.pvs");
  EXPECT_EQ(rc, 2) << out;
  EXPECT_NE(out.find("--pvs-file: the configuration serves 2 scenes"), std::string::npos) << out;
}

// The file's keys, overridden by the options given: --listen replaces `listen`, --scene the
// [[scenes]], --res each scene's `res`; the keys not overridden hold (the log goes to its file
// as JSON lines).
TEST(ServerProcess, CommandLineOptionsOverrideTheConfigurationsKeys) {
  const std::string log = vistream::testing::ProcessTempDir() + "/override.log";
  const std::string path = WriteConfig("override.toml",
                                       "listen = \"127.0.0.1:1\"\n"
                                       "threads = 1\n"
                                       "[log]\n"
                                       "format = \"json\"\n"
                                       "file = \"" + log + "\"\n"
                                       "[[scenes]]\n"
                                       "name = \"no-such-scene\"\n"
                                       "res = 16\n");
  std::string error;
  std::unique_ptr<test::RunningServer> server = test::RunningServer::Start(
      VISTREAM_SERVER_BIN, {"--config", path, "--listen", "127.0.0.1:0", "--scene", "city1", "--res", "32"}, &error);
  ASSERT_NE(server, nullptr) << error;
  EXPECT_NE(server->port(), 1);
  EXPECT_NE(server->ready_line().find("scene city1, 560 viewcells"), std::string::npos) << server->ready_line();
  EXPECT_NE(server->ready_line().find("dual ray space (cpu, 32^2)"), std::string::npos) << server->ready_line();
  absl::StatusOr<v1::ServerStats> stats = client::Probe(server->address(), kWait);
  ASSERT_TRUE(stats.ok()) << stats.status();
  EXPECT_EQ(stats->scene(), "city1");
  EXPECT_EQ(server->Stop(SIGTERM), 0);
  std::ifstream in(log);
  std::string first;
  ASSERT_TRUE(std::getline(in, first)) << "nothing logged to " << log;
  EXPECT_EQ(first.rfind("{\"time\":", 0), 0u) << first;
  EXPECT_NE(first.find("\"level\":\"info\""), std::string::npos) << first;
}

// Two scenes from one configuration file: one process serves both, and GetStats lists them.
TEST(ServerProcess, OneProcessServesEveryConfiguredScene) {
  const std::string path = WriteConfig("two_scenes.toml",
                                       "listen = \"127.0.0.1:0\"\n"
                                       "threads = 2\n"
                                       "[[scenes]]\n"
                                       "name = \"city1\"\n"
                                       "cache_mb = 64\n"
                                       "[[scenes]]\n"
                                       "name = \"streets\"\n");
  std::string error;
  std::unique_ptr<test::RunningServer> server = test::RunningServer::Start(VISTREAM_SERVER_BIN, {"--config", path}, &error);
  ASSERT_NE(server, nullptr) << error;
  EXPECT_NE(server->ready_line().find("2 scenes: city1 (560 viewcells"), std::string::npos) << server->ready_line();
  EXPECT_NE(server->ready_line().find("; streets ("), std::string::npos) << server->ready_line();
  absl::StatusOr<v1::ServerStats> stats = client::Probe(server->address(), kWait);
  ASSERT_TRUE(stats.ok()) << stats.status();
  ASSERT_EQ(stats->scenes_size(), 2);
  EXPECT_EQ(stats->scenes(1).name(), "streets");
  SessionStream c(server->address());
  c.Start(SessionStream::HelloFor("streets"));
  c.SendCredit(uint64_t{1} << 40);
  ASSERT_TRUE(c.WaitFor([](const SessionRecord& r) { return r.scene_info; }, kWait));
  EXPECT_EQ(c.Snapshot().info.name(), "streets");
  EXPECT_TRUE(c.Finish().ok());
  EXPECT_EQ(server->Stop(SIGTERM), 0);
}

}  // namespace
}  // namespace vistream::server
