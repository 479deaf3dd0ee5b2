#include "tools/report_latency.h"

#include <map>
#include <optional>

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
          Int(j.value("mean_triangles_drawn", json()))};
}

// The runs of one simulate output: its `runs`, or the one object it printed.
std::vector<json> RunsOf(const json& out) {
  if (out.contains("runs") && out["runs"].is_array()) return out["runs"].get<std::vector<json>>();
  return {out};
}

const std::vector<std::string> kHead = {"stalls", "stall s", "min margin s", "mean margin s", "MB sent",
                                        "mean triangles drawn"};

std::vector<std::string> Head(const std::string& first) {
  std::vector<std::string> h = {first};
  h.insert(h.end(), kHead.begin(), kHead.end());
  return h;
}

// Stalls (top) and margins (bottom) against x: one file, columns x, stalls, min, mean margin.
GnuplotPlot SweepPlot(const std::string& png, const std::string& title, const std::string& xlabel,
                      const std::vector<std::pair<double, json>>& points) {
  GnuplotPlot plot = GnuplotPlot::Kept(png, 1100, 900);
  GnuplotData d{"sweep.dat", "# x, stalled time (% of the walk), min margin (s), mean margin (s)\n"};
  for (const auto& point : points) {
    const double x = point.first;
    const json& j = point.second;  // (a name, not a structured binding: clang 14 cannot capture those)
    auto num = [&](const char* k) {
      return j.contains(k) && j.at(k).is_number() ? absl::StrFormat("%.6g", j.at(k).get<double>()) : std::string("NaN");
    };
    // Stalled time over the walk's time: frame counts fall with speed only because the walk is shorter.
    const bool have = j.contains("stall_s") && j.at("stall_s").is_number() && j.contains("walk_s") &&
                      j.at("walk_s").is_number() && j.at("walk_s").get<double>() > 0.0;
    const std::string pct =
        have ? absl::StrFormat("%.6g", 100.0 * j.at("stall_s").get<double>() / j.at("walk_s").get<double>()) : "NaN";
    absl::StrAppend(&d.text, absl::StrFormat("%.6g", x), " ", pct, " ", num("min_margin_s"), " ",
                    num("mean_margin_s"), "\n");
  }
  plot.data.push_back(d);
  // Ticks where the runs are, labelled with their values (a log axis's own ticks fall between).
  std::string tics;
  for (const auto& point : points) {
    absl::StrAppend(&tics, tics.empty() ? "" : ", ", absl::StrFormat("'%g' %.6g", point.first, point.first));
  }
  plot.script = absl::StrCat(
      "set multiplot layout 2,1 title ", GnuplotQuote(title), " font ',15'\n", "set grid lc rgb '#d0d0d0'\n",
      "set logscale x 2\n", "set xtics (", tics, ")\n", "set lmargin 12\n", "set rmargin 25\n", "set xlabel ", GnuplotQuote(xlabel), "\n",
      "set key outside right top box\n",
      "set title 'Stalled time (frames drawn before the PVS geometry of their viewcell arrived)'\n",
      "set ylabel 'stalled time (% of the walk)'\n", "set yrange [0:*]\n",
      "plot 'sweep.dat' using 1:2 with linespoints lw 2 pt 7 lc rgb '#d62728' title 'stalled time'\n",
      "set title 'Arrival margin (time from a PVS completing to the client entering its cell)'\n",
      "set ylabel 'margin (s)'\n", "set yrange [*:*]\n", "set key outside right top box\n",
      "plot 'sweep.dat' using 1:3 with linespoints lw 2 pt 7 lc rgb '#1f77b4' title 'minimum margin', "
      "'sweep.dat' using 1:4 with linespoints lw 2 pt 5 lc rgb '#2ca02c' title 'mean margin', "
      "0 with lines lc rgb '#555555' dt 2 notitle\n",
      "unset multiplot\n");
  return plot;
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
  const std::vector<std::string> scheme_args = args({"--schemes", schemes, "--speed", Speed(plan.sweep_speed_kmh)});
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

  // Speed sweep, scheme pvs (on the scene's link, or the plan's slower one).
  const bool own_link = plan.speed_sweep_bps > 0;
  std::vector<std::string> speed_texts;
  for (double v : plan.speeds_kmh) speed_texts.push_back(Speed(v));
  std::vector<std::string> more = {"--scheme", "pvs", "--speeds", absl::StrJoin(speed_texts, ",")};
  if (own_link) more.insert(more.end(), {"--link", absl::StrFormat("%.0f,%g", plan.speed_sweep_bps, latency_ms)});
  const std::vector<std::string> speed_args = args(more);
  std::vector<std::pair<double, json>> by_speed;
  if (const std::optional<json> out = page.Run("simulate speeds", speed_args, false)) {
    for (const json& j : RunsOf(*out)) by_speed.emplace_back(j.value("speed_kmh", 0.0), j);
  }
  const std::string speed_link_words =
      own_link ? absl::StrFormat("a %g kbit/s link (slower than the scene's, so that the sweep reaches stalls)",
                                 plan.speed_sweep_bps / 1e3)
               : std::string("the scene's link");
  page.Text(absl::StrCat("Against walking speed, scheme `pvs`, ", speed_link_words, ". Command: `",
                         page.Command(speed_args), "`"));
  std::vector<std::vector<std::string>> rows;
  for (const auto& [v, j] : by_speed) rows.push_back(Row(Speed(v) + " km/h", j));
  page.Table(Head("speed"), rows);
  const std::string speed_png = "latency_speed_" + plan.scene + ".png";
  if (!by_speed.empty() &&
      page.Plot("latency vs speed",
                SweepPlot(page.Path(speed_png),
                          absl::StrCat(plan.scene, ": stalls and arrival margin against walking speed (scheme pvs",
                                       own_link ? absl::StrFormat(", %g kbit/s", plan.speed_sweep_bps / 1e3) : "",
                                       ")"),
                          "walking speed (km/h, log scale)", by_speed))) {
    page.Image(speed_png, "Stalls and margin against speed");
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
  const std::vector<std::string> max_args = args({"--schemes", schemes, "--speed", "max"});
  std::vector<std::vector<std::string>> max_rows;
  if (const std::optional<json> out = page.Run("simulate max speed", max_args, false)) {
    for (const json& m : RunsOf(*out)) {
      const json stall = m.value("stall_speed_kmh", json());
      std::string upper = "?";
      if (m.contains("search") && m["search"].contains("bracket_kmh")) upper = Fixed(m["search"]["bracket_kmh"][1], 0);
      max_rows.push_back({m.value("scheme", "?"), Fixed(m.value("max_speed_kmh", json()), 1),
                          stall.is_number() ? Fixed(stall, 1) : absl::StrCat("none up to ", upper, " (the search's top)")});
    }
  }
  page.Text(absl::StrCat("Highest speed without a stall, per scheme. Command: `", page.Command(max_args), "`"));
  page.Table({"scheme", "max speed km/h", "slowest speed found to stall, km/h"}, max_rows);


}

}  // namespace vistream::tools
