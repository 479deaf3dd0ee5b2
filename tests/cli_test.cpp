// End-to-end tests of the vistream tool: run the real binary, read its output.
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <glm/glm.hpp>
#include <nlohmann/json.hpp>

#include "scenes/catalog.h"
#include "tests/cli_test_util.h"
#include "visibility/pvs_file.h"

namespace {

using vistream::testing::ExpectBadOption;
using vistream::testing::ExpectRunTimeError;
using vistream::testing::RunResult;
using vistream::testing::ShellOutput;
using vistream::testing::Tmp;
using vistream::testing::Vistream;

TEST(Cli, GeneratedCity1Reports2128Objects) {
  const std::string glb = Tmp("city1.glb");
  const RunResult gen = Vistream("scene generate city1 -o " + glb);
  ASSERT_EQ(gen.exit_code, 0) << gen.out;
  const RunResult info = Vistream("scene info " + glb + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.out;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  EXPECT_EQ(j.at("objects"), 2128);
  EXPECT_EQ(j.at("triangles"), 12 * (1596 + 3 * 532));
  EXPECT_EQ(j.at("occluders"), 1596 + 3 * 532);
  const auto& min = j.at("bounds").at("min");
  const auto& max = j.at("bounds").at("max");
  ASSERT_EQ(min.size(), 3u);
  EXPECT_LT(min[0].get<double>(), max[0].get<double>());
  EXPECT_EQ(min[2].get<double>(), 0.0);
  EXPECT_GT(j.at("kd").at("nodes").get<int>(), 1000);
  // The catalog entry's walks travel in the file: a server or tool that loads it finds them.
  absl::StatusOr<vistream::scenes::CatalogEntry> entry = vistream::scenes::FindCatalogEntry("city1");
  ASSERT_TRUE(entry.ok()) << entry.status();
  absl::StatusOr<vistream::scenes::LoadedScene> loaded = vistream::scenes::LoadScene(glb);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ASSERT_FALSE(entry->walks.empty());
  ASSERT_EQ(loaded->walks.size(), entry->walks.size());
  for (size_t k = 0; k < entry->walks.size(); ++k) {
    EXPECT_EQ(loaded->walks[k].name, entry->walks[k].name);
    EXPECT_EQ(loaded->walks[k].waypoints, entry->walks[k].waypoints);
  }
}

TEST(Cli, SeedChangesTheCity) {
  const RunResult a = Vistream("scene generate city2 --seed 4 -o " + Tmp("a.glb"));
  const RunResult b = Vistream("scene generate city2 --seed 5 -o " + Tmp("b.glb"));
  ASSERT_EQ(a.exit_code, 0) << a.out;
  ASSERT_EQ(b.exit_code, 0) << b.out;
  const auto read = [](const std::string& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  };
  EXPECT_NE(read(Tmp("a.glb")), read(Tmp("b.glb")));
}

TEST(Cli, CatalogNamesWorkWithoutAFile) {
  const RunResult info = Vistream("scene info default --json");
  ASSERT_EQ(info.exit_code, 0) << info.out;
  const nlohmann::json j = nlohmann::json::parse(info.out);
  EXPECT_EQ(j.at("name"), "default");
  EXPECT_GT(j.at("objects").get<int>(), 1000);
}

// `scene walks`: the names a client's --path (or the page's ?walk=) takes, so that nobody
// guesses them. A catalog scene lists its entry's walks in order; an imported scene those
// derived from its data.
TEST(Cli, SceneWalksListsTheCatalogsWalksThenTheDatas) {
  const RunResult r = Vistream("scene walks default --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  absl::StatusOr<vistream::scenes::CatalogEntry> entry = vistream::scenes::FindCatalogEntry("default");
  ASSERT_TRUE(entry.ok()) << entry.status();
  ASSERT_FALSE(entry->walks.empty());
  ASSERT_GE(j.size(), entry->walks.size());
  for (size_t i = 0; i < entry->walks.size(); ++i) {
    EXPECT_EQ(j[i].at("name"), entry->walks[i].name);
    EXPECT_EQ(j[i].at("source"), "catalog");
    EXPECT_EQ(j[i].at("points").get<size_t>(), entry->walks[i].waypoints.size());
    double length = 0.0;
    for (size_t k = 0; k + 1 < entry->walks[i].waypoints.size(); ++k) {
      length += glm::distance(entry->walks[i].waypoints[k], entry->walks[i].waypoints[k + 1]);
    }
    EXPECT_NEAR(j[i].at("length_m").get<double>(), length, 1e-6);
  }
  // The plain form: one line a walk, tab-separated, the first the catalog's first.
  const RunResult plain = Vistream("scene walks default");
  ASSERT_EQ(plain.exit_code, 0) << plain.out;
  const size_t tab = plain.out.find('\t');
  ASSERT_NE(tab, std::string::npos) << plain.out;
  const size_t line = plain.out.rfind('\n', tab) == std::string::npos ? 0 : plain.out.rfind('\n', tab) + 1;
  EXPECT_EQ(plain.out.substr(line, tab - line), entry->walks[0].name) << plain.out;
  EXPECT_NE(plain.out.find("points\tfrom the catalog\n"), std::string::npos) << plain.out;

  // An imported OSM file: its streets' walks, derived from the data, each named and usable.
  const std::string glb = Tmp("streets_walks.glb");
  const RunResult imp = Vistream("scene import-osm " VISTREAM_SOURCE_DIR "/tests/osm/streets.osm -o " + glb);
  ASSERT_EQ(imp.exit_code, 0) << imp.out;
  const RunResult own = Vistream("scene walks " + glb + " --json");
  ASSERT_EQ(own.exit_code, 0) << own.out;
  const nlohmann::json w = nlohmann::json::parse(own.out);
  ASSERT_GT(w.size(), 0u) << own.out;
  for (const nlohmann::json& walk : w) {
    EXPECT_EQ(walk.at("source"), "data");
    EXPECT_FALSE(walk.at("name").get<std::string>().empty());
    EXPECT_GE(walk.at("points").get<size_t>(), 2u);
    EXPECT_GT(walk.at("length_m").get<double>(), 0.0);
  }
  // A scene that is not there: the error names it.
  ExpectRunTimeError("scene walks " + Tmp("nope.glb"), "nope.glb");
}

TEST(Cli, PvsReportsTheSetOfAViewcell) {
  const std::string png = Tmp("pvs.png");
  const RunResult r = Vistream("pvs --scene default --cell 10,10 --res 64 --json --map " + png);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const int objects = j.at("pvs_objects").get<int>();
  EXPECT_GT(objects, 0);
  EXPECT_LT(objects, j.at("total_objects").get<int>());
  EXPECT_GT(j.at("pvs_triangles").get<int>(), objects);
  EXPECT_GT(j.at("queries").get<int>(), 0);
  EXPECT_GE(j.at("ms").get<double>(), 0.0);
  EXPECT_GT(std::filesystem::file_size(png), 1000u);
  // The set itself: sorted ids and their names.
  const auto ids = j.at("objects").get<std::vector<int>>();
  EXPECT_EQ(static_cast<int>(ids.size()), objects);
  EXPECT_TRUE(std::is_sorted(ids.begin(), ids.end()));
  EXPECT_EQ(j.at("object_names").size(), ids.size());
}

// `pvs --all` writes every viewcell's set as a PVS file (what vistream-server --pvs-file serves),
// each set the one `pvs --cell` computes.
TEST(Cli, PvsAllWritesEveryViewcellAsAPvsFile) {
  const std::string file = Tmp("city1_all.pvs");
  const RunResult all = Vistream("pvs --scene city1 --all -o " + file + " --json");
  ASSERT_EQ(all.exit_code, 0) << all.out;
  const nlohmann::json j = nlohmann::json::parse(all.out);
  EXPECT_EQ(j.at("cells"), 560);
  std::ifstream in(file, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const absl::StatusOr<vistream::visibility::PvsFile> f = vistream::visibility::DecodePvsFile(bytes, file);
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->strategy, "dual-ray-space cpu 128^2");
  for (const char* cell : {"3,4", "14,10", "27,19"}) {
    const RunResult one = Vistream(std::string("pvs --scene city1 --json --cell ") + cell);
    ASSERT_EQ(one.exit_code, 0) << one.out;
    const nlohmann::json k = nlohmann::json::parse(one.out);
    const int id = k.at("cell")[1].get<int>() * f->nx + k.at("cell")[0].get<int>();
    EXPECT_EQ(k.at("objects").get<std::vector<uint32_t>>(), f->sets.Objects(static_cast<uint32_t>(id))) << cell;
  }
  // A heatmap reads it back.
  EXPECT_EQ(Vistream("agvs heatmap --scene city1 --pvs " + file + " -o " + Tmp("all.png")).exit_code, 0);
  ExpectBadOption("pvs --scene city1", "--cell or --all: give --cell I,J (one viewcell) or --all -o FILE");
  ExpectBadOption("pvs --scene city1 --all", "--all: writes a PVS file or fills a PVS store: give -o FILE");
  ExpectBadOption("pvs --scene city1 --all --cell 1,1 -o " + file, "--cell: cannot be given with --all");
  ExpectRunTimeError("pvs --scene city1 --all -o /nonexistent/dir/x.pvs", "not a writable folder");
  ExpectBadOption("pvs --scene city1 --cell 1,1 -o " + file, "-o: writes the PVS file of --all; one viewcell prints");
}

// A viewcell smaller than the catalog's, among the buildings: city1-255 stands in plain view
// of viewcell 52,17 of 8 m (it was left out while a wall on a kd node's face blocked the rays
// that end on it), with every backend.
TEST(Cli, SmallViewcellKeepsWhatItSees) {
  for (const char* backend : {"cpu", "gl", "exact"}) {
    const RunResult r =
        Vistream(std::string("pvs --scene city1 --cell 52,17 --cell-size 8 --json --backend ") + backend);
    ASSERT_EQ(r.exit_code, 0) << r.out;
    const auto names = nlohmann::json::parse(r.out).at("object_names").get<std::vector<std::string>>();
    EXPECT_NE(std::find(names.begin(), names.end(), "city1-255"), names.end()) << backend;
  }
}

TEST(Cli, PvsBackendsAgree) {
  auto objects = [](const std::string& backend) {
    const RunResult r = Vistream("pvs --scene default --cell 10,10 --res 32 --json --backend " + backend);
    EXPECT_EQ(r.exit_code, 0) << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j.at("backend").get<std::string>(), backend);
    return j.at("pvs_objects").get<int>();
  };
  const int cpu = objects("cpu"), gl = objects("gl"), exact = objects("exact");
  EXPECT_EQ(cpu, gl);  // the same pixels, so the same set
  EXPECT_LE(exact, cpu);
  EXPECT_GT(exact, 0);
}

TEST(Cli, Table1ReportsBothBackendsAgainstTheExactTest) {
  const std::string csv = Tmp("table1.csv");
  const RunResult r =
      Vistream("bench table1 --scene default --cells 1 --res 16,32 --sizes 100 --json --csv " + csv);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const auto& rows = j.at("rows");
  ASSERT_EQ(rows.size(), 4u);  // two resolutions, two backends
  std::map<std::string, std::vector<double>> objects;
  for (const auto& row : rows) {
    EXPECT_EQ(row.at("cell_size").get<double>(), 100.0);
    EXPECT_GT(row.at("ms").get<double>(), 0.0);
    const double over = row.at("overestimation_pct").get<double>();
    EXPECT_GE(over, 0.0);
    EXPECT_LT(over, 100.0);
    objects[row.at("backend").get<std::string>()].push_back(row.at("pvs_objects").get<double>());
    EXPECT_TRUE(row.at("res").get<int>() == 16 || row.at("res").get<int>() == 32);
  }
  EXPECT_EQ(objects["cpu"], objects["gl"]);  // the same pixels, the same sets
  // The exact set is the smallest; a finer raster never adds objects.
  const double exact = j.at("exact").at(0).at("pvs_objects").get<double>();
  EXPECT_LE(exact, objects["cpu"][1]);
  EXPECT_LE(objects["cpu"][1], objects["cpu"][0]);
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header, "res,cell_size,backend,ms,median_ms,overestimation_pct,pvs_objects");
  int lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  EXPECT_EQ(lines, 4);
  ExpectBadOption("bench table1 --scene default --backends vulkan", "--backends: vulkan not in {cpu,gl}");
}

TEST(Cli, PvsRejectsBadCellsAndBackends) {
  ExpectBadOption("pvs --scene default --cell ten,3", "--cell: 'ten,3': expected I,J (two integers)");
  ExpectRunTimeError("pvs --scene default --cell 500,3", "outside the grid");
  ExpectBadOption("pvs --scene default --cell 1,1 --backend vulkan", "--backend: vulkan not in {cpu,gl,exact}");
  ExpectBadOption("pvs --scene default --cell 1,1 --res 100", "--res: '100' is not a power of two");
}

// Every power of two from 1 to 256 is a raster the query takes (as the server's --res): the
// coarsest one keeps every object the finest one does, and possibly more.
TEST(Cli, PvsAtTheCoarsestRasterHoldsTheFinestOnesObjects) {
  std::map<int, std::vector<std::string>> names;
  for (int res : {1, 256}) {
    const RunResult r = Vistream("pvs --scene default --cell 10,10 --res " + std::to_string(res) + " --json");
    ASSERT_EQ(r.exit_code, 0) << r.out;
    names[res] = nlohmann::json::parse(r.out).at("object_names").get<std::vector<std::string>>();
    std::sort(names[res].begin(), names[res].end());
  }
  ASSERT_FALSE(names[256].empty());
  EXPECT_TRUE(std::includes(names[1].begin(), names[1].end(), names[256].begin(), names[256].end()));
  EXPECT_GT(names[1].size(), names[256].size()) << "at 1x1 the raster should keep more than the finest";
}

TEST(Cli, EpsilonReportsTheSupersetOfANeighbourhood) {
  const std::string png = Tmp("epsilon.png");
  // A street crossing of city1 (lots of 25 m, buildings at least 2.5 m from the lot edge).
  const RunResult r = Vistream("epsilon --scene city1 --at 0,0,2 --size 3.75 --json --map " + png);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const int visible = j.at("visible_triangles").get<int>(), total = j.at("total_triangles").get<int>();
  EXPECT_GT(visible, 0);
  EXPECT_LT(visible, total / 10);
  EXPECT_EQ(total, 38304);
  EXPECT_EQ(j.at("total_boxes").get<int>(), 2128);
  EXPECT_GT(j.at("occluded_boxes").get<int>(), 1000);
  EXPECT_GT(j.at("rays").get<int>(), 0);
  EXPECT_GE(j.at("ms").get<double>(), 0.0);
  EXPECT_GT(std::filesystem::file_size(png), 1000u);
  // Every column gives the same set here (dropping hidden occluders may only keep more).
  const RunResult none = Vistream("epsilon --scene city1 --at 0,0,2 --size 3.75 --json --opt none");
  ASSERT_EQ(none.exit_code, 0) << none.out;
  EXPECT_LE(nlohmann::json::parse(none.out).at("visible_triangles").get<int>(), visible);
}

TEST(Cli, EpsilonRejectsBadPositions) {
  ExpectBadOption("epsilon --scene city1 --at 1,2 --size 3", "--at: '1,2': expected X,Y,Z (three finite numbers, metres)");
  ExpectBadOption("epsilon --scene city1 --at nan,0,2 --size 3", "--at: 'nan,0,2': expected X,Y,Z (three finite");
  ExpectRunTimeError("epsilon --scene city1 --at 5000,0,2 --size 3", "outside the scene");
  ExpectBadOption("epsilon --scene city1 --at 0x10,5,2 --size 4", "--at: '0x10,5,2': expected X,Y,Z");
  // z: the box must reach the ground (what lies below it is cut off) and stay below 1 km over
  // the tallest building.
  ExpectRunTimeError("epsilon --scene city1 --at 10,5,1e300 --size 4", "z from -2.0 (the box reaching the ground)");
  ExpectRunTimeError("epsilon --scene city1 --at 10,5,-3 --size 4", "outside the scene");
  EXPECT_EQ(Vistream("epsilon --scene city1 --at 10,5,-1.5 --size 4").exit_code, 0);
  ExpectBadOption("epsilon --scene city1 --at 0,0,2 --size -1", "--size: '-1' is not a number from 0 to 100000");
  ExpectBadOption("epsilon --scene city1 --at 0,0,2 --size 3 --opt fastest", "--opt: fastest not in");
}

// bench server through a real vistream-server, plaintext and TLS side by side: the walkers are
// served in both, over a certificate made for the run, and the ratios are given.
TEST(Cli, BenchServerRunsPlaintextAndTlsSideBySide) {
  const RunResult r = Vistream("bench server --scene city1 --sessions 2 --seconds 4 --threads 1 --tls both --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out.substr(r.out.find('{')));
  ASSERT_EQ(j.at("runs").size(), 2u) << r.out;
  EXPECT_FALSE(j["runs"][0].at("tls").get<bool>());
  EXPECT_TRUE(j["runs"][1].at("tls").get<bool>());
  for (const auto& run : j["runs"]) {
    EXPECT_EQ(run.at("sessions_started").get<int>(), 2) << run;
    EXPECT_EQ(run.at("server_exit_code").get<int>(), 0) << run;
    EXPECT_GT(run.at("bytes_sent").get<double>(), 0.0) << run;
    EXPECT_GT(run.at("bytes_per_s").get<double>(), 0.0) << run;
    EXPECT_FALSE(run.contains("first_error")) << run;
  }
  EXPECT_GT(j.at("tls_over_plain").at("bytes_per_s").get<double>(), 0.0);
  EXPECT_TRUE(j["tls_over_plain"].contains("crossing_p99_ms"));
  ExpectBadOption("bench server --tls maybe", "--tls: maybe not in {off,on,both}");
}

TEST(Cli, BenchEpsilonReproducesBothTables) {
  const RunResult r = Vistream("bench epsilon --scene city2 --count 3 --opts none,paper,all --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("neighbourhoods").get<int>(), 3);
  EXPECT_GT(j.at("size").get<double>(), 2.0);
  const auto& t1 = j.at("table1");
  EXPECT_EQ(t1.at("total_boxes").get<double>(), 2128.0);
  EXPECT_GT(t1.at("occluded_polygons").get<double>(), 0.5 * t1.at("total_polygons").get<double>());
  const auto& t2 = j.at("table2");
  ASSERT_EQ(t2.size(), 3u);
  EXPECT_EQ(t2[0].at("opt"), "none");
  for (const auto& c : t2) EXPECT_GT(c.at("ms").get<double>(), 0.0);
  EXPECT_EQ(t2[0].at("traversals").get<double>(), t1.at("total_polygons").get<double>());  // one per triangle
  EXPECT_LT(t2[2].at("traversals").get<double>(), t2[1].at("traversals").get<double>());
  // As a server asks: only over each neighbourhood's viewcell PVS, which holds fewer objects.
  const RunResult p = Vistream("bench epsilon --scene city2 --count 2 --opts all --pvs-cell 50 --json");
  ASSERT_EQ(p.exit_code, 0) << p.out;
  const nlohmann::json k = nlohmann::json::parse(p.out);
  EXPECT_GT(k.at("pvs_objects").get<double>(), 0.0);
  EXPECT_LT(k.at("table1").at("total_boxes").get<double>(), 2128.0);
  EXPECT_EQ(k.at("table1").at("total_boxes").get<double>(), k.at("pvs_objects").get<double>());
}

TEST(Cli, AgvsReportsItsFiguresAndWritesAPvsFileTheHeatmapReads) {
  const std::string pvs = Tmp("city1.pvs"), png = Tmp("heat.png"), state = Tmp("city1.state");
  const RunResult r = Vistream("agvs --scene city1 --samples 300000 --batch 16384 -o " + pvs + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_GE(j.at("samples").get<double>(), 300000.0);
  EXPECT_GT(j.at("samples_per_s").get<double>(), 0.0);
  EXPECT_GT(j.at("seconds").get<double>(), 0.0);
  EXPECT_GE(j.at("estimated_pixel_error").get<double>(), 0.0);
  EXPECT_EQ(j.at("cells").get<int>(), 560);
  const double mean = j.at("mean_pvs_objects").get<double>();
  EXPECT_GT(mean, 10.0);
  EXPECT_LT(mean, 2128.0);
  EXPECT_GT(std::filesystem::file_size(pvs), 560u);
  // Two-level sets: at least the index (4 bytes per cell and 512 ids); on a town this small
  // every cell may hold all five of its 64-byte blocks, so the bound is a few flat bitsets.
  EXPECT_GE(j.at("sets_bytes").get<double>(), 560.0 * 5 * 4);
  EXPECT_LT(j.at("sets_bytes").get<double>(), 560.0 * 2128 / 8 * 4);

  const RunResult h = Vistream("agvs heatmap --scene city1 --pvs " + pvs + " -o " + png + " --json");
  ASSERT_EQ(h.exit_code, 0) << h.out;
  const nlohmann::json k = nlohmann::json::parse(h.out);
  EXPECT_EQ(k.at("cells").get<int>(), 560);
  EXPECT_GT(k.at("max_pvs_triangles").get<double>(), k.at("mean_pvs_triangles").get<double>());
  EXPECT_GT(std::filesystem::file_size(png), 1000u);

  // Resuming adds to the saved state.
  const RunResult a = Vistream("agvs --scene city1 --samples 100000 --batch 16384 --state " + state + " --json");
  ASSERT_EQ(a.exit_code, 0) << a.out;
  const RunResult b = Vistream("agvs --scene city1 --samples 100000 --batch 16384 --state " + state + " --json");
  ASSERT_EQ(b.exit_code, 0) << b.out;
  EXPECT_GE(nlohmann::json::parse(b.out).at("samples").get<double>(),
            nlohmann::json::parse(a.out).at("samples").get<double>() + 100000.0);
  EXPECT_GE(nlohmann::json::parse(b.out).at("mean_pvs_objects").get<double>(),
            nlohmann::json::parse(a.out).at("mean_pvs_objects").get<double>());
}

// ^C while sampling: what was sampled is kept (the summary says cancelled, the PVS file is
// written), the command says it was interrupted and exits 130, as every command does.
TEST(Cli, AnInterruptedAgvsKeepsWhatItSampledAndSaysSo) {
  const std::string pvs = Tmp("interrupted.pvs"), log = Tmp("interrupted.log");
  std::filesystem::remove(pvs);
  // The signal comes once sampling shows progress (before, it would stop the scene's loading);
  // the log is printed after the run.
  const std::string cmd = std::string("sh -c '") + VISTREAM_BIN + " agvs --scene city1 --seconds 120 -o " + pvs +
                          " >" + log + " 2>&1 & pid=$!; for i in $(seq 600); do grep -q \"samples/s\" " + log +
                          " && break; sleep 0.1; done; sleep 0.5; kill -INT $pid; wait $pid; echo \"rc=$?\"; cat " +
                          log + "'";
  const std::string out = ShellOutput(cmd);
  EXPECT_NE(out.find("rc=130"), std::string::npos) << out;
  EXPECT_NE(out.find("vistream: interrupted (sampling stopped after "), std::string::npos) << out;
  EXPECT_NE(out.find("samples/s, error"), std::string::npos) << "no progress seen before the signal: " << out;
  EXPECT_NE(out.find(" (cancelled)"), std::string::npos) << out;
  EXPECT_TRUE(std::filesystem::exists(pvs)) << out;
}

TEST(Cli, AgvsRejectsBadInput) {
  ExpectBadOption("agvs --scene city1", "--seconds, --pixel-error or --samples: give one: when to stop sampling");
  ExpectBadOption("agvs --samples 10", "--scene: is required");
  ExpectBadOption("agvs --scene city1 --samples 10 --strategy gvs", "--strategy: unknown sampling strategy 'gvs'");
  ExpectBadOption("agvs --scene city1 --samples 10 --filter blur", "--filter: 'blur': expected none, object, view or both");
  // A PVS file that is not one, and one made for another scene.
  const std::string junk = Tmp("junk.pvs"), city1 = Tmp("other.pvs");
  std::ofstream(junk) << "not a pvs file";
  ExpectRunTimeError("agvs heatmap --scene city1 --pvs " + junk + " -o " + Tmp("x.png"), junk);
  ASSERT_EQ(Vistream("agvs --scene city1 --samples 1000 -o " + city1 + " --json").exit_code, 0);
  ExpectRunTimeError("agvs heatmap --scene default --pvs " + city1 + " -o " + Tmp("y.png"), "another scene");
  ExpectBadOption("agvs heatmap --scene city1 -o " + Tmp("z.png"), "--pvs or --seconds: give one");  // nothing to draw
  // A state file that is not one.
  ExpectRunTimeError("agvs --scene city1 --samples 10 --state " + junk, junk);
}

// The project's main correctness check, end to end: nothing sampling sees from any viewcell
// is missing from the conservative sets. Sample counts, not seconds, so that a failure
// replays exactly. Small viewcells matter most: a wall on a kd node's face, touching rows and
// cells inside or against buildings are the cases 100 m cells never met.
struct CheckCase {
  const char* scene;
  int cell_size;
  const char* backend;
  int cells;          // sampled viewcells (0: all)
  const char* samples;
  int expect_cells;
  double min_entries;  // the check must have checked something
};

void PrintTo(const CheckCase& c, std::ostream* os) {
  *os << c.scene << ", " << c.cell_size << " m cells, " << c.backend << ", " << c.samples << " samples";
}

class CheckConservative : public ::testing::TestWithParam<CheckCase> {};

TEST_P(CheckConservative, FindsNoViolation) {
  const CheckCase& c = GetParam();
  const RunResult r = Vistream("check-conservative --scene " + std::string(c.scene) + " --cell-size " +
                               std::to_string(c.cell_size) + " --backend " + c.backend + " --cells " +
                               std::to_string(c.cells) + " --samples " + c.samples + " --neighbourhoods 10 --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("backend").get<std::string>(), c.backend);
  EXPECT_EQ(j.at("cell_size").get<double>(), c.cell_size);
  EXPECT_EQ(j.at("cells").get<int>(), c.expect_cells);
  EXPECT_EQ(j.at("violations").get<int>(), 0) << r.out;
  EXPECT_GT(j.at("pvs_entries_checked").get<double>(), c.min_entries);
  EXPECT_GT(j.at("epsilon_hits_checked").get<double>(), 10000.0);
  // Something was hidden, so a false occlusion could have shown; the exact backend's own test ran.
  EXPECT_GT(j.at("occluded_queries").get<double>(), 100.0);
  if (std::string(c.backend) == "exact") {
    EXPECT_GT(j.at("exact_tests").get<int>(), 10);
  }
}

INSTANTIATE_TEST_SUITE_P(
    City1AndStreets, CheckConservative,
    ::testing::Values(CheckCase{"city1", 4, "cpu", 300, "8000000", 300, 9000},
                      CheckCase{"city1", 8, "cpu", 300, "8000000", 300, 14000},
                      CheckCase{"city1", 16, "cpu", 300, "8000000", 300, 20000},
                      CheckCase{"city1", 100, "cpu", 0, "8000000", 140, 40000},
                      CheckCase{"city1", 4, "exact", 200, "8000000", 200, 6000},
                      CheckCase{"city1", 100, "exact", 40, "8000000", 40, 10000},
                      CheckCase{"streets", 4, "cpu", 0, "3000000", 4189, 100000},
                      CheckCase{"streets", 8, "cpu", 0, "3000000", 1080, 35000},
                      CheckCase{"streets", 16, "cpu", 0, "3000000", 270, 12000},
                      CheckCase{"streets", 100, "cpu", 0, "3000000", 12, 1500},
                      CheckCase{"streets", 4, "exact", 800, "3000000", 800, 20000},
                      CheckCase{"streets", 8, "exact", 0, "3000000", 1080, 35000},
                      CheckCase{"streets", 16, "gl", 40, "3000000", 40, 1500}),
    [](const ::testing::TestParamInfo<CheckCase>& test) {
      return std::string(test.param.scene) + "_" + std::to_string(test.param.cell_size) + "m_" + test.param.backend;
    });

TEST(Cli, CheckConservativeReplaysASampleCountExactly) {
  const std::string args = "check-conservative --scene streets --cell-size 8 --cells 50 --samples 500000 --json";
  const RunResult a = Vistream(args), b = Vistream(args);
  ASSERT_EQ(a.exit_code, 0) << a.out;
  ASSERT_EQ(b.exit_code, 0) << b.out;
  const nlohmann::json ja = nlohmann::json::parse(a.out), jb = nlohmann::json::parse(b.out);
  EXPECT_EQ(ja.at("samples"), jb.at("samples"));
  EXPECT_EQ(ja.at("pvs_entries_checked"), jb.at("pvs_entries_checked"));
  EXPECT_EQ(ja.at("epsilon_hits_checked"), jb.at("epsilon_hits_checked"));
  // A count or a time, not both; and only the known backends.
  ExpectBadOption("check-conservative --scene streets --samples 1000 --seconds 1", "--seconds: cannot be given with --samples");
  ExpectBadOption("check-conservative --scene streets --backend vulkan", "--backend: vulkan not in {cpu,gl,exact}");
}

TEST(Cli, CheckConservativeRejectsBadScenesAndSizes) {
  // A directory is not a scene (it opens as a stream, then throws on reading).
  const std::string dir = Tmp("a-folder.glb");
  std::filesystem::create_directories(dir);
  for (const std::string& scene : {dir, Tmp("")}) {
    ExpectRunTimeError("check-conservative --scene " + scene + " --samples 1000", "is a directory");
  }
  ExpectBadOption("check-conservative --scene streets --cell-size nan --samples 1000", "--cell-size: 'nan' is not a number");
  // Viewcells so small that their sets would not fit in any memory (london at 1 m: 162 M cells
  // of 146,325 bits), or that the grid would pass 2^31 cells: said, not an abort.
  for (const char* args : {"--scene london --cell-size 1", "--scene streets --cell-size 0.01"}) {
    ExpectRunTimeError(std::string("check-conservative --samples 1000 ") + args, "larger");
  }
}

TEST(Cli, CheckConservativeFindsNoViolationOnALondonSubset) {
  const RunResult r = Vistream("check-conservative --scene london --cells 8 --samples 4000000 --neighbourhoods 10 --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("cells").get<int>(), 8);
  EXPECT_EQ(j.at("violations").get<int>(), 0) << r.out;
  EXPECT_GT(j.at("pvs_entries_checked").get<double>(), 8 * 20.0);
}

// Levels of detail (issue 45): made with progress, saved with the scene, read back; bad input.
TEST(Cli, SceneLevelsMakesMeasuredLevelsAndSavesThem) {
  const std::string out = Tmp("streets_levels.glb");
  const RunResult r = Vistream("scene levels streets -o " + out + " --tile 100 --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("objects").get<int>(), 319);
  EXPECT_EQ(j.at("objects_with_levels").get<int>(), 319);
  EXPECT_GT(j.at("object_levels").get<int>(), 319);
  EXPECT_GT(j.at("clusters").get<int>(), 0);
  EXPECT_GT(j.at("largest_object_error_m").get<double>(), 0.0);
  EXPECT_GT(j.at("peak_rss_mb").get<double>(), 0.0);
  const RunResult info = Vistream("scene info " + out + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.out;
  const nlohmann::json i = nlohmann::json::parse(info.out);
  EXPECT_EQ(i.at("object_levels"), j.at("object_levels"));
  EXPECT_EQ(i.at("clusters"), j.at("clusters"));
  // Progress on a terminal's stream (stderr), both tasks.
  const RunResult plain = Vistream("scene levels streets -o " + out + " --no-clusters");
  ASSERT_EQ(plain.exit_code, 0) << plain.out;
  EXPECT_NE(plain.out.find("levels: objects"), std::string::npos) << plain.out;
  EXPECT_NE(plain.out.find("0 clusters"), std::string::npos) << plain.out;

  ExpectBadOption("scene levels streets -o " + out + " --tile 0", "--tile");
  ExpectBadOption("scene levels streets -o ''", "--output");
  ExpectRunTimeError("scene levels " + Tmp("missing.glb") + " -o " + out, "missing.glb");
}

// OpenStreetMap import, end to end: the summary's keys and what bad input says.
TEST(Cli, ImportOsmWritesASceneAndSummarises) {
  const std::string out = Tmp("courtyard.glb");
  const RunResult r = Vistream(std::string("scene import-osm ") + VISTREAM_SOURCE_DIR + "/tests/osm/courtyard.osm -o " +
                               out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("buildings").get<int>(), 1);
  EXPECT_EQ(j.at("inner_rings").get<int>(), 1);
  EXPECT_EQ(j.at("repaired").get<int>(), 0);
  EXPECT_EQ(j.at("skipped").get<int>(), 0);
  EXPECT_EQ(j.at("utm_zone").get<std::string>(), "32n");
  // The scene file reads back with its origin.
  const RunResult info = Vistream("scene info " + out + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.out;
  EXPECT_EQ(nlohmann::json::parse(info.out).at("objects").get<int>(), 1) << info.out;

  ExpectBadOption(std::string("scene import-osm ") + VISTREAM_SOURCE_DIR + "/tests/osm/courtyard.osm -o " + out +
                      " --bbox 7,43,7.5",
                  "--bbox: bbox '7,43,7.5': needs four numbers");
  ExpectRunTimeError(std::string("scene import-osm ") + VISTREAM_SOURCE_DIR + "/tests/osm/empty.osm -o " + out,
                     "empty.osm: the file is empty");
  ExpectRunTimeError(std::string("scene import-osm ") + VISTREAM_SOURCE_DIR + "/tests/osm -o " + out,
                     "tests/osm: is a directory, not an OpenStreetMap file");
}

// The plausible height limit is an option: a 1,500 m tower is bad data by default (counted,
// the next rule used), a real height with --max-height 2000.
TEST(Cli, ImportOsmMaxHeightDecidesWhatIsImplausible) {
  const std::string in = Tmp("tower.osm");
  {
    std::ofstream f(in);
    f << R"(<?xml version="1.0" encoding="UTF-8"?>
<osm version="0.6">
 <node id="1" lat="47.0000" lon="8.0000"/>
 <node id="2" lat="47.0000" lon="8.0002"/>
 <node id="3" lat="47.0002" lon="8.0002"/>
 <node id="4" lat="47.0002" lon="8.0000"/>
 <way id="10"><nd ref="1"/><nd ref="2"/><nd ref="3"/><nd ref="4"/><nd ref="1"/>
  <tag k="building" v="yes"/><tag k="height" v="1500"/></way>
</osm>
)";
  }
  const std::string out = Tmp("tower.glb");
  const RunResult by_default = Vistream("scene import-osm " + in + " -o " + out + " --json");
  ASSERT_EQ(by_default.exit_code, 0) << by_default.out;
  const nlohmann::json d = nlohmann::json::parse(by_default.out);
  EXPECT_EQ(d.at("implausible_heights").get<int>(), 1);
  EXPECT_LT(d.at("bounds_max")[2].get<double>(), 100.0) << "the rule's height, not 1,500 m";
  const RunResult allowed = Vistream("scene import-osm " + in + " -o " + out + " --max-height 2000 --json");
  ASSERT_EQ(allowed.exit_code, 0) << allowed.out;
  const nlohmann::json a = nlohmann::json::parse(allowed.out);
  EXPECT_EQ(a.at("implausible_heights").get<int>(), 0);
  EXPECT_EQ(a.at("bounds_max")[2].get<double>(), 1500.0);
  ExpectBadOption("scene import-osm " + in + " -o " + out + " --max-height nan", "--max-height");
}

// The whole pipeline on a real city: the Monaco extract (../shared/data/osm, ODbL), a viewcell
// on Rue Grimaldi (the catalog's walk) with each backend, and the inclusion check.
const std::string kMonaco = std::string(VISTREAM_SOURCE_DIR "/../shared/data/osm/monaco.osm.pbf");

TEST(Cli, MonacoPvsWithEachBackend) {
  if (!std::filesystem::exists(kMonaco)) GTEST_SKIP() << kMonaco << " is absent: the Monaco pipeline is not tested";
  std::map<std::string, int> objects;
  for (const std::string backend : {"cpu", "gl", "exact"}) {
    const RunResult r = Vistream("pvs --scene monaco --cell 115,43 --json --backend " + backend);
    ASSERT_EQ(r.exit_code, 0) << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    objects[backend] = j.at("pvs_objects").get<int>();
    EXPECT_GT(j.at("total_objects").get<int>(), 20000);
  }
  EXPECT_EQ(objects["cpu"], objects["gl"]);
  EXPECT_LE(objects["exact"], objects["cpu"]);
  EXPECT_GT(objects["exact"], 10);
  EXPECT_LT(objects["cpu"], 2000);  // a street in a city sees a small part of it
}

TEST(Cli, CheckConservativeFindsNoViolationOnMonaco) {
  if (!std::filesystem::exists(kMonaco)) GTEST_SKIP() << kMonaco << " is absent: the Monaco pipeline is not tested";
  const RunResult r = Vistream("check-conservative --scene monaco --cells 8 --samples 6000000 --neighbourhoods 10 --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("cells").get<int>(), 8);
  EXPECT_EQ(j.at("violations").get<int>(), 0) << r.out;
  EXPECT_GT(j.at("pvs_entries_checked").get<double>(), 8 * 20.0);
  EXPECT_GT(j.at("epsilon_hits_checked").get<double>(), 10000.0);
}

}  // namespace
