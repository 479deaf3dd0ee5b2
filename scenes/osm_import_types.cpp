#include "scenes/osm_import_types.h"

#include <absl/strings/str_cat.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <optional>
#include <system_error>

namespace vistream::scenes {

namespace {

std::string_view Strip(std::string_view t) {
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.front()))) t.remove_prefix(1);
  while (!t.empty() && std::isspace(static_cast<unsigned char>(t.back()))) t.remove_suffix(1);
  return t;
}

// The whole of `t` (stripped) as a finite number.
std::optional<double> Number(std::string_view t) {
  t = Strip(t);
  if (!t.empty() && t.front() == '+') t.remove_prefix(1);
  double v;
  const auto [end, err] = std::from_chars(t.data(), t.data() + t.size(), v);
  if (t.empty() || err != std::errc() || end != t.data() + t.size() || !std::isfinite(v)) {
    return std::nullopt;
  }
  return v;
}

}  // namespace

uint64_t OsmImportSummary::Skipped() const {
  uint64_t n = 0;
  for (const auto& [reason, count] : skipped) n += count;
  return n;
}

absl::StatusOr<GeoBox> ParseGeoBox(std::string_view text) {
  const std::string where = absl::StrCat("bbox '", std::string(text), "'");
  std::vector<std::string_view> parts;
  for (size_t from = 0;;) {
    const size_t comma = text.find(',', from);
    parts.push_back(
        text.substr(from, comma == std::string_view::npos ? std::string_view::npos : comma - from));
    if (comma == std::string_view::npos) break;
    from = comma + 1;
  }
  if (parts.size() != 4) {
    return absl::InvalidArgumentError(
        absl::StrCat(where, ": needs four numbers min_lon,min_lat,max_lon,max_lat"));
  }
  double v[4];
  for (int i = 0; i < 4; ++i) {
    const std::optional<double> x = Number(parts[i]);
    if (!x) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": '", std::string(parts[i]), "' is not a number"));
    }
    v[i] = *x;
  }
  const GeoBox b{v[0], v[1], v[2], v[3]};
  if (b.min_lon < -180 || b.max_lon > 180 || b.min_lat < -90 || b.max_lat > 90 ||
      b.min_lon >= b.max_lon || b.min_lat >= b.max_lat) {
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": needs -180 <= min_lon < max_lon <= 180 and -90 <= min_lat < max_lat <= 90"));
  }
  return b;
}

}  // namespace vistream::scenes
