#include "tools/report_latency.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>

#include "tools/gnuplot.h"
#include "tools/subprocess.h"

namespace vistream::tools {

namespace {

using nlohmann::json;

std::string Speed(double kmh) { return absl::StrFormat("%g", kmh); }

// One simulate result as a table row.
std::vector<std::string> Row(const std::string& first, const json& j) {
  return {first,
          Int(j.value("stalls", json())),
          Fixed(j.value("stall_s", json()), 2),
          Fixed(j.value("min_margin_s", json()), 2),
          Fixed(j.value("mean_margin_s", json()), 2),
          Fixed(j.value("bytes", json()).is_number() ? json(j.at("bytes").get<double>() / 1e6) : json(), 2),
          Int(j.value("mean_triangles_drawn", json())),
          Fixed(j.value("masked_frames_pct", json()), 1),
          Int(j.value("hole_frames", json())),
          Int(j.value("mean_triangles_without_masks", json()))};
}

// The runs of one simulate output: its `runs`, or the one object it printed.
std::vector<json> RunsOf(const json& out) {
  if (out.contains("runs") && out["runs"].is_array()) return out["runs"].get<std::vector<json>>();
  return {out};
}

const std::vector<std::string> kHead = {"stalls", "stall s", "min margin s", "mean margin s", "MB sent",
                                        "mean triangles drawn", "masked frames %", "hole frames",
                                        "mean triangles without masks"};

std::vector<std::string> Head(const std::string& first) {
  std::vector<std::string> h = {first};
  h.insert(h.end(), kHead.begin(), kHead.end());
  return h;
}

// `count` frames (stalls, hole frames) of run `j` as a share of its walk's time: frame counts
// fall with speed only because the walk is shorter.
std::string FramesPct(const json& j, const char* count) {
  const bool have = j.contains(count) && j.at(count).is_number() && j.contains("frame_ms") &&
                    j.at("frame_ms").is_number() && j.contains("walk_s") && j.at("walk_s").is_number() &&
                    j.at("walk_s").get<double>() > 0.0;
  return have ? absl::StrFormat("%.6g", 100.0 * j.at(count).get<double>() * j.at("frame_ms").get<double>() / 1000.0 /
                                            j.at("walk_s").get<double>())
              : "NaN";
}

// Stalls (top) and margins (bottom) against x: one file, columns x, stalls, min, mean margin,
// and with `eps` (runs of pvs+eps at the same x, in the same order) its hole frames.
GnuplotPlot SweepPlot(const std::string& png, const std::string& title, const std::string& xlabel,
                      const std::vector<std::pair<double, json>>& points,
                      const std::vector<std::pair<double, json>>& eps = {}) {
  GnuplotPlot plot = GnuplotPlot::Kept(png, 1100, 900);
  GnuplotData d{"sweep.dat",
                "# x, stalled time (% of the walk), min margin (s), mean margin (s), pvs+eps hole frames' time (% of "
                "the walk)\n"};
  for (size_t k = 0; k < points.size(); ++k) {
    const double x = points[k].first;
    const json& j = points[k].second;  // (a name, not a structured binding: clang 14 cannot capture those)
    auto num = [&](const char* key) {
      return j.contains(key) && j.at(key).is_number() ? absl::StrFormat("%.6g", j.at(key).get<double>())
                                                      : std::string("NaN");
    };
    // Stalled time over the walk's time: frame counts fall with speed only because the walk is shorter.
    const bool have = j.contains("stall_s") && j.at("stall_s").is_number() && j.contains("walk_s") &&
                      j.at("walk_s").is_number() && j.at("walk_s").get<double>() > 0.0;
    const std::string pct =
        have ? absl::StrFormat("%.6g", 100.0 * j.at("stall_s").get<double>() / j.at("walk_s").get<double>()) : "NaN";
    const std::string holes = k < eps.size() ? FramesPct(eps[k].second, "hole_frames") : "NaN";
    absl::StrAppend(&d.text, absl::StrFormat("%.6g", x), " ", pct, " ", num("min_margin_s"), " ",
                    num("mean_margin_s"), " ", holes, "\n");
  }
  plot.data.push_back(d);
  // Ticks where the runs are, labelled with their values (a log axis's own ticks fall between).
  std::string tics;
  for (const auto& point : points) {
    absl::StrAppend(&tics, tics.empty() ? "" : ", ", absl::StrFormat("'%g' %.6g", point.first, point.first));
  }
  plot.script = absl::StrCat(
      "set multiplot layout 2,1 title ", GnuplotQuote(title), " font ',15'\n", "set grid lc rgb '#d0d0d0'\n",
      "set logscale x 2\n", "set xtics (", tics, ")\n", "set lmargin 12\n", (eps.empty() ? "set rmargin 25\n" : "set rmargin 30\n"), "set xlabel ", GnuplotQuote(xlabel), "\n",
      "set key outside right top box\n",
      eps.empty() ? "set title 'Stalled time (frames drawn before the PVS geometry of their viewcell arrived)'\n"
                  : "set title 'Stalls (frames before the PVS of their viewcell arrived) and holes (stalls no ε-mask covered)'\n",
      "set ylabel 'time (% of the walk)'\n", "set yrange [0:*]\n",
      eps.empty() ? "plot 'sweep.dat' using 1:2 with linespoints lw 2 pt 7 lc rgb '#d62728' title 'stalled time'\n"
                  : "plot 'sweep.dat' using 1:2 with linespoints lw 2 pt 7 lc rgb '#d62728' title 'stalls (pvs)', "
                    "'sweep.dat' using 1:5 with linespoints lw 2 pt 5 lc rgb '#ff7f0e' title 'holes (pvs+eps)'\n",
      eps.empty() ? "set title 'Arrival margin (time from a PVS completing to the client entering its cell)'\n"
                  : "set title 'Arrival margin, scheme pvs (time from a PVS completing to the client entering its cell)'\n",
      "set ylabel 'margin (s)'\n", "set yrange [*:*]\n", "set key outside right top box\n",
      "plot 'sweep.dat' using 1:3 with linespoints lw 2 pt 7 lc rgb '#1f77b4' title 'minimum margin', "
      "'sweep.dat' using 1:4 with linespoints lw 2 pt 5 lc rgb '#2ca02c' title 'mean margin', "
      "0 with lines lc rgb '#555555' dt 2 notitle\n",
      "unset multiplot\n");
  return plot;
}

// One sampled frame of a `simulate --series` file.
struct SeriesSample {
  double along_m = 0.0;
  double triangles = 0.0, without = 0.0;
  bool masked = false, hole = false;
};

// The blocks of a `simulate --series` file, one per run in the order of the runs; empty with
// `why` set when the file cannot be read or a line is not six numbers.
std::vector<std::vector<SeriesSample>> ReadSeries(const std::string& path, std::string* why) {
  std::ifstream in(path);
  if (!in) {
    *why = absl::StrCat("cannot read ", path);
    return {};
  }
  std::vector<std::vector<SeriesSample>> blocks;
  std::string line;
  for (size_t n = 1; std::getline(in, line); ++n) {
    if (line.rfind("# run ", 0) == 0) {
      blocks.emplace_back();
      continue;
    }
    if (line.empty() || line[0] == '#') continue;
    std::istringstream fields(line);
    SeriesSample x;
    int masked = 0, hole = 0;
    double t = 0.0;
    if (blocks.empty() || !(fields >> x.along_m >> t >> x.triangles >> x.without >> masked >> hole)) {
      *why = absl::StrCat(path, " line ", n, ": not a sample of a run");
      return {};
    }
    x.masked = masked != 0;
    x.hole = hole != 0;
    blocks.back().push_back(x);
  }
  return blocks;
}

// A round bin width (1, 2 or 5 times a power of ten) of about `raw`.
double RoundBin(double raw) {
  const double p = std::pow(10.0, std::floor(std::log10(std::max(raw, 1e-3))));
  for (double m : {1.0, 2.0, 5.0}) {
    if (m * p >= raw) return m * p;
  }
  return 10.0 * p;
}

// The plot of triangles drawn per frame along the walk, pvs against pvs+eps, from the scheme
// runs' series file (removed afterwards: the plot keeps the binned data it draws).
void TrianglesAlongTheWalk(Page& page, const LatencyPlan& plan, const std::string& series_path,
                           const std::vector<json>& by_scheme) {
  std::string why;
  const std::vector<std::vector<SeriesSample>> blocks = ReadSeries(series_path, &why);
  std::error_code ec;
  std::filesystem::remove(series_path, ec);
  const std::vector<SeriesSample>* pvs = nullptr;
  const std::vector<SeriesSample>* eps = nullptr;
  const json* eps_run = nullptr;
  for (size_t k = 0; k < by_scheme.size() && k < blocks.size(); ++k) {
    const std::string scheme = by_scheme[k].value("scheme", "");
    if (scheme == "pvs") pvs = &blocks[k];
    if (scheme == "pvs+eps") eps = &blocks[k], eps_run = &by_scheme[k];
  }
  if (pvs == nullptr || eps == nullptr || pvs->empty() || eps->empty()) {
    page.NotProduced(absl::StrCat("the plot of triangles drawn along the walk: ",
                                  why.empty() ? "the scheme runs' series lack pvs or pvs+eps" : why));
    return;
  }
  double length = 0.0;
  for (const auto* run : {pvs, eps}) length = std::max(length, run->back().along_m);
  const double bin = RoundBin(length / 500.0);
  const size_t bins = static_cast<size_t>(std::floor(length / bin)) + 1;
  struct Bin {
    double pvs_sum = 0.0, eps_sum = 0.0;
    size_t pvs_n = 0, eps_n = 0, masked = 0, holes = 0;
  };
  std::vector<Bin> b(bins);
  auto at = [&](double along) { return std::min(bins - 1, static_cast<size_t>(std::max(0.0, along) / bin)); };
  for (const SeriesSample& x : *pvs) {
    Bin& c = b[at(x.along_m)];
    c.pvs_sum += x.triangles;
    ++c.pvs_n;
  }
  for (const SeriesSample& x : *eps) {
    Bin& c = b[at(x.along_m)];
    c.eps_sum += x.triangles;
    ++c.eps_n;
    c.masked += x.masked ? 1 : 0;
    c.holes += x.hole ? 1 : 0;
  }
  GnuplotData d{"triangles.dat",
                absl::StrFormat("# bin centre (m along the walk), mean triangles drawn per frame: pvs, pvs+eps; "
                                "pvs+eps frames masked (%%), hole frames (%%); bins of %g m, 10 Hz samples\n",
                                bin)};
  auto mean = [](double sum, size_t n) { return n > 0 ? absl::StrFormat("%.6g", sum / static_cast<double>(n)) : "NaN"; };
  auto pct = [](size_t k, size_t n) {
    return n > 0 ? absl::StrFormat("%.6g", 100.0 * static_cast<double>(k) / static_cast<double>(n)) : "NaN";
  };
  for (size_t k = 0; k < bins; ++k) {
    absl::StrAppend(&d.text, absl::StrFormat("%.6g", (static_cast<double>(k) + 0.5) * bin), " ",
                    mean(b[k].pvs_sum, b[k].pvs_n), " ", mean(b[k].eps_sum, b[k].eps_n), " ",
                    pct(b[k].masked, b[k].eps_n), " ", pct(b[k].holes, b[k].eps_n), "\n");
  }
  const std::string png = "latency_triangles_" + plan.scene + ".png";
  GnuplotPlot plot = GnuplotPlot::Kept(page.Path(png), 1200, 900);
  plot.data.push_back(d);
  const std::string bin_words = absl::StrFormat("%g m", bin);
  plot.script = absl::StrCat(
      "set multiplot layout 2,1 title ",
      GnuplotQuote(absl::StrFormat("%s: triangles drawn per frame along %s at %s km/h, without and with ε-masks",
                                   plan.scene, plan.path, Speed(plan.sweep_speed_kmh))),
      " font ',15'\n", "set grid lc rgb '#d0d0d0'\n", "set lmargin 12\n", "set rmargin 32\n",
      "set key outside right top box\n", "set xlabel 'distance along the walk (m)'\n",
      absl::StrFormat("set xrange [0:%.6g]\n", static_cast<double>(bins) * bin),
      "set title ", GnuplotQuote(absl::StrCat("Triangles drawn per frame after view-frustum culling (mean over each ",
                                              bin_words, " of the walk)")),
      "\n", "set ylabel 'triangles per frame'\n", "set yrange [0:*]\n",
      "plot 'triangles.dat' using 1:2 with lines lw 2 lc rgb '#1f77b4' title 'pvs (viewcell PVS)', "
      "'triangles.dat' using 1:3 with lines lw 2 lc rgb '#ff7f0e' title 'pvs+eps (ε-masks)'\n",
      "set title ", GnuplotQuote(absl::StrCat("pvs+eps: frames drawn with an ε-mask, and hole frames (share of the "
                                              "frames in each ", bin_words, ")")),
      "\n", "set ylabel 'frames (%)'\n", "set yrange [-3:105]\n",
      "plot 'triangles.dat' using 1:4 with lines lw 2 lc rgb '#2ca02c' title 'masked frames', "
      "'triangles.dat' using 1:5 with lines lw 2 lc rgb '#d62728' title 'hole frames'\n",
      "unset multiplot\n");
  page.Text(absl::StrFormat(
      "Triangles drawn per frame along the walk at %s km/h (the scheme runs above): with ε-masks %s a frame on "
      "the mean, against %s for the viewcell PVS on the same frames (%s of it); %s%% of the frames masked, %s "
      "hole frames.",
      Speed(plan.sweep_speed_kmh), Int(eps_run->value("mean_triangles_drawn", json())),
      Int(eps_run->value("mean_triangles_without_masks", json())),
      Fixed(eps_run->value("triangles_with_over_without_masks", json()), 3),
      Fixed(eps_run->value("masked_frames_pct", json()), 1), Int(eps_run->value("hole_frames", json()))));
  if (page.Plot("triangles along the walk", plot)) {
    page.Image(png, "Triangles drawn per frame along the walk, pvs and pvs+eps, with masked and hole frames");
  }
}

}  // namespace

LatencyPlan LatencyPlanFor(bool quick) {
  LatencyPlan p;
  p.schemes = {"pvs", "pvs+eps", "radius", "plain"};
  if (quick) {
    p.scene = "default", p.path = "avenue-and-back-streets";
    // default's walk is short and its PVSs quick: on its declared 20 Mbit/s nothing stalls up to
    // the simulator's top speed, so quick mode sweeps speed on a slow link, where stalls begin.
    p.speeds_kmh = {3, 12, 48, 192};
    p.speed_sweep_bps = 16000;
    p.bandwidths_mbps = {0.004, 0.008, 0.016, 0.064, 0.25, 1};
  } else {
    p.scene = "london", p.path = "cross-town";
    p.speeds_kmh = {3, 6, 12, 24, 48, 96, 192};
    p.bandwidths_mbps = {0.0625, 0.125, 0.25, 0.5, 1, 2, 4};
  }
  p.sweep_speed_kmh = 6;
  return p;
}

void LatencySection(Page& page, const LatencyPlan& plan) {
  page.Heading("Latency: stalls, arrival margin and bytes along a walk (simulated)");
  const std::vector<std::string> base = {"simulate", "--scene", plan.scene, "--path", plan.path};
  auto args = [&](std::vector<std::string> more) {
    std::vector<std::string> a = base;
    a.insert(a.end(), more.begin(), more.end());
    a.push_back("--json");
    return a;
  };
  // Whether this build has the simulator at all: bare `vistream simulate` answers with the
  // unknown-subcommand error when it does not (and asks for --scene when it does).
  const Page::Raw bare = page.RunRaw("simulate (present?)", {"simulate"}, false);
  if (bare.err.find("'simulate': not a vistream command") != std::string::npos) {
    page.SetLastResult("absent: not a vistream command");
    page.NotProduced(absl::StrCat(
        "this build has no `vistream simulate` (`vistream simulate` answered: `",
        bare.err.substr(0, bare.err.find('\n')),
        "`). The discrete-event simulator of server, link and client is not on this branch yet, so no stall, "
        "margin or bytes figure was made; this section fills in once `simulate` is merged."));
    return;
  }
  page.SetLastResult("present (it asks for its options)");

  // Each sweep is one process (its PVSs computed once, their measured times charged to every run).
  const std::string schemes = absl::StrJoin(plan.schemes, ",");
  // The per-frame series of these runs: the triangles-along-the-walk plot's data, read and
  // removed below (its plot keeps what it draws).
  const std::string series_name = "latency_triangles_" + plan.scene + ".series";
  const std::vector<std::string> scheme_args =
      args({"--schemes", schemes, "--speed", Speed(plan.sweep_speed_kmh), "--series", page.Path(series_name)});
  const std::optional<json> by_scheme_out = page.Run("simulate schemes", scheme_args, false);
  if (!by_scheme_out) return;
  const std::vector<json> by_scheme = RunsOf(*by_scheme_out);
  if (by_scheme.empty()) {
    page.Failed(page.Command(scheme_args), "its output holds no run");
    return;
  }
  const json& first = by_scheme.front();
  const json link = first.value("link", json::object());
  const double latency_ms = link.value("latency_ms", 0.0);
  page.Text(absl::StrFormat(
      "%s along `%s`; the link as the catalog declares it: %s Mbit/s, %s ms one way, jitter %s ms, loss %s%%; "
      "%s triangles in the scene. A cell the walker leaves before its PVS arrived counts its whole stay as "
      "stalled and minus its stay as its margin (a bound: the walker did not wait there).",
      plan.scene, plan.path, Fixed(link.value("bandwidth_bps", 0.0) / 1e6, 2), Number(link.value("latency_ms", json())),
      Number(link.value("jitter_ms", json())), Number(link.value("loss_pct", json())),
      Int(first.value("scene_triangles", json()))));

  // Speed sweep, schemes pvs and pvs+eps (on the scene's link, or the plan's slower one).
  const bool own_link = plan.speed_sweep_bps > 0;
  std::vector<std::string> speed_texts;
  for (double v : plan.speeds_kmh) speed_texts.push_back(Speed(v));
  std::vector<std::string> more = {"--schemes", "pvs,pvs+eps", "--speeds", absl::StrJoin(speed_texts, ",")};
  if (own_link) more.insert(more.end(), {"--link", absl::StrFormat("%.0f,%g", plan.speed_sweep_bps, latency_ms)});
  const std::vector<std::string> speed_args = args(more);
  std::vector<std::pair<double, json>> by_speed, by_speed_eps;
  std::vector<std::vector<std::string>> rows;
  if (const std::optional<json> out = page.Run("simulate speeds", speed_args, false)) {
    for (const json& j : RunsOf(*out)) {
      const double v = j.value("speed_kmh", 0.0);
      const std::string scheme = j.value("scheme", "?");
      (scheme == "pvs+eps" ? by_speed_eps : by_speed).emplace_back(v, j);
      rows.push_back(Row(absl::StrCat(Speed(v), " km/h, ", scheme), j));
    }
  }
  // The plot pairs the schemes' runs by speed: only when every speed has both.
  if (by_speed_eps.size() != by_speed.size()) by_speed_eps.clear();
  const std::string speed_link_words =
      own_link ? absl::StrFormat("a %g kbit/s link (slower than the scene's, so that the sweep reaches stalls)",
                                 plan.speed_sweep_bps / 1e3)
               : std::string("the scene's link");
  page.Text(absl::StrCat("Against walking speed, schemes `pvs` and `pvs+eps`, ", speed_link_words,
                         ". Masked frames are drawn with an ε-mask; a hole frame is one drawn with neither a mask "
                         "nor its viewcell's complete PVS (a stall no mask covered). Command: `",
                         page.Command(speed_args), "`"));
  page.Table(Head("speed, scheme"), rows);
  const std::string speed_png = "latency_speed_" + plan.scene + ".png";
  if (!by_speed.empty() &&
      page.Plot("latency vs speed",
                SweepPlot(page.Path(speed_png),
                          absl::StrCat(plan.scene, ": stalls, hole frames and arrival margin against walking speed",
                                       own_link ? absl::StrFormat(" (%g kbit/s)", plan.speed_sweep_bps / 1e3) : "",
                                       ""),
                          "walking speed (km/h, log scale)", by_speed, by_speed_eps))) {
    page.Image(speed_png, "Stalls, hole frames and margin against speed");
  }

  // Bandwidth sweep at the scene's latency.
  std::vector<std::string> bw_texts;
  for (double mbps : plan.bandwidths_mbps) bw_texts.push_back(absl::StrFormat("%.0f", mbps * 1e6));
  const std::vector<std::string> bw_args =
      args({"--scheme", "pvs", "--speed", Speed(plan.sweep_speed_kmh), "--bandwidths", absl::StrJoin(bw_texts, ",")});
  std::vector<std::pair<double, json>> by_bw;
  if (const std::optional<json> out = page.Run("simulate bandwidths", bw_args, false)) {
    for (const json& j : RunsOf(*out)) {
      by_bw.emplace_back(j.value("link", json::object()).value("bandwidth_bps", 0.0) / 1e6, j);
    }
  }
  page.Text(absl::StrFormat("Against link bandwidth, scheme `pvs`, %s km/h, %g ms one way, the declared jitter and "
                            "loss kept. Command: `%s`",
                            Speed(plan.sweep_speed_kmh), latency_ms, page.Command(bw_args)));
  rows.clear();
  for (const auto& [b, j] : by_bw) rows.push_back(Row(absl::StrFormat("%g Mbit/s", b), j));
  page.Table(Head("bandwidth"), rows);
  const std::string bw_png = "latency_bandwidth_" + plan.scene + ".png";
  if (!by_bw.empty() &&
      page.Plot("latency vs bandwidth",
                SweepPlot(page.Path(bw_png),
                          absl::StrFormat("%s: stalls and arrival margin against link bandwidth (scheme pvs, %s km/h)",
                                          plan.scene, Speed(plan.sweep_speed_kmh)),
                          "link bandwidth (Mbit/s, log scale)", by_bw))) {
    page.Image(bw_png, "Stalls and margin against bandwidth");
  }

  // Schemes: the same walk, and each one's highest speed without stalls.
  page.Text(absl::StrFormat("Per scheme at %s km/h (pvs: viewcell PVS; pvs+eps: with ε-masks; radius: distance-radius "
                            "streaming; plain: the paper's plain scheme). Command: `%s`",
                            Speed(plan.sweep_speed_kmh), page.Command(scheme_args)));
  rows.clear();
  for (const json& j : by_scheme) rows.push_back(Row(j.value("scheme", "?"), j));
  page.Table(Head("scheme"), rows);
  GnuplotPlot bytes = GnuplotPlot::Kept(page.Path("latency_bytes_" + plan.scene + ".png"), 1000, 650);
  GnuplotData d{"bytes.dat", "# scheme, MB sent\n"};
  for (const json& j : by_scheme) {
    if (j.contains("bytes") && j.at("bytes").is_number()) {
      absl::StrAppend(&d.text, "\"", j.value("scheme", "?"), "\" ",
                      absl::StrFormat("%.6g", j.at("bytes").get<double>() / 1e6), "\n");
    }
  }
  bytes.data.push_back(d);
  bytes.script = absl::StrCat(
      "set title ", GnuplotQuote(absl::StrFormat("%s: bytes sent along %s at %s km/h, per scheme", plan.scene, plan.path,
                                                 Speed(plan.sweep_speed_kmh))),
      " font ',14'\n", "set style fill solid 0.8 border -1\n", "set boxwidth 0.6\n",
      "set grid ytics lc rgb '#d0d0d0'\n", "set xlabel 'streaming scheme'\n",
      "set ylabel 'data sent to the client (MB = 10^6 bytes)'\n", "set key top left box\n",
      "set yrange [0:*]\n", "set offsets 0, 0, graph 0.08, 0\n",
      "plot 'bytes.dat' using 0:2:xtic(1) with boxes lc rgb '#1f77b4' title 'bytes sent (MB)', "
      "'' using 0:2:(sprintf('%.2f', $2)) with labels offset 0,1 notitle\n");
  const std::string bytes_name = "latency_bytes_" + plan.scene + ".png";
  if (!by_scheme.empty() && page.Plot("bytes per scheme", bytes)) page.Image(bytes_name, "Bytes sent per scheme");
  TrianglesAlongTheWalk(page, plan, page.Path(series_name), by_scheme);
  const std::vector<std::string> max_args = args({"--schemes", schemes, "--speed", "max"});
  std::vector<std::vector<std::string>> max_rows;
  if (const std::optional<json> out = page.Run("simulate max speed", max_args, false)) {
    for (const json& m : RunsOf(*out)) {
      const json stall = m.value("stall_speed_kmh", json());
      std::string upper = "?";
      if (m.contains("search") && m["search"].contains("bracket_kmh")) upper = Fixed(m["search"]["bracket_kmh"][1], 0);
      const json hole = m.value("hole_speed_kmh", json());
      max_rows.push_back({m.value("scheme", "?"), Fixed(m.value("max_speed_kmh", json()), 1),
                          stall.is_number() ? Fixed(stall, 1) : absl::StrCat("none up to ", upper, " (the search's top)"),
                          Fixed(m.value("max_speed_no_hole_kmh", json()), 1),
                          hole.is_number() ? Fixed(hole, 1) : absl::StrCat("none up to ", upper, " (the search's top)")});
    }
  }
  page.Text(absl::StrCat("Highest speed without a stall, and without a hole frame (the same for every scheme but "
                         "pvs+eps, whose masks can cover a stall), per scheme. Command: `",
                         page.Command(max_args), "`"));
  page.Table({"scheme", "max speed km/h", "slowest speed found to stall, km/h", "max speed without a hole frame, km/h",
              "slowest speed found with a hole frame, km/h"},
             max_rows);


}

}  // namespace vistream::tools
