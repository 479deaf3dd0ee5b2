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
  w.Put(static_cast<uint64_t>(pvs_.object_count()), static_cast<uint64_t>(pvs_.cell_count()), grid_.cell_size(),
        grid_.corner().x, grid_.corner().y, static_cast<uint32_t>(options_.strategy), options_.seed);
  w.Put(stats_.batches, stats_.samples, stats_.rays, stats_.discarded_samples, stats_.seconds);
  for (const DistributionStats& d : stats_.distributions) w.Put(d.samples, d.rays, d.contribution, d.probability);
  for (size_t k = 0; k < kDistributionCount; ++k) w.Put(m.ema_contribution[k], m.ema_cost[k]);
  w.PutVarint(m.estimator_window.size());
  for (const auto& [n, nc] : m.estimator_window) {
    w.PutVarint(n);
    w.PutVarint(nc);
  }
  for (uint64_t n : m.cell_samples) w.PutVarint(n);
  for (uint64_t n : m.object_hits) w.PutVarint(n);
  w.PutVarint(m.buffer.size());
  m.buffer.ForEach([&](const Candidate& c, uint32_t mutations) {
    w.Put(c.from, c.to, c.r_from, c.r_to, c.object, mutations);
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
  absl::Status st = r.Get(&objects, "the object count", &cells, "the cell count", &size, "the cell size", &cx,
                          "the corner x", &cy, "the corner y", &strategy, "the strategy", &seed, "the seed");
  if (!st.ok()) return st;
  if (objects != pvs_.object_count() || cells != pvs_.cell_count() || size != grid_.cell_size() ||
      cx != grid_.corner().x || cy != grid_.corner().y) {
    return r.Error(absl::StrCat("made for ", objects, " objects and ", cells, " cells of ", size, " m from (", cx, ", ",
                                cy, "); this scene has ", pvs_.object_count(), " objects and ", pvs_.cell_count(),
                                " cells of ", grid_.cell_size(), " m from (", grid_.corner().x, ", ",
                                grid_.corner().y, ")"));
  }
  if (strategy != static_cast<uint32_t>(options_.strategy) || seed != options_.seed) {
    const std::string made = strategy <= static_cast<uint32_t>(SamplingStrategy::kRef)
                                 ? StrategyName(static_cast<SamplingStrategy>(strategy))
                                 : absl::StrCat("number ", strategy);
    return r.Error(absl::StrCat("made with strategy ", made, " and seed ", seed, "; this run has strategy ",
                                StrategyName(options_.strategy), " and seed ", options_.seed,
                                ": resume with the same ones"));
  }
  AgvsStats s;
  st = r.Get(&s.batches, "batches", &s.samples, "samples", &s.rays, "rays", &s.discarded_samples,
             "discarded samples", &s.seconds, "seconds");
  for (DistributionStats& d : s.distributions) {
    if (st.ok()) {
      st = r.Get(&d.samples, "distribution samples", &d.rays, "distribution rays", &d.contribution,
                 "distribution contribution", &d.probability, "distribution probability");
    }
  }
  std::array<double, kDistributionCount> ema_c{}, ema_cost{};
  for (size_t k = 0; k < kDistributionCount && st.ok(); ++k) {
    st = r.Get(&ema_c[k], "mixture weights", &ema_cost[k], "mixture costs");
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
    st = r.Get(&c.from, "a candidate", &c.to, "a candidate", &c.r_from, "a candidate", &c.r_to, "a candidate",
               &c.object, "a candidate", &c.mutations, "a candidate");
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
