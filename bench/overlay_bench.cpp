// The client overlay's cost a frame (client/overlay.h; the window's issue: at most 1 ms a frame
// at 1280x720): the same frame of the default scene, its PVS-sized set of objects drawn off-screen
// (OSMesa, as the headless client draws), with the overlay off (overlay:0), with the statistics
// panel and the minimap on as the client draws them (overlay:1: rebuilt every 0.2 s of a 60 Hz
// display, composited from their texture between), and rebuilt every frame (overlay:2: what a
// frame with a key press or the mouse over a panel costs), without and with 4x multisampling
// (msaa, the window's default), side by side in one run. The difference of the medians is the
// overlay's cost, the minimap's cell states (client/minimap.h, MinimapCells) included; the
// counter overlay_ms times it within each frame (from the frame drawn to the overlay drawn, both
// waited for), which the machine's noise moves less.
#include <benchmark/benchmark.h>

#include <chrono>
#include <cstdio>
#include <memory>
#include <vector>

#include "client/object_store.h"
#include "client/overlay.h"
#include "client/renderer.h"
#include "gl/gl_context.h"
#include "proto/scene_info.h"
#include "scenes/catalog.h"
#include "visibility/viewcell_grid.h"
#include "proto/walkthrough.pb.h"

namespace vistream::client {
namespace {

namespace v1 = vistream::v1;

struct Fixture {
  scenes::Scene scene;
  std::optional<visibility::ViewcellGrid> grid;
  Camera camera;
  std::vector<uint32_t> ids;
};

const Fixture* Load() {
  static Fixture* f = [] {
    auto* out = new Fixture;
    absl::StatusOr<scenes::LoadedScene> loaded = scenes::LoadScene("default", {});
    if (!loaded.ok()) {
      std::fprintf(stderr, "overlay_bench: %s\n", std::string(loaded.status().message()).c_str());
      return static_cast<Fixture*>(nullptr);
    }
    out->scene = std::move(loaded->scene);
    const scenes::ViewcellSpec spec = scenes::ViewcellSpecFor("default", 0.0, "");
    absl::StatusOr<visibility::ViewcellGrid> grid = visibility::ViewcellGrid::Create(out->scene, spec);
    if (!grid.ok()) return static_cast<Fixture*>(nullptr);
    out->grid = std::move(*grid);
    // The README's walk's start, looking along it (tests/window_test.cpp's pose).
    out->camera.eye = {509.4, 215.9, 1.7};
    out->camera.yaw_rad = 80.0 * M_PI / 180.0;
    out->camera.width = 1280;
    out->camera.height = 720;
    for (const scenes::Object& o : out->scene.objects) out->ids.push_back(o.id);
    return out;
  }();
  return f;
}

void BM_Frame(benchmark::State& state) {
  const Fixture* f = Load();
  if (f == nullptr) {
    state.SkipWithError("the default scene did not load");
    return;
  }
  absl::StatusOr<std::unique_ptr<gl::GlContext>> context = gl::GlContext::CreateOffscreen();
  if (!context.ok()) {
    state.SkipWithError("no OSMesa context");
    return;
  }
  absl::StatusOr<std::unique_ptr<Renderer>> renderer =
      Renderer::Create(context->get(), 1280, 720, true, static_cast<int>(state.range(1)));
  if (!renderer.ok()) {
    state.SkipWithError("no renderer");
    return;
  }
  ObjectStore store(0);
  std::vector<Event> events;
  events.emplace_back(MakeSceneInfo(f->scene, *f->grid, "default"));
  for (const scenes::Object& o : f->scene.objects) {
    ReceivedObject r;
    r.id = o.id;
    r.mesh = o.mesh;
    r.bounds_min = o.bounds.min;
    r.bounds_max = o.bounds.max;
    events.emplace_back(std::move(r));
  }
  const std::optional<uint32_t> cell = f->grid->CellAt(glm::dvec2(f->camera.eye));
  // Every cell's PVS list holds every object: the minimap's states cost what they would on a
  // city whose PVSs are the whole scene (its lookups a frame are bounded, client/minimap.h).
  for (uint32_t c = 0; c < f->grid->CellCount(); ++c) {
    v1::ViewcellPvs pvs;
    pvs.set_cell_id(c);
    for (uint32_t id : f->ids) pvs.add_object_ids(id);
    events.emplace_back(std::move(pvs));
  }
  store.Apply(std::move(events), cell);
  (*renderer)->Sync(store, {}, ~uint64_t{0});

  std::unique_ptr<Overlay> overlay;
  if (state.range(0) != 0) {
    absl::StatusOr<std::unique_ptr<Overlay>> o = Overlay::Create(context->get(), nullptr);
    if (!o.ok()) {
      state.SkipWithError("no overlay");
      return;
    }
    overlay = std::move(*o);
  }
  OverlayStatus status;
  status.server = "127.0.0.1:50051";
  status.scene = "default";
  status.cell = cell;
  status.pvs_listed = status.pvs_complete = true;
  status.pvs_objects = f->ids.size();
  status.held_objects = f->ids.size();
  status.held_bytes = 200u << 20;
  status.memory_budget_bytes = 1024u << 20;
  status.eye = f->camera.eye;
  status.yaw_rad = f->camera.yaw_rad;
  status.walk = "avenue-and-back-streets";
  MinimapCells cells;
  MinimapView map;
  map.grid = &store.grid();
  map.radius_m = MinimapRadius(store.grid());
  const std::vector<std::string> walks{"avenue-and-back-streets"};
  uint64_t frame = 0;
  double now = 0.0;
  double overlay_s = 0.0;
  using Clock = std::chrono::steady_clock;
  for (auto _ : state) {
    const FrameStats fs = (*renderer)->Draw(store, f->camera, f->ids, nullptr, ++frame, nullptr);
    (*renderer)->Resolve();  // as the client does: the overlay goes over the single-sample frame
    // The overlay's own time, the frame's drawing finished first (an upper bound: the client's
    // overlay work overlaps the rasteriser's; the same in every configuration).
    (*renderer)->Finish();
    const Clock::time_point overlay_begin = Clock::now();
    if (overlay != nullptr) {
      status.frames = frame;
      status.triangles_drawn = fs.triangles_drawn;
      overlay->AddFrame(16.0, now += 1.0 / 60.0, frame * 1000);
      cells.Refresh(store, [&](uint32_t id) { return (*renderer)->Uploaded(id); }, f->camera.eye, map.radius_m);
      map.cells = &cells.states();
      if (state.range(0) == 2) overlay->Invalidate();
      if (!overlay->Frame(status, map, walks, 1280, 720, 1.0 / 60.0).ok()) {
        state.SkipWithError("the overlay failed");
        return;
      }
    }
    (*renderer)->Finish();
    overlay_s += std::chrono::duration<double>(Clock::now() - overlay_begin).count();
  }
  state.counters["overlay_ms"] = benchmark::Counter(overlay_s * 1000.0, benchmark::Counter::kAvgIterations);
}
BENCHMARK(BM_Frame)
    ->ArgNames({"overlay", "msaa"})
    ->ArgsProduct({{0, 1, 2}, {0, 4}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MinTime(3.0);

}  // namespace
}  // namespace vistream::client
