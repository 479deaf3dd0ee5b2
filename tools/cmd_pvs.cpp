// vistream pvs: the potentially visible set of one viewcell, or of every one (a PVS file, or
// the PVS store replicas share).
#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>

#include <unistd.h>

#include <CLI/CLI.hpp>
#include <absl/strings/numbers.h>
#include <absl/strings/str_format.h>
#include <nlohmann/json.hpp>

#include "tools/cli_common.h"
#include "tools/commands.h"
#include "gl/pvs_backend.h"
#include "tools/top_view_map.h"
#include "scenes/catalog.h"
#include "scenes/progress.h"
#include "server/pvs_store.h"
#include "server/security.h"
#include "server/server_config.h"
#include "visibility/pvs.h"
#include "visibility/pvs_file.h"
#include "visibility/viewcell_grid.h"

namespace vistream::tools {

namespace {

struct PvsArgs {
  std::string scene, cell, backend = "cpu", map, out;
  bool all = false;
  double cell_size = 0.0;
  uint32_t res = 128;
  int map_size = 2048;
  bool json = false;
  std::string store, store_prefix = "vistream", shard, store_password_file;
};

// "K/N" with 0 <= K < N: the shard of --all this process computes (the cells whose id is K
// modulo N, so that every shard gets a fair share of the dense centre and the empty edge).
bool ParseShard(const std::string& text, uint32_t* k, uint32_t* n) {
  const size_t slash = text.find('/');
  if (slash == std::string::npos) return false;
  uint64_t kk = 0, nn = 0;
  if (!absl::SimpleAtoi(text.substr(0, slash), &kk) || !absl::SimpleAtoi(text.substr(slash + 1), &nn)) return false;
  if (nn < 1 || nn > 100000 || kk >= nn) return false;
  *k = static_cast<uint32_t>(kk);
  *n = static_cast<uint32_t>(nn);
  return true;
}

// Every viewcell of the grid (or one shard of it), written as a PVS file the server can serve
// (--pvs-file) or into the PVS store replicas share (--store).
int PvsAll(const PvsArgs& a) {
  if (a.out.empty() && a.store.empty()) {
    return BadOption("pvs", "--all", "writes a PVS file or fills a PVS store: give -o FILE or --store ADDRESS");
  }
  if (!a.map.empty()) return BadOption("pvs", "--map", "draws one viewcell: not with --all");
  uint32_t shard = 0, shards = 1;
  if (!a.store.empty() && !server::IsStoreKeyPrefix(a.store_prefix)) {
    return BadOption("pvs", "--store-prefix", "'" + a.store_prefix + "' is not a non-empty word without spaces");
  }
  if (!a.shard.empty()) {
    if (a.store.empty()) return BadOption("pvs", "--shard", "fills part of a PVS store: give --store ADDRESS");
    if (!a.out.empty()) return BadOption("pvs", "--shard", "a PVS file holds every viewcell: not with -o");
    if (!ParseShard(a.shard, &shard, &shards)) {
      return BadOption("pvs", "--shard", "'" + a.shard + "' is not K/N with 0 <= K < N (e.g. 0/4 ... 3/4)");
    }
  }
  // Find out now, not after minutes of work, whether the file can be written.
  if (!a.out.empty()) {
    const std::filesystem::path parent = std::filesystem::absolute(a.out).parent_path();
    std::error_code ec;
    if (!std::filesystem::is_directory(parent, ec) || access(parent.c_str(), W_OK) != 0) {
      return Fail(absl::PermissionDeniedError("cannot write '" + a.out + "': " + parent.string() +
                                              " is not a writable folder"));
    }
    if (std::filesystem::is_directory(a.out, ec)) {
      return Fail(absl::InvalidArgumentError("-o " + a.out + " is a directory, not a file"));
    }
  }
  // ... and whether the store answers.
  std::unique_ptr<server::PvsStore> store;
  if (!a.store.empty()) {
    server::PvsStoreOptions so;
    so.address = a.store;
    so.key_prefix = a.store_prefix;
    so.connect_timeout_s = 5.0;
    so.read_timeout_s = 10.0;
    so.write_timeout_s = 10.0;
    if (!a.store_password_file.empty()) {
      absl::StatusOr<std::string> password = server::ReadSecretLine(a.store_password_file);
      if (!password.ok()) return BadOption("pvs", "--store-password-file", std::string(password.status().message()));
      so.password = *std::move(password);
    } else if (const char* password = std::getenv("VISTREAM_STORE_PASSWORD"); password != nullptr) {
      so.password = password;
    }
    absl::StatusOr<std::unique_ptr<server::PvsStore>> created = server::PvsStore::Create(so);
    if (!created.ok()) return BadOption("pvs", "--store", std::string(created.status().message()));
    store = std::move(*created);
    if (absl::Status st = store->Connect(); !st.ok()) return Fail(st);
  }
  InstallCancelHandler();
  const scenes::ViewcellSpec spec = scenes::ViewcellSpecFor(a.scene, a.cell_size);
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene);
  if (!scene.ok()) return Fail(scene.status());
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, spec);
  if (!grid.ok()) return Fail(grid.status());
  const auto t0 = std::chrono::steady_clock::now();
  const visibility::KdTree tree = visibility::KdTree::Build(*scene);
  const visibility::PvsComputer computer(*scene, tree);
  absl::StatusOr<gl::PvsBackend> backend = gl::PvsBackend::Create(a.backend);
  if (!backend.ok()) return Fail(backend.status());
  const visibility::CellQueryOptions options = gl::QueryOptionsFor(a.res);

  std::vector<visibility::CellId> cells;
  for (size_t c = shard; c < grid->CellCount(); c += shards) cells.push_back(static_cast<visibility::CellId>(c));
  const size_t shard_cells = cells.size();
  std::string ns;
  size_t skipped = 0;
  if (store != nullptr) {
    ns = server::PvsStoreNamespace(a.store_prefix, scenes::SceneFingerprint(*scene), *grid, a.res, a.backend);
    if (a.out.empty()) {
      // A run stopped half-way resumes: the cells already stored (and good: each entry is read
      // and checked as a server would) are not computed again; bad ones are deleted and redone.
      std::vector<visibility::CellId> missing, bad;
      std::vector<uint32_t> ignored;
      for (visibility::CellId c : cells) {
        switch (store->Get(ns, c, scene->objects.size(), &ignored)) {
          case server::PvsStore::Read::kHit: break;
          case server::PvsStore::Read::kMiss: missing.push_back(c); break;
          case server::PvsStore::Read::kBad:
            missing.push_back(c);
            bad.push_back(c);
            break;
          case server::PvsStore::Read::kUnavailable:
            if (absl::Status st = store->Connect(); !st.ok()) return Fail(st);
            return Fail(absl::UnavailableError("the PVS store at " + a.store + " stopped answering"));
        }
      }
      if (!bad.empty()) {
        if (absl::Status st = store->Delete(ns, bad); !st.ok()) return Fail(st);
        std::fprintf(stderr, "pvs: %zu stored entries failed their checks; computing them again\n", bad.size());
      }
      skipped = cells.size() - missing.size();
      cells = std::move(missing);
    }
  }
  visibility::GlobalPvs sets(a.out.empty() ? 0 : grid->CellCount(), scene->objects.size());
  double objects = 0;
  // PVS entries by the objects' type (a city model's "Building", "TINRelief", ...), against the
  // whole scene's: how much of the city a viewcell sees, buildings apart from the terrain.
  auto TypeName = [](const scenes::Object& o) { return o.type.empty() ? std::string("untyped") : o.type; };
  std::map<std::string, double> by_type;
  std::vector<std::pair<visibility::CellId, std::string>> batch;
  auto flush = [&]() -> absl::Status {
    if (batch.empty()) return absl::OkStatus();
    absl::Status st = store->Put(ns, batch);
    batch.clear();
    return st;
  };
  const std::string label = shards > 1 ? absl::StrFormat("pvs of viewcell shard %u/%u (%s)", shard, shards, a.backend)
                                       : "pvs of every viewcell (" + a.backend + ")";
  absl::Status computed = gl::ComputeViewcellPvss(
      *backend, computer, *grid, cells, options, ToolRun(), label,
      [&](visibility::CellId cell, const visibility::PvsResult& r) -> absl::Status {
        objects += static_cast<double>(r.objects.size());
        for (scenes::ObjectId id : r.objects) ++by_type[TypeName(scene->objects[id])];
        if (!a.out.empty()) sets.Assign(cell, r.objects);
        if (store == nullptr) return absl::OkStatus();
        batch.emplace_back(cell, visibility::EncodeCellRecord(cell, r.objects));
        return batch.size() >= 64 ? flush() : absl::OkStatus();
      });
  if (computed.ok() && store != nullptr) computed = flush();
  if (!computed.ok()) {
    if (absl::IsCancelled(computed)) {
      return Fail(absl::CancelledError(store != nullptr ? "pvs --all stopped; the cells stored so far stay (run it again to finish)"
                                                        : "pvs --all stopped; nothing written"));
    }
    return Fail(computed);
  }
  visibility::PvsProvenance provenance;
  provenance.strategy = absl::StrFormat("dual-ray-space %s %u^2", a.backend, a.res);
  provenance.seconds = SecondsSince(t0);
  if (!a.out.empty()) {
    if (absl::Status st = WriteFile(a.out, visibility::EncodePvsFile(visibility::MakePvsFile(*scene, *grid, sets, provenance)));
        !st.ok()) {
      return Fail(st);
    }
  }
  const double mean = cells.empty() ? 0.0 : objects / static_cast<double>(cells.size());
  if (a.json) {
    nlohmann::json j;
    j["scene"] = scene->name;
    j["cells"] = grid->CellCount();
    j["cell_size"] = grid->cell_size();
    j["backend"] = a.backend;
    j["res"] = a.res;
    j["mean_pvs_objects"] = mean;
    j["objects"] = scene->objects.size();
    std::map<std::string, uint64_t> in_scene;
    for (const scenes::Object& o : scene->objects) ++in_scene[TypeName(o)];
    nlohmann::json types = nlohmann::json::object();
    for (const auto& [type, n] : in_scene) {
      types[type] = {{"objects", n},
                     {"mean_pvs_objects", cells.empty() ? 0.0 : by_type[type] / static_cast<double>(cells.size())}};
    }
    j["by_type"] = types;
    j["seconds"] = provenance.seconds;
    if (!a.out.empty()) j["pvs_file"] = a.out;
    if (store != nullptr) {
      j["store"] = a.store;
      j["store_namespace"] = ns;
      j["shard"] = absl::StrFormat("%u/%u", shard, shards);
      j["shard_cells"] = shard_cells;
      j["cells_computed"] = cells.size();
      j["cells_already_stored"] = skipped;
    }
    std::printf("%s\n", j.dump(2).c_str());
  } else if (store != nullptr) {
    const std::string average = cells.empty() ? "" : absl::StrFormat(", %.1f objects per PVS on average", mean);
    const std::string done = a.out.empty()
                                 ? absl::StrFormat("%zu computed and stored, %zu already stored", cells.size(), skipped)
                                 : absl::StrFormat("%zu computed, stored where the store had none", cells.size());
    std::printf("%s: %zu of %zu viewcells of %g m (shard %u/%u), %s%s, %.1f s; store %s%s%s\n", scene->name.c_str(),
                shard_cells, grid->CellCount(), grid->cell_size(), shard, shards, done.c_str(), average.c_str(),
                provenance.seconds, a.store.c_str(), a.out.empty() ? "" : "; wrote ", a.out.c_str());
  } else {
    std::printf("%s: %zu viewcells of %g m, %.1f objects per PVS on average, %.1f s; wrote %s\n", scene->name.c_str(),
                grid->CellCount(), grid->cell_size(), mean, provenance.seconds, a.out.c_str());
  }
  return 0;
}

int Pvs(const PvsArgs& a) {
  if (a.json) ToolProgress().set_quiet(true);
  if (a.store.empty()) {
    if (a.store_prefix != "vistream") return BadOption("pvs", "--store-prefix", "names keys in a PVS store: give --store");
    if (!a.store_password_file.empty()) {
      return BadOption("pvs", "--store-password-file", "is the PVS store's: give --store");
    }
  }
  if (!a.store.empty() && !a.all) return BadOption("pvs", "--store", "fills a PVS store with every viewcell: give --all");
  if (a.all) return PvsAll(a);
  if (a.cell.empty()) return BadOption("pvs", "--cell or --all", "give --cell I,J (one viewcell) or --all -o FILE");
  if (!a.out.empty()) return BadOption("pvs", "-o", "writes the PVS file of --all; one viewcell prints");
  int ci = 0, cj = 0;
  char tail = 0;
  if (std::sscanf(a.cell.c_str(), "%d,%d%c", &ci, &cj, &tail) != 2) {
    return BadOption("pvs", "--cell", "'" + a.cell + "': expected I,J (two integers)");
  }
  // Viewcell size and band: the option, else the catalog entry's, else 100 m at eye level.
  const scenes::ViewcellSpec spec = scenes::ViewcellSpecFor(a.scene, a.cell_size);
  double load_s = 0.0;
  absl::StatusOr<scenes::Scene> scene = LoadSceneArg(a.scene, &load_s);
  if (!scene.ok()) return Fail(scene.status());
  absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(*scene, spec);
  if (!grid.ok()) return Fail(grid.status());
  const visibility::CellCoord coord{ci, cj};
  if (!grid->Valid(coord)) {
    return Fail(absl::OutOfRangeError("--cell " + a.cell + " is outside the grid of " + std::to_string(grid->nx()) +
                                      " x " + std::to_string(grid->ny()) + " cells"));
  }
  const scenes::Aabb cell = grid->CellBox(coord);

  auto t0 = std::chrono::steady_clock::now();
  const visibility::KdTree tree = visibility::KdTree::Build(*scene);
  const double kd_ms = 1000.0 * SecondsSince(t0);
  t0 = std::chrono::steady_clock::now();
  const visibility::PvsComputer computer(*scene, tree);
  const double occluders_ms = 1000.0 * SecondsSince(t0);
  const visibility::CellQueryOptions options = gl::QueryOptionsFor(a.res);
  absl::StatusOr<gl::PvsBackend> backend = gl::PvsBackend::Create(a.backend);
  if (!backend.ok()) return Fail(backend.status());
  const visibility::PvsResult pvs = backend->ComputeBatch(computer, std::span(&cell, 1), options).front();

  if (!a.map.empty()) {
    TopViewMap map(scene->bounds, a.map_size, Rgb{250, 250, 250});
    const glm::dvec2 c0(cell.min), c1(cell.max);
    const std::vector<glm::dvec2> square = {c0, {c1.x, c0.y}, c1, {c0.x, c1.y}};
    DrawVisibleSet(*scene, pvs.objects, square,
                   {absl::StrFormat("the viewcell (%g m)", cell.max.x - cell.min.x),
                    "building in the PVS (may be visible)", "building not in the PVS (occluded)"},
                   &map);
    map.SetTitle(absl::StrFormat("%s: PVS of viewcell %d,%d (dual ray space, %s backend, %u\u00b2 raster)",
                                 scene->name, ci, cj, a.backend, a.res),
                 absl::StrFormat("viewcell x %.0f to %.0f m, y %.0f to %.0f m, z %.1f to %.1f m; %zu of %zu objects "
                                 "potentially visible, %llu of %zu triangles",
                                 cell.min.x, cell.max.x, cell.min.y, cell.max.y, cell.min.z, cell.max.z,
                                 pvs.objects.size(), scene->objects.size(),
                                 static_cast<unsigned long long>(pvs.triangles), scene->TriangleCount()));
    if (absl::Status s = map.WritePng(a.map); !s.ok()) return Fail(s);
  }

  if (a.json) {
    nlohmann::json j;
    j["scene"] = scene->name;
    j["cell"] = {ci, cj};
    j["cell_box"] = {{"min", {cell.min.x, cell.min.y, cell.min.z}}, {"max", {cell.max.x, cell.max.y, cell.max.z}}};
    j["backend"] = a.backend;
    j["res"] = a.res;
    j["pvs_objects"] = pvs.objects.size();
    // The set itself, so that it can be compared object by object: ids, and the names.
    j["objects"] = pvs.objects;
    nlohmann::json names = nlohmann::json::array();
    for (scenes::ObjectId id : pvs.objects) names.push_back(scene->objects[id].name);
    j["object_names"] = names;
    j["pvs_triangles"] = pvs.triangles;
    j["total_objects"] = scene->objects.size();
    j["total_triangles"] = scene->TriangleCount();
    j["ms"] = pvs.ms;
    j["queries"] = pvs.stats.queries;
    j["occluded_queries"] = pvs.stats.occluded;
    j["planar_tests"] = pvs.stats.planar_tests;
    j["gathered_pieces"] = pvs.stats.gathered;
    j["blocker_vertices"] = pvs.stats.pieces;
    j["free_rays"] = pvs.stats.free_rays;
    j["raster_rows"] = pvs.stats.raster_rows;
    j["exact_tests"] = pvs.stats.exact_tests;
    j["setup_ms"] = {{"kd_tree", kd_ms}, {"occluders", occluders_ms}};
    std::printf("%s\n", j.dump(2).c_str());
    return 0;
  }
  std::printf("cell (%d, %d): [%.1f, %.1f] - [%.1f, %.1f], z %.1f - %.1f\n", ci, cj, cell.min.x, cell.min.y,
              cell.max.x, cell.max.y, cell.min.z, cell.max.z);
  std::printf("pvs: %zu of %zu objects, %llu of %zu triangles (%.2f%%)\n", pvs.objects.size(), scene->objects.size(),
              static_cast<unsigned long long>(pvs.triangles), scene->TriangleCount(),
              100.0 * static_cast<double>(pvs.triangles) / static_cast<double>(scene->TriangleCount()));
  std::printf("time: %.1f ms, %llu node queries (%llu occluded), %llu planar tests, %llu ended by a free ray\n",
              pvs.ms, static_cast<unsigned long long>(pvs.stats.queries),
              static_cast<unsigned long long>(pvs.stats.occluded),
              static_cast<unsigned long long>(pvs.stats.planar_tests),
              static_cast<unsigned long long>(pvs.stats.free_rays));
  std::printf("set-up: kd-tree %.1f ms, occluder pieces and contacts %.1f ms (once per scene)\n", kd_ms, occluders_ms);
  if (!a.map.empty()) std::printf("map: %s\n", a.map.c_str());
  return 0;
}

}  // namespace

void AddPvsCommand(CLI::App& app, std::function<void(int)> done) {
  auto [c, args] = AddSubcommand<PvsArgs>(
      &app, "pvs", "potentially visible set of one viewcell, or of all (dual ray space)", Pvs,
      done);
  c->add_option("--scene", args->scene, ".glb/.gltf file or catalog name")->required();
  CLI::Option* cell = c->add_option("--cell", args->cell, "viewcell grid coordinates I,J");
  c->add_flag("--all", args->all, "every viewcell of the grid, written to -o as a PVS file (vistream-server --pvs-file) or to --store")
      ->excludes(cell);
  c->add_option("-o,--out", args->out, "with --all: the PVS file to write")->check(OutputPath());
  c->add_option("--store", args->store,
                "with --all: fill the PVS store replicas share (Redis host:port or unix:PATH; password from "
                "$VISTREAM_STORE_PASSWORD); cells already stored are skipped");
  c->add_option("--store-prefix", args->store_prefix, "with --store: the key prefix (as the servers' store.key_prefix)")
      ->capture_default_str();
  c->add_option("--store-password-file", args->store_password_file,
                "with --store: a file whose first line is the store's password (as the servers' store.password_file; "
                "else $VISTREAM_STORE_PASSWORD)");
  c->add_option("--shard", args->shard,
                "with --store: K/N, compute only the viewcells whose id is K modulo N (0 <= K < N; N independent "
                "processes fill the store together)");
  c->add_option("--cell-size", args->cell_size, "viewcell size in metres (default: the catalog's, else 100)")
      ->check(FiniteRange(kMinCellSize, kMaxCellSize));
  c->add_option("--res", args->res, "finest raster resolution (a power of two, 1 to 256); exact: the raster tried before the exact test")
      ->check(PowerOfTwo(1, 256));
  c->add_option("--backend", args->backend, "cpu | gl | exact")->check(CLI::IsMember({"cpu", "gl", "exact"}));
  c->add_flag("--json", args->json, "print one JSON object");
  c->add_option("--map", args->map, "write a top view: viewcell green, visible blue, occluded red")
      ->check(OutputPath());
  c->add_option("--map-size", args->map_size,
                "the --map's pixels on its longer side (default 2048)")
      ->check(WholeRange(16, 16384));
}

}  // namespace vistream::tools
