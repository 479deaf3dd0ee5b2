#include "tools/report_latency.h"

#include <map>
#include <optional>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

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
  GnuplotPlot plot;
  plot.png = png;
  plot.width = 1100;
  plot.height = 900;
  plot.keep_sources = true;
  GnuplotData d{"sweep.dat", "# x, stalls, min margin (s), mean margin (s)\n"};
  for (const auto& point : points) {
    const double x = point.first;
    const json& j = point.second;  // (a name, not a structured binding: clang 14 cannot capture those)
    auto num = [&](const char* k) {
      return j.contains(k) && j.at(k).is_number() ? absl::StrFormat("%.6g", j.at(k).get<double>()) : std::string("NaN");
    };
    absl::StrAppend(&d.text, absl::StrFormat("%.6g", x), " ", num("stalls"), " ", num("min_margin_s"), " ",
                    num("mean_margin_s"), "\n");
  }
  plot.data.push_back(d);
  plot.script = absl::StrCat(
      "set multiplot layout 2,1 title ", GnuplotQuote(title), " font ',15'\n", "set grid lc rgb '#d0d0d0'\n",
      "set logscale x 2\n", "set format x '%g'\n", "set xlabel ", GnuplotQuote(xlabel), "\n",
      "set key top left box opaque\n", "set title 'Stalls (frames drawn before the PVS geometry of their viewcell arrived)'\n",
      "set ylabel 'stalls (count)'\n", "set yrange [0:*]\n",
      "plot 'sweep.dat' using 1:2 with linespoints lw 2 pt 7 lc rgb '#d62728' title 'stalls'\n",
      "set title 'Arrival margin (time from a PVS completing to the client entering its cell)'\n",
      "set ylabel 'margin (s)'\n", "set yrange [*:*]\n", "set key bottom left box opaque\n",
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
    p.speeds_kmh = {3, 12, 48, 192};
    p.bandwidths_mbps = {0.016, 0.064, 0.25, 1, 4};
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
  const std::vector<std::string> probe_args = args({"--scheme", "pvs", "--speed", Speed(plan.sweep_speed_kmh)});
  const Page::Raw probe = page.RunRaw("simulate " + Speed(plan.sweep_speed_kmh) + " km/h", probe_args, true);
  if (probe.exit_code != 0) return;
  json first = json::parse(probe.out, nullptr, false);
  if (first.is_discarded() || !first.is_object()) {
    page.Failed(page.Command(probe_args), "its output is not one JSON object");
    return;
  }
  const json link = first.value("link", json::object());
  const double latency_ms = link.value("latency_ms", 0.0);
  page.Text(absl::StrFormat(
      "%s along `%s`; the link as the catalog declares it: %s Mbit/s, %s ms one way, jitter %s ms, loss %s%%; "
      "%s triangles in the scene. Command of the first run: `%s`.",
      plan.scene, plan.path, Fixed(link.value("bandwidth_bps", 0.0) / 1e6, 2), Number(link.value("latency_ms", json())),
      Number(link.value("jitter_ms", json())), Number(link.value("loss_pct", json())),
      Int(first.value("scene_triangles", json())), page.Command(probe_args)));

  // Speed sweep, scheme pvs.
  std::vector<std::pair<double, json>> by_speed;
  std::vector<double> speeds = plan.speeds_kmh;
  if (std::find(speeds.begin(), speeds.end(), plan.sweep_speed_kmh) == speeds.end()) speeds.push_back(plan.sweep_speed_kmh);
  std::sort(speeds.begin(), speeds.end());
  for (double v : speeds) {
    if (v == plan.sweep_speed_kmh) {
      by_speed.emplace_back(v, first);
      continue;
    }
    if (auto j = page.Run("simulate " + Speed(v) + " km/h", args({"--scheme", "pvs", "--speed", Speed(v)}))) {
      by_speed.emplace_back(v, *j);
    }
  }
  page.Text("Against walking speed, scheme `pvs`, the scene's link:");
  std::vector<std::vector<std::string>> rows;
  for (const auto& [v, j] : by_speed) rows.push_back(Row(Speed(v) + " km/h", j));
  page.Table(Head("speed"), rows);
  const std::string speed_png = "latency_speed_" + plan.scene + ".png";
  if (page.Plot("latency vs speed",
                SweepPlot(page.Path(speed_png),
                          absl::StrCat(plan.scene, ": stalls and arrival margin against walking speed (scheme pvs)"),
                          "walking speed (km/h, log scale)", by_speed))) {
    page.Image(speed_png, "Stalls and margin against speed");
  }

  // Bandwidth sweep at the scene's latency.
  std::vector<std::pair<double, json>> by_bw;
  for (double mbps : plan.bandwidths_mbps) {
    const std::string bps = absl::StrFormat("%.0f,%g", mbps * 1e6, latency_ms);
    if (auto j = page.Run(absl::StrFormat("simulate %g Mbit/s", mbps),
                          args({"--scheme", "pvs", "--speed", Speed(plan.sweep_speed_kmh), "--link", bps}))) {
      by_bw.emplace_back(mbps, *j);
    }
  }
  page.Text(absl::StrFormat("Against link bandwidth, scheme `pvs`, %s km/h, %g ms one way:", Speed(plan.sweep_speed_kmh),
                            latency_ms));
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
  std::vector<std::pair<std::string, json>> by_scheme;
  std::vector<std::vector<std::string>> max_rows;
  for (const std::string& s : plan.schemes) {
    if (s == "pvs") {
      by_scheme.emplace_back(s, first);
    } else if (auto j = page.Run("simulate " + s, args({"--scheme", s, "--speed", Speed(plan.sweep_speed_kmh)}))) {
      by_scheme.emplace_back(s, *j);
    }
    if (auto m = page.Run("simulate " + s + " max", args({"--scheme", s, "--speed", "max"}))) {
      const json stall = m->value("stall_speed_kmh", json());
      std::string upper = "?";
      if (m->contains("search") && (*m)["search"].contains("bracket_kmh")) upper = Fixed((*m)["search"]["bracket_kmh"][1], 0);
      max_rows.push_back({s, Fixed(m->value("max_speed_kmh", json()), 1),
                          stall.is_number() ? Fixed(stall, 1) : absl::StrCat("none up to ", upper, " (the search's top)")});
    }
  }
  page.Text(absl::StrFormat("Per scheme at %s km/h (pvs: viewcell PVS; pvs+eps: with ε-masks; radius: distance-radius "
                            "streaming; plain: the paper's plain scheme):",
                            Speed(plan.sweep_speed_kmh)));
  rows.clear();
  for (const auto& [s, j] : by_scheme) rows.push_back(Row(s, j));
  page.Table(Head("scheme"), rows);
  page.Text("Highest speed without a stall, per scheme (`--speed max`):");
  page.Table({"scheme", "max speed km/h", "slowest speed found to stall, km/h"}, max_rows);

  GnuplotPlot bytes;
  bytes.png = page.Path("latency_bytes_" + plan.scene + ".png");
  bytes.width = 1000;
  bytes.height = 650;
  bytes.keep_sources = true;
  GnuplotData d{"bytes.dat", "# scheme, MB sent\n"};
  for (const auto& [s, j] : by_scheme) {
    if (j.contains("bytes") && j.at("bytes").is_number()) {
      absl::StrAppend(&d.text, "\"", s, "\" ", absl::StrFormat("%.6g", j.at("bytes").get<double>() / 1e6), "\n");
    }
  }
  bytes.data.push_back(d);
  bytes.script = absl::StrCat(
      "set title ", GnuplotQuote(absl::StrFormat("%s: bytes sent along %s at %s km/h, per scheme", plan.scene, plan.path,
                                                 Speed(plan.sweep_speed_kmh))),
      " font ',14'\n", "set style fill solid 0.8 border -1\n", "set boxwidth 0.6\n", "set logscale y 10\n",
      "set grid ytics lc rgb '#d0d0d0'\n", "set xlabel 'streaming scheme'\n",
      "set ylabel 'data sent to the client (MB = 10^6 bytes, log scale)'\n", "set key top left box\n",
      "set yrange [*:*]\n",
      "plot 'bytes.dat' using 0:2:xtic(1) with boxes lc rgb '#1f77b4' title 'bytes sent (MB)', "
      "'' using 0:2:(sprintf('%.2f', $2)) with labels offset 0,1 notitle\n");
  const std::string bytes_name = "latency_bytes_" + plan.scene + ".png";
  if (!by_scheme.empty() && page.Plot("bytes per scheme", bytes)) page.Image(bytes_name, "Bytes sent per scheme");
}

}  // namespace vistream::tools
