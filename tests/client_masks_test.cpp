// The thin client's ε-masks (issue 34): the object store decodes the server's run-length masks,
// keeps those of the nine cells around the eye (at most 64) and picks, for an eye, the mask a
// frame may draw; a walker on city1 at 6 km/h through a real server on loopback draws masked
// frames, no hole frame and no pixel error; mask bytes are credit consumed (a 512-byte window keeps
// flowing); without masks the server sends none. Levels of detail (issue 45) through a real
// server: walkers on a london-generated town and on Den Haag draw levels within tau + 1 px of
// every full-detail silhouette, without a stall or a hole; a resumed session says the levels
// it holds.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <absl/strings/str_format.h>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "client/connection.h"
#include "client/object_store.h"
#include "client/walkthrough.h"
#include "scenes/catalog.h"
#include "scenes/city_import.h"
#include "scenes/gltf_io.h"
#include "scenes/walk.h"
#include "server/served_scene.h"
#include "server/service.h"
#include "tests/client_test_util.h"
#include "tests/temp_dir.h"
#include "visibility/mask_codec.h"

namespace vistream::client {
namespace {

namespace v1 = vistream::v1;

ReceivedObject Object(uint32_t id) {
  ReceivedObject o;
  o.id = id;
  o.raw_bytes = 100;
  return o;
}

// A mask over `objects` (id and its set triangle indices) for the box [lo, hi] in `cell`.
v1::EpsilonMask Mask(uint32_t mask_id, uint32_t cell, glm::dvec3 lo, glm::dvec3 hi,
                     const std::vector<std::pair<uint32_t, std::vector<uint32_t>>>& objects) {
  std::vector<visibility::MaskObject> sets;
  uint64_t triangles = 0;
  for (const auto& [id, set] : objects) {
    visibility::MaskObject m;
    m.object = id;
    for (uint32_t t : set) {
      if (m.bits.size() <= t / 8) m.bits.resize(t / 8 + 1, 0);
      m.bits[t / 8] = static_cast<uint8_t>(m.bits[t / 8] | (1u << (t % 8)));
    }
    triangles += set.size();
    sets.push_back(std::move(m));
  }
  v1::EpsilonMask m;
  m.set_mask_id(mask_id);
  m.set_cell_id(cell);
  m.mutable_neighbourhood_min()->set_x(lo.x);
  m.mutable_neighbourhood_min()->set_y(lo.y);
  m.mutable_neighbourhood_min()->set_z(lo.z);
  m.mutable_neighbourhood_max()->set_x(hi.x);
  m.mutable_neighbourhood_max()->set_y(hi.y);
  m.mutable_neighbourhood_max()->set_z(hi.z);
  m.set_triangles(visibility::EncodeMaskRuns(sets));
  m.set_object_count(static_cast<uint32_t>(sets.size()));
  m.set_triangle_count(triangles);
  return m;
}

// A box in cell `cell` of RowOfCells: x from 10 cell + a to 10 cell + b, all of y, z 0..2.
v1::EpsilonMask MaskIn(uint32_t mask_id, uint32_t cell, double a, double b,
                       const std::vector<std::pair<uint32_t, std::vector<uint32_t>>>& objects) {
  return Mask(mask_id, cell, {10.0 * cell + a, 0.0, 0.0}, {10.0 * cell + b, 10.0, 2.0}, objects);
}

std::vector<uint32_t> HeldMaskIds(const ObjectStore& store) {
  std::vector<uint32_t> ids;
  for (const auto& [id, m] : store.masks()) ids.push_back(id);
  return ids;
}

TEST(ObjectStoreMasks, AMaskIsDecodedWithItsCellBoxObjectsAndTriangleBits) {
  ObjectStore store(0);
  std::vector<Event> events;
  events.emplace_back(RowOfCells());
  events.emplace_back(Mask(3, 1, {11, 2, 0.5}, {15, 4, 1.1}, {{2, {0, 9}}, {7, {4}}}));
  store.Apply(std::move(events), 1u);
  ASSERT_FALSE(store.failure().has_value()) << *store.failure();
  ASSERT_EQ(store.masks().size(), 1u);
  const EpsilonMaskSet& m = store.masks().at(3);
  EXPECT_EQ(m.mask_id, 3u);
  EXPECT_EQ(m.cell, 1u);
  EXPECT_EQ(m.triangles, 3u);
  EXPECT_EQ(m.object_ids, (std::vector<uint32_t>{2, 7}));
  EXPECT_TRUE(m.Contains({13, 3, 0.8}));
  EXPECT_FALSE(m.Contains({13, 3, 1.5}));  // above the box
  EXPECT_FALSE(m.Contains({16, 3, 0.8}));
  ASSERT_NE(m.Bits(2), nullptr);
  EXPECT_TRUE(visibility::MaskBit(*m.Bits(2), 0));
  EXPECT_FALSE(visibility::MaskBit(*m.Bits(2), 1));
  EXPECT_TRUE(visibility::MaskBit(*m.Bits(2), 9));
  EXPECT_FALSE(visibility::MaskBit(*m.Bits(2), 10));
  ASSERT_NE(m.Bits(7), nullptr);
  EXPECT_TRUE(visibility::MaskBit(*m.Bits(7), 4));
  EXPECT_EQ(m.Bits(3), nullptr);  // not in the mask: nothing of it drawn
}

TEST(ObjectStoreMasks, BadMaskBytesAreTheStoresFailureNamingTheMaskAndWhatIsWrong) {
  struct Case {
    std::string bytes, says;
  };
  // An id past the scene's 10 objects; a varint cut short.
  std::string past = Mask(1, 0, {0, 0, 0}, {1, 1, 1}, {{12, {0}}}).triangles();
  const std::vector<Case> cases = {{past, "object"}, {std::string("\x80", 1), "truncated"}};
  for (const Case& c : cases) {
    ObjectStore store(0);
    v1::EpsilonMask bad = Mask(9, 0, {0, 0, 0}, {1, 1, 1}, {});
    bad.set_triangles(c.bytes);
    std::vector<Event> events;
    events.emplace_back(RowOfCells());
    events.emplace_back(bad);
    store.Apply(std::move(events), 0u);
    ASSERT_TRUE(store.failure().has_value());
    EXPECT_TRUE(store.failure_is_bad_data());
    EXPECT_NE(store.failure()->find("mask 9"), std::string::npos) << *store.failure();
    EXPECT_NE(store.failure()->find(c.says), std::string::npos) << *store.failure();
    EXPECT_TRUE(store.masks().empty());
  }
  // Before the scene's description nothing can be decoded: the same failure, saying so.
  ObjectStore early(0);
  std::vector<Event> events;
  events.emplace_back(Mask(4, 0, {0, 0, 0}, {1, 1, 1}, {{1, {0}}}));
  early.Apply(std::move(events), std::nullopt);
  ASSERT_TRUE(early.failure().has_value());
  EXPECT_NE(early.failure()->find("mask 4"), std::string::npos) << *early.failure();
}

TEST(ObjectStoreMasks, MasksOfCellsBeyondTheNineAroundTheEyeAreDroppedAndTheRendererTold) {
  ObjectStore store(0);
  std::vector<Event> events;
  events.emplace_back(RowOfCells());
  for (uint32_t cell = 0; cell < 5; ++cell) events.emplace_back(MaskIn(cell + 1, cell, 1, 9, {{1, {0}}}));
  store.Apply(std::move(events), 0u);  // the eye in cell 0: cells 0 and 1 around it
  EXPECT_EQ(HeldMaskIds(store), (std::vector<uint32_t>{1, 2}));
  std::vector<uint64_t> dropped = store.TakeDroppedMasks();
  EXPECT_EQ(dropped.size(), 3u);
  EXPECT_TRUE(store.TakeDroppedMasks().empty());
  // The eye moves to cell 2: cell 0's mask goes, cell 1's stays.
  store.Apply({}, 2u);
  EXPECT_EQ(HeldMaskIds(store), (std::vector<uint32_t>{2}));
  dropped = store.TakeDroppedMasks();
  ASSERT_EQ(dropped.size(), 1u);
  // An eye outside the grid keeps what is held.
  store.Apply({}, std::nullopt);
  EXPECT_EQ(HeldMaskIds(store), (std::vector<uint32_t>{2}));
}

TEST(ObjectStoreMasks, AtMost64MasksAreHeldTheOldestDroppedFirst) {
  ObjectStore store(0);
  std::vector<Event> events;
  events.emplace_back(RowOfCells());
  for (uint32_t id = 1; id <= 70; ++id) events.emplace_back(MaskIn(id, 0, 1, 9, {{id % 10, {0}}}));
  store.Apply(std::move(events), 0u);
  ASSERT_EQ(store.masks().size(), ObjectStore::kMaxMasks);
  EXPECT_EQ(store.masks().begin()->first, 7u);
  EXPECT_EQ(store.masks().rbegin()->first, 70u);
  EXPECT_EQ(store.TakeDroppedMasks().size(), 6u);
  // One more: mask 7 goes.
  events.clear();
  events.emplace_back(MaskIn(71, 0, 1, 9, {{1, {0}}}));
  store.Apply(std::move(events), 0u);
  EXPECT_EQ(store.masks().size(), ObjectStore::kMaxMasks);
  EXPECT_EQ(store.masks().count(7), 0u);
  EXPECT_EQ(store.masks().count(71), 1u);
}

TEST(ObjectStoreMasks, AMaskIdSeenAgainIsANewSessionsMaskAndReplacesTheOld) {
  ObjectStore store(0);
  std::vector<Event> events;
  events.emplace_back(RowOfCells());
  events.emplace_back(MaskIn(1, 0, 1, 3, {{1, {0}}}));
  store.Apply(std::move(events), 0u);
  const uint64_t old_key = store.masks().at(1).key;
  events.clear();
  events.emplace_back(MaskIn(1, 0, 5, 9, {{2, {0, 1}}}));
  store.Apply(std::move(events), 0u);
  ASSERT_EQ(store.masks().size(), 1u);
  EXPECT_EQ(store.masks().at(1).object_ids, (std::vector<uint32_t>{2}));
  EXPECT_NE(store.masks().at(1).key, old_key);  // the renderer builds nothing on the old one's
  EXPECT_EQ(store.TakeDroppedMasks(), (std::vector<uint64_t>{old_key}));
}

TEST(ObjectStoreMasks, TheUsableMaskHoldsTheEyeHasEveryObjectReadyAndTheFewestTriangles) {
  ObjectStore store(0);
  std::vector<Event> events;
  events.emplace_back(RowOfCells());
  events.emplace_back(MaskIn(1, 1, 0, 6, {{1, {0, 1, 2}}, {2, {0, 1}}}));  // 5 triangles
  events.emplace_back(MaskIn(2, 1, 2, 8, {{3, {0, 1}}}));                // 2 triangles, object 3
  events.emplace_back(MaskIn(3, 1, 7, 10, {{1, {0}}}));                 // 1 triangle, elsewhere
  events.emplace_back(Object(1));
  events.emplace_back(Object(2));
  store.Apply(std::move(events), 1u);
  const glm::dvec3 eye(14, 5, 1);  // in masks 1 and 2
  MaskChoice c = store.ChooseMask(eye);
  EXPECT_TRUE(c.in_box);
  ASSERT_NE(c.mask, nullptr);
  EXPECT_EQ(c.mask->mask_id, 1u) << "mask 2 lacks object 3";
  // Object 3 arrives: mask 2 has fewer triangles.
  events.clear();
  events.emplace_back(Object(3));
  store.Apply(std::move(events), 1u);
  c = store.ChooseMask(eye);
  ASSERT_NE(c.mask, nullptr);
  EXPECT_EQ(c.mask->mask_id, 2u);
  // Not uploaded yet (the renderer's say): mask 1 again.
  c = store.ChooseMask(eye, [](uint32_t id) { return id != 3; });
  ASSERT_NE(c.mask, nullptr);
  EXPECT_EQ(c.mask->mask_id, 1u);
  // In mask 2's box only, with object 3 not ready: in a box, no usable mask.
  c = store.ChooseMask({16.5, 5, 1}, [](uint32_t id) { return id != 3; });
  EXPECT_TRUE(c.in_box);
  EXPECT_EQ(c.mask, nullptr);
  // Above the boxes, or in a cell without masks: in no box, no mask.
  c = store.ChooseMask({14, 5, 2.5});
  EXPECT_FALSE(c.in_box);
  EXPECT_EQ(c.mask, nullptr);
  c = store.ChooseMask({41, 5, 1});
  EXPECT_FALSE(c.in_box);
  EXPECT_EQ(c.mask, nullptr);
  // An object the server evicts makes its masks unusable.
  events.clear();
  v1::Evict evict;
  evict.add_object_ids(3);
  events.emplace_back(evict);
  store.Apply(std::move(events), 1u);
  c = store.ChooseMask(eye);
  ASSERT_NE(c.mask, nullptr);
  EXPECT_EQ(c.mask->mask_id, 1u);
}

// city1 as the server's tests serve it (50 m viewcells), shared by the tests here.
// `scene` (a catalog name or entry) served as these tests serve it: two PVS workers, masks on
// ordinary threads (the shares of masked frames asserted here must not depend on what else
// loads the machine; SCHED_IDLE's effect is MaskQueue's test). With `levels`, its levels of
// detail made at start, as vistream-server --levels makes them.
absl::StatusOr<std::unique_ptr<server::ServedScene>> ServeForMasks(const std::string& scene, uint32_t res = 128,
                                                                    bool levels = false) {
  server::ServedSceneOptions o;
  o.scene = scene;
  o.res = res;
  o.threads = 2;
  o.idle_priority_masks = false;
  o.make_levels = levels;
  return server::ServedScene::Create(o);
}

server::ServedScene& City1() {
  static server::ServedScene* scene = [] {
    absl::StatusOr<std::unique_ptr<server::ServedScene>> s = ServeForMasks("city1");
    EXPECT_TRUE(s.ok()) << s.status();
    return s->release();
  }();
  return *scene;
}

// The frame log's lines as fields, the header first.
std::vector<std::vector<std::string>> ReadCsv(const std::string& path) {
  std::vector<std::vector<std::string>> rows;
  std::ifstream in(path);
  for (std::string line; std::getline(in, line);) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string x; std::getline(ss, x, ',');) f.push_back(x);
    rows.push_back(std::move(f));
  }
  return rows;
}

// A server for `scene` on a free loopback port, and the address to reach it at.
struct LoopbackServer {
  std::unique_ptr<server::WalkthroughServer> server;
  std::string address;
};
absl::StatusOr<LoopbackServer> StartOnLoopback(server::ServedScene* scene) {
  server::ServerOptions so;
  so.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<server::WalkthroughServer>> started = server::WalkthroughServer::Start(scene, so, nullptr);
  if (!started.ok()) return started.status();
  const std::string address = "127.0.0.1:" + std::to_string((*started)->port());
  return LoopbackServer{*std::move(started), address};
}

// A walker along a catalog walk through a real server on loopback, every frame's set checked
// every `every_s` against the full scene's object ids (--verify).
struct MaskedWalk {
  MaskedWalk(server::ServedScene* s, double walk_kmh, double walk_seconds, double check_every_s, std::string catalog = {})
      : scene(s), catalog_dir(std::move(catalog)), kmh(walk_kmh), seconds(walk_seconds), every_s(check_every_s) {}
  server::ServedScene* scene;
  std::string catalog_dir;  // empty: the built-in catalog
  double kmh, seconds, every_s;
  std::string frame_log;    // empty: none
  bool use_masks = true;    // false: Hello.epsilon_masks false
  bool verify = true;
  double lod_tau_px = 1.0;  // levels of detail asked for (0: off); a scene without levels sends full detail
  bool lod_clusters = false;  // cluster levels asked for with levels
};
absl::StatusOr<WalkthroughSummary> WalkWithMasks(const MaskedWalk& w) {
  absl::StatusOr<LoopbackServer> server = StartOnLoopback(w.scene);
  if (!server.ok()) return server.status();
  WalkthroughOptions o;
  o.server = server->address;
  o.headless = true;
  o.width = 320;
  o.height = 180;
  o.max_fps = 30.0;  // leave the 2-core machine to the server
  o.speed_kmh = w.kmh;
  o.seconds = w.seconds;
  o.verify = w.verify;
  o.every_s = w.every_s;
  o.frame_log = w.frame_log;
  o.use_masks = w.use_masks;
  o.lod_tau_px = w.lod_tau_px;
  o.lod_clusters = w.lod_clusters;
  o.catalog_dir = w.catalog_dir;
  o.local_scene = &w.scene->scene();
  absl::StatusOr<WalkthroughSummary> s = RunWalkthrough(o);
  if (s.ok()) {
    std::printf("%s at %g km/h for %g s: frames %llu, masked %llu (%.1f%%), holes %llu, stalls %llu, masks %llu, "
                "triangles %.0f with masks, %.0f without (%.3f), pixel error %llu in %llu checked frames\n",
                w.scene->name().c_str(), w.kmh, w.seconds, static_cast<unsigned long long>(s->frames),
                static_cast<unsigned long long>(s->frames_masked),
                s->frames > 0 ? 100.0 * static_cast<double>(s->frames_masked) / static_cast<double>(s->frames) : 0.0,
                static_cast<unsigned long long>(s->hole_frames), static_cast<unsigned long long>(s->stalls),
                static_cast<unsigned long long>(s->masks_received), s->mean_triangles_drawn,
                s->mean_triangles_without_masks,
                s->mean_triangles_without_masks > 0 ? s->mean_triangles_drawn / s->mean_triangles_without_masks : 0.0,
                static_cast<unsigned long long>(s->pixel_error), static_cast<unsigned long long>(s->checked_frames));
    if (s->lod_tau_px > 0.0 && s->server_levels) {
      std::printf("  levels at tau %g px: %llu objects and cluster levels, %llu bytes saved, geometry %llu bytes, "
                  "%llu coarse frames, differing pixels %.4f%% of those checked, the farthest %.2f px from a silhouette\n",
                  s->lod_tau_px,
                  static_cast<unsigned long long>(s->level_objects_received + s->cluster_levels_received),
                  static_cast<unsigned long long>(s->level_bytes_saved),
                  static_cast<unsigned long long>(s->geometry_bytes), static_cast<unsigned long long>(s->coarse_frames),
                  s->checked_pixels > 0 ? 100.0 * static_cast<double>(s->pixel_error) / s->checked_pixels : 0.0,
                  s->max_silhouette_px);
    }
  }
  return s;
}

TEST(ClientMasks, ACity1WalkerAt6KmhDrawsMaskedFramesWithoutHolesOrPixelError) {
  MaskedWalk w(&City1(), 6.0, 60.0, 3.0);  // 100 m of lot-lines: three viewcells
  w.frame_log = (std::filesystem::path(vistream::testing::ProcessTempDir()) / "city1_masks_frames.csv").string();
  absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(w);
  ASSERT_TRUE(s.ok()) << s.status();
  std::printf("%s", SummaryText(*s).c_str());
  EXPECT_GT(s->frames, 1000u);
  EXPECT_GT(s->masks_received, 0u);
  EXPECT_GT(static_cast<double>(s->frames_masked), 0.95 * static_cast<double>(s->frames));
  EXPECT_EQ(s->hole_frames, 0u);
  EXPECT_EQ(s->pixel_error, 0u);
  EXPECT_GE(s->checked_frames, 20u);
  EXPECT_LT(s->mean_triangles_drawn, s->mean_triangles_without_masks);

  // The frame log: the new columns at the end, consistent with the summary.
  const std::vector<std::vector<std::string>> rows = ReadCsv(w.frame_log);
  ASSERT_EQ(rows.size(), s->frames + 1);
  const std::vector<std::string>& header = rows.front();
  ASSERT_EQ(header.size(), 14u);
  EXPECT_EQ(header[10], "masked");
  EXPECT_EQ(header[11], "hole");
  EXPECT_EQ(header[12], "triangles_without_masks");
  EXPECT_EQ(header[13], "mask_id");
  uint64_t masked = 0, holes = 0;
  for (size_t k = 1; k < rows.size(); ++k) {
    ASSERT_EQ(rows[k].size(), 14u) << "line " << k;
    const bool is_masked = rows[k][10] == "1";
    masked += is_masked ? 1 : 0;
    holes += rows[k][11] == "1" ? 1 : 0;
    EXPECT_EQ(is_masked, rows[k][13] != "0") << "line " << k << ": a masked frame names its mask";
    // Masked triangles are a subset of the PVS's.
    EXPECT_LE(std::stoull(rows[k][7]), std::stoull(rows[k][12])) << "line " << k;
  }
  EXPECT_EQ(masked, s->frames_masked);
  EXPECT_EQ(holes, s->hole_frames);
  nlohmann::json j = nlohmann::json::parse(SummaryJson(*s));
  EXPECT_EQ(j["hole_frames"], s->hole_frames);
  EXPECT_EQ(j["frames_masked"], s->frames_masked);
  EXPECT_DOUBLE_EQ(j["mean_triangles_without_masks"].get<double>(), s->mean_triangles_without_masks);
  // Levels asked for (tau 1 px) from a server without any: full detail, and the summary says why.
  EXPECT_FALSE(s->server_levels);
  EXPECT_EQ(j["server_levels"], false);
  EXPECT_EQ(s->level_objects_received, 0u);
  EXPECT_NE(SummaryText(*s).find("tau 1.00 px asked for, but the server has no levels (vistream-server --levels"),
            std::string::npos)
      << SummaryText(*s);
}

TEST(ClientMasks, MaskBytesAreCreditConsumedSoAWalkerWithASmallWindowKeepsReceiving) {
  // A 512-byte credit window (masks come deflated: a few hundred bytes each): masks the client
  // did not count as consumed would leak that much credit after a few masks, and the server
  // would send nothing more.
  absl::StatusOr<LoopbackServer> server = StartOnLoopback(&City1());
  ASSERT_TRUE(server.ok()) << server.status();
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry("city1");
  ASSERT_TRUE(entry.ok()) << entry.status();
  absl::StatusOr<scenes::Walk> walk = scenes::Walk::Create(entry->walks.front(), 6.0 / 3.6);
  ASSERT_TRUE(walk.ok()) << walk.status();
  ConnectionOptions co;
  co.address = server->address;
  co.scene = "city1";
  co.credit_window_bytes = 512;
  co.epsilon_masks = true;
  co.pose_rate_hz = 20.0;
  Connection connection(co);
  connection.Start();
  const double duration_s = 40.0;
  uint64_t masks_early = 0, objects_early = 0;
  const auto start = std::chrono::steady_clock::now();
  for (;;) {
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (t > duration_s) break;
    const scenes::WalkPose pose = walk->At(t);
    connection.SetPose(pose.eye, pose.velocity, pose.yaw_rad, 0.0, t);
    (void)connection.Take();
    if (t < 0.75 * duration_s) {
      masks_early = connection.stats().masks_received;
      objects_early = connection.stats().objects_received;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  const ConnectionStats stats = connection.stats();
  EXPECT_TRUE(connection.Stop().ok());
  std::printf("masks %llu (%llu bytes), objects %llu (%llu geometry bytes); in the first 3/4: %llu masks, %llu objects\n",
              static_cast<unsigned long long>(stats.masks_received), static_cast<unsigned long long>(stats.mask_bytes),
              static_cast<unsigned long long>(stats.objects_received),
              static_cast<unsigned long long>(stats.geometry_bytes), static_cast<unsigned long long>(masks_early),
              static_cast<unsigned long long>(objects_early));
  EXPECT_GT(stats.mask_bytes, 3 * co.credit_window_bytes) << "few mask bytes: credit leaked, or too few masks to show a leak";
  EXPECT_GT(stats.masks_received, masks_early) << "masks stopped coming: credit leaked";
  EXPECT_GT(stats.objects_received, objects_early) << "geometry stopped coming: credit leaked";
}

TEST(ClientMasks, WithoutMasksTheServerSendsNoneAndBothTriangleCountsAgree) {
  MaskedWalk w(&City1(), 6.0, 15.0, 3.0);
  w.use_masks = false;  // Hello.epsilon_masks false
  w.verify = false;
  absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(w);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_GT(s->frames, 100u);
  EXPECT_EQ(s->masks_received, 0u);
  EXPECT_EQ(s->frames_masked, 0u);
  EXPECT_DOUBLE_EQ(s->mean_triangles_without_masks, s->mean_triangles_drawn);
  EXPECT_EQ(s->hole_frames, s->stalls);  // no mask: every stall is a hole
}

TEST(ClientMasks, ACity1WalkerAt60KmhDrawsMaskedFramesWithoutHolesOrPixelError) {
  // 330 m of lot-lines: seven viewcells, a corner.
  const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(MaskedWalk(&City1(), 60.0, 20.0, 1.0));
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_GT(s->frames, 300u);
  EXPECT_GT(static_cast<double>(s->frames_masked), 0.80 * static_cast<double>(s->frames));
  EXPECT_EQ(s->hole_frames, 0u);
  EXPECT_EQ(s->pixel_error, 0u);
  EXPECT_GE(s->checked_frames, 15u);
  EXPECT_LT(s->mean_triangles_drawn, s->mean_triangles_without_masks);
}

// A walker at 60 km/h who turns back twice, then turns a corner into a street the boxes ahead
// did not cover: no hole, no stall, no pixel error. (Turning back is covered by the masks of
// the boxes behind, which the client still holds.)
TEST(ClientMasks, AWalkerWhoTurnsACornerFallsBackToThePvsWithoutAHole) {
  const std::string dir = vistream::testing::ProcessTempDir() + "/turning_catalog";
  std::filesystem::create_directories(dir);
  {
    std::ifstream in(std::string(VISTREAM_SOURCE_DIR "/scenes/city1.json"));
    nlohmann::json j = nlohmann::json::parse(in);
    j["walks"] = nlohmann::json::parse(
        R"([{"name": "back-and-forth", "speed_mps": 16.7,
             "waypoints": [[-500, 280], [-500, 300], [-500, 285], [-500, 300], [-500, 350], [-420, 350]]}])");
    std::ofstream(dir + "/city1.json") << j.dump(2);
  }
  const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(MaskedWalk(&City1(), 60.0, 10.0, 0.5, dir));
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_GT(s->frames, 200u);
  EXPECT_GT(s->masks_received, 4u);
  // (The corner leaves the boxes ahead behind for a frame or two: the new box's mask comes
  // within a pose and a few ms of computing; that the frames then drew the PVS and no hole is
  // what the next test shows for a jump.)
  EXPECT_GT(static_cast<double>(s->frames_masked), 0.5 * static_cast<double>(s->frames));
  EXPECT_EQ(s->hole_frames, 0u);
  EXPECT_EQ(s->stalls, 0u);
  EXPECT_EQ(s->pixel_error, 0u);
  EXPECT_GE(s->checked_frames, 15u);
}

// Stands at `eye` (reporting it 20 times a second, the store taking what arrives as in `cell`)
// until `done` holds; false after 30 s.
bool StandUntil(Connection& connection, ObjectStore& store, const glm::dvec3& eye, uint32_t cell,
                const std::function<bool()>& done) {
  for (int k = 0; k < 600; ++k) {
    connection.SetPose(eye, glm::dvec3(0.0), 0.0, 0.0, 0.05 * k);
    store.Apply(connection.Take(), cell);
    if (done()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

// A client that jumps 20 m within its viewcell: at the new eye it holds no usable mask (the eye
// is in none of their boxes) but the cell's PVS is complete, so its frames draw the PVS, not a
// hole (client/frame_loop.cpp: a hole is no usable mask and an incomplete PVS); the server
// drops the old chain and the mask of a box around the new eye follows.
TEST(ClientMasks, AClientThatJumpsDrawsThePvsUntilTheMaskOfItsNewBoxArrives) {
  absl::StatusOr<LoopbackServer> server = StartOnLoopback(&City1());
  ASSERT_TRUE(server.ok()) << server.status();
  ConnectionOptions co;
  co.address = server->address;
  co.scene = "city1";
  co.epsilon_masks = true;
  co.pose_rate_hz = 20.0;
  Connection connection(co);
  connection.Start();
  ObjectStore store(0);
  const visibility::ViewcellGrid& grid = City1().grid();
  const uint32_t cell = grid.Id({12, 9});
  const scenes::Aabb box = grid.CellBox(cell);
  const glm::dvec3 a(box.min.x + 15.0, 0.5 * (box.min.y + box.max.y), grid.base_z() + 1.2), b = a + glm::dvec3(20.0, 0.0, 0.0);
  // Stands at a until the cell is complete and a mask holds the eye.
  auto until = [&](const glm::dvec3& eye, const std::function<bool()>& done) {
    return StandUntil(connection, store, eye, cell, done);
  };
  ASSERT_TRUE(until(a, [&] { return store.CellComplete(cell) && store.ChooseMask(a).mask != nullptr; }));
  const uint32_t mask_a = store.ChooseMask(a).mask->mask_id;
  // The jump: no held mask holds b; the PVS is complete, so the frame at b draws the PVS.
  const MaskChoice at_b = store.ChooseMask(b);
  EXPECT_EQ(at_b.mask, nullptr);
  EXPECT_FALSE(at_b.in_box);
  EXPECT_TRUE(store.CellComplete(cell));
  ASSERT_TRUE(until(b, [&] { return store.ChooseMask(b).mask != nullptr; })) << "no mask for the box at b";
  const EpsilonMaskSet* m = store.ChooseMask(b).mask;
  EXPECT_NE(m->mask_id, mask_a);
  EXPECT_EQ(m->cell, cell);
  EXPECT_TRUE(m->Contains(b));
  EXPECT_FALSE(m->Contains(a));
  EXPECT_TRUE(connection.Stop().ok());
}

// ---- Levels of detail (issue 45) ----

// What a levels walk must show: no stall, no hole, levels received and bytes saved, coarse
// frames rare (at most 1 in 100), and every differing pixel of every checked frame within
// tau + 1 px of a full-detail silhouette (no object missing, none grown by more than its error).
void ExpectLevelsHold(const WalkthroughSummary& s, double tau_px, const std::string& what) {
  EXPECT_EQ(s.stalls, 0u) << what;
  EXPECT_EQ(s.hole_frames, 0u) << what;
  EXPECT_TRUE(s.server_levels) << what;
  EXPECT_NE(SummaryText(s).find(absl::StrFormat("levels of detail at tau %.2f px", tau_px)), std::string::npos) << what;
  EXPECT_GT(s.level_objects_received, 0u) << what;
  EXPECT_GT(s.level_bytes_saved, 0u) << what;
  EXPECT_LE(static_cast<double>(s.coarse_frames), 0.01 * static_cast<double>(s.frames)) << what;
  EXPECT_GE(s.checked_frames, 8u) << what;
  EXPECT_LE(s.max_silhouette_px, tau_px + 1.0) << what;
}

// A town of london's generator (1.6 km, 100 m viewcells, tests/simulator/london_small.json:
// irregular streets) on its diagonal walk, served with levels of detail. Asking for none (--lod
// off), at 6 and at 60 km/h: masked frames, no hole, pixel error 0 (the full scene exactly).
// Asking for tau = 1 px, at 6 and 60 km/h: the levels hold (ExpectLevelsHold).
TEST(ClientMasks, ALondonTownWalkerAt6And60KmhDrawsMaskedFramesAndLevelsWithinTauOfEverySilhouette) {
  const std::string dir = vistream::testing::ProcessTempDir() + "/london_town_catalog";
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(std::string(VISTREAM_SOURCE_DIR "/tests/simulator/london_small.json"),
                             dir + "/london-small.json", std::filesystem::copy_options::overwrite_existing);
  absl::StatusOr<std::unique_ptr<server::ServedScene>> town =
      ServeForMasks(dir + "/london-small.json", 64, /*levels=*/true);
  ASSERT_TRUE(town.ok()) << town.status();
  ASSERT_NE((*town)->levels(), nullptr);
  for (const double kmh : {6.0, 60.0}) {
    MaskedWalk off(town->get(), kmh, kmh < 10 ? 30.0 : 20.0, 2.0, dir);
    off.lod_tau_px = 0.0;
    const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(off);
    ASSERT_TRUE(s.ok()) << s.status();
    EXPECT_EQ(s->path, "across");
    EXPECT_GT(s->frames, 300u) << kmh;
    EXPECT_GT(static_cast<double>(s->frames_masked), (kmh < 10 ? 0.95 : 0.80) * static_cast<double>(s->frames)) << kmh;
    EXPECT_EQ(s->hole_frames, 0u) << kmh;
    EXPECT_EQ(s->pixel_error, 0u) << kmh;
    EXPECT_GE(s->checked_frames, 10u) << kmh;
    EXPECT_LT(s->mean_triangles_drawn, s->mean_triangles_without_masks) << kmh;
    EXPECT_EQ(s->level_objects_received, 0u) << kmh;
  }
  for (const double kmh : {6.0, 60.0}) {
    const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(MaskedWalk(town->get(), kmh, 9.0, 1.0, dir));
    ASSERT_TRUE(s.ok()) << s.status();
    EXPECT_GT(s->frames, 100u) << kmh;
    ExpectLevelsHold(*s, 1.0, absl::StrCat("london-small at ", kmh, " km/h"));
  }
}

// Cluster levels drawn by the native client (issue 45): the london-generated town at 1 px, where
// lists choose clusters, at 6 and 60 km/h: some arrive, each object a cluster stands for is
// drawn as its piece (through the mask's bits where the level keeps the triangles), and the
// frames hold within tau + 1 px of every full-detail silhouette (the object-id buffer names the
// piece's object); against the same walk without clusters, no more triangles a frame.
TEST(ClientMasks, ALondonTownWalkerDrawsClusterLevelsAsPiecesWithinTauOfEverySilhouette) {
  const std::string dir = vistream::testing::ProcessTempDir() + "/london_town_clusters";
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(std::string(VISTREAM_SOURCE_DIR "/tests/simulator/london_small.json"),
                             dir + "/london-small.json", std::filesystem::copy_options::overwrite_existing);
  absl::StatusOr<std::unique_ptr<server::ServedScene>> town =
      ServeForMasks(dir + "/london-small.json", 64, /*levels=*/true);
  ASSERT_TRUE(town.ok()) << town.status();
  for (const double kmh : {6.0, 60.0}) {
    MaskedWalk on(town->get(), kmh, kmh < 10 ? 20.0 : 10.0, 1.0, dir);
    on.lod_clusters = true;
    const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(on);
    ASSERT_TRUE(s.ok()) << s.status();
    EXPECT_GT(s->cluster_levels_received, 0u) << kmh;
    ExpectLevelsHold(*s, 1.0, absl::StrCat("london-small at ", kmh, " km/h with clusters"));
    MaskedWalk off = on;
    off.lod_clusters = false;
    const absl::StatusOr<WalkthroughSummary> o = WalkWithMasks(off);
    ASSERT_TRUE(o.ok()) << o.status();
    EXPECT_EQ(o->cluster_levels_received, 0u) << kmh;
    EXPECT_LE(s->mean_triangles_drawn, 1.05 * o->mean_triangles_drawn) << kmh;
  }
}

// A real city model (issue 35): Den Haag's tile 01 served from the catalog (imported from
// ../shared/data/citymodels: LoD2 buildings on a TIN, cells following it) with levels of detail,
// the walker along the walk the server derived from the data ("walk 1": the catalog entry has
// none of its own, so the client takes the server's first). Asking for none, at 6 km/h: no
// stall, no hole, pixel error 0, the eye over the terrain inside each cell's band. Asking for
// tau = 1 px at 6 and 60 km/h: the levels hold (ExpectLevelsHold).
TEST(ClientMasks, ADenHaagWalkerAlongADerivedWalkDrawsMaskedFramesAndLevelsWithinTauOfEverySilhouette) {
  const std::string data = std::string(VISTREAM_SOURCE_DIR "/../shared/data/citymodels/denhaag_01.city.json");
  if (!std::filesystem::exists(data)) GTEST_SKIP() << data << " is absent: Den Haag is not walked";
  absl::StatusOr<std::unique_ptr<server::ServedScene>> city = ServeForMasks("denhaag", 128, /*levels=*/true);
  ASSERT_TRUE(city.ok()) << city.status();
  ASSERT_FALSE((*city)->scene().paths.empty()) << "no walk derived from the data";
  ASSERT_FALSE((*city)->scene().terrain.empty());
  {
    MaskedWalk off(city->get(), 6.0, 15.0, 1.0);
    off.lod_tau_px = 0.0;
    const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(off);
    ASSERT_TRUE(s.ok()) << s.status();
    EXPECT_EQ(s->path, "walk 1");
    EXPECT_GT(s->frames, 150u);
    EXPECT_EQ(s->stalls, 0u);
    EXPECT_GT(static_cast<double>(s->frames_masked), 0.8 * static_cast<double>(s->frames));
    EXPECT_EQ(s->hole_frames, 0u);
    EXPECT_EQ(s->pixel_error, 0u);
    EXPECT_GE(s->checked_frames, 10u);
  }
  for (const double kmh : {6.0, 60.0}) {
    const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(MaskedWalk(city->get(), kmh, 10.0, 1.0));
    ASSERT_TRUE(s.ok()) << s.status();
    EXPECT_EQ(s->path, "walk 1");
    EXPECT_GT(s->frames, 100u) << kmh;
    ExpectLevelsHold(*s, 1.0, absl::StrCat("denhaag at ", kmh, " km/h"));
  }
}

// A surface model (issue 46: tests/citymodel/terraces.city.json, imported as the CLI does): its
// houses closed by their neighbours and the ground occlude, and a walker towards the row's open
// end and along its street draws masked frames with no pixel error, no hole and no stall (the
// party wall r3 draws towards r4 is what a viewer looking in there sees: without it, r3's inside
// shows past its occluders, hidden by the masks).
TEST(ClientMasks, ASurfaceModelWalkerDrawsMaskedFramesWithoutPixelError) {
  scenes::CityImportOptions io;
  scenes::CityImportSummary sum;
  absl::StatusOr<scenes::Scene> city =
      scenes::ImportCity(VISTREAM_SOURCE_DIR "/tests/citymodel/terraces.city.json", io, &sum);
  ASSERT_TRUE(city.ok()) << city.status();
  ASSERT_EQ(sum.buildings_with_occluder, 8u);
  // The walk: west towards the row's open end (r4 lacks its end wall at x = 24: through it the
  // walker looks into r4 and on into r3, where r3's occluders stand), then along the street in
  // front of the row. Model coordinates are relative to (85000, 446000).
  const glm::dvec2 at = glm::dvec2(85000.0, 446000.0) - glm::dvec2(city->origin);
  city->paths = {scenes::ScenePath{"the open end", {at + glm::dvec2(38, 5), at + glm::dvec2(25, 5),
                                                    at + glm::dvec2(25, -10), at + glm::dvec2(-5, -10)}}};
  const std::string glb = (std::filesystem::path(vistream::testing::ProcessTempDir()) / "terraces.glb").string();
  ASSERT_TRUE(scenes::SaveGltf(*city, glb).ok());
  server::ServedSceneOptions o;
  o.scene = glb;
  o.cell_size = 10.0;
  o.res = 128;
  o.threads = 2;
  o.idle_priority_masks = false;
  absl::StatusOr<std::unique_ptr<server::ServedScene>> served = server::ServedScene::Create(o);
  ASSERT_TRUE(served.ok()) << served.status();
  const absl::StatusOr<WalkthroughSummary> s = WalkWithMasks(MaskedWalk(served->get(), 6.0, 25.0, 1.0));
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->path, "the open end");
  EXPECT_GT(s->frames, 250u);
  EXPECT_EQ(s->stalls, 0u);
  EXPECT_GT(static_cast<double>(s->frames_masked), 0.8 * static_cast<double>(s->frames));
  EXPECT_LT(s->mean_triangles_drawn, s->mean_triangles_without_masks) << "the masks hide nothing";
  EXPECT_EQ(s->hole_frames, 0u);
  EXPECT_EQ(s->pixel_error, 0u);
  EXPECT_GE(s->checked_frames, 20u);
}

// A client resuming with levels tells the server the level of each object it holds
// (Hello.held_levels): the server sends a finer level where a cell needs one, and never the
// same level again.
TEST(ClientLevels, AResumedSessionSaysTheLevelsItHoldsAndGetsOnlyFinerOnes) {
  absl::StatusOr<std::unique_ptr<server::ServedScene>> town = ServeForMasks("default", 64, /*levels=*/true);
  ASSERT_TRUE(town.ok()) << town.status();
  absl::StatusOr<LoopbackServer> server = StartOnLoopback(town->get());
  ASSERT_TRUE(server.ok()) << server.status();
  ConnectionOptions co;
  co.address = server->address;
  co.scene = "default";
  co.screen_error_px = 1.0;
  co.viewport_width_px = 320;
  co.viewport_height_px = 180;
  co.pose_rate_hz = 20.0;
  Connection connection(co);
  connection.Start();
  ObjectStore store(0);
  const visibility::ViewcellGrid& grid = (*town)->grid();
  const uint32_t cell = grid.Id({10, 10});
  const scenes::Aabb box = grid.CellBox(cell);
  const glm::dvec3 eye(0.5 * (box.min.x + box.max.x), 0.5 * (box.min.y + box.max.y), grid.base_z() + 1.2);
  auto until = [&](const std::function<bool()>& done) { return StandUntil(connection, store, eye, cell, done); };
  ASSERT_TRUE(until([&] { return store.CellComplete(cell); }));
  const std::vector<uint32_t>* levels = store.PvsLevels(cell);
  ASSERT_NE(levels, nullptr);
  ASSERT_EQ(levels->size(), store.Pvs(cell)->size());
  size_t at_level = 0;
  for (size_t k = 0; k < levels->size(); ++k) {
    const StoredObject* o = store.Find((*store.Pvs(cell))[k]);
    ASSERT_NE(o, nullptr);
    EXPECT_LE(o->data.level, (*levels)[k]) << "object " << o->data.id;
    at_level += o->data.level > 0 ? 1 : 0;
  }
  EXPECT_GT(at_level, 0u);
  const ConnectionStats before = connection.stats();
  EXPECT_GT(before.level_objects, 0u);
  EXPECT_GT(before.level_bytes_saved, 0u);
  // Drop the link: the client resumes saying what it holds at which level.
  connection.DropForTest();
  bool resumed = false;  // the new session's SceneInfo arrived
  for (int k = 0; k < 600 && !resumed; ++k) {
    connection.SetPose(eye, glm::dvec3(0.0), 0.0, 0.0, 30.0 + 0.05 * k);
    std::vector<Event> events = connection.Take();
    for (const Event& e : events) resumed = resumed || std::holds_alternative<v1::SceneInfo>(e);
    store.Apply(std::move(events), cell);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_TRUE(resumed);
  std::this_thread::sleep_for(std::chrono::seconds(2));
  store.Apply(connection.Take(), cell);
  EXPECT_EQ(connection.stats().duplicates, 0u) << "the resumed session sent a level the client held";
  EXPECT_TRUE(store.CellComplete(cell));
  // Two cells on, the objects near there need finer levels than the client held: the resumed
  // server, told which, sends them (one told "full" would send none).
  const uint32_t next = grid.Id({12, 10});
  const scenes::Aabb nb = grid.CellBox(next);
  const glm::dvec3 there(0.5 * (nb.min.x + nb.max.x), 0.5 * (nb.min.y + nb.max.y), eye.z);
  size_t finer_needed = 0;
  auto at_levels = [&]() {
    if (!store.CellComplete(next) || store.PvsLevels(next) == nullptr) return false;
    const std::vector<uint32_t>& list = *store.Pvs(next);
    for (size_t k = 0; k < list.size(); ++k) {
      if (store.Find(list[k])->data.level > (*store.PvsLevels(next))[k]) return false;
    }
    return true;
  };
  for (int k = 0; k < 600 && !at_levels(); ++k) {
    connection.SetPose(there, glm::dvec3(0.0), 0.0, 0.0, 100.0 + 0.05 * k);
    std::vector<Event> events = connection.Take();
    for (const Event& e : events) {
      if (const ReceivedObject* o = std::get_if<ReceivedObject>(&e); o != nullptr && store.Find(o->id) != nullptr &&
                                                                     o->level < store.Find(o->id)->data.level) {
        ++finer_needed;
      }
    }
    store.Apply(std::move(events), next);
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_TRUE(at_levels()) << "the resumed session left objects coarser than the cell asks";
  EXPECT_GT(finer_needed, 0u) << "no object needed a finer level: the walk shows nothing";
  ASSERT_TRUE(connection.Stop().ok());
}

}  // namespace
}  // namespace vistream::client
