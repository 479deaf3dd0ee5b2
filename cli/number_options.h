#pragma once
// CLI11 checks for numeric options, shared by vistream, vistream-server and vistream-client.
// CLI11 puts the option's name in front of the message ("--size: 'nan' is not a number from 0
// to 100000"); the executables print it as "<tool>: error: ..." and exit kBadOptionExit.
// They reject NaN, infinities, text and values outside [lo, hi]: CLI11's own Range and
// PositiveNumber let NaN through and print their bounds with 300 digits.

#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <system_error>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>

namespace vistream::cli {

// The exit code of a bad option or combination of options (run-time errors exit 1, ^C 130).
inline constexpr int kBadOptionExit = 2;

namespace internal {

// `text` as a whole finite decimal number (digits, a point, an exponent; no hex, no sign but
// '-', no spaces, no inf or nan), if it is one.
inline bool ParseFinite(std::string_view text, double* v) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, *v, std::chars_format::general);
  return !text.empty() && ec == std::errc() && ptr == end && std::isfinite(*v);
}

}  // namespace internal

// A finite number in [lo, hi].
inline CLI::Validator FiniteRange(double lo, double hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        double v = 0.0;
        if (!internal::ParseFinite(text, &v) || v < lo || v > hi) {
          return absl::StrFormat("'%s' is not a number from %g to %g", text, lo, hi);
        }
        return "";
      },
      absl::StrFormat("NUMBER in [%g, %g]", lo, hi));
}

namespace internal {

// `text` as a whole decimal number (no sign unless negative, no exponent), if it is one.
inline bool ParseWhole(const std::string& text, int64_t* v) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, *v);
  return !text.empty() && ec == std::errc() && ptr == end;
}

}  // namespace internal

// A whole number in [lo, hi].
inline CLI::Validator WholeRange(int64_t lo, int64_t hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        int64_t v = 0;
        if (!internal::ParseWhole(text, &v) || v < lo || v > hi) {
          return absl::StrFormat("'%s' is not a whole number from %d to %d", text, lo, hi);
        }
        return "";
      },
      absl::StrFormat("INTEGER in [%d, %d]", lo, hi));
}

// A power of two in [lo, hi] (raster resolutions).
inline CLI::Validator PowerOfTwo(int64_t lo, int64_t hi) {
  return CLI::Validator(
      [lo, hi](std::string& text) -> std::string {
        int64_t v = 0;
        if (!internal::ParseWhole(text, &v) || v < lo || v > hi || v <= 0 || (v & (v - 1)) != 0) {
          return absl::StrFormat("'%s' is not a power of two from %d to %d", text, lo, hi);
        }
        return "";
      },
      absl::StrFormat("POWER OF TWO in [%d, %d]", lo, hi));
}

}  // namespace vistream::cli
