// libFuzzer target: the AGVS sampling-state reader (vistream agvs --state FILE resumes from a
// user's file) on untrusted bytes, loaded into a sampler of the small generated streets scene. With
// VISTREAM_FUZZ_SEED_DIR=DIR it first writes that sampler's state after one batch there, the
// seed CI starts from.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <string>
#include <string_view>

#include "scenes/city_generator.h"
#include "visibility/agvs.h"
#include "visibility/viewcell_grid.h"

namespace {

[[noreturn]] void Die(const absl::Status& status) {
  std::fprintf(stderr, "agvs_state_fuzz: cannot set up: %s\n", std::string(status.message()).c_str());
  std::abort();
}

struct Town {
  vistream::scenes::Scene scene;
  std::unique_ptr<vistream::visibility::ViewcellGrid> grid;
  std::unique_ptr<vistream::visibility::GlobalSampler> sampler;
};

Town& TheTown() {
  static Town* town = [] {
    auto* t = new Town;
    t->scene = vistream::scenes::GenerateStreets(vistream::scenes::StreetsOptions{});  // 300 m square
    absl::StatusOr<vistream::visibility::ViewcellGrid> g =
        vistream::visibility::ViewcellGrid::Create(t->scene.bounds, 50.0, 0.5, 2.0);
    if (!g.ok()) Die(g.status());
    t->grid = std::make_unique<vistream::visibility::ViewcellGrid>(std::move(*g));
    vistream::visibility::AgvsOptions options;
    options.batch_samples = 4096;
    options.threads = 1;
    auto sampler = vistream::visibility::GlobalSampler::Create(t->scene, *t->grid, options);
    if (!sampler.ok()) Die(sampler.status());
    t->sampler = std::move(*sampler);
    return t;
  }();
  return *town;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  Town& town = TheTown();
  if (const char* dir = std::getenv("VISTREAM_FUZZ_SEED_DIR")) {
    town.sampler->RunBatch();
    std::ofstream(std::string(dir) + "/seed", std::ios::binary) << town.sampler->SaveState();
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  (void)TheTown().sampler->LoadState(bytes, "fuzz.state");
  return 0;
}
