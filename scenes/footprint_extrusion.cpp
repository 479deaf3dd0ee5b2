#include "scenes/footprint_extrusion.h"

#include <absl/strings/str_cat.h>

#include <algorithm>
#include <utility>
#include <vector>

#include "scenes/mesh.h"
#include "scenes/occluder_tiers.h"
#include "scenes/polygon.h"
#include "scenes/polygon_set.h"

namespace vistream::scenes {

namespace {

bool IsBuilding(const Object& o) { return o.type == "Building" || o.type == "BuildingPart"; }

// The xy projections of the mesh's triangles with area, counter-clockwise.
std::vector<PolygonWithHoles> ProjectedTriangles(const Mesh& mesh) {
  std::vector<PolygonWithHoles> out;
  for (size_t t = 0; t + 2 < mesh.indices.size(); t += 3) {
    Ring r;
    for (int k = 0; k < 3; ++k) {
      const glm::vec3& p = mesh.positions[mesh.indices[t + k]];
      r.emplace_back(p.x, p.y);
    }
    const double area = SignedArea(r);
    if (area == 0.0) continue;  // a wall: its projection is a segment
    if (area < 0.0) std::swap(r[1], r[2]);
    out.push_back(PolygonWithHoles{std::move(r), {}});
  }
  return out;
}

}  // namespace

absl::StatusOr<Scene> ExtrudeFootprints(const Scene& scene, ExtrusionSummary* summary) {
  ExtrusionSummary sum;
  Scene out;
  out.name = scene.name + "-extruded";
  out.origin = scene.origin;
  out.crs = scene.crs;
  out.paths = scene.paths;
  std::vector<bool> terrain(scene.objects.size(), false);
  for (ObjectId id : scene.terrain) {
    if (id < terrain.size()) terrain[id] = true;
  }
  // Dense ids in input order.
  auto push = [&out](Object o) {
    o.id = static_cast<ObjectId>(out.objects.size());
    out.objects.push_back(std::move(o));
  };
  for (const Object& o : scene.objects) {
    if (terrain[o.id]) {
      ++sum.terrain_dropped;
      continue;
    }
    if (!IsBuilding(o)) {
      push(o);
      continue;
    }
    ++sum.buildings;
    auto keep = [&](const std::string& reason) {
      ++sum.not_extruded[reason];
      push(o);
    };
    const double top = o.bounds.max.z;
    if (!(top > 0.0)) {
      keep("no height above the ground level");
      continue;
    }
    absl::StatusOr<std::vector<PolygonWithHoles>> footprint = Union(ProjectedTriangles(o.mesh));
    if (!footprint.ok()) {
      keep("footprint union refused");
      continue;
    }
    Mesh mesh;
    std::vector<std::vector<glm::dvec2>> pieces;
    double area = 0.0;
    bool failed = false;
    for (const PolygonWithHoles& p : *footprint) {
      absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(p);
      if (!tris.ok()) {
        failed = true;
        break;
      }
      AppendPrism(p, *tris, 0.0, top, &mesh);
      for (const Triangle2& t : *tris) {
        pieces.push_back({t[0], t[1], t[2]});
        area += SignedArea(pieces.back());
      }
    }
    if (failed || mesh.indices.empty()) {
      keep(failed ? "footprint not triangulable" : "no footprint (vertical faces only)");
      continue;
    }
    const ObjectId id = static_cast<ObjectId>(out.objects.size());
    Object e;
    e.id = id;
    e.name = o.name;
    e.type = o.type;
    e.mesh = std::move(mesh);
    e.bounds = e.mesh.Bounds();
    push(std::move(e));
    for (std::vector<glm::dvec2>& piece : MergeConvexPieces(std::move(pieces))) {
      out.occluders.push_back(Occluder25D{std::move(piece), top, id});
      ++sum.occluders;
    }
    ++sum.extruded;
    sum.footprint_m2 += area;
  }
  // A flat ground over the input's extent (where its terrain reached): the same viewcell grid
  // as the input's, so that PVSs compare cell by cell.
  if (sum.terrain_dropped > 0 && !out.objects.empty()) {
    const Aabb& b = scene.bounds;
    Mesh ground;
    const glm::vec3 up(0.0f, 0.0f, 1.0f);
    const uint32_t v0 = AppendVertex({b.min.x, b.min.y}, 0.0, up, &ground);
    const uint32_t v1 = AppendVertex({b.max.x, b.min.y}, 0.0, up, &ground);
    const uint32_t v2 = AppendVertex({b.max.x, b.max.y}, 0.0, up, &ground);
    const uint32_t v3 = AppendVertex({b.min.x, b.max.y}, 0.0, up, &ground);
    ground.indices = {v0, v1, v2, v0, v2, v3};
    Object g;
    g.name = "flat ground";
    g.type = "ground";
    g.mesh = std::move(ground);
    g.bounds = g.mesh.Bounds();
    push(std::move(g));
  }
  for (const Object& o : out.objects) out.bounds.Extend(o.bounds);
  if (summary != nullptr) *summary = sum;
  if (out.objects.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("scene '", scene.name, "' has no object to keep but terrain"));
  }
  return out;
}

}  // namespace vistream::scenes
