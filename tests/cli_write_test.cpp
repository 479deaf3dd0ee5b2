// The files the vistream tool writes, when writing fails part-way (a full disk, a file size
// limit): the command fails and names the file, and what the file held before is kept.
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/cli_test_util.h"

namespace {

using vistream::testing::ExpectBadOption;
using vistream::testing::RunResult;
using vistream::testing::Tmp;
using vistream::testing::Vistream;

// Files the tool writes may grow to about 100 kB (ulimit -f counts blocks of 512 or 1024
// bytes, by shell); past that a write fails as on a full disk (SIGXFSZ ignored).
const std::string kLimited = "ulimit -f 200; trap '' XFSZ; ";

std::string Bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(CliWrites, AGlbWriteCutShortFailsAndKeepsTheFileThatWasThere) {
  const std::string glb = Tmp("kept.glb");
  ASSERT_EQ(Vistream("scene generate city1 -o " + glb).exit_code, 0);
  const std::string before = Bytes(glb);
  const RunResult r = Vistream("scene generate city2 -o " + glb, kLimited);  // 3.7 MB
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find(glb + ": cannot write"), std::string::npos) << r.out;
  EXPECT_EQ(Bytes(glb), before);
  EXPECT_FALSE(std::filesystem::exists(glb + ".tmp"));
  const RunResult info = Vistream("scene info " + glb + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.out;
  EXPECT_EQ(nlohmann::json::parse(info.out).at("name"), "city1");
}

TEST(CliWrites, AGltfWriteCutShortFails) {
  const std::string gltf = Tmp("cut.gltf");
  const RunResult r = Vistream("scene generate city1 -o " + gltf, kLimited);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find(gltf + ": cannot write"), std::string::npos) << r.out;
  // Without the limit the same command writes a file that loads.
  ASSERT_EQ(Vistream("scene generate city1 -o " + gltf).exit_code, 0);
  EXPECT_EQ(Vistream("scene info " + gltf).exit_code, 0);
}

// Told before any work (a city's levels take minutes), as a bad option.
TEST(CliWrites, AGlbIntoAMissingFolderIsABadOption) {
  const std::string glb = Tmp("no-such-folder") + "/x.glb";
  ExpectBadOption("scene generate default -o " + glb,
                  "--output: '" + glb + "': there is no folder '" + Tmp("no-such-folder") + "' to write it in");
}

// An empty output path is a bad option (exit 2), not a file named by its extension alone.
TEST(CliWrites, AnEmptyOutputPathIsABadOption) {
  ExpectBadOption("scene generate city1 -o ''", "--output: an empty path");
  ExpectBadOption("scene import-osm x.osm -o ''", "--output: an empty path");
  ExpectBadOption("scene map city1 -o ''", "--output: an empty path");
}

// So are the other paths and names a command writes or is given: empty, each is refused before
// any work rather than taken as "none" or the default (a report into bench/figures, say).
TEST(CliWrites, AnEmptyPathOrNameIsABadOptionNotTheDefault) {
  ExpectBadOption("report --out ''", "--out: an empty path");
  ExpectBadOption("agvs --scene city1 --seconds 1 -o ''", "-o: an empty path");
  ExpectBadOption("agvs --scene city1 --seconds 1 --state ''", "--state: an empty path");
  ExpectBadOption("agvs heatmap --scene city1 --seconds 1 -o ''", "-o: an empty path");
  ExpectBadOption("pvs --scene city1 --all -o ''", "--out: an empty path");
  ExpectBadOption("pvs --scene city1 --cell 0,0 --map ''", "--map: an empty path");
  ExpectBadOption("epsilon --scene city1 --at 0,0,1.7 --size 1 --map ''", "--map: an empty path");
  ExpectBadOption("bench agvs --plot ''", "--plot: an empty path");
  ExpectBadOption("bench server --log ''", "--log: an empty path");
  ExpectBadOption("bench client --path ''", "--path: an empty walk name");
  ExpectBadOption("scene import-osm x.osm -o x.glb --name ''", "--name: an empty name");
  ExpectBadOption("scene import-city x.gml -o x.glb --name ''", "--name: an empty name");
}

// A sampler's state that cannot be saved whole is not lost: the state saved before is kept,
// and sampling resumes from it.
TEST(CliWrites, AnAgvsStateSaveCutShortKeepsTheStateSavedBefore) {
  const std::string state = Tmp("kept.state");
  std::filesystem::remove(state);
  const std::string args = "agvs --scene city1 --samples 200000 --json --state " + state;
  ASSERT_EQ(Vistream(args).exit_code, 0);
  const std::string before = Bytes(state);
  ASSERT_GT(before.size(), 200000u);  // past the limit below
  const RunResult cut = Vistream(args, kLimited);
  EXPECT_EQ(cut.exit_code, 1) << cut.out;
  EXPECT_NE(cut.out.find("cannot write '" + state + "'"), std::string::npos) << cut.out;
  EXPECT_EQ(Bytes(state), before);
  EXPECT_FALSE(std::filesystem::exists(state + ".tmp"));
  const RunResult resumed = Vistream(args);
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out;
}

TEST(CliWrites, AMapPngCutShortKeepsThePngThatWasThere) {
  const std::string png = Tmp("kept-map.png");
  ASSERT_EQ(Vistream("scene map default -o " + png + " --size 64").exit_code, 0);
  const std::string before = Bytes(png);
  ASSERT_LT(before.size(), 100000u);
  const RunResult r = Vistream("scene map default -o " + png + " --size 4000", kLimited);
  EXPECT_EQ(r.exit_code, 1) << r.out;
  EXPECT_NE(r.out.find("cannot write the PNG '" + png + "'"), std::string::npos) << r.out;
  EXPECT_EQ(Bytes(png), before);
  EXPECT_FALSE(std::filesystem::exists(png + ".tmp"));
}

}  // namespace
