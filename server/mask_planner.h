#pragma once
// The ε-masks of one session along its path (DESIGN.md "ε-neighbourhoods along the path";
// Cohen-Or & Zadicario 1998; issue 34): which neighbourhoods get a mask (the chain of
// neighbourhoods ahead of the client, server/neighbourhood_chain.h), the queue of masks to
// compute (each by when the eye reaches its box) and of masks computed and not yet sent
// (soonest reached first), how one mask is built (BuildMask), and the masks' place in the
// session's send order: after the control messages, each mask followed by the objects it
// needs that the client lacks, before the rest of the PVSs' geometry (server/session.h).
//
// A mask narrows its cell's PVS, whose list the client must have first: a mask is computed
// only once its cell's PVS list has been handed out. A box the predicted path leaves before
// its mask is sent is dropped, computed or not.
//
// Not thread-safe: its session calls it under the session's lock. Times are seconds on the
// session's clock; positions metres, velocities metres per second, scene-local frame (z up).

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <unordered_set>
#include <vector>

#include <glm/vec3.hpp>

#include "proto/walkthrough.pb.h"
#include "scenes/aabb.h"
#include "server/neighbourhood_chain.h"
#include "server/pvs_scheduler.h"
#include "visibility/epsilon_superset.h"
#include "visibility/mask_codec.h"
#include "visibility/viewcell_grid.h"

namespace vistream::server {

// One computed ε-mask, before it is numbered and coded for the wire.
struct BuiltMask {
  // An EpsilonMask with its cell, neighbourhood box and counts; mask_id, base_mask_id and
  // triangles are set when it is sent.
  vistream::v1::ServerMessage message;
  std::vector<visibility::MaskObject> sets;  // its triangle sets, objects ascending
  double compute_ms = 0.0;                   // wall time of the computation
};

// Computes the ε-mask of the neighbourhood `box` (metres, scene frame) over `pvs` (the PVS of
// the cell the box lies in) with `eps` (EpsilonSuperset::Compute, default options). Thread-safe
// (runs on the scene's mask workers).
BuiltMask BuildMask(const visibility::EpsilonSuperset& eps, const scenes::Aabb& box, const CellPvs& pvs);

class MaskPlanner {
 public:
  MaskPlanner() = default;
  explicit MaskPlanner(const ChainOptions& chain) : chain_(chain) {}

  // Whether the session gets masks (its Hello asked, the scene has the engine); off: nothing
  // is planned.
  bool on() const { return on_; }
  void set_on(bool on) { on_ = on; }
  // Whether masks go deflated where that is shorter (Hello.deflated_masks; EpsilonMask.deflated).
  void set_deflate(bool deflate) { deflate_ = deflate; }

  // Moves the chain along with a client at `position` moving at `velocity` (its pose at `now`):
  // plans a mask for each neighbourhood the chain adds (due when the eye reaches it, at the
  // client's speed; at once for a standing client) and drops those it removes. The chain moves
  // every quarter metre or quarter second at most. Neighbourhoods lie in cells for which
  // `wanted(cell)` holds. Masks dropped are counted in stats->epsilon_masks_dropped.
  void Advance(const glm::dvec3& position, const glm::dvec3& velocity, double now, const visibility::ViewcellGrid& grid,
               const std::function<bool(CellId)>& wanted, vistream::v1::SessionStats* stats);

  // A mask to compute now.
  struct Job {
    uint64_t key = 0;  // the neighbourhood's id: Planned(key), AddComputed(key, ...)
    scenes::Aabb box;
    CellPvsPtr pvs;    // of the box's cell
    double deadline = 0.0;
  };
  // The planned masks not yet handed out whose cell's PVS list has gone out (`emitted`) and
  // whose PVS is at hand (`received`), in neighbourhood order; each is handed out once.
  std::vector<Job> TakeJobs(const std::set<CellId>& emitted, const std::map<CellId, CellPvsPtr>& received);
  // Whether the mask of `key` is still wanted (not dropped, not yet computed).
  bool Planned(uint64_t key) const { return planned_.count(key) > 0; }
  // Queues the computed mask of `key` to be sent, soonest reached first; false (and nothing
  // queued) when it was dropped while it was computed.
  bool AddComputed(uint64_t key, BuiltMask mask);

  // The session's wanted cells are now `wanted` (current first): forgets the bases of cells no
  // longer wanted and the objects still to go for a mask of such a cell.
  void Rewant(const std::vector<CellId>& wanted);

  // ---- the masks' place in the send order ----

  // Geometry of object `object` for the wire, or the Evict that must go before it (none when
  // it cannot be sent within the memory budget); `rank` is the position in the wanted cells
  // of the cell it is sent for; *sent tells whether the object itself went (Session::SendObject).
  using SendObject =
      std::function<std::optional<vistream::v1::ServerMessage>(uint32_t object, size_t rank, bool* sent)>;
  // The next object the last mask sent needs and `held` (the client's objects) lacks, through
  // `send`; none when every such object went (or had no room: it waits for its cell's turn).
  std::optional<vistream::v1::ServerMessage> NextObject(const std::unordered_set<uint32_t>& held,
                                                        const SendObject& send);
  // The next computed mask whose cell is still wanted and listed (`emitted`), numbered and
  // coded (its sets, or their difference from the cell's last mask, whichever is shorter);
  // the objects it needs that `held` lacks go next (NextObject). Masks of cells the client
  // turned away from are dropped. Counts epsilon_masks, epsilon_mask_bytes, bytes_sent and
  // epsilon_masks_dropped in `stats`.
  struct Sent {
    vistream::v1::ServerMessage message;
    CellId cell = 0;
    double compute_ms = 0.0;
  };
  // `whole(cell, object)`, when given: the object's triangle count where the client draws it
  // whole from this cell's mask (a level of detail that does not keep the full mesh's
  // triangles, issue 45), 0 where the mask's bits apply; such an object's set is sent as all
  // of its triangles (a few bytes, unchanged from one box to the next: nothing in a delta).
  std::optional<Sent> NextMask(const std::vector<CellId>& wanted, const std::set<CellId>& emitted,
                               const std::unordered_set<uint32_t>& held, vistream::v1::SessionStats* stats,
                               const std::function<uint32_t(CellId, uint32_t)>& whole = {});

 private:
  void Drop(uint64_t id, vistream::v1::SessionStats* stats);

  bool on_ = false;
  bool deflate_ = false;
  NeighbourhoodChain chain_;
  glm::dvec3 chain_eye_{0.0};                  // where the chain was last advanced
  double chain_s_ = -1.0;
  double heading_ = 0.0, heading_s_ = -1.0;    // the last moving pose's heading, for the turn rate
  double turn_rate_ = 0.0;                     // rad/s, smoothed
  struct PlannedMask {
    Neighbourhood n;
    double deadline = 0.0;  // when the eye reaches it (session clock)
    bool posted = false;
  };
  std::map<uint64_t, PlannedMask> planned_;    // by neighbourhood id: not computed yet
  struct ReadyMask {
    uint64_t id = 0;
    CellId cell = 0;
    double deadline = 0.0;
    BuiltMask mask;
  };
  std::vector<ReadyMask> ready_;               // computed, not sent: soonest reached first
  std::deque<uint32_t> objects_;               // the last mask sent's objects, to go next
  CellId objects_cell_ = 0;                    // that mask's cell
  size_t objects_rank_ = 0;                    // its place in the wanted cells
  uint32_t next_mask_id_ = 1;
  struct SentMask {
    uint32_t id = 0;
    std::vector<visibility::MaskObject> sets;
  };
  std::map<CellId, SentMask> last_sent_;       // per wanted cell: the base of the next one's delta
};

}  // namespace vistream::server
