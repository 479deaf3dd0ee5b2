#include "visibility/agvs.h"
#include "visibility/agvs_internal.h"

// The global sampler: names, creation and the run loop with its pixel-error estimate.

namespace vistream::visibility {

const char* StrategyName(SamplingStrategy s) {
  switch (s) {
    case SamplingStrategy::kAgvs: return "agvs";
    case SamplingStrategy::kSgvs: return "sgvs";
    case SamplingStrategy::kRef: return "ref";
  }
  return "?";
}

absl::StatusOr<SamplingStrategy> StrategyFromName(std::string_view name) {
  for (SamplingStrategy s : {SamplingStrategy::kAgvs, SamplingStrategy::kSgvs, SamplingStrategy::kRef}) {
    if (name == StrategyName(s)) return s;
  }
  return absl::InvalidArgumentError(absl::StrCat("unknown sampling strategy '", std::string(name), "' (agvs, sgvs or ref)"));
}

const char* DistributionName(Distribution d) {
  switch (d) {
    case Distribution::kViewSpaceDirection: return "view_space_direction";
    case Distribution::kObjectDirection: return "object_direction";
    case Distribution::kTwoPoint: return "two_point";
    case Distribution::kTwoPointMutation: return "two_point_mutation";
    case Distribution::kSilhouetteMutation: return "silhouette_mutation";
    case Distribution::kRef: return "ref";
  }
  return "?";
}

bool BoxMeetsShaft(const Aabb& a, const Aabb& b, const Aabb& c) {
  // hull(A ∪ B) is the union over t in [0, 1] of the boxes (1 - t) A + t B; each axis bounds t
  // by two linear inequalities.
  double lo = 0.0, hi = 1.0;
  auto need = [&](double f0, double f1) {  // f0 + t f1 <= 0
    if (f1 == 0.0) {
      if (f0 > 0.0) hi = -1.0;
      return;
    }
    const double t = -f0 / f1;
    if (f1 > 0.0) hi = std::min(hi, t);
    else lo = std::max(lo, t);
  };
  for (int k = 0; k < 3; ++k) {
    // (1 - t) a.min + t b.min <= c.max and (1 - t) a.max + t b.max >= c.min.
    need(a.min[k] - c.max[k], b.min[k] - a.min[k]);
    need(c.min[k] - a.max[k], a.max[k] - b.max[k]);
  }
  return lo <= hi;
}

EmbreeQuads PairTriangles(std::span<const uint32_t> indices) {
  EmbreeQuads q;
  const size_t triangles = indices.size() / 3;
  for (size_t t = 0; t < triangles;) {
    const uint32_t* a = &indices[3 * t];
    q.first.push_back(static_cast<uint32_t>(t));
    if (t + 1 < triangles && a[3] == a[0] && a[4] == a[2]) {
      q.indices.insert(q.indices.end(), {a[1], a[2], a[5], a[0]});
      q.pair.push_back(true);
      t += 2;
    } else {
      q.indices.insert(q.indices.end(), {a[0], a[1], a[2], a[2]});
      q.pair.push_back(false);
      t += 1;
    }
  }
  return q;
}

// --- The sampler's state beyond the header. ---

// --- GlobalSampler ---

namespace {
// Camera rays the weak law of large numbers asks for to tell a ray share e with P = 0.9,
// k = 0.5: N >= (1 - e) / (k² e (1 - P)).
double RaysToTell(double e) { return (1.0 - e) / (0.25 * e * 0.1); }

// The pixel-error estimate over the newest batches that hold enough camera rays to tell apart
// the share they show, or the target share when that is larger: a high error is told from a
// short window, one near the target needs a long one. Without enough rays in all batches
// together the estimate is over all of them and not settled.
}  // namespace

void agvs_detail::UpdateEstimate(const GlobalSampler::Impl& m, const AgvsOptions& options, AgvsStats* stats) {
  const double target_share = std::clamp(m.estimate_target_pixels / options.resolution, 1e-12, 0.5);
  uint64_t n = 0, nc = 0;
  bool settled = false;
  for (size_t b = m.estimator_window.size(); b-- > 0;) {
    n += m.estimator_window[b].first;
    nc += m.estimator_window[b].second;
    if (n == 0) continue;
    const double share = static_cast<double>(nc) / static_cast<double>(n);
    if (static_cast<double>(n) >= RaysToTell(std::max(share, target_share))) {
      settled = true;
      break;
    }
  }
  stats->estimated_pixel_error = n > 0 ? options.resolution * static_cast<double>(nc) / static_cast<double>(n) : 0.0;
  stats->estimate_settled = settled;
  stats->estimate_rays = n;
}

Mixture agvs_detail::PlanMixture(const GlobalSampler::Impl& m, const AgvsOptions& options) {
  Mixture mix;
  std::vector<Distribution>& available = mix.available;
  switch (options.strategy) {
    case SamplingStrategy::kRef: available = {Distribution::kRef}; break;
    case SamplingStrategy::kSgvs: available = {Distribution::kViewSpaceDirection}; break;
    case SamplingStrategy::kAgvs:
      available = {Distribution::kViewSpaceDirection, Distribution::kObjectDirection, Distribution::kTwoPoint};
      if (m.buffer.size() > 0) {
        available.push_back(Distribution::kTwoPointMutation);
        available.push_back(Distribution::kSilhouetteMutation);
      }
      break;
  }
  std::array<double, kDistributionCount>& share = mix.share;
  {
    double sum = 0.0;
    for (Distribution d : available) {
      const auto k = static_cast<size_t>(d);
      // Until a distribution has been tried, it gets the best weight seen.
      share[k] = m.ema_cost[k] > 0.0 ? m.ema_contribution[k] / m.ema_cost[k] : -1.0;
    }
    double best = 0.0;
    for (Distribution d : available) best = std::max(best, share[static_cast<size_t>(d)]);
    for (Distribution d : available) {
      double& w = share[static_cast<size_t>(d)];
      if (w < 0.0) w = best > 0.0 ? best : 1.0;
      sum += w;
    }
    for (Distribution d : available) {
      double& w = share[static_cast<size_t>(d)];
      w = sum > 0.0 ? w / sum : 1.0 / available.size();
    }
    // The floor keeps every distribution alive (the stationary ones make the whole progressive).
    const double floor = std::min(options.min_probability, 1.0 / available.size());
    sum = 0.0;
    for (Distribution d : available) sum += std::max(share[static_cast<size_t>(d)], floor);
    for (Distribution d : available) {
      double& w = share[static_cast<size_t>(d)];
      w = std::max(w, floor) / sum;
    }
  }
  const uint32_t chunks = (options.batch_samples + kChunk - 1) / kChunk;
  std::vector<uint32_t>& quota = mix.quota;
  quota.assign(kDistributionCount, 0);
  {
    uint32_t given = 0;
    std::vector<std::pair<double, size_t>> remainders;
    for (Distribution d : available) {
      const auto k = static_cast<size_t>(d);
      const double exact = share[k] * chunks;
      quota[k] = std::max<uint32_t>(1, static_cast<uint32_t>(exact));
      given += quota[k];
      remainders.emplace_back(exact - std::floor(exact), k);
    }
    std::sort(remainders.begin(), remainders.end(), [](auto& a, auto& b) {
      return a.first != b.first ? a.first > b.first : a.second < b.second;
    });
    for (size_t r = 0; given < chunks; r = (r + 1) % remainders.size(), ++given) ++quota[remainders[r].second];
  }
  return mix;
}

GlobalSampler::GlobalSampler(const ViewcellGrid& grid, const AgvsOptions& options)
    : grid_(grid), options_(options), impl_(std::make_unique<Impl>()) {}

GlobalSampler::~GlobalSampler() = default;

absl::StatusOr<std::unique_ptr<GlobalSampler>> GlobalSampler::Create(const scenes::Scene& scene,
                                                                    const ViewcellGrid& grid,
                                                                    const AgvsOptions& options) {
  if (grid.CellCount() == 0) return absl::InvalidArgumentError("global sampling over an empty viewcell grid");
  if (scene.TriangleCount() == 0) return absl::InvalidArgumentError("global sampling over a scene without triangles");
  if (options.batch_samples == 0) return absl::InvalidArgumentError("global sampling: batch_samples must be positive");
  // The sets are one bit per cell and object: refuse what this machine cannot hold rather
  // than die allocating it (a viewcell of a centimetre over a town).
  const double set_bytes = static_cast<double>(grid.CellCount()) * 8.0 *
                           static_cast<double>((scene.objects.size() + 63) / 64);
  const double memory = static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGESIZE));
  if (memory > 0 && set_bytes > 0.5 * memory) {
    return absl::ResourceExhaustedError(absl::StrFormat(
        "global sampling: the sets of %d x %d viewcells and %d objects take %.1f GiB, over half of this "
        "machine's %.1f GiB: choose larger viewcells",
        grid.nx(), grid.ny(), scene.objects.size(), set_bytes / (1 << 30), memory / (1 << 30)));
  }
  std::unique_ptr<GlobalSampler> s(new GlobalSampler(grid, options));
  Impl& m = *s->impl_;
  // The frame's origin is the grid's corner, a multiple of the cell size: moving the scene by
  // whole cells moves the frame with it and leaves every frame-relative float as it was.
  m.frame = glm::dvec3(grid.corner(), 0.0);
  m.view_space = grid.Bounds();
  m.view_space.min -= m.frame;
  m.view_space.max -= m.frame;
  m.cell_radius = BoxRadius(grid.CellBox(CellId{0}));
  if (!scene.terrain.empty()) m.terrain = std::make_shared<const scenes::TerrainHeight>(scene);
  m.buffer = MutationBuffer(options.mutation_buffer);
  m.discovery_triangles = options.discovery_triangles;
  m.device = rtcNewDevice(nullptr);
  if (m.device == nullptr) {
    return absl::InternalError(absl::StrCat("Embree: cannot create a device (error ", rtcGetDeviceError(nullptr), ")"));
  }
  m.rtc = rtcNewScene(m.device);
  rtcSetSceneFlags(m.rtc, options.robust_traversal ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(m.rtc, RTC_BUILD_QUALITY_HIGH);
  m.objects.resize(scene.objects.size());
  for (ObjectId id = 0; id < scene.objects.size(); ++id) {
    if (!m.MakeObject(scene.objects[id].mesh, &m.objects[id])) {
      return absl::InvalidArgumentError(absl::StrCat("object ", id, " (", scene.objects[id].name,
                                                     ") has a non-finite position, an index out of range or 2^29 triangles or more"));
    }
    if (!m.objects[id].indices.empty()) m.Attach(id);
  }
  m.Commit();
  if (const RTCError err = rtcGetDeviceError(m.device); err != RTC_ERROR_NONE) {
    return absl::InternalError(absl::StrCat("Embree: building the scene failed (error ", err, ")"));
  }
  m.Rebuild();
  s->pvs_ = GlobalPvs(grid.CellCount(), scene.objects.size());
  m.cell_samples.assign(grid.CellCount(), 0);
  m.object_hits.assign(scene.objects.size(), 0);
  m.witness_cell.assign(grid.CellCount(), false);
  return s;
}

void GlobalSampler::Run(const RunLimits& limits, const scenes::RunControl& run, const std::string& label) {
  const uint64_t start_samples = stats_.samples;
  const double start_seconds = stats_.seconds;
  if (limits.pixel_error > 0) {
    impl_->estimate_target_pixels = limits.pixel_error;
    UpdateEstimate(*impl_, options_, &stats_);
  }
  scenes::Progress progress(run, label, 1000);
  uint64_t shown = 0;
  for (;;) {
    const double ran = stats_.seconds - start_seconds;
    const uint64_t ran_samples = stats_.samples - start_samples;
    double fraction = 0.0;
    bool done = false;
    if (limits.seconds > 0) {
      fraction = std::max(fraction, ran / limits.seconds);
      done |= ran >= limits.seconds;
    }
    if (limits.samples > 0) {
      fraction = std::max(fraction, static_cast<double>(ran_samples) / static_cast<double>(limits.samples));
      done |= ran_samples >= limits.samples;
    }
    if (limits.pixel_error > 0 && stats_.batches > 0) {
      // Progress on a log scale from the first estimate down to the target.
      const double e = std::max(stats_.estimated_pixel_error, 1e-12);
      fraction = std::max(fraction, std::clamp(1.0 - std::log(e / limits.pixel_error) / std::log(1e6), 0.0, 1.0));
      done |= stats_.estimate_settled && stats_.estimated_pixel_error <= limits.pixel_error;
    }
    if (limits.seconds <= 0 && limits.samples == 0 && limits.pixel_error <= 0) done = true;
    if (run.progress != nullptr) {
      const uint64_t now = static_cast<uint64_t>(std::clamp(fraction, 0.0, 1.0) * 1000);
      progress.SetDetail(absl::StrFormat("%.2f M samples/s, error %.1f px",
                                         ran > 0 ? ran_samples / ran * 1e-6 : 0.0, stats_.estimated_pixel_error));
      if (now > shown) {
        progress.Advance(now - shown);
        shown = now;
      }
    }
    if (done || run.Cancelled()) break;
    RunBatch();
  }
  progress.Finish();
}

}  // namespace vistream::visibility
