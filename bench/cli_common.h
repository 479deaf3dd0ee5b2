#pragma once
// Helpers shared by the vistream subcommands.

#include <atomic>
#include <chrono>
#include <string>

#include <absl/status/statusor.h>

#include "scenes/catalog.h"
#include "scenes/scene.h"
#include "visibility/viewcell_grid.h"

namespace vistream::cli {

// Set by SIGINT; long computations poll it through Progress.
std::atomic<bool>& CancelFlag();
void InstallCancelHandler();

// A scene from a .glb/.gltf file, or from the catalog (name or .json path).
absl::StatusOr<scenes::Scene> LoadSceneArg(const std::string& arg, double* seconds = nullptr);

// The viewcell band and size for a scene argument: the catalog entry's (none for glTF files:
// 100 m at eye level), with the size replaced by `cell_size` when that is positive.
scenes::ViewcellSpec ViewcellSpecFor(const std::string& scene_arg, double cell_size);
// The viewcell grid of `spec` over `scene`.
absl::StatusOr<visibility::ViewcellGrid> GridFor(const scenes::Scene& scene, const scenes::ViewcellSpec& spec);

// The whole file, or an error naming it.
absl::StatusOr<std::string> ReadFile(const std::string& path);
absl::Status WriteFile(const std::string& path, const std::string& bytes);

// Seconds elapsed since `start`.
double SecondsSince(std::chrono::steady_clock::time_point start);

// Prints `status` as "vistream: error: ..." and returns the process exit code for it.
int Fail(const absl::Status& status);

}  // namespace vistream::cli
