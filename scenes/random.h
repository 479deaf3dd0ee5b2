#pragma once
// A deterministic random source: xoshiro256** seeded by splitmix64. The standard library's
// distributions are implementation-defined, so generated scenes use only these helpers and
// stay identical across compilers and platforms for a given seed.

#include <cstdint>

#include <glm/vec2.hpp>

namespace vistream::scenes {

class Rng {
 public:
  explicit Rng(uint64_t seed) {
    for (uint64_t& s : state_) s = SplitMix(&seed);
  }
  uint64_t Next() {
    const uint64_t result = Rotl(state_[1] * 5, 7) * 9;
    const uint64_t t = state_[1] << 17;
    state_[2] ^= state_[0];
    state_[3] ^= state_[1];
    state_[1] ^= state_[2];
    state_[0] ^= state_[3];
    state_[2] ^= t;
    state_[3] = Rotl(state_[3], 45);
    return result;
  }
  // Uniform in [0, 1), 53 random bits.
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  // A point uniform in [x0, x1] x [y0, y1], y drawn first: two draws in one expression (a
  // constructor's arguments) come in an order the compiler chooses, and GCC drew y first, so
  // this keeps the generated cities and makes them the same with every compiler.
  glm::dvec2 UniformPoint(double x0, double x1, double y0, double y1) {
    const double y = Uniform(y0, y1);
    const double x = Uniform(x0, x1);
    return {x, y};
  }
  // Uniform integer in [0, n), n > 0, without modulo bias (rejection below 2^64 mod n).
  uint64_t Below(uint64_t n) {
    const uint64_t threshold = (0 - n) % n;
    for (;;) {
      const uint64_t r = Next();
      if (r >= threshold) return r % n;
    }
  }
  bool Chance(double p) { return Uniform() < p; }
  // A new generator whose stream is independent of this one's continuation.
  Rng Fork() { return Rng(Next()); }

 private:
  static uint64_t Rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  static uint64_t SplitMix(uint64_t* x) {
    uint64_t z = (*x += 0x9e3779b97f4a7c15ULL);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  uint64_t state_[4];
};

}  // namespace vistream::scenes
