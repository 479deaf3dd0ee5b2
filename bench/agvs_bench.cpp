// Benchmarks of global visibility sampling on city1 (560 viewcells of 50 m), one batch of
// 65,536 samples per iteration on every core, per strategy:
//   build/bin/vistream_benchmarks --benchmark_filter=Agvs --benchmark_repetitions=5
#include <benchmark/benchmark.h>
#include <embree3/rtcore.h>

#include <cmath>
#include <numbers>

#include "scenes/city_generator.h"
#include "scenes/progress.h"
#include "scenes/random.h"
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
    auto* x = new City1{*scenes::GenerateNamed("city1", scenes::GeneratorParams{}), {}};
    x->grid = *visibility::ViewcellGrid::Create(x->scene, scenes::ViewcellSpec{.size_m = 50.0, .height_m = 2.0, .base_m = 0.5});
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

// The ray tracer alone, one thread: SGVS's rays (a uniform point of the view space, a uniform
// direction, cast both ways) with nothing done with the hits. The ceiling for samples/s per core;
// argument: Embree's robust traversal off or on.
void BM_EmbreeCity1(benchmark::State& state) {
  const City1& f = Fixture();
  RTCDevice device = rtcNewDevice(nullptr);
  RTCScene rtc = rtcNewScene(device);
  rtcSetSceneFlags(rtc, state.range(0) != 0 ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  rtcSetSceneBuildQuality(rtc, RTC_BUILD_QUALITY_HIGH);
  for (const scenes::Object& o : f.scene.objects) {
    if (o.mesh.indices.empty()) continue;
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_QUAD);  // as the sampler reads them
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                          3 * sizeof(float), o.mesh.positions.size()));
    for (size_t i = 0; i < o.mesh.positions.size(); ++i) {
      for (int k = 0; k < 3; ++k) v[3 * i + k] = o.mesh.positions[i][k];
    }
    const visibility::EmbreeQuads q = visibility::PairTriangles(o.mesh.indices);
    auto* ix = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4,
                                                              4 * sizeof(uint32_t), q.indices.size() / 4));
    std::copy(q.indices.begin(), q.indices.end(), ix);
    rtcCommitGeometry(g);
    rtcAttachGeometry(rtc, g);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(rtc);
  const scenes::Aabb vs = f.grid.Bounds();
  scenes::Rng rng(7);
  uint64_t rays = 0, hits = 0;
  for (auto _ : state) {
    for (int i = 0; i < 4096; ++i) {
      const glm::dvec3 p = vs.min + glm::dvec3(rng.Uniform(), rng.Uniform(), rng.Uniform()) * vs.Extent();
      const double phi = 2.0 * std::numbers::pi * rng.Uniform(), cz = 1.0 - 2.0 * rng.Uniform();
      const double sz = std::sqrt(std::max(0.0, 1.0 - cz * cz));
      for (double sign : {1.0, -1.0}) {
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        RTCRayHit rh{};
        rh.ray.org_x = static_cast<float>(p.x);
        rh.ray.org_y = static_cast<float>(p.y);
        rh.ray.org_z = static_cast<float>(p.z);
        rh.ray.dir_x = static_cast<float>(sign * sz * std::cos(phi));
        rh.ray.dir_y = static_cast<float>(sign * sz * std::sin(phi));
        rh.ray.dir_z = static_cast<float>(sign * cz);
        rh.ray.tfar = std::numeric_limits<float>::infinity();
        rh.ray.mask = ~0u;
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(rtc, &ctx, &rh);
        ++rays;
        hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
      }
    }
  }
  state.counters["rays_per_s"] = benchmark::Counter(static_cast<double>(rays), benchmark::Counter::kIsRate);
  state.counters["hit_share"] = static_cast<double>(hits) / static_cast<double>(rays);
  rtcReleaseScene(rtc);
  rtcReleaseDevice(device);
}
BENCHMARK(BM_EmbreeCity1)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace vistream
