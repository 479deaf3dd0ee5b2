#pragma once
// Deterministic procedural cities. The same name, seed and options give the same scene,
// byte for byte, on every platform.

#include <atomic>
#include <cstdint>
#include <string>

#include <absl/status/statusor.h>

#include "scenes/progress.h"
#include "scenes/scene.h"

namespace vistream::scenes {

// The test cities of Cohen-Or & Zadicario 1998: 2,128 buildings on a plane, distributed evenly
// and randomly; a quarter of them three stacked boxes of random height, the rest single
// boxes. `dense` gives city1, otherwise city2 (same buildings, four times the ground area).
Scene GenerateTestCity(bool dense, uint64_t seed);

// A London-like city for the experiments of Koltun et al. 2001: districts with their own
// irregular street grids, long straight avenues, squares, parks, a river, terraced rows,
// varied heights and landmarks far above the skyline. The defaults give 162.5 km².
struct LondonOptions {
  uint64_t seed = 1;
  double width_m = 13000.0;  // along x
  double depth_m = 12500.0;  // along y
  // World position of the local origin (the city centre); default near central London in
  // UTM zone 30U, so that large coordinates are exercised everywhere.
  glm::dvec3 origin{699000.0, 5710000.0, 0.0};
};
Scene GenerateLondon(const LondonOptions& options, const RunControl& run = {});

// A small district of terraced streets, the hard case of from-region visibility: rows of
// houses sharing party walls, corner houses touching two rows, dead-end closes whose end house
// touches both side rows (and sometimes the row behind), courtyards with sheds against the
// houses, large buildings side by side with towers on them, squares with kiosks lower than eye
// level. Streets 6-16 m wide between blocks of 45-90 m whose corners do not line up; a third
// of the blocks turned by up to 5 degrees. Centred on the origin.
struct StreetsOptions {
  uint64_t seed = 1;
  double width_m = 300.0;  // along x
  double depth_m = 300.0;  // along y
  // Coordinates on the 1/256 m grid (exact in float); false leaves them as computed, so the
  // float mesh rounds the double occluders, as imported data may.
  bool snap = true;
};
Scene GenerateStreets(const StreetsOptions& options);

// Parameters a catalog entry or the CLI may set for a named generator.
struct GeneratorParams {
  uint64_t seed = 1;
  double width_m = 0.0;  // 0: the generator's default
  double depth_m = 0.0;
};

// Generates `name` (city1, city2, london, streets). Unknown names and parameters a generator does not
// take give InvalidArgument. Cancellation gives Cancelled.
absl::StatusOr<Scene> GenerateNamed(const std::string& name, const GeneratorParams& params,
                                    const RunControl& run = {});

}  // namespace vistream::scenes
