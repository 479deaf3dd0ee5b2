// The run-length wire form of ε-mask triangle sets (visibility/mask_codec.h).
#include "visibility/mask_codec.h"

#include <gtest/gtest.h>

#include "scenes/random.h"
#include "tests/mask_bits.h"

namespace vistream::visibility {
namespace {

std::vector<uint8_t> Bits(std::initializer_list<uint32_t> set) { return vistream::testing::MaskBits(set); }

TEST(MaskCodec, RandomSetsSurviveTheRoundTripAndBothEncodersAgree) {
  scenes::Rng rng(34);
  for (int round = 0; round < 200; ++round) {
    // Objects with triangles 1..300, each all seen, none seen, or a random mix of runs.
    std::vector<MaskObject> objects;
    std::vector<uint32_t> dense, first;  // the dense-id form: first triangle per object
    uint32_t next_dense = 0, id = static_cast<uint32_t>(rng.Below(3));
    uint64_t set_bits = 0;
    for (int k = 0; k < 30; ++k, id += 1 + static_cast<uint32_t>(rng.Below(rng.Below(2) == 0 ? 2 : 5000))) {
      const uint32_t n = 1 + static_cast<uint32_t>(rng.Below(300));
      const uint64_t kind = rng.Below(3);
      MaskObject m;
      m.object = id;
      m.bits.assign((n + 7) / 8, 0);
      for (uint32_t t = 0; t < n; ++t) {
        const bool on = kind == 0 || (kind == 2 && rng.Below(4) != 0);
        if (!on) continue;
        m.bits[t / 8] = static_cast<uint8_t>(m.bits[t / 8] | (1u << (t % 8)));
        dense.push_back(next_dense + t);
        ++set_bits;
      }
      first.push_back(next_dense);
      next_dense += n;
      objects.push_back(std::move(m));
    }
    std::vector<uint32_t> ids;
    for (const MaskObject& m : objects) ids.push_back(m.object);
    const std::string bytes = EncodeMaskRuns(objects);
    const std::string same = EncodeMaskRuns(
        std::span<const uint32_t>(dense),
        [&](uint32_t t) { return ids[std::upper_bound(first.begin(), first.end(), t) - first.begin() - 1]; },
        [&](uint32_t o) { return first[std::lower_bound(ids.begin(), ids.end(), o) - ids.begin()]; });
    ASSERT_EQ(bytes, same) << "round " << round;
    // The sets built from the dense ids (as the server builds each mask) code the same.
    const std::vector<MaskObject> built = MaskObjectsFromTriangles(
        std::span<const uint32_t>(dense),
        [&](uint32_t t) { return ids[std::upper_bound(first.begin(), first.end(), t) - first.begin() - 1]; },
        [&](uint32_t o) { return first[std::lower_bound(ids.begin(), ids.end(), o) - ids.begin()]; });
    ASSERT_EQ(EncodeMaskRuns(built), bytes) << "round " << round;
    const absl::StatusOr<DecodedMask> d = DecodeMaskRuns(bytes, id + 1, next_dense);
    ASSERT_TRUE(d.ok()) << d.status();
    EXPECT_EQ(d->triangles, set_bits);
    size_t j = 0;
    for (const MaskObject& m : objects) {
      bool any = false;
      for (size_t t = 0; t < m.bits.size() * 8; ++t) any |= MaskBit(m.bits, t);
      if (!any) continue;  // objects without a visible triangle are left out
      ASSERT_LT(j, d->objects.size());
      EXPECT_EQ(d->objects[j].object, m.object);
      for (size_t t = 0; t < m.bits.size() * 8 + 16; ++t) {
        ASSERT_EQ(MaskBit(d->objects[j].bits, t), MaskBit(m.bits, t)) << "object " << m.object << " triangle " << t;
      }
      ++j;
    }
    EXPECT_EQ(j, d->objects.size());
  }
}

TEST(MaskCodec, AWholeObjectTakesAFewBytes) {
  std::vector<uint8_t> all(125, 0xff);  // 1000 triangles, all seen
  const std::string bytes = EncodeMaskRuns(std::vector<MaskObject>{{7, all}, {9, Bits({3, 4, 5, 900})}});
  // id gap, one pair, hidden 0, 1000 visible (2 bytes); gap 1, two pairs, (3, 3), (894, 1).
  EXPECT_EQ(bytes.size(), 5u + 7u);
  EXPECT_TRUE(EncodeMaskRuns(std::vector<MaskObject>{{3, Bits({})}, {4, {0, 0}}}).empty());
}

TEST(MaskCodec, BadBytesAreRefusedNamingTheOffsetAndWhat) {
  const std::string good = EncodeMaskRuns(std::vector<MaskObject>{{2, Bits({0, 1})}, {5, Bits({4})}});
  ASSERT_TRUE(DecodeMaskRuns(good, 6, 100).ok());
  struct Case {
    std::string bytes;
    uint32_t objects;
    uint64_t triangles;
    const char* says;
  };
  const Case cases[] = {
      {good.substr(0, good.size() - 1), 6, 100, "truncated"},
      {good, 5, 100, "past the scene's 5 objects"},
      {std::string("\x02\x00", 2), 6, 100, "no run pairs"},
      {std::string("\x02\x01\x03\x00", 4), 6, 100, "no visible triangle"},
      {std::string("\x02\x01\x00\x65", 4), 6, 100, "past 100 triangles"},
      // Every object reaching 60 triangles: 120 of a scene of 100 in all.
      {std::string("\x00\x01\x00\x3c\x00\x01\x00\x3c", 8), 6, 100, "past 100 triangles"},
      {std::string("\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\x01", 11), 6, 100, "varint"},
      {std::string("\xff\xff\xff\xff\x0f\x01\x00\x01", 8), 6, 100, "past the scene's 6 objects"},
  };
  for (const Case& c : cases) {
    const absl::StatusOr<DecodedMask> d = DecodeMaskRuns(c.bytes, c.objects, c.triangles);
    ASSERT_FALSE(d.ok()) << c.says;
    EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(d.status().message().find(c.says), std::string::npos) << d.status();
    EXPECT_NE(d.status().message().find("byte"), std::string::npos) << d.status();
  }
}


// Random bit sets over objects with 1..200 triangles, some ids left out.
std::vector<MaskObject> RandomMask(scenes::Rng& rng, uint32_t objects, double keep) {
  std::vector<MaskObject> out;
  for (uint32_t o = 0; o < objects; ++o) {
    if (static_cast<double>(rng.Below(1000)) >= keep * 1000) continue;
    const uint32_t n = 1 + static_cast<uint32_t>(rng.Below(200));
    MaskObject m{o, std::vector<uint8_t>((n + 7) / 8, 0)};
    bool any = false;
    for (uint32_t t = 0; t < n; ++t) {
      if (rng.Below(3) == 0) continue;
      m.bits[t / 8] = static_cast<uint8_t>(m.bits[t / 8] | (1u << (t % 8)));
      any = true;
    }
    if (any) out.push_back(std::move(m));
  }
  return out;
}

TEST(MaskCodec, ADeltaAppliedToItsBaseGivesTheMaskBack) {
  scenes::Rng rng(3434);
  for (int round = 0; round < 100; ++round) {
    const std::vector<MaskObject> a = RandomMask(rng, 60, 0.5), b = RandomMask(rng, 60, 0.5);
    const absl::StatusOr<DecodedMask> base = DecodeMaskRuns(EncodeMaskRuns(a), 60, 60 * 200);
    ASSERT_TRUE(base.ok()) << base.status();
    const std::string delta = EncodeMaskDelta(a, b);
    const absl::StatusOr<DecodedMask> got = ApplyMaskDelta(*base, delta, 60, 60 * 200);
    ASSERT_TRUE(got.ok()) << got.status();
    const absl::StatusOr<DecodedMask> want = DecodeMaskRuns(EncodeMaskRuns(b), 60, 60 * 200);
    ASSERT_TRUE(want.ok());
    EXPECT_EQ(got->triangles, want->triangles) << "round " << round;
    ASSERT_EQ(got->objects.size(), want->objects.size()) << "round " << round;
    for (size_t j = 0; j < want->objects.size(); ++j) {
      EXPECT_EQ(got->objects[j].object, want->objects[j].object);
      for (size_t t = 0; t < 200; ++t) {
        ASSERT_EQ(MaskBit(got->objects[j].bits, t), MaskBit(want->objects[j].bits, t))
            << "round " << round << " object " << want->objects[j].object << " triangle " << t;
      }
    }
  }
}

TEST(MaskCodec, NeighbouringMasksCostLessAsADelta) {
  // The next box along a street sees what the last saw, a few objects more and a few less.
  scenes::Rng rng(35);
  const std::vector<MaskObject> a = RandomMask(rng, 400, 0.6);
  std::vector<MaskObject> b(a.begin() + 10, a.end());  // ten objects fall behind
  const std::vector<MaskObject> ahead = RandomMask(rng, 420, 0.05);
  for (const MaskObject& m : ahead) {
    if (m.object >= 400) b.push_back(m);  // and some come into view
  }
  EXPECT_TRUE(EncodeMaskDelta(a, a).empty());
  EXPECT_LT(EncodeMaskDelta(a, b).size() * 4, EncodeMaskRuns(b).size());
}

TEST(MaskCodec, ADeltaPastTheSceneIsRefused) {
  const std::vector<MaskObject> a{{2, Bits({0, 1})}};
  const absl::StatusOr<DecodedMask> base = DecodeMaskRuns(EncodeMaskRuns(a), 6, 100);
  ASSERT_TRUE(base.ok());
  const std::string delta = EncodeMaskDelta(a, std::vector<MaskObject>{{2, Bits({0, 1})}, {5, Bits({90})}});
  EXPECT_TRUE(ApplyMaskDelta(*base, delta, 6, 100).ok());
  const absl::StatusOr<DecodedMask> past = ApplyMaskDelta(*base, delta, 5, 100);
  ASSERT_FALSE(past.ok());
  EXPECT_NE(past.status().message().find("past the scene's 5 objects"), std::string::npos) << past.status();
  const absl::StatusOr<DecodedMask> big = ApplyMaskDelta(*base, delta, 6, 50);
  ASSERT_FALSE(big.ok());
  EXPECT_EQ(big.status().code(), absl::StatusCode::kInvalidArgument);
  // Bounded exactly as DecodeMaskRuns bounds the same sets (found by fuzzing: the bound once
  // counted whole bytes, letting a delta's result reach up to 7 triangles an object further).
  // The result reaches 2 + 91 = 93 triangles: refused under 92, as its runs would be.
  const std::vector<MaskObject> result{{2, Bits({0, 1})}, {5, Bits({90})}};
  EXPECT_TRUE(DecodeMaskRuns(EncodeMaskRuns(result), 6, 93).ok());
  EXPECT_TRUE(ApplyMaskDelta(*base, delta, 6, 93).ok());
  EXPECT_FALSE(DecodeMaskRuns(EncodeMaskRuns(result), 6, 92).ok());
  EXPECT_FALSE(ApplyMaskDelta(*base, delta, 6, 92).ok());
}


// Deflated masks (EpsilonMask.deflated): box-like objects' runs repeat, so about half of the
// bytes go; inflating gives them back exactly; a stream that is not one, is cut, has bytes
// after it, or would inflate past the scene's bound is refused, saying which.
TEST(MaskCodec, DeflatedRunsInflateExactlyAndBadStreamsAreRefused) {
  std::vector<MaskObject> boxes;  // 400 boxes of 12 triangles, faces 0-1, 4-5 and 10-11 seen
  for (uint32_t o = 0; o < 400; ++o) boxes.push_back({o * 3, Bits({0, 1, 4, 5, 10, 11})});
  const std::string runs = EncodeMaskRuns(boxes);
  const std::string deflated = DeflateMaskBytes(runs);
  EXPECT_LT(deflated.size(), runs.size() / 2) << deflated.size() << " of " << runs.size();
  const uint64_t bound = MaxMaskRunBytes(1200, 1200 * 12);
  ASSERT_GE(bound, runs.size());
  absl::StatusOr<std::string> back = InflateMaskBytes(deflated, bound);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(*back, runs);
  // Random sets too (and the empty mask).
  scenes::Rng rng(7);
  for (int k = 0; k < 20; ++k) {
    const std::string r = EncodeMaskRuns(RandomMask(rng, 300, 0.5));
    absl::StatusOr<std::string> b = InflateMaskBytes(DeflateMaskBytes(r), MaxMaskRunBytes(300, 300 * 200));
    ASSERT_TRUE(b.ok()) << b.status();
    EXPECT_EQ(*b, r);
  }
  struct Case {
    std::string bytes;
    size_t max_bytes;
    const char* says;
  };
  const Case cases[] = {
      {"not a zlib stream", bound, "corrupt"},
      {deflated.substr(0, deflated.size() / 2), bound, "truncated"},
      {deflated + "xx", bound, "2 bytes after the end"},
      {DeflateMaskBytes(std::string(1 << 20, '\0')), 1000, "inflates past 1000 bytes"},
  };
  for (const Case& c : cases) {
    const absl::StatusOr<std::string> d = InflateMaskBytes(c.bytes, c.max_bytes);
    ASSERT_FALSE(d.ok()) << c.says;
    EXPECT_EQ(d.status().code(), absl::StatusCode::kInvalidArgument);
    EXPECT_NE(d.status().message().find(c.says), std::string::npos) << d.status();
  }
}

TEST(MaskBases, DeltasApplyToTheLatestMaskOfTheirCellOnly) {
  const std::vector<MaskObject> a{{2, Bits({0, 1})}}, b{{2, Bits({1})}, {4, Bits({3})}}, c{{4, Bits({3, 4})}};
  MaskBases bases(2);
  ASSERT_TRUE(bases.Decode(10, 1, 0, EncodeMaskRuns(a), 6, 100).ok());
  const absl::StatusOr<DecodedMask> got = bases.Decode(10, 2, 1, EncodeMaskDelta(a, b), 6, 100);
  ASSERT_TRUE(got.ok()) << got.status();
  EXPECT_EQ(got->triangles, 2u);
  // Mask 1 is no longer the cell's latest: a delta against it is refused, naming both.
  const absl::StatusOr<DecodedMask> stale = bases.Decode(10, 3, 1, EncodeMaskDelta(a, c), 6, 100);
  ASSERT_FALSE(stale.ok());
  EXPECT_EQ(stale.status().code(), absl::StatusCode::kFailedPrecondition);
  EXPECT_NE(stale.status().message().find("the cell's latest mask is 2"), std::string::npos) << stale.status();
  // Against another cell's mask: refused.
  EXPECT_FALSE(bases.Decode(11, 4, 2, EncodeMaskDelta(b, c), 6, 100).ok());
  // Two cells held: a third pushes out the least recently received.
  ASSERT_TRUE(bases.Decode(11, 5, 0, EncodeMaskRuns(c), 6, 100).ok());
  ASSERT_TRUE(bases.Decode(12, 6, 0, EncodeMaskRuns(c), 6, 100).ok());
  EXPECT_EQ(bases.size(), 2u);
  const absl::StatusOr<DecodedMask> gone = bases.Decode(10, 7, 2, EncodeMaskDelta(b, c), 6, 100);
  ASSERT_FALSE(gone.ok());
  EXPECT_NE(gone.status().message().find("no mask of that cell is held"), std::string::npos) << gone.status();
  EXPECT_TRUE(bases.Decode(11, 8, 5, EncodeMaskDelta(c, a), 6, 100).ok());
}

}  // namespace
}  // namespace vistream::visibility
