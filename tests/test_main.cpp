// The main of every test binary: gtest's, with two rules CI relies on.
//
// 1. A suite whose SetUpTestSuite or TearDownTestSuite failed fails. gtest 1.12 reports the
//    tests of such a suite as skipped ("[  SKIPPED ]", exit 1), and ctest, through the
//    SKIP_REGULAR_EXPRESSION gtest_discover_tests sets, counted them as skips.
// 2. With VISTREAM_EXPECTED_SKIPS=FILE (CI sets it), a skipped test that FILE does not list
//    fails. FILE: one test name a line (Suite.Test), then its reason; '#' starts a comment.
// Either way the test is reported as "[  FAILED  ]", never with gtest's "[  SKIPPED ]" line
// (ctest adds skip patterns to gtest's rather than replacing it, so that line must not show).
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <set>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

namespace {

using ::testing::TestEventListener;
using ::testing::TestInfo;
using ::testing::TestSuite;
using ::testing::UnitTest;

std::set<std::string> ReadExpectedSkips(const char* path, bool* ok) {
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
    if (result.GetTestPartResult(k).skipped()) return result.GetTestPartResult(k).message();
  }
  return "";
}

// gtest's printer, except for skips that are failures here.
class Printer : public TestEventListener {
 public:
  Printer(TestEventListener* inner, const char* expected_path, std::set<std::string> expected)
      : inner_(inner), expected_path_(expected_path), expected_(std::move(expected)) {}

  int failures() const { return failures_; }

  void OnTestEnd(const TestInfo& test) override {
    const TestSuite* suite = UnitTest::GetInstance()->current_test_suite();
    if (!test.result()->Skipped() || suite == nullptr) return inner_->OnTestEnd(test);
    const std::string name = std::string(test.test_suite_name()) + "." + test.name();
    if (suite->ad_hoc_test_result().Failed()) {
      Fail(name, "did not run: its SetUpTestSuite failed (above)");
    } else if (expected_path_ != nullptr && expected_.count(name) == 0) {
      Fail(name, "skipped (" + SkipReason(*test.result()) + "), and " + expected_path_ + " does not expect it");
    } else {
      inner_->OnTestEnd(test);
    }
  }

  void OnTestIterationEnd(const UnitTest& unit, int iteration) override {
    if (failures_ == 0) return inner_->OnTestIterationEnd(unit, iteration);
    std::printf("[  FAILED  ] %d tests skipped where a skip is a failure (above); %d others failed\n", failures_,
                unit.failed_test_count());
    std::fflush(stdout);
  }

  // The rest as gtest prints it.
  void OnTestProgramStart(const UnitTest& u) override { inner_->OnTestProgramStart(u); }
  void OnTestIterationStart(const UnitTest& u, int i) override { inner_->OnTestIterationStart(u, i); }
  void OnEnvironmentsSetUpStart(const UnitTest& u) override { inner_->OnEnvironmentsSetUpStart(u); }
  void OnEnvironmentsSetUpEnd(const UnitTest& u) override { inner_->OnEnvironmentsSetUpEnd(u); }
  void OnTestSuiteStart(const TestSuite& s) override { inner_->OnTestSuiteStart(s); }
#ifndef GTEST_REMOVE_LEGACY_TEST_CASEAPI_
  void OnTestCaseStart(const ::testing::TestCase& s) override { inner_->OnTestCaseStart(s); }
  void OnTestCaseEnd(const ::testing::TestCase& s) override { inner_->OnTestCaseEnd(s); }
#endif
  void OnTestStart(const TestInfo& t) override { inner_->OnTestStart(t); }
  void OnTestDisabled(const TestInfo& t) override { inner_->OnTestDisabled(t); }
  void OnTestPartResult(const ::testing::TestPartResult& r) override { inner_->OnTestPartResult(r); }
  void OnTestSuiteEnd(const TestSuite& s) override { inner_->OnTestSuiteEnd(s); }
  void OnEnvironmentsTearDownStart(const UnitTest& u) override { inner_->OnEnvironmentsTearDownStart(u); }
  void OnEnvironmentsTearDownEnd(const UnitTest& u) override { inner_->OnEnvironmentsTearDownEnd(u); }
  void OnTestProgramEnd(const UnitTest& u) override { inner_->OnTestProgramEnd(u); }

 private:
  void Fail(const std::string& name, const std::string& why) {
    std::printf("[  FAILED  ] %s: %s\n", name.c_str(), why.c_str());
    std::fflush(stdout);
    ++failures_;
  }

  std::unique_ptr<TestEventListener> inner_;
  const char* expected_path_;
  std::set<std::string> expected_;
  int failures_ = 0;
};

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  const char* expected_path = std::getenv("VISTREAM_EXPECTED_SKIPS");
  bool readable = true;
  std::set<std::string> expected;
  if (expected_path != nullptr) expected = ReadExpectedSkips(expected_path, &readable);
  if (!readable) {
    std::printf("vistream-test: error: VISTREAM_EXPECTED_SKIPS: cannot read '%s'\n", expected_path);
    return 1;
  }
  ::testing::TestEventListeners& listeners = UnitTest::GetInstance()->listeners();
  auto* printer = new Printer(listeners.Release(listeners.default_result_printer()), expected_path, std::move(expected));
  listeners.Append(printer);  // owned by gtest from here
  const int code = RUN_ALL_TESTS();
  return printer->failures() > 0 ? 1 : code;
}
