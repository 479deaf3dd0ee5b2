// libFuzzer target: the client's ε-mask decoding (client/mask_holdings.h: what a server sends in
// EpsilonMask.triangles) on untrusted bytes, for a scene of 200 objects and 4,000 triangles. The
// first byte picks the form: bit 0 deflated (visibility::InflateMaskBytes first), bit 1 a delta
// against a fixed base mask (ApplyMaskDelta). Whatever decodes must code again to the same sets
// (EncodeMaskRuns, then DecodeMaskRuns). With VISTREAM_FUZZ_SEED_DIR=DIR it first writes seeds
// there: the base's runs plain and deflated, and a delta.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "tests/mask_bits.h"
#include "visibility/mask_codec.h"

namespace {

constexpr uint32_t kObjects = 200;
constexpr uint64_t kTriangles = 4000;

std::vector<uint8_t> Bits(std::initializer_list<uint32_t> set) { return vistream::testing::MaskBits(set); }

const vistream::visibility::DecodedMask& Base() {
  static const vistream::visibility::DecodedMask* base = [] {
    std::vector<vistream::visibility::MaskObject> objects;
    for (uint32_t o = 0; o < kObjects; o += 3) objects.push_back({o, Bits({0, 1, 4, 5, 10, 11})});
    absl::StatusOr<vistream::visibility::DecodedMask> d =
        vistream::visibility::DecodeMaskRuns(vistream::visibility::EncodeMaskRuns(objects), kObjects, kTriangles);
    if (!d.ok()) std::abort();
    return new vistream::visibility::DecodedMask(*std::move(d));
  }();
  return *base;
}

void Write(const std::string& path, char form, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << form << bytes;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("VISTREAM_FUZZ_SEED_DIR")) {
    const std::string runs = vistream::visibility::EncodeMaskRuns(Base().objects);
    Write(std::string(dir) + "/runs", '\0', runs);
    Write(std::string(dir) + "/deflated", '\1', vistream::visibility::DeflateMaskBytes(runs));
    std::vector<vistream::visibility::MaskObject> next = Base().objects;
    next.resize(next.size() / 2);
    next.push_back({kObjects - 1, Bits({2, 3})});
    Write(std::string(dir) + "/delta", '\2', vistream::visibility::EncodeMaskDelta(Base().objects, next));
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const uint8_t form = data[0];
  std::string runs(reinterpret_cast<const char*>(data + 1), size - 1);
  if ((form & 1u) != 0) {
    absl::StatusOr<std::string> inflated = vistream::visibility::InflateMaskBytes(
        runs, static_cast<size_t>(vistream::visibility::MaxMaskRunBytes(kObjects, kTriangles)));
    if (!inflated.ok()) return 0;
    runs = *std::move(inflated);
  }
  absl::StatusOr<vistream::visibility::DecodedMask> d =
      (form & 2u) != 0 ? vistream::visibility::ApplyMaskDelta(Base(), runs, kObjects, kTriangles)
                       : vistream::visibility::DecodeMaskRuns(runs, kObjects, kTriangles);
  if (!d.ok()) return 0;
  // What decoded codes again to the same sets.
  absl::StatusOr<vistream::visibility::DecodedMask> again =
      vistream::visibility::DecodeMaskRuns(vistream::visibility::EncodeMaskRuns(d->objects), kObjects, kTriangles);
  if (!again.ok() || again->triangles != d->triangles || again->objects.size() != d->objects.size()) std::abort();
  for (size_t k = 0; k < d->objects.size(); ++k) {
    if (again->objects[k].object != d->objects[k].object) std::abort();
    for (size_t t = 0; t < 8 * std::max(again->objects[k].bits.size(), d->objects[k].bits.size()); ++t) {
      if (vistream::visibility::MaskBit(again->objects[k].bits, t) != vistream::visibility::MaskBit(d->objects[k].bits, t)) {
        std::abort();
      }
    }
  }
  return 0;
}
