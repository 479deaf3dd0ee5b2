#pragma once
// ViewcellPvs as a difference from the list before it (Hello.pvs_deltas; issue 45's byte
// budget): both ends of the wire. Neighbouring viewcells' PVSs share most of their objects, and
// the server sends a session's lists one after another, so each is sent as what it removes from
// and adds to the one before, ids gap-coded (small varints), and with levels of detail only the
// levels that changed.

#include <cstdint>
#include <vector>

#include <absl/status/statusor.h>

#include "proto/walkthrough.pb.h"

namespace vistream::proto {

// A whole list: its cell, objects ascending, each object's level (empty without levels), and
// the clusters chosen for the cell with their levels (ViewcellPvs.cluster_ids, cluster_levels:
// sent whole in every list, deltas too; the encoder leaves them to the caller's message).
struct PvsList {
  uint32_t cell = 0;
  std::vector<uint32_t> objects;
  std::vector<uint32_t> levels;
  std::vector<uint32_t> cluster_ids;
  std::vector<uint32_t> cluster_levels;
};

// Fills out's removed, added, level_ids and level_values (and delta) for `next` after `previous`
// (both whole lists; levels either both given or `previous`'s absent, read as 0); clears
// object_ids and object_levels. cell_id and compute_s are the caller's.
void EncodePvsDelta(const PvsList& previous, const PvsList& next, vistream::v1::ViewcellPvs* out);

// The receiving side: the session's previous list, to which a delta applies.
class PvsListDecoder {
 public:
  // The whole list `m` stands for (a whole message, or a delta from the previous list); it
  // becomes the previous list. Errors (INVALID_ARGUMENT naming the cell): a delta before any
  // list, a removed id the previous list lacks or an added one it has, a gap of 0 (or one past
  // 2^32), level_values not one per level_ids entry, a level named for an object not on the list,
  // object_levels neither empty nor one per object, cluster ids that do not ascend, cluster_levels
  // not one per cluster id or a cluster level of 0.
  absl::StatusOr<PvsList> Decode(const vistream::v1::ViewcellPvs& m);
  // A new session: no previous list.
  void Clear() { has_previous_ = false; }

 private:
  PvsList previous_;
  bool has_previous_ = false;
};

}  // namespace vistream::proto
