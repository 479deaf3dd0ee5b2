// vistream bench client: the headless client along a catalog walk through a real server on
// loopback (in this process), measured three ways in one run: the viewcell PVS narrowed by
// ε-masks (what the client does), the viewcell PVS whole, and the whole scene drawn every frame
// (frustum culling only); with --lod TAU (default 1 px; issue 45) first the PVS narrowed by
// ε-masks drawn at levels of detail (the server makes the scene's levels at start). Reports fps,
// frame-time median and p99, triangles drawn a frame, bytes received, and masked, hole and
// coarse frames; then fps and frame-time p99 with masks against without, and levels against
// full detail, side by side.

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
  std::string lod = "1";
  bool verify = false;
  bool json = false;
};

int BenchClient(const BenchClientArgs& a) {
  int width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%dx%d", &width, &height) != 2 || width < 16 || height < 16 || width > 8192 ||
      height > 8192) {
    std::fprintf(stderr, "vistream: error: --size '%s': expected WIDTHxHEIGHT, e.g. 1280x720\n", a.size.c_str());
    return 2;
  }
  // Each screen error of --lod is a mode of its own, first (off: none).
  std::vector<double> listed, taus;
  if (std::string why; !cli::ParseScreenErrors(a.lod, /*refuse_repeats=*/false, &listed, &why)) {
    return BadOption("bench client", "--lod", why);
  }
  for (double tau : listed) {
    if (tau > 0.0 && std::find(taus.begin(), taus.end(), tau) == taus.end()) taus.push_back(tau);
  }
  const double tau_px = taus.empty() ? 0.0 : taus.front();
  TerminalProgress progress;
  server::ServedSceneOptions so;
  so.scene = a.scene;
  so.threads = a.threads;
  so.make_levels = tau_px > 0.0;
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
    std::string name;
    bool masks, everything;
    double tau_px;
  };
  std::vector<Mode> modes;
  for (double tau : taus) {
    modes.push_back(Mode{taus.size() == 1 ? std::string("pvs+eps+lod") : absl::StrFormat("pvs+eps+lod %g", tau), true,
                         false, tau});
  }
  const size_t first = modes.size();  // the modes at full detail follow
  modes.push_back({"pvs+eps", true, false, 0.0});
  modes.push_back({"pvs", false, false, 0.0});
  modes.push_back({"whole scene", false, true, 0.0});
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
    o.lod_tau_px = m.tau_px;
    o.verify = a.verify && !m.everything;  // the whole scene drawn is the reference itself
    o.every_s = 1.0;
    o.local_scene = &(*served)->scene();
    o.log = [&](const std::string& line) { std::fprintf(stderr, "  %s: %s\n", m.name.c_str(), line.c_str()); };
    std::fprintf(stderr, "bench client: %s ...\n", m.name.c_str());
    const server::TaskStats masks_before = (*served)->masks().stats();
    absl::StatusOr<client::WalkthroughSummary> s = client::RunWalkthrough(o);
    const server::TaskStats masks_after = (*served)->masks().stats();
    if (!s.ok()) {
      std::fprintf(stderr, "vistream: error: %s: %s\n", m.name.c_str(), std::string(s.status().message()).c_str());
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
                            {"bytes_received", s->bytes_received},
                            {"geometry_bytes", s->geometry_bytes},
                            {"lod_tau_px", m.tau_px > 0.0 ? nlohmann::ordered_json(m.tau_px) : nlohmann::ordered_json()},
                            {"coarse_frames", s->coarse_frames},
                            {"level_objects_received", s->level_objects_received},
                            {"level_bytes_saved", s->level_bytes_saved},
                            // --verify: differing pixels against the full scene, their share and
                            // the farthest from a full-detail silhouette (null unchecked).
                            {"checked_frames", s->checked_frames},
                            {"pixel_error", s->verified ? nlohmann::ordered_json(s->pixel_error) : nlohmann::ordered_json()},
                            {"differing_share", s->verified && s->checked_pixels > 0
                                                    ? nlohmann::ordered_json(static_cast<double>(s->pixel_error) /
                                                                             static_cast<double>(s->checked_pixels))
                                                    : nlohmann::ordered_json()},
                            {"max_silhouette_px", s->verified ? nlohmann::ordered_json(s->max_silhouette_px)
                                                              : nlohmann::ordered_json()}};
    if (!out.contains("path")) {
      out["path"] = s->path;
      out["speed_kmh"] = s->speed_kmh;
      out["walk_s"] = s->walk_s;
      out["scene_triangles"] = s->scene_triangles;
    }
  }
  // With --lod the first results drew levels; then the same walk with masks at full detail, without masks.
  const client::WalkthroughSummary& with = results[first];
  const client::WalkthroughSummary& without = results[first + 1];
  auto ratio = [](double x, double y) { return y > 0.0 ? x / y : 0.0; };
  if (tau_px > 0.0) {
    const client::WalkthroughSummary& lod = results[0];
    out["levels_against_full"] = {
        {"lod_tau_px", tau_px},
        {"fps_with_levels", lod.fps},
        {"fps_full", with.fps},
        {"fps_ratio", ratio(lod.fps, with.fps)},
        {"frame_ms_p99_with_levels", lod.frame_ms_p99},
        {"frame_ms_p99_full", with.frame_ms_p99},
        {"mean_triangles_with_levels", lod.mean_triangles_drawn},
        {"mean_triangles_full", with.mean_triangles_drawn},
        {"triangle_ratio", ratio(lod.mean_triangles_drawn, with.mean_triangles_drawn)},
        {"bytes_received_with_levels", lod.bytes_received},
        {"bytes_received_full", with.bytes_received},
        {"bytes_ratio", ratio(static_cast<double>(lod.bytes_received), static_cast<double>(with.bytes_received))},
        {"coarse_frames", lod.coarse_frames},
        {"stalls_with_levels", lod.stalls},
        {"hole_frames_with_levels", lod.hole_frames}};
  }
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
  std::printf("%-16s %8s %8s %10s %10s %10s %9s %14s %9s %7s %8s %7s %7s %11s\n", "mode", "frames", "fps", "fps(p50)",
              "p50 ms", "p99 ms", "p99/p50", "triangles", "% scene", "stalls", "masked", "holes", "coarse", "MB down");
  for (size_t k = 0; k < results.size(); ++k) {
    const client::WalkthroughSummary& s = results[k];
    std::printf("%-16s %8llu %8.1f %10.1f %10.2f %10.2f %9.2f %14.0f %8.3f%% %7llu %8llu %7llu %7llu %11.2f\n", modes[k].name.c_str(),
                static_cast<unsigned long long>(s.frames), s.fps, s.frame_ms_p50 > 0 ? 1000.0 / s.frame_ms_p50 : 0.0,
                s.frame_ms_p50, s.frame_ms_p99, s.frame_ms_p50 > 0 ? s.frame_ms_p99 / s.frame_ms_p50 : 0.0,
                s.mean_triangles_drawn,
                s.scene_triangles > 0 ? 100.0 * s.mean_triangles_drawn / static_cast<double>(s.scene_triangles) : 0.0,
                static_cast<unsigned long long>(s.stalls), static_cast<unsigned long long>(s.frames_masked),
                static_cast<unsigned long long>(s.hole_frames), static_cast<unsigned long long>(s.coarse_frames),
                s.bytes_received / 1e6);
  }
  for (size_t k = 0; k < results.size(); ++k) {
    const client::WalkthroughSummary& s = results[k];
    if (!s.verified) continue;
    std::printf("%-16s checked against the full scene: %llu of %llu pixels differ (%.4f%%) in %llu frames%s\n",
                modes[k].name.c_str(), static_cast<unsigned long long>(s.pixel_error),
                static_cast<unsigned long long>(s.checked_pixels),
                s.checked_pixels > 0 ? 100.0 * static_cast<double>(s.pixel_error) / static_cast<double>(s.checked_pixels)
                                     : 0.0,
                static_cast<unsigned long long>(s.checked_frames),
                s.pixel_error > 0 ? absl::StrFormat(", the farthest %.1f px from a full-detail silhouette",
                                                    s.max_silhouette_px)
                                        .c_str()
                                  : "");
  }
  if (tau_px > 0.0) {
    const client::WalkthroughSummary& lod = results[0];
    std::printf("levels at tau %g px against full detail (both with masks): %.1f against %.1f fps (x%.2f), %.0f against "
                "%.0f triangles a frame (x%.2f), %.2f against %.2f MB received (x%.2f); %llu coarse frames\n",
                tau_px, lod.fps, with.fps, ratio(lod.fps, with.fps), lod.mean_triangles_drawn, with.mean_triangles_drawn,
                ratio(lod.mean_triangles_drawn, with.mean_triangles_drawn), lod.bytes_received / 1e6,
                with.bytes_received / 1e6,
                ratio(static_cast<double>(lod.bytes_received), static_cast<double>(with.bytes_received)),
                static_cast<unsigned long long>(lod.coarse_frames));
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
  c->add_option("--lod", args->lod,
                 "levels of detail, first modes (pvs+eps+lod): screen errors in pixels (several: one mode each), or "
                 "off (the server makes the scene's levels at start)")
      ->capture_default_str();
  c->add_flag("--verify", args->verify,
               "check every second's frame against the full scene in the object-id buffer (differing pixels' share, "
               "farthest from a silhouette)");
  c->add_flag("--json", args->json, "print one JSON object");
}

}  // namespace vistream::tools
