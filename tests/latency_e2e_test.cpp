// Real end-to-end runs with time scaled: the vistream-server executable emulating a link
// (--emulate-link --time-scale K) and the headless vistream-client walking a catalog path at
// K times its speed, over loopback. A walk of minutes runs in seconds; every time the client
// reports is real (walk-clock) seconds, K times shorter than the walk's own.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace vistream {
namespace {

// The scale of every run here: the default walk at 6 km/h, 30 times faster (180 km/h), for
// its first 20 s (1 km, ten viewcells of 100 m; 600 s of the walk's own time).
constexpr double kScale = 30.0;
constexpr double kWalkKmh = 6.0;
constexpr double kSeconds = 20.0;

// A vistream-server process on a free loopback port; stopped (SIGTERM, then SIGKILL after 10 s)
// when this goes, whatever failed before.
class ServerProcess {
 public:
  // Starts it with `args` after --listen and waits (up to 120 s) for its ready line.
  static std::unique_ptr<ServerProcess> Start(const std::vector<std::string>& args) {
    int out[2];
    if (pipe(out) != 0) return nullptr;
    std::vector<std::string> all = {VISTREAM_SERVER_BIN, "--listen", "127.0.0.1:0", "--threads", "2"};
    all.insert(all.end(), args.begin(), args.end());
    const pid_t pid = fork();
    if (pid < 0) return nullptr;
    if (pid == 0) {
      dup2(out[1], STDOUT_FILENO);
      close(out[0]);
      std::vector<char*> argv;
      for (std::string& a : all) argv.push_back(a.data());
      argv.push_back(nullptr);
      execv(argv[0], argv.data());
      _exit(127);
    }
    close(out[1]);
    auto s = std::unique_ptr<ServerProcess>(new ServerProcess(pid, fdopen(out[0], "r")));
    char line[2048] = {};
    if (s->out_ == nullptr || std::fgets(line, sizeof(line), s->out_) == nullptr) return s;  // address() empty
    s->ready_ = line;
    const size_t at = s->ready_.find("ready on ");
    if (at != std::string::npos) {
      const size_t colon = s->ready_.find(':', at + 9);
      const size_t end = s->ready_.find(':', colon + 1);
      s->address_ = s->ready_.substr(at + 9, end - at - 9);
    }
    return s;
  }
  ~ServerProcess() {
    kill(pid_, SIGTERM);
    for (int k = 0; k < 1000; ++k) {
      if (waitpid(pid_, nullptr, WNOHANG) == pid_) {
        pid_ = -1;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
    if (out_ != nullptr) std::fclose(out_);
  }
  const std::string& address() const { return address_; }
  const std::string& ready_line() const { return ready_; }

 private:
  ServerProcess(pid_t pid, std::FILE* out) : pid_(pid), out_(out) {}
  pid_t pid_;
  std::FILE* out_;
  std::string ready_, address_;
};

struct CellRow {
  uint32_t cell = 0;
  double entered_s = 0.0, complete_s = 0.0, margin_s = 0.0;
  bool stalled = false;
};

struct ClientRun {
  int rc = -1;
  nlohmann::json summary;
  std::vector<CellRow> cells;  // the cell log, start cell first
  std::string log;             // stderr
};

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("vistream_latency_e2e_" + std::to_string(getpid()) + "_" + name))
      .string();
}

// The headless client along the default walk at kWalkKmh * kScale, for kSeconds.
ClientRun WalkScaled(const std::string& address, const std::string& name) {
  ClientRun r;
  const std::string cells = TempPath(name + ".csv"), err = TempPath(name + ".err");
  std::ostringstream cmd;
  cmd << VISTREAM_CLIENT_BIN << " --headless --server " << address << " --speed " << kWalkKmh * kScale
      << " --seconds " << kSeconds << " --size 320x180 --max-fps 60 --json --cell-log " << cells << " 2>" << err;
  std::FILE* p = popen(cmd.str().c_str(), "r");
  if (p == nullptr) return r;
  std::string out;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
  const int status = pclose(p);
  r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.summary = nlohmann::json::parse(out, nullptr, /*allow_exceptions=*/false);
  std::ifstream e(err);
  r.log.assign(std::istreambuf_iterator<char>(e), std::istreambuf_iterator<char>());
  std::ifstream in(cells);
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    CellRow c;
    int i = 0, j = 0, stalled = 0;
    if (std::sscanf(line.c_str(), "%u,%d,%d,%lf,%lf,%lf,%d", &c.cell, &i, &j, &c.entered_s, &c.complete_s,
                    &c.margin_s, &stalled) == 7) {
      c.stalled = stalled != 0;
      r.cells.push_back(c);
    }
  }
  std::filesystem::remove(cells);
  std::filesystem::remove(err);
  return r;
}

TEST(LatencyE2e, AtWalkingSpeedOnTheDeclaredLinkNoCellStalls) {
  // default declares 20 Mbit/s and 40 ms: at 6 km/h its cells arrive long before the walker.
  auto process = ServerProcess::Start({"--scene", "default", "--emulate-link", "--time-scale", std::to_string(kScale)});
  ASSERT_NE(process, nullptr);
  ASSERT_FALSE(process->address().empty()) << "no ready line: " << process->ready_line();
  EXPECT_NE(process->ready_line().find("emulated link 20 Mbit/s, 40 ms (declared by default), time scale 30"),
            std::string::npos)
      << process->ready_line();
  const ClientRun run = WalkScaled(process->address(), "declared");
  ASSERT_EQ(run.rc, 0) << run.log;
  ASSERT_TRUE(run.summary.is_object()) << run.log;
  std::printf("%s\n", run.summary.dump(2).c_str());
  EXPECT_EQ(run.summary["stalls"], 0) << run.log;
  EXPECT_EQ(run.summary["stalled_cells"], 0) << run.log;
  EXPECT_GE(run.summary["cells_entered"].get<int>(), 8);
  EXPECT_GT(run.summary["min_margin_s"].get<double>(), 0.0);
  ASSERT_EQ(run.cells.size(), run.summary["cells_entered"].get<size_t>() + 1) << "the cell log and the summary";
  for (const CellRow& c : run.cells) {
    EXPECT_FALSE(c.stalled) << "cell " << c.cell;
    EXPECT_NEAR(c.margin_s, c.entered_s - c.complete_s, 1e-3);
  }
}

TEST(LatencyE2e, OnALinkTooSlowForTheWalkCellsStallWithNegativeMargins) {
  // 15 kbit/s: the first cells' geometry (hundreds of kB each crossing) takes longer to send
  // than a walker at 6 km/h takes to cross a 100 m cell; later crossings catch up.
  auto process = ServerProcess::Start(
      {"--scene", "default", "--link", "15k,40", "--time-scale", std::to_string(kScale)});
  ASSERT_NE(process, nullptr);
  ASSERT_FALSE(process->address().empty()) << "no ready line: " << process->ready_line();
  EXPECT_NE(process->ready_line().find("emulated link 15 kbit/s, 40 ms (--link)"), std::string::npos)
      << process->ready_line();
  const ClientRun run = WalkScaled(process->address(), "slow");
  ASSERT_EQ(run.rc, 0) << run.log;
  ASSERT_TRUE(run.summary.is_object()) << run.log;
  std::printf("%s\n", run.summary.dump(2).c_str());
  EXPECT_GT(run.summary["stalls"].get<int>(), 0);
  EXPECT_GE(run.summary["stalled_cells"].get<int>(), 1);
  EXPECT_LT(run.summary["min_margin_s"].get<double>(), 0.0);
  size_t stalled = 0;
  for (size_t k = 1; k < run.cells.size(); ++k) {
    stalled += run.cells[k].stalled ? 1 : 0;
    if (run.cells[k].margin_s < 0.0) {
      EXPECT_TRUE(run.cells[k].stalled) << "cell " << run.cells[k].cell;
    }
  }
  EXPECT_EQ(stalled, run.summary["stalled_cells"].get<size_t>());
}

}  // namespace
}  // namespace vistream
