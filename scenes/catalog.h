#pragma once
// The scene catalog: scenes/*.json, one scene each. A file names the scene's source, its
// viewcell grid, walk paths, and only those simulation effects the scene needs. Parsing is
// strict: unknown keys, wrong types and out-of-range values are errors that name the file,
// the key and the problem.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>

#include "scenes/city_import.h"
#include "scenes/osm_import.h"
#include "scenes/scene.h"

namespace vistream::scenes {

struct SceneSource {
  enum class Kind { kGenerator, kGltf, kOsm, kCity };
  Kind kind = Kind::kGenerator;
  std::string generator;  // kGenerator: city1, city2, london, streets
  uint64_t seed = 1;
  double width_m = 0.0;  // 0: generator default
  double depth_m = 0.0;
  std::string path;  // kGltf, kOsm, kCity: absolute, resolved against the catalog file's folder
  // kOsm: the import's options the entry sets ("bbox", "storey_m", "max_height_m"); the rest
  // are OsmImportOptions' defaults, and BuildScene names the scene after the entry.
  OsmImportOptions osm;
  // kCity: the import's options the entry sets ("lod": the LoD to draw, none: each object's
  // highest; "crs": the CRS when the file names none; "ground": "derived", the default, or
  // "none", for a file without a TIN); the rest are CityImportOptions' defaults.
  CityImportOptions city;
  bool synthesize_occluders = false;  // kGltf ("occluders": "synthesize"): occluders from closed meshes
};

struct ViewcellSpec {
  double size_m = 100.0;   // edge of the square cell
  double height_m = 2.0;   // height of the eye-level band
  double base_m = 0.5;     // bottom of the band above the ground
  // Edge of the neighbourhood a server computes an ε-mask for once a client lingers in it.
  double epsilon_m = 4.0;
};

struct WalkPath {
  std::string name;
  double speed_mps = 1.4;
  double eye_height_m = 1.7;
  std::vector<glm::dvec2> waypoints;  // scene-local metres
};

// The walks of a scene: `declared` (a catalog entry's, in order) followed by the scene's own
// (Scene::paths, e.g. derived from an OSM import's streets) whose names `declared` does not
// already use, at `speed_mps` and `eye_height_m`.
std::vector<WalkPath> WalksWithScenePaths(const std::vector<WalkPath>& declared, const Scene& scene,
                                          double speed_mps = 1.4, double eye_height_m = 1.7);

// Puts `declared` (a catalog entry's walks, in order) first among `scene`'s own paths, which keep
// their order after them but for those whose names `declared` uses: what a scene saved to a file
// carries, so that its walks outlive the catalog (a generated city saved to .glb). Walks of
// fewer than 2 waypoints are left out.
void AddDeclaredWalks(const std::vector<WalkPath>& declared, Scene* scene);

// Each effect is modelled only when its key is present (server/link_model.h says how).
struct LinkSpec {
  std::optional<double> bandwidth_mbps;  // megabits (10^6) per second, > 0
  std::optional<double> latency_ms;      // one-way delay
  std::optional<double> jitter_ms;       // mean extra delay per message
  std::optional<double> loss_pct;        // per TCP segment
};
struct ClientSpec {
  std::optional<double> memory_mb;          // decoded geometry the client may hold, MiB
  std::optional<uint64_t> triangle_budget;  // triangles it can draw a frame
  std::optional<double> frame_ms;           // its frame time (the simulator's frame clock)
};
struct SimulationSpec {
  std::optional<LinkSpec> link;
  std::optional<ClientSpec> client;
};

// How the client draws the scene where the scene calls for it (the catalog's "effects"): distance
// fog towards the sky colour, none below start_m from the eye, whole at end_m and beyond.
struct FogSpec {
  double start_m = 0.0, end_m = 0.0;
};
struct EffectsSpec {
  std::optional<FogSpec> fog;
};

struct CatalogEntry {
  std::string file;  // where it was read from
  std::string name;
  std::string description;
  SceneSource source;
  ViewcellSpec viewcell;
  std::vector<WalkPath> walks;
  SimulationSpec simulation;
  EffectsSpec effects;
};

// Parses a catalog entry. `file` names it in errors; relative source paths resolve against
// `base_dir`.
absl::StatusOr<CatalogEntry> ParseCatalogEntry(std::string_view json_text, const std::string& file,
                                               const std::string& base_dir);
absl::StatusOr<CatalogEntry> LoadCatalogEntry(const std::string& path);

// The default catalog folder: $VISTREAM_SCENES if set; else the installed catalog beside the
// running program (`../share/vistream/scenes` from its folder, /proc/self/exe: /usr/bin/vistream
// reads /usr/share/vistream/scenes) if that folder exists; else the source tree's scenes/ (a
// build tree's programs). The result may not exist; FindCatalogEntry says so.
std::string CatalogDir();
// The lookup CatalogDir() makes, from its inputs: `env` ($VISTREAM_SCENES; null or empty: unset),
// `exe` (the running program's path, links resolved; empty: unknown) and `source_scenes` (the
// source tree's scenes/ folder). Returns `env`, else the installed folder if it exists, else
// `source_scenes`.
std::string CatalogDirFrom(const char* env, const std::filesystem::path& exe, const std::string& source_scenes);
// `name_or_path`: a catalog name (london), looked up in `catalog_dir` (empty: CatalogDir()), or
// a path to a .json file. Errors: NOT_FOUND naming the folder and its entries.
absl::StatusOr<CatalogEntry> FindCatalogEntry(std::string_view name_or_path, const std::string& catalog_dir = "");
// Names of every entry in `catalog_dir` (empty: CatalogDir()), sorted.
std::vector<std::string> CatalogNames(const std::string& catalog_dir = "");

// Generates or loads the entry's scene. Generated scenes take the entry's name.
absl::StatusOr<Scene> BuildScene(const CatalogEntry& entry, const RunControl& run = {},
                                 std::vector<std::string>* warnings = nullptr);

// Whether `path` names a glTF file (.glb or .gltf) rather than a catalog name or entry.
bool IsGltfPath(std::string_view path);

struct LoadOptions {
  std::string catalog_dir;  // where catalog names are looked up; empty: CatalogDir()
  RunControl run;           // progress and cancel for generating or importing
};

// A scene ready to use: the scene and its viewcell band, and the catalog entry it came from.
struct LoadedScene {
  Scene scene;
  ViewcellSpec viewcell;                // the entry's; for glTF files the defaults
  std::optional<CatalogEntry> entry;    // none for glTF files; its walks as the file declares them
  // Every walk of the scene: the entry's, then the scene's own paths (WalksWithScenePaths; at
  // the speed and eye height of the entry's first walk, else 1.4 m/s and 1.7 m).
  std::vector<WalkPath> walks;
  std::vector<std::string> warnings;    // what loading a glTF file skipped, for the caller to show
  double seconds = 0.0;                 // wall time spent loading
};

// The one call that turns a user's scene argument into a scene: a .glb/.gltf file, a catalog
// name (looked up in options.catalog_dir) or a catalog .json path. Errors name the argument:
// NOT_FOUND for an unknown name or missing file, INVALID_ARGUMENT for a malformed one,
// CANCELLED when options.run's flag was raised.
absl::StatusOr<LoadedScene> LoadScene(std::string_view name_or_path, const LoadOptions& options = {});

// The viewcell band for `name_or_path` (the catalog entry's; defaults for glTF files or names
// that do not resolve), with the edge replaced by `cell_size` when that is positive.
ViewcellSpec ViewcellSpecFor(std::string_view name_or_path, double cell_size, const std::string& catalog_dir = "");

}  // namespace vistream::scenes
