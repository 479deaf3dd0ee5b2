#include "scenes/catalog.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <initializer_list>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_join.h>
#include <nlohmann/json.hpp>

#include "scenes/city_generator.h"
#include "scenes/city_import.h"
#include "scenes/gltf_io.h"

namespace vistream::scenes {

namespace {

namespace fs = std::filesystem;
using Json = nlohmann::json;

struct CatalogError {
  std::string message;
};

// Strict reading of one JSON object: every key is consumed or reported unknown.
class Reader {
 public:
  Reader(const Json& j, std::string path, const std::string& file) : j_(j), path_(std::move(path)), file_(file) {
    if (!j_.is_object()) Fail(path_.empty() ? "the top level" : Key(""), "expected an object");
  }

  void Allow(std::initializer_list<const char*> keys) const {
    for (const auto& item : j_.items()) {
      const std::string& k = item.key();
      if (std::none_of(keys.begin(), keys.end(), [&k](const char* a) { return k == a; })) {
        Fail(Key(k), absl::StrCat("unknown key (allowed: ", absl::StrJoin(keys, ", "), ")"));
      }
    }
  }
  bool Has(const std::string& k) const { return j_.contains(k); }

  std::string String(const std::string& k, std::optional<std::string> fallback = std::nullopt) const {
    if (!Has(k)) return Required(k, fallback);
    const Json& v = j_.at(k);
    if (!v.is_string()) Fail(Key(k), absl::StrCat("expected a string, got ", v.dump()));
    return v.get<std::string>();
  }
  double Number(const std::string& k, double lo, double hi, std::optional<double> fallback = std::nullopt,
                bool lo_open = false) const {
    if (!Has(k)) return Required(k, fallback);
    const Json& v = j_.at(k);
    if (!v.is_number()) Fail(Key(k), absl::StrCat("expected a number, got ", v.dump()));
    const double x = v.get<double>();
    if (!std::isfinite(x) || x < lo || x > hi || (lo_open && x == lo)) {
      Fail(Key(k), absl::StrCat("expected a number in ", lo_open ? "(" : "[", lo, ", ", hi, "], got ", v.dump()));
    }
    return x;
  }
  uint64_t Unsigned(const std::string& k, std::optional<uint64_t> fallback = std::nullopt) const {
    if (!Has(k)) return Required(k, fallback);
    const Json& v = j_.at(k);
    if (!v.is_number_unsigned()) Fail(Key(k), absl::StrCat("expected a non-negative integer, got ", v.dump()));
    return v.get<uint64_t>();
  }
  Reader Object(const std::string& k) const {
    if (!Has(k)) Fail(Key(k), "missing");
    return Reader(j_.at(k), Key(k), file_);
  }
  const Json& Array(const std::string& k) const {
    if (!Has(k)) Fail(Key(k), "missing");
    const Json& v = j_.at(k);
    if (!v.is_array()) Fail(Key(k), absl::StrCat("expected an array, got ", v.dump()));
    return v;
  }
  std::string Key(const std::string& k) const {
    if (path_.empty()) return std::string(k);
    return k.empty() ? path_ : absl::StrCat(path_, ".", k);
  }
  [[noreturn]] void Fail(const std::string& key, const std::string& problem) const {
    throw CatalogError{absl::StrCat(file_, ": key '", key, "': ", problem)};
  }
  const std::string& file() const { return file_; }

 private:
  template <typename T>
  T Required(const std::string& k, const std::optional<T>& fallback) const {
    if (!fallback) Fail(Key(k), "missing");
    return *fallback;
  }
  const Json& j_;
  std::string path_;
  const std::string& file_;
};

SceneSource ReadSource(const Reader& r, const std::string& base_dir) {
  SceneSource s;
  if (int{r.Has("generator")} + int{r.Has("gltf")} + int{r.Has("osm")} + int{r.Has("city")} != 1) {
    r.Fail(r.Key(""), "needs exactly one of 'generator', 'gltf', 'osm' or 'city'");
  }
  if (r.Has("generator")) {
    s.kind = SceneSource::Kind::kGenerator;
    s.generator = r.String("generator");
    if (s.generator != "city1" && s.generator != "city2" && s.generator != "london" && s.generator != "streets") {
      r.Fail(r.Key("generator"),
             absl::StrCat("unknown generator '", s.generator, "' (known: city1, city2, london, streets)"));
    }
    if (s.generator == "london") {
      r.Allow({"generator", "seed", "width_m", "depth_m"});
      s.width_m = r.Number("width_m", 200.0, 100000.0, 0.0);
      s.depth_m = r.Number("depth_m", 200.0, 100000.0, 0.0);
    } else if (s.generator == "streets") {
      r.Allow({"generator", "seed", "width_m", "depth_m"});
      s.width_m = r.Number("width_m", 100.0, 5000.0, 0.0);
      s.depth_m = r.Number("depth_m", 100.0, 5000.0, 0.0);
    } else {
      r.Allow({"generator", "seed"});
    }
    s.seed = r.Unsigned("seed", 1);
  } else if (r.Has("gltf")) {
    r.Allow({"gltf", "occluders"});
    s.kind = SceneSource::Kind::kGltf;
    const fs::path p(r.String("gltf"));
    s.path = (p.is_absolute() ? p : fs::path(base_dir) / p).lexically_normal().string();
    if (r.Has("occluders")) {
      const std::string how = r.String("occluders");
      if (how != "synthesize" && how != "file") {
        r.Fail(r.Key("occluders"), absl::StrCat("'", how, "' is not 'file' (the file's own) or 'synthesize' (from closed meshes)"));
      }
      s.synthesize_occluders = how == "synthesize";
    }
  } else if (r.Has("city")) {
    r.Allow({"city", "lod", "crs", "ground"});
    if (r.Has("crs")) s.city.crs = r.String("crs");
    if (r.Has("ground")) {
      const std::string ground = r.String("ground");
      if (ground != "derived" && ground != "none") {
        r.Fail(r.Key("ground"), absl::StrCat("'", ground, "' is not 'derived' (a terrain from the data where the file has none) or 'none' (flat ground)"));
      }
      s.city.ground = ground == "none" ? CityGround::kNone : CityGround::kDerived;
    }
    s.kind = SceneSource::Kind::kCity;
    const fs::path p(r.String("city"));
    s.path = (p.is_absolute() ? p : fs::path(base_dir) / p).lexically_normal().string();
    if (!IsCityModelPath(s.path)) {
      r.Fail(r.Key("city"), "not a city model file name (CityGML: .gml or .xml; CityJSON: .json or .city.json)");
    }
    if (r.Has("lod")) {
      const double lod = r.Number("lod", 0.0, 4.0);
      if (lod != std::floor(lod)) r.Fail(r.Key("lod"), "a level of detail is a whole number (0 to 4)");
      s.city.lod = static_cast<int>(lod);
    }
  } else {
    r.Allow({"osm", "bbox", "storey_m", "max_height_m"});
    s.kind = SceneSource::Kind::kOsm;
    const fs::path p(r.String("osm"));
    s.path = (p.is_absolute() ? p : fs::path(base_dir) / p).lexically_normal().string();
    if (r.Has("bbox")) {
      absl::StatusOr<GeoBox> box = ParseGeoBox(r.String("bbox"));
      if (!box.ok()) r.Fail(r.Key("bbox"), std::string(box.status().message()));
      s.osm.bbox = *box;
    }
    s.osm.storey_m = r.Number("storey_m", 1.0, 20.0, 3.0);
    s.osm.max_height_m = r.Number("max_height_m", 10.0, 10000.0, OsmImportOptions{}.max_height_m);
  }
  return s;
}

std::vector<WalkPath> ReadWalks(const Reader& r) {
  std::vector<WalkPath> walks;
  if (!r.Has("walks")) return walks;
  const Json& list = r.Array("walks");
  for (size_t i = 0; i < list.size(); ++i) {
    Reader w(list[i], absl::StrCat(r.Key("walks"), "[", i, "]"), r.file());
    w.Allow({"name", "speed_mps", "eye_height_m", "waypoints"});
    WalkPath path;
    path.name = w.String("name");
    path.speed_mps = w.Number("speed_mps", 0.0, 100.0, 1.4, /*lo_open=*/true);
    path.eye_height_m = w.Number("eye_height_m", 0.0, 1000.0, 1.7);
    const Json& pts = w.Array("waypoints");
    if (pts.size() < 2) w.Fail(w.Key("waypoints"), absl::StrCat("needs at least 2 waypoints, got ", pts.size()));
    for (size_t k = 0; k < pts.size(); ++k) {
      const Json& p = pts[k];
      if (!p.is_array() || p.size() != 2 || !p[0].is_number() || !p[1].is_number() ||
          !std::isfinite(p[0].get<double>()) || !std::isfinite(p[1].get<double>())) {
        w.Fail(absl::StrCat(w.Key("waypoints"), "[", k, "]"), absl::StrCat("expected [x, y] in metres, got ", p.dump()));
      }
      path.waypoints.emplace_back(p[0].get<double>(), p[1].get<double>());
    }
    walks.push_back(std::move(path));
  }
  return walks;
}

SimulationSpec ReadSimulation(const Reader& r) {
  SimulationSpec sim;
  if (!r.Has("simulation")) return sim;
  const Reader s = r.Object("simulation");
  s.Allow({"link", "client"});
  if (s.Has("link")) {
    const Reader l = s.Object("link");
    l.Allow({"bandwidth_mbps", "latency_ms", "jitter_ms", "loss_pct"});
    LinkSpec link;
    if (l.Has("bandwidth_mbps")) link.bandwidth_mbps = l.Number("bandwidth_mbps", 0.0, 1e6, {}, true);
    if (l.Has("latency_ms")) link.latency_ms = l.Number("latency_ms", 0.0, 1e5);
    if (l.Has("jitter_ms")) link.jitter_ms = l.Number("jitter_ms", 0.0, 1e5);
    if (l.Has("loss_pct")) link.loss_pct = l.Number("loss_pct", 0.0, 100.0);
    sim.link = link;
  }
  if (s.Has("client")) {
    const Reader c = s.Object("client");
    c.Allow({"memory_mb", "triangle_budget", "frame_ms"});
    ClientSpec client;
    if (c.Has("memory_mb")) client.memory_mb = c.Number("memory_mb", 0.0, 1e7, {}, true);
    if (c.Has("triangle_budget")) client.triangle_budget = c.Unsigned("triangle_budget");
    if (c.Has("frame_ms")) client.frame_ms = c.Number("frame_ms", 1.0, 1000.0);
    sim.client = client;
  }
  return sim;
}

}  // namespace

absl::StatusOr<CatalogEntry> ParseCatalogEntry(std::string_view json_text, const std::string& file,
                                               const std::string& base_dir) {
  Json j;
  try {
    j = Json::parse(json_text.begin(), json_text.end());
  } catch (const Json::parse_error& e) {
    // Line and column of the byte the parser stopped at.
    const size_t at = std::min<size_t>(e.byte == 0 ? 0 : e.byte - 1, json_text.size());
    const auto line = 1 + std::count(json_text.begin(), json_text.begin() + static_cast<long>(at), '\n');
    const size_t nl = json_text.rfind('\n', at == 0 ? 0 : at - 1);
    const size_t col = nl == std::string_view::npos ? at + 1 : at - nl;
    return absl::InvalidArgumentError(absl::StrCat(file, ":", static_cast<int64_t>(line), ":", col, ": malformed JSON: ", e.what()));
  } catch (const Json::exception& e) {  // e.g. out_of_range for a number like 1e999
    return absl::InvalidArgumentError(absl::StrCat(file, ": malformed JSON: ", e.what()));
  }
  try {
    const Reader r(j, "", file);
    r.Allow({"name", "description", "source", "viewcell", "walks", "simulation", "effects"});
    CatalogEntry e;
    e.file = file;
    e.name = r.String("name");
    if (e.name.empty()) r.Fail("name", "must not be empty");
    e.description = r.String("description", "");
    e.source = ReadSource(r.Object("source"), base_dir);
    const Reader v = r.Object("viewcell");
    v.Allow({"size_m", "height_m", "base_m", "epsilon_m"});
    e.viewcell.size_m = v.Number("size_m", 0.0, 100000.0, {}, true);
    e.viewcell.height_m = v.Number("height_m", 0.0, 10000.0, {}, true);
    e.viewcell.base_m = v.Number("base_m", -1000.0, 10000.0, 0.5);
    e.viewcell.epsilon_m = v.Number("epsilon_m", 0.0, 1000.0, 4.0, true);
    e.walks = ReadWalks(r);
    e.simulation = ReadSimulation(r);
    if (r.Has("effects")) {
      const Reader fx = r.Object("effects");
      fx.Allow({"fog"});
      if (fx.Has("fog")) {
        const Reader f = fx.Object("fog");
        f.Allow({"start_m", "end_m"});
        FogSpec fog;
        fog.start_m = f.Number("start_m", 0.0, 1e6);
        fog.end_m = f.Number("end_m", 0.0, 1e6, {}, true);
        if (fog.end_m <= fog.start_m) {
          f.Fail(f.Key("end_m"), absl::StrCat("must be beyond start_m (", fog.start_m, "), got ", fog.end_m));
        }
        e.effects.fog = fog;
      }
    }
    return e;
  } catch (const CatalogError& err) {
    return absl::InvalidArgumentError(err.message);
  } catch (const Json::exception& err) {  // e.g. a number too large for its type
    return absl::InvalidArgumentError(absl::StrCat(file, ": ", err.what()));
  }
}

absl::StatusOr<CatalogEntry> LoadCatalogEntry(const std::string& path) {
  // A directory opens as a stream on Linux and then throws on its first read.
  std::error_code ec;
  if (fs::is_directory(path, ec)) return absl::InvalidArgumentError(absl::StrCat(path, ": is a directory, not a catalog file"));
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open catalog file"));
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return ParseCatalogEntry(text, path, fs::path(path).parent_path().string());
}

std::string CatalogDirFrom(const char* env, const fs::path& exe, const std::string& source_scenes) {
  if (env != nullptr && *env != '\0') return env;
  // Installed first: a program installed on the machine that built it (cmake --install, or the
  // package) must read the catalog it was installed with, not the source tree it came from.
  if (!exe.empty()) {
    const fs::path installed = (exe.parent_path() / ".." / "share" / "vistream" / "scenes").lexically_normal();
    std::error_code ec;
    if (fs::is_directory(installed, ec)) return installed.string();
  }
  return source_scenes;
}

std::string CatalogDir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return CatalogDirFrom(std::getenv("VISTREAM_SCENES"), ec ? fs::path() : exe, std::string(VISTREAM_SOURCE_DIR "/scenes"));
}

absl::StatusOr<CatalogEntry> FindCatalogEntry(std::string_view name_or_path, const std::string& catalog_dir) {
  const std::string s(name_or_path);
  if (s.ends_with(".json") || s.find('/') != std::string::npos) return LoadCatalogEntry(s);
  const std::string dir = catalog_dir.empty() ? CatalogDir() : catalog_dir;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return absl::NotFoundError(absl::StrCat("no scene '", s, "': the catalog folder ", dir, " does not exist"));
  }
  const std::string path = dir + "/" + s + ".json";
  if (s.empty() || !fs::exists(path)) {
    return absl::NotFoundError(absl::StrCat("no scene '", s, "' in the catalog ", dir,
                                            " (known: ", absl::StrJoin(CatalogNames(dir), ", "), ")"));
  }
  return LoadCatalogEntry(path);
}

std::vector<std::string> CatalogNames(const std::string& catalog_dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(catalog_dir.empty() ? CatalogDir() : catalog_dir, ec)) {
    if (e.path().extension() == ".json") names.push_back(e.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

absl::StatusOr<Scene> BuildScene(const CatalogEntry& entry, const RunControl& run,
                                 std::vector<std::string>* warnings) {
  if (entry.source.kind == SceneSource::Kind::kGltf) {
    absl::StatusOr<Scene> scene = LoadGltf(entry.source.path, warnings);
    if (scene.ok() && entry.source.synthesize_occluders) AddSynthesizedOccluders(&*scene, /*replace=*/true, {}, run);
    if (scene.ok() && run.Cancelled()) return absl::CancelledError(absl::StrCat(entry.file, ": cancelled"));
    return scene;
  }
  if (entry.source.kind == SceneSource::Kind::kCity) {
    CityImportOptions options = entry.source.city;
    options.name = entry.name;
    return ImportCity(entry.source.path, options, nullptr, run);
  }
  if (entry.source.kind == SceneSource::Kind::kOsm) {
    OsmImportOptions options = entry.source.osm;
    options.name = entry.name;
    return ImportOsm(entry.source.path, options, nullptr, run);
  }
  GeneratorParams params;
  params.seed = entry.source.seed;
  params.width_m = entry.source.width_m;
  params.depth_m = entry.source.depth_m;
  absl::StatusOr<Scene> scene = GenerateNamed(entry.source.generator, params, run);
  if (!scene.ok()) return absl::Status(scene.status().code(), absl::StrCat(entry.file, ": ", scene.status().message()));
  scene->name = entry.name;
  return scene;
}

bool IsGltfPath(std::string_view path) {
  const std::string ext = fs::path(path).extension().string();
  return ext == ".glb" || ext == ".gltf";
}

std::vector<WalkPath> WalksWithScenePaths(const std::vector<WalkPath>& declared, const Scene& scene,
                                          double speed_mps, double eye_height_m) {
  std::vector<WalkPath> walks = declared;
  for (const ScenePath& p : scene.paths) {
    if (std::any_of(walks.begin(), walks.end(), [&](const WalkPath& w) { return w.name == p.name; })) continue;
    WalkPath w;
    w.name = p.name;
    w.speed_mps = speed_mps;
    w.eye_height_m = eye_height_m;
    w.waypoints = p.waypoints;
    walks.push_back(std::move(w));
  }
  return walks;
}

void AddDeclaredWalks(const std::vector<WalkPath>& declared, Scene* scene) {
  std::vector<ScenePath> paths;
  for (const WalkPath& w : declared) {
    if (w.waypoints.size() >= 2) paths.push_back({w.name, w.waypoints});
  }
  for (ScenePath& p : scene->paths) {
    if (std::none_of(declared.begin(), declared.end(), [&](const WalkPath& w) { return w.name == p.name; })) {
      paths.push_back(std::move(p));
    }
  }
  scene->paths = std::move(paths);
}

absl::StatusOr<LoadedScene> LoadScene(std::string_view name_or_path, const LoadOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  LoadedScene out;
  if (IsGltfPath(name_or_path)) {
    absl::StatusOr<Scene> scene = LoadGltf(std::string(name_or_path), &out.warnings);
    if (!scene.ok()) return scene.status();
    out.scene = *std::move(scene);
  } else {
    absl::StatusOr<CatalogEntry> entry = FindCatalogEntry(name_or_path, options.catalog_dir);
    if (!entry.ok()) return entry.status();
    absl::StatusOr<Scene> scene = BuildScene(*entry, options.run, &out.warnings);
    if (!scene.ok()) return scene.status();
    out.scene = *std::move(scene);
    out.viewcell = entry->viewcell;
    out.entry = *std::move(entry);
  }
  const std::vector<WalkPath> none;
  const std::vector<WalkPath>& declared = out.entry.has_value() ? out.entry->walks : none;
  out.walks = declared.empty() ? WalksWithScenePaths(declared, out.scene)
                               : WalksWithScenePaths(declared, out.scene, declared.front().speed_mps,
                                                     declared.front().eye_height_m);
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

ViewcellSpec ViewcellSpecFor(std::string_view name_or_path, double cell_size, const std::string& catalog_dir) {
  ViewcellSpec spec;
  if (!IsGltfPath(name_or_path)) {
    if (auto entry = FindCatalogEntry(name_or_path, catalog_dir); entry.ok()) spec = entry->viewcell;
  }
  if (cell_size > 0.0) spec.size_m = cell_size;
  return spec;
}

}  // namespace vistream::scenes
