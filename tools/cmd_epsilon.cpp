// vistream epsilon: the ε-superset of one small neighbourhood (Cohen-Or & Zadicario 1998).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <string_view>
#include <vector>

#include <CLI/CLI.hpp>
#include <absl/strings/str_format.h>
#include <absl/strings/str_split.h>
#include <nlohmann/json.hpp>

#include "cli/number_options.h"
#include "tools/cli_common.h"
#include "tools/commands.h"
#include "tools/top_view_map.h"
#include "scenes/progress.h"
#include "visibility/epsilon_superset.h"

namespace vistream::tools {

namespace {

struct EpsilonArgs {
  std::string scene, at, opt = "all", map;
  double size = 0.0;
  bool json = false;
};

int Epsilon(const EpsilonArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  const std::vector<std::string> parts = absl::StrSplit(a.at, ',');
  double xyz[3] = {0, 0, 0};
  bool ok = parts.size() == 3;
  for (size_t k = 0; ok && k < 3; ++k) ok = cli::internal::ParseFinite(parts[k], &xyz[k]);
  if (!ok) return BadOption("epsilon", "--at", "'" + a.at + "': expected X,Y,Z (three finite numbers, metres)");
  const double x = xyz[0], y = xyz[1], z = xyz[2];
  absl::StatusOr<visibility::EpsilonOptions> options = visibility::EpsilonOptions::FromName(a.opt);
  if (!options.ok()) return BadOption("epsilon", "--opt", std::string(options.status().message()));

  double load_s = 0.0;
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene, &load_s);
  if (!scene.ok()) return Fail(scene.status());
  const scenes::Aabb& bounds = scene->bounds;
  // The box must reach the ground or above it (what lies below is cut off: viewers stand on the
  // ground), and stay within a kilometre above the tallest building.
  const double h = 0.5 * a.size;
  const double top = std::max(bounds.max.z, 0.0) + 1000.0;
  if (x < bounds.min.x || x > bounds.max.x || y < bounds.min.y || y > bounds.max.y || z + h < 0.0 || z > top) {
    return Fail(absl::OutOfRangeError(absl::StrFormat(
        "--at %s: outside the scene (x %.1f to %.1f, y %.1f to %.1f, z from %.1f (the box reaching the "
        "ground) to %.1f; scene-local metres)",
        a.at, bounds.min.x, bounds.max.x, bounds.min.y, bounds.max.y, -h, top)));
  }
  const scenes::Aabb box{glm::dvec3(x - h, y - h, z - h), glm::dvec3(x + h, y + h, z + h)};

  auto t0 = std::chrono::steady_clock::now();
  absl::StatusOr<std::unique_ptr<visibility::EpsilonSuperset>> eps = visibility::EpsilonSuperset::Create(*scene);
  if (!eps.ok()) return Fail(eps.status());
  const double setup_ms = 1000.0 * SecondsSince(t0);
  const visibility::EpsilonResult r = (*eps)->Compute(box, *options);
  const visibility::EpsilonStats& s = r.stats;

  if (!a.map.empty()) {
    TopViewMap map(scene->bounds, 2048, Rgb{250, 250, 250});
    // The neighbourhood is far smaller than a pixel on a city map: draw it at least 9 px wide.
    const double r_m = std::max(h, 4.5 * map.metres_per_pixel());
    const std::vector<glm::dvec2> square = {{x - r_m, y - r_m}, {x + r_m, y - r_m}, {x + r_m, y + r_m}, {x - r_m, y + r_m}};
    DrawVisibleSet(*scene, r.objects, square,
                   {absl::StrFormat("the neighbourhood (%g m box)", a.size), "building with triangles in the superset",
                    "building hidden from the whole box"},
                   &map);
    map.SetTitle(absl::StrFormat("%s: \u03b5-superset of a %g m box at (%.1f, %.1f, %.1f) m (optimisations: %s)",
                                 scene->name, a.size, x, y, z, a.opt),
                 absl::StrFormat("%llu of %llu triangles left (%zu of %zu objects keep some); the box drawn at least "
                                 "9 pixels wide",
                                 static_cast<unsigned long long>(s.visible_triangles),
                                 static_cast<unsigned long long>(s.total_triangles), r.objects.size(),
                                 scene->objects.size()));
    if (absl::Status st = map.WritePng(a.map); !st.ok()) return Fail(st);
  }

  if (a.json) {
    nlohmann::json j;
    j["scene"] = scene->name;
    j["at"] = {x, y, z};
    j["size"] = a.size;
    j["opt"] = a.opt;
    j["visible_triangles"] = s.visible_triangles;
    j["total_triangles"] = s.total_triangles;
    j["visible_objects"] = r.objects.size();
    j["total_objects"] = scene->objects.size();
    j["occluded_boxes"] = s.occluded_boxes;
    j["total_boxes"] = s.total_boxes;
    j["first_occluders"] = s.first_occluders;
    j["ms"] = s.ms;
    j["box_ms"] = s.box_ms;
    j["polygon_ms"] = s.polygon_ms;
    j["rays"] = s.rays;
    j["skipped_rays"] = s.skipped_rays;
    j["traversals"] = s.traversals;
    j["box_ray_tests"] = s.box_ray_tests;
    j["polygon_ray_tests"] = s.polygon_ray_tests;
    j["prisms"] = (*eps)->prism_count();
    j["setup_ms"] = setup_ms;
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("neighbourhood: %.2f m box centred at (%.2f, %.2f, %.2f), optimisations: %s\n", a.size, x, y, z,
              a.opt.c_str());
  std::printf("superset: %llu of %llu triangles (%.2f%%), %zu of %zu objects\n",
              static_cast<unsigned long long>(s.visible_triangles), static_cast<unsigned long long>(s.total_triangles),
              s.total_triangles ? 100.0 * static_cast<double>(s.visible_triangles) / static_cast<double>(s.total_triangles)
                                : 0.0,
              r.objects.size(), scene->objects.size());
  if (options->boxes) {
    std::printf("boxes: %llu of %llu occluded (%llu by the first occluder met)\n",
                static_cast<unsigned long long>(s.occluded_boxes), static_cast<unsigned long long>(s.total_boxes),
                static_cast<unsigned long long>(s.first_occluders));
  }
  std::printf("time: %.2f ms (boxes %.2f, triangles %.2f); %llu rays, %llu traversals, %llu + %llu ray/prism tests\n",
              s.ms, s.box_ms, s.polygon_ms, static_cast<unsigned long long>(s.rays),
              static_cast<unsigned long long>(s.traversals), static_cast<unsigned long long>(s.box_ray_tests),
              static_cast<unsigned long long>(s.polygon_ray_tests));
  std::printf("set-up: %zu convex prisms, %.1f ms (once per scene)\n", (*eps)->prism_count(), setup_ms);
  if (!a.map.empty()) std::printf("map: %s\n", a.map.c_str());
  return 0;
}

}  // namespace

void AddEpsilonCommand(CLI::App& app, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<EpsilonArgs>(
      &app, "epsilon", "ε-superset: triangles visible from a small box (Cohen-Or & Zadicario)",
      Epsilon, done);
  c->add_option("--scene", args->scene, ".glb/.gltf file or catalog name")->required();
  c->add_option("--at", args->at, "centre of the neighbourhood X,Y,Z (scene-local metres)")->required();
  c->add_option("--size", args->size, "edge of the neighbourhood box in metres (0: one viewpoint)")
      ->required()
      ->check(FiniteRange(0.0, 1e5));
  c->add_option("--opt", args->opt, "optimisations (Table 2's columns): none | boxes | occluders | rays | paper | all")
      ->capture_default_str()
      ->check(CLI::IsMember({"none", "boxes", "occluders", "rays", "paper", "all"}));
  c->add_flag("--json", args->json, "print one JSON object");
  c->add_option("--map", args->map, "write a top view: neighbourhood green, visible objects blue, hidden red")
      ->check(OutputPath());
}

}  // namespace vistream::tools
