#pragma once
// Helpers shared by the vistream subcommands.

#include <atomic>
#include <chrono>
#include <string>

#include <absl/status/statusor.h>

#include "scenes/scene.h"

namespace vistream::cli {

// Set by SIGINT; long computations poll it through Progress.
std::atomic<bool>& CancelFlag();
void InstallCancelHandler();

// A scene from a .glb/.gltf file, or from the catalog (name or .json path).
absl::StatusOr<scenes::Scene> LoadSceneArg(const std::string& arg, double* seconds = nullptr);

// Seconds elapsed since `start`.
double SecondsSince(std::chrono::steady_clock::time_point start);

// Prints `status` as "vistream: error: ..." and returns the process exit code for it.
int Fail(const absl::Status& status);

}  // namespace vistream::cli
