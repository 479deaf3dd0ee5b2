#include "tools/report_levels.h"

#include <map>
#include <optional>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>

#include "tools/gnuplot.h"

namespace vistream::tools {

namespace {

using nlohmann::json;

// tau as the plot's x: "off" at 0.25 px (left of every tau on a log axis), marked so.
double PlotTau(const json& tau) { return tau.is_null() ? 0.25 : tau.get<double>(); }
std::string TauText(const json& tau) { return tau.is_null() ? "off" : absl::StrFormat("%g", tau.get<double>()); }

// A panel with nothing to plot, saying why (gnuplot refuses a plot without a point).
std::string EmptyPanel(const std::string& why) {
  return absl::StrCat("set label 99 ", GnuplotQuote(why), " at graph 0.5, 0.5 center\n",
                      "set xrange [0.2:20]\nset yrange [0:1]\nplot 2 notitle\n",
                      "unset label 99\nset autoscale x\nset yrange [0:*]");
}

}  // namespace

LevelsPlan LevelsPlanFor(bool quick) {
  LevelsPlan p;
  if (quick) {
    p.scenes = {"default"};
    p.taus = "off,1";
    p.speed_search = false;  // and no client run: the tests check the client's pixels (CI's minutes)
  } else {
    p.scenes = {"london", "denhaag"};
    p.taus = "off,0.5,1,2,4,16";
    p.client_scene = "denhaag";
    p.client_seconds = "30";
  }
  return p;
}

void LevelsSection(Page& page, const LevelsPlan& plan) {
  page.Heading("Levels of detail: what accuracy costs");
  page.Text(absl::StrCat(
      "Each object at the coarsest level whose measured error covers at most tau pixels of a 1280 x 720 frame, 60 "
      "degrees high, from anywhere in the viewcell (off: full detail). The walk of each scene is simulated at every "
      "tau over the scene's declared link with pvs+eps (bytes down: geometry, masks and lists; mean triangles a frame",
      plan.speed_search ? "; the highest speed without a stall" : "", "); the real client then draws the levels "
      "against the full scene in the object-id buffer (--verify): the share of differing pixels and the farthest of "
      "them from a full-detail silhouette, which the tests hold within tau + 1 px."));
  struct Point {
    json tau;
    double bytes = 0.0, triangles = 0.0;
    std::optional<double> speed;
    json by_distance;  // simulate's mean_triangles_by_distance
  };
  std::map<std::string, std::vector<Point>> by_scene;
  for (const std::string& scene : plan.scenes) {
    const std::optional<json> j = page.Run(
        "simulate levels " + scene, {"simulate", "--scene", scene, "--schemes", "pvs+eps", "--lod", plan.taus, "--json"});
    if (!j) continue;
    const json runs = j->contains("runs") ? j->at("runs") : json::array({*j});
    for (const json& r : runs) {
      by_scene[scene].push_back({r.at("lod_tau_px"), r.at("bytes").get<double>(), r.at("mean_triangles_drawn").get<double>(),
                                 std::nullopt, r.value("mean_triangles_by_distance", json::array())});
    }
    if (!plan.speed_search) continue;
    const std::optional<json> s = page.Run("simulate levels " + scene + " max speed",
                                           {"simulate", "--scene", scene, "--schemes", "pvs+eps", "--lod", plan.taus,
                                            "--speed", "max", "--json"});
    if (!s) continue;
    const json speed_runs = s->contains("runs") ? s->at("runs") : json::array({*s});
    for (size_t k = 0; k < speed_runs.size() && k < by_scene[scene].size(); ++k) {
      const json& v = speed_runs[k].at("max_speed_kmh");
      if (!v.is_null()) by_scene[scene][k].speed = v.get<double>();
    }
  }
  struct Check {
    json tau;
    double share = 0.0, farthest = 0.0;
    uint64_t frames = 0;
  };
  std::vector<Check> checks;
  if (!plan.client_scene.empty()) {
    const std::optional<json> c =
        page.Run("bench client levels " + plan.client_scene,
                 {"bench", "client", "--scene", plan.client_scene, "--lod", plan.taus.substr(plan.taus.find(',') + 1),
                  "--verify", "--seconds", plan.client_seconds, "--size", "1280x720", "--json"});
    if (c) {
      for (const auto& [name, m] : c->at("modes").items()) {
        if (name == "whole scene" || name == "pvs" || m.at("differing_share").is_null()) continue;
        checks.push_back({m.at("lod_tau_px"), m.at("differing_share").get<double>(),
                          m.at("max_silhouette_px").get<double>(), m.at("checked_frames").get<uint64_t>()});
      }
    }
  }
  if (by_scene.empty() && checks.empty()) return;

  std::vector<std::vector<std::string>> rows;
  GnuplotPlot plot = GnuplotPlot::Kept(page.Path("levels.png"), 1400, 1000);
  std::string bytes_plot, speed_plot, tris_plot;
  for (const auto& [scene, points] : by_scene) {
    GnuplotData d{absl::StrCat("levels_", rows.size(), ".dat"), ""};
    for (const Point& p : points) {
      absl::StrAppendFormat(&d.text, "%g %g %g %s\n", PlotTau(p.tau), p.bytes / 1e6, p.triangles,
                            p.speed.has_value() ? absl::StrFormat("%g", *p.speed) : "NaN");
      rows.push_back({scene, TauText(p.tau), Fixed(p.bytes / 1e6, 2), Fixed(p.triangles, 0),
                      p.speed.has_value() ? Fixed(*p.speed, 1) : std::string("—")});
    }
    plot.data.push_back(d);
    const std::string title = GnuplotQuote(scene);
    absl::StrAppend(&bytes_plot, bytes_plot.empty() ? "plot " : ", ", GnuplotQuote(d.name),
                    " using 1:2 with linespoints lw 2 pt 7 title ", title);
    absl::StrAppend(&tris_plot, tris_plot.empty() ? "plot " : ", ", GnuplotQuote(d.name),
                    " using 1:3 with linespoints lw 2 pt 7 title ", title);
    absl::StrAppend(&speed_plot, speed_plot.empty() ? "plot " : ", ", GnuplotQuote(d.name),
                    " using 1:4 with linespoints lw 2 pt 7 title ", title);
  }
  GnuplotData pixels{"levels_pixels.dat", ""};
  std::vector<std::vector<std::string>> check_rows;
  for (const Check& c : checks) {
    absl::StrAppendFormat(&pixels.text, "%g %g %g\n", PlotTau(c.tau), 100.0 * c.share, c.farthest);
    check_rows.push_back({plan.client_scene, TauText(c.tau), absl::StrFormat("%.4f", 100.0 * c.share),
                          Fixed(c.farthest, 1), c.tau.is_null() ? "0 (pixel error)" : absl::StrFormat("%g", c.tau.get<double>() + 1.0),
                          std::to_string(c.frames)});
  }
  plot.data.push_back(pixels);
  const std::string x = "set logscale x\nset xlabel 'screen error tau (pixels, log scale; off drawn at 0.25)'\n"
                        "set key top left\nset grid\nset yrange [0:*]\n";
  plot.script = absl::StrCat(
      "set multiplot layout 2,2 title 'Levels of detail: what accuracy costs (pvs+eps, 1280 x 720, 60 degrees)'\n", x,
      "set title 'bytes down over the walk'\nset ylabel 'MB'\n", bytes_plot.empty() ? EmptyPanel("no simulation") : bytes_plot,
      "\nset title 'highest speed without a stall'\nset ylabel 'km/h'\n",
      speed_plot.empty() || !plan.speed_search ? EmptyPanel("not measured (quick report)") : speed_plot,
      "\nset title 'triangles drawn a frame, mean'\nset ylabel 'triangles'\n", tris_plot.empty() ? EmptyPanel("no simulation") : tris_plot,
      "\nset title ", GnuplotQuote(absl::StrCat("differing pixels against the full scene (", plan.client_scene, ")")),
      "\nset ylabel '% of pixels checked'\nset y2label 'farthest from a silhouette (px)'\nset y2tics\nset y2range [0:*]\n",
      checks.empty() ? EmptyPanel("not measured (quick report)")
                     : "plot 'levels_pixels.dat' using 1:2 with linespoints lw 2 pt 7 title 'differing pixels (%)', "
                       "'levels_pixels.dat' using 1:3 axes x1y2 with linespoints lw 2 pt 5 title 'farthest (px)'",
      "\nunset multiplot\n");
  if (page.Plot("levels plot", plot)) page.Image("levels.png", "Bytes, speed, triangles and differing pixels against tau");
  if (!rows.empty()) page.Table({"scene", "tau (px)", "MB down", "triangles a frame", "highest speed without a stall (km/h)"}, rows);
  // Where the triangles come from: by the drawn objects' distance from the eye (what levels
  // can still save: far objects coarsen first).
  std::vector<std::string> band_header = {"scene", "tau (px)"};
  std::vector<std::vector<std::string>> band_rows;
  for (const auto& [scene, points] : by_scene) {
    for (const Point& p : points) {
      if (!p.by_distance.is_array() || p.by_distance.empty()) continue;
      std::vector<std::string> row = {scene, TauText(p.tau)};
      for (const json& b : p.by_distance) row.push_back(Fixed(b.at("triangles").get<double>(), 0));
      if (band_header.size() == 2) {
        for (const json& b : p.by_distance) {
          const double from = b.at("from_m").get<double>();
          band_header.push_back(b.at("to_m").is_null() ? absl::StrFormat("beyond %g m", from)
                                                       : absl::StrFormat("%g-%g m", from, b.at("to_m").get<double>()));
        }
      }
      band_rows.push_back(std::move(row));
    }
  }
  if (!band_rows.empty()) {
    page.Text("Triangles drawn a frame (mean) by the distance from the eye to each drawn object's box:");
    page.Table(band_header, band_rows);
  }
  if (!check_rows.empty()) {
    page.Table({"scene (client)", "tau (px)", "differing pixels %", "farthest from a silhouette (px)", "bound (px)",
                "frames checked"},
               check_rows);
  }
}

}  // namespace vistream::tools
