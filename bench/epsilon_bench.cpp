// Benchmarks of the ε-superset on city1 and city2: a fixed sample of ground-level
// neighbourhoods, a quarter of a typical building wide, with the paper's fully optimised
// column and with every optimisation of this project.
//   build/bin/vistream_benchmarks --benchmark_filter=Epsilon --benchmark_repetitions=5
#include <benchmark/benchmark.h>

#include "scenes/city_generator.h"
#include "visibility/epsilon_superset.h"

namespace vistream {
namespace {

struct EpsilonFixture {
  scenes::Scene scene;
  std::unique_ptr<visibility::EpsilonSuperset> eps;
  std::vector<scenes::Aabb> boxes;
};

const EpsilonFixture& Fixture(bool dense) {
  auto make = [](bool d) {
    auto* x = new EpsilonFixture;
    x->scene = scenes::GenerateTestCity(d, 1);
    x->eps = std::move(*visibility::EpsilonSuperset::Create(x->scene));
    x->boxes = visibility::SampleNeighbourhoods(x->scene, 50, 0.25 * visibility::TypicalObjectSize(x->scene), 0.5,
                                                1998);
    return x;
  };
  static const EpsilonFixture* city1 = make(true);
  static const EpsilonFixture* city2 = make(false);
  return dense ? *city1 : *city2;
}

// Arguments: city (1 dense, 2 sparse), optimisations (0 the paper's, 1 all).
void BM_Epsilon(benchmark::State& state) {
  const EpsilonFixture& f = Fixture(state.range(0) == 1);
  const visibility::EpsilonOptions options = *visibility::EpsilonOptions::FromName(state.range(1) ? "all" : "paper");
  double visible = 0, total = 0, ms = 0;
  for (auto _ : state) {
    visible = total = ms = 0;
    for (const scenes::Aabb& box : f.boxes) {
      const visibility::EpsilonResult r = f.eps->Compute(box, options);
      visible += static_cast<double>(r.stats.visible_triangles);
      total += static_cast<double>(r.stats.total_triangles);
      ms += r.stats.ms;
    }
  }
  state.counters["ms_per_neighbourhood"] = ms / static_cast<double>(f.boxes.size());
  state.counters["occluded_pct"] = total > 0 ? 100.0 * (total - visible) / total : 0.0;
}
BENCHMARK(BM_Epsilon)->ArgNames({"city", "all"})->Args({1, 0})->Args({1, 1})->Args({2, 0})->Args({2, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace vistream
