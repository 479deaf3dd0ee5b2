#include "tools/cli_common.h"

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include <unistd.h>

#include <absl/strings/ascii.h>
#include <absl/strings/match.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>

#include "cli/stop_signal.h"
#include "cli/unexpected_arguments.h"
#include "scenes/catalog.h"
#include "tools/terminal_progress.h"

namespace vistream::tools {

std::atomic<bool>& CancelFlag() {
  static std::atomic<bool> flag{false};
  return flag;
}

void InstallCancelHandler() {
  std::signal(SIGINT, [](int) {
    static std::atomic<int64_t> first_ns{0};
    if (cli::ClassifyStopSignal(&CancelFlag(), &first_ns) != cli::StopSignal::kSecond) return;
    // Stopped at once, saying so (write(2) is async-signal-safe).
    static constexpr char kSay[] = "\nvistream: interrupted (a second ^C: stopped at once)\n";
    [[maybe_unused]] const ssize_t n = write(STDERR_FILENO, kSay, sizeof(kSay) - 1);
    std::_Exit(130);
  });
}

scenes::RunControl ToolRun() { return {&ToolProgress(), &CancelFlag()}; }

absl::StatusOr<scenes::Scene> LoadSceneArg(const std::string& arg, double* seconds) {
  scenes::LoadOptions options;
  options.run = ToolRun();
  absl::StatusOr<scenes::LoadedScene> loaded = scenes::LoadScene(arg, options);
  if (!loaded.ok()) return loaded.status();
  for (const std::string& w : loaded->warnings) std::fprintf(stderr, "vistream: warning: %s\n", w.c_str());
  if (seconds != nullptr) *seconds = loaded->seconds;
  // A catalog entry's walks join the scene's own paths: a scene a command saves keeps them
  // (a server loading the file sends them; vistream-client has no catalog entry for a file).
  if (loaded->entry.has_value()) scenes::AddDeclaredWalks(loaded->entry->walks, &loaded->scene);
  return std::move(loaded->scene);
}

namespace {

// The subcommand the user was giving options to: the deepest one parsed (`app` itself when
// none was), and its path as typed ("vistream bench table1") in `path`.
const CLI::App* DeepestCommand(const CLI::App& app, std::string* path) {
  *path = app.get_name();
  const CLI::App* at = &app;
  for (;;) {
    const std::vector<const CLI::App*> parsed = at->get_subcommands([](const CLI::App* s) { return s->parsed(); });
    if (parsed.empty()) return at;
    at = parsed.front();
    *path += " " + at->get_name();
  }
}

void PrintBadOption(const std::string& message, const std::string& command) {
  std::fprintf(stderr, "vistream: error: %s\nRun '%s --help' for the options.\n", message.c_str(), command.c_str());
}

// CLI11's messages, in the form "<option>: <what is wrong>" where they are not already.
std::string OptionMessage(const CLI::ParseError& e) {
  std::string m = e.what();
  for (const char* tail : {" is required"}) {
    const size_t at = m.rfind(tail);
    if (at != std::string::npos && at > 0 && at + std::strlen(tail) == m.size() && m.find(' ') == at) {
      return m.substr(0, at) + ": is required";
    }
  }
  for (const char* infix : {" excludes ", " requires "}) {
    const size_t at = m.find(infix);
    if (at != std::string::npos && m.find(' ') == at) {
      const std::string verb = std::string(infix) == " excludes " ? ": cannot be given with " : ": needs ";
      return m.substr(0, at) + verb + m.substr(at + std::strlen(infix));
    }
  }
  return m;
}

}  // namespace

int BadOption(const std::string& command, const std::string& option, const std::string& what) {
  PrintBadOption(option + ": " + what, "vistream " + command);
  return kBadOptionExit;
}

int ParseFailure(const CLI::App& app, const CLI::ParseError& e) {
  if (dynamic_cast<const CLI::Success*>(&e) != nullptr) return app.exit(e);
  // The deepest command given (none of its own subcommands was), and what it left over.
  std::string command;
  const CLI::App* at = DeepestCommand(app, &command);
  const std::vector<std::string> extra = at->remaining();
  const bool has_commands = !at->get_subcommands({}).empty();
  // CLI11 says "A subcommand is required" for a misspelt one: name it.
  if (has_commands && !extra.empty() && extra.front().rfind('-', 0) != 0) {
    PrintBadOption("'" + extra.front() + "': not a " + command + " command", command);
    return kBadOptionExit;
  }
  if (has_commands && extra.empty() && dynamic_cast<const CLI::RequiredError*>(&e) != nullptr) {
    std::vector<std::string> names;
    for (const CLI::App* s : at->get_subcommands({})) names.push_back(s->get_name());
    PrintBadOption("'" + command + "' needs a command: " + absl::StrJoin(names, ", "), command);
    return kBadOptionExit;
  }
  // Unknown options first: a misspelt option often hides a required one.
  const std::string unexpected = cli::UnexpectedArguments(extra, "'" + command + "'");
  PrintBadOption(unexpected.empty() ? OptionMessage(e) : unexpected, command);
  return kBadOptionExit;
}

absl::StatusOr<std::string> ReadFile(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return absl::NotFoundError("cannot open '" + path + "': " + std::strerror(errno));
  std::string bytes;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), f)) > 0) bytes.append(buf, n);
  const bool failed = std::ferror(f) != 0;
  std::fclose(f);
  if (failed) return absl::DataLossError("cannot read '" + path + "'");
  return bytes;
}

absl::Status WriteFile(const std::string& path, const std::string& bytes) {
  // Written beside and renamed: a write that fails (a full disk, a file size limit) leaves
  // what was there before, never half a file.
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (f == nullptr) return absl::PermissionDeniedError("cannot write '" + path + "': " + std::strerror(errno));
  const bool ok = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
  if (std::fclose(f) != 0 || !ok) {
    std::remove(tmp.c_str());
    return absl::DataLossError("cannot write '" + path + "' (disk full?); it is left as it was");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string why = std::strerror(errno);
    std::remove(tmp.c_str());
    return absl::PermissionDeniedError("cannot write '" + path + "': " + why);
  }
  return absl::OkStatus();
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

int Fail(const absl::Status& status) {
  if (status.code() == absl::StatusCode::kCancelled) {  // ^C or SIGTERM: not an error of the run
    std::fprintf(stderr, "vistream: interrupted (%s)\n", std::string(status.message()).c_str());
    return 130;
  }
  std::fprintf(stderr, "vistream: error: %s\n", std::string(status.message()).c_str());
  return 1;
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n == 0 ? 0.0 : n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

CLI::Validator SceneOutputPath() {
  return CLI::Validator(
      [](std::string& text) -> std::string {
        if (text.empty()) return "an empty path";
        const std::string lower = absl::AsciiStrToLower(text);
        if (!absl::EndsWith(lower, ".glb") && !absl::EndsWith(lower, ".gltf")) {
          return "'" + text + "': a scene is written as .glb or .gltf";
        }
        std::error_code ec;
        if (std::filesystem::is_directory(text, ec)) return "'" + text + "' is a folder";
        // Told before the work (making london's levels takes minutes), not when saving.
        const std::filesystem::path folder = std::filesystem::path(text).parent_path();
        if (!folder.empty() && !std::filesystem::is_directory(folder, ec)) {
          return "'" + text + "': there is no folder '" + folder.string() + "' to write it in";
        }
        if (access(folder.empty() ? "." : folder.c_str(), W_OK) != 0) {
          return "'" + text + "': the folder '" + (folder.empty() ? std::string(".") : folder.string()) +
                 "' is not writable";
        }
        return "";
      },
      "FILE.glb|FILE.gltf");
}

}  // namespace vistream::tools
