#include <absl/strings/str_cat.h>

#include "scenes/city_generator.h"

namespace vistream::scenes {

absl::StatusOr<Scene> GenerateNamed(const std::string& name, const GeneratorParams& params,
                                    const RunControl& run) {
  if (name == "city1" || name == "city2") {
    if (params.width_m != 0.0 || params.depth_m != 0.0) {
      return absl::InvalidArgumentError(absl::StrCat(
          "generator '", name, "' has a fixed size (2,128 buildings); width and depth are not "
                               "parameters of it"));
    }
    return GenerateTestCity(name == "city1", params.seed);
  }
  if (name == "london") {
    LondonOptions o;
    o.seed = params.seed;
    if (params.width_m != 0.0) o.width_m = params.width_m;
    if (params.depth_m != 0.0) o.depth_m = params.depth_m;
    if (!(o.width_m >= 200.0 && o.width_m <= 100000.0 && o.depth_m >= 200.0 &&
          o.depth_m <= 100000.0)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "generator 'london': width and depth must be between 200 and 100000 m, got ",
          o.width_m, " x ", o.depth_m));
    }
    Scene scene = GenerateLondon(o, run);
    if (run.Cancelled()) return absl::CancelledError("generation cancelled");
    return scene;
  }
  if (name == "streets") {
    StreetsOptions o;
    o.seed = params.seed;
    if (params.width_m != 0.0) o.width_m = params.width_m;
    if (params.depth_m != 0.0) o.depth_m = params.depth_m;
    if (!(o.width_m >= 100.0 && o.width_m <= 5000.0 && o.depth_m >= 100.0 && o.depth_m <= 5000.0)) {
      return absl::InvalidArgumentError(absl::StrCat(
          "generator 'streets': width and depth must be between 100 and 5000 m, got ", o.width_m, " x ",
          o.depth_m));
    }
    return GenerateStreets(o);
  }
  return absl::InvalidArgumentError(
      absl::StrCat("unknown generator '", name, "' (known: city1, city2, london, streets)"));
}

}  // namespace vistream::scenes
