#pragma once
// ε-superset visibility (Cohen-Or & Zadicario 1998): a conservative superset of the triangles
// visible from anywhere in a small box around the viewpoint, so that a client can draw far
// less than its viewcell's PVS while it stays inside the box.
//
// An occludee (an object's box, then each triangle of the objects whose box survived) is
// hidden when one convex occluder is crossed by every segment from a corner of the box to a
// vertex of the occludee. Each occluder is a convex prism (a convex piece of an occluder
// footprint, up to its height and down beneath the ground: the ground z = 0 is solid, so a
// segment along it through a footprint is blocked), and the segment must pass through its interior
// shrunk by kShrinkM, and by twice the distance rounding to float moves its corners (the
// meshes are single precision, the occluders double, so an occludee's face may lie microns
// inside its own occluder): grazing an edge or touching a face never hides anything. The first
// segment gathers every prism it crosses with one Embree all-hits traversal; the others are
// tested against that candidate list only, nearest candidate first.
//
// Why that is enough (the paper's argument, made precise): for a convex prism O and a fixed
// end p, the points e for which segment e-p crosses O form a convex set, and so, for fixed e,
// do the points p. So if every corner of the box sees every vertex through O, every point of
// the box sees every point of the occludee through O. O lies inside its object's solid, so a
// segment through O passes through that solid's surface before it reaches p, provided e is
// outside the solid: the prisms of an object whose box meets the neighbourhood are not used.

#include <cstdint>
#include <memory>
#include <span>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/scene.h"
#include "visibility/kdtree.h"

struct RTCIntersectFunctionNArguments;  // Embree's (embree3/rtcore_geometry.h)

namespace vistream::visibility {

using scenes::Aabb;
using scenes::ObjectId;

// The optimisations of the paper's Table 2, each a switch.
struct EpsilonOptions {
  bool boxes = true;                  // test object boxes first, then triangles of the survivors
  bool drop_hidden_occluders = true;  // an object whose box is hidden stops being an occluder
  bool silhouette_rays = true;        // skip the rays that others imply (redundant rays)
  // Beyond the paper: test kd-tree node boxes top-down before the objects' own;
  bool hierarchy = true;
  // and before tracing, try the prisms that hid the last occludees (and, testing triangles
  // one by one, the triangle's own object's, which hide the object's far side); a traversal
  // then stops at the first hider it meets;
  bool hints = true;
  // and share the work of an object's triangles through its distinct vertices: each vertex's
  // rays are built once, remembers the last prism found to hide it and the last found not
  // to, and once a traversal shows that no prism hides it alone, every triangle that has it
  // is kept without more tests. A triangle is then tried on the last hiders (with hints)
  // and traced from one vertex, stopping at the first prism that hides all three (the same
  // test as with it off: one prism crossed by every ray of the triangle).
  bool shared_vertices = true;
  // A column of Table 2: none, boxes, occluders, rays, all; or paper, the paper's fully
  // optimised column (all but this project's additions).
  static absl::StatusOr<EpsilonOptions> FromName(std::string_view name);
};

struct EpsilonStats {
  uint64_t total_boxes = 0;        // object boxes considered (0 when boxes are off)
  uint64_t occluded_boxes = 0;
  uint64_t first_occluders = 0;    // hidden boxes whose occluder was the first one met
  uint64_t total_triangles = 0;    // triangles of the objects considered
  uint64_t visible_triangles = 0;  // in the superset
  uint64_t tested_triangles = 0;   // triangles of the objects whose box survived
  uint64_t rays = 0;               // box-corner to occludee-vertex rays tested
  uint64_t skipped_rays = 0;       // rays left out as implied by others
  uint64_t traversals = 0;         // Embree traversals (one per occludee that the hints did not settle)
  uint64_t box_ray_tests = 0;      // exact ray / prism tests while testing boxes
  uint64_t polygon_ray_tests = 0;  // exact ray / prism tests while testing triangles
  double box_ms = 0.0, polygon_ms = 0.0, ms = 0.0;
};

struct EpsilonResult {
  std::vector<uint32_t> triangles;  // visible triangles, as EpsilonSuperset::TriangleId; sorted
  std::vector<ObjectId> objects;    // objects with at least one visible triangle; sorted
  EpsilonStats stats;
};

class EpsilonSuperset {
 public:
  // A segment must pass this far inside a prism (metres) to count as crossing it.
  static constexpr double kShrinkM = 1e-6;

  // Prepares the convex prisms of `scene`'s occluders and their Embree scene. `scene` is kept
  // by reference and must outlive the result. Fails only if Embree cannot start.
  static absl::StatusOr<std::unique_ptr<EpsilonSuperset>> Create(const scenes::Scene& scene);
  ~EpsilonSuperset();
  EpsilonSuperset(const EpsilonSuperset&) = delete;
  EpsilonSuperset& operator=(const EpsilonSuperset&) = delete;

  // The superset for the neighbourhood `box` (scene-local metres; a zero-size box is a single
  // viewpoint), over every object, on the calling thread. Thread-safe. Viewpoints stand on or
  // above the ground: the part of `box` below z = 0 is left out (a box wholly below it counts
  // as its footprint on the ground).
  EpsilonResult Compute(const Aabb& box, const EpsilonOptions& options) const;
  // The same over `objects` only, distinct ids (e.g. the viewcell's PVS: what it leaves out
  // stays out). Every prism still occludes.
  EpsilonResult Compute(const Aabb& box, const EpsilonOptions& options, std::span<const ObjectId> objects) const;
  // Several neighbourhoods on up to `threads` threads (0: one per core); results in order.
  std::vector<EpsilonResult> ComputeBatch(std::span<const Aabb> boxes, const EpsilonOptions& options,
                                          unsigned threads = 0) const;

  // Triangle `index` of object `object` as one dense id over the scene, and back.
  uint32_t TriangleId(ObjectId object, uint32_t index) const { return triangle_base_[object] + index; }
  ObjectId ObjectOfTriangle(uint32_t id) const;
  // Convex prisms the occluders were decomposed into (degenerate footprints give none).
  size_t prism_count() const { return prisms_.size(); }
  const scenes::Scene& scene() const { return scene_; }

 private:
  struct Prism {
    uint32_t first_edge = 0, edge_count = 0;
    double height = 0.0;
    double shrink = 0.0;  // metres: kShrinkM and the float rounding of the corners
    ObjectId object = 0;
  };
  struct Embree;
  struct Query;
  friend struct Query;
  // Embree's intersect callback for the prisms' user geometry (Query::Intersect, defined
  // beside the query in epsilon_superset.cpp), for Create to register.
  static void IntersectPrisms(const RTCIntersectFunctionNArguments* args);

  explicit EpsilonSuperset(const scenes::Scene& scene);

  // Whether segment q + e + t·d (t in [0, 1]) passes through prism `i` shrunk by its shrink,
  // over a positive length; *t_in is where it enters.
  bool Crosses(uint32_t i, const glm::dvec3& q, const glm::dvec3& e, const glm::dvec3& d, double* t_in) const;

  const scenes::Scene& scene_;
  std::vector<Prism> prisms_;
  struct Edge {
    double nx, ny, ax, ay;  // the unit inward normal, a point of the wall
  };
  std::vector<Edge> edges_;
  std::vector<glm::dvec3> prism_min_, prism_max_;    // prism boxes, for Embree
  std::vector<uint32_t> triangle_base_;              // per object, plus the total at the end
  std::vector<uint32_t> object_prism_start_, object_prisms_;  // the prisms of each object
  // Distinct vertex positions of each object (from vertex_start_[object]), and for each
  // triangle corner (3 per TriangleId) its position's index among its object's.
  std::vector<uint32_t> vertex_start_, triangle_vertex_;
  std::vector<glm::vec3> vertices_;
  std::span<const uint32_t> PrismsOf(ObjectId object) const {
    return {object_prisms_.data() + object_prism_start_[object], object_prism_start_[object + 1] - object_prism_start_[object]};
  }
  KdTree tree_;                                      // over every object
  glm::dvec3 frame_{0.0};                            // Embree works in floats relative to this
  std::unique_ptr<Embree> embree_;
};

// The paper's neighbourhood size: a quarter of a typical object, taken as the median over
// objects of the mean of their box's x and y extents.
double TypicalObjectSize(const scenes::Scene& scene);

// `count` random ground-level neighbourhoods: boxes of edge `size` whose bottom is `base`
// above the ground (over terrain: above the highest ground under the box), uniform over the
// scene's extent, none meeting an object's box but the terrain's (the viewer walks the
// streets). Deterministic for a seed; fewer if the streets are hard to hit.
std::vector<Aabb> SampleNeighbourhoods(const scenes::Scene& scene, size_t count, double size, double base,
                                       uint64_t seed);

}  // namespace vistream::visibility
