// vistream scene generate | import-osm | info | map
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <cstdio>
#include <map>

#include <CLI/CLI.hpp>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/top_view_map.h"
#include "scenes/catalog.h"
#include "scenes/city_generator.h"
#include "scenes/gltf_io.h"
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
  const double generate_s = SecondsSince(start);
  const auto save_start = std::chrono::steady_clock::now();
  if (absl::Status s = scenes::SaveGltf(*scene, a.output); !s.ok()) return Fail(s);
  std::printf("generated %s: %zu objects, %zu triangles, %zu occluders in %.2f s; saved %s in %.2f s\n",
              scene->name.c_str(), scene->objects.size(), scene->TriangleCount(),
              scene->occluders.size(), generate_s, a.output.c_str(), SecondsSince(save_start));
  return 0;
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
  if (!scene.ok() && a.json) {
    // The error path reports what was skipped, by reason, as the success path does.
    nlohmann::json skipped = nlohmann::json::object();
    for (const auto& [reason, n] : sum.skipped) skipped[reason] = n;
    const nlohmann::json j = {{"input", a.input},
                              {"error", std::string(scene.status().message())},
                              {"skipped", sum.Skipped()},
                              {"skipped_by_reason", skipped}};
    std::printf("%s\n", j.dump(2).c_str());
  }
  if (!scene.ok()) return Fail(scene.status());
  const auto save_start = std::chrono::steady_clock::now();
  if (absl::Status s = scenes::SaveGltf(*scene, a.output); !s.ok()) return Fail(s);
  if (ToolRun().Cancelled()) {
    // ^C while saving: what was asked for was not finished, so nothing is left behind.
    std::error_code ec;
    std::filesystem::remove(a.output, ec);
    return Fail(absl::CancelledError("OSM import cancelled (while saving)"));
  }
  const double save_s = SecondsSince(save_start);
  if (a.json) {
    nlohmann::json skipped = nlohmann::json::object();
    for (const auto& [reason, n] : sum.skipped) skipped[reason] = n;
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
        {"skipped_by_reason", skipped},
        {"utm_zone", sum.utm_zone},
        {"origin", {scene->origin.x, scene->origin.y, scene->origin.z}},
        {"bounds_min", {scene->bounds.min.x, scene->bounds.min.y, scene->bounds.min.z}},
        {"bounds_max", {scene->bounds.max.x, scene->bounds.max.y, scene->bounds.max.z}},
        {"import_s", sum.seconds},
        {"save_s", save_s},
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
  if (a.json) {
    nlohmann::json j;
    j["name"] = scene->name;
    j["objects"] = scene->objects.size();
    j["triangles"] = scene->TriangleCount();
    j["vertices"] = scene->VertexCount();
    j["occluders"] = scene->occluders.size();
    j["objects_with_several_occluders"] = tiered;
    j["bounds"] = {{"min", {b.min.x, b.min.y, b.min.z}}, {"max", {b.max.x, b.max.y, b.max.z}}};
    j["origin"] = {scene->origin.x, scene->origin.y, scene->origin.z};
    j["area_km2"] = area_km2;
    j["load_s"] = load_s;
    j["kd"] = {{"nodes", tree.nodes().size()}, {"leaves", tree.LeafCount()}, {"depth", tree.depth()},
               {"leaf_size", a.leaf_size}, {"build_ms", kd_ms}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("scene       %s\n", scene->name.c_str());
  std::printf("objects     %zu (%zu with several occluders: stacked or rows)\n", scene->objects.size(), tiered);
  std::printf("triangles   %zu\n", scene->TriangleCount());
  std::printf("vertices    %zu\n", scene->VertexCount());
  std::printf("occluders   %zu\n", scene->occluders.size());
  std::printf("bounds      min (%.2f, %.2f, %.2f)  max (%.2f, %.2f, %.2f)  [scene-local m]\n", b.min.x,
              b.min.y, b.min.z, b.max.x, b.max.y, b.max.z);
  std::printf("extent      %.0f x %.0f m, %.2f km², height %.1f m\n", b.max.x - b.min.x, b.max.y - b.min.y,
              area_km2, b.max.z - b.min.z);
  std::printf("origin      (%.3f, %.3f, %.3f)\n", scene->origin.x, scene->origin.y, scene->origin.z);
  std::printf("loaded in   %.2f s\n", load_s);
  std::printf("kd-tree     %zu nodes, %zu leaves (<= %u objects), depth %u, built in %.1f ms\n",
              tree.nodes().size(), tree.LeafCount(), a.leaf_size, tree.depth(), kd_ms);
  return 0;
}

struct MapArgs {
  std::string file, output;
  int size = 2048;
};

// Footprints coloured by height (tallest drawn last), the catalog's walk paths in red.
int Map(const MapArgs& a) {
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.file);
  if (!scene.ok()) return Fail(scene.status());
  std::vector<scenes::WalkPath> walks;
  const std::string ext = std::filesystem::path(a.file).extension().string();
  if (ext != ".glb" && ext != ".gltf") {
    if (auto entry = scenes::FindCatalogEntry(a.file); entry.ok()) walks = entry->walks;
  }
  TopViewMap map(scene->bounds, a.size, Rgb{245, 243, 238});
  std::vector<const scenes::Occluder25D*> order;
  for (const auto& oc : scene->occluders) order.push_back(&oc);
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
  const Rgb walk_colour{220, 30, 30};
  for (const scenes::WalkPath& w : walks) {
    for (size_t k = 0; k + 1 < w.waypoints.size(); ++k) {
      map.Line(w.waypoints[k], w.waypoints[k + 1], walk_colour, 3);
    }
  }
  const scenes::Aabb& b = scene->bounds;
  map.SetTitle(absl::StrCat(scene->name, ": building footprints by height, catalog walks"),
               absl::StrFormat("%zu objects, %zu footprints, %.0f x %.0f m, tallest %.1f m", scene->objects.size(),
                               order.size(), b.max.x - b.min.x, b.max.y - b.min.y, b.max.z));
  for (const scenes::WalkPath& w : walks) map.AddLegend(walk_colour, "walk '" + w.name + "'", Swatch::kLine);
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
  CLI::App* scene = app.add_subcommand("scene", "generate, load and inspect scenes");
  scene->require_subcommand(1);

  auto gen = std::make_shared<GenerateArgs>();
  CLI::App* g = scene->add_subcommand("generate", "generate a city (a catalog name or city1, city2, london, streets)");
  g->add_option("NAME", gen->name, "catalog entry (scenes/NAME.json) or generator name")->required();
  g->add_option("--seed", gen->seed, "random seed (default: the catalog's, else 1)")->check(WholeRange(0, kMaxSeed));
  g->add_option("-o,--output", gen->output, "output file, .glb or .gltf")->required()->check(OutputPath());
  g->callback([gen, done] { done(Generate(*gen)); });

  auto imp = std::make_shared<ImportArgs>();
  CLI::App* o = scene->add_subcommand("import-osm", "import OpenStreetMap buildings (.osm or .osm.pbf) into a scene");
  o->add_option("IN", imp->input, "OpenStreetMap file: .osm (XML), .osm.pbf, .osm.bz2 or .osm.gz")->required();
  o->add_option("-o,--output", imp->output, "output file, .glb or .gltf")->required()->check(OutputPath());
  o->add_option("--bbox", imp->bbox, "keep buildings inside MIN_LON,MIN_LAT,MAX_LON,MAX_LAT (degrees)");
  o->add_option("--storey", imp->storey_m, "storey height in metres (levels to heights)")->check(FiniteRange(1.0, 20.0));
  o->add_option("--max-height", imp->max_height_m,
                "plausible limit in metres: taller height or levels tags are bad data (counted; the next rule is used)")
      ->check(FiniteRange(10.0, 10000.0));
  o->add_option("--name", imp->name, "the scene's name (default: the file name up to its first dot)");
  o->add_flag("--json", imp->json, "print the summary as one JSON object");
  o->callback([imp, done] { done(ImportOsm(*imp)); });

  auto info = std::make_shared<InfoArgs>();
  CLI::App* i = scene->add_subcommand("info", "print a scene's statistics");
  i->add_option("FILE", info->file, ".glb/.gltf file, catalog name or catalog .json")->required();
  i->add_flag("--json", info->json, "print one JSON object");
  i->add_option("--leaf-size", info->leaf_size, "kd-tree leaf size")->check(WholeRange(1, 1024));
  i->callback([info, done] { done(Info(*info)); });

  auto map = std::make_shared<MapArgs>();
  CLI::App* m = scene->add_subcommand("map", "write a top-view PNG: footprints by height, walk paths in red");
  m->add_option("FILE", map->file, ".glb/.gltf file, catalog name or catalog .json")->required();
  m->add_option("-o,--output", map->output, "output .png")->required()->check(OutputPath());
  m->add_option("--size", map->size, "pixels on the longer side")->check(WholeRange(16, 16384));
  m->callback([map, done] { done(Map(*map)); });
}

}  // namespace vistream::tools
