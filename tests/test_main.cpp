// The main of every test binary: gtest's, with two rules CI relies on.
//
// 1. A suite whose SetUpTestSuite or TearDownTestSuite failed fails. gtest 1.12 reports the
//    tests of such a suite as skipped and prints "[  SKIPPED ]", which ctest (through
//    gtest_discover_tests' SKIP_REGULAR_EXPRESSION) counted as a skip, not a failure.
// 2. A skipped test prints "vistream-test: skipped: NAME: REASON", the line ctest reads as a
//    skip (tests/CMakeLists.txt). With VISTREAM_EXPECTED_SKIPS=FILE (CI sets it), a skip that
//    FILE does not list is a failure instead. FILE: one test name a line, then its reason;
//    '#' starts a comment.
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

namespace {

std::set<std::string> ExpectedSkips(const char* path, bool* ok) {
  std::set<std::string> names;
  std::ifstream in(path);
  *ok = static_cast<bool>(in);
  for (std::string line; std::getline(in, line);) {
    line = line.substr(0, line.find('#'));
    std::istringstream words(line);
    if (std::string name; words >> name) names.insert(name);
  }
  return names;
}

std::string SkipReason(const ::testing::TestResult& result) {
  for (int k = 0; k < result.total_part_count(); ++k) {
    const ::testing::TestPartResult& part = result.GetTestPartResult(k);
    if (part.skipped()) return part.message();
  }
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  const int code = RUN_ALL_TESTS();
  const ::testing::UnitTest& unit = *::testing::UnitTest::GetInstance();
  bool failed = false;
  for (int i = 0; i < unit.total_test_suite_count(); ++i) {
    const ::testing::TestSuite& suite = *unit.GetTestSuite(i);
    if (suite.ad_hoc_test_result().Failed()) {
      std::printf("vistream-test: error: %s: SetUpTestSuite or TearDownTestSuite failed (above), so its %d tests "
                  "did not run: a failure, not a skip\n",
                  suite.name(), suite.test_to_run_count());
      failed = true;
    }
  }
  if (failed) return 1;

  const char* expected_path = std::getenv("VISTREAM_EXPECTED_SKIPS");
  bool readable = true;
  const std::set<std::string> expected =
      expected_path != nullptr ? ExpectedSkips(expected_path, &readable) : std::set<std::string>{};
  if (!readable) {
    std::printf("vistream-test: error: VISTREAM_EXPECTED_SKIPS: cannot read '%s'\n", expected_path);
    return 1;
  }
  for (int i = 0; i < unit.total_test_suite_count(); ++i) {
    const ::testing::TestSuite& suite = *unit.GetTestSuite(i);
    for (int j = 0; j < suite.total_test_count(); ++j) {
      const ::testing::TestInfo& test = *suite.GetTestInfo(j);
      if (!test.should_run() || !test.result()->Skipped()) continue;
      const std::string name = std::string(suite.name()) + "." + test.name();
      const std::string reason = SkipReason(*test.result());
      if (expected_path != nullptr && expected.count(name) == 0) {
        std::printf("vistream-test: error: %s was skipped (%s), and %s does not expect it\n", name.c_str(),
                    reason.c_str(), expected_path);
        failed = true;
      } else {
        std::printf("vistream-test: skipped: %s: %s\n", name.c_str(), reason.c_str());
      }
    }
  }
  return failed ? 1 : code;
}
