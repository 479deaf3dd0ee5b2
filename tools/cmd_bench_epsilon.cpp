// vistream bench epsilon: Tables 1 and 2 of Cohen-Or & Zadicario 1998 with this project's
// numbers: culling over random ground-level neighbourhoods, and the time each optimisation
// column takes, all columns over the same neighbourhoods in one run.
#include <time.h>

#include <algorithm>
#include <cstdio>
#include <map>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "scenes/catalog.h"
#include "scenes/progress.h"
#include "visibility/epsilon_superset.h"
#include "visibility/pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

namespace {

struct BenchEpsilonArgs {
  std::string scene = "city1";
  std::vector<std::string> opts = {"none", "boxes", "occluders", "rays", "paper", "all"};
  size_t count = 100;
  uint64_t seed = 1998;
  double size = 0.0;  // 0: a quarter of the typical object
  double pvs_cell = 0.0;  // > 0: only the objects of the PVS of this size of viewcell around each box
  bool json = false;
};

// The paper's figures (SGI R4400): Table 1 per model, Table 2 (city1) per column.
struct PaperTable1 {
  double polygons, occluded_polygons, boxes, occluded_boxes, first_occluders;
};
const std::map<std::string, PaperTable1> kPaperTable1 = {{"city1", {21280, 20062, 2128, 1954, 1427}},
                                                         {"city2", {21280, 18713, 2128, 1755, 1225}}};
struct PaperTable2 {
  double total_ms, box_ms, polygon_ms, box_tests, polygon_tests;  // -1: not applicable
};
const std::map<std::string, PaperTable2> kPaperTable2 = {{"none", {30170, -1, 29820, -1, 517800}},
                                                         {"boxes", {8900, 7450, 1410, 135278, 38648}},
                                                         {"occluders", {8850, 7340, 1400, 135089, 38648}},
                                                         {"rays", {7040, 5540, 1410, 45570, 38648}},
                                                         {"paper", {7030, 5550, 1390, 42414, 38648}},
                                                         {"all", {7030, 5550, 1390, 42414, 38648}}};

// One neighbourhood's figures in one column, for --json's per-neighbourhood list: where the
// time goes, and a digest of the superset (to compare builds set by set).
struct QueryFigures {
  double ms = 0, box_ms = 0, polygon_ms = 0, cpu_ms = 0;
  uint64_t traversals = 0, box_tests = 0, polygon_tests = 0, rays = 0, tested_triangles = 0, visible_triangles = 0;
  uint64_t occluded_boxes = 0, digest = 0;
};

// FNV-1a over the sorted triangle ids: equal sets give equal digests.
uint64_t Digest(const std::vector<uint32_t>& triangles) {
  uint64_t h = 1469598103934665603ull;
  for (uint32_t t : triangles) {
    for (int b = 0; b < 4; ++b) {
      h ^= (t >> (8 * b)) & 0xffu;
      h *= 1099511628211ull;
    }
  }
  return h;
}

struct Column {
  std::string opt;
  std::vector<double> ms, cpu_ms;
  std::vector<QueryFigures> queries;
  double box_ms = 0, polygon_ms = 0, rays = 0, traversals = 0, box_tests = 0, polygon_tests = 0;
  double visible_triangles = 0, total_triangles = 0, occluded_boxes = 0, total_boxes = 0, first_occluders = 0;
};

// This thread's CPU time in ms: unlike the wall-clock times, it leaves out the time the
// thread waits for a core on a loaded machine.
double ThreadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e3 * static_cast<double>(ts.tv_sec) + 1e-6 * static_cast<double>(ts.tv_nsec);
}

std::string Paper(double v) { return v < 0 ? "-" : absl::StrFormat("%.0f", v); }

int BenchEpsilon(const BenchEpsilonArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  std::vector<visibility::EpsilonOptions> options;
  for (const std::string& name : a.opts) {
    absl::StatusOr<visibility::EpsilonOptions> o = visibility::EpsilonOptions::FromName(name);
    if (!o.ok()) return BadOption("bench epsilon", "--opts", std::string(o.status().message()));
    options.push_back(*o);
  }
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene);
  if (!scene.ok()) return Fail(scene.status());
  scenes::ViewcellSpec spec;
  if (auto entry = scenes::FindCatalogEntry(a.scene); entry.ok()) spec = entry->viewcell;
  const double typical = visibility::TypicalObjectSize(*scene);
  const double size = a.size > 0 ? a.size : 0.25 * typical;
  const std::vector<scenes::Aabb> boxes = visibility::SampleNeighbourhoods(*scene, a.count, size, spec.base_m, a.seed);
  if (boxes.empty()) return Fail(absl::FailedPreconditionError("no free ground-level neighbourhood found in " + a.scene));
  absl::StatusOr<std::unique_ptr<visibility::EpsilonSuperset>> eps = visibility::EpsilonSuperset::Create(*scene);
  if (!eps.ok()) return Fail(eps.status());

  // As a server would ask: only over the PVS of the viewcell around each neighbourhood (the
  // cell's box grown to hold the neighbourhood, so that the PVS is conservative for it).
  std::vector<std::vector<scenes::ObjectId>> pvs(boxes.size());
  double pvs_objects = 0, pvs_ms = 0;
  if (a.pvs_cell > 0) {
    const visibility::KdTree tree = visibility::KdTree::Build(*scene);
    const visibility::PvsComputer computer(*scene, tree);
    scenes::ViewcellSpec sized = spec;
    sized.size_m = a.pvs_cell;
    absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, sized);
    if (!grid.ok()) return Fail(grid.status());
    for (size_t k = 0; k < boxes.size(); ++k) {
      const std::optional<visibility::CellId> cell = grid->CellAt(glm::dvec2(boxes[k].Centre()));
      scenes::Aabb region = boxes[k];
      if (cell.has_value()) {
        const scenes::Aabb c = grid->CellBox(*cell);
        region.Extend(c.min);
        region.Extend(c.max);
      }
      const visibility::PvsResult r = computer.Compute(region, visibility::CellQueryOptions{});
      pvs[k] = r.objects;
      pvs_objects += static_cast<double>(r.objects.size());
      pvs_ms += r.ms;
    }
  }

  std::vector<Column> columns(options.size());
  for (size_t c = 0; c < options.size(); ++c) columns[c].opt = a.opts[c];
  scenes::Progress progress(ToolRun(), "epsilon", boxes.size() * options.size());
  // Columns alternate per neighbourhood, so that a noisy stretch of the run hits all alike.
  for (size_t k = 0; k < boxes.size(); ++k) {
    std::vector<uint32_t> reference;
    for (size_t c = 0; c < options.size(); ++c) {
      const double cpu0 = ThreadCpuMs();
      const visibility::EpsilonResult r =
          a.pvs_cell > 0 ? (*eps)->Compute(boxes[k], options[c], pvs[k]) : (*eps)->Compute(boxes[k], options[c]);
      const double cpu_ms = ThreadCpuMs() - cpu0;
      // Every column is the same conservative test with different shortcuts: a column that
      // drops hidden occluders may keep more, none may keep less than the first column.
      if (c == 0) {
        reference = r.triangles;
      } else if (!std::includes(r.triangles.begin(), r.triangles.end(), reference.begin(), reference.end()) ||
                 (!options[c].drop_hidden_occluders && !options[0].drop_hidden_occluders && r.triangles != reference)) {
        return Fail(absl::InternalError(absl::StrFormat(
            "neighbourhood %zu: column %s gives a different superset from column %s", k, a.opts[c], a.opts[0])));
      }
      Column& col = columns[c];
      const visibility::EpsilonStats& s = r.stats;
      col.ms.push_back(s.ms);
      col.cpu_ms.push_back(cpu_ms);
      col.queries.push_back({s.ms, s.box_ms, s.polygon_ms, cpu_ms, s.traversals, s.box_ray_tests, s.polygon_ray_tests, s.rays,
                             s.tested_triangles, s.visible_triangles, s.occluded_boxes, Digest(r.triangles)});
      col.box_ms += s.box_ms;
      col.polygon_ms += s.polygon_ms;
      col.rays += static_cast<double>(s.rays);
      col.traversals += static_cast<double>(s.traversals);
      col.box_tests += static_cast<double>(s.box_ray_tests);
      col.polygon_tests += static_cast<double>(s.polygon_ray_tests);
      col.visible_triangles += static_cast<double>(s.visible_triangles);
      col.total_triangles += static_cast<double>(s.total_triangles);
      col.occluded_boxes += static_cast<double>(s.occluded_boxes);
      col.total_boxes += static_cast<double>(s.total_boxes);
      col.first_occluders += static_cast<double>(s.first_occluders);
      progress.Advance();
      if (progress.Cancelled()) return Fail(absl::CancelledError("bench epsilon stopped"));
    }
  }
  progress.Finish();
  const auto n = static_cast<double>(boxes.size());
  auto mean = [n](double sum) { return sum / n; };
  // The mean of per-neighbourhood figures, summed in sample order.
  auto mean_of = [&mean](const std::vector<double>& v) {
    double sum = 0;
    for (double m : v) sum += m;
    return mean(sum);
  };

  // Table 1 from the paper's fully optimised column if it ran (this project's hints find
  // hiders before the first ray, so "first occluders" means nothing there), else the last.
  const auto paper_column = std::find_if(columns.begin(), columns.end(), [](const Column& c) { return c.opt == "paper"; });
  const Column& full = paper_column != columns.end() ? *paper_column : columns.back();
  const PaperTable1* p1 = kPaperTable1.count(scene->name) ? &kPaperTable1.at(scene->name) : nullptr;
  const double polygons = mean(full.total_triangles), occluded = polygons - mean(full.visible_triangles);

  if (a.json) {
    nlohmann::json j;
    j["scene"] = scene->name;
    j["neighbourhoods"] = boxes.size();
    j["size"] = size;
    j["typical_object_size"] = typical;
    j["seed"] = a.seed;
    j["prisms"] = (*eps)->prism_count();
    if (a.pvs_cell > 0) {
      j["pvs_cell"] = a.pvs_cell;
      j["pvs_objects"] = mean(pvs_objects);
      j["pvs_ms"] = mean(pvs_ms);
    }
    j["table1"] = {{"opt", full.opt},
                   {"total_polygons", polygons},
                   {"occluded_polygons", occluded},
                   {"occluded_polygons_pct", polygons > 0 ? 100.0 * occluded / polygons : 0.0},
                   {"total_boxes", mean(full.total_boxes)},
                   {"occluded_boxes", mean(full.occluded_boxes)},
                   {"first_occluders", mean(full.first_occluders)}};
    j["table2"] = nlohmann::json::array();
    for (const Column& c : columns) {
      // Per neighbourhood, in sample order; the digest (hex) of its superset, and of all of them.
      nlohmann::json per = nlohmann::json::array();
      uint64_t all = 1469598103934665603ull;
      for (size_t k = 0; k < c.queries.size(); ++k) {
        const QueryFigures& f = c.queries[k];
        const scenes::Aabb& b = boxes[k];
        per.push_back({{"centre", {b.Centre().x, b.Centre().y, b.Centre().z}},
                       {"pvs_objects", a.pvs_cell > 0 ? pvs[k].size() : 0},
                       {"ms", f.ms},
                       {"box_ms", f.box_ms},
                       {"polygon_ms", f.polygon_ms},
                       {"cpu_ms", f.cpu_ms},
                       {"traversals", f.traversals},
                       {"box_ray_tests", f.box_tests},
                       {"polygon_ray_tests", f.polygon_tests},
                       {"rays", f.rays},
                       {"occluded_boxes", f.occluded_boxes},
                       {"tested_triangles", f.tested_triangles},
                       {"visible_triangles", f.visible_triangles},
                       {"digest", absl::StrFormat("%016x", f.digest)}});
        all = (all ^ f.digest) * 1099511628211ull;
      }
      j["table2"].push_back({{"opt", c.opt},
                             {"ms", mean_of(c.ms)},
                             {"median_ms", Median(c.ms)},
                             {"cpu_ms", mean_of(c.cpu_ms)},
                             {"median_cpu_ms", Median(c.cpu_ms)},
                             {"box_ms", mean(c.box_ms)},
                             {"polygon_ms", mean(c.polygon_ms)},
                             {"rays", mean(c.rays)},
                             {"traversals", mean(c.traversals)},
                             {"box_ray_tests", mean(c.box_tests)},
                             {"polygon_ray_tests", mean(c.polygon_tests)},
                             {"visible_triangles", mean(c.visible_triangles)},
                             {"digest", absl::StrFormat("%016x", all)},
                             {"per_neighbourhood", per}});
    }
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }

  std::printf("ε-superset on %s: %zu random ground-level neighbourhoods of %.2f m (a quarter of the typical "
              "object, %.2f m), bottom %.2f m above the ground, seed %llu; %zu convex prisms. Means per "
              "neighbourhood, one core.\n\n",
              scene->name.c_str(), boxes.size(), size, typical, spec.base_m,
              static_cast<unsigned long long>(a.seed), (*eps)->prism_count());
  if (a.pvs_cell > 0) {
    std::printf("Over the PVS of the %g m viewcell around each neighbourhood: %.0f objects on average (%.1f ms "
                "per PVS, not counted below).\n\n",
                a.pvs_cell, mean(pvs_objects), mean(pvs_ms));
  }
  std::printf("Table 1 (column %s)\n\n| | this run | paper |\n|---|---:|---:|\n", full.opt.c_str());
  auto row1 = [&](const char* name, double v, double paper) {
    std::printf("| %s | %.1f | %s |\n", name, v, p1 ? Paper(paper).c_str() : "-");
  };
  row1("total polygons (triangles here)", polygons, p1 ? p1->polygons : -1);
  row1("occluded polygons", occluded, p1 ? p1->occluded_polygons : -1);
  row1("total bounding boxes", mean(full.total_boxes), p1 ? p1->boxes : -1);
  row1("occluded boxes", mean(full.occluded_boxes), p1 ? p1->occluded_boxes : -1);
  row1("first occluders", mean(full.first_occluders), p1 ? p1->first_occluders : -1);
  std::printf("| occluded polygons %% | %.2f | %s |\n", polygons > 0 ? 100.0 * occluded / polygons : 0.0,
              p1 ? absl::StrFormat("%.2f", 100.0 * p1->occluded_polygons / p1->polygons).c_str() : "-");

  std::printf("\nTable 2 (means per neighbourhood, times in ms; the paper's figures in brackets, its \"fully "
              "optimized\" column beside both paper and all)\n\n| | ");
  for (const Column& c : columns) std::printf("%s | ", c.opt.c_str());
  std::printf("\n|---|");
  for (size_t c = 0; c < columns.size(); ++c) std::printf("---:|");
  std::printf("\n");
  auto row2 = [&](const char* name, auto value, auto paper) {
    std::printf("| %s | ", name);
    for (const Column& c : columns) {
      const auto it = kPaperTable2.find(c.opt);
      std::printf("%s (%s) | ", value(c).c_str(), it == kPaperTable2.end() ? "-" : Paper(paper(it->second)).c_str());
    }
    std::printf("\n");
  };
  auto fmt = [](double v) { return v < 100 ? absl::StrFormat("%.2f", v) : absl::StrFormat("%.0f", v); };
  row2("total time, mean", [&](const Column& c) { return fmt(mean_of(c.ms)); },
       [](const PaperTable2& p) { return p.total_ms; });
  row2("total time, median", [&](const Column& c) { return fmt(Median(c.ms)); }, [](const PaperTable2&) { return -1.0; });
  row2("thread CPU time, mean", [&](const Column& c) { return fmt(mean_of(c.cpu_ms)); },
       [](const PaperTable2&) { return -1.0; });
  row2("thread CPU time, median", [&](const Column& c) { return fmt(Median(c.cpu_ms)); },
       [](const PaperTable2&) { return -1.0; });
  // The rows that are the mean of a figure each column sums, beside the paper's where it has one.
  struct MeanRow {
    const char* name;
    double Column::*sum;
    double PaperTable2::*paper;  // nullptr: not in the paper
  };
  const MeanRow mean_rows[] = {
      {"box occlusion time", &Column::box_ms, &PaperTable2::box_ms},
      {"polygon occlusion time", &Column::polygon_ms, &PaperTable2::polygon_ms},
      {"ray / occluder tests, boxes", &Column::box_tests, &PaperTable2::box_tests},
      {"ray / occluder tests, polygons", &Column::polygon_tests, &PaperTable2::polygon_tests},
      {"rays", &Column::rays, nullptr},
      {"Embree traversals", &Column::traversals, nullptr},
      {"visible triangles", &Column::visible_triangles, nullptr},
  };
  for (const MeanRow& r : mean_rows) {
    row2(r.name, [&](const Column& c) { return fmt(mean(c.*r.sum)); },
         [&](const PaperTable2& p) { return r.paper ? p.*r.paper : -1.0; });
  }
  return 0;
}

}  // namespace

void AddBenchEpsilonCommand(CLI::App* bench, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<BenchEpsilonArgs>(
      bench, "epsilon", "ε-superset: the paper's Tables 1 and 2 over random neighbourhoods",
      BenchEpsilon, done);
  c->add_option("--scene", args->scene, ".glb/.gltf file or catalog name (city1, city2)")->capture_default_str();
  c->add_option("--count", args->count, "neighbourhoods")->capture_default_str()->check(WholeRange(1, 1000000));
  c->add_option("--seed", args->seed, "seed of the neighbourhood sample")->check(WholeRange(0, kMaxSeed))->capture_default_str();
  c->add_option("--size", args->size, "neighbourhood edge in metres (default: a quarter of the typical object)")
      ->check(FiniteRange(1e-3, 1e5));
  c->add_option("--pvs-cell", args->pvs_cell,
                "test only the PVS of the viewcell of this size around each neighbourhood, as a server would")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--opts", args->opts, "columns: none, boxes, occluders, rays, paper, all")
      ->delimiter(',')
      ->capture_default_str()
      ->check(CLI::IsMember({"none", "boxes", "occluders", "rays", "paper", "all"}));
  c->add_flag("--json", args->json, "print one JSON object instead of the Markdown tables");
}

}  // namespace vistream::tools
