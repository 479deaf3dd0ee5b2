#pragma once
// A real redis-server (Debian's) started by a test on a free loopback port, without
// persistence, and always stopped: the shared PVS store's tests run against it.

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "tests/loopback_util.h"

namespace vistream::test {

class RedisServer {
 public:
  // Starts redis-server on 127.0.0.1 at a free port and waits until it answers PING. Null, with
  // why in `*error`, when redis-server is missing or does not come up.
  static std::unique_ptr<RedisServer> Start(std::string* error) {
    std::unique_ptr<RedisServer> r(new RedisServer());
    r->port_ = FreeLoopbackPort();
    if (!r->Launch(error)) return nullptr;
    return r;
  }
  ~RedisServer() { Stop(); }

  int port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  pid_t pid() const { return pid_; }

  // Stops it (SIGKILL: an outage, not a shutdown) and reaps it.
  void Stop() {
    if (pid_ <= 0) return;
    kill(pid_, SIGCONT);
    kill(pid_, SIGKILL);
    waitpid(pid_, nullptr, 0);
    pid_ = -1;
  }
  // Starts it again on the same port (empty: no persistence).
  bool Restart(std::string* error) {
    Stop();
    return Launch(error);
  }
  // Freezes and thaws it (SIGSTOP, SIGCONT): a store that accepts connections but answers
  // nothing, as an overloaded one.
  void Pause() { kill(pid_, SIGSTOP); }
  void Resume() { kill(pid_, SIGCONT); }

  // redis-cli's output for `args` (a shell line's words) against this server.
  std::string Cli(const std::string& args) const {
    std::string out;
    const std::string cmd = "redis-cli -h 127.0.0.1 -p " + std::to_string(port_) + " " + args + " 2>&1";
    std::FILE* p = popen(cmd.c_str(), "r");
    if (p == nullptr) return out;
    char buf[4096];
    for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
    pclose(p);
    while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
    return out;
  }

 private:
  RedisServer() = default;

  bool Launch(std::string* error) {
    const std::string port = std::to_string(port_);
    const pid_t pid = fork();
    if (pid < 0) {
      *error = "fork failed";
      return false;
    }
    if (pid == 0) {
      const int devnull = ::open("/dev/null", O_WRONLY);
      if (devnull >= 0) {
        dup2(devnull, STDOUT_FILENO);
        dup2(devnull, STDERR_FILENO);
      }
      execlp("redis-server", "redis-server", "--port", port.c_str(), "--bind", "127.0.0.1", "--save", "",
             "--appendonly", "no", "--daemonize", "no", "--protected-mode", "yes", static_cast<char*>(nullptr));
      _exit(127);
    }
    pid_ = pid;
    for (int k = 0; k < 200; ++k) {
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {
        pid_ = -1;
        *error = WIFEXITED(status) && WEXITSTATUS(status) == 127
                     ? "redis-server is not installed (Debian redis-server; ./vistream.sh installs it)"
                     : "redis-server exited at start on port " + port;
        return false;
      }
      if (Cli("PING") == "PONG") return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    *error = "redis-server did not answer PING on port " + port + " within 10 s";
    Stop();
    return false;
  }

  int port_ = 0;
  pid_t pid_ = -1;
};

}  // namespace vistream::test
