#pragma once
// The discrete-event simulator behind `vistream simulate` (DESIGN.md "Simulation" and
// "Measures"; the papers' claim that a walking client never reaches a viewcell before its PVS
// has arrived). It runs the server's own Session, with its scheduling policy, PVS cache and
// meshoptimizer geometry, against the client model (client/client_model.h: Hello, credit, pose
// cadence; client/mask_holdings.h; client/cell_completion.h) over the emulated link
// (server/link_model.h), on simulated time (simulation/simulated_workers.h): a PVS is computed
// with the real PvsComputer when a simulated worker starts it, and completes the measured wall
// time later on the simulated clock. Only the link and the clocks are modelled here.
//
// What is modelled is what the scene's catalog entry declares (simulation.link, .client) and
// nothing else: an entry without a link gets an ideal one; without client.frame_ms frames are
// counted at 60 Hz but geometry needs no upload frame.
//
// ε-masks (scheme pvs+eps): the session plans and sends them as the server does (its chain of
// neighbourhoods, computed on one simulated mask worker that runs only while a PVS worker is
// free); the client holds them, grants their bytes back as credit and draws one by the client
// model's rules (client/mask_holdings.h), the same code the real client runs.
//
// Units: seconds of simulated time (0 = the client opens its session), metres in the scene's
// local frame (z up), bytes.

#include <array>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <absl/status/statusor.h>

#include "client/cell_margins.h"
#include "scenes/catalog.h"
#include "scenes/progress.h"
#include "server/event_log.h"
#include "server/link_model.h"
#include "server/served_scene.h"
#include "simulation/simulated_workers.h"

namespace vistream::simulation {

using server::EventLog;
using server::LinkParams;
using server::ServedScene;

// What the server streams for a viewcell.
enum class Scheme {
  kPvsEps,  // "pvs+eps": the viewcell PVS, narrowed by ε-masks along the walk (the server's)
  kPvs,     // "pvs": the viewcell PVS without ε-masks
  kRadius,  // "radius": no visibility: every object within R metres of the cell
  kPlain,   // "plain": the paper's: no shared cache, neighbours in a fixed grid order
};
// "pvs+eps", "pvs", "radius", "plain".
std::string_view SchemeName(Scheme scheme);
// The inverse; INVALID_ARGUMENT naming the text and the schemes otherwise.
absl::StatusOr<Scheme> ParseScheme(std::string_view text);

struct SimulationOptions {
  std::string path;       // the walk's name; empty: the entry's first walk
  double speed_mps = 0.0; // walking speed; 0: the walk's own
  // The link (the entry's declared one, or --link over it); none: an ideal link.
  std::optional<scenes::LinkSpec> link;
  // k > 0: a real run replayed k times faster, as the end-to-end comparison runs it: speed x k
  // and the link's LinkParamsFrom(link, k); compute times, poses (10 Hz) and frames unscaled.
  double time_scale = 1.0;
  Scheme scheme = Scheme::kPvsEps;
  uint64_t seed = 1;                     // the link models' draws (uplink: seed, downlink: seed + 1)
  unsigned workers = 0;                  // simulated PVS workers; 0: this machine's cores
  size_t cache_bytes = size_t{256} << 20;  // the shared PVS cache (vistream-server's --cache-mb)
  // Tests: charge this many seconds per PVS (and per ε-mask) instead of the measured time,
  // for results that do not depend on the machine.
  std::optional<double> fixed_compute_s;
  double radius_m = 0.0;         // the radius scheme's R; 0: NoHoleRadius of the walk
  EventLog* log = nullptr;       // the simulator's events (and the session's); may be null
  std::shared_ptr<PvsMemo> memo; // shared by the runs of one process; null: a fresh one
  double startup_limit_s = 3600.0;  // simulated seconds the first viewcell may take
  bool count_triangles = true;   // false: skip the per-frame culling (speed search probes)
  // Levels of detail (issue 45): the client's screen error tau in pixels on a 1280x720 viewport
  // with a 60 degree vertical field of view; 0: off. The scene must have levels
  // (ServedSceneOptions::make_levels, or its own).
  double lod_tau_px = 0.0;
  // With levels: the client draws cluster levels (HelloSettings::clusters); the scene's levels
  // must have clusters for any to be sent. Off by default: on london they save 1% of the bytes
  // and cost pvs+eps 2.6% of its stall-free speed against pvs on the london town (issue 45).
  bool lod_clusters = false;
};

struct SimulationResult {
  // Frames drawn inside a viewcell whose PVS geometry had not all arrived, at the declared frame
  // time (undeclared: 60 Hz, for counting only); their time; the cells they were in.
  uint64_t stalls = 0;
  uint64_t stalled_cells = 0;
  double stall_s = 0.0;
  // Over the cells entered after the first: entered_s - complete_s (0 when none was entered).
  double min_margin_s = 0.0, mean_margin_s = 0.0;
  uint64_t bytes = 0;           // downlink bytes on the wire (server/link_model.h WireBytes)
  uint64_t uplink_bytes = 0;
  uint64_t geometry_bytes = 0;  // encoded geometry received
  uint64_t objects_received = 0;  // geometry messages (an object evicted and needed again comes again)
  uint64_t distinct_objects = 0;  // objects received at least once
  double mean_triangles_drawn = 0.0;  // per walking frame, after view-frustum culling
  uint64_t max_triangles_drawn = 0;
  uint64_t scene_triangles = 0;
  uint64_t frames = 0;
  // Simulated PVS compute seconds of the jobs started from one crossing to the next (and from
  // the first pose to the first crossing), one entry per crossing.
  std::vector<double> compute_s_per_crossing;
  // Every viewcell entered while walking (client/cell_margins.h, as the real client records
  // them; a cell entered twice has two), the first cell's first (start: the walk waited for it).
  // Complete: its PVS list and every object in it had arrived (and been uploaded at a frame,
  // with a declared frame time); the exit time when it never was.
  std::vector<client::CellEntry> cells;
  uint64_t crossings = 0;
  uint64_t pvs_computed = 0;     // jobs the simulated scheduler ran (paid for)
  uint64_t pvs_cache_hits = 0;
  uint64_t masks = 0;            // ε-masks received
  // ε-masks (scheme pvs+eps; issue 34). Every walking frame is drawn one of three ways, as the
  // client draws it: *masked* (the eye inside the box of a held mask whose objects have all
  // arrived and been uploaded: that mask's triangles, the mask with the fewest when several),
  // else the viewcell's PVS when it is complete, else a *hole* (what is held). A hole frame is
  // also a stall, so hole_frames <= stalls; a masked frame may be a stall too. Counted on every
  // frame.
  uint64_t frames_masked = 0;
  uint64_t hole_frames = 0;
  // Frames not masked whose eye was inside a held mask's box all the same (its objects had not
  // all arrived): misses of ε-first geometry rather than of the chain of neighbourhoods.
  uint64_t frames_in_unready_mask = 0;
  uint64_t mask_bytes = 0;       // EpsilonMask.triangles bytes received (charged to the credit)
  uint64_t list_bytes = 0;       // ViewcellPvs messages received (serialized; whole or differences)
  uint64_t messages = 0;         // server messages received (each costs its framing on the wire)
  uint64_t masks_used = 0;       // masks drawn on at least one frame
  uint64_t masks_computed = 0;   // ε-mask computations run by the simulated mask worker
  uint64_t masks_dropped = 0;    // neighbourhoods the session gave up before their mask was sent
  double mask_compute_s = 0.0;   // simulated seconds the mask worker spent computing
  // Per sampled frame (10 Hz), triangles drawn after view-frustum culling: with masks as drawn
  // (mean_triangles_drawn), and what the PVS-only client would have drawn on the same frames:
  // the viewcell PVS, or on a hole frame (and any stall) what is held. Equal for every scheme
  // but pvs+eps.
  double mean_triangles_without_masks = 0.0;
  // mean_triangles_drawn split by the distance from the eye to each drawn object's box, metres:
  // bands from kTriangleBandsM[i] up to the next (the last unbounded). Where a frame's triangles
  // come from: what levels of detail could still save at a screen error (issue 45).
  static constexpr std::array<double, 4> kTriangleBandsM{0.0, 300.0, 900.0, 2000.0};
  std::array<double, 4> mean_triangles_by_distance{};
  struct TriangleSample {
    double t_s = 0.0;        // since the walk started
    double along_m = 0.0;    // metres along the walk
    uint64_t triangles = 0;  // drawn
    uint64_t triangles_without_masks = 0;
    bool masked = false;
    bool hole = false;
  };
  std::vector<TriangleSample> triangle_samples;  // empty when count_triangles is false
  // Levels of detail: frames drawn in a complete viewcell while an object of its PVS was held at
  // a coarser level than the cell's list asks (the finer one on its way), and geometry messages
  // that carried a level coarser than full.
  uint64_t coarse_frames = 0;
  uint64_t level_objects_received = 0;
  uint64_t cluster_levels_received = 0;  // ClusterGeometry messages
  double lod_tau_px = 0.0;
  uint64_t jitter_draws = 0;     // messages delayed by a jitter draw > 0
  uint64_t lost_segments = 0;
  double radius_m = 0.0;         // the radius scheme's R
  double path_m = 0.0, walk_s = 0.0, sim_s = 0.0, startup_s = 0.0;
  double speed_mps = 0.0;
  double frame_s = 0.0;
  bool frame_declared = false;
  LinkParams link;               // as modelled (ideal when none was declared)
  bool link_declared = false;
};

// The entry's walk named `path` (empty: its first). NOT_FOUND naming the entry's walks;
// FAILED_PRECONDITION when it declares none.
absl::StatusOr<const scenes::WalkPath*> FindWalk(const scenes::CatalogEntry& entry, const std::string& path);

// Walks `options.path` through `scene` (prepared by ServedScene::Create from `entry`) with one
// simulated session. Errors: NOT_FOUND for an unknown walk (naming the entry's walks),
// INVALID_ARGUMENT for a speed that is not positive and finite or a bad option,
// DEADLINE_EXCEEDED when the first viewcell does not arrive within startup_limit_s, INTERNAL
// naming the status when the session ends, CANCELLED when run's flag is raised.
absl::StatusOr<SimulationResult> Simulate(ServedScene& scene, const scenes::CatalogEntry& entry,
                                          const SimulationOptions& options, const scenes::RunControl& run = {});

// The radius scheme's R for a walk: the largest distance (metres, between boxes) from a cell the
// walk passes through to an object of that cell's dual-ray-space PVS, so that streaming every
// object within R of a cell leaves no hole on this walk. Errors as Simulate's for the walk.
absl::StatusOr<double> NoHoleRadius(ServedScene& scene, const scenes::CatalogEntry& entry, const std::string& path,
                                    PvsMemo* memo);

// What a speed search looks for: the highest speed without a stall, or without a hole frame
// (SimulationResult::hole_frames; the same as a stall for every scheme but pvs+eps).
enum class SpeedCriterion { kNoStall, kNoHole };

struct SpeedSearch {
  // For kNoHole read "hole frames" for "stalls" throughout.
  double max_speed_mps = 0.0;  // the highest speed found with zero stalls (0: none in the bracket)
  double stall_speed_mps = 0.0;  // the lowest speed found with stalls (0: none in the bracket)
  SimulationResult at_max;     // the run at max_speed_mps (none found: the run at stall_speed_mps)
  std::vector<std::pair<double, uint64_t>> runs;  // (speed m/s, stalls) of every run, in order
};
// Bisection (on the logarithm of the speed) for the highest speed with zero stalls (or hole
// frames, `criterion`) in
// [lo_mps, hi_mps], until stall_speed <= max_speed * (1 + precision). If hi_mps has no stalls it
// is the answer (stall_speed_mps 0). The first lower end tried is options.speed_mps (0: the
// walk's own speed), and lo_mps only if that stalls (a slow walk costs the most to simulate:
// more frames, and ε-masks while the walker lingers); if lo_mps stalls too, max_speed_mps is 0.
// Stalls are assumed to appear once and stay as the speed grows (a run contradicting it is
// still listed in `runs`). Errors as Simulate's.
absl::StatusOr<SpeedSearch> FindMaxSpeed(ServedScene& scene, const scenes::CatalogEntry& entry,
                                         const SimulationOptions& options, double lo_mps, double hi_mps,
                                         double precision, const scenes::RunControl& run = {},
                                         SpeedCriterion criterion = SpeedCriterion::kNoStall);

}  // namespace vistream::simulation
