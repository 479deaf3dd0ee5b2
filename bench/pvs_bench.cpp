// Benchmarks of the dual-ray-space PVS on london: a fixed sample of 100 m viewcells.
//   build/bin/vistream_benchmarks --benchmark_filter=Pvs --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include "scenes/city_generator.h"
#include "scenes/progress.h"
#include "visibility/pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream {
namespace {

struct LondonPvs {
  scenes::Scene scene;
  visibility::KdTree tree;
  std::unique_ptr<visibility::PvsComputer> computer;
  std::vector<scenes::Aabb> cells;  // 100 m viewcells at eye level, with ground to stand on
};

const LondonPvs& Fixture() {
  static const LondonPvs* f = [] {
    auto* x = new LondonPvs;
    x->scene = scenes::GenerateLondon(scenes::LondonOptions{});
    x->tree = visibility::KdTree::Build(x->scene);
    x->computer = std::make_unique<visibility::PvsComputer>(x->scene, x->tree);
    const auto grid = visibility::ViewcellGrid::Create(x->scene, scenes::ViewcellSpec{.size_m = 100.0, .height_m = 2.0, .base_m = 0.5});
    for (const visibility::CellCoord c : grid->Sample(8, 2001)) x->cells.push_back(grid->CellBox(c));
    return x;
  }();
  return *f;
}

void BM_PvsLondon100m(benchmark::State& state) {
  const LondonPvs& f = Fixture();
  visibility::CellQueryOptions options;
  options.max_res = static_cast<uint32_t>(state.range(0));
  size_t objects = 0;
  double ms = 0.0;
  for (auto _ : state) {
    objects = 0;
    ms = 0.0;
    for (const scenes::Aabb& cell : f.cells) {
      const visibility::PvsResult r = f.computer->Compute(cell, options);
      objects += r.objects.size();
      ms += r.ms;
    }
  }
  const auto n = static_cast<double>(f.cells.size());
  state.counters["ms_per_cell"] = ms / n;
  state.counters["pvs_objects"] = static_cast<double>(objects) / n;
}
BENCHMARK(BM_PvsLondon100m)->Arg(16)->Arg(128)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace vistream
