#pragma once
// OpenStreetMap height tags as people type them: lengths, level counts, and the heights of a
// building or building part (Simple 3D Buildings, https://wiki.openstreetmap.org/wiki/Simple_3D_Buildings).
//
// Numbers are read one way everywhere (heights, levels, roofs, min_height, min_level):
//   - ASCII digits with an optional '+' sign and one decimal separator: '.' ("12.5", "20."),
//     or ',' ("12,5") unless exactly three digits follow it ("1,234" could be a thousands
//     separator: unreadable);
//   - several values separated by ';' ("10;12", "3;5"): the first;
//   - no exponents ("1e3", "1E2"), hex, inf, nan, other scripts' digits or words: unreadable.

#include <optional>
#include <string>
#include <string_view>

namespace vistream::scenes {

// Parses a length tag ("12", "12,5 m", "40 ft", "12'6\"", "12 ft 6 in", "250 cm"): metres,
// >= 0, or none if unreadable. Units: m, meter(s), metre(s), cm, km, mi, ft, feet, foot, ', in,
// inch(es), "; a bare number is metres (OSM's default unit).
std::optional<double> ParseLength(std::string_view text);

// Parses a count tag ("3", "2.5", "3;5" -> 3): a number >= 0 without unit, or none.
std::optional<double> ParseCount(std::string_view text);

// The building type's storeys when no tag gives a height: e.g. 1 for garage or shed, 2 for
// house, 5 for apartments, 4 for anything else ("yes").
int DefaultLevels(std::string_view building);

// The tags that decide a building's (or part's) vertical extent; empty when absent.
struct HeightTags {
  std::string building;  // building=* value, or building:part=* for a part (the rule's input)
  std::string height, building_height, levels, roof_height, roof_levels, min_height, min_level;
};

// What ReadHeights found: metres above the ground, top > base >= 0.
struct HeightReading {
  enum class Source { kHeightTag, kLevels, kRule };
  double base = 0.0, top = 0.0;
  Source source = Source::kRule;
  int unreadable = 0;   // tags present but unreadable (or a zero/negative height): next rule
  int implausible = 0;  // readable values above max_height_m: treated as bad data, next rule
  // min_height / building:min_level at or above the top: the base is dropped (the object
  // stands on the ground up to `top`), and since its tags contradict each other it must not
  // occlude.
  bool base_above_top = false;
};

// The heights of a building or part, in this order: height, else building:height; else
// building:levels x storey_m plus the roof (roof:height, else roof:levels x storey_m, else
// 1 m); else DefaultLevels(building) x storey_m + 1 m. The base: min_height, else
// building:min_level x storey_m. Values above max_height_m (taller than any real building)
// count as implausible and fall through to the next rule, so one typo cannot make a 100,000 km
// tower (the last rule applies whatever max_height_m). Needs storey_m > 0, max_height_m > 0.
HeightReading ReadHeights(const HeightTags& tags, double storey_m, double max_height_m);

}  // namespace vistream::scenes
