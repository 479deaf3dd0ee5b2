// Viewcells that follow terrain, end to end (issue 35, "Terrain"): a town of terraced streets set
// on a ridge between two valleys, its terrain a closed solid with the simplest conservative
// occluders (a ground-up prism per triangle at its lowest vertex), saved as glTF and checked by
// check-conservative: nothing sampling sees from a cell's band (which follows the ground) may
// be missing from its dual-ray-space PVS or from an ε-superset standing on the ground.

#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "scenes/city_generator.h"
#include "scenes/gltf_io.h"
#include "tests/cli_test_util.h"
#include "tests/terrain_test_util.h"

namespace {

using vistream::testing::RunResult;
using vistream::testing::Tmp;
using vistream::testing::Vistream;

// Made once per process.
const std::string& HillyTown() {
  static const std::string path = [] {
    namespace scenes = vistream::scenes;
    scenes::Scene s = vistream::testing::OnTheRidge(scenes::GenerateStreets({.seed = 3, .width_m = 240, .depth_m = 240}));
    scenes::NormalizeOccluders(&s);
    const absl::Status valid = scenes::ValidateScene(s, "hilly town");
    EXPECT_TRUE(valid.ok()) << valid;
    const std::string out = Tmp("hilly-town.glb");
    const absl::Status saved = scenes::SaveGltf(s, out);
    EXPECT_TRUE(saved.ok()) << saved;
    return out;
  }();
  return path;
}

struct TerrainCase {
  int cell_size;
  const char* backend;
  int cells;  // sampled viewcells (0: all)
  const char* samples;
  double min_entries;
  int min_exact_tests;  // the exact backend's own test ran (0: not asked)
};

void PrintTo(const TerrainCase& c, std::ostream* os) { *os << c.cell_size << " m cells, " << c.backend; }

class CheckConservativeOnTerrain : public ::testing::TestWithParam<TerrainCase> {};

TEST_P(CheckConservativeOnTerrain, FindsNoViolation) {
  const TerrainCase& c = GetParam();
  const RunResult r = Vistream("check-conservative --scene " + HillyTown() + " --cell-size " +
                               std::to_string(c.cell_size) + " --backend " + c.backend + " --cells " +
                               std::to_string(c.cells) + " --samples " + c.samples + " --neighbourhoods 10 --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("cell_size").get<double>(), c.cell_size);
  EXPECT_EQ(j.at("violations").get<int>(), 0) << r.out;
  // Not vacuous: entries checked, something hidden, rays from the neighbourhoods checked.
  EXPECT_GT(j.at("pvs_entries_checked").get<double>(), c.min_entries) << r.out;
  EXPECT_GT(j.at("occluded_queries").get<double>(), 10.0) << r.out;
  EXPECT_GT(j.at("epsilon_hits_checked").get<double>(), 1000.0) << r.out;
  EXPECT_GE(j.at("exact_tests").get<int>(), c.min_exact_tests) << r.out;
}

std::string CaseName(const ::testing::TestParamInfo<TerrainCase>& test) {
  return std::to_string(test.param.cell_size) + "m_" + test.param.backend;
}

INSTANTIATE_TEST_SUITE_P(HillyTown, CheckConservativeOnTerrain,
                         ::testing::Values(TerrainCase{100, "cpu", 0, "3000000", 800, 0},
                                           TerrainCase{100, "exact", 0, "3000000", 800, 0}),
                         CaseName);

// At 8 m cells (a cell inside most houses): sampled viewcells, and the exact backend's own test.
// (Surface samples starting on a party wall once saw the ground inside the neighbouring house
// here: tests/agvs_discard_test.cpp's NothingIsSeenFromAPointOnAPartyWall.)
INSTANTIATE_TEST_SUITE_P(HillyTownSmallCells, CheckConservativeOnTerrain,
                         ::testing::Values(TerrainCase{8, "cpu", 200, "3000000", 5000, 0},
                                           TerrainCase{8, "exact", 100, "3000000", 2500, 1}),
                         CaseName);

}  // namespace
