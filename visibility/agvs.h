#pragma once
// Adaptive global visibility sampling (Bittner, Mattausch, Wonka, Havran, Wimmer 2009): the
// PVS of every viewcell of a grid at once, progressively, by casting rays with Embree.
//
// A sample is a ray cast both ways from a point: the free segment between the two hits sees
// both hit objects, so they are added to every viewcell the segment pierces (a DDA over the
// grid). Rays that cannot add anything are not cast (a line missing the viewcells' slab, or
// the far ray when the one towards the slab stops before it). Sampled sets only ever grow
// towards the exact visible sets, never past them
// (aggressive): AGVS ⊆ exact ⊆ any conservative set. That makes this the oracle the
// conservative algorithms are checked against.
//
// Samples come from five distributions mixed by their contribution per unit of cost (view
// space-direction, object-direction, two-point, two-point mutation, silhouette mutation);
// the mutations start from earlier contributing samples kept in a buffer ordered by how often
// each was mutated. The estimated pixel error (the share of uniform camera rays that still
// find something new) is the termination criterion.
//
// Determinism: a batch is cut into fixed chunks, each with its own random stream, and every
// sample is evaluated against the sets as they stood at the start of the batch, so results
// depend on the seed alone, not on the thread count or timing. For the same reason the
// mixture weighs a distribution's cost in rays cast, not in seconds.
//
// Robustness (the paper's section 8): a sample whose ray hits the back of a triangle started
// inside a closed object or slipped through a crack between triangles; it is discarded.
// Embree runs in robust mode too.

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec3.hpp>

#include "scenes/mesh.h"
#include "scenes/progress.h"
#include "scenes/scene.h"
#include "visibility/global_pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::visibility {

// agvs: the adaptive mixture of all five distributions; sgvs: view space-direction only
// (global, not adaptive); ref: a random cell, a random ray from it, the hit object added to
// that cell only (the paper's per-viewcell reference).
enum class SamplingStrategy { kAgvs, kSgvs, kRef };
absl::StatusOr<SamplingStrategy> StrategyFromName(std::string_view name);
const char* StrategyName(SamplingStrategy strategy);

enum class Distribution : uint8_t {
  kViewSpaceDirection,
  kObjectDirection,
  kTwoPoint,
  kTwoPointMutation,
  kSilhouetteMutation,
  kRef,
};
inline constexpr int kDistributionCount = 6;
const char* DistributionName(Distribution d);

struct AgvsOptions {
  SamplingStrategy strategy = SamplingStrategy::kAgvs;
  uint64_t seed = 1;
  unsigned threads = 0;                // 0: one per core; results do not depend on it
  uint32_t batch_samples = 1u << 16;   // samples per batch (rounded up to whole chunks)
  uint32_t mutation_buffer = 1u << 20; // mutation candidates kept at most
  double min_probability = 0.05;       // floor of each distribution's share in the mixture
  double depth_discontinuity_k = 3.0;  // the paper's k for the silhouette mutation
  double resolution = 1024.0 * 1024.0; // camera rays of the pixel-error estimator
  bool backface_rule = true;           // discard samples that hit a back face
  // Embree's robust traversal (watertight at shared edges), besides the back-face rule; costs
  // a few percent of the ray rate on city1.
  bool robust_traversal = true;
  // Objects of more triangles than this search silhouettes with discovery rays (the paper's
  // bisection, logarithmic in the object's size) instead of exactly (linear in the triangles
  // the search plane cuts): a 50,000-node ring keeps the rate of a town.
  uint32_t discovery_triangles = 2048;
};

struct DistributionStats {
  uint64_t samples = 0;
  uint64_t rays = 0;          // cost in rays: Embree rays, and one per silhouette search
  uint64_t contribution = 0;  // new (cell, object) entries found, against the batch's start
  double probability = 0.0;   // share of the last batch
};

struct AgvsStats {
  uint64_t batches = 0;
  uint64_t samples = 0;
  uint64_t rays = 0;               // Embree rays cast
  uint64_t discarded_samples = 0;  // hit a back face
  uint64_t entries = 0;            // PVS entries over all cells
  double seconds = 0.0;            // sampling wall time over every Run and RunBatch
  std::array<DistributionStats, kDistributionCount> distributions{};
  double estimated_pixel_error = 0.0;  // pixels of a `resolution` camera
  bool estimate_settled = false;       // the window held enough rays for P = 0.9, k = 0.5
  uint64_t estimate_rays = 0;          // camera rays in the estimator's window
  size_t mutation_candidates = 0;
};

// The free segment that put an object into a cell's set: from a point inside the cell to the
// point where the object was hit (scene-local metres).
struct Witness {
  glm::dvec3 from{0.0}, to{0.0};
};

// A triangle seen from a box: the ray from `from` (inside the box) hit triangle `triangle` (its
// index in the object's mesh) of `object` at `to` (scene-local metres).
struct BoxHit {
  scenes::ObjectId object = 0;
  uint32_t triangle = 0;
  glm::dvec3 from{0.0}, to{0.0};
};

// The paper's section 5: grow each set by objects that are likely visible given how densely
// its cell has been sampled. Both off: the sampled sets themselves.
struct FilterOptions {
  bool object_space = false;
  bool view_space = false;
  double k = 1.0;                 // scales the object-space extension
  double view_similarity = 0.5;   // neighbours merged when |A ∩ B| / |A ∪ B| is at least this
};

struct RunLimits {
  double seconds = 0.0;      // stop after this much sampling time (0: no limit)
  double pixel_error = 0.0;  // stop when the settled estimate is at most this (0: no limit)
  uint64_t samples = 0;      // stop after this many samples in all (0: no limit)
};

class GlobalSampler {
 public:
  // Copies the geometry of `scene` (frame-relative) into an Embree scene. Errors: an empty
  // grid, a scene with no triangles, Embree failing to start.
  static absl::StatusOr<std::unique_ptr<GlobalSampler>> Create(const scenes::Scene& scene, const ViewcellGrid& grid,
                                                               const AgvsOptions& options);
  ~GlobalSampler();
  GlobalSampler(const GlobalSampler&) = delete;
  GlobalSampler& operator=(const GlobalSampler&) = delete;

  // One batch of options().batch_samples samples.
  void RunBatch();
  // Batches until a limit is met (at least one limit must be set) or run's cancel flag is set.
  // Reports progress to run's sink as task `label`, with samples/s and the estimated pixel
  // error as its detail.
  void Run(const RunLimits& limits, const scenes::RunControl& run = {}, const std::string& label = "agvs");

  const GlobalPvs& pvs() const { return pvs_; }
  const AgvsStats& stats() const { return stats_; }
  const ViewcellGrid& grid() const { return grid_; }
  const AgvsOptions& options() const { return options_; }
  // Objects the sampler knows: the scene's, then inserted ones (deleted ids stay taken).
  size_t object_count() const { return pvs_.object_count(); }

  // Keeps, for the listed cells, the first segment that added each object (for reports).
  void RecordWitnesses(std::span<const CellId> cells);
  std::optional<Witness> WitnessOf(CellId cell, scenes::ObjectId object) const;

  // Triangle-level sampled visibility from a small box (the ε-superset's oracle): `rays` rays
  // from uniform points of `box`, half in uniform directions, half towards uniform points on
  // uniform objects, each reporting the front face it hits first. Deterministic for a seed;
  // thread-safe with other const calls.
  std::vector<BoxHit> SampleFromBox(const scenes::Aabb& box, size_t rays, uint64_t seed) const;

  // The cell's set grown by the filters, ascending.
  std::vector<scenes::ObjectId> Filtered(CellId cell, const FilterOptions& filter) const;
  // Every cell's set through Filtered (the sets themselves when both filters are off).
  GlobalPvs FilteredAll(const FilterOptions& filter) const;

  // Dynamic edits (section 6). Insert adds an object with the next id and removes from every
  // set each object it may hide from that cell (those meeting its penumbra); Delete removes
  // the object from every set and from the ray tracer; Move translates it (scene-local
  // metres) and updates like a delete followed by an insert. Sampling then restores whatever
  // is still visible. Errors: an unknown or deleted id, a mesh without triangles or with
  // non-finite positions.
  absl::StatusOr<scenes::ObjectId> InsertObject(const scenes::Mesh& mesh);
  absl::Status DeleteObject(scenes::ObjectId id);
  absl::Status MoveObject(scenes::ObjectId id, const glm::dvec3& offset);

  // The whole state (sets, counters, mixture, estimator window, mutation buffer), to resume a
  // computation later with the same scene, grid and options. `where` names the source in
  // errors; loading checks that it matches this sampler's scene and grid.
  std::string SaveState() const;
  absl::Status LoadState(std::string_view bytes, const std::string& where);

  struct Impl;  // internal: the ray tracer, objects, mutation buffer and counters

 private:
  GlobalSampler(const ViewcellGrid& grid, const AgvsOptions& options);

  ViewcellGrid grid_;
  AgvsOptions options_;
  GlobalPvs pvs_;
  AgvsStats stats_;
  std::unique_ptr<Impl> impl_;
};

// An object may hide something from `cell` only if it meets the convex hull of the cell and
// that thing: whether box `blocker` meets hull(`cell` ∪ `target`), exactly.
bool BoxMeetsShaft(const scenes::Aabb& cell, const scenes::Aabb& target, const scenes::Aabb& blocker);

// Triangles (`indices`, three per triangle) as Embree quads: two triangles (p, q, r), (p, r, s)
// in a row (a wall, two triangles of a roof's fan) are the quad (q, r, s, p), which Embree
// splits into exactly those two; any other triangle is a quad with its last corner repeated.
// Four indices per quad; `first` gets each quad's first triangle, `pair` whether it has a
// second (hit where u + v > 1).
struct EmbreeQuads {
  std::vector<uint32_t> indices, first;
  std::vector<bool> pair;
};
EmbreeQuads PairTriangles(std::span<const uint32_t> indices);

}  // namespace vistream::visibility
