#include "client/screenshots.h"

#include <filesystem>
#include <system_error>
#include <utility>
#include <vector>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "client/png_image.h"

namespace vistream::client {

absl::Status CreateScreenshotDir(const std::string& dir) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return absl::UnavailableError(absl::StrCat(dir, ": cannot create: ", ec.message(), " (--screenshots)"));
  return absl::OkStatus();
}

absl::StatusOr<std::string> WriteScreenshot(Renderer& renderer, const std::string& screenshots_dir, uint64_t frame,
                                            double t_s) {
  absl::StatusOr<std::vector<uint8_t>> rgb = renderer.ReadRgb();
  if (!rgb.ok()) return rgb.status();
  // F12 and SIGUSR1 without --screenshots: a folder of their own in the working folder.
  std::error_code cwd_error;
  const std::string dir = screenshots_dir.empty()
                              ? (std::filesystem::current_path(cwd_error) / "vistream-screenshots").string()
                              : screenshots_dir;
  if (screenshots_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return absl::UnavailableError(absl::StrCat(dir, ": cannot create: ", ec.message()));
  }
  const std::string path =
      (std::filesystem::path(dir) / absl::StrFormat("frame-%06d-t%07.1fs.png", static_cast<int>(frame), t_s)).string();
  if (absl::Status s = WritePng(path, {renderer.width(), renderer.height(), std::move(*rgb)}); !s.ok()) return s;
  return path;
}

}  // namespace vistream::client
