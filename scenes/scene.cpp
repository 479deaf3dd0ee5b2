#include "scenes/scene.h"

#include <cstring>

#include <algorithm>
#include <cmath>

#include <absl/strings/str_cat.h>

namespace vistream::scenes {

size_t Scene::TriangleCount() const {
  size_t n = 0;
  for (const Object& o : objects) n += o.mesh.TriangleCount();
  return n;
}

size_t Scene::VertexCount() const {
  size_t n = 0;
  for (const Object& o : objects) n += o.mesh.positions.size();
  return n;
}

ObjectId Scene::AddObject(std::string object_name, Mesh mesh) {
  Object o;
  o.id = static_cast<ObjectId>(objects.size());
  o.name = std::move(object_name);
  o.mesh = std::move(mesh);
  o.bounds = o.mesh.Bounds();
  bounds.Extend(o.bounds);
  objects.push_back(std::move(o));
  return objects.back().id;
}

namespace {

bool Finite(const glm::vec3& p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

}  // namespace

absl::Status ValidateMesh(const Mesh& m, const std::string& what) {
  if (m.indices.size() % 3 != 0) {
    return absl::InvalidArgumentError(absl::StrCat(what, ": index count ", m.indices.size(), " is not a multiple of 3"));
  }
  if (m.normals.size() != m.positions.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat(what, ": ", m.normals.size(), " normals for ", m.positions.size(), " positions"));
  }
  for (size_t v = 0; v < m.positions.size(); ++v) {
    if (!Finite(m.positions[v])) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": vertex ", v, " has a non-finite (NaN or infinite) coordinate"));
    }
    if (!Finite(m.normals[v])) {
      return absl::InvalidArgumentError(absl::StrCat(what, ": normal ", v, " has a non-finite coordinate"));
    }
  }
  for (size_t k = 0; k < m.indices.size(); ++k) {
    if (m.indices[k] >= m.positions.size()) {
      return absl::InvalidArgumentError(absl::StrCat(what, ": index ", k, " = ", m.indices[k], " is out of range (",
                                                     m.positions.size(), " vertices)"));
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateScene(const Scene& scene, const std::string& where) {
  if (scene.objects.empty()) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": scene has no objects"));
  }
  if (!std::isfinite(scene.origin.x) || !std::isfinite(scene.origin.y) ||
      !std::isfinite(scene.origin.z)) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": scene origin is not finite"));
  }
  for (size_t i = 0; i < scene.objects.size(); ++i) {
    const Object& o = scene.objects[i];
    const std::string what = absl::StrCat(where, ": object ", i, " ('", o.name, "')");
    if (o.id != i) return absl::InternalError(absl::StrCat(what, ": id ", o.id, " is not dense"));
    if (absl::Status st = ValidateMesh(o.mesh, what); !st.ok()) return st;
  }
  for (size_t i = 0; i < scene.occluders.size(); ++i) {
    const Occluder25D& oc = scene.occluders[i];
    const std::string what = absl::StrCat(where, ": occluder ", i);
    if (oc.object >= scene.objects.size()) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": refers to object ", oc.object, ", which does not exist"));
    }
    if (oc.footprint.size() < 3) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": footprint has ", oc.footprint.size(), " vertices, needs 3"));
    }
    if (!std::isfinite(oc.height) || oc.height < 0.0) {
      return absl::InvalidArgumentError(
          absl::StrCat(what, ": height ", oc.height, " is not a finite non-negative number"));
    }
    for (const glm::dvec2& p : oc.footprint) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y)) {
        return absl::InvalidArgumentError(
            absl::StrCat(what, ": footprint has a non-finite coordinate"));
      }
    }
  }
  for (size_t i = 0; i < scene.terrain.size(); ++i) {
    if (scene.terrain[i] >= scene.objects.size()) {
      return absl::InvalidArgumentError(absl::StrCat(where, ": terrain object ", scene.terrain[i],
                                                     " does not exist"));
    }
    if (i > 0 && scene.terrain[i] <= scene.terrain[i - 1]) {
      return absl::InvalidArgumentError(
          absl::StrCat(where, ": terrain object ids are not sorted and distinct at ", scene.terrain[i]));
    }
  }
  for (size_t i = 0; i < scene.paths.size(); ++i) {
    const ScenePath& p = scene.paths[i];
    const std::string what = absl::StrCat(where, ": path ", i, " ('", p.name, "')");
    if (p.name.empty()) return absl::InvalidArgumentError(absl::StrCat(what, ": has no name"));
    if (p.waypoints.size() < 2) {
      return absl::InvalidArgumentError(absl::StrCat(what, ": needs at least 2 waypoints, has ", p.waypoints.size()));
    }
    for (const glm::dvec2& w : p.waypoints) {
      if (!std::isfinite(w.x) || !std::isfinite(w.y)) {
        return absl::InvalidArgumentError(absl::StrCat(what, ": a waypoint is not finite"));
      }
    }
  }
  return absl::OkStatus();
}

void NormalizeOccluders(Scene* scene) {
  for (Occluder25D& oc : scene->occluders) {
    auto& fp = oc.footprint;
    while (fp.size() > 3 && fp.front() == fp.back()) fp.pop_back();
    if (SignedArea(fp) < 0.0) std::reverse(fp.begin(), fp.end());
  }
}

namespace {
// Folds bytes into a running 64-bit state, eight at a time (splitmix64's finaliser as the mix).
class Digest {
 public:
  void Add(const void* data, size_t size) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (; size >= 8; size -= 8, p += 8) {
      uint64_t w;
      std::memcpy(&w, p, 8);
      Mix(w);
    }
    uint64_t tail = size;
    for (size_t k = 0; k < size; ++k) tail = tail << 8 | p[k];
    Mix(tail);
  }
  template <typename T>
  void Add(const T& v) {
    Add(&v, sizeof(T));
  }
  uint64_t value() const { return h_ == 0 ? 1 : h_; }

 private:
  void Mix(uint64_t w) {
    uint64_t z = (h_ ^ w) + 0x9e3779b97f4a7c15ULL;
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    h_ = z ^ (z >> 31);
  }
  uint64_t h_ = 0x76697374726561ULL;  // "vistrea"
};
}  // namespace

uint64_t SceneFingerprint(const Scene& scene) {
  Digest d;
  d.Add(uint64_t{scene.objects.size()});
  for (const Object& o : scene.objects) {
    d.Add(uint64_t{o.mesh.positions.size()});
    d.Add(o.mesh.positions.data(), o.mesh.positions.size() * sizeof(glm::vec3));
    d.Add(uint64_t{o.mesh.indices.size()});
    d.Add(o.mesh.indices.data(), o.mesh.indices.size() * sizeof(uint32_t));
  }
  d.Add(uint64_t{scene.occluders.size()});
  for (const Occluder25D& oc : scene.occluders) {
    d.Add(oc.object);
    d.Add(oc.height);
    d.Add(uint64_t{oc.footprint.size()});
    d.Add(oc.footprint.data(), oc.footprint.size() * sizeof(glm::dvec2));
  }
  // Terrain decides the viewcells' bands; scenes without it keep the digests they always had.
  if (!scene.terrain.empty()) {
    d.Add(uint64_t{0x7465727261696eULL});  // "terrain"
    d.Add(uint64_t{scene.terrain.size()});
    d.Add(scene.terrain.data(), scene.terrain.size() * sizeof(ObjectId));
  }
  return d.value();
}

}  // namespace vistream::scenes
