#pragma once
// Faces that lie on one another with opposite orientation: the party wall of two touching
// buildings (each has its own wall, facing away from it, in the same place), a tier's floor on
// the roof below it. Nothing outside a solid can reach such a face: it is covered by the solid
// on its other side. A ray that hits one started inside that solid, so the hit says nothing
// about what can be seen, whichever of the two coincident faces the ray tracer reports (the
// ray tracer breaks the tie arbitrarily, and the face in front of the ray is the one whose
// back-face test passes). Ray samplers use this to discard such rays (AGVS, Bittner et al.
// 2009, section 8: samples that start inside objects are discarded).

#include <cstdint>
#include <memory>
#include <span>
#include <unordered_map>
#include <vector>

#include <glm/vec3.hpp>

namespace vistream::visibility {

// One triangle of one mesh.
struct FaceRef {
  uint32_t mesh = 0;
  uint32_t triangle = 0;  // index of the triangle (indices[3 t .. 3 t + 2])
  friend bool operator==(const FaceRef&, const FaceRef&) = default;
};

// A mesh as the finder reads it: positions (any frame, metres) and three indices a triangle,
// counter-clockwise seen from outside.
struct MeshView {
  std::span<const glm::vec3> positions;
  std::span<const uint32_t> indices;
};

// Per mesh, each of its triangles that lies on a triangle of opposite orientation (of any
// mesh, itself included), with those triangles: sorted by triangle, one entry per partner.
struct CoincidentFaces {
  struct Entry {
    uint32_t triangle;
    FaceRef partner;
  };
  std::vector<std::vector<Entry>> of_mesh;

  // The partners of triangle `t` of mesh `m`.
  std::span<const Entry> Partners(uint32_t m, uint32_t t) const;
};

// Asks whether a point lies on one of a triangle's partners (PointOnTriangle over
// CoincidentFaces::Partners), answering from the few whose box holds the point where a triangle
// has many: a flat ground rectangle under the floors of every building standing on it (`scene
// extrude`'s ground) has thousands, and a ray sampler asks at every hit on it.
class PartnerLookup {
 public:
  // A triangle with more partners than this has its partners' boxes in a kd-tree.
  static constexpr size_t kIndexedPartners = 16;

  PartnerLookup() = default;
  // `faces` as FindCoincidentFaces found them in `meshes`: the faces and the meshes' data must
  // outlive the lookup and stay unchanged (build a new lookup after an edit).
  PartnerLookup(const CoincidentFaces& faces, std::vector<MeshView> meshes);

  // Whether `p` (the meshes' frame, metres) lies on a partner of triangle `t` of mesh `m`, up
  // to `tolerance` metres (PointOnTriangle): the same answer as testing every partner.
  bool OnPartner(uint32_t m, uint32_t t, const glm::dvec3& p, double tolerance) const;

  // Triangles whose partners are in a kd-tree.
  size_t IndexedTriangles() const { return indexed_.size(); }

 private:
  struct Indexed;
  bool OnFace(const FaceRef& f, const glm::dvec3& p, double tolerance) const;

  const CoincidentFaces* faces_ = nullptr;
  std::vector<MeshView> meshes_;
  std::unordered_map<uint64_t, std::shared_ptr<const Indexed>> indexed_;  // key: mesh << 32 | triangle
};

// Finds the coincident pairs: planes within `tolerance` metres of each other (every corner of
// each triangle within it of the other's plane, normals opposite within 0.01 radians) and
// triangles whose overlap in that plane is wider than `tolerance`. Degenerate triangles have
// no partner. Expected O(n log n) in the triangle count: triangles are bucketed by plane.
CoincidentFaces FindCoincidentFaces(std::span<const MeshView> meshes, double tolerance = 1e-3);

// Whether point `p` lies on triangle (a, b, c), up to `tolerance` metres from the triangle
// within its plane and from the plane. Used at a hit: is the hit point on the partner too?
bool PointOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c,
                     double tolerance);

}  // namespace vistream::visibility
