// PVS lists as differences from the list before (proto/pvs_delta.h): what the server encodes the
// client decodes back, with levels; bad deltas are errors naming the cell.
#include "proto/pvs_delta.h"

#include <gtest/gtest.h>

#include "scenes/random.h"

namespace vistream::proto {
namespace {

PvsList RandomList(scenes::Rng& rng, uint32_t cell, bool levels) {
  PvsList l;
  l.cell = cell;
  for (uint32_t o = 0; o < 400; ++o) {
    if (rng.Uniform() < 0.5) {
      l.objects.push_back(o * 3);
      if (levels) l.levels.push_back(static_cast<uint32_t>(rng.Uniform(0, 4)));
    }
  }
  return l;
}

TEST(PvsDelta, WhatIsEncodedDecodesBackThroughASequenceOfLists) {
  scenes::Rng rng(4);
  for (const bool levels : {false, true}) {
    PvsListDecoder decoder;
    PvsList previous = RandomList(rng, 0, levels);
    v1::ViewcellPvs first;
    first.set_cell_id(0);
    first.mutable_object_ids()->Add(previous.objects.begin(), previous.objects.end());
    first.mutable_object_levels()->Add(previous.levels.begin(), previous.levels.end());
    ASSERT_TRUE(decoder.Decode(first).ok());
    for (uint32_t cell = 1; cell < 30; ++cell) {
      const PvsList next = RandomList(rng, cell, levels);
      v1::ViewcellPvs m;
      m.set_cell_id(cell);
      EncodePvsDelta(previous, next, &m);
      EXPECT_TRUE(m.delta());
      EXPECT_EQ(m.object_ids_size(), 0);
      const absl::StatusOr<PvsList> back = decoder.Decode(m);
      ASSERT_TRUE(back.ok()) << back.status();
      EXPECT_EQ(back->cell, cell);
      EXPECT_EQ(back->objects, next.objects);
      EXPECT_EQ(back->levels, next.levels);
      previous = next;
    }
  }
}

TEST(PvsDelta, NeighbouringListsCostFewBytes) {
  PvsList a, b;
  for (uint32_t o = 0; o < 3000; ++o) {
    a.objects.push_back(1000 + o * 40);
    a.levels.push_back(1);
  }
  b = a;
  b.objects.erase(b.objects.begin(), b.objects.begin() + 100);  // 100 gone, 100 new
  b.levels.resize(b.objects.size());
  for (uint32_t o = 0; o < 100; ++o) {
    b.objects.push_back(200000 + o);
    b.levels.push_back(1);
  }
  v1::ViewcellPvs whole, delta;
  whole.mutable_object_ids()->Add(b.objects.begin(), b.objects.end());
  whole.mutable_object_levels()->Add(b.levels.begin(), b.levels.end());
  EncodePvsDelta(a, b, &delta);
  EXPECT_LT(delta.ByteSizeLong() * 20, whole.ByteSizeLong());
}

TEST(PvsDelta, BadDifferencesAreErrorsNamingTheCell) {
  PvsListDecoder decoder;
  v1::ViewcellPvs m;
  m.set_cell_id(12);
  m.set_delta(true);
  m.add_added(5);
  EXPECT_NE(decoder.Decode(m).status().message().find("cell 12: a difference from no list before it"), std::string::npos);
  v1::ViewcellPvs first;
  first.set_cell_id(1);
  for (uint32_t o : {3u, 5u, 9u}) first.add_object_ids(o);
  ASSERT_TRUE(decoder.Decode(first).ok());
  auto expect = [&](const v1::ViewcellPvs& bad, const std::string& needle) {
    PvsListDecoder d = decoder;
    const absl::Status s = d.Decode(bad).status();
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << needle;
    EXPECT_NE(s.message().find(needle), std::string::npos) << s;
  };
  v1::ViewcellPvs bad = m;
  bad.clear_added();
  bad.add_added(5);
  expect(bad, "adds object 5, which the list before holds");
  bad = m;
  bad.clear_added();
  bad.add_removed(4);
  expect(bad, "removes object 4, which the list before lacks");
  bad = m;
  bad.clear_added();
  bad.add_removed(100);
  expect(bad, "removes object 100, which the list before lacks");
  bad = m;
  bad.add_added(0);
  expect(bad, "ids that do not ascend");
  bad = m;
  bad.clear_added();
  bad.add_level_ids(3);
  expect(bad, "0 level values for 1 ids");
  bad.add_level_values(2);
  bad.set_level_ids(0, 4);
  expect(bad, "a level for object 4, not on the list");
  v1::ViewcellPvs whole;
  whole.set_cell_id(2);
  for (uint32_t o : {1u, 2u}) whole.add_object_ids(o);
  whole.add_object_levels(1);
  expect(whole, "1 levels for 2 objects");
}

}  // namespace
}  // namespace vistream::proto
