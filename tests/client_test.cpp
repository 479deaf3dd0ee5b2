// The thin client against a real server on loopback: headless walks of the default scene
// (stalls, pixel error, screenshots), a memory budget, a server restart, the window front end
// under Xvfb, and bad input to the executable. Plus its units: grid lookup, object store, walk.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <algorithm>
#include <future>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <grpcpp/grpcpp.h>

#include "client/cell_margins.h"
#include "client/object_store.h"
#include "proto/scene_info.h"
#include "client/png_image.h"
#include "client/renderer.h"
#include "scenes/walk.h"
#include "client/walkthrough.h"
#include "proto/walkthrough.grpc.pb.h"
#include "scenes/catalog.h"
#include "scenes/gltf_io.h"
#include "scenes/osm_import.h"
#include "server/served_scene.h"
#include "server/service.h"
#include "tests/temp_dir.h"

namespace vistream::client {
namespace {

namespace v1 = vistream::v1;
using server::ServedScene;
using server::WalkthroughServer;

// The default scene as the README's run command serves it, shared by every test.
ServedScene& Default() {
  static ServedScene* scene = [] {
    server::ServedSceneOptions o;
    o.scene = "default";
    o.threads = 2;
    absl::StatusOr<std::unique_ptr<ServedScene>> s = ServedScene::Create(o);
    EXPECT_TRUE(s.ok()) << s.status();
    return s->release();
  }();
  return *scene;
}

std::unique_ptr<WalkthroughServer> StartServer(int port = 0) {
  server::ServerOptions o;
  o.listen = "127.0.0.1:" + std::to_string(port);
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> s = WalkthroughServer::Start(&Default(), o, nullptr);
  EXPECT_TRUE(s.ok()) << s.status();
  return s.ok() ? std::move(*s) : nullptr;
}

std::string Address(const WalkthroughServer& s) { return "127.0.0.1:" + std::to_string(s.port()); }

// A fresh folder in the test process's own temporary folder (removed at exit).
std::string TempDir(const std::string& name) {
  const std::filesystem::path p = std::filesystem::path(vistream::testing::ProcessTempDir()) / name;
  std::filesystem::remove_all(p);
  std::filesystem::create_directories(p);
  return p.string();
}

WalkthroughOptions Headless(const std::string& address) {
  WalkthroughOptions o;
  o.server = address;
  o.headless = true;
  o.width = 320;
  o.height = 180;
  o.max_fps = 30.0;  // leave the 2-core machine to the server
  o.log = [](const std::string& line) { std::printf("client: %s\n", line.c_str()); };
  return o;
}

// For each viewcell the default walk enters: the cell it leaves and the cells within 15 m of the
// point where it crosses (the one it enters, and near a corner those the server cannot tell
// from it yet).
struct Crossing {
  uint32_t from = 0;
  std::set<uint32_t> cells;  // from and the cells it may lead into
};
std::vector<Crossing> CrossingsAlong(const scenes::Walk& walk) {
  std::vector<Crossing> out;
  const visibility::ViewcellGrid& grid = Default().grid();
  std::optional<uint32_t> last;
  for (double t = 0.0; t <= walk.duration_s(); t += 0.25 / walk.speed_mps()) {
    const glm::dvec2 p(walk.At(t).eye);
    const std::optional<uint32_t> c = grid.CellAt(p);
    if (!c.has_value() || c == last) continue;
    if (last.has_value()) {
      std::set<uint32_t> cells{*last};
      for (uint32_t n : grid.Neighbours(*last)) {
        const scenes::Aabb b = grid.CellBox(n);
        const double dx = std::max({0.0, b.min.x - p.x, p.x - b.max.x});
        const double dy = std::max({0.0, b.min.y - p.y, p.y - b.max.y});
        if (std::hypot(dx, dy) <= 15.0) cells.insert(n);
      }
      out.push_back({*last, cells});
    }
    last = c;
  }
  return out;
}

scenes::Walk DefaultWalk(double speed_mps) {
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry("default");
  EXPECT_TRUE(entry.ok()) << entry.status();
  absl::StatusOr<scenes::Walk> w = scenes::Walk::Create(entry->walks.front(), speed_mps);
  EXPECT_TRUE(w.ok()) << w.status();
  return *w;
}

// The PVS of `cell` as the server computes it (through its scheduler and cache).
std::vector<uint32_t> ServerPvs(uint32_t cell) {
  std::promise<server::CellPvsPtr> done;
  server::CellPvsPtr cached = Default().scheduler().Request(
      /*requester=*/uint64_t{1} << 62, cell, 0.0, [&](const server::CellPvsPtr& p) { done.set_value(p); });
  if (cached == nullptr) cached = done.get_future().get();
  return cached->objects;
}

uint64_t RawBytes(const std::set<uint32_t>& objects) {
  uint64_t bytes = 0;
  for (uint32_t o : objects) bytes += Default().geometry(o).RawBytes();
  return bytes;
}

// "cell: frames" of the stalled frames in a frame log.
std::string StalledCells(const std::string& frame_log) {
  std::ifstream in(frame_log);
  std::string line;
  std::getline(in, line);
  std::map<std::string, int> stalled;
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    if (f.size() > 5 && f[5] == "1") ++stalled[f[4] + " at t=" + f[1].substr(0, f[1].find('.'))];
  }
  std::string out = "stalled frames by cell and second:";
  for (const auto& [cell, n] : stalled) out += " " + cell + " (" + std::to_string(n) + ")";
  return out;
}

struct Rgb {
  int r, g, b;
};
Rgb FromArray(const std::array<uint8_t, 3>& c) { return {c[0], c[1], c[2]}; }
Rgb At(const RgbImage& im, int x, int y) {
  const uint8_t* p = im.rgb.data() + (static_cast<size_t>(y) * im.width + x) * 3;
  return {p[0], p[1], p[2]};
}
bool Near(Rgb a, Rgb b) { return std::abs(a.r - b.r) <= 2 && std::abs(a.g - b.g) <= 2 && std::abs(a.b - b.b) <= 2; }

TEST(ClientWalk, TheDefaultPathHeadlessHasNoStallsNoPixelErrorAndReadableScreenshots) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  WalkthroughOptions o = Headless(Address(*server));
  o.speed_kmh = 180.0;  // the whole 2.2 km walk in 44 s
  o.verify = true;
  o.every_s = 4.0;
  o.screenshots_dir = TempDir("walk");
  absl::StatusOr<WalkthroughSummary> s = RunWalkthrough(o);
  ASSERT_TRUE(s.ok()) << s.status();
  std::printf("%s", SummaryText(*s).c_str());
  EXPECT_EQ(s->path, "avenue-and-back-streets");
  EXPECT_GT(s->frames, 300u);
  EXPECT_GT(s->cells_visited, 15u);
  // Frames sample the path: corners are cut by a metre or so.
  EXPECT_NEAR(s->distance_m, DefaultWalk(1.0).length_m(), 0.005 * DefaultWalk(1.0).length_m());
  EXPECT_EQ(s->stalls, 0u);
  EXPECT_EQ(s->pixel_error, 0u);
  EXPECT_GE(s->checked_frames, 10u);
  EXPECT_EQ(s->duplicates, 0u);
  EXPECT_GT(s->mean_triangles_drawn, 0.0);
  EXPECT_LT(s->mean_triangles_drawn, 0.5 * static_cast<double>(s->scene_triangles));
  ASSERT_GE(s->screenshots.size(), 10u);
  double sky_share = 0.0;  // of the top rows, over all screenshots
  for (const std::string& path : s->screenshots) {
    absl::StatusOr<RgbImage> im = ReadPng(path);
    ASSERT_TRUE(im.ok()) << im.status();
    ASSERT_EQ(im->width, 320);
    ASSERT_EQ(im->height, 180);
    const Rgb sky = FromArray(Renderer::SkyRgb()), ground = FromArray(Renderer::GroundRgb());
    int sky_top = 0, ground_bottom = 0, buildings = 0;
    for (int x = 0; x < im->width; ++x) {
      sky_top += Near(At(*im, x, 0), sky) ? 1 : 0;
      ground_bottom += Near(At(*im, x, im->height - 1), ground) ? 1 : 0;
    }
    for (int y = 0; y < im->height; ++y) {
      for (int x = 0; x < im->width; ++x) {
        const Rgb c = At(*im, x, y);
        buildings += !Near(c, sky) && !Near(c, ground) ? 1 : 0;
      }
    }
    const double share = static_cast<double>(buildings) / (im->width * im->height);
    EXPECT_GT(sky_top, 0) << path << ": no sky on the top row";
    sky_share += static_cast<double>(sky_top) / im->width / static_cast<double>(s->screenshots.size());
    EXPECT_GE(ground_bottom, im->width * 3 / 4) << path << ": the bottom row is not ground";
    EXPECT_GT(share, 0.03) << path << ": hardly any building";
    EXPECT_LT(share, 0.9) << path << ": buildings everywhere";
  }
  EXPECT_GT(sky_share, 0.4) << "the top rows are mostly not sky";
}

TEST(ClientWalk, ASmallMemoryBudgetIsNeverExceededAndCausesNoStallWhereItHoldsTheNextCells) {
  // The budget holds, at every crossing of the walk, the PVSs of the cell left and of the cells
  // the walker may enter there; not the nine cells around the eye that the client keeps
  // without a budget, so the server must evict.
  const std::vector<Crossing> crossings = CrossingsAlong(DefaultWalk(1.0));
  ASSERT_GT(crossings.size(), 15u);
  uint64_t budget = 0;
  for (const Crossing& crossing : crossings) {
    std::set<uint32_t> objects;
    for (uint32_t c : crossing.cells) {
      for (uint32_t o : ServerPvs(c)) objects.insert(o);
    }
    budget = std::max(budget, RawBytes(objects));
  }
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  WalkthroughOptions o = Headless(Address(*server));
  o.speed_kmh = 180.0;
  o.memory_budget_bytes = budget;
  o.frame_log = TempDir("budget") + "/frames.csv";
  absl::StatusOr<WalkthroughSummary> s = RunWalkthrough(o);
  ASSERT_TRUE(s.ok()) << s.status();
  std::printf("budget %.2f MB: %s", budget / 1e6, SummaryText(*s).c_str());
  uint64_t nine = 0;  // the most that the nine cells around the eye hold together on the walk
  for (const Crossing& crossing : crossings) {
    std::set<uint32_t> objects;
    std::vector<uint32_t> around = Default().grid().Neighbours(crossing.from);
    around.push_back(crossing.from);
    for (uint32_t c : around) {
      for (uint32_t ob : ServerPvs(c)) objects.insert(ob);
    }
    nine = std::max(nine, RawBytes(objects));
  }
  EXPECT_LT(budget, nine) << "the budget does not bind";
  EXPECT_LE(s->max_held_bytes, budget);
  EXPECT_EQ(s->frames_over_memory_budget, 0u);
  EXPECT_EQ(s->evicted_by_budget, 0u) << "the client had to evict on its own: the server's accounting differs";
  EXPECT_GT(s->evicted_by_server, 0u);
  EXPECT_EQ(s->stalls, 0u) << StalledCells(o.frame_log);
  EXPECT_EQ(s->duplicates, 0u);
}


TEST(ClientWalk, AServerRestartMidPathLosesNothingAndDownloadsNothingTwice) {
  auto first = StartServer();
  ASSERT_NE(first, nullptr);
  const int port = first->port();
  WalkthroughOptions o = Headless(Address(*first));
  o.speed_kmh = 36.0;
  o.seconds = 16.0;
  o.verify = true;
  o.every_s = 1.0;
  std::future<absl::StatusOr<WalkthroughSummary>> walk =
      std::async(std::launch::async, [&] { return RunWalkthrough(o); });
  std::this_thread::sleep_for(std::chrono::seconds(5));
  first.reset();  // drains: every session ends UNAVAILABLE
  std::this_thread::sleep_for(std::chrono::seconds(1));
  auto second = StartServer(port);
  ASSERT_NE(second, nullptr);
  absl::StatusOr<WalkthroughSummary> s = walk.get();
  ASSERT_TRUE(s.ok()) << s.status();
  std::printf("%s", SummaryText(*s).c_str());
  EXPECT_GE(s->reconnects, 1u);
  EXPECT_EQ(s->duplicates, 0u) << "objects held before the restart were sent again";
  EXPECT_EQ(s->stalls, 0u);
  EXPECT_EQ(s->pixel_error, 0u);
  EXPECT_GE(s->checked_frames, 12u);
  EXPECT_GT(s->distance_m, 150.0);
}

// A server gone for good: after --give-up seconds the walk ends with UNAVAILABLE naming the
// server, and the summary (what the client prints before the error) holds what it did.
TEST(ClientWalk, GivingUpOnALostServerStillSaysWhatWasWalked) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  WalkthroughOptions o = Headless(Address(*server));
  o.speed_kmh = 36.0;
  o.seconds = 60.0;
  o.give_up_s = 2.0;
  WalkthroughSummary summary;
  std::future<absl::Status> walk = std::async(std::launch::async, [&] { return RunWalkthrough(o, &summary); });
  std::this_thread::sleep_for(std::chrono::seconds(4));
  server.reset();  // and none comes back
  const absl::Status s = walk.get();
  ASSERT_EQ(s.code(), absl::StatusCode::kUnavailable) << s;
  EXPECT_NE(s.message().find("lost the server at " + o.server + ": no answer for 2 s"), std::string::npos) << s;
  EXPECT_GT(summary.frames, 0u);
  EXPECT_GT(summary.objects_received, 0u);
  EXPECT_GT(summary.distance_m, 10.0);
  EXPECT_LT(summary.walk_s, 30.0) << "it gave up, it did not walk on to the end";
  const nlohmann::json j = nlohmann::json::parse(SummaryJson(summary));
  EXPECT_EQ(j["frames"].get<uint64_t>(), summary.frames);
}

// ---- the executables ----

struct Ran {
  int rc = -1;
  std::string output;  // stdout and stderr
};

Ran RunCommand(const std::string& command) {
  Ran r;
  std::FILE* p = popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) r.output.append(buf, n);
  const int status = pclose(p);
  r.rc = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

std::string Client() { return VISTREAM_CLIENT_BIN; }

std::string LastPng(const std::string& dir) {
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(dir)) files.push_back(e.path().string());
  std::sort(files.begin(), files.end());
  return files.empty() ? std::string() : files.back();
}

TEST(ClientProcess, TheWindowUnderXvfbShowsWhatTheHeadlessClientShows) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  ASSERT_EQ(RunCommand("command -v xvfb-run").rc, 0) << "xvfb-run is missing: ./vistream.sh installs it (xvfb)";
  const std::string window = TempDir("window"), headless = TempDir("headless");
  const std::string common = " --server " + Address(*server) +
                             " --pose 509.4,215.9,1.7,80,0 --frames 15 --size 320x180 --json --screenshots ";
  // The window without its panels and multisampling (tests/window_test.cpp tests those).
  const std::string window_only = " --no-overlay --msaa 0";
  const Ran w = RunCommand("xvfb-run -a -s '-screen 0 1024x768x24' " + Client() + window_only + common + window);
  ASSERT_EQ(w.rc, 0) << w.output;
  EXPECT_NE(w.output.find("\"stalls\": 0"), std::string::npos) << w.output;
  const Ran h = RunCommand(Client() + " --headless" + common + headless);
  ASSERT_EQ(h.rc, 0) << h.output;
  absl::StatusOr<RgbImage> a = ReadPng(LastPng(window)), b = ReadPng(LastPng(headless));
  ASSERT_TRUE(a.ok()) << a.status();
  ASSERT_TRUE(b.ok()) << b.status();
  ASSERT_EQ(a->width, b->width);
  ASSERT_EQ(a->height, b->height);
  size_t differ = 0, building = 0;
  const Rgb sky = FromArray(Renderer::SkyRgb()), ground = FromArray(Renderer::GroundRgb());
  for (int y = 0; y < a->height; ++y) {
    for (int x = 0; x < a->width; ++x) {
      const Rgb p = At(*a, x, y), q = At(*b, x, y);
      differ += std::abs(p.r - q.r) > 3 || std::abs(p.g - q.g) > 3 || std::abs(p.b - q.b) > 3 ? 1 : 0;
      building += !Near(p, sky) && !Near(p, ground) ? 1 : 0;
    }
  }
  EXPECT_LE(differ, static_cast<size_t>(a->width * a->height / 1000)) << differ << " pixels differ";
  EXPECT_GT(building, static_cast<size_t>(a->width * a->height / 20)) << "the window shows no city";
}

// A server that speaks another protocol version.
class FutureServer final : public v1::Walkthrough::Service {
  grpc::Status GetStats(grpc::ServerContext*, const v1::StatsRequest*, v1::ServerStats* s) override {
    s->set_scene("default");
    s->set_protocol_version(2);
    return grpc::Status::OK;
  }
};

TEST(ClientProcess, BadInputGetsAClearMessageAndANonZeroExit) {
  auto server = StartServer();
  ASSERT_NE(server, nullptr);
  const std::string real = " --headless --server " + Address(*server);
  // Nothing listens on a port this test holds bound (so that no one else takes it) without
  // listening: a connection to it is refused.
  const int held = socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(held, 0);
  sockaddr_in at{};
  at.sin_family = AF_INET;
  at.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t at_len = sizeof(at);
  ASSERT_EQ(bind(held, reinterpret_cast<const sockaddr*>(&at), sizeof(at)), 0);
  ASSERT_EQ(getsockname(held, reinterpret_cast<sockaddr*>(&at), &at_len), 0);
  const int free_port = ntohs(at.sin_port);
  Ran r = RunCommand(Client() + " --headless --connect-timeout 1 --server 127.0.0.1:" + std::to_string(free_port));
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("no vistream server answers at 127.0.0.1:" + std::to_string(free_port)),
            std::string::npos)
      << r.output;
  close(held);

  FutureServer future;
  int future_port = 0;
  grpc::ServerBuilder b;
  b.AddListeningPort("127.0.0.1:0", grpc::InsecureServerCredentials(), &future_port);
  b.RegisterService(&future);
  std::unique_ptr<grpc::Server> other = b.BuildAndStart();
  r = RunCommand(Client() + " --headless --server 127.0.0.1:" + std::to_string(future_port));
  other->Shutdown();
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("speaks protocol version 2; this client speaks version 1"), std::string::npos) << r.output;

  r = RunCommand(Client() + real + " --path nowhere");
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("has no walk 'nowhere'; its walks: avenue-and-back-streets"), std::string::npos)
      << r.output;

  for (const char* size : {"12x", "1280", "0x720", "1280x720x3", "-5x10", "axb", "99999x99999"}) {
    r = RunCommand(Client() + real + " --size " + size);
    EXPECT_EQ(r.rc, 2) << size << ": " << r.output;
    EXPECT_NE(r.output.find(std::string("--size: '") + size + "': expected WIDTHxHEIGHT"), std::string::npos)
        << r.output;
    EXPECT_NE(r.output.find("Run 'vistream-client --help' for the options."), std::string::npos) << r.output;
  }
  for (const char* lod : {"0", "-1", "1001", "nan", "one"}) {
    r = RunCommand(Client() + real + " --lod " + lod);
    EXPECT_EQ(r.rc, 2) << lod << ": " << r.output;
    EXPECT_NE(r.output.find(std::string("--lod: '") + lod + "': expected off or a screen error in pixels"),
              std::string::npos)
        << r.output;
  }
  for (const char* address : {"127.0.0.1:99999", "127.0.0.1", "127.0.0.1:", "127.0.0.1:80x"}) {
    r = RunCommand(Client() + " --headless --server " + address);
    EXPECT_EQ(r.rc, 2) << address << ": " << r.output;
    EXPECT_NE(r.output.find(std::string("--server: '") + address + "'"), std::string::npos) << r.output;
  }
  r = RunCommand(Client() + " --headless --frame-log /dev/full --seconds 1 --server " + Address(*server));
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("/dev/full: writing the frame log failed"), std::string::npos) << r.output;
  r = RunCommand(Client() + " --headless --cell-log /dev/full --seconds 1 --server " + Address(*server));
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("/dev/full: writing the cell log failed"), std::string::npos) << r.output;
  r = RunCommand(Client() + real + " --cell-log /nonexistent/dir/cells.csv");
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("/nonexistent/dir/cells.csv: cannot open for writing"), std::string::npos) << r.output;
  r = RunCommand(Client() + real + " --speed nan");
  EXPECT_EQ(r.rc, 2) << r.output;
  EXPECT_NE(r.output.find("'nan' is not a number"), std::string::npos) << r.output;
  r = RunCommand(Client() + real + " --pose 1,2");
  EXPECT_EQ(r.rc, 2) << r.output;
  EXPECT_NE(r.output.find("--pose: '1,2'"), std::string::npos) << r.output;
  r = RunCommand(Client() + real + " --port 5");
  EXPECT_EQ(r.rc, 2) << r.output;
  EXPECT_NE(r.output.find("vistream-client: error: --port: not an option of vistream-client"), std::string::npos)
      << r.output;
  // A pose outside the scene: the server ends the session, and the client says why.
  r = RunCommand(Client() + real + " --pose 99999,0,1.7,0,0");
  EXPECT_EQ(r.rc, 1) << r.output;
  EXPECT_NE(r.output.find("outside the viewcell grid"), std::string::npos) << r.output;
}

// ---- units ----

TEST(CellMargins, EachEntryGetsTheTimeItsCellLastBecameCompleteAndTheStartCellIsNoMargin) {
  CellMargins m;
  std::map<uint32_t, std::vector<uint32_t>> lists = {{1, {10, 11}}, {2, {20}}};
  std::set<uint32_t> ready = {10, 11};
  auto frame = [&](double t, std::optional<uint32_t> cell) {
    const bool complete = cell.has_value() && lists.count(*cell) > 0 &&
                          std::all_of(lists[*cell].begin(), lists[*cell].end(), [&](uint32_t id) { return ready.count(id) > 0; });
    m.Observe(t, lists, [&](uint32_t id) { return ready.count(id) > 0; }, cell, /*grid_nx=*/4, !complete);
  };
  frame(-0.5, std::nullopt);  // start-up: nothing entered yet
  m.Shift(0.5);               // the walk's clock starts here
  frame(0.0, 1);              // the start cell, complete
  frame(1.0, 1);
  ready.insert(20);
  frame(2.0, 1);              // cell 2 complete from 2 s
  ready.erase(20);
  frame(2.5, 1);              // ...lost an object: starts over
  ready.insert(20);
  frame(3.0, 1);
  frame(5.0, 2);              // entered 2 s after: margin 2
  lists[3] = {30};
  frame(6.0, 3);              // entered incomplete: a stall
  ready.insert(30);
  frame(7.0, 3);              // complete 1 s after the entry: margin -1
  frame(8.0, 4);              // no list: a stall, left at 9 s before it completed (a bound)
  frame(9.0, 1);              // cell 1 complete since the start: margin 9
  m.Finish(10.0);
  const std::vector<CellEntry>& e = m.entries();
  ASSERT_EQ(e.size(), 5u);
  EXPECT_TRUE(e[0].start);
  EXPECT_EQ(e[0].cell, 1u);
  EXPECT_EQ(e[0].i, 1);
  EXPECT_EQ(e[0].j, 0);
  EXPECT_DOUBLE_EQ(e[0].complete_s, 0.0);  // complete at -0.5 + 0.5
  EXPECT_DOUBLE_EQ(e[1].margin_s, 2.0);
  EXPECT_FALSE(e[1].stalled);
  EXPECT_DOUBLE_EQ(e[2].complete_s, 7.0);
  EXPECT_DOUBLE_EQ(e[2].margin_s, -1.0);
  EXPECT_TRUE(e[2].stalled);
  EXPECT_DOUBLE_EQ(e[3].complete_s, 9.0);
  EXPECT_DOUBLE_EQ(e[3].margin_s, -1.0);
  EXPECT_TRUE(e[3].stalled);
  EXPECT_DOUBLE_EQ(e[4].margin_s, 9.0);
  const MarginSummary s = m.Summary();
  EXPECT_EQ(s.cells_entered, 4u);
  EXPECT_EQ(s.stalled_cells, 2u);
  EXPECT_DOUBLE_EQ(*s.min_margin_s, -1.0);
  EXPECT_DOUBLE_EQ(*s.mean_margin_s, (2.0 - 1.0 - 1.0 + 9.0) / 4.0);
  EXPECT_EQ(m.Csv().substr(0, m.Csv().find('\n')), "cell_id,i,j,entered_s,complete_s,margin_s,stalled");
  EXPECT_NE(m.Csv().find("3,3,0,6.0000,7.0000,-1.0000,1\n"), std::string::npos) << m.Csv();
  EXPECT_FALSE(CellMargins().Summary().min_margin_s.has_value());  // nothing entered: no margin
}

TEST(ClientGrid, FindsTheCellTheServerFinds) {
  const visibility::ViewcellGrid& grid = Default().grid();
  const visibility::ViewcellGrid g = *GridFromSceneInfo(Default().scene_info().grid());
  std::mt19937 rng(5);
  const scenes::Aabb b = grid.Bounds();
  std::uniform_real_distribution<double> x(b.min.x - 50, b.max.x + 50), y(b.min.y - 50, b.max.y + 50);
  for (int k = 0; k < 20000; ++k) {
    // Every fourth point on a cell edge, where the two could disagree.
    glm::dvec2 p(x(rng), y(rng));
    if (k % 4 == 0) p.x = b.min.x + std::round((p.x - b.min.x) / grid.cell_size()) * grid.cell_size();
    if (k % 8 == 0) p.y = b.min.y + std::round((p.y - b.min.y) / grid.cell_size()) * grid.cell_size();
    ASSERT_EQ(g.CellAt(p), grid.CellAt(p)) << p.x << ", " << p.y;
  }
  for (uint32_t c : {0u, 5u, 21u, static_cast<uint32_t>(grid.CellCount() - 1)}) {
    std::vector<uint32_t> want = grid.Neighbours(c);
    want.push_back(c);
    std::vector<uint32_t> got = g.Neighbourhood(c);
    std::sort(want.begin(), want.end());
    std::sort(got.begin(), got.end());
    EXPECT_EQ(got, want) << "cell " << c;
  }
}

// A server older than bands (or a flat scene) sends none: every cell's band is the grid's. A
// server whose cells follow terrain sends each cell's; a list of the wrong length is bad data.
TEST(ObjectStore, ReadsEachCellsBandOrTheGridsOne) {
  v1::SceneInfo info;
  v1::ViewcellGrid* grid = info.mutable_grid();
  grid->set_cell_size_m(10);
  grid->set_nx(2);
  grid->set_ny(1);
  grid->set_base_z_m(0.5);
  grid->set_height_m(2);
  // A store that has been sent `info`, as it stands now.
  auto sent = [&info] {
    auto store = std::make_unique<ObjectStore>(0);
    std::vector<Event> events;
    events.emplace_back(info);
    store->Apply(std::move(events), std::nullopt);
    return store;
  };
  {
    const std::unique_ptr<ObjectStore> s = sent();
    const ObjectStore& store = *s;
    ASSERT_FALSE(store.failure().has_value());
    EXPECT_FALSE(store.grid().has_bands());
    EXPECT_EQ(store.grid().Band(1), (visibility::CellBand{0.5, 2.5}));
    EXPECT_TRUE(store.grid().InBand(1, 1.7));
    EXPECT_FALSE(store.grid().InBand(1, 3.0));
  }
  for (double z : {3.5, 14.0, 6.0, 13.0}) grid->add_band_z(z);
  {
    const std::unique_ptr<ObjectStore> s = sent();
    const ObjectStore& store = *s;
    ASSERT_FALSE(store.failure().has_value());
    EXPECT_TRUE(store.grid().has_bands());
    EXPECT_EQ(store.grid().Band(0), (visibility::CellBand{3.5, 14.0}));
    EXPECT_EQ(store.grid().Band(1), (visibility::CellBand{6.0, 13.0}));
    EXPECT_TRUE(store.grid().InBand(0, 4.0));
    EXPECT_FALSE(store.grid().InBand(1, 4.0));
  }
  for (const auto& [bands, says] : {std::pair{std::vector<double>{3.5, 14.0, 6.0}, "3 band values for 2 cells"},
                                    std::pair{std::vector<double>{3.5, 14.0, 6.0, 6.0}, "viewcell 1's band"}}) {
    grid->clear_band_z();
    for (double z : bands) grid->add_band_z(z);
    const std::unique_ptr<ObjectStore> s = sent();
    const ObjectStore& store = *s;
    ASSERT_TRUE(store.failure().has_value());
    EXPECT_TRUE(store.failure_is_bad_data());
    EXPECT_NE(store.failure()->find(says), std::string::npos) << *store.failure();
    EXPECT_FALSE(store.has_scene_info());
  }
}

TEST(ObjectStore, OverBudgetDropsWhatNoNearbyCellNeedsFirstAndNeverTheCurrentCell) {
  v1::SceneInfo info;
  v1::ViewcellGrid* grid = info.mutable_grid();
  grid->set_cell_size_m(10);
  grid->set_nx(5);
  grid->set_ny(1);
  grid->set_height_m(2);
  auto object = [](uint32_t id, uint64_t bytes) {
    ReceivedObject o;
    o.id = id;
    o.raw_bytes = bytes;
    return o;
  };
  auto pvs = [](uint32_t cell, std::vector<uint32_t> ids) {
    v1::ViewcellPvs p;
    p.set_cell_id(cell);
    p.mutable_object_ids()->Add(ids.begin(), ids.end());
    return p;
  };
  ObjectStore store(1000);
  std::vector<Event> events;
  events.emplace_back(info);
  events.emplace_back(pvs(0, {1, 2, 5}));  // current: cell 0
  events.emplace_back(pvs(1, {3}));     // adjacent
  events.emplace_back(object(1, 300));
  events.emplace_back(object(2, 300));
  events.emplace_back(object(3, 200));
  events.emplace_back(object(4, 150));  // in no PVS near cell 0
  EXPECT_TRUE(store.Apply(std::move(events), 0u).empty());
  EXPECT_EQ(store.held_bytes(), 950u);
  EXPECT_FALSE(store.CellComplete(0));
  // 250 more for the current cell: 4 goes first (in no nearby PVS), then 3 (adjacent only).
  events.clear();
  events.emplace_back(object(5, 250));
  EXPECT_EQ(store.Apply(std::move(events), 0u), (std::vector<uint32_t>{4, 3}));
  EXPECT_EQ(store.held_bytes(), 850u);
  EXPECT_TRUE(store.CellComplete(0));
  EXPECT_EQ(store.evicted_by_budget(), 2u);
  // Past the budget with the current cell alone: it is kept, over budget.
  events.clear();
  events.emplace_back(object(2, 900));  // a resent object replaces the old copy
  store.Apply(std::move(events), 0u);
  EXPECT_NE(store.Find(1), nullptr);
  EXPECT_NE(store.Find(2), nullptr);
  EXPECT_NE(store.Find(5), nullptr);
  EXPECT_GT(store.held_bytes(), 1000u);
  // Evict hints from the server drop exactly what they name.
  events.clear();
  v1::Evict evict;
  evict.add_object_ids(1);
  evict.add_object_ids(77);  // not held: ignored
  events.emplace_back(evict);
  store.Apply(std::move(events), 0u);
  EXPECT_EQ(store.Find(1), nullptr);
  EXPECT_EQ(store.evicted_by_server(), 1u);
  EXPECT_FALSE(store.CellComplete(0));
}

}  // namespace
}  // namespace vistream::client

namespace vistream::client {
namespace {

// Issue 35: an imported scene's own walks (streets of tests/osm/streets.osm), which no catalog
// entry declares, come from the server in SceneInfo.paths and the headless client follows them.
class ServedWalks : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    scenes::OsmImportOptions io;
    io.name = "osmwalks";  // in no catalog
    absl::StatusOr<scenes::Scene> scene =
        scenes::ImportOsm(std::string(VISTREAM_SOURCE_DIR "/tests/osm/streets.osm"), io);
    ASSERT_TRUE(scene.ok()) << scene.status();
    ASSERT_EQ(scene->paths.size(), 2u);
    const std::string glb = vistream::testing::ProcessTempDir() + "/osmwalks.glb";
    ASSERT_TRUE(scenes::SaveGltf(*scene, glb).ok());
    server::ServedSceneOptions o;
    o.scene = glb;
    o.threads = 1;
    absl::StatusOr<std::unique_ptr<ServedScene>> s = ServedScene::Create(o);
    ASSERT_TRUE(s.ok()) << s.status();
    scene_ = s->release();
    server::ServerOptions so;
    so.listen = "127.0.0.1:0";
    absl::StatusOr<std::unique_ptr<WalkthroughServer>> w = WalkthroughServer::Start(scene_, so, nullptr);
    ASSERT_TRUE(w.ok()) << w.status();
    server_ = w->release();
  }
  static void TearDownTestSuite() {
    delete server_;
    server_ = nullptr;
  }
  static ServedScene* scene_;
  static WalkthroughServer* server_;
};
ServedScene* ServedWalks::scene_ = nullptr;
WalkthroughServer* ServedWalks::server_ = nullptr;

TEST_F(ServedWalks, TheHeadlessClientFollowsAWalkOnlyTheServerHas) {
  WalkthroughOptions o = Headless(Address(*server_));
  o.path = "street 2 (Main Street)";
  o.speed_kmh = 72.0;
  o.seconds = 3.0;
  absl::StatusOr<WalkthroughSummary> s = RunWalkthrough(o);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->scene, "osmwalks");
  EXPECT_EQ(s->path, "street 2 (Main Street)");
  EXPECT_GT(s->distance_m, 30.0);
  EXPECT_GT(s->frames, 0u);
  EXPECT_EQ(s->stalls, 0u);
}

TEST_F(ServedWalks, WithoutAPathTheHeadlessClientTakesTheFirstAndABadNameListsThemAll) {
  WalkthroughOptions o = Headless(Address(*server_));
  o.speed_kmh = 72.0;
  o.seconds = 1.0;
  absl::StatusOr<WalkthroughSummary> s = RunWalkthrough(o);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->path, "street 1 (Main Street)");

  o.path = "nowhere";
  absl::StatusOr<WalkthroughSummary> bad = RunWalkthrough(o);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(bad.status().message().find(
                "has no walk 'nowhere'; its walks: street 1 (Main Street), street 2 (Main Street)"),
            std::string::npos)
      << bad.status();
}

// A generated city saved to a file (`vistream scene generate city1 -o city1.glb`) and served from
// it as vistream-server serves a path (the scene named by the path): the catalog entry's walks
// travel in the file, the server sends them, and the headless client, which has no catalog entry
// for a file and does not look for one, follows them (the kind of ../shared/cases' london.glb).
TEST(ServedFile, AGeneratedCitySavedToAFileKeepsItsCatalogWalksForTheClient) {
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry("city1");
  ASSERT_TRUE(entry.ok()) << entry.status();
  ASSERT_FALSE(entry->walks.empty());
  absl::StatusOr<scenes::Scene> scene = scenes::BuildScene(*entry);
  ASSERT_TRUE(scene.ok()) << scene.status();
  scenes::AddDeclaredWalks(entry->walks, &*scene);
  const std::string glb = TempDir("served_file") + "/city1.glb";
  ASSERT_TRUE(scenes::SaveGltf(*scene, glb).ok());
  server::ServedSceneOptions so;
  so.scene = glb;
  so.name = glb;
  so.threads = 1;
  absl::StatusOr<std::unique_ptr<ServedScene>> served = ServedScene::Create(so);
  ASSERT_TRUE(served.ok()) << served.status();
  server::ServerOptions o;
  o.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<WalkthroughServer>> w = WalkthroughServer::Start(served->get(), o, nullptr);
  ASSERT_TRUE(w.ok()) << w.status();
  WalkthroughOptions c = Headless(Address(**w));
  std::string log;
  c.log = [&log](const std::string& line) { log += line + "\n"; };
  c.path = entry->walks.front().name;
  c.speed_kmh = 72.0;
  c.seconds = 2.0;
  absl::StatusOr<WalkthroughSummary> s = RunWalkthrough(c);
  ASSERT_TRUE(s.ok()) << s.status() << "\n" << log;
  EXPECT_EQ(s->scene, glb);
  EXPECT_EQ(s->path, entry->walks.front().name);
  EXPECT_GT(s->distance_m, 20.0);
  EXPECT_EQ(s->stalls, 0u);
  EXPECT_NE(log.find("the server's scene is the glTF file '" + glb + "': walks from the file"), std::string::npos) << log;
  EXPECT_EQ(log.find("malformed JSON"), std::string::npos) << log;
}

}  // namespace
}  // namespace vistream::client
