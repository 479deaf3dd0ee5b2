// vistream check-conservative: the project's main correctness check. Sampled visibility can
// only under-estimate, so every object AGVS saw from a viewcell must be in that cell's
// dual-ray-space PVS, and every triangle a ray from a neighbourhood hits must be in its
// ε-superset. Each violation is reported with the ray that saw it.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/agvs_common.h"
#include "tools/cli_common.h"
#include "tools/commands.h"
#include "gl/pvs_backend.h"
#include "scenes/progress.h"
#include "visibility/epsilon_superset.h"
#include "visibility/kdtree.h"
#include "visibility/pvs.h"

namespace vistream::tools {

namespace {

// ^C: the check stops where it is and concludes nothing.
int CheckStopped() { return Fail(absl::CancelledError("check-conservative stopped; nothing concluded")); }

struct CheckArgs {
  std::string scene;
  size_t cells = 0;            // 0: every cell
  double seconds = 10.0;
  uint64_t samples = 0;        // when set, instead of seconds: the same samples on every run
  size_t neighbourhoods = 20;  // ε-superset neighbourhoods
  size_t rays = 20000;         // rays per neighbourhood
  double cell_size = 0.0;
  uint64_t seed = 1;
  uint32_t res = 128;
  std::string backend = "cpu";
  bool json = false;
  bool allow_unchecked = false;  // exit 0 even when a part of the check had nothing to check
};

struct Violation {
  std::string kind;  // "pvs" or "epsilon"
  size_t where = 0;  // cell id, or neighbourhood index
  scenes::ObjectId object = 0;
  int64_t triangle = -1;
  bool has_ray = false;
  glm::dvec3 from{0.0}, to{0.0};
};

int Check(const CheckArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  absl::StatusOr<gl::PvsBackend> backend = gl::PvsBackend::Create(a.backend);
  if (!backend.ok()) return Fail(backend.status());
  visibility::AgvsOptions options;
  options.seed = a.seed;
  absl::StatusOr<SampledScene> s = SampledScene::Load(a.scene, a.cell_size, options);
  if (!s.ok()) return Fail(s.status());
  const scenes::Scene& scene = s->scene;
  visibility::GlobalSampler& sampler = *s->sampler;

  std::vector<visibility::CellId> cells;
  if (a.cells == 0 || a.cells >= s->grid.CellCount()) {
    for (visibility::CellId c = 0; c < s->grid.CellCount(); ++c) cells.push_back(c);
  } else {
    for (const visibility::CellCoord& c : s->grid.Sample(a.cells, a.seed)) cells.push_back(s->grid.Id(c));
    std::sort(cells.begin(), cells.end());
  }
  sampler.RecordWitnesses(cells);
  InstallCancelHandler();
  // A sample count replays exactly (the sampler's results depend on its seed alone); a time
  // depends on the machine's load.
  const visibility::RunLimits limits = a.samples > 0 ? visibility::RunLimits{0.0, 0.0, a.samples}
                                                     : visibility::RunLimits{a.seconds, 0.0, 0};
  sampler.Run(limits, ToolRun(), "agvs " + scene.name);
  if (CancelFlag().load()) return CheckStopped();

  // The dual-ray-space PVS of each checked cell.
  std::vector<Violation> violations;
  uint64_t pvs_checked = 0;
  visibility::CellQueryStats drs_stats;  // summed over the checked cells
  {
    const visibility::KdTree tree = visibility::KdTree::Build(scene);
    const visibility::PvsComputer computer(scene, tree);
    visibility::CellQueryOptions q;
    q.max_res = a.res;
    std::vector<scenes::Aabb> boxes;
    for (visibility::CellId c : cells) boxes.push_back(s->grid.CellBox(c));
    scenes::Progress progress(ToolRun(), "dual ray space (" + backend->name() + ")", boxes.size());
    constexpr size_t kStep = 16;
    for (size_t first = 0; first < boxes.size(); first += kStep) {
      const size_t n = std::min(kStep, boxes.size() - first);
      const std::vector<visibility::PvsResult> r =
          backend->ComputeBatch(computer, std::span<const scenes::Aabb>(boxes.data() + first, n), q);
      for (size_t k = 0; k < n; ++k) {
        const visibility::CellId cell = cells[first + k];
        drs_stats.planar_tests += r[k].stats.planar_tests;
        drs_stats.exact_tests += r[k].stats.exact_tests;
        drs_stats.occluded += r[k].stats.occluded;
        for (scenes::ObjectId o : sampler.pvs().Objects(cell)) {
          ++pvs_checked;
          if (std::binary_search(r[k].objects.begin(), r[k].objects.end(), o)) continue;
          Violation v{"pvs", cell, o};
          if (auto w = sampler.WitnessOf(cell, o)) {
            v.has_ray = true;
            v.from = w->from;
            v.to = w->to;
          }
          violations.push_back(v);
        }
      }
      progress.Advance(n);
      if (progress.Cancelled()) return CheckStopped();
    }
    progress.Finish();
  }

  // The ε-superset at sampled street-level neighbourhoods.
  uint64_t eps_checked = 0;
  size_t neighbourhoods = 0;
  if (a.neighbourhoods > 0) {
    absl::StatusOr<std::unique_ptr<visibility::EpsilonSuperset>> eps = visibility::EpsilonSuperset::Create(scene);
    if (!eps.ok()) return Fail(eps.status());
    const double size = 0.25 * visibility::TypicalObjectSize(scene);
    const std::vector<scenes::Aabb> boxes =
        visibility::SampleNeighbourhoods(scene, a.neighbourhoods, size, s->grid.base_z(), a.seed);
    neighbourhoods = boxes.size();
    const visibility::EpsilonOptions all = *visibility::EpsilonOptions::FromName("all");
    scenes::Progress progress(ToolRun(), "epsilon superset", boxes.size());
    for (size_t b = 0; b < boxes.size(); ++b) {
      const visibility::EpsilonResult r = (*eps)->Compute(boxes[b], all);
      for (const visibility::BoxHit& h : sampler.SampleFromBox(boxes[b], a.rays, a.seed + b)) {
        ++eps_checked;
        const uint32_t id = (*eps)->TriangleId(h.object, h.triangle);
        if (std::binary_search(r.triangles.begin(), r.triangles.end(), id)) continue;
        violations.push_back({"epsilon", b, h.object, static_cast<int64_t>(h.triangle), true, h.from, h.to});
      }
      progress.Advance();
      if (progress.Cancelled()) return CheckStopped();
    }
    progress.Finish();
  }

  // One report per distinct (kind, where, object): a triangle hit by many rays counts once.
  std::sort(violations.begin(), violations.end(), [](const Violation& x, const Violation& y) {
    return std::tie(x.kind, x.where, x.object, x.triangle) < std::tie(y.kind, y.where, y.object, y.triangle);
  });
  violations.erase(std::unique(violations.begin(), violations.end(),
                               [](const Violation& x, const Violation& y) {
                                 return x.kind == y.kind && x.where == y.where && x.object == y.object &&
                                        x.triangle == y.triangle;
                               }),
                   violations.end());
  const size_t pvs_violations =
      std::count_if(violations.begin(), violations.end(), [](const Violation& v) { return v.kind == "pvs"; });

  // A check that could not have failed passes nothing: say which part checked nothing.
  std::vector<std::string> unchecked;
  if (pvs_checked == 0) unchecked.push_back("no sampled PVS entry was checked (sampling saw nothing from the cells)");
  if (drs_stats.occluded == 0) {
    unchecked.push_back("the dual ray space hid nothing from the checked cells (no occluders, or nothing behind them), so no false occlusion could show");
  }
  if (a.neighbourhoods > 0 && eps_checked == 0) {
    unchecked.push_back(neighbourhoods == 0 ? "no free street-level neighbourhood was found for the epsilon-superset"
                                            : "no sampled ray from the neighbourhoods hit a triangle");
  }

  if (a.json) {
    nlohmann::json j;
    j["scene"] = scene.name;
    j["cells"] = cells.size();
    j["backend"] = backend->name();
    j["cell_size"] = s->grid.cell_size();
    j["seconds"] = sampler.stats().seconds;
    j["samples"] = sampler.stats().samples;
    j["pvs_entries_checked"] = pvs_checked;
    // What the dual ray space did for the checked cells: an exact backend's check means little
    // if its exact test never ran.
    j["planar_tests"] = drs_stats.planar_tests;
    j["occluded_queries"] = drs_stats.occluded;
    j["exact_tests"] = drs_stats.exact_tests;
    j["neighbourhoods"] = neighbourhoods;
    j["epsilon_hits_checked"] = eps_checked;
    j["violations"] = violations.size();
    j["pvs_violations"] = pvs_violations;
    j["epsilon_violations"] = violations.size() - pvs_violations;
    nlohmann::json list = nlohmann::json::array();
    for (size_t i = 0; i < std::min<size_t>(violations.size(), 100); ++i) {
      const Violation& v = violations[i];
      nlohmann::json e = {{"kind", v.kind}, {v.kind == "pvs" ? "cell" : "neighbourhood", v.where}, {"object", v.object}};
      if (v.triangle >= 0) e["triangle"] = v.triangle;
      if (v.has_ray) e["ray"] = {{"from", {v.from.x, v.from.y, v.from.z}}, {"to", {v.to.x, v.to.y, v.to.z}}};
      list.push_back(e);
    }
    j["violation_list"] = list;
    j["unchecked"] = unchecked;
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf("%s: %zu cells, %llu sampled PVS entries checked against the dual ray space; %zu neighbourhoods, "
                "%llu sampled triangle hits against the epsilon-superset\n",
                scene.name.c_str(), cells.size(), static_cast<unsigned long long>(pvs_checked), neighbourhoods,
                static_cast<unsigned long long>(eps_checked));
    std::printf("violations: %zu (%zu pvs, %zu epsilon)\n", violations.size(), pvs_violations,
                violations.size() - pvs_violations);
    for (size_t i = 0; i < std::min<size_t>(violations.size(), 20); ++i) {
      const Violation& v = violations[i];
      std::printf("  %s %zu: object %u", v.kind.c_str(), v.where, v.object);
      if (v.triangle >= 0) std::printf(" triangle %lld", static_cast<long long>(v.triangle));
      if (v.has_ray) {
        std::printf(", seen along (%.4f, %.4f, %.4f) -> (%.4f, %.4f, %.4f)", v.from.x, v.from.y, v.from.z, v.to.x,
                    v.to.y, v.to.z);
      }
      std::printf("\n");
    }
  }
  if (!violations.empty()) return 1;
  if (!unchecked.empty()) {
    for (const std::string& u : unchecked) {
      std::fprintf(stderr, "vistream: %s: check-conservative checked nothing: %s\n",
                   a.allow_unchecked ? "warning" : "error", u.c_str());
    }
    if (!a.allow_unchecked) {
      std::fprintf(stderr, "vistream: (--allow-unchecked accepts this)\n");
      return 1;
    }
  }
  return 0;
}

}  // namespace

void AddCheckCommand(CLI::App& app, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<CheckArgs>(
      &app, "check-conservative",
      "check that the dual-ray-space PVS and the epsilon-superset contain everything sampling sees "
      "(exit 1 if not)",
      Check, done);
  c->add_option("--scene", args->scene, "catalog name, .json entry or .glb/.gltf file")->required();
  c->add_option("--cells", args->cells, "viewcells to check, sampled (0: every cell)")->check(WholeRange(0, 1 << 30));
  CLI::Option* seconds =
      c->add_option("--seconds", args->seconds, "AGVS sampling time before checking")->check(FiniteRange(1e-3, kMaxSeconds));
  c->add_option("--samples", args->samples, "AGVS samples before checking, instead of --seconds (replays exactly)")
      ->check(WholeRange(1, kMaxSamples))
      ->excludes(seconds);
  c->add_option("--backend", args->backend, "dual ray space backend: cpu | gl | exact")
      ->check(CLI::IsMember({"cpu", "gl", "exact"}));
  c->add_option("--neighbourhoods", args->neighbourhoods, "street-level epsilon neighbourhoods to check (0: none)")
      ->check(WholeRange(0, 1000000));
  c->add_option("--rays", args->rays, "sampled rays per neighbourhood")->check(WholeRange(1, 1000000000));
  c->add_option("--cell-size", args->cell_size, "viewcell edge in metres (default: the catalog's)")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--res", args->res, "dual ray space raster resolution")->check(PowerOfTwo(1, 256));
  c->add_option("--seed", args->seed, "random seed (sampling, cells, neighbourhoods)")->check(WholeRange(0, kMaxSeed));
  c->add_flag("--json", args->json, "print the result as JSON");
  c->add_flag("--allow-unchecked", args->allow_unchecked,
              "exit 0 even when a part of the check had nothing to check (it is still said)");
}

}  // namespace vistream::tools
