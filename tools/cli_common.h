#pragma once
// Helpers shared by the vistream subcommands.

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <absl/status/statusor.h>

#include "cli/number_options.h"
#include "scenes/catalog.h"
#include "scenes/progress.h"
#include "tools/terminal_progress.h"
#include "scenes/scene.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

// Set by SIGINT; long computations poll it through Progress.
std::atomic<bool>& CancelFlag();
// SIGINT sets CancelFlag(); a second SIGINT a second or more after the first, before the
// program has stopped, exits at once with 130 after "vistream: interrupted (a second ^C:
// stopped at once)" on stderr; one within the second is ignored (cli/stop_signal.h).
void InstallCancelHandler();

// What the tool's long computations report to and poll: the terminal sink and CancelFlag().
scenes::RunControl ToolRun();

// scenes::LoadScene with the tool's progress and cancel; prints the loader's warnings. A catalog
// entry's walks join the scene's own paths (scenes::AddDeclaredWalks), so that a file saved from it keeps them.
absl::StatusOr<scenes::Scene> LoadSceneArg(const std::string& arg, double* seconds = nullptr);

// Checks for numeric options (cli/number_options.h) and the exit code of a bad option.
using cli::FiniteRange;
using cli::kBadOptionExit;
using cli::PowerOfTwo;
using cli::WholeRange;

// Bounds shared by several commands' options.
inline constexpr int64_t kMaxSeed = INT64_MAX;
inline constexpr int64_t kMaxSamples = int64_t{1} << 50;
inline constexpr double kMaxSeconds = 1e7;       // about 116 days
inline constexpr double kMinCellSize = 0.01;     // metres; what vistream-server accepts
inline constexpr double kMaxCellSize = 1e6;

// Prints "vistream: error: <option>: <what>" and a hint to `vistream <command> --help`;
// returns kBadOptionExit. For what CLI11's checks cannot see (a value's form, two options together).
int BadOption(const std::string& command, const std::string& option, const std::string& what);

// The exit code for CLI11's parse error `e` in `app`: 0 after printing --help, else
// kBadOptionExit after printing the error as BadOption does.
int ParseFailure(const CLI::App& app, const CLI::ParseError& e);

// Text that is not empty: given empty, the option is bad ("<option>: <message>", exit 2) rather
// than its default.
inline CLI::Validator NonEmpty(const std::string& message, const std::string& value_name = "") {
  return CLI::Validator([message](std::string& text) -> std::string { return text.empty() ? message : ""; },
                        value_name);
}

// An output file's path: not empty (an empty -o is a bad option, exit 2, not a file named by
// the extension alone, the default, or a write error).
inline CLI::Validator OutputPath() { return NonEmpty("an empty path", "PATH"); }

// A scene file to write: a path ending in .glb or .gltf (any case) that is not a folder.
CLI::Validator SceneOutputPath();

// The whole file, or an error naming it.
absl::StatusOr<std::string> ReadFile(const std::string& path);
// Writes `bytes` to `path` through `path`.tmp renamed over it, so a failed write (disk full,
// a file size limit, no permission) leaves the file as it was; the error names the path.
absl::Status WriteFile(const std::string& path, const std::string& bytes);

// Seconds elapsed since `start`.
double SecondsSince(std::chrono::steady_clock::time_point start);
// The median of `v` (the mean of the middle two for an even count); 0 for none.
double Median(std::vector<double> v);

// Adds subcommand `name` to `app`: a group whose own subcommands do the work (`vistream bench
// server`); the command line must choose one of them.
inline CLI::App* AddCommandGroup(CLI::App& app, const std::string& name, const std::string& description) {
  CLI::App* group = app.add_subcommand(name, description);
  group->require_subcommand(1);
  return group;
}

// A subcommand of `parent` and the arguments its options fill, kept alive for its run.
template <class Args>
struct Subcommand {
  CLI::App* app;
  std::shared_ptr<Args> args;
};

// Adds subcommand `name` (described by `description` in --help) to `parent`; when the command line
// chooses it, `run(args)` runs after parsing and its exit code goes to `done`. Its options are added
// to the returned app and fill the returned args.
template <class Args>
Subcommand<Args> AddSubcommand(CLI::App* parent, const std::string& name, const std::string& description,
                               int (*run)(const Args&), std::function<void(int)> done) {
  auto args = std::make_shared<Args>();
  CLI::App* app = parent->add_subcommand(name, description);
  app->callback([args, run, done = std::move(done)] { done(run(*args)); });
  return {app, args};
}

// Prints `status` as "vistream: error: ..." and returns the process exit code for it.
int Fail(const absl::Status& status);

}  // namespace vistream::tools
