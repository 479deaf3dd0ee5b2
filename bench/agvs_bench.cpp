// Benchmarks of global visibility sampling on city1 (560 viewcells of 50 m), one batch of
// 65,536 samples per iteration on every core, per strategy:
//   build/bin/vistream_benchmarks --benchmark_filter=Agvs --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include "scenes/city_generator.h"
#include "scenes/progress.h"
#include "visibility/agvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream {
namespace {

struct City1 {
  scenes::Scene scene;
  visibility::ViewcellGrid grid;
};

const City1& Fixture() {
  static const City1* f = [] {
    scenes::Progress::SetQuiet(true);
    auto* x = new City1{*scenes::GenerateNamed("city1", scenes::GeneratorParams{}), {}};
    x->grid = *visibility::ViewcellGrid::Create(x->scene.bounds, 50.0, 0.5, 2.0);
    return x;
  }();
  return *f;
}

void BM_AgvsCity1(benchmark::State& state) {
  const City1& f = Fixture();
  visibility::AgvsOptions o;
  o.strategy = static_cast<visibility::SamplingStrategy>(state.range(0));
  auto sampler = *visibility::GlobalSampler::Create(f.scene, f.grid, o);
  for (int warm = 0; warm < 8; ++warm) sampler->RunBatch();  // past the first, cheap batches
  const visibility::AgvsStats before = sampler->stats();
  for (auto _ : state) sampler->RunBatch();
  const visibility::AgvsStats& after = sampler->stats();
  const double seconds = after.seconds - before.seconds;
  state.counters["samples_per_s"] = static_cast<double>(after.samples - before.samples) / seconds;
  state.counters["rays_per_s"] = static_cast<double>(after.rays - before.rays) / seconds;
  state.SetLabel(visibility::StrategyName(o.strategy));
}
BENCHMARK(BM_AgvsCity1)
    ->Arg(static_cast<int>(visibility::SamplingStrategy::kAgvs))
    ->Arg(static_cast<int>(visibility::SamplingStrategy::kSgvs))
    ->Arg(static_cast<int>(visibility::SamplingStrategy::kRef))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace vistream
