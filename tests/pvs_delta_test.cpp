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
  // Cluster levels (issue 45): one level (>= 1) per cluster id, ids ascending.
  bad = first;
  bad.add_cluster_ids(4);
  expect(bad, "0 cluster levels for 1 clusters");
  bad.add_cluster_levels(0);
  expect(bad, "cluster 4 at level 0");
  bad.set_cluster_levels(0, 2);
  bad.add_cluster_ids(4);
  bad.add_cluster_levels(1);
  expect(bad, "cluster ids that do not ascend (4 then 4)");
}

// A list's clusters come whole with every list, deltas too, and decode as sent.
TEST(PvsDelta, ClustersComeWithEveryListWhole) {
  PvsListDecoder decoder;
  const PvsList a{7, {1, 2, 3}, {1, 1, 0}, {4, 9}, {1, 3}};
  const PvsList b{8, {1, 2, 5}, {1, 2, 0}, {9}, {2}};
  v1::ViewcellPvs first;
  first.set_cell_id(a.cell);
  first.mutable_object_ids()->Add(a.objects.begin(), a.objects.end());
  first.mutable_object_levels()->Add(a.levels.begin(), a.levels.end());
  first.mutable_cluster_ids()->Add(a.cluster_ids.begin(), a.cluster_ids.end());
  first.mutable_cluster_levels()->Add(a.cluster_levels.begin(), a.cluster_levels.end());
  absl::StatusOr<PvsList> got = decoder.Decode(first);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->cluster_ids, a.cluster_ids);
  EXPECT_EQ(got->cluster_levels, a.cluster_levels);
  v1::ViewcellPvs delta;
  delta.set_cell_id(b.cell);
  EncodePvsDelta(a, b, &delta);
  delta.mutable_cluster_ids()->Add(b.cluster_ids.begin(), b.cluster_ids.end());
  delta.mutable_cluster_levels()->Add(b.cluster_levels.begin(), b.cluster_levels.end());
  got = decoder.Decode(delta);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->objects, b.objects);
  EXPECT_EQ(got->levels, b.levels);
  EXPECT_EQ(got->cluster_ids, b.cluster_ids);
  EXPECT_EQ(got->cluster_levels, b.cluster_levels);
}

}  // namespace
}  // namespace vistream::proto
