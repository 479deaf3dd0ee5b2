#pragma once
// CLI11 checks for numeric options, shared by vistream, vistream-server and vistream-client.
// CLI11 puts the option's name in front of the message ("--size: 'nan' is not a number from 0
// to 100000"); the executables print it as "<tool>: error: ..." and exit kBadOptionExit.
// They reject NaN, infinities, text and values outside [lo, hi]: CLI11's own Range and
// PositiveNumber let NaN through and print their bounds with 300 digits.

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>
#include <system_error>
#include <vector>

#include <CLI/CLI.hpp>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_split.h>

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

// `text` as a whole decimal number (no sign unless negative, no exponent), if it is one.
inline bool ParseWhole(const std::string& text, int64_t* v) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, *v);
  return !text.empty() && ec == std::errc() && ptr == end;
}

inline std::string NumberText(double v) { return absl::StrFormat("%g", v); }
inline std::string NumberText(int64_t v) { return absl::StrFormat("%d", v); }

// A check that lets through a text `parse` reads whole as a T in [lo, hi] that `also` accepts;
// else it fails with "'<text>' is not <what> from <lo> to <hi>". --help shows the value as
// "<value_name> in [<lo>, <hi>]".
template <typename T, typename Parse, typename Also>
CLI::Validator NumberIn(T lo, T hi, Parse parse, Also also, const char* what, const char* value_name) {
  const std::string lo_text = NumberText(lo), hi_text = NumberText(hi);
  return CLI::Validator(
      [=](std::string& text) -> std::string {
        T v{};
        if (parse(text, &v) && v >= lo && v <= hi && also(v)) return "";
        return absl::StrCat("'", text, "' is not ", what, " from ", lo_text, " to ", hi_text);
      },
      absl::StrCat(value_name, " in [", lo_text, ", ", hi_text, "]"));
}

}  // namespace internal

// A finite number in [lo, hi].
inline CLI::Validator FiniteRange(double lo, double hi) {
  return internal::NumberIn(lo, hi, internal::ParseFinite, [](double) { return true; }, "a number", "NUMBER");
}

// A whole number in [lo, hi].
inline CLI::Validator WholeRange(int64_t lo, int64_t hi) {
  return internal::NumberIn(lo, hi, internal::ParseWhole, [](int64_t) { return true; }, "a whole number", "INTEGER");
}

// A power of two in [lo, hi] (raster resolutions).
inline CLI::Validator PowerOfTwo(int64_t lo, int64_t hi) {
  return internal::NumberIn(lo, hi, internal::ParseWhole, [](int64_t v) { return v > 0 && (v & (v - 1)) == 0; },
                            "a power of two", "POWER OF TWO");
}

// A screen error for levels of detail (issue 45): "off" (0) or tau in pixels, (0, 1000] (the
// range Hello.levels takes). False for anything else.
inline bool ParseScreenError(std::string_view text, double* tau_px) {
  if (text == "off") {
    *tau_px = 0.0;
    return true;
  }
  double v = 0.0;
  if (!internal::ParseFinite(text, &v) || !(v > 0.0) || v > 1000.0) return false;
  *tau_px = v;
  return true;
}

// A comma-separated list of ParseScreenError values ("off,1,16": one run each). False, with
// *why saying which item and what is wrong, for an item that is no screen error, or (with
// `refuse_repeats`) one listed twice.
inline bool ParseScreenErrors(std::string_view text, bool refuse_repeats, std::vector<double>* taus_px,
                              std::string* why) {
  taus_px->clear();
  for (absl::string_view part : absl::StrSplit(absl::string_view(text.data(), text.size()), ',')) {
    const std::string_view item(part.data(), part.size());
    double tau = 0.0;
    if (!ParseScreenError(item, &tau)) {
      *why = absl::StrCat("'", part, "' is not a screen error: expected off or pixels in (0, 1000]");
      return false;
    }
    if (refuse_repeats && std::find(taus_px->begin(), taus_px->end(), tau) != taus_px->end()) {
      *why = absl::StrCat("'", part, "' is listed twice");
      return false;
    }
    taus_px->push_back(tau);
  }
  return true;
}

}  // namespace vistream::cli
