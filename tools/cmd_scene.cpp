// vistream scene generate | import-osm | import-city | occluders | extrude | levels | info | map
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <map>
#include <optional>

#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <glm/glm.hpp>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/top_view_map.h"
#include "scenes/catalog.h"
#include "scenes/city_generator.h"
#include "scenes/city_import.h"
#include "scenes/footprint_extrusion.h"
#include "scenes/gltf_io.h"
#include "scenes/levels.h"
#include "scenes/osm_import.h"
#include "scenes/progress.h"
#include "visibility/kdtree.h"

namespace vistream::tools {

namespace {

struct GenerateArgs {
  std::string name, output;
  std::optional<uint64_t> seed;
};

int Generate(const GenerateArgs& a) {
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<scenes::Scene> scene;
  absl::StatusOr<scenes::CatalogEntry> entry = scenes::FindCatalogEntry(a.name);
  if (entry.ok()) {
    if (a.seed) entry->source.seed = *a.seed;
    if (entry->source.kind != scenes::SceneSource::Kind::kGenerator) {
      return Fail(absl::InvalidArgumentError(
          entry->file + ": this scene is loaded from a file, not generated; use 'vistream scene info'"));
    }
    scene = scenes::BuildScene(*entry, ToolRun());
  } else if (entry.status().code() == absl::StatusCode::kNotFound) {
    // Not in the catalog: a bare generator name.
    scenes::GeneratorParams params;
    params.seed = a.seed.value_or(1);
    scene = scenes::GenerateNamed(a.name, params, ToolRun());
    if (!scene.ok()) {
      return Fail(absl::Status(scene.status().code(),
                               std::string(scene.status().message()) + "; catalog: " +
                                   std::string(entry.status().message())));
    }
  } else {
    return Fail(entry.status());
  }
  if (!scene.ok()) return Fail(scene.status());
  // The entry's walks go into the file (Scene::paths; glTF extras), so that a server loading the
  // file sends them (SceneInfo.paths) and tools that read it find them by name.
  if (entry.ok()) scenes::AddDeclaredWalks(entry->walks, &*scene);
  const double generate_s = SecondsSince(start);
  const auto save_start = std::chrono::steady_clock::now();
  if (absl::Status s = scenes::SaveGltf(*scene, a.output); !s.ok()) return Fail(s);
  std::printf("generated %s: %zu objects, %zu triangles, %zu occluders in %.2f s; saved %s in %.2f s\n",
              scene->name.c_str(), scene->objects.size(), scene->TriangleCount(),
              scene->occluders.size(), generate_s, a.output.c_str(), SecondsSince(save_start));
  return 0;
}

// The process's peak resident memory so far, MiB (getrusage).
double PeakRssMib() {
  struct rusage usage {};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

nlohmann::json CountsJson(const std::map<std::string, uint64_t>& counts) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [k, n] : counts) j[k] = n;
  return j;
}

nlohmann::json WalksJson(const std::vector<std::pair<std::string, double>>& walks) {
  nlohmann::json j = nlohmann::json::array();
  for (const auto& [name, length] : walks) j.push_back({{"name", name}, {"length_m", length}});
  return j;
}

void PrintCounts(const char* title, uint64_t total, const std::map<std::string, uint64_t>& counts) {
  std::printf("%s: %llu\n", title, static_cast<unsigned long long>(total));
  for (const auto& [reason, n] : counts) std::printf("  %-48s %llu\n", reason.c_str(), static_cast<unsigned long long>(n));
}

// Removes an output a cancelled command did not finish.
int CancelledWhileSaving(const std::string& output, const char* what) {
  std::error_code ec;
  std::filesystem::remove(output, ec);
  return Fail(absl::CancelledError(absl::StrCat(what, " cancelled (while saving)")));
}

// Saves `scene` to `output`. A ^C that came while saving removes the file (what was asked for
// was not finished, so nothing is left behind): "<what> cancelled (while saving)". The exit
// code when the save failed or was cancelled, nullopt when `output` is written.
std::optional<int> SaveSceneOutput(const scenes::Scene& scene, const std::string& output, const char* what) {
  if (absl::Status s = scenes::SaveGltf(scene, output); !s.ok()) return Fail(s);
  if (ToolRun().Cancelled()) return CancelledWhileSaving(output, what);
  return std::nullopt;
}

// An import of `input` that failed with `status`: with --json (`as_json`) it first prints the
// error and what was skipped, by reason, as the success path reports them.
int ImportFailed(const std::string& input, const absl::Status& status, uint64_t skipped,
                 const std::map<std::string, uint64_t>& skipped_by_reason, bool as_json) {
  if (as_json) {
    const nlohmann::json j = {{"input", input},
                              {"error", std::string(status.message())},
                              {"skipped", skipped},
                              {"skipped_by_reason", CountsJson(skipped_by_reason)}};
    std::printf("%s\n", j.dump(2).c_str());
  }
  return Fail(status);
}

struct ImportArgs {
  std::string input, output, bbox, name;
  double storey_m = 3.0;
  double max_height_m = scenes::OsmImportOptions{}.max_height_m;
  bool json = false;
};

int ImportOsm(const ImportArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  scenes::OsmImportOptions options;
  options.storey_m = a.storey_m;
  options.max_height_m = a.max_height_m;
  options.name = a.name;
  if (!a.bbox.empty()) {
    absl::StatusOr<scenes::GeoBox> box = scenes::ParseGeoBox(a.bbox);
    if (!box.ok()) return BadOption("scene import-osm", "--bbox", std::string(box.status().message()));
    options.bbox = *box;
  }
  scenes::OsmImportSummary sum;
  absl::StatusOr<scenes::Scene> scene = scenes::ImportOsm(a.input, options, &sum, ToolRun());
  if (!scene.ok()) return ImportFailed(a.input, scene.status(), sum.Skipped(), sum.skipped, a.json);
  const auto save_start = std::chrono::steady_clock::now();
  if (std::optional<int> failed = SaveSceneOutput(*scene, a.output, "OSM import")) return *failed;
  const double save_s = SecondsSince(save_start);
  if (a.json) {
    nlohmann::json walks_json = nlohmann::json::array();
    for (const scenes::OsmWalkSummary& w : sum.walks) walks_json.push_back({{"name", w.name}, {"length_m", w.length_m}});
    const nlohmann::json j = {
        {"input", a.input},
        {"output", a.output},
        {"scene", scene->name},
        {"buildings", sum.buildings},
        {"from_ways", sum.from_ways},
        {"from_relations", sum.from_relations},
        {"outer_rings", sum.outer_rings},
        {"inner_rings", sum.inner_rings},
        {"occluders", sum.occluders},
        {"triangles", scene->TriangleCount()},
        {"raised", sum.raised},
        {"height_tagged", sum.height_tagged},
        {"levels_tagged", sum.levels_tagged},
        {"height_by_rule", sum.height_by_rule},
        {"bad_height_tags", sum.bad_height_tags},
        {"implausible_heights", sum.implausible_heights},
        {"min_height_above_height", sum.min_height_above_height},
        {"parts", sum.parts},
        {"outlines_hidden_by_parts", sum.outlines_hidden_by_parts},
        {"outlines_cut_by_parts", sum.outlines_cut_by_parts},
        {"merged_way_outlines", sum.merged_way_outlines},
        {"repaired", sum.Repaired()},
        {"repaired_duplicate_points", sum.repaired_duplicate_points},
        {"repaired_spikes", sum.repaired_spikes},
        {"dropped_inner_rings", sum.dropped_inner_rings},
        {"skipped", sum.Skipped()},
        {"skipped_by_reason", CountsJson(sum.skipped)},
        {"utm_zone", sum.utm_zone},
        {"origin", {scene->origin.x, scene->origin.y, scene->origin.z}},
        {"bounds_min", {scene->bounds.min.x, scene->bounds.min.y, scene->bounds.min.z}},
        {"bounds_max", {scene->bounds.max.x, scene->bounds.max.y, scene->bounds.max.z}},
        {"import_s", sum.seconds},
        {"save_s", save_s},
        {"highway_ways", sum.highway_ways},
        {"street_edges", sum.street_edges},
        {"walks", walks_json},
        {"walk_notes", sum.walk_notes},
    };
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("imported %s: %llu buildings (%llu ways, %llu relations), %llu outer and %llu inner rings, %zu triangles, "
              "%llu occluders in %.2f s; saved %s in %.2f s\n",
              scene->name.c_str(), static_cast<unsigned long long>(sum.buildings),
              static_cast<unsigned long long>(sum.from_ways), static_cast<unsigned long long>(sum.from_relations),
              static_cast<unsigned long long>(sum.outer_rings), static_cast<unsigned long long>(sum.inner_rings),
              scene->TriangleCount(), static_cast<unsigned long long>(sum.occluders), sum.seconds, a.output.c_str(),
              save_s);
  std::printf("heights: %llu tagged, %llu from levels, %llu by the building-type rule; %llu raised (no occluder); "
              "%llu unreadable height tags, %llu implausible, %llu min_height above height\n",
              static_cast<unsigned long long>(sum.height_tagged), static_cast<unsigned long long>(sum.levels_tagged),
              static_cast<unsigned long long>(sum.height_by_rule), static_cast<unsigned long long>(sum.raised),
              static_cast<unsigned long long>(sum.bad_height_tags),
              static_cast<unsigned long long>(sum.implausible_heights),
              static_cast<unsigned long long>(sum.min_height_above_height));
  std::printf("parts: %llu (outlines: %llu hidden by their parts, %llu cut); %llu ways merged into their relation\n",
              static_cast<unsigned long long>(sum.parts), static_cast<unsigned long long>(sum.outlines_hidden_by_parts),
              static_cast<unsigned long long>(sum.outlines_cut_by_parts),
              static_cast<unsigned long long>(sum.merged_way_outlines));
  std::printf("repaired: %llu (%llu duplicate points, %llu spikes, %llu inner rings dropped)\n",
              static_cast<unsigned long long>(sum.Repaired()), static_cast<unsigned long long>(sum.repaired_duplicate_points),
              static_cast<unsigned long long>(sum.repaired_spikes), static_cast<unsigned long long>(sum.dropped_inner_rings));
  std::printf("skipped: %llu\n", static_cast<unsigned long long>(sum.Skipped()));
  for (const auto& [reason, n] : sum.skipped) std::printf("  %-40s %llu\n", reason.c_str(), static_cast<unsigned long long>(n));
  std::printf("origin: UTM %s (%.0f, %.0f) m\n", sum.utm_zone.c_str(), scene->origin.x, scene->origin.y);
  std::printf("walks: %zu from %llu highway ways (%llu street edges)\n", sum.walks.size(),
              static_cast<unsigned long long>(sum.highway_ways), static_cast<unsigned long long>(sum.street_edges));
  for (const scenes::OsmWalkSummary& w : sum.walks) std::printf("  %-40s %.0f m\n", w.name.c_str(), w.length_m);
  for (const std::string& n : sum.walk_notes) std::printf("  (%s)\n", n.c_str());
  return 0;
}

struct ImportCityArgs {
  std::string input, output, name, crs;
  std::optional<int> lod;
  double terrain_tile_m = 100.0;
  std::string ground = "derived";
  bool keep_going = false;
  bool json = false;
};

int ImportCity(const ImportCityArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  scenes::CityImportOptions options;
  options.lod = a.lod;
  options.name = a.name;
  options.keep_going = a.keep_going;
  options.crs = a.crs;
  options.terrain_tile_m = a.terrain_tile_m;
  options.ground = a.ground == "none" ? scenes::CityGround::kNone : scenes::CityGround::kDerived;
  scenes::CityImportSummary sum;
  absl::StatusOr<scenes::Scene> scene = scenes::ImportCity(a.input, options, &sum, ToolRun());
  if (!scene.ok()) return ImportFailed(a.input, scene.status(), sum.Skipped(), sum.skipped, a.json);
  const auto save_start = std::chrono::steady_clock::now();
  if (std::optional<int> failed = SaveSceneOutput(*scene, a.output, "city import")) return *failed;
  const double save_s = SecondsSince(save_start);
  const double share = sum.buildings_drawn == 0 ? 0.0 : static_cast<double>(sum.buildings_with_occluder) / sum.buildings_drawn;
  const double volume_share = sum.solid_volume_m3 > 0.0 ? sum.occluder_volume_m3 / sum.solid_volume_m3 : 0.0;
  if (a.json) {
    const nlohmann::json j = {
        {"input", a.input},
        {"output", a.output},
        {"scene", scene->name},
        {"format", sum.format},
        {"crs", sum.crs},
        {"lod", a.lod ? nlohmann::json(*a.lod) : nlohmann::json("highest")},
        {"lods", CountsJson(sum.lods)},
        {"city_objects", sum.city_objects},
        {"objects_by_type", CountsJson(sum.objects_by_type)},
        {"objects", sum.objects},
        {"buildings", sum.buildings},
        {"building_parts", sum.building_parts},
        {"buildings_drawn", sum.buildings_drawn},
        {"buildings_with_occluder", sum.buildings_with_occluder},
        {"occluder_share", share},
        {"surfaces", sum.surfaces},
        {"triangles", sum.triangles},
        {"solids", sum.solids},
        {"occluders", sum.occluders},
        {"without_occluder", CountsJson(sum.without_occluder)},
        {"solid_volume_m3", sum.solid_volume_m3},
        {"occluder_volume_m3", sum.occluder_volume_m3},
        {"occluder_volume_share", volume_share},
        {"terrain",
         {{"from", sum.terrain_from},
          {"objects", sum.terrain_objects},
          {"triangles", sum.terrain_triangles},
          {"tiles", sum.terrain_tiles},
          {"skirt_triangles", sum.terrain_skirt_triangles},
          {"occluders", sum.terrain_occluders},
          {"min_z", sum.terrain_min_z},
          {"max_z", sum.terrain_max_z},
          {"relief_m", sum.terrain_max_z - sum.terrain_min_z},
          {"derived",
           {{"floors", sum.ground_floors},
            {"floors_overlapping", sum.ground_floors_overlapping},
            {"floor_points", sum.ground_floor_points},
            {"surface_points", sum.ground_surface_points},
            {"points_under_floors", sum.ground_points_under_floors},
            {"corner_points", sum.ground_corner_points}}}}},
        {"walks_from", sum.walks_from},
        {"walks", WalksJson(sum.walks)},
        {"walk_notes", sum.walk_notes},
        {"repaired", sum.Repaired()},
        {"repaired_by_reason", CountsJson(sum.repaired)},
        {"skipped", sum.Skipped()},
        {"skipped_by_reason", CountsJson(sum.skipped)},
        {"origin", {scene->origin.x, scene->origin.y, scene->origin.z}},
        {"bounds_min", {scene->bounds.min.x, scene->bounds.min.y, scene->bounds.min.z}},
        {"bounds_max", {scene->bounds.max.x, scene->bounds.max.y, scene->bounds.max.z}},
        {"read_s", sum.read_s},
        {"build_s", sum.build_s},
        {"save_s", save_s},
        {"peak_rss_mib", PeakRssMib()},
    };
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("imported %s (%s, %s): %llu city objects, %llu scene objects, %llu triangles, %llu occluders; "
              "read in %.2f s, built in %.2f s, saved %s in %.2f s; peak memory %.0f MiB\n",
              scene->name.c_str(), sum.format.c_str(), sum.crs.empty() ? "no CRS" : sum.crs.c_str(),
              static_cast<unsigned long long>(sum.city_objects), static_cast<unsigned long long>(sum.objects),
              static_cast<unsigned long long>(sum.triangles), static_cast<unsigned long long>(sum.occluders), sum.read_s,
              sum.build_s, a.output.c_str(), save_s, PeakRssMib());
  std::printf("buildings: %llu, parts: %llu; drawn %llu, of them %llu with an occluder (%.1f%%); occluders hold %.1f%% of "
              "the closed solids' volume (%.0f of %.0f m³)\n",
              static_cast<unsigned long long>(sum.buildings), static_cast<unsigned long long>(sum.building_parts),
              static_cast<unsigned long long>(sum.buildings_drawn),
              static_cast<unsigned long long>(sum.buildings_with_occluder), 100.0 * share, 100.0 * volume_share,
              sum.occluder_volume_m3, sum.solid_volume_m3);
  if (sum.terrain_triangles > 0) {
    std::printf("terrain: %llu triangles in %llu tiles, %llu occluders, heights %.2f to %.2f m (relief %.2f m)\n",
                static_cast<unsigned long long>(sum.terrain_triangles), static_cast<unsigned long long>(sum.terrain_tiles),
                static_cast<unsigned long long>(sum.terrain_occluders), sum.terrain_min_z, sum.terrain_max_z,
                sum.terrain_max_z - sum.terrain_min_z);
    if (sum.terrain_from == "derived") {
      std::printf("terrain derived (the file has no TIN): %llu building floors (%llu left out over a lower one), "
                  "%llu floor corners, %llu ground surface points (%llu under floors left out), %llu box corners\n",
                  static_cast<unsigned long long>(sum.ground_floors),
                  static_cast<unsigned long long>(sum.ground_floors_overlapping),
                  static_cast<unsigned long long>(sum.ground_floor_points),
                  static_cast<unsigned long long>(sum.ground_surface_points),
                  static_cast<unsigned long long>(sum.ground_points_under_floors),
                  static_cast<unsigned long long>(sum.ground_corner_points));
    }
  } else {
    std::printf("terrain: none (flat ground at the lowest point, %.2f m)\n", scene->origin.z);
  }
  std::printf("by type:");
  for (const auto& [type, n] : sum.objects_by_type) std::printf(" %s %llu", type.c_str(), static_cast<unsigned long long>(n));
  std::printf("\nLoD drawn:");
  for (const auto& [lod, n] : sum.lods) std::printf(" %s (%llu)", lod.c_str(), static_cast<unsigned long long>(n));
  std::printf("\n");
  uint64_t without = 0;
  for (const auto& [reason, n] : sum.without_occluder) without += n;
  PrintCounts("solids without an occluder", without, sum.without_occluder);
  if (!sum.walks_from.empty()) {
    std::printf("walks from the %s: %zu\n", sum.walks_from.c_str(), sum.walks.size());
    for (const auto& [name, length] : sum.walks) std::printf("  %-48s %.0f m\n", name.c_str(), length);
    for (const std::string& note : sum.walk_notes) std::printf("  note: %s\n", note.c_str());
  }
  PrintCounts("repaired", sum.Repaired(), sum.repaired);
  PrintCounts("skipped", sum.Skipped(), sum.skipped);
  std::printf("origin: %s (%.0f, %.0f, %.3f)\n", sum.crs.empty() ? "unknown CRS" : sum.crs.c_str(), scene->origin.x,
              scene->origin.y, scene->origin.z);
  return 0;
}

struct OccludersArgs {
  std::string input, output;
  bool keep = false;
  bool json = false;
};

int Occluders(const OccludersArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  std::vector<std::string> warnings;
  absl::StatusOr<scenes::Scene> scene = scenes::LoadGltf(a.input, &warnings);
  if (!scene.ok()) return Fail(scene.status());
  if (!a.json) {
    for (const std::string& w : warnings) std::fprintf(stderr, "vistream: warning: %s\n", w.c_str());
  }
  const size_t before = scene->occluders.size();
  const auto start = std::chrono::steady_clock::now();
  const scenes::OccluderSynthesisSummary sum = scenes::AddSynthesizedOccluders(&*scene, /*replace=*/!a.keep, {}, ToolRun());
  if (ToolRun().Cancelled()) return Fail(absl::CancelledError("occluder synthesis cancelled"));
  const double synth_s = SecondsSince(start);
  if (std::optional<int> failed = SaveSceneOutput(*scene, a.output, "occluder synthesis")) return *failed;
  const double volume_share = sum.solid_volume_m3 > 0.0 ? sum.occluder_volume_m3 / sum.solid_volume_m3 : 0.0;
  if (a.json) {
    const nlohmann::json j = {{"input", a.input},
                              {"output", a.output},
                              {"objects", scene->objects.size()},
                              {"objects_considered", sum.objects},
                              {"objects_with_occluder", sum.objects_with_occluder},
                              {"occluders_before", before},
                              {"occluders_synthesized", sum.occluders},
                              {"occluders", scene->occluders.size()},
                              {"without_occluder", CountsJson(sum.without_occluder)},
                              {"solid_volume_m3", sum.solid_volume_m3},
                              {"occluder_volume_m3", sum.occluder_volume_m3},
                              {"occluder_volume_share", volume_share},
                              {"synthesis_s", synth_s}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("%s: %llu of %llu objects considered got occluders (%llu prisms; %zu before, %s); occluders hold %.1f%% of "
              "the closed meshes' volume; %.2f s; saved %s\n",
              a.input.c_str(), static_cast<unsigned long long>(sum.objects_with_occluder),
              static_cast<unsigned long long>(sum.objects), static_cast<unsigned long long>(sum.occluders), before,
              a.keep ? "kept" : "replaced", 100.0 * volume_share, synth_s, a.output.c_str());
  uint64_t without = 0;
  for (const auto& [reason, n] : sum.without_occluder) without += n;
  PrintCounts("objects without an occluder", without, sum.without_occluder);
  return 0;
}

struct ExtrudeArgs {
  std::string input, output;
  bool json = false;
};

int Extrude(const ExtrudeArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  double load_s = 0.0;
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.input, &load_s);
  if (!scene.ok()) return Fail(scene.status());
  const auto start = std::chrono::steady_clock::now();
  scenes::ExtrusionSummary sum;
  absl::StatusOr<scenes::Scene> extruded = scenes::ExtrudeFootprints(*scene, &sum);
  if (!extruded.ok()) return Fail(extruded.status());
  const double extrude_s = SecondsSince(start);
  if (std::optional<int> failed = SaveSceneOutput(*extruded, a.output, "extrusion")) return *failed;
  uint64_t kept = 0;
  for (const auto& [reason, n] : sum.not_extruded) kept += n;
  if (a.json) {
    const nlohmann::json j = {{"input", a.input},
                              {"output", a.output},
                              {"objects_before", scene->objects.size()},
                              {"objects", extruded->objects.size()},
                              {"buildings", sum.buildings},
                              {"extruded", sum.extruded},
                              {"not_extruded", CountsJson(sum.not_extruded)},
                              {"terrain_dropped", sum.terrain_dropped},
                              {"occluders", sum.occluders},
                              {"footprint_m2", sum.footprint_m2},
                              {"triangles", extruded->TriangleCount()},
                              {"extrude_s", extrude_s}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("%s: %llu of %llu buildings extruded (%.0f m² of footprint, %llu occluders), %llu terrain objects left "
              "out; %zu objects, %zu triangles; %.2f s; saved %s\n",
              a.input.c_str(), static_cast<unsigned long long>(sum.extruded),
              static_cast<unsigned long long>(sum.buildings), sum.footprint_m2,
              static_cast<unsigned long long>(sum.occluders), static_cast<unsigned long long>(sum.terrain_dropped),
              extruded->objects.size(), extruded->TriangleCount(), extrude_s, a.output.c_str());
  PrintCounts("buildings kept as they were", kept, sum.not_extruded);
  return 0;
}

uint64_t ObjectLevelCount(const scenes::SceneLevels& levels) {
  uint64_t n = 0;
  for (const auto& chain : levels.objects) n += chain.size();
  return n;
}

struct LevelsArgs {
  std::string input, output;
  double tile_m = 250.0;
  bool no_clusters = false;
  bool json = false;
};

// vistream scene levels: every object's chain of coarser meshes and the clusters (issue 45),
// measured, saved with the scene (glTF MSFT_lod).
int Levels(const LevelsArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  double load_s = 0.0;
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.input, &load_s);
  if (!scene.ok()) return Fail(scene.status());
  scenes::LevelOptions options;
  if (a.no_clusters) options.cluster_tiles_m.clear();
  else options.cluster_tiles_m = {a.tile_m, 4.0 * a.tile_m};
  const auto start = std::chrono::steady_clock::now();
  absl::StatusOr<scenes::SceneLevels> levels = scenes::MakeLevels(*scene, options, ToolRun());
  if (!levels.ok()) return Fail(levels.status());
  const double make_s = SecondsSince(start);
  scene->levels = *std::move(levels);
  if (std::optional<int> failed = SaveSceneOutput(*scene, a.output, "levels")) return *failed;
  const scenes::SceneLevels& l = scene->levels;
  const uint64_t object_levels = ObjectLevelCount(l);
  uint64_t with = 0, cluster_levels = 0;
  for (const auto& chain : l.objects) with += chain.empty() ? 0 : 1;
  for (const auto& c : l.clusters) cluster_levels += c.levels.size();
  double max_error = 0.0;
  for (const auto& chain : l.objects) {
    for (const auto& lv : chain) max_error = std::max(max_error, lv.error_m);
  }
  struct rusage usage {};
  getrusage(RUSAGE_SELF, &usage);
  const double peak_mb = static_cast<double>(usage.ru_maxrss) / 1024.0;
  if (a.json) {
    const nlohmann::json j = {{"input", a.input},
                              {"output", a.output},
                              {"objects", scene->objects.size()},
                              {"objects_with_levels", with},
                              {"object_levels", object_levels},
                              {"clusters", l.clusters.size()},
                              {"cluster_levels", cluster_levels},
                              {"level_bytes", scenes::LevelBytes(l)},
                              {"largest_object_error_m", max_error},
                              {"load_s", load_s},
                              {"levels_s", make_s},
                              {"peak_rss_mb", peak_mb}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("%s: %llu of %zu objects have levels (%llu levels), %zu clusters (%llu levels); levels hold %.1f MB; "
              "made in %.1f s, peak memory %.0f MB; saved %s\n",
              a.input.c_str(), static_cast<unsigned long long>(with), scene->objects.size(),
              static_cast<unsigned long long>(object_levels), l.clusters.size(),
              static_cast<unsigned long long>(cluster_levels), static_cast<double>(scenes::LevelBytes(l)) / 1e6, make_s,
              peak_mb, a.output.c_str());
  return 0;
}

struct InfoArgs {
  std::string file;
  bool json = false;
  uint32_t leaf_size = 4;
};

int Info(const InfoArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  double load_s = 0.0;
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.file, &load_s);
  if (!scene.ok()) return Fail(scene.status());
  const auto kd_start = std::chrono::steady_clock::now();
  const visibility::KdTree tree = visibility::KdTree::Build(*scene, {.leaf_size = a.leaf_size});
  const double kd_ms = 1000.0 * SecondsSince(kd_start);

  size_t tiered = 0;
  std::map<scenes::ObjectId, int> per_object;
  for (const auto& oc : scene->occluders) ++per_object[oc.object];
  for (const auto& [id, n] : per_object) tiered += n > 1;
  const auto& b = scene->bounds;
  const double area_km2 = (b.max.x - b.min.x) * (b.max.y - b.min.y) / 1e6;
  const scenes::OcclusionStats st = scenes::ComputeOcclusionStats(*scene);
  const double occluding_share = st.solid_volume_m3 > 0.0 ? st.occluder_volume_m3 / st.solid_volume_m3 : 0.0;
  if (a.json) {
    nlohmann::json j;
    j["name"] = scene->name;
    j["objects"] = scene->objects.size();
    j["triangles"] = scene->TriangleCount();
    j["vertices"] = scene->VertexCount();
    j["occluders"] = scene->occluders.size();
    j["object_levels"] = ObjectLevelCount(scene->levels);
    j["clusters"] = scene->levels.clusters.size();
    j["objects_with_several_occluders"] = tiered;
    j["bounds"] = {{"min", {b.min.x, b.min.y, b.min.z}}, {"max", {b.max.x, b.max.y, b.max.z}}};
    j["origin"] = {scene->origin.x, scene->origin.y, scene->origin.z};
    j["area_km2"] = area_km2;
    j["load_s"] = load_s;
    j["crs"] = scene->crs;
    j["objects_by_type"] = CountsJson(st.objects_by_type);
    j["objects_with_occluder"] = st.objects_with_occluder;
    j["non_terrain_objects"] = st.non_terrain_objects;
    j["solid_volume_m3"] = st.solid_volume_m3;
    j["occluder_volume_m3"] = st.occluder_volume_m3;
    j["occluder_volume_share"] = occluding_share;
    j["open_objects_with_occluder"] = st.open_objects_with_occluder;
    j["terrain"] = {{"derived", st.derived_terrain_objects > 0},
                    {"objects", st.terrain_objects},
                    {"triangles", st.terrain_triangles},
                    {"occluders", st.terrain_occluders},
                    {"min_z", st.terrain_min_z},
                    {"max_z", st.terrain_max_z},
                    {"relief_m", st.terrain_max_z - st.terrain_min_z}};
    j["kd"] = {{"nodes", tree.nodes().size()}, {"leaves", tree.LeafCount()}, {"depth", tree.depth()},
               {"leaf_size", a.leaf_size}, {"build_ms", kd_ms}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("scene       %s\n", scene->name.c_str());
  std::printf("objects     %zu (%zu with several occluders: stacked or rows)\n", scene->objects.size(), tiered);
  std::printf("triangles   %zu\n", scene->TriangleCount());
  std::printf("vertices    %zu\n", scene->VertexCount());
  std::printf("occluders   %zu (%llu of terrain); %llu of %llu objects occlude", scene->occluders.size(),
              static_cast<unsigned long long>(st.terrain_occluders),
              static_cast<unsigned long long>(st.objects_with_occluder),
              static_cast<unsigned long long>(st.non_terrain_objects));
  if (st.solid_volume_m3 > 0.0) {
    std::printf(", with %.0f of their %.0f m³ (%.1f%%)", st.occluder_volume_m3, st.solid_volume_m3,
                100.0 * occluding_share);
  }
  std::printf("\n");
  if (st.open_objects_with_occluder > 0) {
    std::printf("            (%llu occluding objects are surfaces closed by their neighbours and the ground: their "
                "volumes are not measured)\n",
                static_cast<unsigned long long>(st.open_objects_with_occluder));
  }
  if (!scene->levels.empty()) {
    std::printf("levels      %llu object levels, %zu clusters (%.1f MB)\n",
                static_cast<unsigned long long>(ObjectLevelCount(scene->levels)), scene->levels.clusters.size(),
                static_cast<double>(scenes::LevelBytes(scene->levels)) / 1e6);
  }
  if (st.objects_by_type.size() > 1 || !st.objects_by_type.count("object")) {
    std::printf("types      ");
    for (const auto& [type, n] : st.objects_by_type) std::printf(" %s %llu", type.c_str(), static_cast<unsigned long long>(n));
    std::printf("\n");
  }
  if (st.terrain_objects > 0) {
    std::printf("terrain     %llu objects, %llu triangles, heights %.2f to %.2f m (relief %.2f m)%s\n",
                static_cast<unsigned long long>(st.terrain_objects), static_cast<unsigned long long>(st.terrain_triangles),
                st.terrain_min_z, st.terrain_max_z, st.terrain_max_z - st.terrain_min_z,
                st.derived_terrain_objects > 0 ? "; derived from the data (the file had no TIN)" : "");
  }
  std::printf("bounds      min (%.2f, %.2f, %.2f)  max (%.2f, %.2f, %.2f)  [scene-local m]\n", b.min.x,
              b.min.y, b.min.z, b.max.x, b.max.y, b.max.z);
  std::printf("extent      %.0f x %.0f m, %.2f km², height %.1f m\n", b.max.x - b.min.x, b.max.y - b.min.y,
              area_km2, b.max.z - b.min.z);
  std::printf("origin      (%.3f, %.3f, %.3f)%s%s\n", scene->origin.x, scene->origin.y, scene->origin.z,
              scene->crs.empty() ? "" : " in ", scene->crs.c_str());
  std::printf("loaded in   %.2f s\n", load_s);
  std::printf("kd-tree     %zu nodes, %zu leaves (<= %u objects), depth %u, built in %.1f ms\n",
              tree.nodes().size(), tree.LeafCount(), a.leaf_size, tree.depth(), kd_ms);
  return 0;
}

// The walks of the scene `file` names: its catalog entry's (when it is a catalog name or .json),
// then the scene's own (derived from its data), as the server serves them; `*declared` says how
// many come from the catalog.
std::vector<scenes::WalkPath> WalksOf(const std::string& file, const scenes::Scene& scene, size_t* declared) {
  std::vector<scenes::WalkPath> walks;
  const std::string ext = std::filesystem::path(file).extension().string();
  if (ext != ".glb" && ext != ".gltf") {
    if (auto entry = scenes::FindCatalogEntry(file); entry.ok()) walks = entry->walks;
  }
  *declared = walks.size();
  return scenes::WalksWithScenePaths(walks, scene);
}

struct WalksArgs {
  std::string file;
  bool json = false;
};

// Lists the walks a client can name (--path, the page's ?walk=): name, length, waypoints.
int Walks(const WalksArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.file);
  if (!scene.ok()) return Fail(scene.status());
  size_t declared = 0;
  const std::vector<scenes::WalkPath> walks = WalksOf(a.file, *scene, &declared);
  nlohmann::ordered_json j = nlohmann::ordered_json::array();
  for (size_t i = 0; i < walks.size(); ++i) {
    double length = 0.0;
    for (size_t k = 0; k + 1 < walks[i].waypoints.size(); ++k) {
      length += glm::distance(walks[i].waypoints[k], walks[i].waypoints[k + 1]);
    }
    const char* source = i < declared ? "catalog" : "data";
    if (a.json) {
      j.push_back({{"name", walks[i].name}, {"length_m", length}, {"points", walks[i].waypoints.size()},
                   {"source", source}});
    } else {
      std::printf("%s\t%.0f m\t%zu points\t%s\n", walks[i].name.c_str(), length, walks[i].waypoints.size(),
                  i < declared ? "from the catalog" : "from the data");
    }
  }
  if (a.json) {
    std::printf("%s\n", j.dump(2).c_str());
  } else if (walks.empty()) {
    std::fprintf(stderr, "vistream: %s has no walks (a client walks it by keys, or --path names none)\n",
                 a.file.c_str());
  }
  return 0;
}

struct MapArgs {
  std::string file, output;
  int size = 2048;
};

// Footprints coloured by height (tallest drawn last), the catalog's walk paths in red, the
// scene's own (Scene::paths) in blue.
int Map(const MapArgs& a) {
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.file);
  if (!scene.ok()) return Fail(scene.status());
  size_t declared = 0;
  const std::vector<scenes::WalkPath> walks = WalksOf(a.file, *scene, &declared);
  TopViewMap map(scene->bounds, a.size, Rgb{245, 243, 238});
  std::vector<bool> is_terrain(scene->objects.size(), false), occludes(scene->objects.size(), false);
  for (scenes::ObjectId t : scene->terrain) is_terrain[t] = true;
  std::vector<const scenes::Occluder25D*> order;
  for (const auto& oc : scene->occluders) {
    if (is_terrain[oc.object]) continue;  // terrain tiers would hide the buildings
    order.push_back(&oc);
    occludes[oc.object] = true;
  }
  // Terrain underneath: its triangles shaded from low (light) to high (dark) ground.
  double ground_lo = INFINITY, ground_hi = -INFINITY;
  for (scenes::ObjectId t : scene->terrain) {
    ground_lo = std::min(ground_lo, scene->objects[t].bounds.min.z);
    ground_hi = std::max(ground_hi, scene->objects[t].bounds.max.z);
  }
  auto shade = [&](double z) {
    const double f = ground_hi > ground_lo ? (z - ground_lo) / (ground_hi - ground_lo) : 0.0;
    return Rgb{static_cast<uint8_t>(225 - 90 * f), static_cast<uint8_t>(232 - 80 * f), static_cast<uint8_t>(205 - 95 * f)};
  };
  auto fill_mesh = [&](const scenes::Mesh& m, auto colour_of) {
    for (size_t k = 0; k + 2 < m.indices.size(); k += 3) {
      const glm::vec3 p0 = m.positions[m.indices[k]], p1 = m.positions[m.indices[k + 1]], p2 = m.positions[m.indices[k + 2]];
      const glm::dvec2 tri[3] = {glm::dvec2(p0), glm::dvec2(p1), glm::dvec2(p2)};
      map.FillPolygon(tri, colour_of((p0.z + p1.z + p2.z) / 3.0), /*antialias=*/false);
    }
  };
  for (scenes::ObjectId t : scene->terrain) fill_mesh(scene->objects[t].mesh, shade);
  // Objects that do not occlude (open solids, raised parts, surfaces, furniture), in grey.
  const Rgb no_occluder{170, 170, 178};
  size_t grey = 0;
  for (const scenes::Object& o : scene->objects) {
    if (is_terrain[o.id] || occludes[o.id]) continue;
    fill_mesh(o.mesh, [&](double) { return no_occluder; });
    ++grey;
  }
  std::sort(order.begin(), order.end(), [](auto* x, auto* y) { return x->height < y->height; });
  const double top = std::max(1.0, scene->bounds.max.z);
  // Where a footprint is a few pixels, smoothed edges blend every building into its
  // neighbours: no outline to read, and colours that swell the PNG (london: 3.6 MB). There
  // the footprints are filled pixel-sharp and not outlined.
  const bool outlines = map.outlines_readable();
  for (const scenes::Occluder25D* oc : order) {
    // Log scale: two-storey houses and 300 m towers both stay distinguishable.
    map.FillPolygon(oc->footprint, Ramp(std::log1p(oc->height) / std::log1p(top)), /*antialias=*/outlines);
  }
  const Rgb outline{60, 60, 60};
  if (outlines) {
    for (const scenes::Occluder25D* oc : order) map.StrokePolygon(oc->footprint, outline, 0.6);
  }
  // The catalog's walks in red, the scene's own (derived from its data) in blue.
  const Rgb walk_colour{220, 30, 30}, path_colour{30, 80, 220};
  for (size_t i = 0; i < walks.size(); ++i) {
    const scenes::WalkPath& w = walks[i];
    for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
      map.Line(w.waypoints[k], w.waypoints[k + 1], i < declared ? walk_colour : path_colour, 3);
    }
  }
  const scenes::Aabb& b = scene->bounds;
  map.SetTitle(absl::StrCat(scene->name, ": building footprints by height, walks"),
               absl::StrFormat("%zu objects, %zu footprints, %.0f x %.0f m, tallest %.1f m", scene->objects.size(),
                               order.size(), b.max.x - b.min.x, b.max.y - b.min.y, b.max.z));
  for (size_t i = 0; i < walks.size(); ++i) {
    map.AddLegend(i < declared ? walk_colour : path_colour,
                  absl::StrCat(i < declared ? "walk '" : "walk from the data '", walks[i].name, "'"), Swatch::kLine);
  }
  if (grey > 0) map.AddLegend(no_occluder, absl::StrFormat("object without an occluder (%zu)", grey));
  if (!scene->terrain.empty()) {
    map.AddLegend(shade(ground_lo), absl::StrFormat("terrain, low (%.1f m)", scene->origin.z + ground_lo));
    map.AddLegend(shade(ground_hi), absl::StrFormat("terrain, high (%.1f m)", scene->origin.z + ground_hi));
  }
  if (outlines) {
    map.AddLegend(outline, "building footprint edge", Swatch::kOutline);
  } else {
    map.AddNote(absl::StrFormat("footprints outlined below %g m per pixel only",
                                TopViewMap::kOutlineMetresPerPixel));
  }
  map.SetColourBar("building height (m, log scale)", top);
  if (absl::Status s = map.WritePng(a.output); !s.ok()) return Fail(s);
  std::printf("wrote %s: %d x %d pixels, %.2f m per pixel, %zu footprints, %zu walks\n", a.output.c_str(),
              map.width(), map.height(), map.metres_per_pixel(), order.size(), walks.size());
  return 0;
}

}  // namespace

void AddSceneCommands(CLI::App& app, std::function<void(int)> done) {
  CLI::App* scene = AddCommandGroup(app, "scene", "generate, load and inspect scenes");

  auto [g, gen] = AddSubcommand<GenerateArgs>(
      scene, "generate", "generate a city (a catalog name or city1, city2, london, streets)",
      Generate, done);
  g->add_option("NAME", gen->name, "catalog entry (scenes/NAME.json) or generator name")->required();
  g->add_option("--seed", gen->seed, "random seed (default: the catalog's, else 1)")->check(WholeRange(0, kMaxSeed));
  g->add_option("-o,--output", gen->output, "output file, .glb or .gltf")
      ->required()
      ->check(SceneOutputPath());

  auto [o, imp] = AddSubcommand<ImportArgs>(
      scene, "import-osm", "import OpenStreetMap buildings (.osm or .osm.pbf) into a scene",
      ImportOsm, done);
  o->add_option("IN", imp->input, "OpenStreetMap file: .osm (XML), .osm.pbf, .osm.bz2 or .osm.gz")->required();
  o->add_option("-o,--output", imp->output, "output file, .glb or .gltf")->required()->check(SceneOutputPath());
  o->add_option("--bbox", imp->bbox, "keep buildings inside MIN_LON,MIN_LAT,MAX_LON,MAX_LAT (degrees)");
  o->add_option("--storey", imp->storey_m, "storey height in metres (levels to heights)")->check(FiniteRange(1.0, 20.0));
  o->add_option("--max-height", imp->max_height_m,
                "plausible limit in metres: taller height or levels tags are bad data (counted; the next rule is used)")
      ->check(FiniteRange(10.0, 10000.0));
  o->add_option("--name", imp->name, "the scene's name (default: the file name up to its first dot)")
      ->check(NonEmpty("an empty name"));
  o->add_flag("--json", imp->json, "print the summary as one JSON object");

  auto [c, city] =
      AddSubcommand<ImportCityArgs>(scene, "import-city",
                                    "import a 3D city model (CityGML .gml/.xml, CityJSON "
                                    ".json/.city.json): buildings, parts, terrain, "
                                    "with occluders synthesized from the solids",
                                    ImportCity, done);
  c->add_option("IN", city->input, "CityGML 1.0/2.0 (.gml, .xml) or CityJSON 0.x-2.0 (.json, .city.json)")->required();
  c->add_option("-o,--output", city->output, "output file, .glb or .gltf")->required()->check(SceneOutputPath());
  c->add_option("--lod", city->lod, "level of detail to draw (its integer part: 1, 2); default: each object's highest")
      ->check(WholeRange(0, 4));
  c->add_option("--name", city->name, "the scene's name (default: the file name up to its first dot)")
      ->check(NonEmpty("an empty name"));
  c->add_option("--crs", city->crs, "the coordinate reference system when the file names none (EPSG:28992)")
      ->check(CLI::Validator(
          [](std::string& text) -> std::string {
            return scenes::IsCrsName(text) ? "" : "'" + text + "' names no coordinate reference system (AUTHORITY:CODE, such as EPSG:28992)";
          },
          "AUTHORITY:CODE"));
  c->add_option("--terrain-tile", city->terrain_tile_m, "edge of the terrain's tiles in metres (each tile an object)")
      ->check(FiniteRange(1.0, 100000.0));
  c->add_option("--ground", city->ground,
                 "without a TIN in the file: derived (a terrain from building floors and roads, land use, water) "
                 "or none (flat ground at the lowest point)")
      ->check(CLI::IsMember({"derived", "none"}))
      ->capture_default_str();
  c->add_flag("--keep-going", city->keep_going, "leave out objects with malformed geometry (counted) instead of failing");
  c->add_flag("--json", city->json, "print the summary as one JSON object");

  auto [oc, occ] = AddSubcommand<OccludersArgs>(
      scene, "occluders", "synthesize occluders from a glTF scene's closed meshes", Occluders,
      done);
  oc->add_option("IN", occ->input, ".glb or .gltf file")->required();
  oc->add_option("-o,--output", occ->output, "output file, .glb or .gltf")->required()->check(SceneOutputPath());
  oc->add_flag("--keep", occ->keep, "keep the file's occluders (synthesize only for objects without); default: replace them");
  oc->add_flag("--json", occ->json, "print the summary as one JSON object");

  auto [ex, ext] =
      AddSubcommand<ExtrudeArgs>(scene, "extrude",
                                 "a city model as OpenStreetMap draws it: each building its "
                                 "footprint's prism, ground to top, flat ground",
                                 Extrude, done);
  ex->add_option("IN", ext->input, ".glb/.gltf file, catalog name or catalog .json")->required();
  ex->add_option("-o,--output", ext->output, "output file, .glb or .gltf")->required()->check(SceneOutputPath());
  ex->add_flag("--json", ext->json, "print the summary as one JSON object");

  auto [lv, lev] = AddSubcommand<LevelsArgs>(
      scene, "levels",
      "make levels of detail: each object's coarser meshes and merged clusters of nearby objects, each with its "
      "measured error in metres, saved with the scene (glTF MSFT_lod)",
      Levels, done);
  lv->add_option("IN", lev->input, ".glb/.gltf file, catalog name or catalog .json")->required();
  lv->add_option("-o,--output", lev->output, "output file, .glb or .gltf")->required()->check(SceneOutputPath());
  lv->add_option("--tile", lev->tile_m, "edge of the small cluster tiles in metres (large tiles: 4 times)")
      ->check(FiniteRange(10.0, 100000.0))
      ->capture_default_str();
  lv->add_flag("--no-clusters", lev->no_clusters, "object levels only");
  lv->add_flag("--json", lev->json, "print the summary as one JSON object");

  auto [i, info] = AddSubcommand<InfoArgs>(scene, "info", "print a scene's statistics", Info, done);
  i->add_option("FILE", info->file, ".glb/.gltf file, catalog name or catalog .json")->required();
  i->add_flag("--json", info->json, "print one JSON object");
  i->add_option("--leaf-size", info->leaf_size, "kd-tree leaf size")->check(WholeRange(1, 1024));

  auto [wk, walks] = AddSubcommand<WalksArgs>(
      scene, "walks", "list the walks a client can follow (--path NAME): the catalog's, then those derived from the data",
      Walks, done);
  wk->add_option("FILE", walks->file, ".glb/.gltf file, catalog name or catalog .json")->required();
  wk->add_flag("--json", walks->json, "print a JSON array of {name, length_m, points, source}");

  auto [m, map] = AddSubcommand<MapArgs>(
      scene, "map",
      "write a top-view PNG: footprints by height, the catalog's walks in red, those derived from the data in blue", Map,
      done);
  m->add_option("FILE", map->file, ".glb/.gltf file, catalog name or catalog .json")->required();
  m->add_option("-o,--output", map->output, "output .png")->required()->check(OutputPath());
  m->add_option("--size", map->size, "pixels on the longer side")->check(WholeRange(16, 16384));
}

}  // namespace vistream::tools
