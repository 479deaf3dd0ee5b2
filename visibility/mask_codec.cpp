#include "visibility/mask_codec.h"

#include <algorithm>
#include <bit>

#include <absl/strings/str_cat.h>
#include <zlib.h>

#include "visibility/bytes.h"

namespace vistream::visibility {

namespace mask_codec_internal {

void AppendObject(std::string* out, uint32_t gap, std::span<const uint32_t> indices) {
  // Runs of consecutive indices: (hidden before it, its length).
  std::vector<std::pair<uint32_t, uint32_t>> runs;
  uint32_t next = 0;  // the first triangle index not yet coded
  size_t k = 0;
  while (k < indices.size()) {
    const uint32_t start = indices[k];
    uint32_t end = start + 1;
    ++k;
    while (k < indices.size() && indices[k] == end) {
      ++end;
      ++k;
    }
    runs.emplace_back(start - next, end - start);
    next = end;
  }
  if (runs.empty()) return;
  ByteWriter w;
  w.PutVarint(gap);
  w.PutVarint(runs.size());
  for (const auto& [hidden, visible] : runs) {
    w.PutVarint(hidden);
    w.PutVarint(visible);
  }
  out->append(w.bytes());
}

}  // namespace mask_codec_internal

std::string EncodeMaskRuns(std::span<const MaskObject> objects) {
  std::string out;
  std::vector<uint32_t> indices;
  int64_t previous = -1;
  for (const MaskObject& m : objects) {
    indices.clear();
    for (size_t t = 0; t < m.bits.size() * 8; ++t) {
      if (MaskBit(m.bits, t)) indices.push_back(static_cast<uint32_t>(t));
    }
    if (indices.empty()) continue;
    mask_codec_internal::AppendObject(&out, static_cast<uint32_t>(m.object - previous - 1), indices);
    previous = m.object;
  }
  return out;
}

absl::StatusOr<DecodedMask> DecodeMaskRuns(std::string_view bytes, uint32_t object_count, uint64_t max_triangles) {
  ByteReader in(bytes, "ε-mask triangles");
  DecodedMask out;
  int64_t previous = -1;
  uint64_t spanned = 0;  // triangle indices every object's runs reach, summed: within max_triangles
  while (!in.AtEnd()) {
    const size_t at = in.offset();
    const std::string what = absl::StrCat("object ", out.objects.size());
    uint64_t gap = 0, pairs = 0;
    if (absl::Status st = in.GetVarint(&gap, what + " id"); !st.ok()) return st;
    const uint64_t id = static_cast<uint64_t>(previous + 1) + std::min<uint64_t>(gap, object_count);
    if (id >= object_count) {
      return absl::InvalidArgumentError(absl::StrCat("ε-mask triangles at byte ", at, ": ", what, " id ", id,
                                                     " is past the scene's ", object_count, " objects"));
    }
    if (absl::Status st = in.GetVarint(&pairs, what + " run pairs"); !st.ok()) return st;
    if (pairs == 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("ε-mask triangles at byte ", at, ": object ", id, " has no run pairs"));
    }
    MaskObject m;
    m.object = static_cast<uint32_t>(id);
    uint64_t next = 0;
    for (uint64_t p = 0; p < pairs; ++p) {
      uint64_t hidden = 0, visible = 0;
      const std::string pair = absl::StrCat("object ", id, " run pair ", p);
      if (absl::Status st = in.GetVarint(&hidden, pair + " hidden"); !st.ok()) return st;
      if (absl::Status st = in.GetVarint(&visible, pair + " visible"); !st.ok()) return st;
      if (visible == 0) {
        return absl::InvalidArgumentError(
            absl::StrCat("ε-mask triangles at byte ", in.offset(), ": ", pair, " has no visible triangle"));
      }
      if (hidden > max_triangles || visible > max_triangles || spanned + next + hidden + visible > max_triangles) {
        return absl::InvalidArgumentError(absl::StrCat("ε-mask triangles at byte ", in.offset(), ": ", pair,
                                                       " takes the mask past ", max_triangles,
                                                       " triangles (more than the scene has)"));
      }
      const uint64_t start = next + hidden, end = start + visible;
      m.bits.resize((end + 7) / 8, 0);
      for (uint64_t t = start; t < end; ++t) m.bits[t / 8] = static_cast<uint8_t>(m.bits[t / 8] | (1u << (t % 8)));
      out.triangles += visible;
      next = end;
    }
    spanned += next;
    out.objects.push_back(std::move(m));
    previous = static_cast<int64_t>(id);
  }
  return out;
}

namespace {

// a XOR b, trailing zero bytes trimmed.
std::vector<uint8_t> Xor(const std::vector<uint8_t>& a, const std::vector<uint8_t>& b) {
  std::vector<uint8_t> out(std::max(a.size(), b.size()), 0);
  for (size_t k = 0; k < out.size(); ++k) {
    out[k] = static_cast<uint8_t>((k < a.size() ? a[k] : 0) ^ (k < b.size() ? b[k] : 0));
  }
  while (!out.empty() && out.back() == 0) out.pop_back();
  return out;
}

// One past the highest set bit of `bits` (whose last byte is not 0: Xor's results): the
// triangle indices the object's runs reach, as DecodeMaskRuns counts them.
uint64_t Reach(const std::vector<uint8_t>& bits) {
  return bits.empty() ? 0 : 8 * (bits.size() - 1) + static_cast<uint64_t>(std::bit_width(bits.back()));
}

uint64_t Popcount(const std::vector<uint8_t>& bits) {
  uint64_t n = 0;
  for (uint8_t b : bits) n += static_cast<uint64_t>(__builtin_popcount(b));
  return n;
}

}  // namespace

std::string EncodeMaskDelta(std::span<const MaskObject> base, std::span<const MaskObject> current) {
  std::vector<MaskObject> diff;
  size_t i = 0, j = 0;
  static const std::vector<uint8_t> kNone;
  while (i < base.size() || j < current.size()) {
    const bool take_base = j == current.size() || (i < base.size() && base[i].object <= current[j].object);
    const bool take_current = i == base.size() || (j < current.size() && current[j].object <= base[i].object);
    MaskObject d;
    d.object = take_base ? base[i].object : current[j].object;
    d.bits = Xor(take_base ? base[i].bits : kNone, take_current ? current[j].bits : kNone);
    if (take_base) ++i;
    if (take_current) ++j;
    if (!d.bits.empty()) diff.push_back(std::move(d));
  }
  return EncodeMaskRuns(diff);
}

absl::StatusOr<DecodedMask> ApplyMaskDelta(const DecodedMask& base, std::string_view delta, uint32_t object_count,
                                           uint64_t max_triangles) {
  absl::StatusOr<DecodedMask> d = DecodeMaskRuns(delta, object_count, max_triangles);
  if (!d.ok()) return d.status();
  DecodedMask out;
  size_t i = 0, j = 0;
  uint64_t spanned = 0;
  static const std::vector<uint8_t> kNone;
  while (i < base.objects.size() || j < d->objects.size()) {
    const bool take_base = j == d->objects.size() || (i < base.objects.size() && base.objects[i].object <= d->objects[j].object);
    const bool take_delta = i == base.objects.size() || (j < d->objects.size() && d->objects[j].object <= base.objects[i].object);
    MaskObject m;
    m.object = take_base ? base.objects[i].object : d->objects[j].object;
    m.bits = Xor(take_base ? base.objects[i].bits : kNone, take_delta ? d->objects[j].bits : kNone);
    if (take_base) ++i;
    if (take_delta) ++j;
    if (m.bits.empty()) continue;
    spanned += Reach(m.bits);  // bounded as DecodeMaskRuns bounds a mask's runs
    if (spanned > max_triangles) {
      return absl::InvalidArgumentError(absl::StrCat("ε-mask delta: object ", m.object, " takes the mask past ",
                                                     max_triangles, " triangles (more than the scene has)"));
    }
    out.triangles += Popcount(m.bits);
    out.objects.push_back(std::move(m));
  }
  return out;
}

std::string DeflateMaskBytes(std::string_view runs) {
  uLongf size = compressBound(static_cast<uLong>(runs.size()));
  std::string out(size, '\0');
  const int rc = compress2(reinterpret_cast<Bytef*>(out.data()), &size, reinterpret_cast<const Bytef*>(runs.data()),
                           static_cast<uLong>(runs.size()), Z_BEST_COMPRESSION);
  if (rc != Z_OK) return std::string(runs);  // cannot happen with compressBound's room; sent plain
  out.resize(size);
  return out;
}

absl::StatusOr<std::string> InflateMaskBytes(std::string_view deflated, size_t max_bytes) {
  z_stream z{};
  if (inflateInit(&z) != Z_OK) return absl::InternalError("deflated ε-mask: zlib could not start inflating");
  z.next_in = reinterpret_cast<Bytef*>(const_cast<char*>(deflated.data()));
  z.avail_in = static_cast<uInt>(deflated.size());
  std::string out;
  int rc = Z_OK;
  while (rc == Z_OK) {
    if (out.size() >= max_bytes) {
      inflateEnd(&z);
      return absl::InvalidArgumentError(
          absl::StrCat("deflated ε-mask: inflates past ", max_bytes, " bytes, more than any mask of this scene"));
    }
    const size_t at = out.size();
    const size_t room = std::min<size_t>(max_bytes - at, std::max<size_t>(4096, at));
    out.resize(at + room);
    z.next_out = reinterpret_cast<Bytef*>(out.data() + at);
    z.avail_out = static_cast<uInt>(room);
    rc = inflate(&z, Z_NO_FLUSH);
    out.resize(at + room - z.avail_out);
  }
  const size_t used = deflated.size() - z.avail_in;
  inflateEnd(&z);
  if (rc == Z_BUF_ERROR) {
    return absl::InvalidArgumentError(absl::StrCat("deflated ε-mask: truncated after ", deflated.size(), " bytes"));
  }
  if (rc != Z_STREAM_END) {
    return absl::InvalidArgumentError(absl::StrCat("deflated ε-mask: corrupt near byte ", used, " (",
                                                   z.msg != nullptr ? z.msg : "zlib error", ")"));
  }
  if (used != deflated.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat("deflated ε-mask: ", deflated.size() - used, " bytes after the end of its stream"));
  }
  return out;
}

uint64_t MaxMaskRunBytes(uint32_t object_count, uint64_t max_triangles) {
  return 10 * static_cast<uint64_t>(object_count) + 10 * max_triangles;
}

absl::StatusOr<DecodedMask> MaskBases::Decode(uint32_t cell, uint32_t mask_id, uint32_t base_mask_id,
                                              std::string_view bytes, uint32_t object_count, uint64_t max_triangles) {
  auto it = bases_.find(cell);
  absl::StatusOr<DecodedMask> d;
  if (base_mask_id == 0) {
    d = DecodeMaskRuns(bytes, object_count, max_triangles);
  } else if (it == bases_.end() || it->second.mask_id != base_mask_id) {
    return absl::FailedPreconditionError(
        absl::StrCat("ε-mask ", mask_id, " of cell ", cell, " is a delta against mask ", base_mask_id, ", but ",
                     it == bases_.end() ? std::string("no mask of that cell is held")
                                        : absl::StrCat("the cell's latest mask is ", it->second.mask_id)));
  } else {
    d = ApplyMaskDelta(it->second.mask, bytes, object_count, max_triangles);
  }
  if (!d.ok()) return d.status();
  if (it == bases_.end()) {
    order_.push_back(cell);
    it = bases_.emplace(cell, Base{0, {}, std::prev(order_.end())}).first;
  } else {
    order_.splice(order_.end(), order_, it->second.order);
  }
  it->second.mask_id = mask_id;
  it->second.mask = *d;
  while (bases_.size() > max_cells_) {
    bases_.erase(order_.front());
    order_.pop_front();
  }
  return d;
}

}  // namespace vistream::visibility
