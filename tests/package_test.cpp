// The install tree and the Debian package (issue 32, "Install"; deploy/CMakeLists.txt):
// `cmake --install` into a temporary prefix, `cpack -G DEB`, what dpkg-deb says of the package,
// the systemd unit under `systemd-analyze verify`, and the installed programs run from the
// installed tree. The install and the package are made once for the suite (SetUpTestSuite),
// so ctest runs this binary as one test.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "tests/grpc_health_util.h"
#include "tests/loopback_util.h"
#include "tests/temp_dir.h"

namespace vistream {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

struct RunResult {
  int exit_code = -1;  // -1: did not exit normally
  std::string out;     // stdout and stderr
};

RunResult Shell(const std::string& command) {
  RunResult r;
  std::FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) r.out.append(buf, n);
  const int status = pclose(p);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string Quote(const fs::path& p) {
  std::string q = "'";
  for (char c : p.string()) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string ReadFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void WriteFile(const fs::path& p, const std::string& text) {
  std::ofstream out(p, std::ios::binary);
  out << text;
}

double SecondsSince(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

// Every file (and link) below `root`, as paths relative to it.
std::set<std::string> FilesBelow(const fs::path& root) {
  std::set<std::string> files;
  for (const fs::directory_entry& e : fs::recursive_directory_iterator(root)) {
    if (!e.is_directory()) files.insert(fs::relative(e.path(), root).generic_string());
  }
  return files;
}

// What the issue names, relative to the prefix: the three programs, the catalog (with the
// OpenStreetMap extract monaco reads and its licence), the example configuration, the unit and
// the documentation.
std::set<std::string> ExpectedTree() {
  std::set<std::string> files = {
      "bin/vistream",
      "bin/vistream-server",
      "bin/vistream-client",
      "share/vistream/data/osm/monaco.osm.pbf",
      "share/vistream/data/osm/README.md",
      "etc/vistream/server.toml",
      "lib/systemd/system/vistream-server.service",
      "share/doc/vistream/README.md",
      // The deployment and scaling pages, where the README's links (docs/...) find them.
      "share/doc/vistream/docs/deploying.md",
      "share/doc/vistream/docs/scaling-out.md",
      "share/doc/vistream/tokens.example",
      "share/doc/vistream/haproxy.cfg",
      // The browser client's page (web/), which vistream-server serves by default from here.
      "share/vistream/web/app.js",
      "share/vistream/web/index.html",
  };
  for (const fs::directory_entry& e : fs::directory_iterator(fs::path(VISTREAM_SOURCE_DIR) / "scenes")) {
    if (e.path().extension() == ".json") files.insert("share/vistream/scenes/" + e.path().filename().string());
  }
  return files;
}

// Where the package puts a file of the prefix tree: /etc and /lib stay, the rest goes below /usr.
std::string PackagePath(const std::string& prefix_relative) {
  if (prefix_relative.starts_with("etc/") || prefix_relative.starts_with("lib/systemd/")) return prefix_relative;
  return "usr/" + prefix_relative;
}

class Package : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::path(testing::ProcessTempDir()) / "package";
    prefix_ = dir_ / "prefix";
    root_ = dir_ / "root";
    fs::create_directories(dir_);

    const Clock::time_point install_start = Clock::now();
    const RunResult install =
        Shell(std::string(CMAKE_COMMAND_PATH) + " --install " + Quote(VISTREAM_BUILD_DIR) + " --prefix " + Quote(prefix_));
    ASSERT_EQ(install.exit_code, 0) << install.out;
    std::printf("cmake --install: %.1f s\n", SecondsSince(install_start));

    const RunResult arch = Shell("dpkg --print-architecture");
    ASSERT_EQ(arch.exit_code, 0) << arch.out;
    deb_ = dir_ / "deb" / ("vistream_" VISTREAM_VERSION "_" + arch.out.substr(0, arch.out.find('\n')) + ".deb");
    // cpack's staging folder goes to -B as well, so the build folder is left as it was.
    const Clock::time_point pack_start = Clock::now();
    const RunResult pack = Shell("cd " + Quote(dir_) + " && " + CPACK_COMMAND_PATH + " -G DEB --config " +
                               Quote(fs::path(VISTREAM_BUILD_DIR) / "CPackConfig.cmake") + " -B " + Quote(dir_ / "deb"));
    ASSERT_EQ(pack.exit_code, 0) << pack.out;
    ASSERT_TRUE(fs::exists(deb_)) << "no " << deb_ << "; cpack said:\n" << pack.out;
    std::printf("cpack -G DEB: %.1f s, %s: %.1f MB\n", SecondsSince(pack_start), deb_.filename().c_str(),
                static_cast<double>(fs::file_size(deb_)) / 1e6);

    const RunResult extract = Shell("dpkg-deb -x " + Quote(deb_) + " " + Quote(root_));
    ASSERT_EQ(extract.exit_code, 0) << extract.out;
  }

  static fs::path dir_;     // everything this suite makes
  static fs::path prefix_;  // cmake --install --prefix
  static fs::path deb_;     // the package
  static fs::path root_;    // the package's files, dpkg-deb -x
};
fs::path Package::dir_, Package::prefix_, Package::deb_, Package::root_;

TEST_F(Package, InstallPutsTheIssuesFilesBelowThePrefixAndNothingElse) {
  EXPECT_EQ(FilesBelow(prefix_), ExpectedTree());
  for (const char* program : {"vistream", "vistream-server", "vistream-client"}) {
    const fs::perms p = fs::status(prefix_ / "bin" / program).permissions();
    EXPECT_NE(p & fs::perms::others_exec, fs::perms::none) << program;
  }
  const fs::path deploy = fs::path(VISTREAM_SOURCE_DIR) / "deploy";
  EXPECT_EQ(ReadFile(prefix_ / "etc/vistream/server.toml"), ReadFile(deploy / "server.toml"));
  EXPECT_EQ(ReadFile(prefix_ / "lib/systemd/system/vistream-server.service"), ReadFile(deploy / "vistream-server.service"));
  // The installed page is the built one.
  EXPECT_EQ(ReadFile(prefix_ / "share/vistream/web/index.html"), ReadFile(fs::path(VISTREAM_BUILD_DIR) / "web" / "index.html"));
  // The installed monaco reads the extract installed beside the catalog.
  const std::string monaco = ReadFile(prefix_ / "share/vistream/scenes/monaco.json");
  EXPECT_NE(monaco.find(R"("osm": "../data/osm/monaco.osm.pbf")"), std::string::npos) << monaco;
}

TEST_F(Package, DebIsNamedForTheVersionAndHoldsTheSameTreeUnderUsrAndEtc) {
  const RunResult list = Shell("dpkg-deb -c " + Quote(deb_));
  ASSERT_EQ(list.exit_code, 0) << list.out;
  std::printf("%s (%ju bytes):\n%s", deb_.filename().c_str(), static_cast<uintmax_t>(fs::file_size(deb_)),
              list.out.c_str());
  // "-rw-r--r-- root/root  1234 2026-12-03 15:55 ./usr/share/doc/vistream/README.md"
  std::set<std::string> files;
  std::istringstream lines(list.out);
  for (std::string line; std::getline(lines, line);) {
    EXPECT_NE(line.find(" root/root "), std::string::npos) << line;
    const size_t at = line.find(" ./");
    ASSERT_NE(at, std::string::npos) << line;
    if (line[0] != 'd') files.insert(line.substr(at + 3));
  }
  std::set<std::string> expected;
  for (const std::string& f : ExpectedTree()) expected.insert(PackagePath(f));
  EXPECT_EQ(files, expected);
  EXPECT_EQ(FilesBelow(root_), expected);
}

TEST_F(Package, DependsAreTheDebianPackagesOfTheLinkedLibrariesAndAdduser) {
  const RunResult depends = Shell("dpkg-deb -f " + Quote(deb_) + " Depends");
  ASSERT_EQ(depends.exit_code, 0) << depends.out;
  std::printf("Depends: %s", depends.out.c_str());
  // "adduser, libabsl20220623 (>= 0~20220623.0-1), libc6 (>= 2.34), ..."
  std::set<std::string> names;
  std::stringstream items(depends.out.substr(0, depends.out.find('\n')));
  for (std::string item; std::getline(items, item, ',');) {
    const size_t start = item.find_first_not_of(' ');
    ASSERT_NE(start, std::string::npos) << depends.out;
    const std::string name = item.substr(start, item.find_first_of(" (|", start) - start);
    names.insert(name);
    EXPECT_FALSE(name.ends_with("-dev")) << name;
    // A real Debian package: the one this machine has installed under that name.
    const RunResult installed = Shell("dpkg-query -W -f='${Status}' " + name);
    EXPECT_NE(installed.out.find("install ok installed"), std::string::npos) << name << ": " << installed.out;
  }
  EXPECT_TRUE(names.contains("adduser")) << depends.out;
  EXPECT_TRUE(names.contains("libc6")) << depends.out;
  EXPECT_NE(depends.out.find("libc6 (>= "), std::string::npos) << "not from dpkg-shlibdeps: " << depends.out;
  for (const char* library : {R"(libgrpc\+\+[0-9.]+)", R"(libprotobuf[0-9]+)", R"(libabsl[0-9]+)", R"(libembree3-3)",
                              R"(libosmesa6)", R"(libglfw3)", R"(libcairo2)"}) {
    const std::regex pattern(library);
    EXPECT_TRUE(std::any_of(names.begin(), names.end(), [&](const std::string& n) { return std::regex_match(n, pattern); }))
        << library << " not in " << depends.out;
  }
}

TEST_F(Package, ConfigurationIsAConffileAndTheMaintainerScriptsAreSound) {
  const RunResult conffiles = Shell("dpkg-deb -I " + Quote(deb_) + " conffiles");
  ASSERT_EQ(conffiles.exit_code, 0) << conffiles.out;
  EXPECT_EQ(conffiles.out, "/etc/vistream/server.toml\n");
  const fs::path control = dir_ / "control";
  const RunResult e = Shell("dpkg-deb -e " + Quote(deb_) + " " + Quote(control));
  ASSERT_EQ(e.exit_code, 0) << e.out;
  for (const char* script : {"postinst", "prerm", "postrm"}) {
    ASSERT_TRUE(fs::exists(control / script)) << script;
    EXPECT_NE(fs::status(control / script).permissions() & fs::perms::owner_exec, fs::perms::none) << script;
    const RunResult syntax = Shell("sh -n " + Quote(control / script));
    EXPECT_EQ(syntax.exit_code, 0) << script << ": " << syntax.out;
  }
  const std::string postinst = ReadFile(control / "postinst");
  EXPECT_NE(postinst.find("adduser --system"), std::string::npos);
  EXPECT_NE(postinst.find("[ -d /run/systemd/system ]"), std::string::npos) << "systemctl must wait for systemd";
  const RunResult fields = Shell("dpkg-deb -f " + Quote(deb_) + " Package Version Section Maintainer Description");
  ASSERT_EQ(fields.exit_code, 0) << fields.out;
  EXPECT_NE(fields.out.find("Package: vistream\n"), std::string::npos) << fields.out;
  EXPECT_NE(fields.out.find("Version: " VISTREAM_VERSION "\n"), std::string::npos) << fields.out;
}

TEST_F(Package, ProgramsInThePackageAreStripped) {
  for (const char* program : {"vistream", "vistream-server", "vistream-client"}) {
    const fs::path packaged = root_ / "usr/bin" / program;
    const RunResult sections = Shell("readelf -S --wide " + Quote(packaged));
    ASSERT_EQ(sections.exit_code, 0) << sections.out;
    EXPECT_NE(sections.out.find(" .text "), std::string::npos) << program;
    EXPECT_EQ(sections.out.find(".debug_info"), std::string::npos) << program << " keeps its debug information";
    EXPECT_LT(fs::file_size(packaged), fs::file_size(fs::path(VISTREAM_BUILD_DIR) / "bin" / program)) << program;
  }
}

// systemd-analyze verify checks that ExecStart's program exists: the packaged unit is checked
// with its /usr/bin/vistream-server pointed at the packaged program, everything else as shipped.
TEST_F(Package, UnitIsCleanUnderSystemdAnalyzeVerify) {
  const std::string unit = ReadFile(root_ / "lib/systemd/system/vistream-server.service");
  for (const char* line : {"ExecStart=/usr/bin/vistream-server --config /etc/vistream/server.toml\n", "User=vistream\n",
                           "Restart=on-failure\n", "KillSignal=SIGTERM\n", "ExecReload=/bin/kill -HUP $MAINPID\n",
                           "NoNewPrivileges=yes\n", "ProtectSystem=strict\n", "WantedBy=multi-user.target\n"}) {
    EXPECT_NE(unit.find(line), std::string::npos) << "no " << line;
  }
  // systemd waits longer than the configured drain and grace before it kills a draining server.
  std::smatch timeout, grace, drain;
  const std::string toml = ReadFile(root_ / "etc/vistream/server.toml");
  ASSERT_TRUE(std::regex_search(unit, timeout, std::regex(R"(\nTimeoutStopSec=([0-9]+)s\n)")));
  ASSERT_TRUE(std::regex_search(toml, grace, std::regex(R"(\ngrace_s = ([0-9.]+)\n)")));
  ASSERT_TRUE(std::regex_search(toml, drain, std::regex(R"(\ndrain_s = ([0-9.]+)\n)")));
  EXPECT_GE(std::stod(timeout[1]), std::stod(drain[1]) + std::stod(grace[1]) + 5)
      << "TimeoutStopSec " << timeout[1] << ", drain_s " << drain[1] << ", grace_s " << grace[1];

  const fs::path verify = dir_ / "verify";
  fs::create_directories(verify);
  const auto checked = [&](const std::string& server) {
    std::string copy = unit;
    copy.replace(copy.find("/usr/bin/vistream-server"), std::string("/usr/bin/vistream-server").size(), server);
    WriteFile(verify / "vistream-server.service", copy);
    return Shell("systemd-analyze verify " + Quote(verify / "vistream-server.service"));
  };
  const RunResult clean = checked((root_ / "usr/bin/vistream-server").string());
  EXPECT_EQ(clean.exit_code, 0) << clean.out;
  EXPECT_EQ(clean.out, "") << "warnings";
  // The check is real: a program that is not there fails it.
  const RunResult missing = checked((root_ / "usr/bin/no-such-server").string());
  EXPECT_NE(missing.exit_code, 0) << missing.out;
  EXPECT_NE(missing.out.find("no-such-server"), std::string::npos) << missing.out;
}

// The installed programs read the catalog installed beside them (../share/vistream/scenes),
// not the source tree's they were built from: an entry only the installed catalog has is found.
TEST_F(Package, InstalledProgramsReadTheInstalledCatalog) {
  WriteFile(root_ / "usr/share/vistream/scenes/only-installed.json",
            R"({"name": "only-installed", "source": {"generator": "streets", "seed": 3},
                "viewcell": {"size_m": 16, "height_m": 2}})");
  const std::string vistream = "env -u VISTREAM_SCENES " + Quote(root_ / "usr/bin/vistream");
  const RunResult only = Shell(vistream + " scene info only-installed --json");
  EXPECT_EQ(only.exit_code, 0) << only.out;
  EXPECT_NE(only.out.find(R"("name": "only-installed")"), std::string::npos) << only.out;
  fs::remove(root_ / "usr/share/vistream/scenes/only-installed.json");
  // monaco, whose OpenStreetMap extract the package carries.
  const RunResult monaco = Shell(vistream + " scene info monaco --json");
  EXPECT_EQ(monaco.exit_code, 0) << monaco.out;
  EXPECT_NE(monaco.out.find(R"("name": "monaco")"), std::string::npos) << monaco.out;
}

// The installed server, from the installed example configuration (a copy whose metrics port is
// a free one; the service's port from --listen, which overrides the key): ready, healthy over
// gRPC and HTTP, metrics, and exit 0 on SIGTERM.
TEST_F(Package, InstalledServerStartsFromTheExampleConfigurationAndAnswersHealth) {
  const int metrics_port = ::vistream::test::FreeLoopbackPort();
  ASSERT_GT(metrics_port, 0);
  std::string config = ReadFile(prefix_ / "etc/vistream/server.toml");
  const std::string metrics_listen = "[metrics]\n";
  const size_t table = config.find(metrics_listen);
  ASSERT_NE(table, std::string::npos) << config;
  const size_t key = config.find("\nlisten = \"127.0.0.1:9464\"\n", table);
  ASSERT_NE(key, std::string::npos) << config;
  config.replace(key, std::string("\nlisten = \"127.0.0.1:9464\"\n").size(),
                 "\nlisten = \"127.0.0.1:" + std::to_string(metrics_port) + "\"\n");
  const fs::path config_path = dir_ / "server.toml";
  WriteFile(config_path, config);
  const fs::path log_path = dir_ / "server.log";
  const std::string server = (prefix_ / "bin/vistream-server").string();

  int out[2];
  ASSERT_EQ(pipe(out), 0);
  const Clock::time_point start = Clock::now();
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    dup2(out[1], STDOUT_FILENO);
    close(out[0]);
    std::FILE* log = std::fopen(log_path.c_str(), "w");
    if (log != nullptr) dup2(fileno(log), STDERR_FILENO);
    unsetenv("VISTREAM_SCENES");
    execl(server.c_str(), server.c_str(), "--config", config_path.c_str(), "--listen", "127.0.0.1:0",
          static_cast<char*>(nullptr));
    _exit(127);
  }
  close(out[1]);
  struct Reap {  // never leave the server running, whatever fails below
    pid_t pid;
    bool waited = false;
    ~Reap() {
      if (!waited) {
        kill(pid, SIGKILL);
        waitpid(pid, nullptr, 0);
      }
    }
  } reap{pid};

  // "vistream-server: ready on 127.0.0.1:PORT: ..." within two minutes.
  std::string output, address;
  const std::regex ready(R"(vistream-server: ready on ([0-9.]+:[0-9]+))");
  while (address.empty() && SecondsSince(start) < 120) {
    pollfd p{out[0], POLLIN, 0};
    if (poll(&p, 1, 1000) <= 0) continue;
    char buf[1024];
    const ssize_t n = read(out[0], buf, sizeof(buf));
    if (n <= 0) break;  // the server ended
    output.append(buf, static_cast<size_t>(n));
    std::smatch m;
    if (std::regex_search(output, m, ready)) address = m[1];
  }
  close(out[0]);
  ASSERT_FALSE(address.empty()) << "not ready; stdout:\n" << output << "\nlog:\n" << ReadFile(log_path);
  std::printf("the installed server was ready in %.1f s: %s", SecondsSince(start), output.c_str());

  EXPECT_EQ(::vistream::test::GrpcHealth(address), "SERVING");
  const auto [healthz_status, healthz] = ::vistream::test::HttpGet(metrics_port, "/healthz");
  EXPECT_EQ(healthz_status, 200) << healthz;
  const auto [metrics_status, metrics] = ::vistream::test::HttpGet(metrics_port, "/metrics");
  EXPECT_EQ(metrics_status, 200) << metrics;
  EXPECT_NE(metrics.find("vistream_sessions_active"), std::string::npos) << metrics;

  ASSERT_EQ(kill(pid, SIGTERM), 0);
  int status = 0;
  const Clock::time_point stop = Clock::now();
  while (SecondsSince(stop) < 30) {
    if (waitpid(pid, &status, WNOHANG) == pid) {
      reap.waited = true;
      break;
    }
    usleep(100 * 1000);
  }
  ASSERT_TRUE(reap.waited) << "still running 30 s after SIGTERM";
  EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << "status " << status << "\n" << ReadFile(log_path);
}

}  // namespace
}  // namespace vistream
