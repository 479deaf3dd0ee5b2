// vistream bench client: the headless client along a catalog walk through a real server on
// loopback (in this process), measured three ways in one run: the viewcell PVS narrowed by
// ε-masks (what the client does), the viewcell PVS whole, and the whole scene drawn every frame
// (frustum culling only). Reports fps, frame-time median and p99, triangles drawn a frame, and
// masked and hole frames; then fps and frame-time p99 with masks against without, side by side.

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "client/walkthrough.h"
#include "server/served_scene.h"
#include "server/service.h"
#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/terminal_progress.h"

namespace vistream::tools {

namespace {

struct BenchClientArgs {
  std::string scene = "default";
  std::string path;
  std::string size = "1280x720";
  double speed_kmh = 30.0;
  double seconds = 60.0;
  unsigned threads = 2;
  bool json = false;
};

int BenchClient(const BenchClientArgs& a) {
  int width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%dx%d", &width, &height) != 2 || width < 16 || height < 16 || width > 8192 ||
      height > 8192) {
    std::fprintf(stderr, "vistream: error: --size '%s': expected WIDTHxHEIGHT, e.g. 1280x720\n", a.size.c_str());
    return 2;
  }
  TerminalProgress progress;
  server::ServedSceneOptions so;
  so.scene = a.scene;
  so.threads = a.threads;
  scenes::RunControl run;
  run.progress = &progress;
  absl::StatusOr<std::unique_ptr<server::ServedScene>> served = server::ServedScene::Create(so, run);
  if (!served.ok()) {
    std::fprintf(stderr, "vistream: error: %s\n", std::string(served.status().message()).c_str());
    return 1;
  }
  server::ServerOptions options;
  options.listen = "127.0.0.1:0";
  absl::StatusOr<std::unique_ptr<server::WalkthroughServer>> server =
      server::WalkthroughServer::Start(served->get(), options, nullptr);
  if (!server.ok()) {
    std::fprintf(stderr, "vistream: error: %s\n", std::string(server.status().message()).c_str());
    return 1;
  }
  struct Mode {
    const char* name;
    bool masks, everything;
  };
  const Mode modes[] = {{"pvs+eps", true, false}, {"pvs", false, false}, {"whole scene", false, true}};
  nlohmann::ordered_json out;
  out["scene"] = a.scene;
  out["size"] = a.size;
  std::vector<client::WalkthroughSummary> results;
  server::TaskStats masks_with;  // the server's mask queue during the mode with masks
  for (const Mode& m : modes) {
    client::WalkthroughOptions o;
    o.server = "127.0.0.1:" + std::to_string((*server)->port());
    o.headless = true;
    o.path = a.path;
    o.speed_kmh = a.speed_kmh;
    o.seconds = a.seconds;
    o.width = width;
    o.height = height;
    o.max_fps = 0.0;  // as fast as it draws: the measure
    o.use_masks = m.masks;
    o.draw_everything = m.everything;
    o.local_scene = &(*served)->scene();
    o.log = [&](const std::string& line) { std::fprintf(stderr, "  %s: %s\n", m.name, line.c_str()); };
    std::fprintf(stderr, "bench client: %s ...\n", m.name);
    const server::TaskStats masks_before = (*served)->masks().stats();
    absl::StatusOr<client::WalkthroughSummary> s = client::RunWalkthrough(o);
    const server::TaskStats masks_after = (*served)->masks().stats();
    if (!s.ok()) {
      std::fprintf(stderr, "vistream: error: %s: %s\n", m.name, std::string(s.status().message()).c_str());
      return 1;
    }
    results.push_back(*s);
    if (m.masks) {
      masks_with.computed = masks_after.computed - masks_before.computed;
      masks_with.dropped = masks_after.dropped - masks_before.dropped;
      masks_with.cpu_s = masks_after.cpu_s - masks_before.cpu_s;
    }
    const double share = s->scene_triangles > 0 ? s->mean_triangles_drawn / static_cast<double>(s->scene_triangles) : 0;
    out["modes"][m.name] = {{"frames", s->frames},
                            {"fps", s->fps},
                            {"fps_median", s->frame_ms_p50 > 0 ? 1000.0 / s->frame_ms_p50 : 0.0},
                            {"frame_ms_p50", s->frame_ms_p50},
                            {"frame_ms_p99", s->frame_ms_p99},
                            {"p99_over_p50", s->frame_ms_p50 > 0 ? s->frame_ms_p99 / s->frame_ms_p50 : 0.0},
                            {"mean_triangles_drawn", s->mean_triangles_drawn},
                            {"triangle_share", share},
                            {"mean_triangles_without_masks", s->mean_triangles_without_masks},
                            {"stalls", s->stalls},
                            {"frames_masked", s->frames_masked},
                            {"hole_frames", s->hole_frames},
                            {"masks_received", s->masks_received},
                            // The server's mask queue over the mode (idle-priority threads: a
                            // client drawing flat out on the same cores leaves them little).
                            {"server_masks_computed", masks_after.computed - masks_before.computed},
                            {"server_masks_dropped", masks_after.dropped - masks_before.dropped},
                            {"server_mask_cpu_s", masks_after.cpu_s - masks_before.cpu_s},
                            {"bytes_received", s->bytes_received}};
    if (!out.contains("path")) {
      out["path"] = s->path;
      out["speed_kmh"] = s->speed_kmh;
      out["walk_s"] = s->walk_s;
      out["scene_triangles"] = s->scene_triangles;
    }
  }
  // results[0] drew with masks, results[1] the same walk without.
  const client::WalkthroughSummary& with = results[0];
  const client::WalkthroughSummary& without = results[1];
  auto ratio = [](double x, double y) { return y > 0.0 ? x / y : 0.0; };
  out["masks_against_pvs"] = {{"fps_with_masks", with.fps},
                              {"fps_without_masks", without.fps},
                              {"fps_ratio", ratio(with.fps, without.fps)},
                              {"frame_ms_p99_with_masks", with.frame_ms_p99},
                              {"frame_ms_p99_without_masks", without.frame_ms_p99},
                              {"frame_ms_p99_ratio", ratio(with.frame_ms_p99, without.frame_ms_p99)},
                              {"mean_triangles_with_masks", with.mean_triangles_drawn},
                              {"mean_triangles_without_masks", without.mean_triangles_drawn},
                              {"triangle_ratio", ratio(with.mean_triangles_drawn, without.mean_triangles_drawn)},
                              {"frames_masked", with.frames_masked},
                              {"masked_share", ratio(static_cast<double>(with.frames_masked),
                                                     static_cast<double>(with.frames))},
                              {"hole_frames_with_masks", with.hole_frames},
                              {"hole_frames_without_masks", without.hole_frames}};
  if (a.json) {
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("bench client: %s along '%s' at %.0f km/h for %.0f s, %s, headless (OSMesa)\n", a.scene.c_str(),
              results.front().path.c_str(), results.front().speed_kmh, results.front().walk_s, a.size.c_str());
  std::printf("%-12s %8s %8s %10s %10s %10s %9s %14s %9s %7s %8s %7s\n", "mode", "frames", "fps", "fps(p50)",
              "p50 ms", "p99 ms", "p99/p50", "triangles", "% scene", "stalls", "masked", "holes");
  for (size_t k = 0; k < results.size(); ++k) {
    const client::WalkthroughSummary& s = results[k];
    std::printf("%-12s %8llu %8.1f %10.1f %10.2f %10.2f %9.2f %14.0f %8.3f%% %7llu %8llu %7llu\n", modes[k].name,
                static_cast<unsigned long long>(s.frames), s.fps, s.frame_ms_p50 > 0 ? 1000.0 / s.frame_ms_p50 : 0.0,
                s.frame_ms_p50, s.frame_ms_p99, s.frame_ms_p50 > 0 ? s.frame_ms_p99 / s.frame_ms_p50 : 0.0,
                s.mean_triangles_drawn,
                s.scene_triangles > 0 ? 100.0 * s.mean_triangles_drawn / static_cast<double>(s.scene_triangles) : 0.0,
                static_cast<unsigned long long>(s.stalls), static_cast<unsigned long long>(s.frames_masked),
                static_cast<unsigned long long>(s.hole_frames));
  }
  std::printf(
      "with masks against without: %.1f against %.1f fps (x%.2f), frame time p99 %.2f against %.2f ms (x%.2f), "
      "%.0f against %.0f triangles a frame (%.1f%%); %llu of %llu frames masked, %llu hole frames (the server computed "
      "%llu masks in %.1f s of CPU, dropped %llu)\n",
      with.fps, without.fps, ratio(with.fps, without.fps), with.frame_ms_p99, without.frame_ms_p99,
      ratio(with.frame_ms_p99, without.frame_ms_p99), with.mean_triangles_drawn, without.mean_triangles_drawn,
      100.0 * ratio(with.mean_triangles_drawn, without.mean_triangles_drawn),
      static_cast<unsigned long long>(with.frames_masked), static_cast<unsigned long long>(with.frames),
      static_cast<unsigned long long>(with.hole_frames), static_cast<unsigned long long>(masks_with.computed),
      masks_with.cpu_s, static_cast<unsigned long long>(masks_with.dropped));
  return 0;
}

}  // namespace

void AddBenchClientCommand(CLI::App* bench, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<BenchClientArgs>(
      bench, "client", "the headless client along a walk: PVS+ε, PVS, whole scene", BenchClient,
      done);
  c->add_option("--scene", args->scene, "catalog name")->capture_default_str();
  c->add_option("--path", args->path, "walk of the catalog entry (default: its first)")->check(NonEmpty("an empty walk name"));
  c->add_option("--size", args->size, "frame size, WIDTHxHEIGHT")->capture_default_str();
  c->add_option("--speed", args->speed_kmh, "walking speed, km/h")->check(FiniteRange(0.1, 1000.0))
      ->capture_default_str();
  c->add_option("--seconds", args->seconds, "seconds of the walk per mode (0: all of it)")
      ->check(FiniteRange(0.0, 86400.0))->capture_default_str();
  c->add_option("--threads", args->threads, "server PVS workers")->check(WholeRange(1, 256))->capture_default_str();
  c->add_flag("--json", args->json, "print one JSON object");
}

}  // namespace vistream::tools
