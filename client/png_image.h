#pragma once
// PNG files of RGB pixels (8 bits a channel, rows top first), through libpng: the client's
// screenshots and the tools' maps.

#include <cstdint>
#include <string>
#include <vector>

#include <absl/status/status.h>
#include <absl/status/statusor.h>

namespace vistream::client {

struct RgbImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // width * height * 3, top row first
};

// Errors: UNAVAILABLE when `path` cannot be opened for writing, DATA_LOSS when writing fails,
// INVALID_ARGUMENT when the pixel count does not match the size.
absl::Status WritePng(const std::string& path, const RgbImage& image);
// Any 8-bit PNG, converted to RGB. Errors name the path.
absl::StatusOr<RgbImage> ReadPng(const std::string& path);

}  // namespace vistream::client
