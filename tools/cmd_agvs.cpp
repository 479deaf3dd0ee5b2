// vistream agvs: adaptive global visibility sampling of every viewcell at once (Bittner et al.
// 2009), its PVS file, and `agvs heatmap`, the PVS cost of every viewcell over the top view.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/agvs_common.h"
#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/top_view_map.h"
#include "scenes/progress.h"
#include "visibility/agvs.h"
#include "visibility/pvs_file.h"

namespace vistream::tools {

namespace {

struct AgvsArgs {
  std::string scene, strategy = "agvs", out, state, filter = "none";
  double seconds = 0.0, pixel_error = 0.0, cell_size = 0.0;
  uint64_t samples = 0, seed = 1;
  uint32_t batch = 1u << 16;
  unsigned threads = 0;
  bool json = false;
};

nlohmann::json StatsJson(const visibility::GlobalSampler& s) {
  const visibility::AgvsStats& st = s.stats();
  nlohmann::json j;
  j["samples"] = st.samples;
  j["rays"] = st.rays;
  j["seconds"] = st.seconds;
  j["samples_per_s"] = st.seconds > 0 ? static_cast<double>(st.samples) / st.seconds : 0.0;
  j["rays_per_s"] = st.seconds > 0 ? static_cast<double>(st.rays) / st.seconds : 0.0;
  j["batches"] = st.batches;
  j["discarded_samples"] = st.discarded_samples;
  j["estimated_pixel_error"] = st.estimated_pixel_error;
  j["estimate_settled"] = st.estimate_settled;
  j["mutation_candidates"] = st.mutation_candidates;
  nlohmann::json d = nlohmann::json::object();
  for (int k = 0; k < visibility::kDistributionCount; ++k) {
    const visibility::DistributionStats& ds = st.distributions[k];
    if (ds.samples == 0) continue;
    d[visibility::DistributionName(static_cast<visibility::Distribution>(k))] = {
        {"samples", ds.samples}, {"rays", ds.rays}, {"contribution", ds.contribution}, {"probability", ds.probability}};
  }
  j["distributions"] = d;
  return j;
}

int Agvs(const AgvsArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  if (a.scene.empty()) return BadOption("agvs", "--scene", "is required");
  if (a.seconds <= 0 && a.pixel_error <= 0 && a.samples == 0) {
    return BadOption("agvs", "--seconds, --pixel-error or --samples", "give one: when to stop sampling");
  }
  absl::StatusOr<visibility::FilterOptions> filter = FilterFromName(a.filter);
  if (!filter.ok()) return BadOption("agvs", "--filter", std::string(filter.status().message()));
  absl::StatusOr<visibility::SamplingStrategy> strategy = visibility::StrategyFromName(a.strategy);
  if (!strategy.ok()) return BadOption("agvs", "--strategy", std::string(strategy.status().message()));
  visibility::AgvsOptions options;
  options.strategy = *strategy;
  options.seed = a.seed;
  options.threads = a.threads;
  options.batch_samples = a.batch;

  absl::StatusOr<SampledScene> s = SampledScene::Load(a.scene, a.cell_size, options);
  if (!s.ok()) return Fail(s.status());
  visibility::GlobalSampler& sampler = *s->sampler;
  if (!a.state.empty() && std::filesystem::exists(a.state)) {
    absl::StatusOr<std::string> bytes = ReadFile(a.state);
    if (!bytes.ok()) return Fail(bytes.status());
    if (absl::Status st = sampler.LoadState(*bytes, a.state); !st.ok()) return Fail(st);
    if (!a.json) {
      std::fprintf(stderr, "resuming from %s: %llu samples, %.1f s so far\n", a.state.c_str(),
                   static_cast<unsigned long long>(sampler.stats().samples), sampler.stats().seconds);
    }
  }
  InstallCancelHandler();
  sampler.Run({a.seconds, a.pixel_error, a.samples}, ToolRun(), "agvs " + s->scene.name);
  const bool cancelled = CancelFlag().load();

  if (!a.state.empty()) {
    if (absl::Status st = WriteFile(a.state, sampler.SaveState()); !st.ok()) return Fail(st);
  }
  const visibility::GlobalPvs sets = sampler.FilteredAll(*filter);
  if (!a.out.empty()) {
    if (absl::Status st = WriteFile(a.out, visibility::EncodePvsFile(MakePvsFile(*s, sets))); !st.ok()) return Fail(st);
  }
  const double mean_objects = sets.MeanSize();
  const double mean_triangles = MeanTriangles(s->scene, sets);
  nlohmann::json j = StatsJson(sampler);
  j["scene"] = s->scene.name;
  j["strategy"] = a.strategy;
  j["filter"] = a.filter;
  j["seed"] = a.seed;
  j["cells"] = sets.cell_count();
  j["cell_size"] = s->grid.cell_size();
  j["objects"] = s->scene.objects.size();
  j["entries"] = sets.TotalEntries();
  j["sets_bytes"] = sampler.pvs().MemoryBytes();  // the sampled sets' index and blocks
  j["mean_pvs_objects"] = mean_objects;
  j["mean_pvs_triangles"] = mean_triangles;
  j["cancelled"] = cancelled;
  if (!a.out.empty()) j["pvs_file"] = a.out;
  // ^C: what was sampled is kept (an anytime result), and said so, as every interrupted command.
  auto interrupted = [&] {
    std::fprintf(stderr, "vistream: interrupted (sampling stopped after %llu samples%s)\n",
                 static_cast<unsigned long long>(sampler.stats().samples),
                 a.out.empty() && a.state.empty() ? ""
                 : a.out.empty()                  ? "; the state saved"
                 : a.state.empty()                ? "; the PVS file written from them"
                                                  : "; the state saved and the PVS file written from them");
    return 130;
  };
  if (a.json) {
    std::printf("%s\n", j.dump(2).c_str());
    return cancelled ? interrupted() : 0;
  }
  const visibility::AgvsStats& st = sampler.stats();
  std::printf("%s, %zu cells of %.0f m: %llu samples in %.1f s (%.2f M samples/s, %.2f M rays/s)%s\n",
              s->scene.name.c_str(), sets.cell_count(), s->grid.cell_size(),
              static_cast<unsigned long long>(st.samples), st.seconds, st.samples / std::max(st.seconds, 1e-9) * 1e-6,
              st.rays / std::max(st.seconds, 1e-9) * 1e-6, cancelled ? " (cancelled)" : "");
  std::printf("mean PVS: %.1f of %zu objects, %.0f triangles; estimated pixel error %.2f px of 1024 x 1024%s\n",
              mean_objects, s->scene.objects.size(), mean_triangles, st.estimated_pixel_error,
              st.estimate_settled ? "" : " (window still filling)");
  for (int k = 0; k < visibility::kDistributionCount; ++k) {
    const visibility::DistributionStats& ds = st.distributions[k];
    if (ds.samples == 0) continue;
    std::printf("  %-22s %12llu samples %12llu new entries  share %.3f\n",
                visibility::DistributionName(static_cast<visibility::Distribution>(k)),
                static_cast<unsigned long long>(ds.samples), static_cast<unsigned long long>(ds.contribution),
                ds.probability);
  }
  if (!a.out.empty()) std::printf("PVS file: %s\n", a.out.c_str());
  std::fflush(stdout);
  return cancelled ? interrupted() : 0;
}

struct HeatmapArgs {
  std::string scene, pvs, out, filter = "none";
  double seconds = 0.0, cell_size = 0.0;
  uint64_t seed = 1;
  int size = 2048;
  bool json = false;
};

int Heatmap(const HeatmapArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  if (a.pvs.empty() == (a.seconds <= 0)) {
    return BadOption("agvs heatmap", "--pvs or --seconds", "give one: a PVS file (from agvs -o) or a time to sample first");
  }
  absl::StatusOr<visibility::FilterOptions> filter = FilterFromName(a.filter);
  if (!filter.ok()) return BadOption("agvs heatmap", "--filter", std::string(filter.status().message()));
  visibility::AgvsOptions options;
  options.seed = a.seed;
  absl::StatusOr<SampledScene> s = SampledScene::Load(a.scene, a.cell_size, options);
  if (!s.ok()) return Fail(s.status());
  visibility::GlobalPvs sets;
  if (!a.pvs.empty()) {
    absl::StatusOr<visibility::PvsFile> f = visibility::LoadPvsFile(a.pvs, s->grid, s->scene);
    if (!f.ok()) return Fail(f.status());
    sets = std::move(f->sets);
  } else {
    InstallCancelHandler();
    s->sampler->Run({a.seconds, 0.0, 0}, ToolRun(), "agvs " + s->scene.name);
    sets = s->sampler->FilteredAll(*filter);
  }
  const std::string source = !a.pvs.empty() ? "PVS file " + std::filesystem::path(a.pvs).filename().string()
                                             : absl::StrFormat("AGVS, %g s of sampling", a.seconds);
  const HeatmapStats h = WriteHeatmap(s->scene, s->grid, sets, a.out, source, a.size);
  if (!h.status.ok()) return Fail(h.status);
  if (a.json) {
    nlohmann::json j;
    j["scene"] = s->scene.name;
    j["png"] = a.out;
    j["cells"] = sets.cell_count();
    j["max_pvs_triangles"] = h.max_triangles;
    j["mean_pvs_triangles"] = h.mean_triangles;
    j["width"] = h.width;
    j["height"] = h.height;
    j["metres_per_pixel"] = h.metres_per_pixel;
    j["footprint_outlines"] = h.outlines;
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("%s: PVS cost of %zu cells, mean %.0f, max %llu triangles -> %s (%d x %d)\n", s->scene.name.c_str(),
              sets.cell_count(), h.mean_triangles, static_cast<unsigned long long>(h.max_triangles), a.out.c_str(),
              h.width, h.height);
  return 0;
}

}  // namespace

void AddAgvsCommand(CLI::App& app, std::function<void(int)> done) {
  auto args = std::make_shared<AgvsArgs>();
  CLI::App* c = app.add_subcommand("agvs", "adaptive global visibility sampling: the PVS of every viewcell at once");
  c->add_option("--scene", args->scene, "catalog name, .json entry or .glb/.gltf file (required)");
  c->add_option("--seconds", args->seconds, "stop after this much sampling time")->check(FiniteRange(1e-3, kMaxSeconds));
  c->add_option("--pixel-error", args->pixel_error, "stop when the estimated pixel error (of 1024 x 1024) is this low")
      ->check(FiniteRange(1e-9, 1024.0 * 1024.0));
  c->add_option("--samples", args->samples, "stop after this many samples")->check(WholeRange(1, kMaxSamples));
  c->add_option("--strategy", args->strategy, "agvs (adaptive mixture), sgvs (view space-direction only), ref (per cell)");
  c->add_option("-o", args->out, "write the PVS file a server serves from")->check(OutputPath());
  c->add_option("--state", args->state, "resume from this state file if it exists, and save the state there")
      ->check(OutputPath());
  c->add_option("--filter", args->filter, "visibility filter applied to the output: none, object, view, both");
  c->add_option("--cell-size", args->cell_size, "viewcell edge in metres (default: the catalog's)")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--seed", args->seed, "random seed; results depend on it alone")->check(WholeRange(0, kMaxSeed));
  c->add_option("--threads", args->threads, "worker threads (0: one per core)")->check(WholeRange(0, 1024));
  c->add_option("--batch", args->batch, "samples per batch")->check(WholeRange(1, 1 << 24));
  c->add_flag("--json", args->json, "print the result as JSON");
  c->callback([args, done, c] {
    if (c->get_subcommands().empty()) done(Agvs(*args));
  });

  auto [hm, h] = AddSubcommand<HeatmapArgs>(
      c, "heatmap", "PNG of the PVS cost (triangles) of every viewcell over the top view", Heatmap,
      done);
  hm->add_option("--scene", h->scene, "catalog name, .json entry or .glb/.gltf file")->required();
  hm->add_option("--pvs", h->pvs, "a PVS file from vistream agvs -o");
  hm->add_option("--seconds", h->seconds, "or sample this long first")->check(FiniteRange(1e-3, kMaxSeconds));
  hm->add_option("--filter", h->filter, "with --seconds: none, object, view, both");
  hm->add_option("--cell-size", h->cell_size, "viewcell edge in metres (default: the catalog's)")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  hm->add_option("--seed", h->seed, "random seed")->check(WholeRange(0, kMaxSeed));
  hm->add_option("-o", h->out, "the PNG to write")->required()->check(OutputPath());
  hm->add_option("--size", h->size,
                 absl::StrFormat("the map's pixels on its longer side (default 2048); footprints are outlined only "
                                 "below %g m per pixel", TopViewMap::kOutlineMetresPerPixel))
      ->check(WholeRange(16, 16384));
  hm->add_flag("--json", h->json, "print the result as JSON");
}

}  // namespace vistream::tools
