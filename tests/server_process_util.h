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

namespace vistream::server::test {

// Runs the vistream-server executable with `args` (a shell line's words) to its end: its exit
// code (-1 if it did not exit) and everything it printed.
inline std::pair<int, std::string> RunServer(const std::string& args) {
  std::string out;
  std::FILE* p = popen((std::string(VISTREAM_SERVER_BIN) + " " + args + " 2>&1").c_str(), "r");
  if (p == nullptr) return {-1, out};
  char buf[1024];
  for (size_t n; (n = std::fread(buf, 1, sizeof(buf), p)) > 0;) out.append(buf, n);
  const int status = pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

class RunningServer {
 public:
  // Starts `binary` with `args` (stdout read for the ready line, stderr to `log_path` if given,
  // else inherited). Returns null, with what it printed in `*error`, when it exits or prints
  // something else first.
  static std::unique_ptr<RunningServer> Start(const std::string& binary, const std::vector<std::string>& args,
                                              std::string* error, const std::string& log_path = "") {
    int out[2];
    if (pipe(out) != 0) return nullptr;
    const pid_t pid = fork();
    if (pid < 0) return nullptr;
    if (pid == 0) {
      dup2(out[1], STDOUT_FILENO);
      close(out[0]);
      if (!log_path.empty()) {  // open(), not fopen(): async-signal-safe in the forked child
        if (const int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644); log >= 0) {
          dup2(log, STDERR_FILENO);
        }
      }
      std::vector<char*> argv{const_cast<char*>(binary.c_str())};
      for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(binary.c_str(), argv.data());
      _exit(127);
    }
    close(out[1]);
    std::unique_ptr<RunningServer> s(new RunningServer());
    s->pid_ = pid;
    s->out_ = fdopen(out[0], "r");
    char line[4096] = {};
    if (std::fgets(line, sizeof(line), s->out_) == nullptr) {
      if (error != nullptr) *error = "the server exited (status " + std::to_string(s->Stop(SIGKILL)) + ")";
      return nullptr;
    }
    s->ready_ = line;
    const size_t at = s->ready_.find("ready on ");
    if (at == std::string::npos) {
      if (error != nullptr) *error = s->ready_;
      return nullptr;
    }
    const size_t colon = s->ready_.find(':', at + 9);
    s->address_ = s->ready_.substr(at + 9, s->ready_.find(':', colon + 1) - at - 9);
    return s;
  }

  ~RunningServer() {
    if (pid_ > 0) Stop(SIGKILL);
  }

  const std::string& address() const { return address_; }
  const std::string& ready_line() const { return ready_; }
  pid_t pid() const { return pid_; }
  // The port of address().
  int port() const { return std::stoi(address_.substr(address_.rfind(':') + 1)); }

  // Sends `sig` (0: none, only waits) and waits: the exit code, 128 + the signal if killed, -1
  // if already stopped.
  int Stop(int sig = SIGTERM) {
    if (pid_ <= 0) return -1;
    if (sig != 0) kill(pid_, sig);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    if (out_ != nullptr) std::fclose(out_);
    out_ = nullptr;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  }

 private:
  RunningServer() = default;
  pid_t pid_ = -1;
  std::FILE* out_ = nullptr;
  std::string ready_, address_;
};

}  // namespace vistream::server::test
