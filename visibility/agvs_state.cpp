#include "visibility/agvs.h"
#include "visibility/agvs_internal.h"

// Saving and resuming the sampler's state.

namespace vistream::visibility {

// --- Saved state ---

namespace {
constexpr char kStateMagic[8] = {'V', 'S', 'A', 'G', 'V', 'S', '0', '1'};
}  // namespace

std::string GlobalSampler::SaveState() const {
  const Impl& m = *impl_;
  ByteWriter w;
  w.PutRaw(std::string_view(kStateMagic, 8));
  w.Put<uint64_t>(pvs_.object_count());
  w.Put<uint64_t>(pvs_.cell_count());
  w.Put(grid_.cell_size());
  w.Put(grid_.corner().x);
  w.Put(grid_.corner().y);
  w.Put<uint32_t>(static_cast<uint32_t>(options_.strategy));
  w.Put(options_.seed);
  w.Put(stats_.batches);
  w.Put(stats_.samples);
  w.Put(stats_.rays);
  w.Put(stats_.discarded_samples);
  w.Put(stats_.seconds);
  for (const DistributionStats& d : stats_.distributions) {
    w.Put(d.samples);
    w.Put(d.rays);
    w.Put(d.contribution);
    w.Put(d.probability);
  }
  for (size_t k = 0; k < kDistributionCount; ++k) {
    w.Put(m.ema_contribution[k]);
    w.Put(m.ema_cost[k]);
  }
  w.PutVarint(m.estimator_window.size());
  for (const auto& [n, nc] : m.estimator_window) {
    w.PutVarint(n);
    w.PutVarint(nc);
  }
  for (uint64_t n : m.cell_samples) w.PutVarint(n);
  for (uint64_t n : m.object_hits) w.PutVarint(n);
  w.PutVarint(m.buffer.size());
  m.buffer.ForEach([&](const Candidate& c, uint32_t mutations) {
    w.Put(c.from);
    w.Put(c.to);
    w.Put(c.r_from);
    w.Put(c.r_to);
    w.Put(c.object);
    w.Put(mutations);
  });
  EncodeSets(pvs_, &w);
  return std::move(w.bytes());
}

absl::Status GlobalSampler::LoadState(std::string_view bytes, const std::string& where) {
  Impl& m = *impl_;
  ByteReader r(bytes, where);
  if (absl::Status st = r.ExpectMagic(std::string_view(kStateMagic, sizeof(kStateMagic)), "sampling state"); !st.ok()) {
    return st;
  }
  uint64_t objects = 0, cells = 0;
  double size = 0, cx = 0, cy = 0;
  uint32_t strategy = 0;
  uint64_t seed = 0;
  absl::Status st = r.Get(&objects, "the object count");
  if (st.ok()) st = r.Get(&cells, "the cell count");
  if (st.ok()) st = r.Get(&size, "the cell size");
  if (st.ok()) st = r.Get(&cx, "the corner x");
  if (st.ok()) st = r.Get(&cy, "the corner y");
  if (st.ok()) st = r.Get(&strategy, "the strategy");
  if (st.ok()) st = r.Get(&seed, "the seed");
  if (!st.ok()) return st;
  if (objects != pvs_.object_count() || cells != pvs_.cell_count() || size != grid_.cell_size() ||
      cx != grid_.corner().x || cy != grid_.corner().y) {
    return r.Error(absl::StrCat("made for ", objects, " objects and ", cells, " cells of ", size,
                                " m; this scene has ", pvs_.object_count(), " objects and ", pvs_.cell_count(),
                                " cells of ", grid_.cell_size(), " m"));
  }
  if (strategy != static_cast<uint32_t>(options_.strategy) || seed != options_.seed) {
    return r.Error(absl::StrCat("made with strategy ", strategy, " and seed ", seed, "; resume with the same ones"));
  }
  AgvsStats s;
  st = r.Get(&s.batches, "batches");
  if (st.ok()) st = r.Get(&s.samples, "samples");
  if (st.ok()) st = r.Get(&s.rays, "rays");
  if (st.ok()) st = r.Get(&s.discarded_samples, "discarded samples");
  if (st.ok()) st = r.Get(&s.seconds, "seconds");
  for (DistributionStats& d : s.distributions) {
    if (st.ok()) st = r.Get(&d.samples, "distribution samples");
    if (st.ok()) st = r.Get(&d.rays, "distribution rays");
    if (st.ok()) st = r.Get(&d.contribution, "distribution contribution");
    if (st.ok()) st = r.Get(&d.probability, "distribution probability");
  }
  std::array<double, kDistributionCount> ema_c{}, ema_cost{};
  for (size_t k = 0; k < kDistributionCount && st.ok(); ++k) {
    st = r.Get(&ema_c[k], "mixture weights");
    if (st.ok()) st = r.Get(&ema_cost[k], "mixture costs");
  }
  uint64_t window = 0;
  if (st.ok()) st = r.GetVarint(&window, "the estimator window");
  if (!st.ok()) return st;
  if (window > r.remaining()) return r.Error("estimator window longer than the file");
  std::vector<std::pair<uint64_t, uint64_t>> est(window);
  for (auto& [n, nc] : est) {
    if (st.ok()) st = r.GetVarint(&n, "estimator rays");
    if (st.ok()) st = r.GetVarint(&nc, "estimator hits");
  }
  std::vector<uint64_t> cell_samples(cells), object_hits(objects);
  for (uint64_t& n : cell_samples) {
    if (st.ok()) st = r.GetVarint(&n, "cell sample counts");
  }
  for (uint64_t& n : object_hits) {
    if (st.ok()) st = r.GetVarint(&n, "object hit counts");
  }
  uint64_t candidates = 0;
  if (st.ok()) st = r.GetVarint(&candidates, "the candidate count");
  if (!st.ok()) return st;
  if (candidates > r.remaining()) return r.Error("more mutation candidates than bytes left");
  MutationBuffer buffer(options_.mutation_buffer);
  for (uint64_t i = 0; i < candidates && st.ok(); ++i) {
    Candidate c;
    st = r.Get(&c.from, "a candidate");
    if (st.ok()) st = r.Get(&c.to, "a candidate");
    if (st.ok()) st = r.Get(&c.r_from, "a candidate");
    if (st.ok()) st = r.Get(&c.r_to, "a candidate");
    if (st.ok()) st = r.Get(&c.object, "a candidate");
    if (st.ok()) st = r.Get(&c.mutations, "a candidate");
    if (st.ok() && c.object >= objects) st = r.Error(absl::StrCat("candidate ", i, " names object ", c.object));
    const double len = glm::length(c.to - c.from);
    if (st.ok() && !(len > 1e-6 && std::isfinite(len) && c.r_from >= 0 && c.r_to >= 0 && std::isfinite(c.r_from) &&
                     std::isfinite(c.r_to))) {
      st = r.Error(absl::StrCat("candidate ", i, " is not a finite segment"));
    }
    if (st.ok()) buffer.Add(c);
  }
  if (!st.ok()) return st;
  GlobalPvs sets(cells, objects);
  if (st = DecodeSets(&r, &sets); !st.ok()) return st;
  if (!r.AtEnd()) return r.Error(absl::StrCat(r.remaining(), " bytes follow the sets"));
  s.entries = sets.TotalEntries();
  s.mutation_candidates = buffer.size();
  pvs_ = std::move(sets);
  stats_ = s;
  m.ema_contribution = ema_c;
  m.ema_cost = ema_cost;
  m.estimator_window = std::move(est);
  m.cell_samples = std::move(cell_samples);
  m.object_hits = std::move(object_hits);
  m.buffer = std::move(buffer);
  m.witnesses.clear();
  UpdateEstimate(m, options_, &stats_);
  return absl::OkStatus();
}

}  // namespace vistream::visibility
