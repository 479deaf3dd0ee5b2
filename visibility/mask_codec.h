#pragma once
// The wire form of an ε-mask's triangle sets (proto/walkthrough.proto EpsilonMask.triangles):
// run-length coded, so that a mask of a few hundred objects, most of whose triangles are
// either all seen or all hidden, takes a few bytes an object.
//
// Layout, objects in ascending id order, every number an unsigned LEB128 varint:
//   per object: id gap (id - previous id - 1; the first object's id itself), run pairs k >= 1,
//   then k pairs (hidden, visible): `hidden` triangles not in the set, then `visible` (>= 1)
//   triangles in it. Triangles past the last pair are not in the set. An object is listed only
//   with at least one visible triangle, so every encoding is canonical.

#include <cstdint>
#include <list>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>

namespace vistream::visibility {

// One object of a mask: bit t of `bits` (little-endian within bytes) set: triangle t may be
// visible from the neighbourhood. Bits past the end are clear.
struct MaskObject {
  uint32_t object = 0;
  std::vector<uint8_t> bits;
};

// Bit t of `bits` (false past its end).
inline bool MaskBit(const std::vector<uint8_t>& bits, size_t t) {
  return t / 8 < bits.size() && ((bits[t / 8] >> (t % 8)) & 1u) != 0;
}

// `objects` in ascending id order, distinct; objects without a set bit are left out.
std::string EncodeMaskRuns(std::span<const MaskObject> objects);

// The same from the sorted dense triangle ids of a visibility::EpsilonResult: `object_of(t)`
// and `first_triangle(o)` map them to objects and triangle indices (EpsilonSuperset's
// ObjectOfTriangle and TriangleId(o, 0)). Equal to EncodeMaskRuns of the same sets.
template <typename ObjectOf, typename FirstTriangle>
std::string EncodeMaskRuns(std::span<const uint32_t> sorted_triangles, ObjectOf object_of,
                           FirstTriangle first_triangle);

// The per-object sets of the sorted dense triangle ids of a visibility::EpsilonResult, the
// form EncodeMaskRuns and EncodeMaskDelta take (the server builds each ε-mask so, issue 34):
// objects ascending, each with the bits of its listed triangles set (bits sized to the last
// one). `object_of` and `first_triangle` as EncodeMaskRuns' template takes them.
// `sorted_triangles` must be ascending (EpsilonResult::triangles is).
template <typename ObjectOf, typename FirstTriangle>
std::vector<MaskObject> MaskObjectsFromTriangles(std::span<const uint32_t> sorted_triangles, ObjectOf object_of,
                                                 FirstTriangle first_triangle);

struct DecodedMask {
  std::vector<MaskObject> objects;  // ascending ids, each with at least one set bit
  uint64_t triangles = 0;           // set bits over every object
};

// Decodes EncodeMaskRuns' bytes. `object_count`: the scene's objects (ids must be below it);
// `max_triangles`: a bound on the triangles every object's runs reach, summed over the objects
// (the scene's triangle count: no real mask exceeds it; it bounds what decoding allocates). INVALID_ARGUMENT naming the byte offset and what is wrong: a truncated or
// over-long varint, an id past the scene or out of order, no run pairs, an empty visible run,
// runs past max_triangles.
absl::StatusOr<DecodedMask> DecodeMaskRuns(std::string_view bytes, uint32_t object_count, uint64_t max_triangles);

// Deflated run-length bytes (EpsilonMask.deflated): zlib's format (RFC 1950) at its best
// compression. Run-length masks repeat their gap and run values from object to object (a box's
// faces, a terrace's walls): about half of their bytes go.
std::string DeflateMaskBytes(std::string_view runs);
// The run-length bytes back. INVALID_ARGUMENT naming what is wrong: not a zlib stream, corrupt,
// truncated, bytes after its end, or more than `max_bytes` once inflated (what decoding
// allocates stays within it).
absl::StatusOr<std::string> InflateMaskBytes(std::string_view deflated, size_t max_bytes);
// The most bytes the run-length coding of any mask (sets or a delta) can take over a scene of
// `object_count` objects and `max_triangles` triangles: per object a gap and a pair count, per
// triangle at most one pair (each run at least one triangle), each varint at most 5 bytes.
uint64_t MaxMaskRunBytes(uint32_t object_count, uint64_t max_triangles);

// Masks along a path differ little from one box to the next: the later can go as its
// difference from the earlier. EncodeMaskDelta codes, per object, the XOR of the two bit sets
// (objects whose sets are equal are left out) exactly as EncodeMaskRuns codes a set; both
// arguments ascending and distinct (DecodedMask::objects).
std::string EncodeMaskDelta(std::span<const MaskObject> base, std::span<const MaskObject> current);
// `base` with such a delta applied: the XOR per object, objects left without a set bit removed.
// Errors as DecodeMaskRuns's, and INVALID_ARGUMENT when the result would pass max_triangles.
absl::StatusOr<DecodedMask> ApplyMaskDelta(const DecodedMask& base, std::string_view delta, uint32_t object_count,
                                           uint64_t max_triangles);

// The receiving side of EpsilonMask.base_mask_id: the latest mask of each cell, so that a
// delta against it can be applied (client/object_store and the simulator's client model).
// Holds the last `max_cells` cells that received a mask (least recently received dropped
// first); the server deltas only against cells it still wants, a few dozen at most.
class MaskBases {
 public:
  explicit MaskBases(size_t max_cells = 256) : max_cells_(max_cells) {}
  // Decodes the bytes of mask `mask_id` of `cell`: the sets when `base_mask_id` is 0, else a
  // delta against the held mask of the cell, which must be mask `base_mask_id`. The result
  // becomes the cell's base. Errors: DecodeMaskRuns's and ApplyMaskDelta's, and
  // FAILED_PRECONDITION when the base is not held (naming the cell, the base held if any).
  absl::StatusOr<DecodedMask> Decode(uint32_t cell, uint32_t mask_id, uint32_t base_mask_id, std::string_view bytes,
                                     uint32_t object_count, uint64_t max_triangles);
  // Forgets every base (a new session numbers masks from 1 again).
  void Clear() {
    bases_.clear();
    order_.clear();
  }
  size_t size() const { return bases_.size(); }

 private:
  struct Base {
    uint32_t mask_id = 0;
    DecodedMask mask;
    std::list<uint32_t>::iterator order;
  };
  size_t max_cells_;
  std::map<uint32_t, Base> bases_;  // by cell
  std::list<uint32_t> order_;       // cells, least recently received first
};

// ---- implementation of the template ----

namespace mask_codec_internal {
// Appends one object's runs: its set triangle indices, ascending (distinct).
void AppendObject(std::string* out, uint32_t gap, std::span<const uint32_t> indices);
}  // namespace mask_codec_internal

template <typename ObjectOf, typename FirstTriangle>
std::string EncodeMaskRuns(std::span<const uint32_t> sorted_triangles, ObjectOf object_of,
                           FirstTriangle first_triangle) {
  std::string out;
  std::vector<uint32_t> indices;
  int64_t previous = -1;
  size_t k = 0;
  while (k < sorted_triangles.size()) {
    const uint32_t o = object_of(sorted_triangles[k]);
    const uint32_t base = first_triangle(o);
    indices.clear();
    for (; k < sorted_triangles.size() && object_of(sorted_triangles[k]) == o; ++k) {
      indices.push_back(sorted_triangles[k] - base);
    }
    mask_codec_internal::AppendObject(&out, static_cast<uint32_t>(o - previous - 1), indices);
    previous = o;
  }
  return out;
}

template <typename ObjectOf, typename FirstTriangle>
std::vector<MaskObject> MaskObjectsFromTriangles(std::span<const uint32_t> sorted_triangles, ObjectOf object_of,
                                                 FirstTriangle first_triangle) {
  std::vector<MaskObject> sets;
  for (uint32_t t : sorted_triangles) {
    const uint32_t o = object_of(t);
    if (sets.empty() || sets.back().object != o) sets.push_back(MaskObject{o, {}});
    const uint32_t k = t - first_triangle(o);
    std::vector<uint8_t>& bits = sets.back().bits;
    if (bits.size() <= k / 8) bits.resize(k / 8 + 1, 0);
    bits[k / 8] = static_cast<uint8_t>(bits[k / 8] | (1u << (k % 8)));
  }
  return sets;
}

}  // namespace vistream::visibility
