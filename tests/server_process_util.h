#pragma once
// A vistream-server executable started by a test: its ready line, its address, and a stop that
// never leaves it running (the destructor kills what the test did not stop).

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "tools/replica_set.h"

namespace vistream::server::test {

// Runs the vistream-server executable with `args` (a shell line's words) to its end: its exit
// code (-1 if it did not exit) and everything it printed.
inline std::pair<int, std::string> RunServer(const std::string& args) {
  std::string out;
  std::FILE* p = popen((std::string(VISTREAM_SERVER_BIN " ") + args + " 2>&1").c_str(), "r");
  if (p == nullptr) return {-1, out};
  char buf[1024];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

using tools::RunningServer;

}  // namespace vistream::server::test
