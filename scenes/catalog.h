#pragma once
// The scene catalog: scenes/*.json, one scene each. A file names the scene's source, its
// viewcell grid, walk paths, and only those simulation effects the scene needs. Parsing is
// strict: unknown keys, wrong types and out-of-range values are errors that name the file,
// the key and the problem.

#include <atomic>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>

#include "scenes/osm_import.h"
#include "scenes/scene.h"

namespace vistream::scenes {

struct SceneSource {
  enum class Kind { kGenerator, kGltf, kOsm };
  Kind kind = Kind::kGenerator;
  std::string generator;  // kGenerator: city1, city2, london, streets
  uint64_t seed = 1;
  double width_m = 0.0;  // 0: generator default
  double depth_m = 0.0;
  std::string path;  // kGltf, kOsm: absolute, resolved against the catalog file's folder
  std::optional<GeoBox> bbox;  // kOsm: keep only buildings inside
  double storey_m = 3.0;       // kOsm
};

struct ViewcellSpec {
  double size_m = 100.0;   // edge of the square cell
  double height_m = 2.0;   // height of the eye-level band
  double base_m = 0.5;     // bottom of the band above the ground
};

struct WalkPath {
  std::string name;
  double speed_mps = 1.4;
  double eye_height_m = 1.7;
  std::vector<glm::dvec2> waypoints;  // scene-local metres
};

// Each effect is modelled only when its key is present.
struct LinkSpec {
  std::optional<double> bandwidth_mbps, latency_ms, jitter_ms, loss_pct;
};
struct ClientSpec {
  std::optional<double> memory_mb;
  std::optional<uint64_t> triangle_budget;
};
struct SimulationSpec {
  std::optional<LinkSpec> link;
  std::optional<ClientSpec> client;
};

struct CatalogEntry {
  std::string file;  // where it was read from
  std::string name;
  std::string description;
  SceneSource source;
  ViewcellSpec viewcell;
  std::vector<WalkPath> walks;
  SimulationSpec simulation;
};

// Parses a catalog entry. `file` names it in errors; relative source paths resolve against
// `base_dir`.
absl::StatusOr<CatalogEntry> ParseCatalogEntry(std::string_view json_text, const std::string& file,
                                               const std::string& base_dir);
absl::StatusOr<CatalogEntry> LoadCatalogEntry(const std::string& path);

// The catalog folder: $VISTREAM_SCENES if set, else the source tree's scenes/.
std::string CatalogDir();
// `name_or_path`: a catalog name (london) or a path to a .json file.
absl::StatusOr<CatalogEntry> FindCatalogEntry(std::string_view name_or_path);
// Names of every entry in CatalogDir(), sorted.
std::vector<std::string> CatalogNames();

// Generates or loads the entry's scene. Generated scenes take the entry's name.
absl::StatusOr<Scene> BuildScene(const CatalogEntry& entry, const std::atomic<bool>* cancel = nullptr,
                                 std::vector<std::string>* warnings = nullptr);

}  // namespace vistream::scenes
