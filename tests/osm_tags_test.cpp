#include "scenes/osm_tags.h"

#include <gtest/gtest.h>

namespace vistream::scenes {
namespace {

TEST(OsmTags, DecimalCommaAndSeveralValuesReadAlikeInHeightsAndLevels) {
  EXPECT_DOUBLE_EQ(*ParseLength("12,5"), 12.5);
  EXPECT_DOUBLE_EQ(*ParseCount("2,5"), 2.5);
  EXPECT_DOUBLE_EQ(*ParseLength("10;12"), 10.0);
  EXPECT_DOUBLE_EQ(*ParseLength("10 m;12 m"), 10.0);
  EXPECT_DOUBLE_EQ(*ParseCount("3;5"), 3.0);
  EXPECT_DOUBLE_EQ(*ParseLength("+20"), 20.0);
  EXPECT_DOUBLE_EQ(*ParseLength("20."), 20.0);
  EXPECT_DOUBLE_EQ(*ParseLength("  15  "), 15.0);
  EXPECT_DOUBLE_EQ(*ParseLength("12.5 M"), 12.5);
  EXPECT_DOUBLE_EQ(*ParseLength("5 meters"), 5.0);
  EXPECT_DOUBLE_EQ(*ParseLength("6'"), 6 * 0.3048);
  EXPECT_DOUBLE_EQ(*ParseLength("12 ft 6 in"), 12 * 0.3048 + 6 * 0.0254);
  EXPECT_DOUBLE_EQ(*ParseLength("2 km"), 2000.0);
}

TEST(OsmTags, ExponentsHexAndAmbiguousCommasAreUnreadableEverywhere) {
  // The same text is refused as a height and as a level count (1E2 levels was read, 1e3 m not).
  for (const char* bad : {"1e3", "1E2", "1e400", "0x20", "1,234", "inf", "NaN", "~10", "-5",
                          "three", "3 storeys", "\xd9\xa1\xd9\xa2" /* Arabic-Indic 12 */, ""}) {
    EXPECT_FALSE(ParseLength(bad).has_value()) << bad;
    EXPECT_FALSE(ParseCount(bad).has_value()) << bad;
  }
  EXPECT_FALSE(ParseCount("3 m").has_value());  // a count has no unit
  EXPECT_FALSE(ParseLength("12'6").has_value());  // inches without their mark
}

HeightTags Tags(std::string height, std::string levels = "", std::string min_height = "") {
  HeightTags t;
  t.building = "yes";
  t.height = std::move(height);
  t.levels = std::move(levels);
  t.min_height = std::move(min_height);
  return t;
}

TEST(OsmTags, ImplausibleHeightFallsBackToTheNextRuleAndIsCounted) {
  // 99999999 m: past the 1000 m limit; the rule for "yes" is 4 storeys of 3 m and a 1 m roof.
  const HeightReading tower = ReadHeights(Tags("99999999"), 3.0, 1000.0);
  EXPECT_EQ(tower.implausible, 1);
  EXPECT_EQ(tower.source, HeightReading::Source::kRule);
  EXPECT_DOUBLE_EQ(tower.top, 4 * 3.0 + 1.0);
  // A million levels: 3,000 km; the height tag beside it is used instead.
  const HeightReading levels = ReadHeights(Tags("", "1000000"), 3.0, 1000.0);
  EXPECT_EQ(levels.implausible, 1);
  EXPECT_DOUBLE_EQ(levels.top, 13.0);
  const HeightReading both = ReadHeights(Tags("99999999", "10"), 3.0, 1000.0);
  EXPECT_EQ(both.implausible, 1);
  EXPECT_EQ(both.source, HeightReading::Source::kLevels);
  EXPECT_DOUBLE_EQ(both.top, 10 * 3.0 + 1.0);
  // The limit is the caller's: 900 m passes at 1000 and fails at 500.
  EXPECT_DOUBLE_EQ(ReadHeights(Tags("900"), 3.0, 1000.0).top, 900.0);
  EXPECT_EQ(ReadHeights(Tags("900"), 3.0, 500.0).implausible, 1);
}

TEST(OsmTags, UnreadableAndZeroHeightsFallBackAndAreCounted) {
  const HeightReading zero = ReadHeights(Tags("0"), 3.0, 1000.0);
  EXPECT_EQ(zero.unreadable, 1);
  EXPECT_DOUBLE_EQ(zero.top, 13.0);
  const HeightReading comma = ReadHeights(Tags("12,5"), 3.0, 1000.0);
  EXPECT_EQ(comma.unreadable, 0);
  EXPECT_DOUBLE_EQ(comma.top, 12.5);
  HeightTags roof = Tags("", "4");
  roof.roof_levels = "2;3";
  EXPECT_DOUBLE_EQ(ReadHeights(roof, 3.0, 1000.0).top, 4 * 3.0 + 2 * 3.0);
  roof.roof_levels = "-1";  // unreadable: the 1 m roof
  const HeightReading bad_roof = ReadHeights(roof, 3.0, 1000.0);
  EXPECT_EQ(bad_roof.unreadable, 1);
  EXPECT_DOUBLE_EQ(bad_roof.top, 4 * 3.0 + 1.0);
}

TEST(OsmTags, MinHeightAtOrAboveHeightDropsTheBaseAndIsFlagged) {
  const HeightReading above = ReadHeights(Tags("10", "", "20"), 3.0, 1000.0);
  EXPECT_TRUE(above.base_above_top);
  EXPECT_DOUBLE_EQ(above.base, 0.0);
  EXPECT_DOUBLE_EQ(above.top, 10.0);
  EXPECT_TRUE(ReadHeights(Tags("10", "", "10"), 3.0, 1000.0).base_above_top);
  // building:min_level 10 of 3 levels: base 30 m over a 10 m top.
  HeightTags levels = Tags("", "3");
  levels.min_level = "10";
  EXPECT_TRUE(ReadHeights(levels, 3.0, 1000.0).base_above_top);
  // A thin slab is consistent: 9.95 to 10 m.
  const HeightReading slab = ReadHeights(Tags("10", "", "9.95"), 3.0, 1000.0);
  EXPECT_FALSE(slab.base_above_top);
  EXPECT_DOUBLE_EQ(slab.base, 9.95);
  // A negative base is unreadable: on the ground.
  const HeightReading negative = ReadHeights(Tags("10", "", "-3"), 3.0, 1000.0);
  EXPECT_EQ(negative.unreadable, 1);
  EXPECT_DOUBLE_EQ(negative.base, 0.0);
  EXPECT_FALSE(negative.base_above_top);
  // min_height wins over building:min_level.
  HeightTags both = Tags("30", "", "10");
  both.min_level = "1";
  EXPECT_DOUBLE_EQ(ReadHeights(both, 3.0, 1000.0).base, 10.0);
}

}  // namespace
}  // namespace vistream::scenes
