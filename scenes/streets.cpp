// A small district of terraced streets: the touching and face-sharing buildings that from-region
// visibility finds hardest (see GenerateStreets in city_generator.h).

#include <algorithm>
#include <cmath>
#include <vector>

#include <absl/strings/str_cat.h>

#include "scenes/building.h"
#include "scenes/city_generator.h"
#include "scenes/random.h"

namespace vistream::scenes {

namespace {

// A block's frame: the block is [0, w] x [0, h] in the frame with origin `o` and axes u, v.
struct Frame {
  glm::dvec2 o{0.0}, u{1.0, 0.0}, v{0.0, 1.0};
  std::vector<glm::dvec2> Rect(double u0, double v0, double u1, double v1) const {
    return FrameRect(o, u, v, u0, u1, v0, v1);
  }
};

class District {
 public:
  District(Scene* scene, bool snap) : scene_(scene), snap_(snap) {}
  // Each block draws from a stream of its own: what one block holds never moves another.
  void StartBlock(Rng rng) { rng_ = rng; }

  // One building: a box, with now and then a narrower tier standing on it.
  void House(const Frame& f, double u0, double v0, double u1, double v1, double height) {
    std::vector<Prism> prisms = {{f.Rect(u0, v0, u1, v1), 0.0, height}};
    const double w = u1 - u0, d = v1 - v0;
    if (w > 6.0 && d > 6.0 && rng_.Chance(0.15)) {
      const double inset_u = rng_.Uniform(1.0, 0.3 * w), inset_v = rng_.Uniform(1.0, 0.3 * d);
      prisms.push_back({f.Rect(u0 + inset_u, v0 + inset_v, u1 - inset_u, v1 - inset_v), height,
                        height + rng_.Uniform(3.0, 15.0)});
    }
    AddBuilding(scene_, absl::StrCat("streets-", scene_->objects.size()), prisms, snap_);
  }

  // A row of houses sharing party walls, running along u (or along v) from a0 to a1 and across
  // from b0 to b1. Heights run in terraces: equal roofs side by side, then a step. Every corner
  // is computed from block coordinates alone, so a wall two houses share is bit-identical.
  void Row(const Frame& f, bool along_v, double a0, double a1, double b0, double b1) {
    double a = a0, height = rng_.Uniform(7.0, 20.0);
    while (a1 - a > 0.5) {
      double next = a + rng_.Uniform(4.0, 10.0);
      if (a1 - next < 4.0) next = a1;  // no sliver at the end of the row
      if (rng_.Chance(0.4)) height = rng_.Uniform(7.0, 20.0);
      if (along_v) {
        House(f, b0, a, b1, next, height);
      } else {
        House(f, a, b0, next, b1, height);
      }
      a = next;
    }
  }

  // Houses round the block's edge, corners included, around a courtyard; the corner houses
  // touch both of their rows.
  void Perimeter(const Frame& f, double w, double h) {
    const double d = rng_.Uniform(8.0, 14.0);
    auto corner = [&](double u0, double v0) { House(f, u0, v0, u0 + d, v0 + d, rng_.Uniform(8.0, 24.0)); };
    corner(0, 0);
    corner(w - d, 0);
    corner(w - d, h - d);
    corner(0, h - d);
    Row(f, false, d, w - d, 0, d);
    Row(f, false, d, w - d, h - d, h);
    Row(f, true, d, h - d, 0, d);
    Row(f, true, d, h - d, w - d, w);
    // A shed lower than eye level against the back of a house, in the courtyard.
    if (w > 2 * d + 8 && h > 2 * d + 8 && rng_.Chance(0.5)) {
      const double u0 = rng_.Uniform(d, w - d - 4);
      House(f, u0, d, u0 + 4, d + 3, rng_.Uniform(2.0, 2.4));
    }
  }

  // A dead-end close entering the block from its bottom side: rows along both sides and an end
  // house that touches both rows (as in a mews), then the rest of the block round it.
  void Close(const Frame& f, double w, double h) {
    const double d = rng_.Uniform(8.0, 12.0);
    const double width = rng_.Uniform(6.0, 10.0);
    const double c0 = rng_.Uniform(d + 2.0, w - d - 2.0 - width), c1 = c0 + width;
    // The end house sometimes reaches the terrace along the top, touching three rows.
    const double end = rng_.Uniform(6.0, 12.0);
    const double length = (h - d - end) * (rng_.Chance(0.3) ? 1.0 : rng_.Uniform(0.5, 0.9));
    Row(f, true, 0.0, length + end, c0 - d, c0);  // left of the close
    Row(f, true, 0.0, length + end, c1, c1 + d);  // right of it
    House(f, c0, length, c1, length + end, rng_.Uniform(8.0, 22.0));  // the end house
    // The rest of the block: a terrace along the top, detached houses at the bottom corners.
    Row(f, false, 0.0, w, h - d, h);
    if (c0 - d > 10.0) House(f, 1.0, 1.0, c0 - d - 3.0, rng_.Uniform(8.0, 14.0), rng_.Uniform(6.0, 14.0));
    if (w - c1 - d > 10.0) House(f, c1 + d + 3.0, 1.0, w - 1.0, rng_.Uniform(8.0, 14.0), rng_.Uniform(6.0, 14.0));
  }

  // Two to four large buildings side by side, some with towers.
  void Slabs(const Frame& f, double w, double h) {
    const int n = 2 + static_cast<int>(rng_.Below(3));
    const double v0 = rng_.Uniform(2.0, 8.0), v1 = h - rng_.Uniform(2.0, 8.0);
    const double margin = rng_.Uniform(2.0, 6.0), step = (w - 2 * margin) / n;
    double u = margin;
    for (int k = 0; k < n; ++k) {
      const double next = k + 1 == n ? w - margin : margin + step * (k + 1 + rng_.Uniform(-0.2, 0.2));
      std::vector<Prism> prisms = {{f.Rect(u, v0, next, v1), 0.0, rng_.Uniform(12.0, 30.0)}};
      if (next - u > 12.0 && v1 - v0 > 12.0 && rng_.Chance(0.5)) {
        const double a = rng_.Uniform(u + 2, next - 8), b = rng_.Uniform(v0 + 2, v1 - 8);
        prisms.push_back({f.Rect(a, b, a + 6, b + 6), prisms[0].z1, prisms[0].z1 + rng_.Uniform(10.0, 40.0)});
      }
      AddBuilding(scene_, absl::StrCat("streets-", scene_->objects.size()), prisms, snap_);
      u = next;
    }
  }

  // An open square: kiosks lower than eye level and a monument.
  void Square(const Frame& f, double w, double h) {
    for (int k = 0; k < 3; ++k) {
      const double u = rng_.Uniform(k * w / 3 + 2.0, (k + 1) * w / 3 - 6.0), v = rng_.Uniform(2.0, h - 6.0);
      if (k == 0) {
        House(f, u, v, u + 2.0, v + 2.0, rng_.Uniform(12.0, 25.0));
      } else {
        House(f, u, v, u + rng_.Uniform(2.0, 4.0), v + rng_.Uniform(1.5, 3.0), rng_.Uniform(1.2, 2.3));
      }
    }
  }

 private:
  Scene* scene_;
  Rng rng_{0};
  bool snap_;
};

}  // namespace

Scene GenerateStreets(const StreetsOptions& options) {
  Rng rng(options.seed ^ 0x73747265657473ULL);
  Scene scene;
  scene.name = "streets";
  District district(&scene, options.snap);
  // Streets of varying width between blocks of varying size: the block corners do not line up
  // from one row of blocks to the next, and some blocks are turned off the axes.
  auto cuts = [&](double extent) {
    std::vector<double> at = {-0.5 * extent};
    for (;;) {
      const double street = rng.Uniform(6.0, 16.0), block = rng.Uniform(45.0, 90.0);
      if (at.back() + street + block + 6.0 > 0.5 * extent) break;
      at.push_back(at.back() + street);
      at.push_back(at.back() + block);
    }
    return at;
  };
  const std::vector<double> xs = cuts(options.width_m);
  for (size_t i = 1; i + 1 < xs.size(); i += 2) {
    const std::vector<double> ys = cuts(options.depth_m);
    for (size_t j = 1; j + 1 < ys.size(); j += 2) {
      double x0 = xs[i], x1 = xs[i + 1], y0 = ys[j], y1 = ys[j + 1];
      Frame f;
      double w = x1 - x0, h = y1 - y0;
      if ((i / 2 + j / 2) % 3 == 1) {
        // Turned by up to 5 degrees about its centre, shrunk so that it stays in its lot.
        const double t = rng.Uniform(-0.087, 0.087), c = std::cos(t), s = std::abs(std::sin(t));
        const double wr = (w * c - h * s) / (c * c - s * s), hr = (h * c - w * s) / (c * c - s * s);
        if (wr > 40.0 && hr > 40.0) {
          f.u = glm::dvec2(std::cos(t), std::sin(t));
          f.v = glm::dvec2(-f.u.y, f.u.x);
          const glm::dvec2 centre(0.5 * (x0 + x1), 0.5 * (y0 + y1));
          f.o = centre - 0.5 * wr * f.u - 0.5 * hr * f.v;
          w = wr;
          h = hr;
        } else {
          f.o = glm::dvec2(x0, y0);
        }
      } else {
        f.o = glm::dvec2(x0, y0);
      }
      const double kind = rng.Uniform();
      district.StartBlock(rng.Fork());
      if (kind < 0.45) {
        district.Perimeter(f, w, h);
      } else if (kind < 0.75) {
        district.Close(f, w, h);
      } else if (kind < 0.9) {
        district.Slabs(f, w, h);
      } else {
        district.Square(f, w, h);
      }
    }
  }
  return scene;
}

}  // namespace vistream::scenes
