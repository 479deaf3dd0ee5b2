// vistream report: regenerates every published figure as a Markdown page with PNG plots and
// maps. Each step runs this same binary (/proc/self/exe) as a subprocess with --json, so that
// every number in the page is what that command printed, and the page names the command.
// Full mode uses the published figures' scenes and sizes (docs/benchmarks.md; london: an hour
// or more); --quick uses the small scenes and counts (minutes, for CI).
#include <sys/resource.h>
#include <sys/utsname.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>

#include <CLI/CLI.hpp>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/numbers.h>
#include <absl/strings/str_join.h>
#include <absl/strings/str_split.h>
#include <absl/strings/strip.h>
#include <absl/strings/ascii.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/gnuplot.h"
#include "tools/report_latency.h"
#include "tools/report_levels.h"
#include "tools/report_pace.h"
#include "tools/report_page.h"
#include "tools/subprocess.h"

namespace vistream::tools {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct ReportArgs {
  std::string out;  // default: bench/figures (full), bench/figures/quick (--quick: never over the full run)
  bool quick = false;
  bool json = false;
};

// What each mode measures. Full: the published figures (docs/benchmarks.md); quick: the same
// sections, small.
struct Plan {
  std::string table1_scene;
  std::vector<std::string> table1_extra;  // options after --scene
  std::vector<std::string> epsilon_scenes;
  std::string epsilon_count;
  std::string agvs_scene, agvs_seconds, agvs_views;
  std::string pvs_scene, pvs_cell;
  std::string heatmap_scene, heatmap_seconds;
  std::string map_scene;
  std::string city_scene;  // an imported city model (issue 35)
  LatencyPlan latency;
  PacePlan pace;
  LevelsPlan levels;
};

Plan PlanFor(bool quick) {
  Plan p;
  if (quick) {
    p.table1_scene = "default";
    p.table1_extra = {"--cells", "2", "--sizes", "50,100,300", "--backends", "cpu"};
    p.epsilon_scenes = {"city1"};
    p.epsilon_count = "10";
    p.agvs_scene = "city1", p.agvs_seconds = "4", p.agvs_views = "4";
    p.pvs_scene = "default", p.pvs_cell = "10,10";
    p.heatmap_scene = "city1", p.heatmap_seconds = "4";
    p.map_scene = "default";
  } else {
    p.table1_scene = "london";
    p.table1_extra = {"--cells", "3"};
    p.epsilon_scenes = {"city1", "city2"};
    p.epsilon_count = "100";
    p.agvs_scene = "london", p.agvs_seconds = "60", p.agvs_views = "24";
    p.pvs_scene = "monaco", p.pvs_cell = "115,43";
    p.heatmap_scene = "london", p.heatmap_seconds = "60";
    p.map_scene = "london";
  }
  // The quick page: Delft (591 objects, imported in under two seconds: the quick report is
  // a CI test); the full one Den Haag (2,032 objects). CI has the data folder (.ci/run).
  p.city_scene = quick ? "delft" : "denhaag";
  p.latency = LatencyPlanFor(quick);
  p.pace = PacePlanFor(quick);
  p.levels = LevelsPlanFor(quick);
  return p;
}

// The stamp: UTC date, commit (dirty when the tree has changes), machine.
std::string Stamp() {
  const std::time_t now = std::time(nullptr);
  char date[64];
  std::strftime(date, sizeof(date), "%Y-%m-%d %H:%M UTC", std::gmtime(&now));
  std::string commit = "unknown (not a git checkout)";
  if (absl::StatusOr<ProcessResult> r = RunProcess({"git", "rev-parse", "--short", "HEAD"}); r.ok() && r->exit_code == 0) {
    commit = std::string(absl::StripAsciiWhitespace(r->out));
    absl::StatusOr<ProcessResult> s = RunProcess({"git", "status", "--porcelain", "--untracked-files=no"});
    if (s.ok() && s->exit_code == 0 && !absl::StripAsciiWhitespace(s->out).empty()) commit += " (dirty: uncommitted changes)";
  }
  std::string cpu = "unknown CPU";
  if (absl::StatusOr<std::string> info = ReadFile("/proc/cpuinfo"); info.ok()) {
    const size_t at = info->find("model name");
    if (at != std::string::npos) {
      const size_t colon = info->find(':', at), end = info->find('\n', at);
      if (colon != std::string::npos && colon < end) cpu = std::string(absl::StripAsciiWhitespace(info->substr(colon + 1, end - colon - 1)));
    }
  }
  const long cores = sysconf(_SC_NPROCESSORS_ONLN);
  const double gib = static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGE_SIZE)) /
                     (1024.0 * 1024.0 * 1024.0);
  utsname u{};
  uname(&u);
  return absl::StrFormat("%s; commit %s; machine: %s, %ld cores, %.1f GiB memory (%s %s)", date, commit, cpu, cores,
                         gib, u.sysname, u.machine);
}

// The maps' longer side: enough for a street's width at city scale, and PNGs near 1 MB.
constexpr const char* kMapPixels = "1400";

// The machine's CPU time so far (/proc/stat, all cores): busy (user, nice, system, irq,
// softirq) and stolen by the host, in seconds.
struct MachineCpu {
  double busy_s = 0.0, steal_s = 0.0;
};
std::optional<MachineCpu> ReadMachineCpu() {
  absl::StatusOr<std::string> stat = ReadFile("/proc/stat");
  if (!stat.ok() || stat->rfind("cpu ", 0) != 0) return std::nullopt;
  const std::vector<std::string> f =
      absl::StrSplit(stat->substr(0, stat->find('\n')), ' ', absl::SkipEmpty());  // cpu user nice system idle iowait irq softirq steal
  if (f.size() < 9) return std::nullopt;
  double v[8];
  for (int k = 0; k < 8; ++k) {
    if (!absl::SimpleAtod(f[static_cast<size_t>(k) + 1], &v[k])) return std::nullopt;
  }
  const double tick = static_cast<double>(sysconf(_SC_CLK_TCK));
  return MachineCpu{(v[0] + v[1] + v[2] + v[5] + v[6]) / tick, v[7] / tick};
}

// CPU seconds used by this process and its waited-for children.
double OwnCpuSeconds() {
  auto secs = [](const timeval& t) { return static_cast<double>(t.tv_sec) + 1e-6 * static_cast<double>(t.tv_usec); };
  rusage self{}, children{};
  getrusage(RUSAGE_SELF, &self);
  getrusage(RUSAGE_CHILDREN, &children);
  return secs(self.ru_utime) + secs(self.ru_stime) + secs(children.ru_utime) + secs(children.ru_stime);
}

// --- the sections -------------------------------------------------------------------------

void SceneSection(Page& page, const Plan& plan) {
  page.Heading("Scene");
  const std::string png = "scene_" + plan.map_scene + ".png";
  const std::optional<json> info = page.Run("scene info", {"scene", "info", plan.map_scene, "--json"});
  if (info) {
    page.Table({"scene", "objects", "triangles", "occluders", "area km²", "height m"},
               {{info->value("name", ""), Int(info->at("objects")), Int(info->at("triangles")),
                 Int(info->at("occluders")), Fixed(info->at("area_km2"), 2),
                 Fixed(info->at("bounds").at("max")[2].get<double>() - info->at("bounds").at("min")[2].get<double>(), 1)}});
  }
  if (page.RunForFile("scene map", {"scene", "map", plan.map_scene, "-o", page.Path(png), "--size", kMapPixels}, png)) {
    page.Image(png, plan.map_scene + ": building footprints by height and the catalog's walks");
  }
}

// What a city model import gave (scene info of the catalog entry: it imports the file), its
// map, and its PVSs at 100 m viewcells against the same city's footprints extruded as
// OpenStreetMap would draw them (scene extrude): how much of the extrusions' culling the real
// roofs and the synthesised occluders keep.
void CitySection(Page& page, const Plan& plan) {
  page.Heading("A city model: " + plan.city_scene);
  const std::optional<json> info = page.Run("scene info (city)", {"scene", "info", plan.city_scene, "--json"});
  if (info) {
    const json& types = info->at("objects_by_type");
    const uint64_t buildings = types.value("Building", uint64_t{0}) + types.value("BuildingPart", uint64_t{0});
    const json& terrain = info->at("terrain");
    page.Table({"scene", "CRS", "buildings and parts", "occluding objects", "occluder volume / solids' volume",
                "terrain relief m", "terrain tiles", "triangles"},
               {{info->value("name", ""), info->value("crs", ""), Int(buildings), Int(info->at("objects_with_occluder")),
                 Fixed(100.0 * info->at("occluder_volume_share").get<double>(), 1) + "%",
                 Fixed(terrain.at("relief_m"), 1), Int(terrain.at("objects")), Int(info->at("triangles"))}});
  }
  const std::string png = "city_" + plan.city_scene + ".png";
  if (page.RunForFile("scene map (city)", {"scene", "map", plan.city_scene, "-o", page.Path(png), "--size", kMapPixels},
                      png)) {
    page.Image(png, plan.city_scene + ": footprints by height over the terrain, objects without occluders grey, derived walks");
  }
  // The extrusion and the PVS files are scratch: they go to a temporary folder, not the page's.
  std::error_code ec;
  const fs::path scratch = fs::temp_directory_path(ec) / ("vistream-report-" + std::to_string(getpid()));
  fs::create_directories(scratch, ec);
  const std::string extruded = (scratch / (plan.city_scene + "-extruded.glb")).string();
  const std::optional<json> ext =
      page.Run("scene extrude", {"scene", "extrude", plan.city_scene, "-o", extruded, "--json"});
  std::vector<std::vector<std::string>> rows;
  const std::pair<std::string, std::string> models[] = {{"LoD2, occluders synthesised", plan.city_scene},
                                                        {"footprints extruded (OSM-style)", extruded}};
  for (const auto& [model, scene] : models) {
    if (scene == extruded && !ext) continue;
    const std::optional<json> pvs =
        page.Run("pvs --all (city)", {"pvs", "--scene", scene, "--all", "--cell-size", "100", "-o",
                                      (scratch / "city.pvs").string(), "--json"});
    if (!pvs) continue;
    // Buildings and their parts (a city without parts, Delft, has no BuildingPart entry).
    const json& by = pvs->at("by_type");
    auto sum = [&by](const char* key) {
      double total = 0.0;
      for (const char* type : {"Building", "BuildingPart"}) {
        if (by.contains(type)) total += by.at(type).at(key).get<double>();
      }
      return total;
    };
    const double mean = sum("mean_pvs_objects"), all = sum("objects");
    if (all == 0.0) continue;
    rows.push_back({model, Int(pvs->at("cells")), Fixed(mean, 1), Fixed(all, 0), Fixed(100.0 * mean / all, 1) + "%"});
  }
  fs::remove_all(scratch, ec);
  if (!rows.empty()) {
    page.Table({"model", "100 m viewcells", "mean buildings and parts in a PVS", "of", "share"}, rows);
  }
}

void Table1Section(Page& page, const Plan& plan) {
  page.Heading("Table 1 of Koltun et al. 2001: dual ray space by resolution and viewcell size");
  std::vector<std::string> args = {"bench", "table1", "--scene", plan.table1_scene};
  args.insert(args.end(), plan.table1_extra.begin(), plan.table1_extra.end());
  args.insert(args.end(), {"--csv", "", "--json"});
  const std::optional<json> j = page.Run("bench table1", args);
  if (!j) return;
  page.Text(absl::StrFormat("%s, %s objects, %s sampled viewcells per size (seed %s). Times are the mean per "
                            "viewcell; overestimation is (P_E − P_C) / P_E, where P_E is the ground area of the "
                            "objects the exact test finds occluded and P_C that of the objects the raster "
                            "(the conservative test) finds occluded.",
                            j->value("scene", ""), Int(j->at("objects")), Int(j->at("cells_per_size")),
                            Number(j->at("seed"))));
  std::vector<std::vector<std::string>> rows;
  std::map<std::pair<double, std::string>, GnuplotData> series;  // (size, backend) -> res, ms, overestimation
  double res_lo = 1e9, res_hi = 0;
  for (const json& r : j->at("rows")) {
    const std::string res = Int(r.at("res")), size = Number(r.at("cell_size"));
    rows.push_back({res + "²", size + " m", r.value("backend", ""), Fixed(r.at("ms"), 1), Fixed(r.at("median_ms"), 1),
                    Fixed(r.at("overestimation_pct"), 4), Fixed(r.at("pvs_objects"), 0)});
    GnuplotData& d = series[{r.at("cell_size").get<double>(), r.value("backend", "")}];
    res_lo = std::min(res_lo, r.at("res").get<double>());
    res_hi = std::max(res_hi, r.at("res").get<double>());
    absl::StrAppend(&d.text, res, " ", r.at("ms").get<double>(), " ", r.at("overestimation_pct").get<double>(), "\n");
  }
  page.Table({"resolution", "viewcell", "backend", "ms", "median ms", "overestimation %", "PVS objects"}, rows);
  std::vector<std::vector<std::string>> exact;
  for (const json& e : j->at("exact")) {
    exact.push_back({Number(e.at("cell_size")) + " m", Fixed(e.at("ms"), 1), Fixed(e.at("pvs_objects"), 0)});
  }
  page.Text("The exact planar test (CGAL), which the overestimation is measured against:");
  page.Table({"viewcell", "exact ms", "exact PVS objects"}, exact);

  GnuplotPlot plot = GnuplotPlot::Kept(page.Path("table1_" + plan.table1_scene + ".png"), 1200, 1000);
  std::string ms_plot, over_plot;
  int k = 0;
  for (auto& [size_backend, d] : series) {
    const std::string key = absl::StrCat(absl::StrFormat("%g", size_backend.first), " m, ", size_backend.second);
    d.name = absl::StrCat("series", k++, ".dat");
    absl::StrAppend(&ms_plot, ms_plot.empty() ? "plot " : ", ", GnuplotQuote(d.name), " using 1:2 with linespoints lw 2 pt 7 title ",
                    GnuplotQuote(key));
    absl::StrAppend(&over_plot, over_plot.empty() ? "plot " : ", ", GnuplotQuote(d.name),
                    " using 1:($3 > 0 ? $3 : NaN) with linespoints lw 2 pt 7 title ", GnuplotQuote(key));
    plot.data.push_back(d);
  }
  plot.script = absl::StrCat(
      "set multiplot layout 2,1 title ",
      GnuplotQuote(absl::StrCat("Dual ray space on ", j->value("scene", ""), ": time and overestimation by raster resolution")),
      " font ',15'\n", "set grid lc rgb '#d0d0d0'\n", "set logscale x 2\n", "set xtics (1, 2, 4, 8, 16, 32, 64, 128, 256)\n",
      absl::StrFormat("set xrange [%g:%g]\n", res_lo / 1.25, res_hi * 1.25),
      "set xlabel 'raster resolution (pixels per side of the dual ray space, log scale)'\n",
      "set key outside right box\n", "set logscale y 10\n", "set title 'Time per viewcell'\n",
      "set ylabel 'time per viewcell (ms, log scale)'\n", ms_plot, "\n",
      "set title 'Overestimation (points at 0 are left out of the log scale)'\n",
      "set ylabel 'overestimation (% of occluded area, log scale)'\n", over_plot, "\n", "unset multiplot\n");
  const std::string png = "table1_" + plan.table1_scene + ".png";
  if (page.Plot("Table 1 plot", plot)) page.Image(png, "Time and overestimation against raster resolution");
}

void EpsilonSection(Page& page, const Plan& plan) {
  page.Heading("Tables 1 and 2 of Cohen-Or and Zadicario 1998: the ε-superset");
  for (const std::string& scene : plan.epsilon_scenes) {
    const std::optional<json> j =
        page.Run("bench epsilon " + scene, {"bench", "epsilon", "--scene", scene, "--count", plan.epsilon_count, "--json"});
    if (!j) continue;
    page.Text(absl::StrFormat("%s: %s random ground-level neighbourhoods of %s m (seed %s), %s convex prisms; means "
                              "per neighbourhood, one core.",
                              scene, Int(j->at("neighbourhoods")), Fixed(j->at("size"), 2), Number(j->at("seed")),
                              Int(j->at("prisms"))));
    const json& t1 = j->at("table1");
    page.Table({"Table 1 (column " + t1.value("opt", "") + ")", scene},
               {{"total polygons (triangles)", Fixed(t1.at("total_polygons"), 0)},
                {"occluded polygons", Fixed(t1.at("occluded_polygons"), 0)},
                {"occluded polygons %", Fixed(t1.at("occluded_polygons_pct"), 2)},
                {"total bounding boxes", Fixed(t1.at("total_boxes"), 0)},
                {"occluded boxes", Fixed(t1.at("occluded_boxes"), 0)},
                {"first occluders", Fixed(t1.at("first_occluders"), 0)}});
    std::vector<std::string> head = {"Table 2"};
    const json& t2 = j->at("table2");
    for (const json& c : t2) head.push_back(c.value("opt", ""));
    std::vector<std::vector<std::string>> rows;
    for (const auto& [key, name, digits] : std::vector<std::tuple<std::string, std::string, int>>{
             {"ms", "total ms, mean", 2},
             {"median_ms", "total ms, median", 2},
             {"box_ms", "box occlusion ms", 2},
             {"polygon_ms", "polygon occlusion ms", 2},
             {"box_ray_tests", "segment / prism tests, boxes", 0},
             {"polygon_ray_tests", "segment / prism tests, polygons", 0},
             {"rays", "rays", 0},
             {"traversals", "Embree traversals", 0},
             {"visible_triangles", "visible triangles", 0}}) {
      std::vector<std::string> row = {name};
      for (const json& c : t2) row.push_back(Fixed(c.at(key), digits));
      rows.push_back(row);
    }
    page.Table(head, rows);
  }
}

void AgvsSection(Page& page, const Plan& plan) {
  page.Heading("Global visibility sampling: AGVS, SGVS and REF (Bittner et al. 2009)");
  const std::string png = "agvs_" + plan.agvs_scene + ".png";
  const std::optional<json> j =
      page.Run("bench agvs", {"bench", "agvs", "--scene", plan.agvs_scene, "--seconds", plan.agvs_seconds, "--views",
                              plan.agvs_views, "--plot", page.Path(png), "--json"});
  if (!j) return;
  page.Text(absl::StrFormat("%s: %s viewcells of %s m, %s objects; %s s of sampling each, side by side; %s rendered "
                            "views (cube maps of %s²). Pixel error is of a 1024 × 1024 camera: estimated by the "
                            "sampler / measured by rendering.",
                            j->value("scene", ""), Int(j->at("cells")), Number(j->at("cell_size")),
                            Int(j->at("objects")), Number(j->at("seconds")), Int(j->at("views")),
                            Int(j->at("view_resolution"))));
  const json& st = j->at("strategies");
  std::vector<std::vector<std::string>> rows;
  const size_t n = st.at("agvs").at("checkpoints").size();
  for (size_t k = 0; k < n; ++k) {
    std::vector<std::string> row = {Fixed(st.at("agvs").at("checkpoints")[k].at("seconds"), 2)};
    for (const char* s : {"agvs", "sgvs", "ref"}) {
      const json& cps = st.at(s).at("checkpoints");
      if (k < cps.size()) {
        row.push_back(Fixed(cps[k].at("mean_pvs_objects"), 1));
        row.push_back(Fixed(cps[k].at("estimated_pixel_error"), 0) + " / " + Fixed(cps[k].at("measured_pixel_error"), 0));
      } else {
        row.insert(row.end(), {"–", "–"});
      }
    }
    rows.push_back(row);
  }
  page.Table({"seconds", "AGVS objects", "AGVS est. / meas. px", "SGVS objects", "SGVS est. / meas. px", "REF objects",
              "REF est. / meas. px"},
             rows);
  std::vector<std::vector<std::string>> rates;
  for (const char* s : {"agvs", "sgvs", "ref"}) {
    const json& t = st.at(s);
    const double reach = t.at("time_to_ref_final").get<double>();
    rates.push_back({s, Fixed(t.at("samples_per_s").get<double>() * 1e-6, 3), Fixed(t.at("rays_per_s").get<double>() * 1e-6, 3),
                     Fixed(t.at("final_mean_pvs_objects"), 1), reach > 0 ? Fixed(reach, 2) : "never",
                     reach > 0 ? Fixed(t.at("speedup_vs_ref"), 1) + "×" : "–"});
  }
  page.Table({"strategy", "M samples/s", "M rays/s", "final mean PVS objects", "s to REF's final size", "sooner than REF"},
             rates);
  if (page.CheckFile(png)) page.Image(png, "AGVS, SGVS and REF: mean PVS size and pixel error against sampling time");
}

void MapsSection(Page& page, const Plan& plan) {
  page.Heading("PVS maps");
  const std::string pvs_png = "pvs_" + plan.pvs_scene + ".png";
  const std::optional<json> p = page.Run(
      "pvs --map", {"pvs", "--scene", plan.pvs_scene, "--cell", plan.pvs_cell, "--json", "--map", page.Path(pvs_png), "--map-size", kMapPixels});
  if (p) {
    page.Table({"scene", "viewcell", "backend", "raster", "PVS objects", "of", "PVS triangles", "of", "ms"},
               {{p->value("scene", ""), plan.pvs_cell, p->value("backend", ""), Int(p->at("res")) + "²",
                 Int(p->at("pvs_objects")), Int(p->at("total_objects")), Int(p->at("pvs_triangles")),
                 Int(p->at("total_triangles")), Fixed(p->at("ms"), 1)}});
    if (page.CheckFile(pvs_png)) page.Image(pvs_png, "The PVS of one viewcell");
  }
  const std::string eps_png = "epsilon_city1.png";
  const std::optional<json> e = page.Run("epsilon --map", {"epsilon", "--scene", "city1", "--at", "0,0,2", "--size",
                                                           "3.75", "--json", "--map", page.Path(eps_png)});
  if (e) {
    page.Table({"scene", "neighbourhood", "optimisations", "triangles left", "of", "objects left", "of", "ms"},
               {{e->value("scene", ""), "3.75 m box at (0, 0, 2)", e->value("opt", ""), Int(e->at("visible_triangles")),
                 Int(e->at("total_triangles")), Int(e->at("visible_objects")), Int(e->at("total_objects")),
                 Fixed(e->at("ms"), 2)}});
    if (page.CheckFile(eps_png)) page.Image(eps_png, "The ε-superset of a small neighbourhood");
  }
}

void HeatmapSection(Page& page, const Plan& plan) {
  page.Heading("PVS cost heatmap");
  const std::string png = "heatmap_" + plan.heatmap_scene + ".png";
  const std::optional<json> h =
      page.Run("agvs heatmap", {"agvs", "heatmap", "--scene", plan.heatmap_scene, "--seconds", plan.heatmap_seconds,
                                "-o", page.Path(png), "--size", kMapPixels, "--json"});
  if (!h) return;
  page.Table({"scene", "viewcells", "mean PVS triangles", "max PVS triangles"},
             {{h->value("scene", ""), Int(h->at("cells")), Fixed(h->at("mean_pvs_triangles"), 0),
               Int(h->at("max_pvs_triangles"))}});
  if (page.CheckFile(png)) page.Image(png, "PVS cost of every viewcell (AGVS)");
}

int Report(const ReportArgs& given) {
  ReportArgs a = given;
  if (a.out.empty()) a.out = a.quick ? "bench/figures/quick" : "bench/figures";
  std::error_code ec;
  fs::create_directories(a.out, ec);
  if (ec || !fs::is_directory(a.out)) {
    return BadOption("report", "--out", absl::StrCat("'", a.out, "': cannot make the folder (",
                                                      ec ? ec.message() : "not a folder", ")"));
  }
  if (access(a.out.c_str(), W_OK) != 0) return BadOption("report", "--out", absl::StrCat("'", a.out, "': not writable"));
  const std::string self = fs::read_symlink("/proc/self/exe", ec).string();
  if (ec) return Fail(absl::InternalError("cannot find this program (/proc/self/exe): " + ec.message()));

  const Plan plan = PlanFor(a.quick);
  // An older page would stand beside the PNGs this run replaces: it goes first, and a run that
  // is stopped (^C, or SIGTERM, which here stops the running step too) writes none.
  const std::string stamp = Stamp();  // first: removing the page would make the checkout look dirty
  fs::remove(fs::path(a.out) / "report.md", ec);
  std::signal(SIGTERM, [](int) { CancelFlag().store(true); });
  Page page(self, a.out);
  const auto start = std::chrono::steady_clock::now();
  const std::optional<MachineCpu> cpu_start = ReadMachineCpu();
  const double own_start = OwnCpuSeconds();
  page.Title(a.quick ? "vistream figures (quick)" : "vistream figures");
  page.Text(absl::StrCat("Generated by `vistream report", a.quick ? " --quick" : "", "`: ", stamp, "."));
  page.Text(absl::StrCat(
      "Every number and figure below was produced by the command its section names (run by the report as a "
      "subprocess with --json, its output parsed); nothing is typed by hand. ",
      a.quick ? "Quick mode: small scenes and counts, for CI; the published figures (docs/benchmarks.md) come "
                "from the full run."
              : "Full mode: the scenes and sizes of the published figures (docs/benchmarks.md)."));
  SceneSection(page, plan);
  CitySection(page, plan);
  Table1Section(page, plan);
  EpsilonSection(page, plan);
  AgvsSection(page, plan);
  PaceSection(page, plan.pace);
  LevelsSection(page, plan.levels);
  LatencySection(page, plan.latency);
  MapsSection(page, plan);
  HeatmapSection(page, plan);
  const double seconds = SecondsSince(start);
  if (CancelFlag().load()) {
    return Fail(absl::CancelledError(absl::StrFormat("report stopped after %.0f s; no report.md written in %s",
                                                     seconds, a.out)));
  }
  page.Heading("Run");
  page.Text(absl::StrFormat("The whole report took %.0f s.", seconds));
  // Whether the machine was the report's alone: the timed figures (ms per viewcell, samples/s,
  // the compute times the simulator charges) are slower when other work shares the cores.
  std::optional<double> own_share;
  const std::optional<MachineCpu> cpu_end = ReadMachineCpu();
  if (cpu_start && cpu_end && cpu_end->busy_s > cpu_start->busy_s) {
    const double busy = cpu_end->busy_s - cpu_start->busy_s, own = OwnCpuSeconds() - own_start;
    own_share = std::min(1.0, own / busy);
    page.Text(absl::StrFormat(
        "Machine load: the report's processes used %.0f of the %.0f CPU-seconds the machine's cores were busy "
        "during the run (%.0f%%); the host stole %.0f s. Where other work took a large share, the timed figures "
        "above (ms per viewcell, samples/s, the compute times the simulator charged) are slower than the machine "
        "alone would give.",
        own, busy, 100.0 * *own_share, cpu_end->steal_s - cpu_start->steal_s));
  }
  page.StepTable();
  if (absl::Status s = page.Write("report.md"); !s.ok()) return Fail(s);
  std::fprintf(stderr, "report: %s in %.0f s, %zu failed step(s)\n", page.Path("report.md").c_str(), seconds,
               page.failures());
  if (a.json) {
    json j = page.Summary();
    j["seconds"] = seconds;
    j["quick"] = a.quick;
    j["cpu_share"] = own_share ? json(*own_share) : json();
    std::printf("%s\n", j.dump(2).c_str());
  } else {
    std::printf("wrote %s (%zu images) in %.0f s\n", page.Path("report.md").c_str(), page.images().size(), seconds);
  }
  if (page.failures() > 0) {
    return Fail(absl::InternalError(absl::StrCat(page.failures(), " step(s) failed; ", page.Path("report.md"),
                                                 " says which and why")));
  }
  return 0;
}

}  // namespace

void AddReportCommand(CLI::App& app, std::function<void(int)> done) {
  auto [c, args] =
      AddSubcommand<ReportArgs>(&app, "report",
                                "regenerate every published figure: report.md with PNG plots and "
                                "maps, stamped with date, commit, machine",
                                Report, done);
  c->add_option("--out", args->out, "folder for report.md and the PNGs (default: bench/figures, with --quick bench/figures/quick)")
      ->check(OutputPath());
  c->add_flag("--quick", args->quick, "small scenes and counts (minutes; for CI)");
  c->add_flag("--json", args->json, "print a JSON summary (steps, times, files)");
}

}  // namespace vistream::tools
