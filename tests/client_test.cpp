// The thin client against a real server on loopback: headless walks of the default scene
// (stalls, pixel error, screenshots), a memory budget, a server restart, the window front end
// under Xvfb, and bad input to the executable. Plus its units: grid lookup, object store, walk.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <grpcpp/grpcpp.h>

#include "client/object_store.h"
#include "client/png_image.h"
#include "client/renderer.h"
#include "client/walk.h"
#include "client/walkthrough.h"
#include "proto/walkthrough.grpc.pb.h"
#include "scenes/catalog.h"
#include "server/served_scene.h"
#include "server/service.h"

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

// A fresh folder under the test's temporary directory.
std::string TempDir(const std::string& name) {
  const std::filesystem::path p = std::filesystem::temp_directory_path() /
                                  ("vistream_client_test_" + std::to_string(getpid()) + "_" + name);
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
std::vector<Crossing> CrossingsAlong(const Walk& walk) {
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

Walk DefaultWalk(double speed_mps) {
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry("default");
  EXPECT_TRUE(entry.ok()) << entry.status();
  absl::StatusOr<Walk> w = Walk::Create(entry->walks.front(), speed_mps);
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

}  // namespace
}  // namespace vistream::client
