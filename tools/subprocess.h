#pragma once
// Running a program and collecting what it printed: gnuplot for the plots, and the tool itself
// (/proc/self/exe) for each step of `vistream report`.

#include <atomic>
#include <string>
#include <vector>

#include <absl/status/statusor.h>

namespace vistream::tools {

struct ProcessResult {
  int exit_code = 0;  // the program's own; 128 + N when signal N ended it
  std::string out;    // its standard output
  std::string err;    // its standard error
  double seconds = 0.0;
};

// Runs `argv` (argv[0] looked up on PATH when it has no '/'), stdin from /dev/null, stdout
// and stderr collected through temporary files. An error only when it could not be started:
// NOT_FOUND when the program does not exist, naming it.
// With `cancel`, a flag set while the program runs (a ^C of the caller's) passes SIGINT on to
// it once, and the program's own exit is returned as usual.
absl::StatusOr<ProcessResult> RunProcess(const std::vector<std::string>& argv,
                                         const std::atomic<bool>* cancel = nullptr);

// The last `lines` lines of `text`.
std::string LastLines(const std::string& text, int lines);

}  // namespace vistream::tools
