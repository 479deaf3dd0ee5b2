// vistream bench table1: the paper's Table 1 (Koltun, Chrysanthou, Cohen-Or 2001) with this
// project's numbers: time per viewcell and overestimation by raster resolution and viewcell
// size, for the cpu and gl backends in one run.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <map>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "gl/pvs_backend.h"
#include "scenes/catalog.h"
#include "scenes/progress.h"
#include "visibility/pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

namespace {

struct Table1Args {
  std::string scene = "london", csv = "table1.csv";
  std::vector<uint32_t> res = {16, 32, 64, 128, 256};
  std::vector<double> sizes = {50, 100, 300};
  std::vector<std::string> backends = {"cpu", "gl"};
  size_t cells = 4;
  uint64_t seed = 2001;
  bool json = false;
  bool batch = false;
};

// The paper's Table 1 (750 MHz Pentium III, ATI Rage Mobility): seconds and overestimation %,
// by resolution (rows 16..256) and viewcell size (50, 100, 300 m).
struct PaperRow {
  double seconds[3];
  double overestimation[3];
};
const std::map<uint32_t, PaperRow> kPaper = {
    {16, {{0.4, 0.5, 1.8}, {0.391, 0.518, 1.192}}},  {32, {{0.6, 0.7, 2.7}, {0.335, 0.436, 0.901}}},
    {64, {{0.9, 1.1, 4.1}, {0.185, 0.240, 0.533}}},  {128, {{2.1, 2.5, 7.8}, {0.012, 0.026, 0.106}}},
    {256, {{6.6, 7.9, 24}, {0.001, 0.005, 0.019}}}};

const PaperRow* PaperFor(uint32_t res, double size, int* column) {
  const auto it = kPaper.find(res);
  *column = size == 50 ? 0 : size == 100 ? 1 : size == 300 ? 2 : -1;
  return it == kPaper.end() || *column < 0 ? nullptr : &it->second;
}

struct Row {
  uint32_t res;
  double cell_size;
  std::string backend;
  double ms = 0, median_ms = 0;  // per viewcell
  double overestimation_pct = 0;
  double pvs_objects = 0;         // per viewcell
  // --batch rows: the five cells of a diagonal crossing in one ComputeAdjacent call on two
  // threads; ms and median_ms per batch, singles_ms the five single calls' summed time.
  size_t batch_cells = 0;
  double singles_ms = 0, singles_median_ms = 0;
};

// The batch shape: the five cells a client crossing diagonally from (i - 1, j - 1) into (i, j)
// comes to border (ViewcellGrid::NewlyAdjacent): (i + 1, j + 1), its edge neighbours (i, j + 1)
// and (i + 1, j), and those beyond them, (i - 1, j + 1) and (i + 1, j - 1). A sampled cell
// near the grid's edge is moved inwards so that all five exist.
std::vector<scenes::Aabb> DiagonalCrossing(const visibility::ViewcellGrid& grid, visibility::CellCoord c) {
  c.i = std::clamp(c.i, 1, std::max(1, grid.nx() - 2));
  c.j = std::clamp(c.j, 1, std::max(1, grid.ny() - 2));
  std::vector<scenes::Aabb> out;
  if (!grid.Valid(c) || !grid.Valid({c.i - 1, c.j - 1})) return out;
  for (visibility::CellId id : grid.NewlyAdjacent(grid.Id({c.i - 1, c.j - 1}), grid.Id(c))) out.push_back(grid.CellBox(id));
  return out;
}

// ^C: the rows measured so far are in the CSV (written as they come).
int Table1Stopped() { return Fail(absl::CancelledError("table1 stopped; a --csv file keeps the rows measured")); }

// One --batch row: per sample, the five single calls (one core) and then the batch (two
// threads), side by side; the batch's sets are checked against the single calls' and the
// exact sets.
template <typename OccludedArea>
int BatchRow(const visibility::PvsComputer& computer, const visibility::ViewcellGrid& grid,
             const std::vector<visibility::CellCoord>& samples, uint32_t res, double size,
             const visibility::CellQueryOptions& options,
             const std::vector<std::vector<std::vector<scenes::ObjectId>>>& exact_batch, OccludedArea&& occluded_area,
             scenes::Progress* progress, Row* row) {
  *row = Row{res, size, "cpu"};
  row->batch_cells = 5;
  std::vector<double> batch_ms, singles_ms;
  double p_e = 0, p_c = 0, objects = 0, cells_done = 0;
  for (size_t k = 0; k < samples.size(); ++k) {
    const std::vector<scenes::Aabb> cells = DiagonalCrossing(grid, samples[k]);
    if (cells.size() != 5) continue;
    double singles = 0;
    std::vector<std::vector<scenes::ObjectId>> single_sets;
    for (const scenes::Aabb& cell : cells) {
      visibility::PvsResult r = computer.Compute(cell, options);
      singles += r.ms;
      single_sets.push_back(std::move(r.objects));
    }
    const std::vector<visibility::PvsResult> batch = computer.ComputeAdjacent(cells, options, 2);
    for (size_t c = 0; c < cells.size(); ++c) {
      if (batch[c].objects != single_sets[c]) {
        return Fail(absl::InternalError(absl::StrFormat(
            "batch at %u^2, %g m, sample %zu, cell %zu: the batch's set differs from the single call's", res, size, k, c)));
      }
      const auto& e = exact_batch[k][c];
      if (!std::includes(batch[c].objects.begin(), batch[c].objects.end(), e.begin(), e.end())) {
        return Fail(absl::InternalError(absl::StrFormat(
            "batch at %u^2, %g m, sample %zu, cell %zu: an object the exact test sees is missing", res, size, k, c)));
      }
      p_e += occluded_area(e);
      p_c += occluded_area(batch[c].objects);
      objects += static_cast<double>(batch[c].objects.size());
      ++cells_done;
    }
    batch_ms.push_back(batch[0].ms);
    singles_ms.push_back(singles);
    progress->Advance();
    if (progress->Cancelled()) return Table1Stopped();
  }
  double sum = 0, singles_sum = 0;
  for (double m : batch_ms) sum += m;
  for (double m : singles_ms) singles_sum += m;
  const double n = std::max<double>(1.0, static_cast<double>(batch_ms.size()));
  row->ms = sum / n;
  row->median_ms = Median(batch_ms);
  row->singles_ms = singles_sum / n;
  row->singles_median_ms = Median(singles_ms);
  row->pvs_objects = objects / std::max(1.0, cells_done);
  row->overestimation_pct = p_e > 0 ? 100.0 * (p_e - p_c) / p_e : 0.0;
  row->backend = "cpu";
  return 0;
}

int Table1(const Table1Args& a) {
  if (a.json) ToolProgress().set_quiet(true);
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene);
  if (!scene.ok()) return Fail(scene.status());
  scenes::ViewcellSpec spec;
  if (auto entry = scenes::FindCatalogEntry(a.scene); entry.ok()) spec = entry->viewcell;
  const visibility::KdTree tree = visibility::KdTree::Build(*scene);
  const visibility::PvsComputer computer(*scene, tree);

  std::map<std::string, gl::PvsBackend> backends;
  for (const std::string& name : a.backends) {
    absl::StatusOr<gl::PvsBackend> b = gl::PvsBackend::Create(name);
    if (!b.ok()) return Fail(b.status());
    backends.emplace(name, std::move(*b));
  }
  const absl::StatusOr<gl::PvsBackend> exact = gl::PvsBackend::Create("exact");

  // The ground area of an object, the unit in which occluded area is counted.
  auto area = [&](scenes::ObjectId id) {
    const scenes::Aabb& b = scene->objects[id].bounds;
    return (b.max.x - b.min.x) * (b.max.y - b.min.y);
  };
  double total_area = 0;
  for (const scenes::Object& o : scene->objects) total_area += area(o.id);
  auto occluded_area = [&](const std::vector<scenes::ObjectId>& pvs) {
    double visible = 0;
    for (scenes::ObjectId id : pvs) visible += area(id);
    return total_area - visible;
  };

  // Rows go to the CSV as they come, so a long run that is stopped keeps what it measured.
  std::ofstream csv;
  if (!a.csv.empty()) {
    csv.open(a.csv);
    csv << "res,cell_size,backend,ms,median_ms,overestimation_pct,pvs_objects\n" << std::flush;
    if (!csv) return Fail(absl::UnavailableError("cannot write " + a.csv));
  }
  std::vector<Row> rows;
  nlohmann::json exact_json = nlohmann::json::array();
  // A step: one viewcell's query per resolution and backend and its exact set; with --batch also
  // one sample's five exact sets, and its batch and five single calls per resolution.
  const size_t per_cell = 1 + a.res.size() * a.backends.size() + (a.batch ? 1 + a.res.size() : 0);
  scenes::Progress progress(ToolRun(), "table1", a.sizes.size() * a.cells * per_cell);
  for (double size : a.sizes) {
    scenes::ViewcellSpec sized = spec;
    sized.size_m = size;
    sized.height_m = 2.0;
    absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, sized);
    if (!grid.ok()) return Fail(grid.status());
    std::vector<scenes::Aabb> cells;
    const std::vector<visibility::CellCoord> samples = grid->Sample(a.cells, a.seed);
    for (const visibility::CellCoord c : samples) cells.push_back(grid->CellBox(c));
    // --batch: the exact sets of each sample's five cells, once.
    std::vector<std::vector<std::vector<scenes::ObjectId>>> exact_batch;
    Row row_out{0, size, "cpu"};
    if (a.batch) {
      for (const visibility::CellCoord c : samples) {
        exact_batch.emplace_back();
        for (const scenes::Aabb& cell : DiagonalCrossing(*grid, c)) {
          exact_batch.back().push_back(
              exact->Compute(computer, cell, visibility::CellQueryOptions{.max_res = 256}).objects);
        }
        progress.Advance();
        if (progress.Cancelled()) return Table1Stopped();
      }
    }

    // The exact planar test, once per viewcell: P_E.
    std::vector<double> exact_occluded;
    std::vector<std::vector<scenes::ObjectId>> exact_pvs;
    double exact_ms = 0, exact_objects = 0;
    for (const scenes::Aabb& cell : cells) {
      const visibility::PvsResult r = exact->Compute(computer, cell, visibility::CellQueryOptions{.max_res = 256});
      exact_occluded.push_back(occluded_area(r.objects));
      exact_pvs.push_back(r.objects);
      exact_ms += r.ms;
      exact_objects += static_cast<double>(r.objects.size());
      progress.Advance();
      if (progress.Cancelled()) return Table1Stopped();
    }
    exact_json.push_back({{"cell_size", size},
                          {"ms", exact_ms / static_cast<double>(cells.size())},
                          {"pvs_objects", exact_objects / static_cast<double>(cells.size())}});

    for (uint32_t res : a.res) {
      const visibility::CellQueryOptions options{.min_res = std::min(16u, res), .max_res = res};
      for (const std::string& backend : a.backends) {
        Row row{res, size, backend};
        std::vector<double> ms;
        double p_e = 0, p_c = 0;
        for (size_t k = 0; k < cells.size(); ++k) {
          const visibility::PvsResult r = backends.at(backend).Compute(computer, cells[k], options);
          // The exact set must lie inside every conservative one: a self-check, not a figure.
          if (!std::includes(r.objects.begin(), r.objects.end(), exact_pvs[k].begin(), exact_pvs[k].end())) {
            return Fail(absl::InternalError(absl::StrFormat(
                "%s backend at %u^2, %g m viewcell %zu: an object the exact test sees is missing", backend, res,
                size, k)));
          }
          ms.push_back(r.ms);
          row.pvs_objects += static_cast<double>(r.objects.size());
          p_e += exact_occluded[k];
          p_c += occluded_area(r.objects);
          progress.Advance();
          if (progress.Cancelled()) return Table1Stopped();
        }
        const auto n = static_cast<double>(cells.size());
        double sum = 0;
        for (double m : ms) sum += m;
        row.ms = sum / n;
        row.median_ms = Median(ms);
        row.pvs_objects /= n;
        row.overestimation_pct = p_e > 0 ? 100.0 * (p_e - p_c) / p_e : 0.0;
        rows.push_back(row);
        if (csv.is_open()) {
          csv << absl::StrFormat("%u,%g,%s,%.3f,%.3f,%.6f,%.1f\n", row.res, row.cell_size, row.backend, row.ms,
                                 row.median_ms, row.overestimation_pct, row.pvs_objects)
              << std::flush;
        }
        if (!a.json) {
          std::fprintf(stderr, "table1: %u^2, %g m, %s: %.1f ms per viewcell, overestimation %.4f%%\n", res, size,
                       backend.c_str(), row.ms, row.overestimation_pct);
        }
      }
      if (a.batch) {
        const int status = BatchRow(computer, *grid, samples, res, size, options, exact_batch, occluded_area, &progress,
                                    &row_out);
        if (status != 0) return status;
        rows.push_back(row_out);
        if (csv.is_open()) {
          csv << absl::StrFormat("%u,%g,%s,%.3f,%.3f,%.6f,%.1f\n", row_out.res, row_out.cell_size, row_out.backend,
                                 row_out.ms, row_out.median_ms, row_out.overestimation_pct, row_out.pvs_objects)
              << std::flush;
        }
        if (!a.json) {
          std::fprintf(stderr, "table1: %u^2, %g m, batch of 5 on 2 threads: %.1f ms per batch (five single calls: %.1f ms)\n",
                       res, size, row_out.ms, row_out.singles_ms);
        }
      }
    }
  }
  progress.Finish();

  if (csv.is_open() && !csv) return Fail(absl::UnavailableError("cannot write " + a.csv));

  if (a.json) {
    nlohmann::json j;
    j["scene"] = scene->name;
    j["objects"] = scene->objects.size();
    j["cells_per_size"] = a.cells;
    j["seed"] = a.seed;
    j["rows"] = nlohmann::json::array();
    for (const Row& r : rows) {
      nlohmann::json row = {{"res", r.res},
                            {"cell_size", r.cell_size},
                            {"backend", r.backend},
                            {"ms", r.ms},
                            {"median_ms", r.median_ms},
                            {"overestimation_pct", r.overestimation_pct},
                            {"pvs_objects", r.pvs_objects}};
      if (r.batch_cells > 0) {
        row["batch_cells"] = r.batch_cells;
        row["batch_threads"] = 2;
        row["singles_ms"] = r.singles_ms;
        row["singles_median_ms"] = r.singles_median_ms;
      }
      j["rows"].push_back(row);
    }
    j["exact"] = exact_json;
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }

  std::printf("Table 1 on %s (%zu objects): mean per viewcell over %zu viewcells per size (2 m high), one "
              "core for cpu.\nOverestimation (P_E - P_C) / P_E: occluded ground area, counted as the objects' "
              "ground boxes, exact test vs raster.\n\n",
              scene->name.c_str(), scene->objects.size(), a.cells);
  std::printf("| res | viewcell | backend | ms | median ms | overest. %% | PVS objects | paper s | paper overest. %% |\n");
  std::printf("|---:|---:|---|---:|---:|---:|---:|---:|---:|\n");
  for (const Row& r : rows) {
    int column = -1;
    const PaperRow* paper = PaperFor(r.res, r.cell_size, &column);
    const std::string ps = paper ? absl::StrFormat("%g", paper->seconds[column]) : "-";
    const std::string po = paper ? absl::StrFormat("%.3f", paper->overestimation[column]) : "-";
    const std::string name = r.batch_cells > 0 ? r.backend + ", batch of 5" : r.backend;
    std::printf("| %u² | %g m | %s | %.1f | %.1f | %.4f | %.0f | %s | %s |\n", r.res, r.cell_size, name.c_str(),
                r.ms, r.median_ms, r.overestimation_pct, r.pvs_objects, r.batch_cells > 0 ? "-" : ps.c_str(),
                r.batch_cells > 0 ? "-" : po.c_str());
  }
  // The ratio the targets ask for, measured side by side.
  std::printf("\n");
  for (const Row& r : rows) {
    if (r.batch_cells == 0) continue;
    std::printf("batch of 5 at %u², %g m: %.1f ms median on 2 threads; the five single calls %.1f ms median on one core\n",
                r.res, r.cell_size, r.median_ms, r.singles_median_ms);
  }
  for (const Row& r : rows) {
    if (r.backend != "gl" || r.batch_cells > 0) continue;
    for (const Row& c : rows) {
      if (c.backend == "cpu" && c.batch_cells == 0 && c.res == r.res && c.cell_size == r.cell_size && c.ms > 0) {
        std::printf("gl / cpu at %u², %g m: %.1fx\n", r.res, r.cell_size, r.ms / c.ms);
      }
    }
  }
  for (const auto& e : exact_json) {
    std::printf("exact, %g m: %.1f ms, %.0f PVS objects per viewcell\n", e["cell_size"].get<double>(),
                e["ms"].get<double>(), e["pvs_objects"].get<double>());
  }
  if (!a.csv.empty()) std::printf("csv: %s\n", a.csv.c_str());
  return 0;
}

}  // namespace

void AddBenchCommands(CLI::App& app, std::function<void(int)> done) {
  CLI::App* bench = AddCommandGroup(app, "bench", "benchmarks that reproduce the papers' tables");
  auto [c, args] = AddSubcommand<Table1Args>(
      bench, "table1", "dual ray space: time and overestimation by resolution and size", Table1,
      done);
  c->add_option("--scene", args->scene, ".glb/.gltf file or catalog name")->capture_default_str();
  c->add_option("--cells", args->cells, "viewcells sampled per size")->capture_default_str()->check(WholeRange(1, 1000000));
  c->add_option("--seed", args->seed, "seed of the viewcell sample")->check(WholeRange(0, kMaxSeed))->capture_default_str();
  c->add_option("--res", args->res, "raster resolutions")->delimiter(',')->capture_default_str()->check(PowerOfTwo(1, 256));
  c->add_option("--sizes", args->sizes, "viewcell sizes in metres")->delimiter(',')->capture_default_str()
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--backends", args->backends, "cpu, gl")->delimiter(',')->capture_default_str()
      ->check(CLI::IsMember({"cpu", "gl"}));
  c->add_option("--csv", args->csv, "CSV output ('' for none)")->capture_default_str();
  c->add_flag("--json", args->json, "print one JSON object instead of the Markdown table");
  c->add_flag("--batch", args->batch,
              "also a cpu row per resolution and size for batches of five adjacent viewcells (a "
              "diagonal crossing) on 2 threads");
  AddBenchEpsilonCommand(bench, done);
  AddBenchAgvsCommand(bench, done);
  AddBenchServerCommand(bench, done);
  AddBenchClientCommand(bench, done);
  AddBenchWebCommand(bench, done);
}

}  // namespace vistream::tools
