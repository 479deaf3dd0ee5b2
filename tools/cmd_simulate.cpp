// vistream simulate: the discrete-event simulator (simulation/simulator.h): stalls, arrival margins,
// bytes, masked and hole frames and triangles drawn along a catalog walk, over the scene's
// declared link.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_split.h>
#include <nlohmann/json.hpp>

#include "server/link_model.h"
#include "server/served_scene.h"
#include "simulation/simulator.h"
#include "tools/cli_common.h"
#include "tools/commands.h"

namespace vistream::tools {

namespace {

// The speed search's bracket and precision (`--speed max`).
constexpr double kMinSearchKmh = 1.0, kMaxSearchKmh = 500.0, kSearchPrecision = 0.01;
// Walking speeds accepted: from the search's bottom (slower walks only take longer to
// simulate, hours of wall time at a few metres an hour, and show nothing new) to 1,000 km/h.
constexpr double kMinKmh = kMinSearchKmh, kMaxKmh = 1000.0;

struct SimulateArgs {
  std::string scene, path, speed, speeds, link, bandwidths, scheme, schemes, log, series;
  std::string lod = "off";
  std::string lod_clusters = "off";
  double cell_size = 0.0, compute_ms = -1.0;
  int64_t res = 128, threads = 0, seed = 1;
  bool json = false;
};

double Pct(const std::vector<double>& v, double q) {
  if (v.empty()) return 0.0;
  std::vector<double> s = v;
  std::sort(s.begin(), s.end());
  return s[static_cast<size_t>(std::round(q * static_cast<double>(s.size() - 1)))];
}

nlohmann::json ToJson(const simulation::SimulationResult& r, simulation::Scheme scheme, const std::string& path,
                      bool ideal_asked) {
  nlohmann::json j;
  j["scheme"] = std::string(simulation::SchemeName(scheme));
  j["path"] = path;
  j["speed_kmh"] = r.speed_mps * 3.6;
  j["stalls"] = r.stalls;
  j["stall_s"] = r.stall_s;
  j["stalled_cells"] = r.stalled_cells;
  j["min_margin_s"] = r.min_margin_s;
  j["mean_margin_s"] = r.mean_margin_s;
  j["bytes"] = r.bytes;
  j["uplink_bytes"] = r.uplink_bytes;
  j["geometry_bytes"] = r.geometry_bytes;
  j["objects_received"] = r.objects_received;
  j["distinct_objects"] = r.distinct_objects;
  j["mean_triangles_drawn"] = r.mean_triangles_drawn;
  j["max_triangles_drawn"] = r.max_triangles_drawn;
  // mean_triangles_drawn by the drawn objects' distance from the eye (SimulationResult).
  auto by_distance = nlohmann::json::array();
  for (size_t i = 0; i < r.mean_triangles_by_distance.size(); ++i) {
    const auto& bands = simulation::SimulationResult::kTriangleBandsM;
    by_distance.push_back({{"from_m", bands[i]},
                           {"to_m", i + 1 < bands.size() ? nlohmann::json(bands[i + 1]) : nlohmann::json(nullptr)},
                           {"triangles", r.mean_triangles_by_distance[i]}});
  }
  j["mean_triangles_by_distance"] = by_distance;
  j["scene_triangles"] = r.scene_triangles;
  j["triangles_pct"] =
      r.scene_triangles > 0 ? 100.0 * r.mean_triangles_drawn / static_cast<double>(r.scene_triangles) : 0.0;
  j["compute_ms_per_crossing"] = {{"p50", 1000.0 * Pct(r.compute_s_per_crossing, 0.5)},
                                  {"p99", 1000.0 * Pct(r.compute_s_per_crossing, 0.99)},
                                  {"max", 1000.0 * Pct(r.compute_s_per_crossing, 1.0)}};
  uint64_t entered = 0;
  for (const client::CellEntry& c : r.cells) entered += c.start ? 0 : 1;
  j["cells_entered"] = entered;
  j["crossings"] = r.crossings;
  j["pvs_computed"] = r.pvs_computed;
  j["pvs_cache_hits"] = r.pvs_cache_hits;
  j["masks"] = r.masks;
  j["frames"] = r.frames;
  // ε-masks: how the frames were drawn (masked, from the PVS, holes), what the masks saved, and
  // what they cost.
  j["frames_masked"] = r.frames_masked;
  j["masked_frames_pct"] = r.frames > 0 ? 100.0 * static_cast<double>(r.frames_masked) / static_cast<double>(r.frames) : 0.0;
  j["hole_frames"] = r.hole_frames;
  j["frames_in_unready_mask"] = r.frames_in_unready_mask;
  j["mean_triangles_without_masks"] = r.mean_triangles_without_masks;
  j["triangles_with_over_without_masks"] =
      r.mean_triangles_without_masks > 0.0 ? r.mean_triangles_drawn / r.mean_triangles_without_masks : 1.0;
  j["masks_received"] = r.masks;
  j["masks_used"] = r.masks_used;
  j["mask_bytes"] = r.mask_bytes;
  j["list_bytes"] = r.list_bytes;
  j["messages"] = r.messages;
  j["masks_computed"] = r.masks_computed;
  j["masks_dropped"] = r.masks_dropped;
  j["mask_compute_s"] = r.mask_compute_s;
  j["mask_compute_ms_mean"] = r.masks_computed > 0 ? 1000.0 * r.mask_compute_s / static_cast<double>(r.masks_computed) : 0.0;
  j["frame_ms"] = r.frame_s * 1000.0;
  j["frame_declared"] = r.frame_declared;
  // Levels of detail (issue 45): null tau when off.
  j["lod_tau_px"] = r.lod_tau_px > 0.0 ? nlohmann::json(r.lod_tau_px) : nlohmann::json();
  j["coarse_frames"] = r.coarse_frames;
  j["level_objects_received"] = r.level_objects_received;
  j["cluster_levels_received"] = r.cluster_levels_received;
  j["jitter_draws"] = r.jitter_draws;
  j["lost_segments"] = r.lost_segments;
  if (scheme == simulation::Scheme::kRadius) j["radius_m"] = r.radius_m;
  nlohmann::json link;
  link["bandwidth_bps"] = std::isfinite(r.link.bandwidth_bps) ? nlohmann::json(r.link.bandwidth_bps) : nlohmann::json();
  link["latency_ms"] = r.link.latency_s * 1000.0;
  link["jitter_ms"] = r.link.jitter_s * 1000.0;
  link["loss_pct"] = r.link.loss * 100.0;
  link["described"] = r.link_declared ? r.link.Describe()
                      : ideal_asked   ? "ideal (--link none)"
                                      : "ideal (the scene declares no link)";
  j["link"] = link;
  j["path_m"] = r.path_m;
  j["walk_s"] = r.walk_s;
  j["sim_s"] = r.sim_s;
  j["startup_s"] = r.startup_s;
  return j;
}

void PrintText(const nlohmann::json& j) {
  const bool levels = !j["lod_tau_px"].is_null();
  std::printf("%s%s on '%s' at %.1f km/h over %s\n", j["scheme"].get<std::string>().c_str(),
              levels ? absl::StrFormat(" at tau %g px", j["lod_tau_px"].get<double>()).c_str() : "",
              j["path"].get<std::string>().c_str(), j["speed_kmh"].get<double>(),
              j["link"]["described"].get<std::string>().c_str());
  std::printf("  stalls: %llu frames (%.2f s) in %llu of %llu cells entered; first viewcell after %.1f s\n",
              static_cast<unsigned long long>(j["stalls"].get<uint64_t>()), j["stall_s"].get<double>(),
              static_cast<unsigned long long>(j["stalled_cells"].get<uint64_t>()),
              static_cast<unsigned long long>(j["cells_entered"].get<uint64_t>()), j["startup_s"].get<double>());
  std::printf("  arrival margin: min %.2f s, mean %.2f s\n", j["min_margin_s"].get<double>(),
              j["mean_margin_s"].get<double>());
  std::printf("  bytes: %.2f MB on the wire down (%.2f MB geometry), %.2f MB up\n", j["bytes"].get<double>() / 1e6,
              j["geometry_bytes"].get<double>() / 1e6, j["uplink_bytes"].get<double>() / 1e6);
  std::printf("  triangles drawn per frame: mean %.0f (%.3f%% of %llu), max %llu\n",
              j["mean_triangles_drawn"].get<double>(), j["triangles_pct"].get<double>(),
              static_cast<unsigned long long>(j["scene_triangles"].get<uint64_t>()),
              static_cast<unsigned long long>(j["max_triangles_drawn"].get<uint64_t>()));
  std::printf("  PVS compute per crossing: p50 %.0f ms, p99 %.0f ms, max %.0f ms; %llu computed, %llu from the cache\n",
              j["compute_ms_per_crossing"]["p50"].get<double>(), j["compute_ms_per_crossing"]["p99"].get<double>(),
              j["compute_ms_per_crossing"]["max"].get<double>(),
              static_cast<unsigned long long>(j["pvs_computed"].get<uint64_t>()),
              static_cast<unsigned long long>(j["pvs_cache_hits"].get<uint64_t>()));
  std::printf("  masked frames: %llu of %llu (%.1f%%), hole frames: %llu; triangles drawn per frame: mean %.0f with "
              "masks, %.0f without (%.3f)\n",
              static_cast<unsigned long long>(j["frames_masked"].get<uint64_t>()),
              static_cast<unsigned long long>(j["frames"].get<uint64_t>()), j["masked_frames_pct"].get<double>(),
              static_cast<unsigned long long>(j["hole_frames"].get<uint64_t>()), j["mean_triangles_drawn"].get<double>(),
              j["mean_triangles_without_masks"].get<double>(), j["triangles_with_over_without_masks"].get<double>());
  {
    std::string bands;
    for (const auto& b : j["mean_triangles_by_distance"]) {
      const double from = b["from_m"].get<double>(), tris = b["triangles"].get<double>();
      absl::StrAppendFormat(&bands, "%s%.0f ", bands.empty() ? "" : ", ", tris);
      absl::StrAppend(&bands, b["to_m"].is_null() ? absl::StrFormat("beyond %.0f m", from)
                                                   : absl::StrFormat("at %.0f-%.0f m", from, b["to_m"].get<double>()));
    }
    std::printf("  triangles drawn per frame by the objects' distance: %s\n", bands.c_str());
  }
  if (j["masks_received"].get<uint64_t>() > 0 || j["masks_computed"].get<uint64_t>() > 0) {
    std::printf("  ε-masks: %llu received (%.1f kB), %llu drawn; %llu computed (%.1f ms each, %.1f s in all), %llu dropped\n",
                static_cast<unsigned long long>(j["masks_received"].get<uint64_t>()), j["mask_bytes"].get<double>() / 1e3,
                static_cast<unsigned long long>(j["masks_used"].get<uint64_t>()),
                static_cast<unsigned long long>(j["masks_computed"].get<uint64_t>()), j["mask_compute_ms_mean"].get<double>(),
                j["mask_compute_s"].get<double>(), static_cast<unsigned long long>(j["masks_dropped"].get<uint64_t>()));
  }
  if (levels) {
    std::printf("  levels of detail at tau %g px: %llu objects received at a level, %llu cluster levels, %llu coarse "
                "frames\n",
                j["lod_tau_px"].get<double>(), static_cast<unsigned long long>(j["level_objects_received"].get<uint64_t>()),
                static_cast<unsigned long long>(j["cluster_levels_received"].get<uint64_t>()),
                static_cast<unsigned long long>(j["coarse_frames"].get<uint64_t>()));
  } else {
    std::printf("  levels of detail: off (full detail)\n");
  }
  if (j.contains("radius_m")) std::printf("  radius: %.1f m (the smallest with no hole on this walk)\n", j["radius_m"].get<double>());
  std::printf("  walk: %.0f m in %.0f s of simulated time\n", j["path_m"].get<double>(), j["sim_s"].get<double>());
}

// One walking speed in km/h, or nothing with `why` set.
std::optional<double> ParseSpeed(const std::string& text, std::string* why) {
  double kmh = 0.0;
  if (!cli::internal::ParseFinite(text, &kmh) || !(kmh >= kMinKmh) || kmh > kMaxKmh) {
    *why = absl::StrFormat("'%s' is not a speed: expected km/h from %g to %g", text, kMinKmh, kMaxKmh);
    return std::nullopt;
  }
  return kmh;
}

int Simulate(const SimulateArgs& a) {
  // Options first: their errors need no scene.
  const bool search = a.speed == "max";
  // The runs: every scheme at every speed (--speed, or each of --speeds; 0: the walk's own)
  // over every link (the declared or --link one, or each of --bandwidths at its latency).
  std::vector<double> speeds_kmh;
  std::string why;
  if (!a.speed.empty() && !a.speeds.empty()) return BadOption("simulate", "--speeds", "give --speed or --speeds, not both");
  if (!a.speed.empty() && !search) {
    const std::optional<double> v = ParseSpeed(a.speed, &why);
    if (!v) return BadOption("simulate", "--speed", why + ", or max");
    speeds_kmh.push_back(*v);
  }
  const std::vector<std::string> speed_texts = absl::StrSplit(a.speeds, ',', absl::SkipEmpty());
  if (!a.speeds.empty() && speed_texts.empty()) return BadOption("simulate", "--speeds", "no speed listed");
  if (!a.speeds.empty() && speed_texts.size() != static_cast<size_t>(std::count(a.speeds.begin(), a.speeds.end(), ',')) + 1) {
    return BadOption("simulate", "--speeds", absl::StrCat("'", a.speeds, "' has an empty item"));
  }
  for (const std::string& text : speed_texts) {
    const std::optional<double> v = ParseSpeed(text, &why);
    if (!v) return BadOption("simulate", "--speeds", why);
    if (std::find(speeds_kmh.begin(), speeds_kmh.end(), *v) != speeds_kmh.end()) {
      return BadOption("simulate", "--speeds", absl::StrCat("'", text, "' is listed twice"));
    }
    speeds_kmh.push_back(*v);
  }
  if (speeds_kmh.empty()) speeds_kmh.push_back(0.0);
  std::vector<simulation::Scheme> schemes;
  if (!a.schemes.empty() && !a.scheme.empty()) {
    return BadOption("simulate", "--schemes", "give --scheme or --schemes, not both");
  }
  if (!a.schemes.empty()) {
    const std::vector<std::string> names = absl::StrSplit(a.schemes, ',');
    for (const std::string& s : names) {
      absl::StatusOr<simulation::Scheme> scheme = simulation::ParseScheme(s);
      if (!scheme.ok()) return BadOption("simulate", "--schemes", std::string(scheme.status().message()));
      if (std::find(schemes.begin(), schemes.end(), *scheme) != schemes.end()) {
        return BadOption("simulate", "--schemes", absl::StrCat("'", s, "' is listed twice"));
      }
      schemes.push_back(*scheme);
    }
  } else {
    absl::StatusOr<simulation::Scheme> scheme = simulation::ParseScheme(a.scheme.empty() ? "pvs+eps" : a.scheme);
    if (!scheme.ok()) return BadOption("simulate", "--scheme", std::string(scheme.status().message()));
    schemes.push_back(*scheme);
  }
  // Levels of detail: each of --lod is a run (off, or tau in pixels).
  std::vector<double> taus;
  if (!cli::ParseScreenErrors(a.lod, /*refuse_repeats=*/true, &taus, &why)) {
    return BadOption("simulate", "--lod", why);
  }
  if (scenes::IsGltfPath(a.scene)) {
    return BadOption("simulate", "--scene",
                     absl::StrCat("'", a.scene, "' is a glTF file, which has no walks: simulate needs a catalog entry "
                                  "(a name such as london, or a catalog .json)"));
  }
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry(a.scene);
  if (!entry.ok()) return Fail(entry.status());
  std::optional<scenes::LinkSpec> link = entry->simulation.link;
  if (a.link == "none") {
    link.reset();  // an ideal link, whatever the entry declares
  } else if (!a.link.empty()) {
    absl::StatusOr<scenes::LinkSpec> l = server::ParseLinkOption(a.link, link, "--link");
    if (!l.ok()) {
      std::string m(l.status().message());
      if (m.rfind("--link: ", 0) == 0) m = m.substr(8);
      return BadOption("simulate", "--link", m);
    }
    link = *l;
  }
  // Each of --bandwidths replaces the link's bandwidth (its latency, jitter and loss kept).
  std::vector<std::optional<scenes::LinkSpec>> links;
  const double latency_ms = link.has_value() ? link->latency_ms.value_or(0.0) : 0.0;
  const std::vector<std::string> bandwidth_texts = absl::StrSplit(a.bandwidths, ',', absl::SkipEmpty());
  if (!a.bandwidths.empty() && bandwidth_texts.empty()) return BadOption("simulate", "--bandwidths", "no bandwidth listed");
  if (!a.bandwidths.empty() && bandwidth_texts.size() != static_cast<size_t>(std::count(a.bandwidths.begin(), a.bandwidths.end(), ',')) + 1) {
    return BadOption("simulate", "--bandwidths", absl::StrCat("'", a.bandwidths, "' has an empty item"));
  }
  for (const std::string& text : bandwidth_texts) {
    // The latency is set after parsing: printed, a tiny declared latency would need an exponent.
    absl::StatusOr<scenes::LinkSpec> l = server::ParseLinkOption(absl::StrCat(text, ",0"), link, "--bandwidths");
    if (l.ok()) l->latency_ms = latency_ms;
    if (!l.ok()) {
      // The link parser's reason (not a number, out of range), about this item.
      std::string m(l.status().message());
      const size_t colon = m.find("': ");
      if (colon != std::string::npos) m = m.substr(colon + 3);
      return BadOption("simulate", "--bandwidths", absl::StrCat("'", text, "' is not a bandwidth: ", m));
    }
    for (const auto& earlier : links) {
      if (earlier->bandwidth_mbps == l->bandwidth_mbps) {
        return BadOption("simulate", "--bandwidths", absl::StrCat("'", text, "' is listed twice"));
      }
    }
    links.push_back(*l);
  }
  if (links.empty()) links.push_back(link);
  // Generated scenes have only the walks their entry declares: checked before the scene is
  // built. Imported ones may have walks of their own (Scene::paths): checked once loaded.
  if (absl::StatusOr<const scenes::WalkPath*> walk = simulation::FindWalk(*entry, a.path);
      !walk.ok() && entry->source.kind == scenes::SceneSource::Kind::kGenerator) {
    return Fail(walk.status());
  }
  std::FILE* log_file = nullptr;
  if (!a.log.empty()) {
    log_file = std::fopen(a.log.c_str(), "w");
    if (log_file == nullptr) return Fail(absl::NotFoundError(absl::StrCat("--log ", a.log, ": cannot write it")));
  }
  std::unique_ptr<server::EventLog> log =
      log_file != nullptr ? std::make_unique<server::EventLog>(log_file, true) : nullptr;
  struct Closer {
    std::FILE* f;
    ~Closer() {
      if (f != nullptr) std::fclose(f);
    }
  } closer{log_file};
  std::FILE* series_file = nullptr;
  if (!a.series.empty()) {
    series_file = std::fopen(a.series.c_str(), "w");
    if (series_file == nullptr) return Fail(absl::NotFoundError(absl::StrCat("--series ", a.series, ": cannot write it")));
    std::fprintf(series_file,
                 "# vistream simulate --series: every sampled frame (10 Hz) of each run, one block per run in the "
                 "order of the runs (gnuplot: index K), blocks separated by two blank lines.\n"
                 "# columns: metres along the walk, seconds since the walk started, triangles drawn, triangles the "
                 "PVS-only client would draw, masked (1/0), hole (1/0)\n");
  }
  Closer series_closer{series_file};
  size_t series_blocks = 0;
  auto write_series = [&](const simulation::SimulationResult& r, simulation::Scheme scheme) {
    if (series_file == nullptr) return;
    std::fprintf(series_file, "%s# run %zu: scheme %s, %.6g km/h, %s\n", series_blocks > 0 ? "\n\n" : "", series_blocks,
                 std::string(simulation::SchemeName(scheme)).c_str(), r.speed_mps * 3.6,
                 r.link_declared ? r.link.Describe().c_str() : "ideal link");
    for (const simulation::SimulationResult::TriangleSample& t : r.triangle_samples) {
      std::fprintf(series_file, "%.3f %.3f %llu %llu %d %d\n", t.along_m, t.t_s, static_cast<unsigned long long>(t.triangles),
                   static_cast<unsigned long long>(t.triangles_without_masks), t.masked ? 1 : 0, t.hole ? 1 : 0);
    }
    ++series_blocks;
  };

  const auto start = std::chrono::steady_clock::now();
  server::ServedSceneOptions so;
  so.scene = a.scene;
  so.cell_size = a.cell_size;
  so.res = static_cast<uint32_t>(a.res);
  so.threads = 1;  // the simulator computes on its own thread; simulated workers are --threads
  so.make_levels = std::any_of(taus.begin(), taus.end(), [](double t) { return t > 0.0; });
  so.make_clusters = a.lod_clusters == "on";
  absl::StatusOr<std::unique_ptr<server::ServedScene>> scene = server::ServedScene::Create(so, ToolRun());
  if (!scene.ok()) return Fail(scene.status());
  std::fprintf(stderr, "simulate: %s ready after %.1f s (%s, %zu objects)\n", entry->name.c_str(), SecondsSince(start),
               (*scene)->pvs_source().c_str(), (*scene)->scene().objects.size());
  const size_t declared_walks = entry->walks.size();
  entry->walks = declared_walks > 0 ? scenes::WalksWithScenePaths(entry->walks, (*scene)->scene(), entry->walks.front().speed_mps,
                                                                  entry->walks.front().eye_height_m)
                                    : scenes::WalksWithScenePaths(entry->walks, (*scene)->scene());
  absl::StatusOr<const scenes::WalkPath*> walk = simulation::FindWalk(*entry, a.path);
  if (!walk.ok()) return Fail(walk.status());

  simulation::SimulationOptions opt;
  opt.path = (*walk)->name;
  opt.seed = static_cast<uint64_t>(a.seed);
  opt.workers = static_cast<unsigned>(a.threads);
  if (a.compute_ms >= 0.0) opt.fixed_compute_s = a.compute_ms / 1000.0;
  opt.log = log.get();
  opt.memo = std::make_shared<simulation::PvsMemo>();

  nlohmann::json runs = nlohmann::json::array();
  struct Point {
    simulation::Scheme scheme;
    double speed_kmh;
    std::optional<scenes::LinkSpec> link;
    double tau_px;
  };
  std::vector<Point> points;
  for (const auto& l : links) {
    for (double v : speeds_kmh) {
      for (double tau : taus) {
        for (simulation::Scheme scheme : schemes) points.push_back({scheme, v, l, tau});
      }
    }
  }
  for (const Point& point : points) {
    const simulation::Scheme scheme = point.scheme;
    opt.scheme = scheme;
    opt.lod_tau_px = point.tau_px;
    opt.lod_clusters = a.lod_clusters == "on";
    opt.speed_mps = point.speed_kmh / 3.6;
    opt.link = point.link;
    const auto t0 = std::chrono::steady_clock::now();
    nlohmann::json j;
    if (search) {
      opt.speed_mps = 0.0;  // the search starts from the walk's own speed
      absl::StatusOr<simulation::SpeedSearch> s = simulation::FindMaxSpeed(**scene, *entry, opt, kMinSearchKmh / 3.6,
                                                                   kMaxSearchKmh / 3.6, kSearchPrecision, ToolRun());
      if (!s.ok()) return Fail(s.status());
      j = ToJson(s->at_max, scheme, opt.path, a.link == "none");
      write_series(s->at_max, scheme);
      auto kmh_or_null = [](double mps) { return mps > 0.0 ? nlohmann::json(mps * 3.6) : nlohmann::json(); };
      // Null when even the search's bottom stalls (then the run shown is the one there).
      j["max_speed_kmh"] = kmh_or_null(s->max_speed_mps);
      j["stall_speed_kmh"] = kmh_or_null(s->stall_speed_mps);
      nlohmann::json probes = nlohmann::json::array();
      for (const auto& [mps, stalls] : s->runs) probes.push_back({{"speed_kmh", mps * 3.6}, {"stalls", stalls}});
      j["search"] = {{"bracket_kmh", {kMinSearchKmh, kMaxSearchKmh}}, {"precision", kSearchPrecision}, {"runs", probes}};
      // The highest speed without a hole frame: with ε-masks a search of its own, from the
      // highest without a stall up (a hole frame is a stall); without masks every stall is a
      // hole, so the same speed.
      j["max_speed_no_hole_kmh"] = j["max_speed_kmh"];
      j["hole_speed_kmh"] = j["stall_speed_kmh"];
      if (scheme == simulation::Scheme::kPvsEps && s->stall_speed_mps > 0.0) {
        const double lo = std::max(kMinSearchKmh / 3.6, s->max_speed_mps);
        absl::StatusOr<simulation::SpeedSearch> h = simulation::FindMaxSpeed(
            **scene, *entry, opt, lo, kMaxSearchKmh / 3.6, kSearchPrecision, ToolRun(), simulation::SpeedCriterion::kNoHole);
        if (!h.ok()) return Fail(h.status());
        j["max_speed_no_hole_kmh"] = kmh_or_null(h->max_speed_mps);
        j["hole_speed_kmh"] = kmh_or_null(h->stall_speed_mps);
        nlohmann::json hole_probes = nlohmann::json::array();
        for (const auto& [mps, holes] : h->runs) hole_probes.push_back({{"speed_kmh", mps * 3.6}, {"hole_frames", holes}});
        j["search"]["hole_runs"] = hole_probes;
      }
    } else {
      absl::StatusOr<simulation::SimulationResult> r = simulation::Simulate(**scene, *entry, opt, ToolRun());
      if (!r.ok()) return Fail(r.status());
      j = ToJson(*r, scheme, opt.path, a.link == "none");
      write_series(*r, scheme);
    }
    j["scene"] = entry->name;
    j["cell_size_m"] = (*scene)->grid().cell_size();
    j["res"] = a.res;
    j["seed"] = a.seed;
    j["compute"] = opt.fixed_compute_s.has_value() ? absl::StrFormat("fixed %g ms", a.compute_ms) : "measured";
    j["wall_s"] = SecondsSince(t0);
    std::fprintf(stderr, "simulate: %s at %.1f km/h: %llu stalls, %llu hole frames, %.1f%% masked, %.2f MB, %.1f s\n",
                 std::string(simulation::SchemeName(scheme)).c_str(), j["speed_kmh"].get<double>(),
                 static_cast<unsigned long long>(j["stalls"].get<uint64_t>()),
                 static_cast<unsigned long long>(j["hole_frames"].get<uint64_t>()), j["masked_frames_pct"].get<double>(),
                 j["bytes"].get<double>() / 1e6, j["wall_s"].get<double>());
    runs.push_back(j);
  }
  // The log is written as the runs go: its errors (a full disk) show when it is closed.
  if (log_file != nullptr) {
    log.reset();
    const bool failed = std::ferror(log_file) != 0;
    const int closed = std::fclose(log_file);
    closer.f = nullptr;
    if (failed || closed != 0) return Fail(absl::DataLossError(absl::StrCat("--log ", a.log, ": writing the log failed")));
  }
  if (series_file != nullptr) {
    const bool failed = std::ferror(series_file) != 0;
    const int closed = std::fclose(series_file);
    series_closer.f = nullptr;
    if (failed || closed != 0) {
      return Fail(absl::DataLossError(absl::StrCat("--series ", a.series, ": writing the series failed")));
    }
  }
  auto print_run = [&](const nlohmann::json& j) {
    PrintText(j);
    if (search && j["max_speed_kmh"].is_null()) {
      std::printf("  stalls even at %g km/h, the search's bottom (%zu run(s)): no speed without a stall\n",
                  kMinSearchKmh, j["search"]["runs"].size());
    } else if (search && j["stall_speed_kmh"].is_null()) {
      std::printf("  no stall up to %g km/h, the search's top (%zu run(s))\n", kMaxSearchKmh, j["search"]["runs"].size());
    } else if (search) {
      std::printf("  highest speed with zero stalls: %.1f km/h (bisection in [%g, %g] km/h to %g%%, %zu run(s))\n",
                  j["max_speed_kmh"].get<double>(), kMinSearchKmh, kMaxSearchKmh, 100.0 * kSearchPrecision,
                  j["search"]["runs"].size());
    }
    if (search && j["search"].contains("hole_runs")) {
      if (j["max_speed_no_hole_kmh"].is_null()) {
        std::printf("  hole frames even at %g km/h: no speed without a hole frame\n", kMinSearchKmh);
      } else if (j["hole_speed_kmh"].is_null()) {
        std::printf("  no hole frame up to %g km/h, the search's top (%zu run(s))\n", kMaxSearchKmh,
                    j["search"]["hole_runs"].size());
      } else {
        std::printf("  highest speed with zero hole frames: %.1f km/h (%zu run(s))\n",
                    j["max_speed_no_hole_kmh"].get<double>(), j["search"]["hole_runs"].size());
      }
    }
  };
  if (runs.size() == 1) {
    if (a.json) {
      std::printf("%s\n", runs[0].dump(2).c_str());
    } else {
      print_run(runs[0]);
    }
    return 0;
  }
  nlohmann::json out;
  out["runs"] = runs;
  // Bytes of each scheme against the server's (pvs+eps) or the first listed, at the same speed
  // and link (the runs go scheme by scheme within each speed and link).
  for (size_t group = 0; group < runs.size(); group += schemes.size()) {
    size_t ref = group;
    for (size_t k = group; k < group + schemes.size(); ++k) {
      if (runs[k]["scheme"] == "pvs+eps") ref = k;
    }
    const double ref_bytes = runs[ref]["bytes"].get<double>();
    for (size_t k = group; k < group + schemes.size(); ++k) {
      out["runs"][k]["bytes_over_" + runs[ref]["scheme"].get<std::string>()] =
          ref_bytes > 0 ? runs[k]["bytes"].get<double>() / ref_bytes : 0.0;
    }
  }
  if (a.json) {
    std::printf("%s\n", out.dump(2).c_str());
  } else {
    for (const nlohmann::json& j : out["runs"]) print_run(j);
  }
  return 0;
}

}  // namespace

void AddSimulateCommand(CLI::App& app, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<SimulateArgs>(&app, "simulate",
                                               "discrete-event simulation of a catalog walk: "
                                               "stalls, arrival margins, bytes, triangles drawn",
                                               Simulate, done);
  c->add_option("--scene", args->scene, "catalog name or .json entry")->required();
  // The text options: given empty, each is an error rather than the default.
  const CLI::Validator given = NonEmpty("empty: leave the option out for the default");
  c->add_option("--path", args->path, "the entry's walk (default: its first)")->check(given);
  c->add_option("--speed", args->speed,
                "walking speed in km/h, 1 to 1000 (default: the walk's), or max: the highest with zero stalls, and for "
                "pvs+eps also the highest with zero hole frames (bisection in [1, 500] km/h to 1%)")
      ->check(given);
  c->add_option("--speeds", args->speeds,
                "several speeds in km/h, comma-separated: one run each (per scheme, per bandwidth), in one process "
                "whose PVSs serve them all")
      ->check(given);
  c->add_option("--link", args->link,
                "BPS,LATENCY_MS over the declared link's bandwidth and latency (its jitter and loss kept); default: the "
                "declared link, none: ideal")
      ->check(given);
  c->add_option("--bandwidths", args->bandwidths,
                "several link bandwidths in bits per second (k/M/G suffixes), comma-separated: one run each at the "
                "link's latency, jitter and loss")
      ->check(given);
  c->add_option("--scheme", args->scheme,
                "pvs+eps (the server's; the default) | pvs (no ε-masks) | radius | plain (the paper's)")
      ->check(given);
  c->add_option("--lod", args->lod,
                "levels of detail: the screen error tau in pixels (1280x720, 60 degrees vertical), or off; several, "
                "comma-separated, one run each (default: off; levels are made at start when the scene has none)")
      ->capture_default_str()
      ->check(given);
  c->add_option("--lod-clusters", args->lod_clusters,
                "with --lod: on, the client draws cluster levels (one mesh for a group of far objects) where a "
                "cell's list chooses them; off (the default), objects' own levels only")
      ->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  c->add_option("--schemes", args->schemes, "several schemes, comma-separated, side by side (instead of --scheme)")
      ->check(given);
  c->add_option("--cell-size", args->cell_size, "viewcell edge in metres (default: the catalog's)")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--res", args->res, "the dual ray space's finest raster")->capture_default_str()->check(PowerOfTwo(1, 256));
  c->add_option("--threads", args->threads, "simulated PVS workers (default: this machine's cores)")
      ->check(WholeRange(0, 1024));
  c->add_option("--seed", args->seed, "the link models' draws")->capture_default_str()->check(WholeRange(0, kMaxSeed));
  c->add_option("--compute-ms", args->compute_ms,
                "charge this many ms per PVS and ε-mask instead of the measured time (machine-independent runs)")
      ->check(FiniteRange(0.0, 1e7));
  c->add_option("--log", args->log,
                "write the simulator's events (deliveries with jitter, computations, cells) as JSON lines")
      ->check(given);
  c->add_option("--series", args->series,
                "write every sampled frame (10 Hz) of each run: metres along the walk, seconds, triangles drawn, "
                "triangles without masks, masked, hole; one whitespace-separated block per run (gnuplot's index)")
      ->check(given);
  c->add_flag("--json", args->json, "print one JSON object");
}

}  // namespace vistream::tools
