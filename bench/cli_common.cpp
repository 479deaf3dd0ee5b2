#include "bench/cli_common.h"

#include <chrono>
#include <csignal>
#include <cstdio>
#include <filesystem>

#include "scenes/catalog.h"
#include "scenes/gltf_io.h"

namespace vistream::cli {

std::atomic<bool>& CancelFlag() {
  static std::atomic<bool> flag{false};
  return flag;
}

void InstallCancelHandler() {
  std::signal(SIGINT, [](int) {
    if (CancelFlag().exchange(true)) std::_Exit(130);  // a second ^C stops at once
  });
}

absl::StatusOr<scenes::Scene> LoadSceneArg(const std::string& arg, double* seconds) {
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<scenes::Scene> scene;
  const std::string ext = std::filesystem::path(arg).extension().string();
  if (ext == ".glb" || ext == ".gltf") {
    std::vector<std::string> warnings;
    scene = scenes::LoadGltf(arg, &warnings);
    for (const std::string& w : warnings) std::fprintf(stderr, "vistream: warning: %s\n", w.c_str());
  } else {
    absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry(arg);
    if (!entry.ok()) return entry.status();
    scene = scenes::BuildScene(*entry, &CancelFlag());
  }
  if (seconds != nullptr) *seconds = SecondsSince(start);
  return scene;
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

int Fail(const absl::Status& status) {
  std::fprintf(stderr, "vistream: error: %s\n", std::string(status.message()).c_str());
  return status.code() == absl::StatusCode::kCancelled ? 130 : 1;
}

}  // namespace vistream::cli
