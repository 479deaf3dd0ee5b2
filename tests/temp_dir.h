#pragma once
// The test process's own temporary folder: `vistream-test-PID` under the system's temp folder,
// emptied when first asked for (a PID can repeat) and removed when the process exits normally
// (by its creator only: a forked child that exits leaves it). Header-only, so that every test
// binary shares one rule without linking test_util.cpp.

#include <sys/types.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>

namespace vistream::testing {

inline const std::string& ProcessTempDir() {
  // Heap-held and never freed: the exit handler below runs after static destructors would.
  static const std::string* dir = [] {
    const std::filesystem::path path =
        std::filesystem::temp_directory_path() / ("vistream-test-" + std::to_string(getpid()));
    std::error_code ec;
    std::filesystem::remove_all(path, ec);
    std::filesystem::create_directories(path);
    static const pid_t owner = getpid();
    std::atexit([] {
      if (getpid() != owner) return;
      std::error_code ignored;
      std::filesystem::remove_all(ProcessTempDir(), ignored);
    });
    return new std::string(path.string());
  }();
  return *dir;
}

}  // namespace vistream::testing
