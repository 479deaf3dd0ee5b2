#include "scenes/catalog.h"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include <gtest/gtest.h>

#include "scenes/city_generator.h"
#include "scenes/gltf_io.h"
#include "scenes/progress.h"
#include "tests/temp_dir.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

const char* kMinimal = R"({
  "name": "t",
  "source": {"generator": "city1"},
  "viewcell": {"size_m": 50, "height_m": 2}
})";

absl::Status ParseError(const std::string& text) {
  return ParseCatalogEntry(text, "scenes/t.json", "/base").status();
}

void ExpectErrorMentions(const std::string& text, std::initializer_list<const char*> parts) {
  const absl::Status s = ParseError(text);
  ASSERT_FALSE(s.ok()) << "accepted: " << text;
  EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("scenes/t.json"), std::string::npos) << s;
  for (const char* p : parts) EXPECT_NE(s.message().find(p), std::string::npos) << "missing '" << p << "' in " << s;
}

TEST(Catalog, MinimalEntryGetsDefaults) {
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(kMinimal, "t.json", "/base");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->source.kind, SceneSource::Kind::kGenerator);
  EXPECT_EQ(e->source.generator, "city1");
  EXPECT_EQ(e->source.seed, 1u);
  EXPECT_EQ(e->viewcell.size_m, 50.0);
  EXPECT_EQ(e->viewcell.base_m, 0.5);
  EXPECT_TRUE(e->walks.empty());
  EXPECT_FALSE(e->simulation.link.has_value());
  EXPECT_FALSE(e->simulation.client.has_value());
}

TEST(Catalog, OnlyDeclaredSimulationEffectsArePresent) {
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(R"({
    "name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 50, "height_m": 2},
    "simulation": {"link": {"latency_ms": 30}}})", "t.json", "/base");
  ASSERT_TRUE(e.ok()) << e.status();
  ASSERT_TRUE(e->simulation.link.has_value());
  EXPECT_EQ(e->simulation.link->latency_ms, 30.0);
  EXPECT_FALSE(e->simulation.link->bandwidth_mbps.has_value());
  EXPECT_FALSE(e->simulation.link->loss_pct.has_value());
  EXPECT_FALSE(e->simulation.client.has_value());
}

TEST(Catalog, ClientFrameTimeIsAnEffectOfItsOwn) {
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(R"({
    "name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 50, "height_m": 2},
    "simulation": {"client": {"frame_ms": 16.7}}})", "t.json", "/base");
  ASSERT_TRUE(e.ok()) << e.status();
  ASSERT_TRUE(e->simulation.client.has_value());
  EXPECT_EQ(e->simulation.client->frame_ms, 16.7);
  EXPECT_FALSE(e->simulation.client->memory_mb.has_value());
  EXPECT_FALSE(e->simulation.client->triangle_budget.has_value());
  EXPECT_FALSE(e->simulation.link.has_value());
}

TEST(Catalog, FogIsOnOnlyWhereTheEntryDeclaresItAndItsRangeIsChecked) {
  absl::StatusOr<CatalogEntry> plain = ParseCatalogEntry(kMinimal, "t.json", "/base");
  ASSERT_TRUE(plain.ok()) << plain.status();
  EXPECT_FALSE(plain->effects.fog.has_value());
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(R"({
    "name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 50, "height_m": 2},
    "effects": {"fog": {"start_m": 400, "end_m": 2500}}})", "t.json", "/base");
  ASSERT_TRUE(e.ok()) << e.status();
  ASSERT_TRUE(e->effects.fog.has_value());
  EXPECT_EQ(e->effects.fog->start_m, 400.0);
  EXPECT_EQ(e->effects.fog->end_m, 2500.0);
  const std::string head = R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 50, "height_m": 2}, )";
  ExpectErrorMentions(head + R"("effects": {"fog": {"start_m": 500, "end_m": 400}}})",
                      {"effects.fog.end_m", "beyond start_m"});
  ExpectErrorMentions(head + R"("effects": {"fog": {"start_m": -1, "end_m": 400}}})", {"effects.fog.start_m"});
  ExpectErrorMentions(head + R"("effects": {"fog": {"end_m": 400}}})", {"effects.fog.start_m", "missing"});
  ExpectErrorMentions(head + R"("effects": {"rain": true}})", {"effects.rain", "unknown key"});
  ExpectErrorMentions(head + R"("effects": {"fog": {"start_m": 1, "end_m": 400, "colour": 3}}})",
                      {"effects.fog.colour", "unknown key"});
}

TEST(Catalog, GltfSourceResolvesAgainstTheCatalogFolder) {
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(
      R"({"name": "t", "source": {"gltf": "../data/x.glb"}, "viewcell": {"size_m": 50, "height_m": 2}})",
      "t.json", "/base/scenes");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->source.path, "/base/data/x.glb");
  absl::StatusOr<Scene> scene = BuildScene(*e);
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("/base/data/x.glb"), std::string::npos) << scene.status();
}

TEST(Catalog, OsmSourceResolvesItsFileAndReadsItsBox) {
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(
      R"({"name": "t", "source": {"osm": "../data/x.osm.pbf", "bbox": "7.4,43.7,7.5,43.8", "storey_m": 3.5,
                                 "max_height_m": 900},
          "viewcell": {"size_m": 50, "height_m": 2}})",
      "t.json", "/base/scenes");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->source.kind, SceneSource::Kind::kOsm);
  EXPECT_EQ(e->source.path, "/base/data/x.osm.pbf");
  ASSERT_TRUE(e->source.osm.bbox.has_value());
  EXPECT_DOUBLE_EQ(e->source.osm.bbox->max_lat, 43.8);
  EXPECT_DOUBLE_EQ(e->source.osm.storey_m, 3.5);
  EXPECT_DOUBLE_EQ(e->source.osm.max_height_m, 900.0);
  absl::StatusOr<Scene> scene = BuildScene(*e);
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("/base/data/x.osm.pbf: no such file"), std::string::npos) << scene.status();

  const absl::Status bad_box = ParseError(
      R"({"name": "t", "source": {"osm": "x.osm", "bbox": "7.4,43.7"}, "viewcell": {"size_m": 50, "height_m": 2}})");
  EXPECT_NE(bad_box.message().find("key 'source.bbox'"), std::string::npos) << bad_box;
  const absl::Status two = ParseError(
      R"({"name": "t", "source": {"osm": "x.osm", "gltf": "x.glb"}, "viewcell": {"size_m": 50, "height_m": 2}})");
  EXPECT_NE(two.message().find("exactly one of 'generator', 'gltf', 'osm' or 'city'"), std::string::npos) << two;
  const absl::Status unknown = ParseError(
      R"({"name": "t", "source": {"osm": "x.osm", "seed": 3}, "viewcell": {"size_m": 50, "height_m": 2}})");
  EXPECT_NE(unknown.message().find("unknown key"), std::string::npos) << unknown;
  const absl::Status low = ParseError(
      R"({"name": "t", "source": {"osm": "x.osm", "max_height_m": 5}, "viewcell": {"size_m": 50, "height_m": 2}})");
  EXPECT_NE(low.message().find("key 'source.max_height_m'"), std::string::npos) << low;
}

TEST(Catalog, CitySourceReadsItsGround) {
  absl::StatusOr<CatalogEntry> e = ParseCatalogEntry(
      R"({"name": "t", "source": {"city": "x.city.json", "lod": 1}, "viewcell": {"size_m": 50, "height_m": 2}})", "t.json",
      "/base/scenes");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->source.kind, SceneSource::Kind::kCity);
  EXPECT_EQ(e->source.city.lod, 1);
  EXPECT_EQ(e->source.city.ground, CityGround::kDerived) << "the default";
  e = ParseCatalogEntry(
      R"({"name": "t", "source": {"city": "x.city.json", "ground": "none"}, "viewcell": {"size_m": 50, "height_m": 2}})",
      "t.json", "/base/scenes");
  ASSERT_TRUE(e.ok()) << e.status();
  EXPECT_EQ(e->source.city.ground, CityGround::kNone);
  ExpectErrorMentions(
      R"({"name": "t", "source": {"city": "x.city.json", "ground": "flat"}, "viewcell": {"size_m": 50, "height_m": 2}})",
      {"key 'source.ground'", "'flat' is not 'derived'"});
}

TEST(Catalog, MalformedJsonGivesLineAndColumn) {
  const absl::Status s = ParseError("{\n  \"name\": \"t\",\n  \"source\": {,}\n}");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("scenes/t.json:3:"), std::string::npos) << s;
  EXPECT_NE(s.message().find("malformed JSON"), std::string::npos) << s;
  ExpectErrorMentions("", {"malformed JSON"});
  ExpectErrorMentions(R"({"name": "t", "viewcell": {"size_m": NaN}})", {"malformed JSON"});
  // Found by catalog_fuzz: a number out of double's range threw out of the parser.
  ExpectErrorMentions(R"({"name": "t", "viewcell": {"size_m": 1e999}})", {"malformed JSON"});
}

TEST(Catalog, UnknownKeysAreNamedWithTheirPath) {
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"sise_m": 5, "height_m": 2}})",
                      {"viewcell.sise_m", "unknown key"});
  ExpectErrorMentions(R"({"name": "t", "colour": 1, "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2}})",
                      {"'colour'", "unknown key"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1", "width_m": 300},
                          "viewcell": {"size_m": 5, "height_m": 2}})",
                      {"source.width_m", "unknown key"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "simulation": {"link": {"latency": 3}}})",
                      {"simulation.link.latency"});
}

TEST(Catalog, WrongTypesMissingKeysAndBadRangesAreErrors) {
  ExpectErrorMentions(R"({"source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2}})", {"'name'", "missing"});
  ExpectErrorMentions(R"({"name": 3, "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2}})",
                      {"'name'", "expected a string"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": -5, "height_m": 2}})",
                      {"viewcell.size_m", "-5"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": "big", "height_m": 2}})",
                      {"viewcell.size_m", "expected a number"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1", "seed": -1}, "viewcell": {"size_m": 5, "height_m": 2}})",
                      {"source.seed", "non-negative integer"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "tokyo"}, "viewcell": {"size_m": 5, "height_m": 2}})",
                      {"source.generator", "tokyo"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1", "gltf": "x.glb"}, "viewcell": {"size_m": 5, "height_m": 2}})",
                      {"'source'", "exactly one"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "walks": [{"name": "w", "waypoints": [[0, 0]]}]})",
                      {"walks[0].waypoints", "at least 2"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "walks": [{"name": "w", "waypoints": [[0, 0], [1, "x"]]}]})",
                      {"walks[0].waypoints[1]"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "walks": [{"name": "w", "speed_mps": 0, "waypoints": [[0, 0], [1, 1]]}]})",
                      {"walks[0].speed_mps"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "simulation": {"link": {"loss_pct": 150}}})",
                      {"simulation.link.loss_pct"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "simulation": {"client": {"frame_ms": 0}}})",
                      {"simulation.client.frame_ms"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "simulation": {"client": {"frame_time": 16}}})",
                      {"simulation.client.frame_time"});
  ExpectErrorMentions(R"({"name": "t", "source": {"generator": "city1"}, "viewcell": {"size_m": 5, "height_m": 2},
                          "simulation": {"link": {"bandwidth_mbps": "fast"}}})",
                      {"simulation.link.bandwidth_mbps", "expected a number"});
  ExpectErrorMentions(R"([1, 2])", {"expected an object"});
}

TEST(Catalog, ShippedEntriesParseAndTheirWalksFollowStreets) {
  const std::vector<std::string> names = CatalogNames();
  for (const char* required : {"default", "city1", "city2", "london", "monaco", "streets"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), required), names.end()) << required;
  }
  size_t built = 0;
  std::string absent;  // entries whose data is not here
  for (const std::string& name : names) {
    absl::StatusOr<CatalogEntry> e = FindCatalogEntry(name);
    ASSERT_TRUE(e.ok()) << e.status();
    EXPECT_EQ(e->name, name);
    // Entries reading data from outside the repository (../shared/data) are built where that
    // data is present; where it is not, the test ends as a skip naming them (CI fails on it).
    if (e->source.kind != SceneSource::Kind::kGenerator && !std::filesystem::exists(e->source.path)) {
      absent += " " + name + " (" + e->source.path + ")";
      continue;
    }
    ++built;
    absl::StatusOr<Scene> scene = BuildScene(*e);
    ASSERT_TRUE(scene.ok()) << scene.status();
    // The entry's walks and those the data gives (a city model's roads or free space).
    const std::vector<WalkPath> walks = WalksWithScenePaths(e->walks, *scene);
    EXPECT_FALSE(walks.empty()) << name << " has no walk path";
    // Buildings only: the terrain's occluders are the ground walked on.
    Scene buildings = *scene;
    std::erase_if(buildings.occluders, [&](const Occluder25D& oc) {
      return std::binary_search(scene->terrain.begin(), scene->terrain.end(), oc.object);
    });
    for (size_t i = 0; i < walks.size(); ++i) {
      const WalkPath& w = walks[i];
      // The catalog's walks keep a metre from every building; those derived from a street map
      // follow the streets' centre lines, which may pass under a building (an arcade, a
      // passage): they are checked on the walks' tests (derived_walks_test, osm_walks_test).
      if (i >= e->walks.size() && e->source.kind == SceneSource::Kind::kOsm) continue;
      for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
        EXPECT_TRUE(testing::SegmentClearOfOccluders(buildings, w.waypoints[k], w.waypoints[k + 1], 1.0))
            << name << ": walk '" << w.name << "' leg " << k << " runs into a building";
      }
    }
  }
  EXPECT_GE(built, 5u);  // the generated ones at least
  if (!absent.empty()) GTEST_SKIP() << "data absent, walks not checked:" << absent;
}

TEST(Catalog, UnknownNameListsTheKnownOnes) {
  absl::StatusOr<CatalogEntry> e = FindCatalogEntry("atlantis");
  ASSERT_FALSE(e.ok());
  EXPECT_EQ(e.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(e.status().message().find("london"), std::string::npos) << e.status();
}

TEST(Catalog, DefaultFolderIsTheEnvironmentThenTheInstalledCatalogThenTheSourceTree) {
  // An installed tree: PREFIX/bin/vistream-server and PREFIX/share/vistream/scenes.
  const std::filesystem::path prefix = vistream::testing::ProcessTempDir() + "/catalog_prefix";
  const std::filesystem::path exe = prefix / "bin" / "vistream-server";
  const std::string source = "/src/vistream/scenes";

  // Nothing installed beside the program (a build tree's bin/): the source tree.
  std::filesystem::create_directories(prefix / "bin");
  EXPECT_EQ(CatalogDirFrom(nullptr, exe, source), source);
  EXPECT_EQ(CatalogDirFrom("", exe, source), source);  // an empty variable is unset
  EXPECT_EQ(CatalogDirFrom(nullptr, "", source), source);  // the program's path unknown

  // Installed: PREFIX/share/vistream/scenes, even where the source tree still exists.
  std::filesystem::create_directories(prefix / "share" / "vistream" / "scenes");
  EXPECT_EQ(CatalogDirFrom(nullptr, exe, source), (prefix / "share" / "vistream" / "scenes").string());
  // A file of that name is no catalog.
  const std::filesystem::path other = vistream::testing::ProcessTempDir() + "/catalog_file_prefix";
  std::filesystem::create_directories(other / "bin");
  std::filesystem::create_directories(other / "share" / "vistream");
  std::FILE* f = std::fopen((other / "share" / "vistream" / "scenes").c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::fclose(f);
  EXPECT_EQ(CatalogDirFrom(nullptr, other / "bin" / "vistream", source), source);

  // $VISTREAM_SCENES wins over both, existing or not (FindCatalogEntry says when it is missing).
  EXPECT_EQ(CatalogDirFrom("/elsewhere/scenes", exe, source), "/elsewhere/scenes");

  // This test program lives in the build tree: the compiled-in source tree's scenes/ (or the
  // variable, when the run sets it).
  const char* env = std::getenv("VISTREAM_SCENES");
  EXPECT_EQ(CatalogDir(), env != nullptr && *env != '\0' ? std::string(env) : std::string(VISTREAM_SOURCE_DIR "/scenes"));
}

TEST(Catalog, LoadSceneTakesNamesPathsAndAnotherCatalogFolder) {
  // A folder of its own with one entry: found there by name, and not in the default catalog.
  const std::string dir = vistream::testing::ProcessTempDir() + "/catalog_elsewhere";
  std::filesystem::create_directories(dir);
  std::FILE* f = std::fopen((dir + "/tiny.json").c_str(), "w");
  ASSERT_NE(f, nullptr);
  std::fputs(R"({"name": "tiny", "source": {"generator": "city1"}, "viewcell": {"size_m": 40, "height_m": 3}})", f);
  std::fclose(f);
  LoadOptions there;
  there.catalog_dir = dir;
  absl::StatusOr<LoadedScene> s = LoadScene("tiny", there);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->scene.name, "tiny");
  EXPECT_EQ(s->viewcell.size_m, 40);
  EXPECT_EQ(s->viewcell.height_m, 3);
  ASSERT_TRUE(s->entry.has_value());
  EXPECT_EQ(s->entry->file, dir + "/tiny.json");
  EXPECT_GT(s->scene.objects.size(), 2000u);
  EXPECT_EQ(ViewcellSpecFor("tiny", 0, dir).size_m, 40);
  EXPECT_EQ(ViewcellSpecFor("tiny", 25, dir).size_m, 25);
  EXPECT_EQ(ViewcellSpecFor(dir + "/tiny.json", 0).size_m, 40);  // a path needs no folder

  const absl::Status unknown = LoadScene("tiny").status();  // not in the default catalog
  EXPECT_EQ(unknown.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(unknown.message().find("'tiny'"), std::string::npos) << unknown;
  const absl::Status elsewhere = LoadScene("london", there).status();
  EXPECT_EQ(elsewhere.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(elsewhere.message().find(dir), std::string::npos) << elsewhere;
  EXPECT_NE(elsewhere.message().find("tiny"), std::string::npos) << elsewhere;  // what it has
  EXPECT_EQ(LoadScene("").status().code(), absl::StatusCode::kNotFound);
  LoadOptions nowhere;
  nowhere.catalog_dir = dir + "/missing";
  const absl::Status no_folder = LoadScene("tiny", nowhere).status();
  EXPECT_EQ(no_folder.code(), absl::StatusCode::kNotFound);
  EXPECT_NE(no_folder.message().find("catalog folder " + dir + "/missing does not exist"), std::string::npos)
      << no_folder;
  EXPECT_FALSE(LoadScene(dir + "/missing.glb").ok());
  EXPECT_TRUE(IsGltfPath("a/b.glb"));
  EXPECT_TRUE(IsGltfPath("b.gltf"));
  EXPECT_FALSE(IsGltfPath("london"));
  EXPECT_FALSE(IsGltfPath("x.json"));
}

// Records what a computation reports, as a caller's sink would receive it.
class RecordingSink : public ProgressSink {
 public:
  void Start(std::string_view label, uint64_t total) override {
    labels.emplace_back(label);
    totals.push_back(total);
  }
  void Update(std::string_view, uint64_t done, uint64_t total, double, std::string_view) override {
    EXPECT_LE(done, total);
    if (!dones.empty()) {
      EXPECT_GE(done, dones.back());
    }
    dones.push_back(done);
  }
  void End(std::string_view, double seconds, bool completed) override {
    EXPECT_GE(seconds, 0.0);
    ends.push_back(completed);
  }
  std::vector<std::string> labels;
  std::vector<uint64_t> totals, dones;
  std::vector<bool> ends;
};

TEST(Progress, ReportsToTheCallersSinkAndSaysWhenStoppedEarly) {
  RecordingSink sink;
  LoadOptions reported;
  reported.run.progress = &sink;
  absl::StatusOr<LoadedScene> s = LoadScene("streets", reported);
  ASSERT_TRUE(s.ok()) << s.status();
  // The streets generator reports nothing; a tracked task reports start, steps and end.
  {
    Progress p({.progress = &sink}, "work", 10000);
    for (int i = 0; i < 10000; ++i) p.Advance();
    p.Finish();
  }
  ASSERT_EQ(sink.labels.back(), "work");
  EXPECT_EQ(sink.totals.back(), 10000u);
  EXPECT_LE(sink.dones.size(), 1002u);  // at most once a thousandth, and once at the end
  EXPECT_EQ(sink.dones.back(), 10000u);
  ASSERT_FALSE(sink.ends.empty());
  EXPECT_TRUE(sink.ends.back());

  // Cancelled: london's generator stops and its task ends as stopped, not done.
  std::atomic<bool> cancel{true};
  RecordingSink stopped;
  LondonOptions small;
  small.width_m = small.depth_m = 2000;
  (void)GenerateLondon(small, {.progress = &stopped, .cancel = &cancel});
  ASSERT_EQ(stopped.labels.size(), 1u);
  EXPECT_EQ(stopped.labels[0], "generating london");
  ASSERT_EQ(stopped.ends.size(), 1u);
  EXPECT_FALSE(stopped.ends[0]);

  // No sink: nothing reported, nothing printed, the work still done.
  LondonOptions tiny = small;
  EXPECT_GT(GenerateLondon(tiny, {}).objects.size(), 100u);
}

}  // namespace
}  // namespace vistream::scenes

namespace vistream::scenes {
namespace {

TEST(Catalog, DeclaredWalksGoFirstIntoTheScenesPathsAndReplaceThoseOfTheirNames) {
  Scene scene;
  scene.paths = {{"street 1", {{0, 0}, {100, 0}}}, {"street 2", {{0, 0}, {0, 100}}}};
  WalkPath mine{"mine", 2.5, 1.6, {{1, 1}, {2, 2}}};
  WalkPath street{"street 1", 1.4, 1.7, {{5, 5}, {6, 6}}};
  WalkPath dot{"dot", 1.4, 1.7, {{3, 3}}};  // one waypoint: no walk
  AddDeclaredWalks({mine, street, dot}, &scene);
  ASSERT_EQ(scene.paths.size(), 3u);
  EXPECT_EQ(scene.paths[0].name, "mine");
  EXPECT_EQ(scene.paths[0].waypoints, mine.waypoints);
  EXPECT_EQ(scene.paths[1].name, "street 1");
  EXPECT_EQ(scene.paths[1].waypoints, street.waypoints);  // the declared one
  EXPECT_EQ(scene.paths[2].name, "street 2");
}

TEST(Catalog, LoadSceneFollowsTheEntrysWalksWithTheScenesOwn) {
  const std::string dir = vistream::testing::ProcessTempDir() + "/catalog_paths";
  std::filesystem::create_directories(dir);
  Scene scene = GenerateTestCity(true, 1);
  scene.paths = {{"street 1", {{0, 0}, {100, 0}}}, {"street 2", {{0, 0}, {0, 100}}}};
  ASSERT_TRUE(SaveGltf(scene, dir + "/walked.glb").ok());
  std::FILE* f = std::fopen((dir + "/walked.json").c_str(), "w");
  ASSERT_NE(f, nullptr);
  // The entry names one walk like the scene's first: the entry's is kept, the scene's skipped.
  std::fputs(R"({"name": "walked", "source": {"gltf": "walked.glb"}, "viewcell": {"size_m": 50, "height_m": 2},
                 "walks": [{"name": "mine", "speed_mps": 2.5, "eye_height_m": 1.6, "waypoints": [[1, 1], [2, 2]]},
                           {"name": "street 1", "waypoints": [[5, 5], [6, 6]]}]})",
             f);
  std::fclose(f);
  LoadOptions there;
  there.catalog_dir = dir;
  absl::StatusOr<LoadedScene> s = LoadScene("walked", there);
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->walks.size(), 3u);
  EXPECT_EQ(s->walks[0].name, "mine");
  EXPECT_EQ(s->walks[1].name, "street 1");
  EXPECT_EQ(s->walks[1].waypoints, (std::vector<glm::dvec2>{{5, 5}, {6, 6}}));  // the entry's
  EXPECT_EQ(s->walks[2].name, "street 2");
  EXPECT_EQ(s->walks[2].waypoints, (std::vector<glm::dvec2>{{0, 0}, {0, 100}}));
  EXPECT_EQ(s->walks[2].speed_mps, 2.5);  // the entry's first walk's
  EXPECT_EQ(s->walks[2].eye_height_m, 1.6);
  ASSERT_TRUE(s->entry.has_value());
  EXPECT_EQ(s->entry->walks.size(), 2u);  // the entry as its file says

  // A glTF file alone: its own walks, at the defaults.
  absl::StatusOr<LoadedScene> g = LoadScene(dir + "/walked.glb");
  ASSERT_TRUE(g.ok()) << g.status();
  ASSERT_EQ(g->walks.size(), 2u);
  EXPECT_EQ(g->walks[0].name, "street 1");
  EXPECT_EQ(g->walks[0].speed_mps, 1.4);
  EXPECT_EQ(g->walks[0].eye_height_m, 1.7);

  // A generated scene: the entry's walks only.
  absl::StatusOr<LoadedScene> d = LoadScene("default");
  ASSERT_TRUE(d.ok()) << d.status();
  ASSERT_TRUE(d->entry.has_value());
  EXPECT_EQ(d->walks.size(), d->entry->walks.size());
}

}  // namespace
}  // namespace vistream::scenes
