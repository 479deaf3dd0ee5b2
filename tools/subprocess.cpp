#include "tools/subprocess.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <thread>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include <absl/strings/str_cat.h>

#include "tools/cli_common.h"

extern char** environ;

namespace vistream::tools {

namespace fs = std::filesystem;

absl::StatusOr<ProcessResult> RunProcess(const std::vector<std::string>& argv, const std::atomic<bool>* cancel) {
  if (argv.empty()) return absl::InvalidArgumentError("RunProcess: no program");
  std::error_code ec;
  std::string tmpl = (fs::temp_directory_path(ec) / "vistream-run-XXXXXX").string();
  if (mkdtemp(tmpl.data()) == nullptr) {
    return absl::UnavailableError(absl::StrCat("cannot make a temporary folder: ", std::strerror(errno)));
  }
  const fs::path dir = tmpl;
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ignored;
      fs::remove_all(dir, ignored);
    }
  } cleanup{dir};
  const std::string out_path = (dir / "out").string(), err_path = (dir / "err").string();

  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  std::vector<std::string> args = argv;
  std::vector<char*> cargv;
  for (std::string& s : args) cargv.push_back(s.data());
  cargv.push_back(nullptr);
  const auto start = std::chrono::steady_clock::now();
  pid_t pid = 0;
  const int err = posix_spawnp(&pid, args[0].c_str(), &actions, nullptr, cargv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (err == ENOENT) return absl::NotFoundError(absl::StrCat("cannot run '", argv[0], "': not found"));
  if (err != 0) return absl::InternalError(absl::StrCat("cannot run '", argv[0], "': ", std::strerror(err)));
  int status = 0;
  if (cancel == nullptr) {
    while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
    }
  } else {
    bool passed_on = false;
    for (;;) {
      const pid_t done = waitpid(pid, &status, WNOHANG);
      if (done == pid || (done < 0 && errno != EINTR)) break;
      if (!passed_on && cancel->load()) {
        kill(pid, SIGINT);  // the program stops as on ^C (and the caller's ^C may have reached it already)
        passed_on = true;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
  }
  ProcessResult r;
  r.seconds = SecondsSince(start);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? 128 + WTERMSIG(status) : 255;
  if (absl::StatusOr<std::string> s = ReadFile(out_path); s.ok()) r.out = std::move(*s);
  if (absl::StatusOr<std::string> s = ReadFile(err_path); s.ok()) r.err = std::move(*s);
  return r;
}

std::string LastLines(const std::string& text, int lines) {
  size_t end = text.size();
  while (end > 0 && (text[end - 1] == '\n' || text[end - 1] == '\r')) --end;
  size_t at = end;
  for (int n = 0; n < lines && at > 0; ++n) {
    at = text.rfind('\n', at - 1);
    if (at == std::string::npos) {
      at = 0;
      break;
    }
    if (n + 1 < lines && at == 0) break;
  }
  const size_t begin = at == 0 && (text.empty() || text[0] != '\n') ? 0 : at + 1;
  return text.substr(begin, end - begin);
}

}  // namespace vistream::tools
