// The tool's figures read on their own: maps (Cairo) with a frame, a title, a legend, a colour
// bar and a scale bar; plots (gnuplot) of the size asked for; `report`'s option errors. The
// PNGs are read back with Cairo and checked pixel by pixel where the layout promises exact
// colours: the map's frame is the image's only pure black, legend swatches and the colour
// bar are drawn without antialiasing (tools/top_view_map.h).
#include <cairo.h>

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "tests/cli_test_util.h"

namespace {

using vistream::testing::ExpectBadOption;
using vistream::testing::ExpectRunTimeError;
using vistream::testing::RunResult;
using vistream::testing::ShellOutput;
using vistream::testing::Tmp;
using vistream::testing::Vistream;

struct Rgb {
  int r, g, b;
};

class Png {
 public:
  explicit Png(const std::string& path) : surface_(cairo_image_surface_create_from_png(path.c_str())) {}
  ~Png() { cairo_surface_destroy(surface_); }
  bool ok() const { return cairo_surface_status(surface_) == CAIRO_STATUS_SUCCESS; }
  int width() const { return cairo_image_surface_get_width(surface_); }
  int height() const { return cairo_image_surface_get_height(surface_); }
  Rgb At(int x, int y) const {
    const unsigned char* row = cairo_image_surface_get_data(surface_) + static_cast<size_t>(y) * cairo_image_surface_get_stride(surface_);
    uint32_t p = 0;
    std::memcpy(&p, row + 4 * x, 4);
    return {static_cast<int>((p >> 16) & 0xff), static_cast<int>((p >> 8) & 0xff), static_cast<int>(p & 0xff)};
  }
  // Pixels of exactly `c` in [x0, x1) x [y0, y1).
  int Count(Rgb c, int x0, int y0, int x1, int y1) const {
    int n = 0;
    for (int y = std::max(0, y0); y < std::min(height(), y1); ++y) {
      for (int x = std::max(0, x0); x < std::min(width(), x1); ++x) {
        const Rgb p = At(x, y);
        n += p.r == c.r && p.g == c.g && p.b == c.b;
      }
    }
    return n;
  }
  // Pixels darker than 100 in every channel (text, marks).
  int Dark(int x0, int y0, int x1, int y1) const {
    int n = 0;
    for (int y = std::max(0, y0); y < std::min(height(), y1); ++y) {
      for (int x = std::max(0, x0); x < std::min(width(), x1); ++x) {
        const Rgb p = At(x, y);
        n += p.r < 100 && p.g < 100 && p.b < 100;
      }
    }
    return n;
  }

 private:
  cairo_surface_t* surface_;
};

// The map's frame: the bounding box of the pure black pixels (inclusive).
struct Frame {
  int x0 = 1 << 30, y0 = 1 << 30, x1 = -1, y1 = -1;
};
Frame FindFrame(const Png& png) {
  Frame f;
  for (int y = 0; y < png.height(); ++y) {
    for (int x = 0; x < png.width(); ++x) {
      const Rgb p = png.At(x, y);
      if (p.r == 0 && p.g == 0 && p.b == 0) {
        f.x0 = std::min(f.x0, x), f.y0 = std::min(f.y0, y), f.x1 = std::max(f.x1, x), f.y1 = std::max(f.y1, y);
      }
    }
  }
  return f;
}

constexpr Rgb kInk{25, 25, 25};  // text, marks and the scale bar's dark segments
constexpr Rgb kRamp0{68, 1, 84}, kRamp1{253, 231, 37};

TEST(CliFigures, PvsMapHasATitleALegendAScaleBarAndTheViewcellWhereItIs) {
  const std::string png_path = Tmp("pvs_legend.png");
  const RunResult r = Vistream("pvs --scene default --cell 10,10 --res 64 --json --map " + png_path);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const RunResult info = Vistream("scene info default --json");
  ASSERT_EQ(info.exit_code, 0) << info.out;
  const nlohmann::json b = nlohmann::json::parse(info.out).at("bounds");
  const double bx0 = b["min"][0], by0 = b["min"][1], bx1 = b["max"][0], by1 = b["max"][1];

  const Png png(png_path);
  ASSERT_TRUE(png.ok());
  const Frame f = FindFrame(png);
  ASSERT_GE(f.x1, 0) << "no frame";
  // The map inside the frame: 2048 pixels on the scene's longer side.
  const int map_w = f.x1 - f.x0 - 1, map_h = f.y1 - f.y0 - 1;
  EXPECT_EQ(std::max(map_w, map_h), 2048);
  const double scale = std::max(bx1 - bx0, by1 - by0) / 2048.0;
  EXPECT_NEAR(map_w, (bx1 - bx0) / scale, 1.0);
  // Margins on every side: axes left and below, the title above, the legend right.
  EXPECT_GT(f.x0, 60);
  EXPECT_GT(f.y0, 40);
  EXPECT_GT(png.height() - f.y1, 40);
  EXPECT_GT(png.width() - f.x1, 300);
  EXPECT_GT(png.Dark(f.x0, 0, png.width(), f.y0), 500) << "no title";
  EXPECT_GT(png.Dark(f.x0, f.y1 + 1, f.x1, png.height()), 200) << "no x ticks";
  EXPECT_GT(png.Dark(0, f.y0, f.x0, f.y1), 200) << "no y ticks";
  // The legend right of the frame: a swatch of each colour the map uses.
  const int lx = f.x1 + 1;
  EXPECT_GT(png.Count({30, 200, 60}, lx, 0, png.width(), png.height()), 200) << "viewcell swatch";
  EXPECT_GT(png.Count({40, 90, 220}, lx, 0, png.width(), png.height()), 200) << "in-PVS swatch";
  EXPECT_GT(png.Count({215, 50, 40}, lx, 0, png.width(), png.height()), 200) << "occluded swatch";
  // The scale bar's dark segments (and the north arrow) in exact ink.
  EXPECT_GT(png.Count(kInk, lx, 0, png.width(), png.height()), 1000) << "no scale bar";
  // The viewcell's centre, in the map, is the viewcell's green.
  const auto& cell = j.at("cell_box");
  const double cx = 0.5 * (cell["min"][0].get<double>() + cell["max"][0].get<double>());
  const double cy = 0.5 * (cell["min"][1].get<double>() + cell["max"][1].get<double>());
  const int px = f.x0 + 1 + static_cast<int>((cx - bx0) / scale);
  const int py = f.y0 + 1 + map_h - 1 - static_cast<int>((cy - by0) / scale);
  const Rgb c = png.At(px, py);
  EXPECT_EQ(c.r, 30);
  EXPECT_EQ(c.g, 200);
  EXPECT_EQ(c.b, 60);
}

TEST(CliFigures, HeatmapAndSceneMapHaveALabelledColourBar) {
  const std::string heat = Tmp("heat_bar.png"), map = Tmp("map_bar.png");
  const RunResult h = Vistream("agvs heatmap --scene city1 --seconds 0.3 -o " + heat + " --json");
  ASSERT_EQ(h.exit_code, 0) << h.out;
  const nlohmann::json j = nlohmann::json::parse(h.out);
  const Png hp(heat);
  ASSERT_TRUE(hp.ok());
  EXPECT_EQ(j.at("width").get<int>(), hp.width());
  EXPECT_EQ(j.at("height").get<int>(), hp.height());
  Frame f = FindFrame(hp);
  ASSERT_GE(f.x1, 0);
  // The colour bar's two ends, exact, right of the map; its tick labels beside it.
  EXPECT_GT(hp.Count(kRamp0, f.x1 + 1, 0, hp.width(), hp.height()), 20);
  EXPECT_GT(hp.Count(kRamp1, f.x1 + 1, 0, hp.width(), hp.height()), 20);
  EXPECT_GT(hp.Dark(f.x1 + 1, 0, hp.width(), hp.height()), 2000);

  const RunResult m = Vistream("scene map city1 --size 800 -o " + map);
  ASSERT_EQ(m.exit_code, 0) << m.out;
  const Png mp(map);
  ASSERT_TRUE(mp.ok());
  f = FindFrame(mp);
  ASSERT_GE(f.x1, 0);
  EXPECT_EQ(std::max(f.x1 - f.x0 - 1, f.y1 - f.y0 - 1), 800);
  EXPECT_GT(mp.Count(kRamp0, f.x1 + 1, 0, mp.width(), mp.height()), 20);
  EXPECT_GT(mp.Count(kRamp1, f.x1 + 1, 0, mp.width(), mp.height()), 20);
  EXPECT_GT(mp.Count({220, 30, 30}, f.x1 + 1, 0, mp.width(), mp.height()), 40) << "the walk's legend line";
}

// A legend's outline swatch: a horizontal run of at least `run` pixels of exactly `c` right of
// the frame. Antialiased text never makes one (its edge pixels blend with the paper).
bool HasLegendRun(const Png& png, const Frame& f, Rgb c, int run) {
  for (int y = 0; y < png.height(); ++y) {
    int n = 0;
    for (int x = f.x1 + 1; x < png.width(); ++x) {
      const Rgb p = png.At(x, y);
      n = p.r == c.r && p.g == c.g && p.b == c.b ? n + 1 : 0;
      if (n >= run) return true;
    }
  }
  return false;
}

// city1 is about 1,400 m on its longer side: 600 pixels are 2.3 m each (too coarse for
// outlines, which are drawn below 1.5 m a pixel), 2,000 pixels 0.7 m each.
TEST(CliFigures, HeatmapSizeSetsTheMapAndFootprintsAreOutlinedOnlyWhereAPixelIsFine) {
  const Rgb outline{40, 40, 40};  // agvs_common.cpp's footprint outline
  for (const int size : {600, 2000}) {
    const std::string png_path = Tmp("heat_size_" + std::to_string(size) + ".png");
    const RunResult r = Vistream("agvs heatmap --scene city1 --seconds 0.2 --size " + std::to_string(size) + " -o " +
                                 png_path + " --json");
    ASSERT_EQ(r.exit_code, 0) << r.out;
    const nlohmann::json j = nlohmann::json::parse(r.out);
    const Png png(png_path);
    ASSERT_TRUE(png.ok());
    EXPECT_EQ(j.at("width").get<int>(), png.width());
    const Frame f = FindFrame(png);
    ASSERT_GE(f.x1, 0) << "no frame";
    EXPECT_EQ(std::max(f.x1 - f.x0 - 1, f.y1 - f.y0 - 1), size);
    const double mpp = j.at("metres_per_pixel").get<double>();
    EXPECT_GT(mpp * size, 1300.0);
    EXPECT_LT(mpp * size, 1600.0);
    const bool fine = size == 2000;
    EXPECT_EQ(j.at("footprint_outlines").get<bool>(), fine) << size;
    // The legend shows the outline swatch exactly when the map has outlines.
    EXPECT_EQ(HasLegendRun(png, f, outline, 20), fine) << size;
  }
  for (const char* bad : {"0", "15", "16385", "1e3", "big"}) {
    ExpectBadOption(std::string("agvs heatmap --scene city1 --seconds 0.2 -o ") + Tmp("bad.png") + " --size " + bad,
                    "--size");
  }
}

TEST(CliFigures, SceneMapOutlinesFootprintsOnlyWhereAPixelIsFine) {
  const Rgb outline{60, 60, 60};  // cmd_scene.cpp's footprint edge
  for (const int size : {600, 2000}) {
    const std::string png_path = Tmp("scene_size_" + std::to_string(size) + ".png");
    const RunResult r = Vistream("scene map city1 --size " + std::to_string(size) + " -o " + png_path);
    ASSERT_EQ(r.exit_code, 0) << r.out;
    const Png png(png_path);
    ASSERT_TRUE(png.ok());
    const Frame f = FindFrame(png);
    ASSERT_GE(f.x1, 0) << "no frame";
    EXPECT_EQ(std::max(f.x1 - f.x0 - 1, f.y1 - f.y0 - 1), size);
    EXPECT_EQ(HasLegendRun(png, f, outline, 20), size == 2000) << size;
  }
}

TEST(CliFigures, BenchAgvsPlotIsAGnuplotFigureAndSaysWhenGnuplotIsMissing) {
  const std::string png = Tmp("agvs_plot.png");
  const std::string args = "bench agvs --scene city1 --seconds 0.2 --views 1 --res 16 --checkpoints 3 --json --plot ";
  const RunResult r = Vistream(args + png);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const Png p(png);
  ASSERT_TRUE(p.ok());
  EXPECT_EQ(p.width(), 1200);
  EXPECT_EQ(p.height(), 1000);
  // Axes, tick labels, titles and curves: plenty of dark pixels, not a blank page.
  EXPECT_GT(p.Dark(0, 0, p.width(), p.height()), 5000);
  // The three strategies' colours (AGVS, SGVS, REF) as drawn in the plot and its legend.
  EXPECT_GT(p.Count({0xd0, 0x8c, 0x00}, 0, 0, p.width(), p.height()), 50);
  EXPECT_GT(p.Count({0x1b, 0x9e, 0x9e}, 0, 0, p.width(), p.height()), 50);
  EXPECT_GT(p.Count({0xd6, 0x27, 0x28}, 0, 0, p.width(), p.height()), 50);

  setenv("VISTREAM_GNUPLOT", "/nonexistent/gnuplot", 1);
  ExpectRunTimeError(args + Tmp("no_gnuplot.png"), "cannot run gnuplot ('/nonexistent/gnuplot' not found)");
  unsetenv("VISTREAM_GNUPLOT");
}

// bench epsilon --json: per neighbourhood, where the time goes and a digest of the superset,
// so that two builds can be compared set by set. Columns none and rays are the same exact test
// (neither drops hidden occluders), so their sets, and digests, agree neighbourhood by
// neighbourhood; the means are those of the per-neighbourhood figures.
TEST(CliFigures, BenchEpsilonJsonGivesPerNeighbourhoodFiguresAndSetDigests) {
  const RunResult r = Vistream("bench epsilon --scene city2 --count 4 --opts none,rays --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  const auto& t2 = j.at("table2");
  ASSERT_EQ(t2.size(), 2u);
  for (const auto& c : t2) {
    const auto& per = c.at("per_neighbourhood");
    ASSERT_EQ(per.size(), 4u);
    double ms = 0, cpu = 0, visible = 0;
    for (const auto& q : per) {
      ms += q.at("ms").get<double>();
      cpu += q.at("cpu_ms").get<double>();
      visible += q.at("visible_triangles").get<double>();
      EXPECT_EQ(q.at("digest").get<std::string>().size(), 16u);
      // A thread's CPU time never exceeds the wall-clock time it took (timer granularity aside).
      EXPECT_LE(q.at("cpu_ms").get<double>(), q.at("ms").get<double>() + 1.0);
      EXPECT_EQ(q.at("centre").size(), 3u);
    }
    EXPECT_NEAR(c.at("ms").get<double>(), ms / 4, 1e-9 + 1e-9 * ms);
    EXPECT_NEAR(c.at("cpu_ms").get<double>(), cpu / 4, 1e-9 + 1e-9 * cpu);
    EXPECT_NEAR(c.at("visible_triangles").get<double>(), visible / 4, 1e-9 * (1 + visible));
  }
  for (size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(t2[0]["per_neighbourhood"][k].at("digest"), t2[1]["per_neighbourhood"][k].at("digest")) << k;
  }
  EXPECT_EQ(t2[0].at("digest"), t2[1].at("digest"));
  // Different sets give different digests: the neighbourhoods see different parts of the city.
  EXPECT_NE(t2[0]["per_neighbourhood"][0].at("digest"), t2[0]["per_neighbourhood"][1].at("digest"));
}

// vistream bench client (issue 45): the modes side by side through a real server on loopback,
// levels first; with --verify each mode's differing pixels against the full scene, said in the
// text as well as --json (full detail: none; levels: within a silhouette's reach).
TEST(CliFigures, BenchClientPutsLevelsBesideFullDetailAndSaysEachCheckedModesDifferingPixels) {
  const RunResult r = Vistream("bench client --scene city2 --lod 1 --verify --seconds 3 --size 160x90");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  for (const char* mode : {"pvs+eps+lod ", "pvs+eps ", "pvs ", "whole scene "}) {
    EXPECT_NE(r.out.find(std::string("\n") + mode), std::string::npos) << mode << " row: " << r.out;
  }
  EXPECT_NE(r.out.find("pvs+eps+lod      checked against the full scene: "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("pvs+eps          checked against the full scene: 0 of "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("pvs              checked against the full scene: 0 of "), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("levels at tau 1 px against full detail (both with masks): "), std::string::npos) << r.out;
}

TEST(CliFigures, ReportRejectsAnOutThatIsNoFolder) {
  const std::string file = Tmp("not_a_folder");
  { std::FILE* f = std::fopen(file.c_str(), "w"); ASSERT_NE(f, nullptr); std::fclose(f); }
  ExpectBadOption("report --quick --out " + file, "--out: '" + file + "': cannot make the folder");
  ExpectBadOption("report --quick --out /proc/vistream-report", "--out: '/proc/vistream-report': cannot make the folder");
  ExpectBadOption("report --slow", "--slow");
}

}  // namespace

namespace {

// The whole quick report (about 20 s on the 2-core machine): the page, its stamp, a section for
// each figure, and every PNG it names.
// ^C or SIGTERM: the running step is stopped (and says so, not FAILED), no other starts, exit
// 130, and no report.md (an older one is removed first: it would not match the PNGs this run
// replaced).
TEST(CliFigures, AStoppedReportWritesNoPage) {
  for (const char* signal : {"INT", "TERM"}) {
    const std::string dir = Tmp(std::string("stopped-") + signal);
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    { std::ofstream(dir + "/report.md") << "an older page\n"; }
    // One signal to the report alone, as a ^C in a terminal would be. The shell prints the
    // report's exit status last.
    const std::string cmd = std::string("sh -c '") + VISTREAM_BIN + " report --quick --out " + dir +
                            " 2>&1 & pid=$!; sleep 5; kill -" + signal + " $pid; wait $pid; echo \"rc=$?\"'";
    const std::string out = ShellOutput(cmd);
    EXPECT_NE(out.find("rc=130"), std::string::npos) << signal << ": " << out;
    EXPECT_NE(out.find("vistream: interrupted (report stopped after "), std::string::npos) << signal << ": " << out;
    EXPECT_FALSE(std::filesystem::exists(dir + "/report.md")) << signal;
    EXPECT_EQ(out.find("FAILED"), std::string::npos) << signal << ": the stopped step is not a failure: " << out;
  }
}

TEST(CliFigures, QuickReportWritesThePageAndEveryImageItNames) {
  const std::string dir = Tmp("report");
  std::filesystem::remove_all(dir);
  const RunResult r = Vistream("report --quick --json --out " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  // Progress on stderr, a line a step with its time; then the JSON summary on stdout.
  EXPECT_NE(r.out.find("report: [1] scene info"), std::string::npos) << r.out;
  const size_t json_at = r.out.find("\n{\n");
  ASSERT_NE(json_at, std::string::npos) << r.out;
  const nlohmann::json j = nlohmann::json::parse(r.out.substr(json_at + 1));
  EXPECT_EQ(j.at("failures").get<int>(), 0);
  EXPECT_TRUE(j.at("quick").get<bool>());
  std::ifstream in(dir + "/report.md");
  const std::string md((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (const char* s : {"Generated by `vistream report --quick`", "; commit ", "cores", "## Table 1", "## Tables 1 and 2",
                        "## Global visibility sampling", "## Latency", "## PVS maps", "## PVS cost heatmap",
                        "Command: `vistream bench table1 --scene default"}) {
    EXPECT_NE(md.find(s), std::string::npos) << s;
  }
  // The latency section: the simulator's sweeps, one command each, and their plots; the schemes
  // and speeds with masked frames, hole frames and triangles drawn with and without masks.
  for (const char* s : {"| speed, scheme | stalls |", "| bandwidth | stalls |", "| scheme | stalls |",
                        "| mean triangles drawn | masked frames % | hole frames | mean triangles without masks |",
                        "Command: `vistream simulate --scene default --path avenue-and-back-streets --schemes pvs,pvs+eps "
                        "--speeds ",
                        " km/h, pvs+eps |", "max speed without a hole frame, km/h",
                        "(latency_speed_default.png)", "(latency_bandwidth_default.png)", "(latency_bytes_default.png)",
                        "(latency_triangles_default.png)", "Triangles drawn per frame along the walk at 6 km/h",
                        "Machine load: the report's processes used ",
                        "| scene | tau (px) | 0-300 m | 300-900 m | 900-2000 m | beyond 2000 m |"}) {
    EXPECT_NE(md.find(s), std::string::npos) << s;
  }
  EXPECT_FALSE(std::filesystem::exists(dir + "/latency_triangles_default.series")) << "the raw series is not kept";
  {
    // The triangles plot reads on its own: a title, both axes labelled with units, a legend
    // naming both schemes; its kept data has pvs+eps frames drawn with masks and fewer triangles.
    std::ifstream gp(dir + "/latency_triangles_default.gp");
    const std::string script((std::istreambuf_iterator<char>(gp)), std::istreambuf_iterator<char>());
    for (const char* s : {"set multiplot layout 2,1 title 'default: triangles drawn per frame along",
                          "set xlabel 'distance along the walk (m)'", "set ylabel 'triangles per frame'",
                          "set ylabel 'frames (%)'", "title 'pvs (viewcell PVS)'", "title 'pvs+eps (ε-masks)'",
                          "title 'masked frames'", "title 'hole frames'", "set key"}) {
      EXPECT_NE(script.find(s), std::string::npos) << s;
    }
    std::ifstream dat(dir + "/latency_triangles_default.triangles.dat");
    ASSERT_TRUE(dat);
    std::string line;
    double pvs_sum = 0, eps_sum = 0, masked_max = 0;
    size_t bins = 0;
    while (std::getline(dat, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream f(line);
      std::string x, pvs, eps, masked, holes;
      ASSERT_TRUE(f >> x >> pvs >> eps >> masked >> holes) << line;
      if (pvs == "NaN" || eps == "NaN") continue;
      pvs_sum += std::stod(pvs);
      eps_sum += std::stod(eps);
      masked_max = std::max(masked_max, std::stod(masked));
      ++bins;
    }
    EXPECT_GT(bins, 50u);
    EXPECT_GT(masked_max, 0.0);
    EXPECT_LT(eps_sum, pvs_sum);
  }
  EXPECT_EQ(md.find("this build has no `vistream simulate`"), std::string::npos);
  ASSERT_TRUE(j.at("cpu_share").is_number());
  EXPECT_GT(j.at("cpu_share").get<double>(), 0.0);
  EXPECT_LE(j.at("cpu_share").get<double>(), 1.0);
  // The gnuplot figures keep their script beside them (NAME.gp), which writes NAME.png at the
  // size the report asks for.
  const struct {
    const char* name;
    int width, height;
  } plots[] = {{"table1_default", 1200, 1000},
               {"latency_speed_default", 1100, 900},
               {"latency_bandwidth_default", 1100, 900},
               {"latency_bytes_default", 1000, 650},
               {"latency_triangles_default", 1200, 900}};
  for (const auto& p : plots) {
    std::ifstream gp(dir + "/" + p.name + ".gp");
    const std::string script((std::istreambuf_iterator<char>(gp)), std::istreambuf_iterator<char>());
    EXPECT_NE(script.find(std::string("set output '") + p.name + ".png'"), std::string::npos) << p.name;
    EXPECT_NE(script.find("set terminal pngcairo size " + std::to_string(p.width) + "," + std::to_string(p.height)),
              std::string::npos)
        << p.name;
    const Png png(dir + "/" + p.name + ".png");
    ASSERT_TRUE(png.ok()) << p.name;
    EXPECT_EQ(png.width(), p.width) << p.name;
    EXPECT_EQ(png.height(), p.height) << p.name;
  }
  const auto& images = j.at("images");
  EXPECT_GE(images.size(), 7u);
  for (const auto& name : images) {
    EXPECT_NE(md.find("](" + name.get<std::string>() + ")"), std::string::npos) << name;
    const Png png(dir + "/" + name.get<std::string>());
    EXPECT_TRUE(png.ok()) << name;
    EXPECT_GE(png.width(), 800) << name;
    EXPECT_GT(png.Dark(0, 0, png.width(), png.height()), 1000) << name << ": no text or lines";
  }
}

}  // namespace
