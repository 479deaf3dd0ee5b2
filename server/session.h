#pragma once
// One walkthrough session's protocol, apart from the transport: what a client message does,
// and which message goes out next. The gRPC reactor (server/session_reactor.h) feeds it client messages and
// writes what NextMessage() gives, one at a time; the fuzz target and tests drive it directly.
//
// Order of what goes out (DESIGN.md, "Server and client"): SceneInfo after Hello; after the
// first pose the PVS of the client's cell, its geometry, then the eight neighbours' PVSs and
// geometry, in the order the client will reach them (its velocity); on each crossing the up to
// five newly adjacent cells likewise. Geometry is sent once: the client keeps what cells left
// behind needed until its memory budget needs the room, and then an Evict hint names what it
// may drop (what no wanted cell needs first, then what is needed latest). Control messages (PVS
// lists, Evict) go first; then, within the client's credit, ε-masks of the neighbourhoods ahead
// (server/neighbourhood_chain.h), soonest reached first, each followed by the objects it needs
// that the client lacks (ε-first geometry); then the rest of the PVSs' geometry, the current
// cell's before any neighbour's.
//
// ε-masks (issue 34; Cohen-Or & Zadicario 1998): only for a client whose Hello asks for them. A
// mask is computed (on the scene's MaskQueue, by when the eye reaches its box) once its cell's
// PVS list has been handed out; a box the predicted path leaves before its mask is sent is
// dropped, computed or not. The chain, its queues and the masks' place in the send order are
// server/mask_planner.h's; when each wanted cell is reached, server/cell_deadlines.h's.

#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <unordered_set>
#include <vector>

#include <absl/status/status.h>
#include <glm/vec3.hpp>

#include "proto/pvs_delta.h"
#include "proto/walkthrough.pb.h"
#include "server/event_log.h"
#include "server/mask_planner.h"
#include "server/neighbourhood_chain.h"
#include "server/served_scene.h"

namespace vistream::server {

// Per-session limits; a session that breaks one ends with RESOURCE_EXHAUSTED.
struct SessionLimits {
  double max_pose_rate_hz = 120.0;             // sustained poses per second (bursts to twice that)
  size_t max_queued_bytes = size_t{8} << 20;   // bytes waiting to be written to the client
  double epsilon_size_m = 4.0;                 // edge of a standing client's ε-neighbourhood (catalog);
                                               // a session whose Hello picks a scene uses that scene's
  // The neighbourhoods ahead of a walker (standing_size_m is epsilon_size_m).
  ChainOptions chain;
};

// What a session runs on: in the server the scene's threaded scheduler and ε-mask queue and the
// steady clock; in the simulator (simulation/simulator.h) its own, on simulated time. The defaults
// are the server's, and leave the session's behaviour as it was.
struct SessionSeams {
  PvsSource* pvs = nullptr;       // null: scene->scheduler()
  TaskRunner* masks = nullptr;    // null: scene->masks()
  std::function<double()> clock;  // seconds (Stats' session time); empty: the steady clock
  // false: the paper's plain scheme: neighbours asked for and sent in a fixed grid order
  // (ViewcellGrid::Neighbours'), not by the client's velocity.
  bool look_ahead = true;
  bool epsilon_masks = true;      // false: no ε-masks (the viewcell PVS only)
  // Server metrics (empty: none), called under the session's lock (they must not call back):
  // the cells a crossing made newly adjacent were served (their PVS lists and geometry handed to
  // the transport) `seconds` after the crossing; a client entered a cell before it was served.
  std::function<void(const std::string& scene, double seconds)> crossing_served;
  std::function<void(const std::string& scene)> late_cell;
};

// The scenes a server serves, by the name a Hello gives (ServedScene::name()).
struct SceneDirectory {
  std::vector<ServedScene*> scenes;  // not owned; in the configuration's order
  // Null when no scene has that name.
  ServedScene* Find(std::string_view name) const;
  // "'a', 'b'": for messages.
  std::string Names() const;
};

class Session : public std::enable_shared_from_this<Session> {
 public:
  // `wake` is called, without the session's lock, whenever a message becomes ready from a
  // worker thread (a PVS arrived); the transport then calls NextMessage(). `log` may be null.
  static std::shared_ptr<Session> Create(uint64_t id, ServedScene* scene, const SessionLimits& limits, EventLog* log,
                                         std::function<void()> wake, SessionSeams seams = {});
  // A session of a server of several scenes: its Hello picks one of `scenes` (not owned; it
  // must outlive the session), and a scene it does not list ends it with NOT_FOUND naming
  // those it does. The seams' pvs and masks must be null (each scene's own are used).
  static std::shared_ptr<Session> Create(uint64_t id, const SceneDirectory* scenes, const SessionLimits& limits,
                                         EventLog* log, std::function<void()> wake, SessionSeams seams = {});
  ~Session();

  uint64_t id() const { return id_; }
  // The scene the session's Hello picked; null before it (a server of several scenes).
  ServedScene* scene() const;
  // Whether Hello has arrived.
  bool greeted() const;

  // Handles one client message at `now` (seconds on the steady clock). A status other than OK
  // ends the session with it (the status names the message and what is wrong).
  absl::Status OnMessage(const vistream::v1::ClientMessage& message, double now);
  // The next message to write now, if any (credit and order allowed). Pops it.
  std::optional<vistream::v1::ServerMessage> NextMessage();
  // Non-OK when the session must end for something that happened off the read path.
  absl::Status failure() const;
  // Stops every request this session has with the scheduler; no more wake() calls.
  void End();

  vistream::v1::SessionStats Stats() const;

 private:
  Session(uint64_t id, ServedScene* scene, const SceneDirectory* directory, const SessionLimits& limits,
          EventLog* log, std::function<void()> wake, SessionSeams seams);
  double Now() const;

  absl::Status OnHello(const vistream::v1::Hello& hello);
  absl::Status OnPose(const vistream::v1::Pose& pose, double now);
  // Makes `current_` and its neighbours the wanted cells, in the order they will be reached.
  void SetWanted(double now);
  void RequestCell(CellId cell, double deadline);
  void OnCellReady(const CellPvsPtr& pvs, bool from_cache);  // lock held
  void EmitReady();                                          // lock held
  void Emit(CellId cell);                                    // lock held
  // Drops from `cell`'s chosen clusters those that cost more bytes than the objects they stand
  // for that the client does not hold at their own level already (the choice is per cell; this
  // is per session, as the list goes out).
  void DropDearClusters(CellId cell);                        // lock held
  // Adds to `cell`'s chosen clusters those the client holds at a level fine enough from the cell
  // that keeps its objects' triangles (drawn as their own levels would be, at no byte cost),
  // in place of chosen clusters sharing an object with them.
  void AdoptHeldClusters(CellId cell);                       // lock held
  // Moves the chain of neighbourhoods along with the client; posts the masks it can.
  void UpdateMasks(double now);                              // lock held
  // Posts the masks whose cells' PVS lists went out to the scene's mask workers.
  void PostMasks();                                          // lock held
  // Geometry of `o` for the wire (or the Evict that must go before it; none when it cannot be
  // sent within the memory budget), charged to the credit; `rank`: the position in wanted_ of
  // the cell it is sent for. An object a cluster chosen for that cell stands for: the cluster
  // (none when the client holds it at some level).
  std::optional<vistream::v1::ServerMessage> SendObject(uint32_t o, size_t rank, bool* sent);  // lock held
  // Geometry of `key` (an object, or kClusterKey | cluster) at `level` (0: an object's full mesh).
  std::optional<vistream::v1::ServerMessage> SendLevel(uint32_t key, uint32_t level, size_t rank,
                                                       bool* sent);  // lock held
  void QueueControl(vistream::v1::ServerMessage message);    // lock held
  // The level `key` needs for `cell` (an object: 0 full, always 0 without levels; a cluster: its
  // chosen level, 0 when the cell did not choose it).
  uint32_t NeededLevel(CellId cell, uint32_t key) const;     // lock held
  // Whether the client holds what `cell` needs of `key` (ViewcellPvs.cluster_ids' rule): an
  // object at its level or finer, or the cluster the cell chose for it at the cluster's level or
  // finer; a chosen cluster at its level or finer, or all the cell's objects it stands for.
  bool Satisfied(CellId cell, uint32_t key) const;           // lock held
  // Whether the client can draw what `cell` needs of `key` at some level (else a stall).
  bool Drawable(CellId cell, uint32_t key) const;            // lock held
  // The level the client holds `key` at (0 also when it does not hold it).
  uint32_t HeldLevel(uint32_t key) const;                    // lock held
  // What `key` at `level` takes decoded (RawMeshBytes: the memory budget's unit).
  uint64_t RawBytesOf(uint32_t key, uint32_t level) const;   // lock held
  // Whether `cell`'s PVS list and geometry have been handed out (emitted, nothing pending).
  bool Served(CellId cell) const;                            // lock held
  // Whether `cell`'s list went out and some object on it is not held at any level: a client
  // there stalls (a coarser level held is drawn: a coarse frame, not a stall).
  bool LacksGeometry(CellId cell) const;                     // lock held
  // The link budget (issue 45): whether the client's cell or the next it reaches lacks geometry.
  bool Urgent() const;                                       // lock held
  // While Urgent(): the next object of wanted_[0] or wanted_[1] the client holds at no level.
  std::optional<vistream::v1::ServerMessage> NextMissingObject();  // lock held
  // Reports crossings whose new cells are all served now (SessionSeams::crossing_served).
  void NoteServedCrossings(double now);                      // lock held

  const uint64_t id_;
  const SceneDirectory* const directory_;  // null: the scene is fixed at Create
  // Set at Create, or by Hello from directory_ (under mu_, before any reader needs them: every
  // other message is refused before Hello).
  ServedScene* scene_;
  const SessionLimits limits_;
  EventLog* const log_;
  std::function<void()> wake_;
  const SessionSeams seams_;
  PvsSource* pvs_;
  TaskRunner* masks_;
  const double start_s_;
  double epsilon_size_m_;  // limits_' for a fixed scene; the picked scene's catalog value otherwise

  mutable std::mutex mu_;
  bool ended_ = false;
  bool hello_ = false;
  absl::Status failure_;
  uint64_t memory_budget_ = 0;  // 0: unlimited
  std::optional<CellId> current_;
  glm::dvec3 position_{0.0}, velocity_{0.0};
  glm::dvec3 ranked_velocity_{0.0};  // the velocity wanted_ was ordered for
  double last_pose_s_ = 0.0;
  double pose_tokens_ = 0.0;
  uint64_t poses_ = 0;

  std::vector<CellId> wanted_;                 // current first, then by deadline
  std::map<CellId, CellPvsPtr> received_;      // PVSs of wanted cells that arrived
  std::set<CellId> requested_;                 // asked of the scheduler, not arrived
  std::set<CellId> emitted_;                   // PVS message queued or sent
  // Geometry is named by keys: an object by its id, a cluster level (issue 45) by kClusterKey | id.
  static constexpr uint32_t kClusterKey = uint32_t{1} << 31;
  std::map<CellId, std::deque<uint32_t>> pending_geometry_;  // per wanted cell, keys not yet sent
  std::unordered_set<uint32_t> sent_;          // keys the client holds (sent or held on resume), any level
  // Hello.pvs_deltas: lists go as differences from the one sent before (proto/pvs_delta.h).
  bool pvs_deltas_ = false;
  std::optional<proto::PvsList> previous_list_;  // the last list handed to the transport
  // Levels of detail (Hello.levels; issue 45): on when the client asked and the scene has them.
  bool levels_on_ = false;
  bool clusters_on_ = false;  // LevelRequest.clusters, and the scene has clusters
  scenes::ScreenSpec screen_;
  double tau_px_ = 0.0;
  std::unordered_map<uint32_t, uint32_t> held_level_;  // level of each held key (absent: an object's full mesh)
  // Per received cell: what its list asks of each level (scenes/level_choice.h ChooseLevels).
  struct CellLevels {
    std::vector<uint32_t> objects;                           // each PVS object's own level
    std::vector<std::pair<uint32_t, uint32_t>> clusters;     // chosen (cluster, level), ascending
    std::unordered_map<uint32_t, uint32_t> cover;            // PVS object -> the chosen cluster standing for it
    std::unordered_map<uint32_t, std::vector<uint32_t>> members;  // chosen cluster -> the PVS objects it stands for
  };
  std::map<CellId, CellLevels> cell_levels_;
  uint64_t held_bytes_ = 0;                    // decoded bytes of sent_
  int64_t credit_ = 0;
  // The link budget (issue 45): while Urgent(), ε-masks (with the objects they pull) take at
  // most kUrgentMaskShare of the bytes sent; geometry sent then earns them tokens, a mask spends
  // them (it goes while they are not negative); at most 64 KiB are banked. Reset when nothing
  // is urgent.
  static constexpr size_t kUrgentCells = 2;  // the client's cell and the next it reaches (wanted_[0], [1])
  static constexpr double kUrgentMaskShare = 0.25;
  static constexpr double kMaxMaskTokens = 65536.0;
  double mask_tokens_ = 0.0;

  // An Evict of held objects needed later than wanted_[rank] (or not at all), freeing enough
  // of the memory budget for `bytes` more; none when that cannot be done. Caller holds mu_.
  std::optional<vistream::v1::ServerMessage> MakeRoom(size_t bytes, size_t rank);
  // The client no longer holds `objects` (as the server counts): the Evict that tells it so,
  // logged with `reason`. Caller holds mu_.
  vistream::v1::ServerMessage Forget(std::vector<uint32_t> objects, const char* reason);
  struct Control {
    vistream::v1::ServerMessage message;
    size_t bytes;
    std::optional<CellId> cell;  // a PVS list: dropped if the cell stops being wanted
  };
  std::deque<Control> control_;
  size_t control_bytes_ = 0;
  struct Crossing {
    double at_s;
    std::vector<CellId> cells;  // newly adjacent, not yet served
  };
  std::deque<Crossing> crossings_;  // with SessionSeams::crossing_served only

  // ε-masks along the path: the chain, its queues, the masks' place in the send order.
  MaskPlanner planner_;

  vistream::v1::SessionStats stats_;
};

}  // namespace vistream::server
