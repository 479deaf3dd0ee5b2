// Benchmarks of the foundation: city generation, glTF save/load and kd-tree construction.
//   build/bin/vistream_benchmarks --benchmark_repetitions=5 --benchmark_report_aggregates_only
#include <filesystem>

#include <benchmark/benchmark.h>

#include "scenes/city_generator.h"
#include "scenes/gltf_io.h"
#include "scenes/progress.h"
#include "visibility/kdtree.h"

namespace vistream {
namespace {

const scenes::Scene& London() {
  static const scenes::Scene* scene = [] {
    return new scenes::Scene(scenes::GenerateLondon(scenes::LondonOptions{}));
  }();
  return *scene;
}

void BM_GenerateCity1(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(scenes::GenerateTestCity(true, 1));
}
BENCHMARK(BM_GenerateCity1)->Unit(benchmark::kMillisecond);

void BM_GenerateLondon(benchmark::State& state) {
  for (auto _ : state) benchmark::DoNotOptimize(scenes::GenerateLondon(scenes::LondonOptions{}));
  state.counters["triangles"] = static_cast<double>(London().TriangleCount());
}
BENCHMARK(BM_GenerateLondon)->Unit(benchmark::kMillisecond)->Iterations(1);

void BM_KdTreeBuildLondon(benchmark::State& state) {
  const scenes::Scene& scene = London();
  const visibility::KdTreeOptions options{.leaf_size = static_cast<uint32_t>(state.range(0))};
  for (auto _ : state) benchmark::DoNotOptimize(visibility::KdTree::Build(scene, options));
  state.counters["objects"] = static_cast<double>(scene.objects.size());
}
BENCHMARK(BM_KdTreeBuildLondon)->Arg(1)->Arg(4)->Arg(16)->Unit(benchmark::kMillisecond);

void BM_SaveLoadLondonGlb(benchmark::State& state) {
  const std::string path = (std::filesystem::temp_directory_path() / "vistream-bench-london.glb").string();
  if (!scenes::SaveGltf(London(), path).ok()) {
    state.SkipWithError("cannot write the london .glb");
    return;
  }
  for (auto _ : state) benchmark::DoNotOptimize(scenes::LoadGltf(path));
  state.counters["bytes"] = static_cast<double>(std::filesystem::file_size(path));
  std::filesystem::remove(path);
}
BENCHMARK(BM_SaveLoadLondonGlb)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace
}  // namespace vistream

BENCHMARK_MAIN();
