// The .glb files vistream writes, as other tools read them: the Khronos glTF validator
// (npm gltf-validator, installed by ./vistream.sh's set-up into BUILD/node) must report no
// errors and no warnings on a generated city and on an OpenStreetMap import. Infos and hints
// are allowed (printed when there are any): they flag style, not files other tools misread.
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/temp_dir.h"

namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code;
  std::string out;  // stdout (stderr too when `merge_stderr`)
};

RunResult RunCommand(const std::string& cmd, bool merge_stderr) {
  FILE* pipe = popen((cmd + (merge_stderr ? " 2>&1" : "")).c_str(), "r");
  if (pipe == nullptr) return {-1, "popen failed"};
  std::string out;
  std::array<char, 4096> buf;
  while (size_t n = fread(buf.data(), 1, buf.size(), pipe)) out.append(buf.data(), n);
  const int status = pclose(pipe);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

std::string Tmp(const std::string& name) { return vistream::testing::ProcessTempDir() + "/" + name; }

// The validator's report on `file`; fails the test (with how to install the validator) when
// it cannot run.
nlohmann::json Validate(const std::string& file) {
  const std::string dir = GLTF_VALIDATOR_DIR;
  const std::string install = std::string("install it with ./vistream.sh test (its set-up does), or by hand: npm install "
                                          "--prefix ") + fs::path(dir).parent_path().parent_path().string() +
                              " gltf-validator@" + GLTF_VALIDATOR_VERSION + " (node and npm: Debian's nodejs, npm)";
  if (!fs::exists(fs::path(dir) / "package.json")) {
    ADD_FAILURE() << "the Khronos glTF validator is not installed at " << dir << ": " << install;
    return {};
  }
  const RunResult r = RunCommand("node '" + std::string(GLTF_VALIDATE_JS) + "' '" + dir + "' '" + file + "'", false);
  if (r.exit_code != 0) {
    ADD_FAILURE() << "node " << GLTF_VALIDATE_JS << " failed (exit " << r.exit_code << "): " << r.out
                  << "\nIs node installed? " << install;
    return {};
  }
  nlohmann::json report = nlohmann::json::parse(r.out, nullptr, false);
  if (report.is_discarded() || !report.contains("issues")) {
    ADD_FAILURE() << "the validator's output is not a report: " << r.out.substr(0, 2000);
    return {};
  }
  return report;
}

// No errors, no warnings; and the validator counts the vertices and draw calls the scene has
// (one shared vertex accessor made it count every object's reference to all of them).
void ExpectCleanReport(const std::string& glb) {
  const RunResult info = RunCommand(std::string(VISTREAM_BIN " scene info '") + glb + "' --json", false);
  ASSERT_EQ(info.exit_code, 0) << info.out;
  const nlohmann::json scene = nlohmann::json::parse(info.out);
  const nlohmann::json report = Validate(glb);
  if (report.is_null()) return;
  const nlohmann::json& issues = report["issues"];
  EXPECT_EQ(issues["numErrors"], 0) << issues.dump(1);
  EXPECT_EQ(issues["numWarnings"], 0) << issues.dump(1);
  if (issues["numInfos"] != 0 || issues["numHints"] != 0) std::printf("infos/hints: %s\n", issues.dump().c_str());
  EXPECT_EQ(report["info"]["totalVertexCount"], scene["vertices"]);
  EXPECT_EQ(report["info"]["totalTriangleCount"], scene["triangles"]);
  EXPECT_EQ(report["info"]["drawCallCount"], scene["objects"]);
}

TEST(GltfValidator, GeneratedCityHasNoErrorsOrWarnings) {
  const std::string glb = Tmp("city1.glb");
  const RunResult gen = RunCommand(std::string(VISTREAM_BIN " scene generate city1 -o '") + glb + "'", true);
  ASSERT_EQ(gen.exit_code, 0) << gen.out;
  ExpectCleanReport(glb);
}

TEST(GltfValidator, OsmImportHasNoErrorsOrWarnings) {
  const std::string glb = Tmp("terrace.glb");
  const RunResult imp = RunCommand(std::string(VISTREAM_BIN " scene import-osm '") + VISTREAM_TESTS_DIR +
                                "/osm/multipolygon.osm' -o '" + glb + "'", true);
  ASSERT_EQ(imp.exit_code, 0) << imp.out;
  ExpectCleanReport(glb);
}

TEST(GltfValidator, ValidatorReportsAnErrorInABrokenFile) {
  // The check can fail: a .glb whose index points past its mesh's vertices is an error.
  const std::string glb = Tmp("broken.glb");
  const RunResult gen = RunCommand(std::string(VISTREAM_BIN " scene generate city1 -o '") + glb + "'", true);
  ASSERT_EQ(gen.exit_code, 0) << gen.out;
  std::string bytes;
  {
    FILE* f = std::fopen(glb.c_str(), "rb");
    ASSERT_NE(f, nullptr);
    std::array<char, 4096> buf;
    while (size_t n = std::fread(buf.data(), 1, buf.size(), f)) bytes.append(buf.data(), n);
    std::fclose(f);
  }
  // The first object's first index (the index view follows positions and normals: find the
  // first accessor's count in the JSON instead of guessing offsets).
  const uint32_t json_length = *reinterpret_cast<const uint32_t*>(bytes.data() + 12);
  const nlohmann::json gltf = nlohmann::json::parse(bytes.substr(20, json_length));
  const nlohmann::json& index_view = gltf["bufferViews"][2];
  const size_t at = 20 + json_length + 8 + index_view.value("byteOffset", size_t{0});
  const uint32_t bad = 1000000;
  bytes.replace(at, 4, reinterpret_cast<const char*>(&bad), 4);
  {
    FILE* f = std::fopen(glb.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    std::fwrite(bytes.data(), 1, bytes.size(), f);
    std::fclose(f);
  }
  const nlohmann::json report = Validate(glb);
  if (report.is_null()) return;
  EXPECT_GT(report["issues"]["numErrors"], 0) << report["issues"].dump(1);
}

}  // namespace
