#pragma once
// A triangle bit set (visibility::MaskObject::bits) from the triangle indices it holds: the mask
// codec's tests and its fuzz target write sets so.

#include <cstdint>
#include <initializer_list>
#include <vector>

namespace vistream::testing {

inline std::vector<uint8_t> MaskBits(std::initializer_list<uint32_t> set) {
  std::vector<uint8_t> b;
  for (uint32_t t : set) {
    if (b.size() <= t / 8) b.resize(t / 8 + 1, 0);
    b[t / 8] = static_cast<uint8_t>(b[t / 8] | (1u << (t % 8)));
  }
  return b;
}

}  // namespace vistream::testing
