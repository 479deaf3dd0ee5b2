// vistream-server's TOML configuration (server/server_config.h): every key read, every bad
// value refused as "FILE:LINE: KEY: what is wrong".
#include "server/server_config.h"

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/temp_dir.h"

namespace vistream::server {
namespace {

namespace fs = std::filesystem;

// A folder of this test's own with a readable file `a.pem` in it.
std::string Folder() {
  static const std::string dir = [] {
    const std::string d = vistream::testing::ProcessTempDir() + "/config";
    fs::create_directories(d);
    std::ofstream(d + "/a.pem") << "x\n";
    std::ofstream(d + "/tokens") << "alice 0123456789abcdef\n";
    return d;
  }();
  return dir;
}

absl::StatusOr<ServerConfig> Parse(const std::string& text) {
  return ParseServerConfig(text, Folder() + "/server.toml");
}

// The error of `text`, which must fail.
std::string ErrorOf(const std::string& text) {
  absl::StatusOr<ServerConfig> c = Parse(text);
  EXPECT_FALSE(c.ok()) << text;
  return c.ok() ? "" : std::string(c.status().message());
}

TEST(ServerConfig, AFullFileSetsEveryKey) {
  const std::string dir = Folder();
  const std::string text = "listen = \"0.0.0.0:7000\"\n"
                           "threads = 3\n"
                           "max_sessions = 40\n"
                           "catalog = \"" + dir + "\"\n"
                           "grace_s = 2.5\n"
                           "[limits]\n"
                           "hello_timeout_s = 7\n"
                           "max_pose_rate_hz = 60.5\n"
                           "max_sessions_per_address = 4\n"
                           "max_sessions_per_token = 9\n"
                           "[tls]\n"
                           "cert = \"a.pem\"\n"
                           "key = \"" + dir + "/a.pem\"\n"
                           "client_ca = \"a.pem\"\n"
                           "insecure = true\n"
                           "[auth]\n"
                           "tokens = \"tokens\"\n"
                           "[metrics]\n"
                           "listen = \"127.0.0.1:9464\"\n"
                           "[store]\n"
                           "address = \"10.0.0.5:6379\"\n"
                           "key_prefix = \"city\"\n"
                           "connect_timeout_ms = 300\n"
                           "read_timeout_ms = 20\n"
                           "write_timeout_ms = 900\n"
                           "username = \"vistream\"\n"
                           "password_file = \"a.pem\"\n"
                           "[log]\n"
                           "format = \"json\"\n"
                           "file = \"server.log\"\n"
                           "[[scenes]]\n"
                           "name = \"london\"\n"
                           "cache_mb = 512\n"
                           "levels = true\n"
                           "[[scenes]]\n"
                           "name = \"town\"\n"
                           "file = \"a.pem\"\n"
                           "pvs_file = \"a.pem\"\n"
                           "cell_size_m = 50\n"
                           "res = 64\n"
                           "backend = \"exact\"\n";
  absl::StatusOr<ServerConfig> c = Parse(text);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->listen, "0.0.0.0:7000");
  EXPECT_EQ(c->threads, 3u);
  EXPECT_EQ(c->max_sessions, 40u);
  EXPECT_EQ(c->catalog, dir);
  EXPECT_EQ(c->grace_s, 2.5);
  EXPECT_EQ(c->hello_timeout_s, 7.0);
  EXPECT_EQ(c->max_pose_rate_hz, 60.5);
  EXPECT_EQ(c->max_sessions_per_address, 4u);
  EXPECT_EQ(c->max_sessions_per_token, 9u);
  // Relative paths are the configuration file's folder's.
  EXPECT_EQ(c->tls_cert, dir + "/a.pem");
  EXPECT_EQ(c->tls_key, dir + "/a.pem");
  EXPECT_EQ(c->tls_client_ca, dir + "/a.pem");
  EXPECT_TRUE(c->tls_insecure);
  EXPECT_EQ(c->tokens, dir + "/tokens");
  EXPECT_EQ(c->metrics_listen, "127.0.0.1:9464");
  EXPECT_EQ(c->store_address, "10.0.0.5:6379");
  EXPECT_EQ(c->store_key_prefix, "city");
  EXPECT_EQ(c->store_connect_timeout_ms, 300.0);
  EXPECT_EQ(c->store_read_timeout_ms, 20.0);
  EXPECT_EQ(c->store_write_timeout_ms, 900.0);
  EXPECT_EQ(c->store_username, "vistream");
  EXPECT_EQ(c->store_password_file, dir + "/a.pem");
  EXPECT_TRUE(c->log_json);
  EXPECT_EQ(c->log_file, dir + "/server.log");
  ASSERT_EQ(c->scenes.size(), 2u);
  EXPECT_EQ(c->scenes[0].name, "london");
  EXPECT_EQ(c->scenes[0].source(), "london");
  EXPECT_EQ(c->scenes[0].cache_mb, 512.0);
  EXPECT_TRUE(c->scenes[0].levels);
  EXPECT_FALSE(c->scenes[1].levels);
  EXPECT_EQ(c->scenes[0].res, 128u);  // the default
  EXPECT_EQ(c->scenes[0].line, 31);
  EXPECT_EQ(c->scenes[1].name, "town");
  EXPECT_EQ(c->scenes[1].source(), dir + "/a.pem");
  EXPECT_EQ(c->scenes[1].pvs_file, dir + "/a.pem");
  EXPECT_EQ(c->scenes[1].cell_size_m, 50.0);
  EXPECT_EQ(c->scenes[1].res, 64u);
  EXPECT_EQ(c->scenes[1].backend, "exact");
  EXPECT_TRUE(CheckServerConfig(*c).ok());
}

TEST(ServerConfig, AnEmptyFileKeepsTheDefaultsButServesNothing) {
  absl::StatusOr<ServerConfig> c = Parse("# nothing\n");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->listen, "127.0.0.1:50051");
  EXPECT_EQ(c->max_sessions, 256u);
  EXPECT_EQ(c->hello_timeout_s, 30.0);
  EXPECT_FALSE(c->log_json);
  EXPECT_TRUE(c->metrics_listen.empty());
  EXPECT_TRUE(c->store_address.empty());
  EXPECT_EQ(c->store_read_timeout_ms, 50.0);
  const absl::Status st = CheckServerConfig(*c);
  EXPECT_FALSE(st.ok());
  EXPECT_NE(st.message().find("no scene to serve"), std::string::npos) << st;
}

// Each key with a value of the wrong type or out of range: the file, the line, the key.
TEST(ServerConfig, EveryKeyRefusesBadValuesNamingFileLineAndKey) {
  const std::string file = Folder() + "/server.toml";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"listen = 5", ":1: listen: expected a string, got a whole number"},
      {"listen = \"localhost\"", ":1: listen: 'localhost' is not host:port"},
      {"listen = \"h:70000\"", ":1: listen: 'h:70000' is not host:port"},
      {"threads = -1", ":1: threads: -1 is out of range (0 to 1024)"},
      {"threads = 2.5", ":1: threads: expected a whole number, got a number with a fraction"},
      {"max_sessions = 0", ":1: max_sessions: 0 is out of range (1 to 100000)"},
      {"catalog = \"/no/such/folder\"", ":1: catalog: /no/such/folder: no such folder"},
      {"grace_s = \"5\"", ":1: grace_s: expected a number, got a string"},
      {"grace_s = 4000", ":1: grace_s: 4000 is out of range (0 to 3600)"},
      {"grace_s = nan", ":1: grace_s: nan is out of range"},
      {"drain_s = \"5\"", ":1: drain_s: expected a number, got a string"},
      {"drain_s = -1", ":1: drain_s: -1 is out of range (0 to 3600)"},
      {"[limits]\nhello_timeout_s = -1", ":2: limits.hello_timeout_s: -1 is out of range (0 to 86400)"},
      {"[limits]\nmax_pose_rate_hz = 0", ":2: limits.max_pose_rate_hz: 0 is out of range (0.1 to 100000)"},
      {"[limits]\nmax_sessions_per_address = -3", ":2: limits.max_sessions_per_address: -3 is out of range"},
      {"[limits]\nmax_sessions_per_token = true", ":2: limits.max_sessions_per_token: expected a whole number"},
      {"[tls]\ncert = \"missing.pem\"\nkey = \"a.pem\"", ":2: tls.cert: " + Folder() + "/missing.pem: no such file"},
      {"[tls]\ncert = \"a.pem\"\nkey = \"/no/key.pem\"", ":3: tls.key: /no/key.pem: no such file"},
      {"[tls]\ncert = \"a.pem\"", ":1: tls.key: tls.cert and tls.key go together"},
      {"[tls]\nclient_ca = \"a.pem\"", ":1: tls.client_ca: mutual TLS needs the server's own tls.cert and tls.key"},
      {"[tls]\nclient_ca = 1", ":2: tls.client_ca: expected a string, got a whole number"},
      {"[tls]\ninsecure = \"yes\"", ":2: tls.insecure: expected true or false, got a string"},
      {"[auth]\ntokens = \"nope\"", ":2: auth.tokens: " + Folder() + "/nope: no such file"},
      {"[metrics]\nlisten = \"9464\"", ":2: metrics.listen: '9464' is not host:port"},
      {"[store]\naddress = \"redis\"", ":2: store.address: 'redis' is not host:port or unix:/path"},
      {"[store]\naddress = \"h:0\"", ":2: store.address: 'h:0' is not host:port or unix:/path"},
      {"[store]\nkey_prefix = \"a\"", ":1: store.address: missing"},
      {"[store]\naddress = \"h:1\"\nkey_prefix = \"a b\"", ":3: store.key_prefix: expected a non-empty word"},
      {"[store]\naddress = \"h:1\"\nread_timeout_ms = 0", ":3: store.read_timeout_ms: 0 is out of range (above 0"},
      {"[store]\naddress = \"h:1\"\npassword_file = \"/no/pw\"", ":3: store.password_file: /no/pw: no such file"},
      {"[log]\nformat = \"xml\"", ":2: log.format: 'xml' is not one of text, json"},
      {"[log]\nfile = \"/no/such/dir/server.log\"", ":2: log.file: /no/such/dir: no such folder"},
      {"[log]\nfile = \"" + Folder() + "\"", ":2: log.file: " + Folder() + ": is a folder, not a file"},
      {"[[scenes]]\nname = 3", ":2: scenes[1].name: expected a string, got a whole number"},
      {"[[scenes]]\ncache_mb = 512", ":1: scenes[1].name: missing"},
      {"[[scenes]]\nname = \"\"", ":1: scenes[1].name: must not be empty"},
      {"[[scenes]]\nname = \"a\"\nfile = \"x.glb\"", ":3: scenes[1].file: " + Folder() + "/x.glb: no such file"},
      {"[[scenes]]\nname = \"a\"\npvs_file = \"/x.pvs\"", ":3: scenes[1].pvs_file: /x.pvs: no such file"},
      {"[[scenes]]\nname = \"a\"\ncell_size_m = 0.001", ":3: scenes[1].cell_size_m: 0.001 is out of range"},
      {"[[scenes]]\nname = \"a\"\ncell_size_m = -1", ":3: scenes[1].cell_size_m: -1 is out of range"},
      {"[[scenes]]\nname = \"a\"\nres = 100", ":3: scenes[1].res: 100 is not a power of two from 1 to 256"},
      {"[[scenes]]\nname = \"a\"\nres = 512", ":3: scenes[1].res: 512 is out of range (1 to 256)"},
      {"[[scenes]]\nname = \"a\"\nbackend = \"gpu\"", ":3: scenes[1].backend: 'gpu' is not one of cpu, gl, exact"},
      {"[[scenes]]\nname = \"a\"\ncache_mb = 0", ":3: scenes[1].cache_mb: 0 is out of range (1 to 1e+06)"},
      {"[[scenes]]\nname = \"a\"\nlevels = 1", ":3: scenes[1].levels: expected"},
      {"[[scenes]]\nname = \"a\"\n[[scenes]]\nname = \"b\"\n[[scenes]]\nname = \"a\"",
       ":5: scenes[3].name: a second scene named 'a' (the first is at line 1)"},
      {"scenes = \"london\"", ":1: scenes: expected [[scenes]] tables, got a string"},
      {"tls = 1", ":1: tls: expected a table ([tls]), got a whole number"},
  };
  for (const auto& [text, expected] : cases) {
    const std::string error = ErrorOf(text);
    EXPECT_EQ(error.rfind(file + ":", 0), 0u) << text << " -> " << error;
    EXPECT_NE(error.find(expected), std::string::npos) << text << " -> " << error << "\n expected: " << expected;
  }
}

// drain_s: seconds a SIGTERM'd server keeps serving behind a 503 /healthz (a balancer takes it
// out meanwhile); 5 by default, 0 allowed (end the sessions at once), a top-level key.
TEST(ServerConfig, DrainSecondsIsReadDefaultsToFiveAndBelongsAtTheTop) {
  absl::StatusOr<ServerConfig> c = Parse("drain_s = 12.5\n");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->drain_s, 12.5);
  c = Parse("drain_s = 0\n");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->drain_s, 0.0);
  c = Parse("");
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->drain_s, 5.0);
  const std::string e = ErrorOf("[metrics]\nlisten = \"127.0.0.1:1\"\ndrain_s = 3\n");
  EXPECT_NE(e.find(":3: metrics.drain_s: unknown key"), std::string::npos) << e;
  EXPECT_NE(e.find("top-level keys go above the first [table] in the file"), std::string::npos) << e;
}

TEST(ServerConfig, UnknownKeysAreNamedWithTheKeysThatExist) {
  std::string e = ErrorOf("listen = \"127.0.0.1:1\"\nlisen = \"x\"\n");
  EXPECT_NE(e.find("server.toml:2: lisen: unknown key (top level keys: listen, threads"), std::string::npos) << e;
  e = ErrorOf("[tls]\ncertificate = \"a.pem\"\n");
  EXPECT_NE(e.find(":2: tls.certificate: unknown key ([tls] keys: cert, key, client_ca, insecure)"), std::string::npos)
      << e;
  e = ErrorOf("[[scenes]]\nname = \"a\"\nresolution = 64\n");
  EXPECT_NE(e.find(":3: scenes[1].resolution: unknown key ([scenes[1]] keys: name, file"), std::string::npos) << e;
  // A top-level key written below a table lands in it: the message says where it belongs.
  e = ErrorOf("[[scenes]]\nname = \"a\"\nlisten = \"0.0.0.0:50051\"\n");
  EXPECT_NE(e.find(":3: scenes[1].listen: unknown key"), std::string::npos) << e;
  EXPECT_NE(e.find("top-level keys go above the first [table] in the file"), std::string::npos) << e;
  e = ErrorOf("[metric]\nlisten = \"127.0.0.1:1\"\n");
  EXPECT_NE(e.find(":1: metric: unknown key"), std::string::npos) << e;
}

TEST(ServerConfig, SyntaxErrorsNameLineAndColumn) {
  const std::string e = ErrorOf("listen = \"127.0.0.1:1\"\nthreads = = 2\n");
  EXPECT_EQ(e.rfind(Folder() + "/server.toml:2:", 0), 0u) << e;
  const std::string twice = ErrorOf("threads = 1\nthreads = 2\n");
  EXPECT_EQ(twice.rfind(Folder() + "/server.toml:2:", 0), 0u) << twice;
}

TEST(ServerConfig, AFileThatCannotBeReadIsNamed) {
  absl::StatusOr<ServerConfig> c = LoadServerConfig("/no/such/server.toml");
  ASSERT_FALSE(c.ok());
  EXPECT_EQ(c.status().message(), "/no/such/server.toml: cannot read: No such file or directory");
  c = LoadServerConfig(Folder());
  ASSERT_FALSE(c.ok());
  EXPECT_NE(c.status().message().find("is a folder"), std::string::npos) << c.status();
  if (geteuid() != 0) {  // root reads anything
    const std::string locked = Folder() + "/locked.toml";
    std::ofstream(locked) << "threads = 1\n";
    chmod(locked.c_str(), 0);
    c = LoadServerConfig(locked);
    EXPECT_FALSE(c.ok());
  }
  // And a real file reads.
  const std::string good = Folder() + "/good.toml";
  std::ofstream(good) << "threads = 1\n[[scenes]]\nname = \"city1\"\n";
  c = LoadServerConfig(good);
  ASSERT_TRUE(c.ok()) << c.status();
  EXPECT_EQ(c->path, good);
  EXPECT_EQ(c->scenes.size(), 1u);
}

TEST(ServerConfig, HostPortIsCheckedAsGrpcWouldNeedIt) {
  for (const char* good : {"127.0.0.1:0", "localhost:50051", "[::1]:9464", "0.0.0.0:65535", "h:1"}) {
    EXPECT_TRUE(IsHostPort(good)) << good;
  }
  for (const char* bad : {"", ":1", "127.0.0.1", "127.0.0.1:", "127.0.0.1:65536", "a:b", "::1:5", "[]:1", "a b:1"}) {
    EXPECT_FALSE(IsHostPort(bad)) << bad;
  }
}

}  // namespace
}  // namespace vistream::server
