#include "tools/cli_common.h"

#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>

#include <absl/strings/str_format.h>

#include "scenes/catalog.h"
#include "tools/terminal_progress.h"

namespace vistream::tools {

std::atomic<bool>& CancelFlag() {
  static std::atomic<bool> flag{false};
  return flag;
}

void InstallCancelHandler() {
  std::signal(SIGINT, [](int) {
    if (CancelFlag().exchange(true)) std::_Exit(130);  // a second ^C stops at once
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
  return std::move(loaded->scene);
}

CLI::Validator FiniteRange(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (end == text.c_str() || *end != '\0' || !std::isfinite(v) || v < lo || v > hi) {
          return "'" + text + "' is not a number from " + absl::StrFormat("%g to %g", lo, hi);
        }
        return "";
      },
      absl::StrFormat("NUMBER in [%g, %g]", lo, hi));
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

}  // namespace vistream::tools
