#include "bench/cli_common.h"

#include <chrono>
#include <cerrno>
#include <csignal>
#include <cstring>
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

scenes::ViewcellSpec ViewcellSpecFor(const std::string& scene_arg, double cell_size) {
  scenes::ViewcellSpec spec;
  const std::string ext = std::filesystem::path(scene_arg).extension().string();
  if (ext != ".glb" && ext != ".gltf") {
    if (auto entry = scenes::FindCatalogEntry(scene_arg); entry.ok()) spec = entry->viewcell;
  }
  if (cell_size > 0.0) spec.size_m = cell_size;
  return spec;
}

absl::StatusOr<visibility::ViewcellGrid> GridFor(const scenes::Scene& scene, const scenes::ViewcellSpec& spec) {
  return visibility::ViewcellGrid::Create(scene.bounds, spec.size_m, spec.base_m, spec.height_m);
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
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return absl::PermissionDeniedError("cannot write '" + path + "': " + std::strerror(errno));
  const bool ok = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size();
  if (std::fclose(f) != 0 || !ok) return absl::DataLossError("cannot write '" + path + "' (disk full?)");
  return absl::OkStatus();
}

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

int Fail(const absl::Status& status) {
  std::fprintf(stderr, "vistream: error: %s\n", std::string(status.message()).c_str());
  return status.code() == absl::StatusCode::kCancelled ? 130 : 1;
}

}  // namespace vistream::cli
