// vistream bench web: the browser client (web/) and the native headless client along the same
// catalog walk, each through a fresh vistream-server on loopback (the executable beside this
// one, with its web listener), side by side in one run (issue 47):
//   - the page in Debian's chromium, headless, WebGL 2 through SwiftShader, driven by
//     puppeteer-core (web/headless.mjs): frames, fps, stalls, hole and masked frames, bytes
//     received, from opening the URL to the first drawn frame;
//   - the native headless client (OSMesa) on the same walk with the same Hello (ε-masks on, full
//     detail: the page draws no levels of detail yet, the same memory budget): the same figures;
//   - at --poses poses spread over the page's walk, the objects the page's id pass shows against
//     the objects the full scene shows from the same pinhole (the native id buffer,
//     gl/id_renderer.h; a conservative client draws exactly those: its pixel error is 0); objects
//     under 4 pixels in either are set aside and counted; of the objects that differ, those
//     without an interior pixel (a pixel whose eight neighbours show it too: a sliver under three
//     pixels thick, which the two rasterizers' sub-pixel snapping can show or hide) are counted
//     apart, the poses equal but for them too.
// The page's bytes against the native client's is the measure of "the same protocol".

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <csignal>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>
#include <nlohmann/json.hpp>

#include "client/walkthrough.h"
#include "gl/id_renderer.h"
#include "scenes/catalog.h"
#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/replica_set.h"
#include "tools/subprocess.h"

namespace vistream::tools {

namespace {

struct BenchWebArgs {
  std::string scene = "default";
  std::string path;
  double speed_kmh = 30.0;
  double seconds = 60.0;
  std::string size = "1280x720";
  int poses = 10;
  bool masks = true;     // false: both draw the viewcell PVS whole (a baseline)
  double max_fps = 0.0;  // both clients; 0: the page every animation frame (60 Hz), the native as fast as it draws
  std::string screenshot;
  bool json = false;
};

// "vistream: error: bench web: MESSAGE", exit 1 (tools::Fail).
int Fail(const std::string& message) { return tools::Fail(absl::UnknownError("bench web: " + message)); }

// A ^C (CancelFlag) while `what` ran: "vistream: interrupted (...)", exit 130; nothing compared.
int Interrupted(const std::string& what) {
  return tools::Fail(absl::CancelledError("bench web stopped during " + what + "; nothing compared"));
}

std::string UrlEncode(const std::string& s) {
  std::string out;
  for (unsigned char c : s) {
    if (std::isalnum(c) || c == '-' || c == '_' || c == '.' || c == '~') {
      out += static_cast<char>(c);
    } else {
      out += absl::StrFormat("%%%02X", c);
    }
  }
  return out;
}

int BenchWeb(const BenchWebArgs& a) {
  int width = 0, height = 0;
  if (std::sscanf(a.size.c_str(), "%dx%d", &width, &height) != 2 || width < 16 || height < 16 || width > 4096 ||
      height > 4096) {
    return BadOption("bench web", "--size", "expected WIDTHxHEIGHT, e.g. 1280x720");
  }
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe");
  const std::string server_bin = (self.parent_path() / "vistream-server").string();
  if (!std::filesystem::exists(server_bin)) return Fail("no vistream-server beside " + self.string());
  const std::string headless = VISTREAM_SOURCE_DIR "/web/headless.mjs";
  if (!std::filesystem::exists(VISTREAM_SOURCE_DIR "/web/node_modules/puppeteer-core/package.json")) {
    return Fail("puppeteer-core is not installed in " VISTREAM_SOURCE_DIR "/web/node_modules: run ./vistream.sh test "
                "(it installs the page's npm packages)");
  }
  absl::StatusOr<scenes::LoadedScene> loaded = scenes::LoadScene(a.scene, {});
  if (!loaded.ok()) return Fail(std::string(loaded.status().message()));
  std::string path = a.path;
  if (path.empty()) {
    if (loaded->walks.empty()) return Fail(absl::StrFormat("scene '%s' has no walk", a.scene));
    path = loaded->walks.front().name;
  }
  if (std::none_of(loaded->walks.begin(), loaded->walks.end(), [&](const scenes::WalkPath& w) { return w.name == path; })) {
    std::vector<std::string> names;
    for (const scenes::WalkPath& w : loaded->walks) names.push_back(w.name);
    return Fail(absl::StrFormat("--path '%s': scene '%s' has no such walk (known: %s)", path, a.scene,
                                absl::StrJoin(names, ", ")));
  }
  // The client's memory budget as the catalog gives the native client, for both.
  double memory_mb = 0.0;
  if (loaded->entry.has_value() && loaded->entry->simulation.client.has_value() &&
      loaded->entry->simulation.client->memory_mb.has_value()) {
    memory_mb = *loaded->entry->simulation.client->memory_mb;
  }

  // A server with its web listener on free loopback ports, one for each client: each walks a
  // cold server (a warm one would have the PVSs and masks the other made).
  const auto start_server = [&](std::string* web_base, std::string* error) -> std::unique_ptr<RunningServer> {
    std::unique_ptr<RunningServer> s = RunningServer::Start(
        server_bin, {"--scene", a.scene, "--listen", "127.0.0.1:0", "--web-listen", "127.0.0.1:0"}, error, "/dev/null");
    if (s == nullptr) return nullptr;
    const std::string& ready = s->ready_line();
    const size_t at = ready.find("web page on ");
    if (at == std::string::npos) {
      *error = "no web address in: " + ready;
      return nullptr;
    }
    *web_base = ready.substr(at + 12);
    while (!web_base->empty() && std::isspace(static_cast<unsigned char>(web_base->back()))) web_base->pop_back();
    return s;
  };
  std::string error, base;
  std::unique_ptr<RunningServer> server = start_server(&base, &error);
  if (server == nullptr) return Fail("vistream-server did not start: " + error);

  // The page first, then the native client.
  const std::string url =
      absl::StrFormat("%s?scene=%s&walk=%s&speed=%g&seconds=%g&memory_mb=%g&max_fps=%g%s", base, UrlEncode(a.scene),
                      UrlEncode(path), a.speed_kmh, a.seconds, memory_mb, a.max_fps, a.masks ? "" : "&masks=off");
  std::fprintf(stderr, "bench web: the page (chromium, SwiftShader) along '%s' ...\n", path.c_str());
  std::vector<std::string> argv = {"node",   headless, "--url", url, "--seconds", absl::StrFormat("%g", a.seconds + 60),
                                   "--until-walk-done", "--size", a.size, "--id-passes", std::to_string(a.poses),
                                   "--id-span", absl::StrFormat("%g", a.seconds)};
  if (!a.screenshot.empty()) argv.insert(argv.end(), {"--screenshot", a.screenshot});
  absl::StatusOr<ProcessResult> page = RunProcess(argv, &CancelFlag());
  if (!page.ok()) return Fail(std::string(page.status().message()));
  if (CancelFlag().load()) return Interrupted("the page's walk");
  nlohmann::json p;
  for (size_t k = 0; k < page->out.size();) {
    const size_t end = std::min(page->out.find('\n', k), page->out.size());
    if (page->out[k] == '{') p = nlohmann::json::parse(page->out.substr(k, end - k), nullptr, false);
    k = end + 1;
  }
  if (page->exit_code != 0 || !p.is_object()) {
    return Fail(absl::StrFormat("the page failed (exit %d): %s%s", page->exit_code, LastLines(page->err, 5),
                                LastLines(page->out, 2)));
  }
  const nlohmann::json& ps = p["summary"];

  server->Stop(SIGTERM);
  server = start_server(&base, &error);
  if (CancelFlag().load()) return Interrupted("the second server's start");
  if (server == nullptr) return Fail("vistream-server did not start again: " + error);
  std::fprintf(stderr, "bench web: the native headless client along '%s' ...\n", path.c_str());
  client::WalkthroughOptions o;
  o.server = server->address();
  o.headless = true;
  o.path = path;
  o.speed_kmh = a.speed_kmh;
  o.seconds = a.seconds;
  o.width = width;
  o.height = height;
  o.max_fps = a.max_fps;
  o.use_masks = a.masks;
  o.lod_tau_px = 0.0;  // full detail, as the page
  o.memory_budget_bytes = static_cast<uint64_t>(memory_mb * 1048576.0);
  o.local_scene = &loaded->scene;
  o.log = [](const std::string& line) { std::fprintf(stderr, "  native: %s\n", line.c_str()); };
  o.cancel = &CancelFlag();  // a ^C ends the walk after its frame
  absl::StatusOr<client::WalkthroughSummary> native = client::RunWalkthrough(o);
  if (CancelFlag().load()) return Interrupted("the native client's walk");
  if (!native.ok()) return Fail("the native client: " + std::string(native.status().message()));
  server->Stop(SIGTERM);

  // The page's id passes against the full scene from the same pinholes.
  absl::StatusOr<std::unique_ptr<gl::IdRenderer>> ids = gl::IdRenderer::Create(loaded->scene, 64);
  if (!ids.ok()) return Fail(std::string(ids.status().message()));
  nlohmann::ordered_json poses = nlohmann::ordered_json::array();
  uint64_t equal_poses = 0, equal_poses_but_slivers = 0, set_aside = 0, differing = 0, sliver_count = 0;
  for (const nlohmann::json& pass : p["id_passes"]) {
    if (CancelFlag().load()) return Interrupted("the id passes");
    const glm::dvec3 eye(pass["eye"][0].get<double>(), pass["eye"][1].get<double>(), pass["eye"][2].get<double>());
    const double yaw = pass["yaw"].get<double>(), pitch = pass["pitch"].get<double>();
    const glm::dvec3 forward(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw), std::sin(pitch));
    const int w = pass["width"].get<int>(), h = pass["height"].get<int>();
    absl::StatusOr<std::vector<uint32_t>> view =
        (*ids)->RenderView(eye, forward, glm::dvec3(0, 0, 1), 60.0 * M_PI / 180.0, w, h, nullptr);
    if (!view.ok()) return Fail(std::string(view.status().message()));
    // Per object its pixels and its interior pixels (all eight neighbours show it too), as the
    // page counts them (web/src/main.js, idPass).
    std::map<uint32_t, uint64_t> full, full_interior, shown, shown_interior;
    const auto object_at = [&](int x, int y) {
      const uint32_t v = (*view)[static_cast<size_t>(y) * w + x];
      return v == gl::kNothing || (v & gl::kBackFace) != 0 ? 0u : v;
    };
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const uint32_t v = object_at(x, y);
        if (v == 0) continue;
        ++full[v - 1];
        bool inside = x > 0 && y > 0 && x < w - 1 && y < h - 1;
        for (int dy = -1; dy <= 1 && inside; ++dy) {
          for (int dx = -1; dx <= 1 && inside; ++dx) inside = object_at(x + dx, y + dy) == v;
        }
        if (inside) ++full_interior[v - 1];
      }
    }
    for (const auto& [id, n] : pass["objects"].items()) shown[static_cast<uint32_t>(std::stoul(id))] = n.get<uint64_t>();
    if (pass.contains("interior")) {
      for (const auto& [id, n] : pass["interior"].items()) {
        shown_interior[static_cast<uint32_t>(std::stoul(id))] = n.get<uint64_t>();
      }
    }
    // The target's rule: an object in one set only differs unless it is under 4 px. Apart from
    // it, the slivers: objects in one set only without an interior pixel (under three pixels
    // thick), which a sub-pixel difference between the two rasterizers can show or hide.
    std::vector<uint32_t> only_page, only_full, slivers;
    nlohmann::ordered_json pixels = nlohmann::ordered_json::object();  // of the objects that differ: page, full
    uint64_t aside = 0;
    std::set<uint32_t> all;
    for (const auto& [id, n] : full) all.insert(id);
    for (const auto& [id, n] : shown) all.insert(id);
    for (uint32_t id : all) {
      const uint64_t f = full.count(id) ? full[id] : 0, s = shown.count(id) ? shown[id] : 0;
      if ((f > 0) == (s > 0)) continue;
      if (std::max(f, s) < 4) {
        ++aside;
        continue;
      }
      if (f > 0) only_full.push_back(id);
      if (s > 0) only_page.push_back(id);
      pixels[std::to_string(id)] = {s, f};
      const uint64_t interior = f > 0 ? (full_interior.count(id) ? full_interior[id] : 0)
                                      : (shown_interior.count(id) ? shown_interior[id] : 0);
      if (interior == 0) slivers.push_back(id);
    }
    const bool equal = only_page.empty() && only_full.empty();
    const bool equal_but_slivers = only_page.size() + only_full.size() == slivers.size();
    equal_poses += equal;
    equal_poses_but_slivers += equal_but_slivers;
    set_aside += aside;
    differing += only_page.size() + only_full.size();
    sliver_count += slivers.size();
    poses.push_back({{"eye", pass["eye"]}, {"yaw", yaw}, {"pitch", pitch}, {"objects_page", shown.size()},
                     {"objects_full_scene", full.size()}, {"only_on_the_page", only_page},
                     {"only_in_the_full_scene", only_full}, {"pixels_page_full", pixels}, {"under_4_px_set_aside", aside},
                     {"slivers", slivers}, {"equal", equal}, {"equal_but_slivers", equal_but_slivers}});
  }

  const double page_frames = ps["frames"].get<double>();
  const double page_walk = std::max(1e-9, ps["walk_s"].get<double>());
  const double page_bytes = ps["bytes_received"].get<double>();
  nlohmann::ordered_json out;
  out["scene"] = a.scene;
  out["path"] = path;
  out["speed_kmh"] = a.speed_kmh;
  out["seconds"] = a.seconds;
  out["size"] = a.size;
  out["memory_mb"] = memory_mb;
  out["max_fps"] = a.max_fps;
  out["masks"] = a.masks;
  out["page"] = {{"renderer", p["renderer"]},
                 {"reversed_depth", ps.value("reversed_depth", false)},
                 {"frames", ps["frames"]},
                 {"fps", page_frames / page_walk},
                 {"walk_s", ps["walk_s"]},
                 {"stalls", ps["stalls"]},
                 {"hole_frames", ps["hole_frames"]},
                 {"masked_frames", ps["masked_frames"]},
                 {"masked_share", page_frames > 0 ? ps["masked_frames"].get<double>() / page_frames : 0.0},
                 {"bytes_received", ps["bytes_received"]},
                 {"objects_received", ps["objects_received"]},
                 {"objects_received_twice", ps["objects_received_twice"]},
                 {"masks_received", ps["masks_received"]},
                 {"startup_s", ps["startup_s"]},
                 {"first_frame_ms", ps["first_frame_ms"]}};
  out["native"] = {{"frames", native->frames},
                   {"fps", native->fps},
                   {"walk_s", native->walk_s},
                   {"stalls", native->stalls},
                   {"hole_frames", native->hole_frames},
                   {"masked_frames", native->frames_masked},
                   {"masked_share", native->frames > 0 ? double(native->frames_masked) / double(native->frames) : 0.0},
                   {"bytes_received", native->bytes_received},
                   {"objects_received", native->objects_received},
                   {"masks_received", native->masks_received},
                   {"startup_s", native->startup_s}};
  const double bytes_ratio = native->bytes_received > 0 ? page_bytes / double(native->bytes_received) : 0.0;
  out["page_against_native"] = {{"fps_ratio", native->fps > 0 ? page_frames / page_walk / native->fps : 0.0},
                                {"bytes_ratio", bytes_ratio},
                                {"bytes_within_1_percent", std::abs(bytes_ratio - 1.0) <= 0.01}};
  out["id_passes"] = {{"poses", poses.size()},
                      {"equal_poses", equal_poses},
                      {"differing_objects", differing},
                      {"under_4_px_set_aside", set_aside},
                      {"equal_poses_but_slivers", equal_poses_but_slivers},
                      {"differing_slivers", sliver_count},
                      {"each", poses}};
  if (a.json) {
    std::printf("%s\n", out.dump(2).c_str());
    return 0;
  }
  std::printf("bench web: %s along '%s' at %g km/h for %g s, %s; page: %s\n", a.scene.c_str(), path.c_str(),
              a.speed_kmh, a.seconds, a.size.c_str(), p["renderer"].get<std::string>().c_str());
  std::printf("%-8s %8s %7s %7s %7s %8s %12s %10s\n", "client", "frames", "fps", "stalls", "holes", "masked", "MB received",
              "startup s");
  std::printf("%-8s %8.0f %7.1f %7d %7d %7.1f%% %12.3f %10.2f\n", "page", page_frames, page_frames / page_walk,
              ps["stalls"].get<int>(), ps["hole_frames"].get<int>(),
              page_frames > 0 ? 100.0 * ps["masked_frames"].get<double>() / page_frames : 0.0, page_bytes / 1e6,
              ps["startup_s"].is_number() ? ps["startup_s"].get<double>() : 0.0);
  std::printf("%-8s %8llu %7.1f %7llu %7llu %7.1f%% %12.3f %10.2f\n", "native", (unsigned long long)native->frames,
              native->fps, (unsigned long long)native->stalls, (unsigned long long)native->hole_frames,
              native->frames > 0 ? 100.0 * double(native->frames_masked) / double(native->frames) : 0.0,
              native->bytes_received / 1e6, native->startup_s);
  std::printf("page bytes / native bytes: %.4f (%s 1%%); first frame drawn %.0f ms after opening the URL\n",
              bytes_ratio, std::abs(bytes_ratio - 1.0) <= 0.01 ? "within" : "NOT within",
              ps["first_frame_ms"].is_number() ? ps["first_frame_ms"].get<double>() : -1.0);
  std::printf("id passes: %llu of %zu poses show the objects the full scene shows (%llu objects differ; %llu under 4 px "
              "set aside); %llu of %zu but for slivers under 3 px thick (%llu of the differing objects)\n",
              (unsigned long long)equal_poses, poses.size(), (unsigned long long)differing,
              (unsigned long long)set_aside, (unsigned long long)equal_poses_but_slivers, poses.size(),
              (unsigned long long)sliver_count);
  return 0;
}

}  // namespace

void AddBenchWebCommand(CLI::App* bench, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<BenchWebArgs>(
      bench, "web", "the browser client (headless chromium) beside the native headless client on one walk", BenchWeb,
      done);
  c->add_option("--scene", args->scene, "catalog name")->capture_default_str();
  c->add_option("--path", args->path, "walk of the catalog entry (default: its first)")->check(NonEmpty("an empty walk name"));
  c->add_option("--speed", args->speed_kmh, "walking speed, km/h")->check(FiniteRange(0.1, 1000.0))->capture_default_str();
  c->add_option("--seconds", args->seconds, "seconds of the walk")->check(FiniteRange(1.0, 3600.0))->capture_default_str();
  c->add_option("--size", args->size, "frame size, WIDTHxHEIGHT")->capture_default_str();
  c->add_option("--poses", args->poses, "id passes spread over the page's walk")->check(WholeRange(0, 100))
      ->capture_default_str();
  c->add_option("--max-fps", args->max_fps,
                "frame rate cap of both clients (0: the page at every animation frame, the native as fast as it draws)")
      ->check(FiniteRange(0.0, 1000.0))->capture_default_str();
  c->add_flag("!--no-masks", args->masks, "both clients ask for no ε-masks and draw the viewcell PVS whole");
  c->add_option("--screenshot", args->screenshot, "a PNG of the page at the walk's end");
  c->add_flag("--json", args->json, "print one JSON object");
}

}  // namespace vistream::tools
