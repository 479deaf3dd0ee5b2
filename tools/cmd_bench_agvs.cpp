// vistream bench agvs: the paper's convergence comparison. AGVS, SGVS (view space-direction
// only) and REF (a random cell, a random ray) sample the same scene side by side, a batch
// each in turn, so that the machine's noise falls on all three alike. Reports mean PVS size
// against sampling time, how much sooner each reaches the size REF ends with, and the
// estimated pixel error against the pixel error measured by rendering: object-id cube maps
// from random points of random cells (OSMesa), a pixel wrong when the object it shows is not
// in that cell's PVS, weighted by its solid angle and scaled to the estimator's 1024 x 1024.
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <map>
#include <numbers>

#include <CLI/CLI.hpp>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/gnuplot.h"
#include "gl/id_renderer.h"
#include "scenes/progress.h"
#include "scenes/random.h"
#include "visibility/agvs.h"

namespace vistream::tools {

namespace {

using visibility::GlobalSampler;
using visibility::SamplingStrategy;

struct BenchAgvsArgs {
  std::string scene = "london";
  double seconds = 60.0;  // sampling time of each strategy
  int views = 24;
  int res = 128;
  uint32_t batch = 1u << 14;
  int checkpoints = 7;
  double cell_size = 0.0;
  uint64_t seed = 1;
  unsigned threads = 0;
  std::string plot;
  bool json = false;
};

// A rendered view: its cell and the solid angle each visible object covers.
struct View {
  visibility::CellId cell = 0;
  glm::dvec3 eye{0.0};
  std::vector<std::pair<scenes::ObjectId, double>> objects;  // ascending ids
};

struct Checkpoint {
  double seconds = 0.0, mean_objects = 0.0, estimated = 0.0, measured = 0.0;
  uint64_t samples = 0;
};

struct Track {
  SamplingStrategy strategy;
  std::unique_ptr<GlobalSampler> sampler;
  std::vector<std::pair<double, double>> curve;  // seconds, mean PVS objects
  std::vector<Checkpoint> checkpoints;
  size_t next_checkpoint = 0;
};

constexpr double kResolution = 1024.0 * 1024.0;

// Pixels of a 1024 x 1024 camera: the share of the sphere, over the views, whose object is
// missing from the view's cell's set.
double MeasuredError(const std::vector<View>& views, const visibility::GlobalPvs& pvs) {
  if (views.empty()) return 0.0;
  double wrong = 0.0;
  for (const View& v : views) {
    for (const auto& [o, w] : v.objects) {
      if (!pvs.Contains(v.cell, o)) wrong += w;
    }
  }
  return kResolution * wrong / (4.0 * std::numbers::pi * static_cast<double>(views.size()));
}

// The first time the curve reaches `size`, linearly between its points; negative if never.
double TimeToReach(const std::vector<std::pair<double, double>>& curve, double size) {
  double t0 = 0.0, s0 = 0.0;
  for (const auto& [t, s] : curve) {
    if (s >= size) return s > s0 ? t0 + (t - t0) * (size - s0) / (s - s0) : t;
    t0 = t;
    s0 = s;
  }
  return -1.0;
}

// The plot's colour of strategy `s`: AGVS amber, SGVS teal, REF red (in SamplingStrategy's order).
const char* StrategyColour(SamplingStrategy s) {
  static constexpr std::array<const char*, 3> kColours = {"#d08c00", "#1b9e9e", "#d62728"};
  const auto k = static_cast<size_t>(s);
  return k < kColours.size() ? kColours[k] : "#000000";
}

// Two panels on a log time axis (gnuplot): mean PVS size (top, linear) and pixel error
// (bottom, log; estimated as lines, measured as points).
absl::Status WritePlot(const std::vector<Track>& tracks, const std::string& scene, size_t cells, double cell_size,
                       size_t views, const std::string& png) {
  GnuplotPlot plot;
  plot.png = png;
  plot.width = 1200;
  plot.height = 1000;
  std::string size_plot, error_plot;
  for (const Track& tr : tracks) {
    const std::string name = visibility::StrategyName(tr.strategy);
    std::string upper = name;
    for (char& c : upper) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
    GnuplotData curve{name + "_curve.dat", "# sampling time (s), mean PVS size (objects per viewcell)\n"};
    for (const auto& [t, size] : tr.curve) absl::StrAppend(&curve.text, absl::StrFormat("%.6g %.6g\n", t, size));
    GnuplotData points{name + "_checkpoints.dat", "# sampling time (s), estimated pixel error, measured pixel error\n"};
    for (const Checkpoint& c : tr.checkpoints) {
      absl::StrAppend(&points.text, absl::StrFormat("%.6g %.6g %.6g\n", c.seconds, c.estimated, c.measured));
    }
    const std::string colour = StrategyColour(tr.strategy);
    absl::StrAppend(&size_plot, size_plot.empty() ? "plot " : ", \\\n     ", GnuplotQuote(curve.name),
                    " using 1:2 with lines lw 2 lc rgb '", colour, "' title '", upper, "'");
    absl::StrAppend(&error_plot, error_plot.empty() ? "plot " : ", \\\n     ", GnuplotQuote(points.name),
                    " using 1:($2 > 0 ? $2 : NaN) with linespoints lw 2 pt 0 lc rgb '", colour, "' title '", upper,
                    " estimated', ", GnuplotQuote(points.name), " using 1:($3 > 0 ? $3 : NaN) with points pt 5 ps 1.5 lc rgb '",
                    colour, "' title '", upper, " measured (rendered)'");
    plot.data.push_back(std::move(curve));
    plot.data.push_back(std::move(points));
  }
  plot.script = absl::StrCat(
      "set multiplot layout 2,1 title ",
      GnuplotQuote(absl::StrFormat("Global visibility sampling on %s: AGVS, SGVS and REF side by side "
                                   "(%zu viewcells of %g m, %zu rendered views)",
                                   scene, cells, cell_size, views)),
      " font ',15'\n", "set grid xtics ytics mxtics lc rgb '#d0d0d0'\n", "set logscale x 10\n",
      "set format x '%g'\n", "set key top left box opaque Left reverse\n", "set xlabel 'sampling time (s, log scale)'\n",
      "set title 'Mean PVS size against sampling time'\n",
      "set ylabel 'mean PVS size (objects per viewcell)'\n", "set yrange [0:*]\n", size_plot, "\n",
      "set title ", GnuplotQuote("Pixel error against sampling time (lines: the sampler's estimate; points: measured by rendering)"), "\n",
      "set logscale y 10\n", "set yrange [*:*]\n", "set format y '10^{%L}'\n", "set key top right box opaque Left reverse\n",
      "set ylabel 'pixel error (pixels of a 1024 x 1024 view, log scale)'\n", error_plot, "\n",
      "unset multiplot\n");
  return RunGnuplot(plot);
}

int BenchAgvs(const BenchAgvsArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  if (!(a.seconds > 0)) return Fail(absl::InvalidArgumentError("--seconds must be positive"));
  const scenes::ViewcellSpec spec = scenes::ViewcellSpecFor(a.scene, a.cell_size);
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene);
  if (!scene.ok()) return Fail(scene.status());
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, spec);
  if (!grid.ok()) return Fail(grid.status());

  // The measured side first: views from uniform points of uniform cells, as the estimator's
  // camera rays start; a view that sees a back face starts inside a building and is drawn
  // again (the sampler discards such rays too).
  std::vector<View> views;
  {
    absl::StatusOr<std::unique_ptr<gl::IdRenderer>> renderer = gl::IdRenderer::Create(*scene, a.res);
    if (!renderer.ok()) return Fail(renderer.status());
    scenes::Rng rng(scenes::Rng(a.seed).Next() ^ 0x51ed27);
    scenes::Progress progress(ToolRun(), "rendering views", static_cast<uint64_t>(a.views));
    InstallCancelHandler();
    for (int tries = 0; static_cast<int>(views.size()) < a.views && tries < 50 * a.views; ++tries) {
      View v;
      v.cell = static_cast<visibility::CellId>(rng.Below(grid->CellCount()));
      const scenes::Aabb box = grid->CellBox(v.cell);
      v.eye = glm::dvec3(rng.Uniform(box.min.x, box.max.x), rng.Uniform(box.min.y, box.max.y),
                         rng.Uniform(box.min.z, box.max.z));
      absl::StatusOr<std::array<std::vector<uint32_t>, 6>> cube = (*renderer)->RenderCube(v.eye);
      if (!cube.ok()) return Fail(cube.status());
      std::map<scenes::ObjectId, double> seen;
      bool inside = false;
      for (const std::vector<uint32_t>& face : *cube) {
        for (int y = 0; y < a.res && !inside; ++y) {
          for (int x = 0; x < a.res; ++x) {
            const uint32_t id = face[static_cast<size_t>(y) * a.res + x];
            if ((id & gl::kBackFace) != 0) {
              inside = true;
              break;
            }
            if (id != gl::kNothing) seen[id - 1] += (*renderer)->PixelSolidAngle(x, y);
          }
        }
      }
      if (inside) continue;
      v.objects.assign(seen.begin(), seen.end());
      views.push_back(std::move(v));
      progress.Advance();
      if (progress.Cancelled()) return Fail(absl::CancelledError("bench agvs stopped"));
    }
    progress.Finish();
  }

  std::vector<Track> tracks;
  for (SamplingStrategy st : {SamplingStrategy::kAgvs, SamplingStrategy::kSgvs, SamplingStrategy::kRef}) {
    visibility::AgvsOptions o;
    o.strategy = st;
    o.seed = a.seed;
    o.threads = a.threads;
    o.batch_samples = a.batch;
    absl::StatusOr<std::unique_ptr<GlobalSampler>> s = GlobalSampler::Create(*scene, *grid, o);
    if (!s.ok()) return Fail(s.status());
    tracks.push_back({st, std::move(*s), {}, {}, 0});
  }
  // Checkpoints at T / 2^k.
  std::vector<double> marks;
  for (int k = a.checkpoints - 1; k >= 0; --k) marks.push_back(a.seconds / std::pow(2.0, k));

  const double cells = static_cast<double>(grid->CellCount());
  {
    scenes::Progress progress(ToolRun(), "sampling " + scene->name + " (agvs, sgvs, ref in turn)", 1000);
    uint64_t shown = 0;
    for (;;) {
      Track* next = nullptr;
      for (Track& t : tracks) {
        if (t.sampler->stats().seconds < a.seconds &&
            (next == nullptr || t.sampler->stats().seconds < next->sampler->stats().seconds)) {
          next = &t;
        }
      }
      if (next == nullptr) break;
      next->sampler->RunBatch();
      const visibility::AgvsStats& st = next->sampler->stats();
      next->curve.emplace_back(st.seconds, static_cast<double>(st.entries) / cells);
      while (next->next_checkpoint < marks.size() && st.seconds >= marks[next->next_checkpoint]) {
        next->checkpoints.push_back({st.seconds, static_cast<double>(st.entries) / cells, st.estimated_pixel_error,
                                     MeasuredError(views, next->sampler->pvs()), st.samples});
        ++next->next_checkpoint;
      }
      double least = a.seconds;
      for (const Track& t : tracks) least = std::min(least, t.sampler->stats().seconds);
      const auto now = static_cast<uint64_t>(std::clamp(least / a.seconds, 0.0, 1.0) * 1000);
      progress.SetDetail(absl::StrFormat("agvs %.0f, sgvs %.0f, ref %.0f objects", tracks[0].curve.empty() ? 0.0 : tracks[0].curve.back().second,
                                         tracks[1].curve.empty() ? 0.0 : tracks[1].curve.back().second,
                                         tracks[2].curve.empty() ? 0.0 : tracks[2].curve.back().second));
      if (now > shown) {
        progress.Advance(now - shown);
        shown = now;
      }
      if (progress.Cancelled()) return Fail(absl::CancelledError("bench agvs stopped"));
    }
    progress.Finish();
  }

  const Track& ref = tracks[2];
  const double ref_final = ref.curve.back().second, ref_seconds = ref.curve.back().first;
  nlohmann::json j;
  j["scene"] = scene->name;
  j["cells"] = grid->CellCount();
  j["cell_size"] = grid->cell_size();
  j["objects"] = scene->objects.size();
  j["seconds"] = a.seconds;
  j["views"] = views.size();
  j["view_resolution"] = a.res;
  j["ref_final_mean_pvs_objects"] = ref_final;
  for (const Track& t : tracks) {
    const visibility::AgvsStats& st = t.sampler->stats();
    nlohmann::json s;
    s["samples"] = st.samples;
    s["rays"] = st.rays;
    s["seconds"] = st.seconds;
    s["samples_per_s"] = st.samples / st.seconds;
    s["rays_per_s"] = st.rays / st.seconds;
    s["final_mean_pvs_objects"] = t.curve.back().second;
    const double reach = TimeToReach(t.curve, ref_final);
    s["time_to_ref_final"] = reach;
    s["speedup_vs_ref"] = reach > 0 ? ref_seconds / reach : 0.0;
    nlohmann::json cps = nlohmann::json::array();
    for (const Checkpoint& c : t.checkpoints) {
      cps.push_back({{"seconds", c.seconds},
                     {"samples", c.samples},
                     {"mean_pvs_objects", c.mean_objects},
                     {"estimated_pixel_error", c.estimated},
                     {"measured_pixel_error", c.measured}});
    }
    s["checkpoints"] = cps;
    nlohmann::json curve = nlohmann::json::array();
    for (const auto& [sec, size] : t.curve) curve.push_back({sec, size});
    s["curve"] = curve;
    j["strategies"][visibility::StrategyName(t.strategy)] = s;
  }
  if (!a.plot.empty()) {
    if (absl::Status st = WritePlot(tracks, scene->name, grid->CellCount(), grid->cell_size(), views.size(), a.plot);
        !st.ok()) {
      return Fail(st);
    }
    j["plot"] = a.plot;
  }
  if (a.json) {
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("%s: %zu cells of %.0f m, %zu objects; %.0f s of sampling each, side by side; %zu views of 6 x %d^2\n",
              scene->name.c_str(), grid->CellCount(), grid->cell_size(), scene->objects.size(), a.seconds, views.size(),
              a.res);
  std::printf("\nmean PVS size (objects) and pixel error (of 1024 x 1024: estimated / measured by rendering)\n");
  std::printf("%9s | %-32s | %-32s | %-32s\n", "seconds", "agvs", "sgvs", "ref");
  for (size_t k = 0; k < marks.size(); ++k) {
    std::printf("%9.2f", marks[k]);
    for (const Track& t : tracks) {
      if (k < t.checkpoints.size()) {
        const Checkpoint& c = t.checkpoints[k];
        std::printf(" | %8.1f obj %9.1f / %9.1f px", c.mean_objects, c.estimated, c.measured);
      } else {
        std::printf(" | %-32s", "-");
      }
    }
    std::printf("\n");
  }
  std::printf("\n");
  for (const Track& t : tracks) {
    const visibility::AgvsStats& st = t.sampler->stats();
    const double reach = TimeToReach(t.curve, ref_final);
    std::printf("%-5s %7.3f M samples/s %7.3f M rays/s; final %.1f objects; REF's final %.1f reached after %s\n",
                visibility::StrategyName(t.strategy), st.samples / st.seconds * 1e-6, st.rays / st.seconds * 1e-6,
                t.curve.back().second, ref_final,
                reach > 0 ? absl::StrFormat("%.2f s (%.1fx sooner than REF)", reach, ref_seconds / reach).c_str()
                          : "never");
  }
  if (!a.plot.empty()) {
    std::printf("plot: %s (gnuplot; log time; top: mean PVS objects, bottom: pixel error, log, lines estimated, "
                "squares measured)\n",
                a.plot.c_str());
  }
  return 0;
}

}  // namespace

void AddBenchAgvsCommand(CLI::App* bench, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<BenchAgvsArgs>(bench, "agvs",
                                                "AGVS, SGVS and REF side by side: PVS size against "
                                                "time, estimated against rendered pixel error",
                                                BenchAgvs, done);
  c->add_option("--scene", args->scene, "catalog name, .json entry or .glb/.gltf file");
  c->add_option("--seconds", args->seconds, "sampling time of each strategy")->check(FiniteRange(1e-3, kMaxSeconds));
  c->add_option("--views", args->views, "rendered views for the measured pixel error")->check(WholeRange(1, 100000));
  c->add_option("--res", args->res, "pixels per cube face side")->check(WholeRange(8, 1024));
  c->add_option("--batch", args->batch, "samples per batch")->check(WholeRange(1, 1 << 24));
  c->add_option("--checkpoints", args->checkpoints, "table rows, at T / 2^k")->check(WholeRange(1, 30));
  c->add_option("--cell-size", args->cell_size, "viewcell edge in metres (default: the catalog's)")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--seed", args->seed, "random seed")->check(WholeRange(0, kMaxSeed));
  c->add_option("--threads", args->threads, "worker threads (0: one per core)")->check(WholeRange(0, 1024));
  c->add_option("--plot", args->plot, "write the convergence plot (PNG)")->check(OutputPath());
  c->add_flag("--json", args->json, "print the result as JSON");
}

}  // namespace vistream::tools
