// The vistream tool's options and exit codes, end to end: what a bad option says and exits
// with, and a check that checked nothing.
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/cli_test_util.h"

namespace {

using vistream::testing::ExpectBadOption;
using vistream::testing::ExpectRunTimeError;
using vistream::testing::kBadOption;
using vistream::testing::kRunTimeError;
using vistream::testing::RunResult;
using vistream::testing::Tmp;
using vistream::testing::Vistream;

TEST(Cli, BadInputGivesAClearErrorAndItsExitCode) {
  ExpectRunTimeError("scene info " + Tmp("nope.glb"), "nope.glb");
  const std::string bad = Tmp("bad.json");
  std::ofstream(bad) << R"({"name": "bad", "source": {"generator": "city1"}, "viewcell": {"size_m": 0, "height_m": 2}})";
  ExpectRunTimeError("scene info " + bad, "viewcell.size_m");
  ExpectRunTimeError("scene generate atlantis -o " + Tmp("x.glb"), "atlantis");
  ExpectBadOption("scene generate city1", "--output: is required");
  ExpectBadOption("frobnicate", "'frobnicate': not a vistream command");
  ExpectBadOption("", "'vistream' needs a command: scene, pvs, epsilon, agvs, check-conservative, bench");
  ExpectBadOption("scene", "'vistream scene' needs a command: generate, import-osm, import-city, occluders, extrude, levels, info, walks, map");
  ExpectBadOption("bench nosuch", "'nosuch': not a vistream bench command");
  ExpectBadOption("scene import-city x.city.json -o " + Tmp("never.glb") + " --ground flat", "--ground: ");
  // A CRS is AUTHORITY:CODE; a scene is written as .glb or .gltf, not into a folder or a .png,
  // and these are told before anything is read.
  ExpectBadOption("scene import-city x.city.json -o " + Tmp("never.glb") + " --crs nonsense",
                  "--crs: 'nonsense' names no coordinate reference system");
  ExpectBadOption("scene import-city x.city.json -o " + Tmp("never.png"), "--output: '" + Tmp("never.png") +
                                                                             "': a scene is written as .glb or .gltf");
  std::filesystem::create_directories(Tmp("folder.glb"));
  ExpectBadOption("scene extrude city1 -o " + Tmp("folder.glb"), "--output: '" + Tmp("folder.glb") + "' is a folder");
  ExpectBadOption("scene levels city1 -o " + Tmp("nowhere") + "/city1.glb",
                  "--output: '" + Tmp("nowhere") + "/city1.glb': there is no folder '" + Tmp("nowhere") +
                      "' to write it in");
  ExpectBadOption("scene generate city1 -o " + Tmp("city1.json"),
                  "--output: '" + Tmp("city1.json") + "': a scene is written as .glb or .gltf");
  ExpectBadOption("pvs --scene city1 --cell 1,1 --bogus", "--bogus: not an option of 'vistream pvs'");
  // Named before the required option it hides, without the value beside it.
  ExpectBadOption("pvs --sene city1", "--sene: not an option of 'vistream pvs'");
  ExpectBadOption("pvs --scene city1 --cell 1,1 --frob 1 --blah", "--frob, --blah: not options of 'vistream pvs'");
  ExpectBadOption("pvs --scene city1 --cell 1,1 stray", "'stray': not expected by 'vistream pvs'");
  // --help is no error.
  const RunResult help = Vistream("check-conservative --help");
  EXPECT_EQ(help.exit_code, 0) << help.out;
  EXPECT_NE(help.out.find("--allow-unchecked"), std::string::npos) << help.out;
}

// Every numeric option rejects NaN, infinities, text and out-of-range values, naming itself,
// before any work starts (a NaN size once gave 0 rays and exit 0; --cell-size nan or 0 once
// quietly took the catalog's size).
TEST(Cli, NanInfinityAndOutOfRangeNumbersAreRejectedNamingTheOption) {
  const std::string png = " -o " + Tmp("never.png");
  const struct {
    std::string args, message;
  } cases[] = {
      {"epsilon --scene city1 --at 10,5,2.5 --size nan", "--size: 'nan' is not a number from 0 to 100000"},
      {"epsilon --scene city1 --at 10,5,2.5 --size inf", "--size: 'inf' is not a number"},
      {"epsilon --scene city1 --at 10,5,2.5 --size -1", "--size: '-1' is not a number"},
      {"pvs --scene city1 --cell 1,1 --cell-size nan", "--cell-size: 'nan' is not a number from 0.01 to 1e+06"},
      {"pvs --scene city1 --cell 1,1 --cell-size 0", "--cell-size: '0' is not a number from 0.01"},
      {"pvs --scene city1 --cell 1,1 --cell-size 0x10", "--cell-size: '0x10' is not a number from 0.01"},
      {"pvs --scene city1 --cell 1,1 --cell-size ' 8'", "--cell-size: ' 8' is not a number from 0.01"},
      {"pvs --scene city1 --cell 1,1 --res nan", "--res: 'nan' is not a power of two from 1 to 256"},
      {"pvs --scene city1 --cell 1,1 --res 100", "--res: '100' is not a power of two from 1 to 256"},
      {"pvs --scene city1 --cell 1,1 --res 0", "--res: '0' is not a power of two from 1 to 256"},
      {"check-conservative --scene city1 --res 512", "--res: '512' is not a power of two from 1 to 256"},
      {"bench server --scene city1 --res 100", "--res: '100' is not a power of two from 1 to 256"},
      {"agvs --scene city1 --samples 10 --cell-size 0", "--cell-size: '0' is not a number"},
      {"agvs --scene city1 --seconds nan", "--seconds: 'nan' is not a number"},
      {"agvs --scene city1 --pixel-error nan", "--pixel-error: 'nan' is not a number"},
      {"agvs --scene city1 --samples -1", "--samples: '-1' is not a whole number from 1 to"},
      {"agvs --scene city1 --samples 1e6", "--samples: '1e6' is not a whole number"},
      {"agvs --scene city1 --samples 10 --seed -1", "--seed: '-1' is not a whole number from 0 to"},
      {"agvs --scene city1 --samples 10 --threads nan", "--threads: 'nan' is not a whole number"},
      {"agvs --scene city1 --samples 10 --batch 0", "--batch: '0' is not a whole number from 1 to 16777216"},
      {"agvs heatmap --scene city1 --seconds 1 --cell-size 0" + png, "--cell-size: '0' is not a number"},
      {"agvs heatmap --scene city1 --seconds inf" + png, "--seconds: 'inf' is not a number"},
      {"check-conservative --scene city1 --cell-size 0", "--cell-size: '0' is not a number"},
      {"check-conservative --scene city1 --cell-size nan", "--cell-size: 'nan' is not a number"},
      {"check-conservative --scene city1 --seconds -inf", "--seconds: '-inf' is not a number"},
      {"check-conservative --scene city1 --samples 0", "--samples: '0' is not a whole number"},
      {"check-conservative --scene city1 --cells nan", "--cells: 'nan' is not a whole number"},
      {"check-conservative --scene city1 --neighbourhoods -2", "--neighbourhoods: '-2' is not a whole number"},
      {"check-conservative --scene city1 --rays 0", "--rays: '0' is not a whole number"},
      {"check-conservative --scene city1 --seed nan", "--seed: 'nan' is not a whole number"},
      {"scene generate city1 -o x.glb --seed 1.5", "--seed: '1.5' is not a whole number"},
      {"scene info city1 --leaf-size nan", "--leaf-size: 'nan' is not a whole number from 1 to 1024"},
      {"scene map city1 -o x.png --size 1e9", "--size: '1e9' is not a whole number from 16 to 16384"},
      {"scene import-osm x.osm -o x.glb --storey inf", "--storey: 'inf' is not a number from 1 to 20"},
      {"bench table1 --cells 0", "--cells: '0' is not a whole number"},
      {"bench table1 --sizes 100,nan", "--sizes: 'nan' is not a number"},
      {"bench table1 --res 16,300", "--res: '300' is not a power of two from 1 to 256"},
      {"bench table1 --res 16,100", "--res: '100' is not a power of two from 1 to 256"},
      {"bench epsilon --count nan", "--count: 'nan' is not a whole number"},
      {"bench epsilon --size inf", "--size: 'inf' is not a number"},
      {"bench epsilon --pvs-cell 0", "--pvs-cell: '0' is not a number"},
      {"bench agvs --seconds nan", "--seconds: 'nan' is not a number"},
      {"bench agvs --views 0", "--views: '0' is not a whole number"},
      {"bench agvs --checkpoints 31", "--checkpoints: '31' is not a whole number from 1 to 30"},
      {"bench agvs --cell-size 0", "--cell-size: '0' is not a number"},
      {"bench server --sessions nan", "--sessions: 'nan' is not a whole number"},
      {"bench server --speed nan", "--speed: 'nan' is not a number"},
      {"bench server --res 0", "--res: '0' is not a power of two from 1 to 256"},
      {"bench client --threads 0", "--threads: '0' is not a whole number from 1 to 256"},
      {"bench client --seconds inf", "--seconds: 'inf' is not a number"},
      {"bench client --lod 0", "--lod: '0' is not a screen error"},
      {"bench server --lod -1", "--lod: '-1' is not a screen error"},
      {"bench web --speed nan", "--speed: 'nan' is not a number"},
      {"bench web --seconds 0", "--seconds: '0' is not a number"},
      {"bench web --poses 101", "--poses: '101' is not a whole number from 0 to 100"},
      {"bench web --max-fps inf", "--max-fps: 'inf' is not a number"},
      {"bench web --size 10x10", "--size: expected WIDTHxHEIGHT, e.g. 1280x720"},
  };
  for (const auto& c : cases) ExpectBadOption(c.args, c.message);
}

// The three executables share their numeric checks (cli/number_options.h) and exit code 2.
TEST(Cli, ServerAndClientRejectNanOptionsAsTheToolDoes) {
  const std::string bin = std::filesystem::path(VISTREAM_BIN).parent_path().string();
  for (const std::string& cmd : {bin + "/vistream-server --scene city1 --cell-size nan",
                                 bin + "/vistream-client --headless --speed nan"}) {
    FILE* pipe = popen(("exec " + cmd + " 2>&1").c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    std::string out;
    std::array<char, 4096> buf;
    while (size_t n = fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
    const int status = pclose(pipe);
    ASSERT_TRUE(WIFEXITED(status)) << cmd << "\n" << out;
    EXPECT_EQ(WEXITSTATUS(status), kBadOption) << cmd << "\n" << out;
    EXPECT_NE(out.find("'nan' is not a number from 0.01 to "), std::string::npos) << cmd << "\n" << out;
  }
}

// A glTF file of plain meshes has no occluders: the dual ray space hides nothing, so the PVS
// check could not have failed, and no free street-level neighbourhood may exist. Such a check
// says so and fails unless --allow-unchecked.
std::string GltfWithoutOccluders() {
  const std::string bin = Tmp("no_occluders.bin"), gltf = Tmp("no_occluders.gltf");
  // Two triangles (glTF is y-up): a 60 x 60 m ground and a 10 m high wall across it.
  const std::vector<float> p = {0, 0, 0, 60, 0, 0, 0, 0, -60, 30, 0, 0, 30, 0, -60, 30, 10, -30};
  std::ofstream(bin, std::ios::binary).write(reinterpret_cast<const char*>(p.data()), p.size() * sizeof(float));
  std::ofstream(gltf) << R"({"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0, 1]}],
    "nodes": [{"mesh": 0, "name": "ground"}, {"mesh": 1, "name": "wall"}],
    "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}, {"primitives": [{"attributes": {"POSITION": 1}}]}],
    "accessors": [
      {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, -60], "max": [60, 0, 0]},
      {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3", "min": [30, 0, -60], "max": [30, 10, 0]}],
    "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 36}],
    "buffers": [{"uri": "no_occluders.bin", "byteLength": 72}]})";
  return gltf;
}

TEST(Cli, CheckConservativeThatCheckedNothingSaysSoAndFails) {
  const std::string args = "check-conservative --scene " + GltfWithoutOccluders() + " --cell-size 10 --samples 100000";
  const RunResult r = Vistream(args);
  EXPECT_EQ(r.exit_code, kRunTimeError) << r.out;
  EXPECT_NE(r.out.find("vistream: error: check-conservative checked nothing: the dual ray space hid nothing"),
            std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("--allow-unchecked"), std::string::npos) << r.out;
  // In JSON too, and --allow-unchecked accepts it (still said, as a warning).
  const RunResult j = Vistream(args + " --allow-unchecked --json");
  ASSERT_EQ(j.exit_code, 0) << j.out;
  const std::string json = j.out.substr(j.out.find('{'), j.out.rfind('}') - j.out.find('{') + 1);
  const nlohmann::json k = nlohmann::json::parse(json);
  EXPECT_EQ(k.at("violations").get<int>(), 0);
  EXPECT_EQ(k.at("occluded_queries").get<int>(), 0);
  EXPECT_GE(k.at("unchecked").size(), 1u) << j.out;
  EXPECT_NE(j.out.find("vistream: warning: check-conservative checked nothing"), std::string::npos) << j.out;
  // A real scene checks both parts: nothing unchecked.
  const RunResult city = Vistream("check-conservative --scene city1 --cells 4 --samples 200000 --json");
  ASSERT_EQ(city.exit_code, 0) << city.out;
  EXPECT_TRUE(nlohmann::json::parse(city.out).at("unchecked").empty()) << city.out;
}

}  // namespace
