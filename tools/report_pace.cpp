#include "tools/report_pace.h"

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

namespace vistream::tools {

namespace {

using nlohmann::json;

// Issue 22's targets.
constexpr double kCellMs = 50.0, kBatchMs = 100.0, kOverestPct = 0.03, kEpsilonMs = 10.0;

// "met" or "missed by N×" for a figure that must stay at most `target`.
std::string AtMost(double value, double target) {
  if (value <= target) return "met";
  return absl::StrFormat("missed by %.2f×", value / target);
}

std::string AtLeast(double value, double target) {
  if (value >= target) return "met";
  return value > 0.0 ? absl::StrFormat("missed by %.2f×", target / value) : "missed";
}

}  // namespace

PacePlan PacePlanFor(bool quick) {
  PacePlan p;
  if (quick) {
    p.table1 = {{"default", "2"}};
    p.epsilon_scene = "city1", p.epsilon_count = "5";
    p.agvs_scenes = {"city1"};
    p.agvs_seconds = "3";
  } else {
    p.table1 = {{"london", "24"}, {"monaco", "8"}};
    p.epsilon_scene = "london", p.epsilon_count = "20";
    p.agvs_scenes = {"city1", "london"};
    p.agvs_seconds = "20";
  }
  return p;
}

void PaceSection(Page& page, const PacePlan& plan) {
  page.Heading("Visibility at the server's pace");
  page.Text("The figures the server's pace needs, each against its target: one 100 m viewcell at 128² on one core "
            "(at most 50 ms, median), the five viewcells a diagonal crossing makes adjacent in one batch on 2 "
            "threads (at most 100 ms wall, median), overestimation at 128² and 100 m (at most 0.03%), the "
            "ε-superset over a viewcell's PVS (at most 10 ms per neighbourhood, median) and AGVS's sampling rate "
            "on 2 cores (at least 2 M samples/s on city1, 1 M on london). Timed on this machine as it was during "
            "the run (see the load at the end of the page).");
  std::vector<std::vector<std::string>> rows;
  for (const PacePlan::Table1Run& run : plan.table1) {
    const std::optional<json> j =
        page.Run("bench table1 " + run.scene, {"bench", "table1", "--scene", run.scene, "--cells", run.cells, "--res", "128",
                                               "--sizes", "100", "--backends", "cpu", "--batch", "--csv", "", "--json"});
    if (!j) continue;
    for (const json& r : j->at("rows")) {
      const bool batch = r.contains("batch_cells");
      const double median = r.at("median_ms").get<double>(), over = r.at("overestimation_pct").get<double>();
      if (batch) {
        rows.push_back({run.scene, run.cells, "batch of 5, 2 threads", Fixed(r.at("ms"), 1), Fixed(median, 1),
                        AtMost(median, kBatchMs),
                        absl::StrCat(Fixed(r.at("singles_median_ms"), 1), " ms (five single calls, one core)"),
                        Fixed(over, 4), AtMost(over, kOverestPct)});
      } else {
        rows.push_back({run.scene, run.cells, "one viewcell, one core", Fixed(r.at("ms"), 1), Fixed(median, 1),
                        AtMost(median, kCellMs), "", Fixed(over, 4), AtMost(over, kOverestPct)});
      }
    }
  }
  if (!rows.empty()) {
    page.Table({"scene", "samples", "call", "ms", "median ms", "time target", "beside it", "overestimation %",
                "overestimation target"},
               rows);
  }
  if (const std::optional<json> j =
          page.Run("bench epsilon pvs", {"bench", "epsilon", "--scene", plan.epsilon_scene, "--count", plan.epsilon_count,
                                         "--opts", "all", "--pvs-cell", "100", "--json"})) {
    const json& c = j->at("table2").at(0);
    const double median = c.at("median_ms").get<double>();
    page.Table({"ε-superset over a 100 m viewcell's PVS", plan.epsilon_scene},
               {{"neighbourhoods", Int(j->at("neighbourhoods"))},
                {"PVS objects, mean", Fixed(j->at("pvs_objects"), 0)},
                {"ms per neighbourhood, mean", Fixed(c.at("ms"), 2)},
                {"ms per neighbourhood, median", Fixed(median, 2)},
                {"thread CPU ms, mean / median", Fixed(c.at("cpu_ms"), 2) + " / " + Fixed(c.at("median_cpu_ms"), 2)},
                {"target (median at most 10 ms)", AtMost(median, kEpsilonMs)}});
  }
  std::vector<std::vector<std::string>> rates;
  for (const std::string& scene : plan.agvs_scenes) {
    const std::optional<json> j =
        page.Run("agvs " + scene, {"agvs", "--scene", scene, "--seconds", plan.agvs_seconds, "--json"});
    if (!j) continue;
    const double sps = j->at("samples_per_s").get<double>();
    const double target = scene == "london" ? 1e6 : 2e6;
    rates.push_back({scene, Fixed(sps * 1e-6, 3), Fixed(j->at("rays_per_s").get<double>() * 1e-6, 3),
                     Fixed(target * 1e-6, 1), AtLeast(sps, target)});
  }
  if (!rates.empty()) page.Table({"AGVS, 2 cores", "M samples/s", "M rays/s", "target M samples/s", ""}, rates);
}

}  // namespace vistream::tools
