#include "scenes/osm_tags.h"

#include <cctype>
#include <charconv>
#include <cmath>
#include <utility>

namespace vistream::scenes {

namespace {

bool IsDigit(char c) { return c >= '0' && c <= '9'; }
bool IsSpace(char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; }

std::string_view Strip(std::string_view t) {
  while (!t.empty() && IsSpace(t.front())) t.remove_prefix(1);
  while (!t.empty() && IsSpace(t.back())) t.remove_suffix(1);
  return t;
}

// The first of several values "a;b;c".
std::string_view FirstValue(std::string_view t) { return Strip(t.substr(0, t.find(';'))); }

// Reads a decimal number at the front of `*t` (see osm_tags.h) and removes it; none if `*t`
// does not start with one. Only digits and one separator are taken (at most 15 digits before
// it), so the value is finite and a glued letter ("1e3", "0x20") is left for the caller, which
// accepts only known units.
std::optional<double> TakeDecimal(std::string_view* t) {
  std::string_view s = *t;
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  std::string digits;
  size_t i = 0, int_digits = 0, frac_digits = 0;
  for (; i < s.size() && IsDigit(s[i]); ++i, ++int_digits) digits.push_back(s[i]);
  if (i < s.size() && (s[i] == '.' || s[i] == ',')) {
    const char sep = s[i++];
    digits.push_back('.');
    for (; i < s.size() && IsDigit(s[i]); ++i, ++frac_digits) digits.push_back(s[i]);
    if (sep == ',' && (frac_digits == 0 || frac_digits == 3)) return std::nullopt;
  }
  if (int_digits + frac_digits == 0 || int_digits > 15) return std::nullopt;
  if (digits.back() == '.') digits.pop_back();
  double v = 0.0;
  const auto [end, err] = std::from_chars(digits.data(), digits.data() + digits.size(), v);
  if (err != std::errc() || end != digits.data() + digits.size()) return std::nullopt;
  t->remove_prefix(static_cast<size_t>(s.data() - t->data()) + i);
  return v;
}

std::string Lower(std::string_view t) {
  std::string out(t);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

// Metres per unit, or none for an unknown unit; "" is metres.
std::optional<double> UnitScale(std::string_view unit) {
  static const std::pair<std::string_view, double> kUnits[] = {
      {"", 1.0},        {"m", 1.0},         {"meter", 1.0},    {"meters", 1.0},
      {"metre", 1.0},   {"metres", 1.0},    {"cm", 0.01},      {"km", 1000.0},
      {"mi", 1609.344}, {"ft", 0.3048},     {"feet", 0.3048},  {"foot", 0.3048},
      {"'", 0.3048},    {"in", 0.0254},     {"inch", 0.0254},  {"inches", 0.0254},
      {"\"", 0.0254},
  };
  for (const auto& [name, scale] : kUnits) {
    if (name == unit) return scale;
  }
  return std::nullopt;
}

// Takes a unit word (letters) or a foot/inch mark from the front of `*t`.
std::string TakeUnit(std::string_view* t) {
  *t = Strip(*t);
  size_t n = 0;
  if (!t->empty() && (t->front() == '\'' || t->front() == '"')) {
    n = 1;
  } else {
    while (n < t->size() && std::isalpha(static_cast<unsigned char>((*t)[n]))) ++n;
  }
  std::string unit = Lower(t->substr(0, n));
  t->remove_prefix(n);
  *t = Strip(*t);
  return unit;
}

bool IsFeet(double scale) { return scale == 0.3048; }
bool IsInches(double scale) { return scale == 0.0254; }

}  // namespace

std::optional<double> ParseLength(std::string_view text) {
  std::string_view t = FirstValue(text);
  const std::optional<double> v = TakeDecimal(&t);
  if (!v) return std::nullopt;
  const std::optional<double> scale = UnitScale(TakeUnit(&t));
  if (!scale) return std::nullopt;
  double metres = *v * *scale;
  // Feet may be followed by inches: 12'6", 12 ft 6 in.
  if (!t.empty() && IsFeet(*scale)) {
    const std::optional<double> inches = TakeDecimal(&t);
    if (!inches) return std::nullopt;
    const std::optional<double> in_scale = UnitScale(TakeUnit(&t));
    if (!in_scale || !IsInches(*in_scale)) return std::nullopt;
    metres += *inches * *in_scale;
  }
  if (!t.empty()) return std::nullopt;
  return metres;
}

std::optional<double> ParseCount(std::string_view text) {
  std::string_view t = FirstValue(text);
  const std::optional<double> v = TakeDecimal(&t);
  if (!v || !t.empty()) return std::nullopt;
  return v;
}

int DefaultLevels(std::string_view building) {
  static const std::pair<std::string_view, int> kTable[] = {
      {"garage", 1},      {"garages", 1},          {"shed", 1},
      {"hut", 1},         {"kiosk", 1},            {"carport", 1},
      {"roof", 1},        {"service", 1},          {"toilets", 1},
      {"cabin", 1},       {"container", 1},        {"greenhouse", 1},
      {"bunker", 1},      {"transformer_tower", 2}, {"house", 2},
      {"detached", 2},    {"semidetached_house", 2}, {"terrace", 2},
      {"bungalow", 1},    {"farm", 2},             {"barn", 2},
      {"retail", 2},      {"supermarket", 1},      {"industrial", 2},
      {"warehouse", 2},   {"church", 5},           {"cathedral", 8},
      {"chapel", 3},      {"apartments", 5},       {"residential", 4},
      {"hotel", 6},       {"office", 6},           {"commercial", 4},
      {"hospital", 5},    {"school", 3},           {"university", 4},
      {"public", 3},      {"civic", 3},            {"government", 4},
      {"train_station", 3}, {"stadium", 4},
  };
  for (const auto& [key, levels] : kTable) {
    if (key == building) return levels;
  }
  return 4;  // "yes" and everything else
}

HeightReading ReadHeights(const HeightTags& tags, double storey_m, double max_height_m) {
  constexpr double kRoofM = 1.0;  // the roof on top of counted storeys, when no tag says
  HeightReading r;
  // A candidate value: unreadable and implausible ones are counted and passed over.
  auto usable = [&](const std::string& tag, std::optional<double> v, bool positive) {
    if (tag.empty()) return false;
    if (!v || (positive && !(*v > 0.0))) {
      ++r.unreadable;
      return false;
    }
    if (*v > max_height_m) {
      ++r.implausible;
      return false;
    }
    return true;
  };
  std::optional<double> top;
  for (const std::string* tag : {&tags.height, &tags.building_height}) {
    if (top) break;
    const std::optional<double> v = tag->empty() ? std::nullopt : ParseLength(*tag);
    if (usable(*tag, v, true)) {
      top = v;
      r.source = HeightReading::Source::kHeightTag;
    }
  }
  if (!top && !tags.levels.empty()) {
    const std::optional<double> levels = ParseCount(tags.levels);
    if (!levels) {
      ++r.unreadable;
    } else {
      double roof = kRoofM;
      const std::optional<double> rh =
          tags.roof_height.empty() ? std::nullopt : ParseLength(tags.roof_height);
      const std::optional<double> rl =
          tags.roof_levels.empty() ? std::nullopt : ParseCount(tags.roof_levels);
      if (usable(tags.roof_height, rh, false)) {
        roof = *rh;
      } else if (usable(tags.roof_levels, rl ? std::optional<double>(*rl * storey_m) : rl,
                        false)) {
        roof = *rl * storey_m;
      }
      if (usable(tags.levels, *levels * storey_m + roof, true)) {
        top = *levels * storey_m + roof;
        r.source = HeightReading::Source::kLevels;
      }
    }
  }
  if (!top) {
    top = DefaultLevels(tags.building) * storey_m + kRoofM;
    r.source = HeightReading::Source::kRule;
  }
  r.top = *top;
  const std::optional<double> mh =
      tags.min_height.empty() ? std::nullopt : ParseLength(tags.min_height);
  const std::optional<double> ml =
      tags.min_level.empty() ? std::nullopt : ParseCount(tags.min_level);
  if (usable(tags.min_height, mh, false)) {
    r.base = *mh;
  } else if (usable(tags.min_level, ml ? std::optional<double>(*ml * storey_m) : ml, false)) {
    r.base = *ml * storey_m;
  }
  if (r.base >= r.top) {
    r.base_above_top = true;
    r.base = 0.0;
  }
  return r;
}

}  // namespace vistream::scenes
