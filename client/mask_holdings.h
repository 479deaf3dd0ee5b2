#pragma once
// Which ε-masks a client holds and which one a frame draws (DESIGN.md "ε-neighbourhoods along
// the path"; the client model, client/client_model.h): the one rule the native client's object
// store (client/object_store.h) and the simulator (simulation/simulator.h) both follow.
//
// Held: masks decoded as they arrive (deltas against the latest mask of their cell,
// visibility::MaskBases), kept while their cell is the client's current cell or one of its
// eight neighbours, at most kMaxMasks (the oldest dropped first). A mask holds for its box
// forever (the scene is static). Drawn: of the held masks whose box holds the eye and all of
// whose objects are ready (held, and uploaded where the caller draws), the one with the fewest
// triangles (ties: the lower mask id); none, and the frame draws the viewcell's PVS.

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <vector>

#include <absl/status/status.h>
#include <glm/vec3.hpp>

#include "proto/walkthrough.pb.h"
#include "visibility/mask_codec.h"
#include "visibility/viewcell_grid.h"

namespace vistream::client {

// An ε-mask decoded (proto EpsilonMask): which triangles of its cell's PVS may be seen from
// anywhere in its neighbourhood box. Objects with no such triangle are not listed.
struct EpsilonMaskSet {
  uint32_t mask_id = 0;  // the server's id (session-unique: a new session starts again from 1)
  uint64_t key = 0;      // the holder's own id, unique over its life (renderer caches key on it)
  uint32_t cell = 0;     // the viewcell whose PVS it narrows
  glm::dvec3 box_min{0.0}, box_max{0.0};  // the neighbourhood, scene-local metres
  std::vector<visibility::MaskObject> objects;  // ascending ids, each with a set bit
  std::vector<uint32_t> object_ids;             // the same ids, to draw
  std::vector<uint64_t> object_triangles;       // the same objects' set bits, each
  uint64_t triangles = 0;                       // set bits over all objects

  bool Contains(const glm::dvec3& p) const {
    return p.x >= box_min.x && p.x <= box_max.x && p.y >= box_min.y && p.y <= box_max.y && p.z >= box_min.z &&
           p.z <= box_max.z;
  }
  // The triangle bits of `object` (bit t: its triangle t may be seen); null if it has none.
  const std::vector<uint8_t>* Bits(uint32_t object) const;
};

// The mask a frame may draw (MaskHoldings::Choose).
struct MaskChoice {
  const EpsilonMaskSet* mask = nullptr;  // none: no held mask is usable for the eye
  bool in_box = false;                   // the eye is inside the box of some held mask
};

// The run-length bytes of `m` (visibility/mask_codec.h): its `triangles`, inflated when it
// came deflated (EpsilonMask.deflated). `object_count` and `triangle_count` are the scene's,
// bounding what inflating may allocate. Errors: visibility::InflateMaskBytes's, naming the mask.
absl::StatusOr<std::string> MaskRunBytes(const vistream::v1::EpsilonMask& m, uint32_t object_count,
                                         uint64_t triangle_count);

class MaskHoldings {
 public:
  // At most this many masks are held.
  static constexpr size_t kMaxMasks = 64;

  // Decodes and holds `m` (a mask id held already comes from a new session, whose ids start
  // again at 1: the new one replaces it). `object_count` and `triangle_count` are the scene's
  // (SceneInfo), bounding what decoding accepts. Errors: MaskRunBytes's and
  // visibility::MaskBases::Decode's (INVALID_ARGUMENT for bytes that do not decode,
  // FAILED_PRECONDITION for a delta whose base is not held); nothing is held then.
  absl::Status Add(const vistream::v1::EpsilonMask& m, uint32_t object_count, uint64_t triangle_count);
  // A new session starts: its masks number from 1 again, so no delta may refer to an old base.
  void NewSession() { bases_.Clear(); }
  // Drops the masks of cells other than `cell` and its eight neighbours on `grid` (none: no
  // cell is known, nothing is dropped for that), then the oldest while over kMaxMasks.
  void KeepNear(std::optional<uint32_t> cell, const visibility::ViewcellGrid& grid);
  // The mask a frame at `eye` (scene-local metres) may draw: among held masks whose box holds
  // the eye and each of whose objects passes `ready`, the one with the fewest triangles (ties:
  // the lower mask id). Also whether the eye is in any held mask's box at all.
  MaskChoice Choose(const glm::dvec3& eye, const std::function<bool(uint32_t)>& ready) const;
  // The same with `ready` told the mask's cell too (an object a cluster of that cell's list
  // stands for is ready when the cluster is: issue 45).
  MaskChoice Choose(const glm::dvec3& eye, const std::function<bool(uint32_t object, uint32_t cell)>& ready) const;

  // Every mask held, by the server's mask id.
  const std::map<uint32_t, EpsilonMaskSet>& masks() const { return masks_; }
  // Keys (EpsilonMaskSet::key) of masks dropped or replaced since the last call.
  std::vector<uint64_t> TakeDropped();

 private:
  void Drop(std::map<uint32_t, EpsilonMaskSet>::iterator it);

  std::map<uint32_t, EpsilonMaskSet> masks_;  // by mask id
  visibility::MaskBases bases_;               // the latest mask of each cell: deltas' bases
  uint64_t next_key_ = 1;
  std::vector<uint64_t> dropped_;
};

}  // namespace vistream::client
