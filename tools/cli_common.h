#pragma once
// Helpers shared by the vistream subcommands.

#include <atomic>
#include <chrono>
#include <string>

#include <CLI/CLI.hpp>
#include <absl/status/statusor.h>

#include "scenes/catalog.h"
#include "scenes/progress.h"
#include "tools/terminal_progress.h"
#include "scenes/scene.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

// Set by SIGINT; long computations poll it through Progress.
std::atomic<bool>& CancelFlag();
void InstallCancelHandler();

// What the tool's long computations report to and poll: the terminal sink and CancelFlag().
scenes::RunControl ToolRun();

// scenes::LoadScene with the tool's progress and cancel; prints the loader's warnings.
absl::StatusOr<scenes::Scene> LoadSceneArg(const std::string& arg, double* seconds = nullptr);

// A CLI11 check: a finite number in [lo, hi] (CLI11's Range and PositiveNumber let NaN through).
CLI::Validator FiniteRange(double lo, double hi);

// The whole file, or an error naming it.
absl::StatusOr<std::string> ReadFile(const std::string& path);
absl::Status WriteFile(const std::string& path, const std::string& bytes);

// Seconds elapsed since `start`.
double SecondsSince(std::chrono::steady_clock::time_point start);

// Prints `status` as "vistream: error: ..." and returns the process exit code for it.
int Fail(const absl::Status& status);

}  // namespace vistream::tools
