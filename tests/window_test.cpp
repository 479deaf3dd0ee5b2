// The client's window as people use it: under a real X server (Xvfb, Debian) with real key
// presses (xdotool, Debian), against a real server on loopback. F1 and M change what is drawn
// where the panels sit, F12 writes a PNG, P then Enter follows a walk and space pauses it, a
// resize and F11 keep drawing at the new size, the overlay's numbers equal the --json summary.
// And the headless front end's --overlay, its screenshot on SIGUSR1, multisampling and fog.
#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "client/overlay.h"
#include "client/png_image.h"
#include "client/renderer.h"
#include "gl/gl_context.h"
#include "server/served_scene.h"
#include "server/service.h"
#include "tests/temp_dir.h"

namespace vistream::client {
namespace {

namespace fs = std::filesystem;

// The default scene, served by every test here.
server::ServedScene& Default() {
  static server::ServedScene* scene = [] {
    server::ServedSceneOptions o;
    o.scene = "default";
    o.threads = 2;
    absl::StatusOr<std::unique_ptr<server::ServedScene>> s = server::ServedScene::Create(o);
    EXPECT_TRUE(s.ok()) << s.status();
    return s->release();
  }();
  return *scene;
}

std::unique_ptr<server::WalkthroughServer> StartServer() {
  server::ServerOptions o;
  o.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<server::WalkthroughServer>> s = server::WalkthroughServer::Start(&Default(), o, nullptr);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

std::string TempDir(const std::string& name) {
  const fs::path p = fs::path(vistream::testing::ProcessTempDir()) / name;
  fs::remove_all(p);
  fs::create_directories(p);
  return p.string();
}

void Sleep(double s) { std::this_thread::sleep_for(std::chrono::duration<double>(s)); }

// A child process with its own environment additions, working folder and output files; killed
// (and reaped) if still running when it goes.
class Child {
 public:
  Child(const std::vector<std::string>& argv, const std::map<std::string, std::string>& env, const std::string& cwd,
        const std::string& out_path, const std::string& err_path) {
    pid_ = fork();
    if (pid_ == 0) {
      for (const auto& [k, v] : env) setenv(k.c_str(), v.c_str(), 1);
      if (!cwd.empty() && chdir(cwd.c_str()) != 0) _exit(126);
      if (const int fd = open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644); fd >= 0) dup2(fd, STDOUT_FILENO);
      if (const int fd = open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644); fd >= 0) dup2(fd, STDERR_FILENO);
      std::vector<char*> args;
      for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
      args.push_back(nullptr);
      execvp(args[0], args.data());
      _exit(127);
    }
  }
  ~Child() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;

  bool Running() {
    if (pid_ <= 0) return false;
    int status = 0;
    if (waitpid(pid_, &status, WNOHANG) == pid_) {
      pid_ = -1;
      code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      return false;
    }
    return true;
  }
  void Signal(int sig) {
    if (pid_ > 0) kill(pid_, sig);
  }
  // The exit code (128 + N for signal N), -1 if it had not ended within `timeout_s` (then killed).
  int Wait(double timeout_s) {
    for (const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
         std::chrono::steady_clock::now() < end;) {
      if (!Running()) return code_;
      Sleep(0.05);
    }
    Signal(SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
    return -1;
  }

 private:
  pid_t pid_ = -1;
  int code_ = -1;
};

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A bare X server (no window manager) on a free display number, 1280x1024.
class Xvfb {
 public:
  static constexpr int kWidth = 1280, kHeight = 1024;
  Xvfb() {
    int fds[2];
    if (pipe(fds) != 0) return;
    pid_ = fork();
    if (pid_ == 0) {
      close(fds[0]);
      if (const int null = open("/dev/null", O_WRONLY); null >= 0) dup2(null, STDERR_FILENO);
      const std::string fd = std::to_string(fds[1]);
      execlp("Xvfb", "Xvfb", "-displayfd", fd.c_str(), "-screen", "0", "1280x1024x24", "-nolisten", "tcp", nullptr);
      _exit(127);
    }
    close(fds[1]);
    std::string number;
    char c = 0;
    while (read(fds[0], &c, 1) == 1 && c != '\n') number.push_back(c);
    close(fds[0]);
    if (!number.empty()) display_ = ":" + number;
  }
  ~Xvfb() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      waitpid(pid_, nullptr, 0);
    }
  }
  const std::string& display() const { return display_; }

  // Runs xdotool with `args` on this display; its output.
  std::string Xdotool(const std::string& args) const {
    const std::string command = "DISPLAY=" + display_ + " timeout 60 xdotool " + args + " 2>&1";
    std::string out;
    if (std::FILE* p = popen(command.c_str(), "r")) {
      char buf[512];
      for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
      pclose(p);
    }
    return out;
  }

 private:
  pid_t pid_ = -1;
  std::string display_;
};

// A windowed client on `x`, its window found and focused, with its files in `dir`.
class WindowClient {
 public:
  WindowClient(const Xvfb& x, const std::string& dir, std::vector<std::string> args) : x_(x), dir_(dir) {
    std::vector<std::string> argv{VISTREAM_CLIENT_BIN, "--frame-log", dir + "/frames.csv", "--screenshots",
                                  dir + "/shots", "--max-fps", "20"};
    argv.insert(argv.end(), args.begin(), args.end());
    child_ = std::make_unique<Child>(argv, std::map<std::string, std::string>{{"DISPLAY", x.display()}}, dir,
                                     dir + "/out.txt", dir + "/err.txt");
    const std::string found = x_.Xdotool("search --sync --name '^vistream'");
    window_ = found.substr(0, found.find('\n'));
    if (!window_.empty()) x_.Xdotool("windowfocus --sync " + window_);
  }
  const std::string& window() const { return window_; }
  Child& child() { return *child_; }
  std::string err() const { return ReadFile(dir_ + "/err.txt"); }
  std::string out() const { return ReadFile(dir_ + "/out.txt"); }

  void Key(const std::string& key) { x_.Xdotool("key --clearmodifiers " + key); }
  // Holds `key` down for `seconds`.
  void Hold(const std::string& key, double seconds) {
    x_.Xdotool("keydown " + key);
    Sleep(seconds);
    x_.Xdotool("keyup " + key);
  }

  // The frame log's rows: (x, y) of each frame drawn, and whether it stalled.
  struct Row {
    double x = 0.0, y = 0.0;
    bool stall = false;
  };
  std::vector<Row> Frames() const {
    std::vector<Row> rows;
    std::istringstream in(ReadFile(dir_ + "/frames.csv"));
    std::string line;
    std::getline(in, line);  // the header
    while (std::getline(in, line)) {
      std::vector<std::string> f;
      std::stringstream ss(line);
      for (std::string cell; std::getline(ss, cell, ',');) f.push_back(cell);
      if (f.size() < 6) continue;  // a line being written
      rows.push_back({std::stod(f[2]), std::stod(f[3]), f[5] == "1"});
    }
    return rows;
  }
  // Waits until `n` frames have been drawn after the first viewcell arrived, none stalled at
  // the end. False after `timeout_s`.
  bool WaitForFrames(size_t n, double timeout_s = 120.0) {
    for (double waited = 0.0; waited < timeout_s; waited += 0.1) {
      const std::vector<Row> rows = Frames();
      if (rows.size() >= n && !rows.back().stall) return true;
      if (!child_->Running()) return false;
      Sleep(0.1);
    }
    return false;
  }
  std::vector<std::string> Shots() const {
    std::vector<std::string> files;
    if (fs::exists(dir_ + "/shots")) {
      for (const auto& e : fs::directory_iterator(dir_ + "/shots")) files.push_back(e.path().string());
    }
    std::sort(files.begin(), files.end());
    return files;
  }
  // Presses F12 and waits for the new PNG; its path, or empty.
  std::string Screenshot() {
    const size_t before = Shots().size();
    Key("F12");
    for (int k = 0; k < 200; ++k) {
      if (Shots().size() > before) {
        Sleep(0.3);  // written whole
        return Shots().back();
      }
      Sleep(0.05);
    }
    return "";
  }

 private:
  const Xvfb& x_;
  std::string dir_;
  std::unique_ptr<Child> child_;
  std::string window_;
};

struct Box {
  int x0, y0, x1, y1;  // pixels, [x0, x1) x [y0, y1)
  bool Contains(int x, int y) const { return x >= x0 && x < x1 && y >= y0 && y < y1; }
};

// Pixels differing by more than 3 in a channel, inside `in` (or anywhere) and outside every box
// of `out`.
size_t Differ(const RgbImage& a, const RgbImage& b, const std::optional<Box>& in, const std::vector<Box>& out = {}) {
  size_t n = 0;
  for (int y = 0; y < std::min(a.height, b.height); ++y) {
    for (int x = 0; x < std::min(a.width, b.width); ++x) {
      if (in.has_value() && !in->Contains(x, y)) continue;
      if (std::any_of(out.begin(), out.end(), [&](const Box& o) { return o.Contains(x, y); })) continue;
      const size_t i = (static_cast<size_t>(y) * a.width + x) * 3, j = (static_cast<size_t>(y) * b.width + x) * 3;
      bool d = false;
      for (int c = 0; c < 3; ++c) d = d || std::abs(int{a.rgb[i + c]} - int{b.rgb[j + c]}) > 3;
      n += d ? 1 : 0;
    }
  }
  return n;
}

// Where the panels sit (client/overlay.h), with room for their auto-sized heights.
Box StatsBox() { return {0, 0, Overlay::kMargin + Overlay::kStatsWidth + 10, 470}; }
Box MinimapBox(int width) { return {width - Overlay::kMinimapPx - Overlay::kMargin - 20, 0, width, 380}; }

constexpr const char* kPose = "509.4,215.9,1.7,80,0";

RgbImage Png(const std::string& path) {
  absl::StatusOr<RgbImage> im = ReadPng(path);
  EXPECT_TRUE(im.ok()) << path << ": " << im.status();
  return im.ok() ? *im : RgbImage{};
}

// A headless screenshot at kPose: the client's last frame of 10; `summary`, if given, gets its
// --json summary.
RgbImage HeadlessShot(const std::string& address, const std::string& dir, const std::vector<std::string>& more,
                      nlohmann::json* summary = nullptr) {
  std::vector<std::string> argv{VISTREAM_CLIENT_BIN, "--headless", "--server", address, "--pose", kPose,
                                "--frames", "10", "--screenshots", dir, "--json"};
  argv.insert(argv.end(), more.begin(), more.end());
  Child c(argv, {}, dir, dir + "/out.txt", dir + "/err.txt");
  EXPECT_EQ(c.Wait(120.0), 0) << ReadFile(dir + "/err.txt");
  if (summary != nullptr) *summary = nlohmann::json::parse(ReadFile(dir + "/out.txt"));
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(dir)) {
    if (e.path().extension() == ".png") files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  EXPECT_FALSE(files.empty()) << ReadFile(dir + "/err.txt");
  return files.empty() ? RgbImage{} : Png(files.back());
}

class WindowTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server_ = StartServer();
    ASSERT_NE(server_, nullptr);
    address_ = "127.0.0.1:" + std::to_string(server_->port());
    x_ = std::make_unique<Xvfb>();
    ASSERT_FALSE(x_->display().empty()) << "Xvfb did not start (./vistream.sh installs it: xvfb)";
    ASSERT_NE(x_->Xdotool("version").find("xdotool"), std::string::npos)
        << "xdotool is missing (./vistream.sh installs it)";
  }
  std::unique_ptr<server::WalkthroughServer> server_;
  std::string address_;
  std::unique_ptr<Xvfb> x_;
};

TEST_F(WindowTest, F1AndMHideThePanelsWhereTheySitAndF12WritesWhatIsOnScreen) {
  const std::string dir = TempDir("panels");
  WindowClient c(*x_, dir, {"--server", address_, "--pose", kPose, "--size", "960x540", "--msaa", "0"});
  ASSERT_FALSE(c.window().empty()) << c.err();
  ASSERT_TRUE(c.WaitForFrames(20)) << c.err();
  Sleep(1.0);  // the neighbours' cells arrive: the minimap settles
  const std::string both = c.Screenshot();
  ASSERT_FALSE(both.empty()) << "F12 wrote no PNG: " << c.err();
  c.Key("F1");
  const std::string map_only = c.Screenshot();
  c.Key("m");
  const std::string none = c.Screenshot();
  ASSERT_FALSE(none.empty()) << c.err();
  c.Key("q");
  EXPECT_EQ(c.child().Wait(30.0), 0) << c.err();

  const RgbImage a = Png(both), b = Png(map_only), n = Png(none);
  ASSERT_EQ(a.width, 960);
  ASSERT_EQ(a.height, 540);
  const Box stats = StatsBox(), map = MinimapBox(960);
  // F1: the statistics panel goes, the rest stays.
  EXPECT_GT(Differ(a, b, stats), 5000u);
  EXPECT_LE(Differ(a, b, std::nullopt, {stats, map}), 50u);
  // M: the minimap goes, the rest stays.
  EXPECT_GT(Differ(b, n, map), 5000u);
  EXPECT_LE(Differ(b, n, std::nullopt, {map}), 50u);
  // With both off the window shows what the client showed before the overlay: the headless
  // frame at the same pose, pixel for pixel.
  const RgbImage h = HeadlessShot(address_, TempDir("panels-headless"), {"--size", "960x540"});
  EXPECT_LE(Differ(n, h, std::nullopt), static_cast<size_t>(960 * 540 / 1000));
}

TEST_F(WindowTest, PThenEnterFollowsAWalkAndSpacePausesIt) {
  const std::string dir = TempDir("walk");
  WindowClient c(*x_, dir, {"--server", address_, "--size", "640x360", "--overlay-dump", dir + "/overlay.txt"});
  ASSERT_FALSE(c.window().empty()) << c.err();
  ASSERT_TRUE(c.WaitForFrames(10)) << c.err();
  auto at = [&] {
    const auto rows = c.Frames();
    return rows.empty() ? glm::dvec2(0.0) : glm::dvec2(rows.back().x, rows.back().y);
  };
  const glm::dvec2 standing = at();
  Sleep(1.0);
  EXPECT_LT(glm::length(at() - standing), 0.01) << "it moved before P";
  c.Key("p");
  // The walk list takes only its own keys: F12 still writes a screenshot.
  EXPECT_FALSE(c.Screenshot().empty()) << "F12 with the walk list open: " << c.err();
  c.Key("Return");
  Sleep(3.0);
  const glm::dvec2 walking = at();
  EXPECT_GT(glm::length(walking - standing), 1.0) << c.err();
  EXPECT_NE(c.err().find("following the walk"), std::string::npos) << c.err();
  c.Key("space");
  Sleep(0.5);
  const glm::dvec2 paused = at();
  Sleep(2.0);
  EXPECT_LT(glm::length(at() - paused), 0.01) << "space did not pause the walk";
  c.Key("space");
  Sleep(2.0);
  EXPECT_GT(glm::length(at() - paused), 1.0) << "space did not resume the walk";
  c.Key("KP_Add");  // once: 1.25 times the walk's 6 km/h
  c.Key("a");       // a step aside leaves the walk: the eye stays where it is
  Sleep(0.5);
  const glm::dvec2 left = at();
  Sleep(1.5);
  EXPECT_LT(glm::length(at() - left), 0.01) << "still following after a movement key";
  EXPECT_NE(c.err().find("left the walk"), std::string::npos) << c.err();
  // Free walking: W held for 1.5 s at 7.5 km/h (2.1 m/s) walks about 3 m.
  c.Hold("w", 1.5);
  Sleep(0.5);
  const double walked = glm::length(at() - left);
  EXPECT_GT(walked, 1.5) << "W held for 1.5 s";
  EXPECT_LT(walked, 6.0) << "W held for 1.5 s";
  // A quick click (within a frame) on the city starts mouse look: Esc then frees the mouse and
  // the window stays open. (The panels off: at 640 x 360 they cover most of it.)
  c.Key("F1");
  c.Key("m");
  Sleep(0.3);
  x_->Xdotool("mousemove --window " + c.window() + " 320 300 click 1");
  Sleep(0.5);
  c.Key("Escape");
  Sleep(0.5);
  EXPECT_TRUE(c.child().Running()) << "Esc after a click closed the window: the click was missed";
  const size_t shots = c.Shots().size();
  c.Key("q");
  EXPECT_EQ(c.child().Wait(30.0), 0) << c.err();
  EXPECT_EQ(c.Shots().size(), shots + 1) << "Q: --screenshots takes the last frame";
  const std::string dump = ReadFile(dir + "/overlay.txt");
  EXPECT_NE(dump.find("free walking at 7.5 km/h"), std::string::npos) << dump;
}

TEST_F(WindowTest, AResizeAndF11KeepDrawingAtTheNewSize) {
  const std::string dir = TempDir("resize");
  WindowClient c(*x_, dir, {"--server", address_, "--pose", kPose, "--size", "640x360"});
  ASSERT_FALSE(c.window().empty()) << c.err();
  ASSERT_TRUE(c.WaitForFrames(10)) << c.err();
  auto city = [](const RgbImage& im) {
    size_t n = 0;
    const std::array<uint8_t, 3> sky = Renderer::SkyRgb(), ground = Renderer::GroundRgb();
    for (size_t i = 0; i + 2 < im.rgb.size(); i += 3) {
      auto near = [&](const std::array<uint8_t, 3>& c2) {
        return std::abs(int{im.rgb[i]} - c2[0]) <= 6 && std::abs(int{im.rgb[i + 1]} - c2[1]) <= 6 &&
               std::abs(int{im.rgb[i + 2]} - c2[2]) <= 6;
      };
      n += !near(sky) && !near(ground) ? 1 : 0;
    }
    return n;
  };
  x_->Xdotool("windowsize --sync " + c.window() + " 800 500");
  Sleep(1.0);
  const RgbImage resized = Png(c.Screenshot());
  EXPECT_EQ(resized.width, 800);
  EXPECT_EQ(resized.height, 500);
  EXPECT_GT(city(resized), static_cast<size_t>(800 * 500 / 20)) << "no city drawn after the resize";
  c.Key("F11");
  Sleep(1.5);
  const RgbImage full = Png(c.Screenshot());
  EXPECT_EQ(full.width, Xvfb::kWidth);
  EXPECT_EQ(full.height, Xvfb::kHeight);
  EXPECT_GT(city(full), static_cast<size_t>(Xvfb::kWidth * Xvfb::kHeight / 20)) << "no city drawn full screen";
  c.Key("F11");
  Sleep(1.5);
  const RgbImage back = Png(c.Screenshot());
  EXPECT_EQ(back.width, 800);
  EXPECT_EQ(back.height, 500);
  c.Key("q");
  EXPECT_EQ(c.child().Wait(30.0), 0) << c.err();
}

// "frames N, stalls S (...), holes H" and "masked frames M (...), masks K" from the dump.
void ExpectOverlayEqualsSummary(const std::string& dump, const std::string& json_text) {
  ASSERT_FALSE(dump.empty());
  const nlohmann::json j = nlohmann::json::parse(json_text.substr(json_text.find('{')));
  std::smatch m;
  ASSERT_TRUE(std::regex_search(dump, m, std::regex(R"(frames (\d+), stalls (\d+) \(.*\), holes (\d+))"))) << dump;
  EXPECT_EQ(std::stoull(m[1]), j["frames"].get<uint64_t>()) << dump;
  EXPECT_EQ(std::stoull(m[2]), j["stalls"].get<uint64_t>()) << dump;
  EXPECT_EQ(std::stoull(m[3]), j["hole_frames"].get<uint64_t>()) << dump;
  ASSERT_TRUE(std::regex_search(dump, m, std::regex(R"(masked frames (\d+) \(.*\), masks (\d+))"))) << dump;
  EXPECT_EQ(std::stoull(m[1]), j["frames_masked"].get<uint64_t>()) << dump;
  EXPECT_EQ(std::stoull(m[2]), j["masks_received"].get<uint64_t>()) << dump;
  EXPECT_NE(dump.find("scene " + j["scene"].get<std::string>() + " on " + j["server"].get<std::string>()),
            std::string::npos)
      << dump;
  EXPECT_NE(dump.find("walk '" + j["path"].get<std::string>() + "'"), std::string::npos) << dump;
}

TEST_F(WindowTest, TheOverlaysNumbersEqualTheJsonSummaryAtTheEnd) {
  const std::string dir = TempDir("numbers");
  WindowClient c(*x_, dir, {"--server", address_, "--path", "avenue-and-back-streets", "--seconds", "6", "--json",
                            "--overlay-dump", dir + "/overlay.txt", "--size", "640x360", "--verify"});
  ASSERT_FALSE(c.window().empty()) << c.err();
  ASSERT_EQ(c.child().Wait(180.0), 0) << c.err();
  ExpectOverlayEqualsSummary(ReadFile(dir + "/overlay.txt"), c.out());
  // Multisampling (on by default in the window) leaves the object-id check at 0.
  const nlohmann::json j = nlohmann::json::parse(c.out().substr(c.out().find('{')));
  EXPECT_EQ(j["pixel_error"].get<uint64_t>(), 0u);
  EXPECT_GT(j["checked_frames"].get<uint64_t>(), 0u);
}

TEST(WindowOptions, BadOverlayAndPictureOptionsExitTwoNamingTheOption) {
  const std::string dir = TempDir("options");
  struct Case {
    std::vector<std::string> args;
    std::string says;
  };
  const Case cases[] = {
      {{"--msaa", "99"}, "--msaa"},
      {{"--msaa", "-1"}, "--msaa"},
      {{"--overlay", "--no-overlay"}, "--overlay: cannot be given with --no-overlay"},
      {{"--headless", "--overlay-dump", dir + "/o.txt"}, "--overlay-dump: headless, needs --overlay"},
      {{"--catalog", dir + "/nowhere"}, "--catalog: '" + dir + "/nowhere': no such folder"},
  };
  for (const Case& c : cases) {
    std::vector<std::string> argv{VISTREAM_CLIENT_BIN, "--server", "127.0.0.1:1"};
    argv.insert(argv.end(), c.args.begin(), c.args.end());
    Child child(argv, {}, dir, dir + "/out.txt", dir + "/err.txt");
    EXPECT_EQ(child.Wait(30.0), 2) << c.says;
    EXPECT_NE(ReadFile(dir + "/err.txt").find(c.says), std::string::npos) << ReadFile(dir + "/err.txt");
  }
}

// ---- the headless front end ----

TEST(HeadlessOverlay, DrawsThePanelsWhereTheySitAndNothingElseChanges) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string address = "127.0.0.1:" + std::to_string(server->port());
  const RgbImage plain = HeadlessShot(address, TempDir("plain"), {"--size", "1280x720"});
  const RgbImage with = HeadlessShot(address, TempDir("with"), {"--size", "1280x720", "--overlay"});
  ASSERT_EQ(plain.width, 1280);
  ASSERT_EQ(with.width, 1280);
  const Box stats = StatsBox(), map = MinimapBox(1280);
  EXPECT_GT(Differ(plain, with, stats), 10000u);
  EXPECT_GT(Differ(plain, with, map), 10000u);
  EXPECT_EQ(Differ(plain, with, std::nullopt, {stats, map}), 0u);
}

// Frames of the overlay in process (OSMesa): an empty city's frame, the panels over it.
class OverlayFrames {
 public:
  explicit OverlayFrames(int samples, int width = 800, int height = 600) : w_(width), h_(height) {
    absl::StatusOr<std::unique_ptr<gl::GlContext>> c = gl::GlContext::CreateOffscreen();
    EXPECT_TRUE(c.ok()) << c.status();
    if (!c.ok()) return;
    context_ = std::move(*c);
    absl::StatusOr<std::unique_ptr<Renderer>> r = Renderer::Create(context_.get(), w_, h_, true, samples);
    EXPECT_TRUE(r.ok()) << r.status();
    absl::StatusOr<std::unique_ptr<Overlay>> o = Overlay::Create(context_.get(), nullptr);
    EXPECT_TRUE(o.ok()) << o.status();
    if (!r.ok() || !o.ok()) return;
    renderer_ = std::move(*r);
    overlay_ = std::move(*o);
    camera_.width = w_;
    camera_.height = h_;
  }
  bool ok() const { return overlay_ != nullptr; }
  Overlay& overlay() { return *overlay_; }
  // One frame with `status`, `dt_s` after the last, the panels over the resolved frame (as the
  // client draws) or, `!resolve_first`, into the multisample one; its picture.
  RgbImage Frame(const OverlayStatus& status, double dt_s, bool resolve_first = true, const MinimapView& map = {}) {
    renderer_->Draw(store_, camera_, {}, nullptr, ++frame_, nullptr);
    if (resolve_first) renderer_->Resolve();
    absl::StatusOr<OverlayRequest> req = overlay_->Frame(status, map, {}, w_, h_, dt_s);
    EXPECT_TRUE(req.ok()) << req.status();
    absl::StatusOr<std::vector<uint8_t>> rgb = renderer_->ReadRgb();
    EXPECT_TRUE(rgb.ok()) << rgb.status();
    return RgbImage{w_, h_, rgb.ok() ? *rgb : std::vector<uint8_t>{}};
  }

 private:
  int w_, h_;
  std::unique_ptr<gl::GlContext> context_;
  std::unique_ptr<Renderer> renderer_;
  std::unique_ptr<Overlay> overlay_;
  ObjectStore store_{0};
  Camera camera_;
  uint64_t frame_ = 0;
};

// The first frame of a new 800 x 600 overlay with `samples`; empty when the context failed.
RgbImage OneFrame(int samples, const OverlayStatus& s, bool resolve_first, const MinimapView& map) {
  OverlayFrames f(samples);
  return f.ok() ? f.Frame(s, 0.0, resolve_first, map) : RgbImage{};
}

TEST(HeadlessOverlay, BetweenBuildsAFrameCopiesThePanelsAsBuiltAndAKeyOrTheClockRebuildsThem) {
  OverlayFrames f(0);
  ASSERT_TRUE(f.ok());
  OverlayStatus a;
  a.server = "127.0.0.1:1";
  a.scene = "default";
  a.frames = 10;
  OverlayStatus b = a;
  b.frames = 987654;
  b.stalls = 321;
  const RgbImage built = f.Frame(a, 0.0);
  const Box stats = StatsBox(), map = MinimapBox(800);
  // Within kRebuildS the panels are the ones built (their lines are this frame's)...
  const RgbImage copied = f.Frame(b, 0.25 * Overlay::kRebuildS);
  EXPECT_EQ(Differ(built, copied, std::nullopt), 0u);
  EXPECT_NE(f.overlay().last_lines(), OverlayLines(a, 0.0, 0.0, 0.0));
  // ...a key (Invalidate) rebuilds them with the new numbers, only where the statistics sit...
  f.overlay().Invalidate();
  const RgbImage keyed = f.Frame(b, 0.25 * Overlay::kRebuildS);
  EXPECT_GT(Differ(built, keyed, stats), 50u);
  EXPECT_EQ(Differ(built, keyed, std::nullopt, {stats}), 0u);
  // ...and so does the clock, kRebuildS after the last build.
  const RgbImage before = f.Frame(a, 0.5 * Overlay::kRebuildS);
  EXPECT_EQ(Differ(keyed, before, std::nullopt), 0u);
  const RgbImage after = f.Frame(a, 0.6 * Overlay::kRebuildS);
  EXPECT_EQ(Differ(built, after, std::nullopt), 0u);
  // Hiding a panel is seen at once; nothing outside the panels ever changed.
  f.overlay().show_minimap = false;
  const RgbImage hidden = f.Frame(a, 0.0);
  EXPECT_GT(Differ(after, hidden, map), 10000u);
  EXPECT_EQ(Differ(after, hidden, std::nullopt, {map}), 0u);
}

TEST(HeadlessOverlay, AMultisampleFrameGetsThePanelsAsASingleSampleOne) {
  // Copied (a single-sample frame) or drawn (into a multisample one, left unresolved): the
  // same panels. ImGui's shapes are pixel-aligned but for the graph's lines and the minimap's
  // eye and north arrow, whose edges multisampling smooths: under 1% of a panel's pixels.
  OverlayStatus s;
  s.server = "127.0.0.1:1";
  s.scene = "default";
  s.frames = 10;
  const RgbImage copied = OneFrame(0, s, true, {});
  const RgbImage drawn = OneFrame(4, s, false, {});
  ASSERT_FALSE(copied.rgb.empty());
  ASSERT_EQ(drawn.rgb.size(), copied.rgb.size());
  const Box stats = StatsBox(), map = MinimapBox(800);
  EXPECT_LT(Differ(copied, drawn, stats), 2000u);
  EXPECT_LT(Differ(copied, drawn, map), 1100u);
  EXPECT_EQ(Differ(copied, drawn, std::nullopt, {stats, map}), 0u);
}

TEST(HeadlessOverlay, InAFrameTooNarrowForBothPanelsTheMinimapShrinksBesideTheStatistics) {
  OverlayStatus s;
  s.server = "127.0.0.1:1";
  s.scene = "default";
  for (const auto& [w, h] : {std::pair{640, 360}, std::pair{1280, 720}}) {
    OverlayFrames f(0, w, h);
    ASSERT_TRUE(f.ok());
    const RgbImage im = f.Frame(s, 0.0);
    // Sky just right of the statistics panel, at the minimap's height: the two do not touch.
    const int x = Overlay::kMargin + Overlay::kStatsWidth + 3, y = 3 * Overlay::kMargin;
    const size_t i = (static_cast<size_t>(y) * w + x) * 3;
    ASSERT_LT(i + 2, im.rgb.size());
    const std::array<uint8_t, 3> sky = Renderer::SkyRgb();
    EXPECT_EQ((std::array<uint8_t, 3>{im.rgb[i], im.rgb[i + 1], im.rgb[i + 2]}), sky) << w << "x" << h;
    // And the minimap is there: its panel at the right edge.
    const size_t j = (static_cast<size_t>(y) * w + (w - Overlay::kMargin - 5)) * 3;
    EXPECT_NE((std::array<uint8_t, 3>{im.rgb[j], im.rgb[j + 1], im.rgb[j + 2]}), sky) << w << "x" << h;
  }
}

TEST(HeadlessOverlay, AWalkRunningPastTheMinimapIsClippedToIt) {
  OverlayStatus s;
  s.server = "127.0.0.1:1";
  s.scene = "default";
  s.eye = {500.0, 200.0, 1.7};
  const RgbImage without = OneFrame(0, s, true, {});
  MinimapView map;
  map.walk = {{-5000.0, 150.0}, {500.0, 200.0}, {600.0, 9000.0}};  // far past the map, west and north
  const RgbImage with = OneFrame(0, s, true, map);
  ASSERT_FALSE(with.rgb.empty());
  ASSERT_EQ(with.rgb.size(), without.rgb.size());
  // The minimap's column (its legend grows by the walk's row): the line clipped to the map
  // leaves everything left of it as it was.
  const Box column{MinimapBox(800).x0, 0, 800, 600};
  EXPECT_GT(Differ(without, with, column), 100u);  // the line on the map
  EXPECT_EQ(Differ(without, with, std::nullopt, {column}), 0u);
}

TEST(HeadlessPicture, MoreSamplesThanTheOpenGLTakesIsAnErrorNamingTheMost) {
  absl::StatusOr<std::unique_ptr<gl::GlContext>> c = gl::GlContext::CreateOffscreen();
  ASSERT_TRUE(c.ok()) << c.status();
  GLint most = 0;
  (*c)->functions().GetIntegerv(GL_MAX_SAMPLES, &most);
  ASSERT_GT(most, 0);
  ASSERT_LT(most, 16) << "this OpenGL takes every sample count --msaa allows";
  absl::StatusOr<std::unique_ptr<Renderer>> r = Renderer::Create(c->get(), 64, 64, true, most + 1);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(r.status().message().find(absl::StrCat("takes at most ", most, " (--msaa)")), std::string::npos)
      << r.status();
  EXPECT_TRUE(Renderer::Create(c->get(), 64, 64, true, most).ok());
}

TEST(HeadlessOverlay, ItsNumbersEqualTheJsonSummary) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string dir = TempDir("headless-numbers");
  Child c({VISTREAM_CLIENT_BIN, "--headless", "--server", "127.0.0.1:" + std::to_string(server->port()), "--seconds",
           "5", "--overlay", "--overlay-dump", dir + "/overlay.txt", "--json", "--size", "320x180", "--max-fps", "20"},
          {}, dir, dir + "/out.txt", dir + "/err.txt");
  ASSERT_EQ(c.Wait(180.0), 0) << ReadFile(dir + "/err.txt");
  ExpectOverlayEqualsSummary(ReadFile(dir + "/overlay.txt"), ReadFile(dir + "/out.txt"));
}

TEST(HeadlessOverlay, ALostServerShowsReconnectingWithItsBackOff) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string dir = TempDir("lost");
  Child c({VISTREAM_CLIENT_BIN, "--headless", "--server", "127.0.0.1:" + std::to_string(server->port()), "--pose",
           kPose, "--frames", "100000", "--max-fps", "20", "--size", "320x180", "--give-up", "3", "--overlay",
           "--overlay-dump", dir + "/overlay.txt", "--frame-log", dir + "/frames.csv"},
          {}, dir, dir + "/out.txt", dir + "/err.txt");
  for (int k = 0; k < 1200 && ReadFile(dir + "/frames.csv").find("\n5,") == std::string::npos; ++k) Sleep(0.1);
  server.reset();  // stopped: the client reconnects with back-off, then gives up
  EXPECT_EQ(c.Wait(60.0), 1) << ReadFile(dir + "/err.txt");
  const std::string dump = ReadFile(dir + "/overlay.txt");
  EXPECT_NE(dump.find("connection: reconnecting for "), std::string::npos) << dump;
  EXPECT_NE(dump.find(", back-off "), std::string::npos) << dump;
  EXPECT_NE(dump.find("gives up after 3 s"), std::string::npos) << dump;
  EXPECT_NE(ReadFile(dir + "/err.txt").find("no answer for 3 s"), std::string::npos) << ReadFile(dir + "/err.txt");
}

TEST(OverlayLines, SayTheScreenErrorAndWhetherTheServerHasLevels) {
  auto has = [](const std::vector<std::string>& lines, const std::string& text) {
    return std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
  };
  OverlayStatus s;
  EXPECT_TRUE(has(OverlayLines(s, 0.0, 0.0, 0.0), "levels: off (full detail)"));
  s.lod_tau_px = 2.0;
  s.coarse_frames = 3;
  s.level_objects = 40;
  EXPECT_TRUE(has(OverlayLines(s, 0.0, 0.0, 0.0), "levels: tau 2 px, 3 coarse frames, 40 at a level"));
  s.server_without_levels = true;
  EXPECT_TRUE(has(OverlayLines(s, 0.0, 0.0, 0.0), "levels: tau 2 px asked, the server has none (full detail)"));
}

TEST(OverlayLines, SayTheConnectionAndWhatTheFrameDrew) {
  OverlayStatus s;
  s.server = "127.0.0.1:1";
  s.scene = "london";
  s.reconnects = 2;
  auto has = [](const std::vector<std::string>& lines, const std::string& text) {
    return std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
  };
  std::vector<std::string> l = OverlayLines(s, 60.0, 16.7, 2.5e6);
  EXPECT_TRUE(has(l, "scene london on 127.0.0.1:1"));
  EXPECT_TRUE(has(l, "connection: connected (2 reconnects)"));
  EXPECT_TRUE(has(l, "fps 60.0, frame 16.7 ms"));
  EXPECT_TRUE(has(l, "2.50 MB/s"));
  EXPECT_TRUE(has(l, "frame: viewcell PVS"));
  EXPECT_TRUE(has(l, "viewcell: none"));
  EXPECT_TRUE(has(l, "free walking"));
  EXPECT_FALSE(has(l, "starting"));
  s.starting_s = 3.2;
  s.startup_timeout_s = 120.0;
  EXPECT_TRUE(has(OverlayLines(s, 0.0, 0.0, 0.0),
                  "starting: waiting 3 s for the first viewcell's PVS and geometry (120 s at most)"));
  s.starting_s = -1.0;
  s.link = OverlayStatus::Link::kReconnecting;
  s.lost_for_s = 3.3;
  s.backoff_s = 1.0;
  s.give_up_s = 60.0;
  s.hole = true;
  s.cell = 7;
  s.cell_i = 2;
  s.cell_j = 1;
  s.pvs_listed = true;
  s.pvs_objects = 10;
  s.pvs_missing = 3;
  l = OverlayLines(s, 0.0, 0.0, 0.0);
  EXPECT_TRUE(has(l, "connection: reconnecting for 3.3 s, back-off 1.00 s, gives up after 60 s")) << l[1];
  EXPECT_TRUE(has(l, "frame: HOLE"));
  EXPECT_TRUE(has(l, "viewcell 2,1 (id 7): PVS 10 objects, 3 missing"));
  s.link = OverlayStatus::Link::kGivenUp;
  EXPECT_TRUE(has(OverlayLines(s, 0.0, 0.0, 0.0), "connection: given up after 60 s"));
  s.link = OverlayStatus::Link::kLocal;
  EXPECT_TRUE(has(OverlayLines(s, 0.0, 0.0, 0.0), "connection: none"));
  s.hole = false;
  s.masked = true;
  s.mask_id = 12;
  s.mask_box_min = {0.0, 0.0, 0.0};
  s.mask_box_max = {8.0, 6.0, 2.0};
  s.walk = "cross-town";
  s.walk_paused = true;
  s.speed_kmh = 6.0;
  l = OverlayLines(s, 0.0, 0.0, 0.0);
  EXPECT_TRUE(has(l, "frame: masked (eps-mask 12, neighbourhood 8 x 6 m)"));
  EXPECT_TRUE(has(l, "walk 'cross-town'"));
  EXPECT_TRUE(has(l, "PAUSED"));
}

// A headless client standing at kPose until stopped, working in `dir`, once it has drawn two
// frames (its frame log, dir/frames.csv, says so).
std::unique_ptr<Child> StandingHeadless(int port, const std::string& dir) {
  auto c = std::make_unique<Child>(
      std::vector<std::string>{VISTREAM_CLIENT_BIN, "--headless", "--server", "127.0.0.1:" + std::to_string(port),
                               "--pose", kPose, "--frames", "100000", "--max-fps", "10", "--size", "320x180",
                               "--frame-log", dir + "/frames.csv"},
      std::map<std::string, std::string>{}, dir, dir + "/out.txt", dir + "/err.txt");
  for (int k = 0; k < 1200 && ReadFile(dir + "/frames.csv").find("\n2,") == std::string::npos; ++k) Sleep(0.1);
  return c;
}

TEST(HeadlessOverlay, AScreenshotThatCannotBeWrittenIsSaidAndTheWalkGoesOn) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string dir = TempDir("unwritable");
  // A file where the screenshots' folder would be: the folder cannot be made.
  std::ofstream(dir + "/vistream-screenshots") << "not a folder";
  const std::unique_ptr<Child> child = StandingHeadless(server->port(), dir);
  Child& c = *child;
  c.Signal(SIGUSR1);
  for (int k = 0; k < 100 && ReadFile(dir + "/err.txt").find("screenshot failed") == std::string::npos; ++k) Sleep(0.1);
  const std::string before = ReadFile(dir + "/frames.csv");
  const auto frames_then = static_cast<size_t>(std::count(before.begin(), before.end(), '\n'));
  Sleep(1.0);
  EXPECT_TRUE(c.Running()) << ReadFile(dir + "/err.txt");
  const std::string log = ReadFile(dir + "/frames.csv");
  EXPECT_GT(static_cast<size_t>(std::count(log.begin(), log.end(), '\n')), frames_then + 3) << "the walk stopped";
  c.Signal(SIGTERM);
  EXPECT_EQ(c.Wait(60.0), 130) << ReadFile(dir + "/err.txt");
  EXPECT_NE(ReadFile(dir + "/err.txt").find("screenshot failed: " + dir + "/vistream-screenshots: cannot create"),
            std::string::npos)
      << ReadFile(dir + "/err.txt");
}

TEST(HeadlessOverlay, SigUsr1WritesAScreenshotIntoTheWorkingFolder) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string dir = TempDir("usr1");
  const std::unique_ptr<Child> child = StandingHeadless(server->port(), dir);
  Child& c = *child;
  c.Signal(SIGUSR1);
  const fs::path shots = fs::path(dir) / "vistream-screenshots";
  bool written = false;
  for (int k = 0; k < 100 && !written; ++k) {
    Sleep(0.1);
    written = fs::exists(shots) && !fs::is_empty(shots);
  }
  c.Signal(SIGTERM);
  EXPECT_EQ(c.Wait(60.0), 130) << ReadFile(dir + "/err.txt");
  ASSERT_TRUE(written) << ReadFile(dir + "/err.txt");
  const RgbImage im = Png(fs::directory_iterator(shots)->path().string());
  EXPECT_EQ(im.width, 320);
  EXPECT_EQ(im.height, 180);
}

TEST(HeadlessPicture, MultisamplingSmoothsEdgesOnlyAndFogFadesOnlyTheDistance) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string address = "127.0.0.1:" + std::to_string(server->port());
  const RgbImage plain = HeadlessShot(address, TempDir("msaa0"), {"--size", "640x360"});
  nlohmann::json checked;
  const RgbImage msaa =
      HeadlessShot(address, TempDir("msaa4"), {"--size", "640x360", "--msaa", "4", "--verify", "--every", "0.1"}, &checked);
  // The object-id pass has no multisampling: the pixel error stays 0.
  EXPECT_EQ(checked["pixel_error"].get<uint64_t>(), 0u);
  EXPECT_GE(checked["checked_frames"].get<uint64_t>(), 1u);
  // Edges only: some pixels change, most do not.
  const size_t edges = Differ(plain, msaa, std::nullopt);
  EXPECT_GT(edges, 100u);
  EXPECT_LT(edges, static_cast<size_t>(640 * 360 / 10));
  // Fog where the scene's catalog entry declares it (a copy of the catalog, default with fog).
  const std::string catalog = TempDir("fog-catalog");
  nlohmann::json entry = nlohmann::json::parse(ReadFile(std::string(VISTREAM_SOURCE_DIR "/scenes/default.json")));
  entry["effects"] = {{"fog", {{"start_m", 30.0}, {"end_m", 400.0}}}};
  std::ofstream(catalog + "/default.json") << entry.dump(2);
  const RgbImage fog = HeadlessShot(address, TempDir("fog"),
                                    {"--size", "640x360", "--catalog", catalog, "--verify", "--every", "0.1"}, &checked);
  EXPECT_EQ(checked["pixel_error"].get<uint64_t>(), 0u) << "the object-id pass has no fog";
  EXPECT_GE(checked["checked_frames"].get<uint64_t>(), 1u);
  const size_t fogged = Differ(plain, fog, std::nullopt);
  EXPECT_GT(fogged, 1000u) << "the fog changed nothing";
  // Fog goes towards the sky colour: the sky itself does not change, and what changes comes
  // nearer to it.
  const std::array<uint8_t, 3> sky = Renderer::SkyRgb();
  size_t sky_pixels = 0, sky_changed = 0, nearer = 0, changed = 0;
  for (size_t i = 0; i + 2 < plain.rgb.size() && i + 2 < fog.rgb.size(); i += 3) {
    int before = 0, after = 0;
    bool is_sky = true, differs = false;
    for (int c = 0; c < 3; ++c) {
      before += std::abs(int{plain.rgb[i + c]} - sky[c]);
      after += std::abs(int{fog.rgb[i + c]} - sky[c]);
      is_sky = is_sky && plain.rgb[i + c] == sky[c];
      differs = differs || plain.rgb[i + c] != fog.rgb[i + c];
    }
    sky_pixels += is_sky ? 1 : 0;
    sky_changed += is_sky && differs ? 1 : 0;
    changed += differs ? 1 : 0;
    nearer += differs && after < before ? 1 : 0;
  }
  EXPECT_GT(sky_pixels, 1000u);
  EXPECT_EQ(sky_changed, 0u);
  EXPECT_GE(nearer, changed * 99 / 100) << nearer << " of " << changed << " changed pixels came nearer the sky colour";
}

}  // namespace
}  // namespace vistream::client
