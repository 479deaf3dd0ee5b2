#include "scenes/building.h"

#include <cmath>

namespace vistream::scenes {

namespace {

// Generated coordinates are snapped to 1/256 m (4 mm). Such values below 65,536 m are exact
// in single precision, so the float mesh and the double occluder describe the very same solid
// (an occluder never pokes out of its building by a rounding error); touching walls stay
// exactly touching, since equal inputs snap alike; and files stay short.
double Snap(double x) { return std::round(x * 256.0) / 256.0; }

}  // namespace

ObjectId AddBuilding(Scene* scene, std::string name, const std::vector<Prism>& input, bool snap) {
  std::vector<Prism> prisms = input;
  for (Prism& p : prisms) {
    if (!snap) break;
    for (glm::dvec2& q : p.footprint) q = glm::dvec2(Snap(q.x), Snap(q.y));
    p.z0 = Snap(p.z0);
    p.z1 = Snap(p.z1);
  }
  Mesh mesh;
  for (const Prism& p : prisms) AppendConvexPrism(p.footprint, p.z0, p.z1, &mesh);
  const ObjectId id = scene->AddObject(std::move(name), std::move(mesh));
  for (const Prism& p : prisms) {
    scene->occluders.push_back(Occluder25D{p.footprint, p.z1, id});
  }
  return id;
}

std::vector<glm::dvec2> FrameRect(const glm::dvec2& o, const glm::dvec2& u, const glm::dvec2& v,
                                  double u0, double u1, double v0, double v1) {
  return {o + u * u0 + v * v0, o + u * u1 + v * v0, o + u * u1 + v * v1, o + u * u0 + v * v1};
}

std::vector<glm::dvec2> ScaleAboutCentroid(const std::vector<glm::dvec2>& polygon, double factor,
                                           const glm::dvec2& shift) {
  glm::dvec2 c(0.0);
  for (const glm::dvec2& p : polygon) c += p;
  c /= static_cast<double>(polygon.size());
  std::vector<glm::dvec2> out;
  out.reserve(polygon.size());
  for (const glm::dvec2& p : polygon) out.push_back(c + shift + (p - c) * factor);
  return out;
}

}  // namespace vistream::scenes
