// city1 and city2 of Cohen-Or & Zadicario 1998.

#include <absl/strings/str_cat.h>

#include "scenes/building.h"
#include "scenes/city_generator.h"
#include "scenes/random.h"

namespace vistream::scenes {

namespace {

// 2,128 = 56 x 38 lots: one building per lot, placed and sized at random inside it.
constexpr int kLotsX = 56;
constexpr int kLotsY = 38;
constexpr int kBuildings = kLotsX * kLotsY;
constexpr int kStacked = kBuildings / 4;  // "about 25%": exactly a quarter, chosen at random

}  // namespace

Scene GenerateTestCity(bool dense, uint64_t seed) {
  Rng rng(seed ^ (dense ? 0x6369747931ULL : 0x6369747932ULL));
  // Dense: 25 m lots (streets of 5 m and more); sparse: 50 m lots.
  const double pitch = dense ? 25.0 : 50.0;
  const glm::dvec2 corner(-0.5 * kLotsX * pitch, -0.5 * kLotsY * pitch);

  // Choose exactly kStacked lots for the stacked buildings (partial Fisher-Yates).
  std::vector<int> order(kBuildings);
  for (int i = 0; i < kBuildings; ++i) order[i] = i;
  std::vector<bool> stacked(kBuildings, false);
  for (int i = 0; i < kStacked; ++i) {
    const int j = i + static_cast<int>(rng.Below(kBuildings - i));
    std::swap(order[i], order[j]);
    stacked[order[i]] = true;
  }

  Scene scene;
  scene.name = dense ? "city1" : "city2";
  scene.objects.reserve(kBuildings);
  const glm::dvec2 u(1.0, 0.0), v(0.0, 1.0);
  for (int j = 0; j < kLotsY; ++j) {
    for (int i = 0; i < kLotsX; ++i) {
      const int lot = j * kLotsX + i;
      const double w = rng.Uniform(10.0, 20.0), d = rng.Uniform(10.0, 20.0);
      // At least 2.5 m from the lot edge, so neighbouring buildings never touch.
      const double x0 = corner.x + i * pitch + rng.Uniform(2.5, pitch - 2.5 - w);
      const double y0 = corner.y + j * pitch + rng.Uniform(2.5, pitch - 2.5 - d);
      std::vector<Prism> prisms;
      auto base = FrameRect(glm::dvec2(0.0), u, v, x0, x0 + w, y0, y0 + d);
      if (!stacked[lot]) {
        prisms.push_back({base, 0.0, rng.Uniform(10.0, 40.0)});
      } else {
        double z = 0.0;
        for (int tier = 0; tier < 3; ++tier) {
          const double top = z + rng.Uniform(6.0, 20.0);
          prisms.push_back({base, z, top});
          z = top;
          // The next box stands on this one: shrink and shift it, staying inside.
          const double f = rng.Uniform(0.55, 0.85);
          const double slack_x = 0.5 * (1.0 - f) * (base[1].x - base[0].x);
          const double slack_y = 0.5 * (1.0 - f) * (base[3].y - base[0].y);
          base = ScaleAboutCentroid(
              base, f,
              rng.UniformPoint(-0.8, 0.8, -0.8, 0.8) * glm::dvec2(slack_x, slack_y));
        }
      }
      AddBuilding(&scene, absl::StrCat(scene.name, "-", lot), prisms);
    }
  }
  return scene;
}

}  // namespace vistream::scenes
