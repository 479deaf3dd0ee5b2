// A London-like city: a patchwork of districts, each with its own irregular street grid,
// cut by long straight avenues, a winding river, parks and squares; terraced rows along the
// streets, heights rising towards two clusters, and landmark towers far above the skyline.

#include <algorithm>
#include <cmath>
#include <numbers>

#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>

#include "scenes/building.h"
#include "scenes/city_generator.h"
#include "scenes/progress.h"
#include "scenes/random.h"

namespace vistream::scenes {

namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kDistrictSpacing = 900.0;  // mean distance between district seeds, metres
constexpr double kStorey = 3.2;

struct District {
  glm::dvec2 seed;
  glm::dvec2 u, v;         // street grid axes
  double block_u, block_v;  // mean block size along u and v
  double street;            // street width
  double lot_width;         // mean lot frontage
  double terrace;           // probability that a block side is one continuous terrace
};

struct Avenue {
  glm::dvec2 a, dir;  // start and unit direction
  double length, half_width;
};

struct Disc {
  glm::dvec2 centre;
  double radius;
};

struct Landmark {
  glm::dvec2 centre;
  double clear_radius;
};

// Open ground and the district partition: everything a candidate building is tested against.
class CityPlan {
 public:
  CityPlan(const LondonOptions& o, Rng& rng) : half_(0.5 * o.width_m, 0.5 * o.depth_m) {
    // Districts on a jittered grid; the nearest seed owns a point (a Voronoi partition).
    nx_ = std::max(1, static_cast<int>(std::ceil(o.width_m / kDistrictSpacing)));
    ny_ = std::max(1, static_cast<int>(std::ceil(o.depth_m / kDistrictSpacing)));
    cell_ = glm::dvec2(o.width_m / nx_, o.depth_m / ny_);
    for (int j = 0; j < ny_; ++j) {
      for (int i = 0; i < nx_; ++i) {
        District d;
        d.seed = -half_ + cell_ * (glm::dvec2(i, j) + rng.UniformPoint(0.15, 0.85, 0.15, 0.85));
        const double theta = rng.Uniform(0.0, kPi / 2);
        d.u = glm::dvec2(std::cos(theta), std::sin(theta));
        d.v = glm::dvec2(-d.u.y, d.u.x);
        d.block_u = rng.Uniform(90.0, 200.0);
        d.block_v = rng.Uniform(60.0, 130.0);
        d.street = rng.Uniform(9.0, 18.0);
        d.lot_width = rng.Uniform(9.0, 20.0);
        d.terrace = rng.Uniform(0.3, 0.9);
        districts_.push_back(d);
      }
    }
    // Open features scale with the area: the defaults are tuned for 162.5 km².
    const double area_ratio = o.width_m * o.depth_m / 162.5e6;
    const double span = std::max(o.width_m, o.depth_m);
    // Long straight avenues (Oxford Street, Euston Road...).
    const int avenues = std::max(2, static_cast<int>(std::lround(16.0 * std::sqrt(area_ratio))));
    for (int k = 0; k < avenues; ++k) {
      Avenue av;
      const glm::dvec2 mid = rng.UniformPoint(-0.8, 0.8, -0.8, 0.8) * half_;
      const double theta = rng.Uniform(0.0, kPi);
      av.dir = glm::dvec2(std::cos(theta), std::sin(theta));
      av.length = rng.Uniform(0.25, 0.85) * span;
      av.a = mid - av.dir * (0.5 * av.length);
      av.half_width = 0.5 * rng.Uniform(22.0, 40.0);
      avenues_.push_back(av);
    }
    // Parks (few, large) and squares (many, small).
    // A park is a cluster of overlapping discs: an irregular blob, not a circle.
    const int parks = static_cast<int>(14.0 * area_ratio + rng.Uniform());
    for (int k = 0; k < parks; ++k) {
      const glm::dvec2 centre = rng.UniformPoint(-0.9, 0.9, -0.9, 0.9) * half_;
      const double size = rng.Uniform(250.0, 700.0);
      const int lobes = 2 + static_cast<int>(rng.Below(3));
      for (int l = 0; l < lobes; ++l) {
        const double a = rng.Uniform(0.0, 2 * kPi), d = rng.Uniform(0.2, 0.9) * size;
        parks_.push_back({centre + d * glm::dvec2(std::cos(a), std::sin(a)), size * rng.Uniform(0.45, 0.8)});
      }
    }
    const int squares = static_cast<int>(320.0 * area_ratio + rng.Uniform());
    for (int k = 0; k < squares; ++k) {
      squares_.push_back({rng.UniformPoint(-1.0, 1.0, -1.0, 1.0) * half_,
                          rng.Uniform(30.0, 85.0)});
    }
    // The river: a sine-sum centreline across the whole width.
    river_y0_ = rng.Uniform(-0.2, 0.2) * half_.y;
    river_amp_[0] = rng.Uniform(300.0, 700.0);
    river_amp_[1] = rng.Uniform(100.0, 300.0);
    river_freq_[0] = 2 * kPi / rng.Uniform(5000.0, 9000.0);
    river_freq_[1] = 2 * kPi / rng.Uniform(1500.0, 3000.0);
    river_phase_[0] = rng.Uniform(0.0, 2 * kPi);
    river_phase_[1] = rng.Uniform(0.0, 2 * kPi);
    river_half_width_ = rng.Uniform(110.0, 160.0);
    // Two high-rise clusters (the City, Docklands), off the river.
    clusters_[0] = RiverBank(rng.Uniform(-0.15, 0.1) * half_.x, +1, 600.0);
    clusters_[1] = RiverBank(rng.Uniform(0.3, 0.5) * half_.x, -1, 500.0);
  }

  const std::vector<District>& districts() const { return districts_; }
  const glm::dvec2& half() const { return half_; }
  glm::dvec2 cluster(int k) const { return clusters_[k]; }

  double RiverY(double x) const {
    return river_y0_ + river_amp_[0] * std::sin(river_freq_[0] * x + river_phase_[0]) +
           river_amp_[1] * std::sin(river_freq_[1] * x + river_phase_[1]);
  }
  // A point `offset` metres beyond the river's edge on side `side` at x.
  glm::dvec2 RiverBank(double x, int side, double offset) const {
    return glm::dvec2(x, RiverY(x) + side * (river_half_width_ + offset));
  }

  // Index of the district owning p.
  int DistrictAt(const glm::dvec2& p) const {
    int best = 0;
    double best_d2 = INFINITY;
    ForNearbyDistricts(p, [&](int k) {
      const glm::dvec2 d = p - districts_[k].seed;
      const double d2 = glm::dot(d, d);
      if (d2 < best_d2) best_d2 = d2, best = k;
    });
    return best;
  }

  // True when the footprint lies inside the city, inside district `k` at least `margin`
  // from its border, and clear of avenues, the river, parks, squares and landmarks.
  bool Buildable(const std::vector<glm::dvec2>& fp, int k, double margin,
                 const std::vector<Landmark>& landmarks) const {
    glm::dvec2 c(0.0);
    for (const glm::dvec2& p : fp) {
      if (std::abs(p.x) > half_.x || std::abs(p.y) > half_.y) return false;
      c += p;
    }
    c /= static_cast<double>(fp.size());
    bool inside = true;
    ForNearbyDistricts(c, [&](int other) {
      if (other == k || !inside) return;
      // Signed distance of each corner to the bisector of the two seeds.
      const glm::dvec2 a = districts_[k].seed, b = districts_[other].seed;
      const glm::dvec2 n = glm::normalize(b - a);
      const glm::dvec2 m = 0.5 * (a + b);
      for (const glm::dvec2& p : fp) {
        if (glm::dot(p - m, n) > -margin) inside = false;
      }
    });
    if (!inside) return false;
    for (const Avenue& av : avenues_) {
      if (Crosses(fp, av)) return false;
    }
    // River: every corner (and the centre) must stay off the water, on one bank.
    int side = 0;
    for (const glm::dvec2& p : fp) {
      const double dy = p.y - RiverY(p.x);
      if (std::abs(dy) < river_half_width_ + 5.0) return false;
      const int s = dy > 0 ? 1 : -1;
      if (side != 0 && s != side) return false;
      side = s;
    }
    for (const Disc& d : parks_) {
      if (NearDisc(fp, c, d)) return false;
    }
    for (const Disc& d : squares_) {
      if (NearDisc(fp, c, d)) return false;
    }
    for (const Landmark& l : landmarks) {
      if (NearDisc(fp, c, {l.centre, l.clear_radius})) return false;
    }
    return true;
  }

 private:
  template <typename F>
  void ForNearbyDistricts(const glm::dvec2& p, F&& f) const {
    const int ci = static_cast<int>(std::floor((p.x + half_.x) / cell_.x));
    const int cj = static_cast<int>(std::floor((p.y + half_.y) / cell_.y));
    for (int j = std::max(0, cj - 2); j <= std::min(ny_ - 1, cj + 2); ++j) {
      for (int i = std::max(0, ci - 2); i <= std::min(nx_ - 1, ci + 2); ++i) f(j * nx_ + i);
    }
  }
  static bool Crosses(const std::vector<glm::dvec2>& fp, const Avenue& av) {
    const glm::dvec2 n(-av.dir.y, av.dir.x);
    double lo = INFINITY, hi = -INFINITY, tlo = INFINITY, thi = -INFINITY;
    for (const glm::dvec2& p : fp) {
      const double s = glm::dot(p - av.a, n), t = glm::dot(p - av.a, av.dir);
      lo = std::min(lo, s), hi = std::max(hi, s);
      tlo = std::min(tlo, t), thi = std::max(thi, t);
    }
    const double clear = av.half_width + 2.0;
    return thi > -clear && tlo < av.length + clear && hi > -clear && lo < clear;
  }
  static bool NearDisc(const std::vector<glm::dvec2>& fp, const glm::dvec2& c, const Disc& d) {
    const double r2 = d.radius * d.radius;
    auto in = [&](const glm::dvec2& p) { return glm::dot(p - d.centre, p - d.centre) < r2; };
    if (in(c)) return true;
    return std::any_of(fp.begin(), fp.end(), in);
  }

  glm::dvec2 half_;
  int nx_ = 1, ny_ = 1;
  glm::dvec2 cell_{1.0};
  std::vector<District> districts_;
  std::vector<Avenue> avenues_;
  std::vector<Disc> parks_, squares_;
  double river_y0_ = 0, river_amp_[2] = {}, river_freq_[2] = {}, river_phase_[2] = {};
  double river_half_width_ = 120;
  glm::dvec2 clusters_[2];
};

// Storeys of an ordinary building at p: two to five in the suburbs, up to fifteen near the
// high-rise clusters.
double BuildingHeight(const CityPlan& plan, const glm::dvec2& p, Rng& rng) {
  double f = 0.0;
  for (int k = 0; k < 2; ++k) {
    const double d = glm::length(p - plan.cluster(k));
    f = std::max(f, std::exp(-d / (k == 0 ? 2500.0 : 1200.0)));
  }
  double storeys = 2.0 + std::floor(rng.Uniform() * (4.0 + 10.0 * f));
  if (rng.Chance(0.03 + 0.12 * f)) storeys += rng.Uniform(6.0, 16.0) * (0.3 + f);  // mid-rise
  return storeys * kStorey + rng.Uniform(0.0, 2.5);
}

// Landmark towers: tapering stacks far above the skyline, most in the two clusters.
std::vector<Landmark> PlaceLandmarks(const CityPlan& plan, Rng& rng, Scene* scene) {
  std::vector<Landmark> placed;
  const int count = 32;
  int attempts = 0;
  while (static_cast<int>(placed.size()) < count && attempts++ < 2000) {
    const double pick = rng.Uniform();
    glm::dvec2 c;
    if (pick < 0.55) {
      c = plan.cluster(0) + rng.UniformPoint(-900, 900, -600, 600);
    } else if (pick < 0.85) {
      c = plan.cluster(1) + rng.UniformPoint(-600, 600, -500, 500);
    } else {
      c = rng.UniformPoint(-0.9, 0.9, -0.9, 0.9) * plan.half();
    }
    const double side = rng.Uniform(28.0, 60.0);
    const double theta = rng.Uniform(0.0, kPi / 2);
    const glm::dvec2 u(std::cos(theta), std::sin(theta)), v(-u.y, u.x);
    std::vector<glm::dvec2> base = FrameRect(c, u, v, -side / 2, side / 2, -side / 2, side / 2);
    if (rng.Chance(0.4)) {  // an octagonal tower
      base.clear();
      for (int k = 0; k < 8; ++k) {
        const double a = theta + k * kPi / 4;
        base.push_back(c + 0.5 * side * glm::dvec2(std::cos(a), std::sin(a)));
      }
    }
    const double clear = 0.75 * side + 12.0;
    const int district = plan.DistrictAt(c);
    if (!plan.Buildable(base, district, 0.0, placed)) continue;
    bool apart = true;
    for (const Landmark& l : placed) apart &= glm::length(l.centre - c) > l.clear_radius + clear;
    if (!apart) continue;
    const double total = rng.Uniform(120.0, 310.0);
    const int tiers = 3 + static_cast<int>(rng.Below(3));
    std::vector<Prism> prisms;
    double z = 0.0;
    for (int t = 0; t < tiers; ++t) {
      // Each tier takes a share of what is left; the last one reaches the total height.
      const double top = t + 1 == tiers ? total : z + (total - z) * rng.Uniform(0.3, 0.55);
      prisms.push_back({base, z, top});
      z = top;
      base = ScaleAboutCentroid(base, rng.Uniform(0.6, 0.85));
    }
    AddBuilding(scene, absl::StrCat("landmark-", placed.size()), prisms);
    placed.push_back({c, clear});
  }
  return placed;
}

// Lots along one side of a block: frontage along `dir` from `start` for `length` metres,
// depth `depth` into the block along `inward`.
struct BlockSide {
  glm::dvec2 start, dir, inward;
  double length, depth;
};

}  // namespace

Scene GenerateLondon(const LondonOptions& options, const RunControl& run) {
  Rng rng(options.seed ^ 0x6c6f6e646f6eULL);
  Scene scene;
  scene.name = "london";
  scene.origin = options.origin;
  CityPlan plan(options, rng);
  const std::vector<Landmark> landmarks = PlaceLandmarks(plan, rng, &scene);

  Progress progress(run, "generating london", plan.districts().size());
  int district_index = 0;
  for (const District& d : plan.districts()) {
    if (progress.Cancelled()) return scene;
    Rng drng = rng.Fork();
    // Street lines at irregular spacings, covering the district's neighbourhood.
    const double reach = 1.6 * kDistrictSpacing;
    auto lines = [&](double mean) {
      std::vector<double> at;
      for (double t = -reach + drng.Uniform(0.0, mean); t < reach; t += mean * drng.Uniform(0.65, 1.4)) {
        at.push_back(t);
      }
      return at;
    };
    const std::vector<double> us = lines(d.block_u), vs = lines(d.block_v);
    const double hs = 0.5 * d.street;
    for (size_t i = 0; i + 1 < us.size(); ++i) {
      for (size_t j = 0; j + 1 < vs.size(); ++j) {
        const double u0 = us[i] + hs, u1 = us[i + 1] - hs, v0 = vs[j] + hs, v1 = vs[j + 1] - hs;
        const glm::dvec2 centre = d.seed + d.u * (0.5 * (u0 + u1)) + d.v * (0.5 * (v0 + v1));
        // Blocks whose centre another district owns are built by that one, if at all.
        if (plan.DistrictAt(centre) != district_index) continue;
        if (u1 - u0 < 12.0 || v1 - v0 < 12.0) continue;
        // A side of the block: lots of varying frontage; a terrace shares walls.
        const double depth_s = std::min(drng.Uniform(10.0, 24.0), 0.5 * (v1 - v0));
        const double depth_n = std::min(drng.Uniform(10.0, 24.0), 0.5 * (v1 - v0));
        const double depth_w = std::min(drng.Uniform(10.0, 24.0), 0.5 * (u1 - u0));
        const double depth_e = std::min(drng.Uniform(10.0, 24.0), 0.5 * (u1 - u0));
        const BlockSide sides[4] = {
            {d.seed + d.u * u0 + d.v * v0, d.u, d.v, u1 - u0, depth_s},
            {d.seed + d.u * u1 + d.v * v1, -d.u, -d.v, u1 - u0, depth_n},
            {d.seed + d.u * u0 + d.v * (v1 - depth_n), -d.v, d.u, (v1 - depth_n) - (v0 + depth_s), depth_w},
            {d.seed + d.u * u1 + d.v * (v0 + depth_s), d.v, -d.u, (v1 - depth_n) - (v0 + depth_s), depth_e},
        };
        for (const BlockSide& side : sides) {
          if (side.length < 6.0) continue;
          const bool terrace = drng.Chance(d.terrace);
          const double setback = terrace ? 0.0 : drng.Uniform(0.0, 4.0);
          std::vector<Prism> row;  // the current object: a run of lots sharing walls
          int run_left = 0;
          auto flush = [&]() {
            if (!row.empty()) {
              AddBuilding(&scene, absl::StrCat("b", scene.objects.size()), row);
              row.clear();
            }
          };
          double t = 0.0;
          while (t < side.length - 4.0) {
            double w = d.lot_width * drng.Uniform(0.6, 1.5);
            if (side.length - (t + w) < 5.0) w = side.length - t;  // absorb a thin remainder
            const double gap = terrace ? 0.0 : drng.Uniform(1.0, 4.0);
            const double a = t + 0.5 * gap, b = t + w - 0.5 * gap;
            t += w;
            const double depth = side.depth * (terrace ? drng.Uniform(0.85, 1.0) : drng.Uniform(0.6, 1.0));
            if (b - a < 4.0 || depth - setback < 5.0) {
              flush();
              continue;
            }
            std::vector<glm::dvec2> fp = FrameRect(side.start, side.dir, side.inward, a, b, setback, depth);
            if (!plan.Buildable(fp, district_index, hs, landmarks)) {
              flush();
              continue;
            }
            const glm::dvec2 at = side.start + side.dir * (0.5 * (a + b));
            const double h = BuildingHeight(plan, at, drng);
            // Detached buildings are objects of their own; terraces group 1-6 houses.
            if (!terrace || run_left <= 0) {
              flush();
              run_left = terrace ? 1 + static_cast<int>(drng.Below(6)) : 1;
            }
            --run_left;
            row.push_back({fp, 0.0, h});
            // Some buildings step back above a lower storey (a tier on a wider tier).
            if (b - a > 12.0 && depth - setback > 12.0 && drng.Chance(0.08)) {
              const double in = drng.Uniform(2.0, 4.0);
              row.push_back({FrameRect(side.start, side.dir, side.inward, a + in, b - in,
                                       setback + in, depth - in),
                             h, h + drng.Uniform(2.0, 4.0) * kStorey});
            }
          }
          flush();
        }
      }
    }
    ++district_index;
    progress.Advance();
  }
  progress.Finish();
  return scene;
}

}  // namespace vistream::scenes
