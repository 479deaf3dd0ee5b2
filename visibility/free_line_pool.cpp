#include "visibility/free_line_pool.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <numbers>

namespace vistream::visibility {

namespace {

// The bucket of direction angle `theta` (radians, any value: taken modulo a turn).
int BucketOf(double theta) {
  const double turns = (theta + std::numbers::pi) / (2 * std::numbers::pi);
  const double b = std::floor((turns - std::floor(turns)) * FreeLinePool::kBuckets);
  return std::clamp(static_cast<int>(b), 0, FreeLinePool::kBuckets - 1);
}

}  // namespace

void FreeLinePool::Clear() {
  lines_.clear();
  for (auto& b : buckets_) b.clear();
}

void FreeLinePool::Add(const FreeLine& line) {
  if (!line.valid || line.from == line.to) return;
  const glm::dvec2 d = line.to - line.from;
  buckets_[BucketOf(std::atan2(d.y, d.x))].push_back(static_cast<uint32_t>(lines_.size()));
  lines_.push_back(line);
}

void FreeLinePool::Candidates(const glm::dvec2& d0, const glm::dvec2& d1, std::vector<uint32_t>* out) const {
  const size_t first = out->size();
  const double t0 = std::atan2(d0.y, d0.x), t1 = std::atan2(d1.y, d1.x);
  // The shorter arc: from `start`, counter-clockwise by `len` (at most a half turn).
  double len = t1 - t0;
  if (len > std::numbers::pi) len -= 2 * std::numbers::pi;
  if (len < -std::numbers::pi) len += 2 * std::numbers::pi;
  const double start = len >= 0 ? t0 : t1;
  const int b0 = BucketOf(start);
  int count = BucketOf(start + std::abs(len)) - b0;
  if (count < 0) count += kBuckets;
  for (int k = 0; k <= count; ++k) {
    const auto& bucket = buckets_[(b0 + k) % kBuckets];
    out->insert(out->end(), bucket.begin(), bucket.end());
  }
  std::sort(out->begin() + static_cast<ptrdiff_t>(first), out->end(), std::greater<uint32_t>());
}

}  // namespace vistream::visibility
