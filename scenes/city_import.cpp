#include "scenes/city_import.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <unordered_map>
#include <utility>

#include <absl/strings/ascii.h>
#include <absl/strings/match.h>
#include <absl/strings/numbers.h>
#include <absl/strings/str_cat.h>
#include <absl/strings/str_format.h>
#include <absl/strings/str_join.h>
#include <glm/geometric.hpp>

#include "scenes/derived_ground.h"
#include "scenes/derived_walks.h"
#include "scenes/mesh.h"
#include "scenes/polygon.h"
#include "scenes/polygon_set.h"
#include "scenes/shell_closure.h"
#include "scenes/solid_check.h"
#include "scenes/solid_floor.h"

namespace vistream::scenes {

namespace {

namespace fs = std::filesystem;

double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// "2.2" -> 2.2; the integer part is the LoD `--lod` selects. None for text that is not a
// number from 0 to 4.x.
std::optional<double> ParseLod(const std::string& text) {
  double v = 0.0;
  if (!absl::SimpleAtod(text, &v) || !(v >= 0.0) || !(v < 5.0)) return std::nullopt;
  return v;
}

bool IsBuilding(const std::string& type) { return type == "Building" || type == "BuildingPart"; }
bool IsTerrain(const std::string& type) { return type == "TINRelief"; }
constexpr const char* kDerivedTerrainType = "DerivedTerrain";
// How far road walks keep from buildings (the catalog's walks keep a metre too).
constexpr double kWalkClearanceM = 1.0;
// The ground covers whose points a derived terrain takes (city_import.h "Ground without a TIN").
bool IsGroundSurface(const std::string& type) {
  return type == "Road" || type == "Railway" || type == "TransportSquare" || type == "LandUse" || type == "WaterBody";
}

// The geometries of `o` drawn at the chosen LoD: those whose LoD text is the best one
// (highest, or highest with integer part `lod`). Empty when none qualifies.
std::vector<const CityGeometry*> ChooseGeometries(const CityObject& o, std::optional<int> lod,
                                                  std::map<std::string, uint64_t>* skipped, std::string* chosen) {
  std::optional<double> best;
  std::string best_text;
  for (const CityGeometry& g : o.geometries) {
    const std::optional<double> v = ParseLod(g.lod);
    if (!v) {
      ++(*skipped)[absl::StrCat("geometry with an unreadable LoD ('", g.lod.substr(0, 16), "')")];
      continue;
    }
    if (lod && static_cast<int>(*v) != *lod) continue;
    if (!best || *v > *best) {
      best = v;
      best_text = g.lod;
    }
  }
  std::vector<const CityGeometry*> out;
  if (!best) return out;
  for (const CityGeometry& g : o.geometries) {
    const std::optional<double> v = ParseLod(g.lod);
    if (v && *v == *best) out.push_back(&g);
  }
  *chosen = best_text;
  return out;
}

// Every surface of a geometry, solids' shells included, with the solid it belongs to (-1 for
// surfaces of surface geometries).
template <typename Fn>
void ForEachSurface(const CityGeometry& g, Fn&& fn) {
  for (size_t s = 0; s < g.solids.size(); ++s) {
    for (const auto& shell : g.solids[s].shells) {
      for (const CitySurface& surface : shell) fn(surface, static_cast<int>(s));
    }
  }
  for (const CitySurface& surface : g.surfaces) fn(surface, -1);
}

// Points ordered by x, then y, then z: rings, terrain triangles and edges in an order that does
// not depend on how the file listed them.
bool LexLess(const glm::dvec3& a, const glm::dvec3& b) {
  return a.x != b.x ? a.x < b.x : (a.y != b.y ? a.y < b.y : a.z < b.z);
}

// A triangulated polygon in scene-local double coordinates.
struct Triangulated {
  std::vector<std::array<glm::dvec3, 3>> triangles;
  glm::dvec3 normal{0.0};  // unit, the ring's (Newell's) orientation
  bool dropped = false;    // a ring without area (fewer than 3 distinct points, or on a line)
};

// Removes consecutive duplicates (the closing point too) of a 3D ring; returns how many.
size_t DropDuplicates(std::vector<glm::dvec3>* ring) {
  size_t dropped = 0;
  std::vector<glm::dvec3> out;
  out.reserve(ring->size());
  for (const glm::dvec3& p : *ring) {
    if (!out.empty() && out.back() == p) {
      ++dropped;
      continue;
    }
    out.push_back(p);
  }
  while (out.size() > 1 && out.front() == out.back()) {
    out.pop_back();
    ++dropped;
  }
  *ring = std::move(out);
  return dropped;
}

// Triangulates one polygon (local coordinates). On failure returns the reason.
absl::StatusOr<Triangulated> TriangulateSurface(const CitySurface& surface, const glm::dvec3& origin,
                                                std::map<std::string, uint64_t>* repaired) {
  auto local = [&](const std::vector<glm::dvec3>& ring) {
    std::vector<glm::dvec3> out;
    out.reserve(ring.size());
    for (const glm::dvec3& p : ring) out.push_back(p - origin);
    return out;
  };
  std::vector<glm::dvec3> outer = local(surface.outer);
  if (size_t d = DropDuplicates(&outer); d > 0) (*repaired)["duplicate points dropped"] += d;
  // Every ring from its least point: the same polygon triangulates the same way whichever
  // vertex a file starts it at (a rectangle has two Delaunay diagonals).
  auto least_first = [](std::vector<glm::dvec3>* ring) {
    std::rotate(ring->begin(), std::min_element(ring->begin(), ring->end(), LexLess), ring->end());
  };
  least_first(&outer);
  Triangulated out;
  // A ring of fewer than 3 distinct points, or one whose points all lie on a line (a wall
  // written as [a, a, b, b]: LoD2 surface models have them), bounds nothing: its edges go
  // there and back, so leaving it out opens nothing. Dropped, not an error.
  const glm::dvec3 n = outer.size() < 3 ? glm::dvec3(0.0) : NewellNormal(outer);
  const double len = glm::length(n);
  if (!(len > 0.0)) {
    bool collinear = true;
    for (size_t i = 2; i < outer.size() && collinear; ++i) {
      collinear = glm::length(glm::cross(outer[1] - outer[0], outer[i] - outer[0])) == 0.0;
    }
    if (!collinear) return absl::InvalidArgumentError("a polygon without area");
    out.dropped = true;
    return out;
  }
  out.normal = n / len;
  // Project on the plane of the dominant axis; keep the 2D -> 3D correspondence.
  const glm::dvec3 an = glm::abs(n);
  const int drop = an.z >= an.x && an.z >= an.y ? 2 : (an.y >= an.x ? 1 : 0);
  const int u = drop == 0 ? 1 : 0, v = drop == 2 ? 1 : 2;
  // Seen along +axis the (u, v) plane is counter-clockwise for a positive normal component
  // when (u, v) is (x, y), (z, x) or (y, z); with (x, z) for drop == 1 the sign flips.
  const bool flip = (n[drop] < 0.0) != (drop == 1);
  std::map<std::pair<double, double>, glm::dvec3> lift;
  auto project = [&](const std::vector<glm::dvec3>& ring) {
    Ring r;
    r.reserve(ring.size());
    for (const glm::dvec3& p : ring) {
      r.emplace_back(p[u], p[v]);
      lift.emplace(std::make_pair(p[u], p[v]), p);
    }
    return r;
  };
  if (outer.size() == 3 && surface.holes.empty()) {
    // A triangle (TIN patches): nothing to triangulate.
    out.triangles.push_back({outer[0], outer[1], outer[2]});
    return out;
  }
  PolygonWithHoles poly;
  poly.outer = project(outer);
  RingRepairs rr = CleanRing(&poly.outer);
  if (SignedArea(poly.outer) < 0.0) std::reverse(poly.outer.begin(), poly.outer.end());
  for (const auto& hole3 : surface.holes) {
    std::vector<glm::dvec3> h = local(hole3);
    if (size_t d = DropDuplicates(&h); d > 0) (*repaired)["duplicate points dropped"] += d;
    if (!h.empty()) least_first(&h);
    Ring r = project(h);
    const RingRepairs hr = CleanRing(&r);
    rr.duplicate_points += hr.duplicate_points;
    rr.spikes += hr.spikes;
    if (r.size() < 3) {
      ++(*repaired)["degenerate inner rings dropped"];
      continue;
    }
    if (SignedArea(r) > 0.0) std::reverse(r.begin(), r.end());
    poly.holes.push_back(std::move(r));
  }
  if (rr.duplicate_points > 0) (*repaired)["duplicate points dropped"] += rr.duplicate_points;
  if (rr.spikes > 0) (*repaired)["spikes removed"] += rr.spikes;
  absl::StatusOr<std::vector<Triangle2>> tris = Triangulate(poly);
  if (!tris.ok()) return tris.status();
  out.triangles.reserve(tris->size());
  for (const Triangle2& t : *tris) {
    std::array<glm::dvec3, 3> t3;
    for (int k = 0; k < 3; ++k) {
      auto it = lift.find({t[k].x, t[k].y});
      if (it == lift.end()) return absl::InternalError("a triangle corner that is not a ring point");
      t3[k] = it->second;
    }
    if (flip) std::swap(t3[1], t3[2]);
    out.triangles.push_back(t3);
  }
  return out;
}

// Terrain triangles in a grid, for the ground's lowest height under a box.
class GroundIndex {
 public:
  GroundIndex(const std::vector<std::array<glm::dvec3, 3>>& triangles, double cell) : cell_(cell), tris_(triangles) {
    for (const auto& t : tris_) {
      for (const auto& p : t) box_.Extend(p);
    }
    if (tris_.empty()) return;
    // At most 1024 cells a side, whatever the file's extent.
    cell_ = std::max(cell_, std::max(box_.max.x - box_.min.x, box_.max.y - box_.min.y) / 1024.0);
    if (!std::isfinite(cell_)) cell_ = std::numeric_limits<double>::max();
    nx_ = std::clamp(static_cast<int>(std::ceil((box_.max.x - box_.min.x) / cell_)), 1, 1024);
    ny_ = std::clamp(static_cast<int>(std::ceil((box_.max.y - box_.min.y) / cell_)), 1, 1024);
    cells_.resize(static_cast<size_t>(nx_) * ny_);
    for (uint32_t k = 0; k < tris_.size(); ++k) {
      int i0, j0, i1, j1;
      Range(TriBox(tris_[k]), &i0, &j0, &i1, &j1);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) cells_[static_cast<size_t>(j) * nx_ + i].push_back(k);
      }
    }
  }

  // A height at or below the terrain everywhere inside the xy box: the lowest vertex of the
  // terrain triangles meeting it, or 0 (the flat ground beyond the terrain) when a corner of
  // the box lies on no terrain triangle or none meets it.
  double LowestUnder(const Aabb& box) const {
    if (tris_.empty()) return 0.0;
    for (const glm::dvec2& c : {glm::dvec2(box.min.x, box.min.y), glm::dvec2(box.max.x, box.min.y),
                                glm::dvec2(box.min.x, box.max.y), glm::dvec2(box.max.x, box.max.y)}) {
      if (!Covered(c)) return 0.0;
    }
    int i0, j0, i1, j1;
    Range(box, &i0, &j0, &i1, &j1);
    double lowest = std::numeric_limits<double>::infinity();
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        for (uint32_t k : cells_[static_cast<size_t>(j) * nx_ + i]) {
          const Aabb tb = TriBox(tris_[k]);
          // Triangles that only touch the box's border add nothing: the surface there is
          // also the height of a triangle reaching inside.
          if (tb.max.x <= box.min.x || tb.min.x >= box.max.x || tb.max.y <= box.min.y || tb.min.y >= box.max.y) continue;
          lowest = std::min(lowest, tb.min.z);
        }
      }
    }
    return std::isfinite(lowest) ? lowest : 0.0;
  }

  // The ground under the xy box for SynthesizeOccluders: the terrain triangles meeting it,
  // flat at 0 elsewhere.
  GroundSurface Under(const Aabb& box) const {
    GroundSurface g;
    if (tris_.empty()) return g;
    int i0, j0, i1, j1;
    Range(box, &i0, &j0, &i1, &j1);
    std::vector<uint32_t> ids;
    for (int j = j0; j <= j1; ++j) {
      for (int i = i0; i <= i1; ++i) {
        for (uint32_t k : cells_[static_cast<size_t>(j) * nx_ + i]) {
          const Aabb tb = TriBox(tris_[k]);
          if (tb.max.x < box.min.x || tb.min.x > box.max.x || tb.max.y < box.min.y || tb.min.y > box.max.y) continue;
          ids.push_back(k);
        }
      }
    }
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    for (uint32_t k : ids) g.triangles.push_back(tris_[k]);
    return g;
  }

 private:
  static Aabb TriBox(const std::array<glm::dvec3, 3>& t) {
    Aabb b;
    for (const auto& p : t) b.Extend(p);
    return b;
  }
  void Range(const Aabb& b, int* i0, int* j0, int* i1, int* j1) const {
    auto clampi = [](double v, int n) { return v >= 0.0 ? static_cast<int>(std::min(std::floor(v), n - 1.0)) : 0; };
    *i0 = clampi((b.min.x - box_.min.x) / cell_, nx_);
    *i1 = clampi((b.max.x - box_.min.x) / cell_, nx_);
    *j0 = clampi((b.min.y - box_.min.y) / cell_, ny_);
    *j1 = clampi((b.max.y - box_.min.y) / cell_, ny_);
  }
  bool Covered(const glm::dvec2& p) const {
    if (p.x < box_.min.x || p.x > box_.max.x || p.y < box_.min.y || p.y > box_.max.y) return false;
    int i0, j0, i1, j1;
    Aabb b;
    b.Extend(glm::dvec3(p, 0.0));
    Range(b, &i0, &j0, &i1, &j1);
    for (uint32_t k : cells_[static_cast<size_t>(j0) * nx_ + i0]) {
      const auto& t = tris_[k];
      auto side = [&](const glm::dvec3& a, const glm::dvec3& c) {
        return (c.x - a.x) * (p.y - a.y) - (c.y - a.y) * (p.x - a.x);
      };
      const double d1 = side(t[0], t[1]), d2 = side(t[1], t[2]), d3 = side(t[2], t[0]);
      if ((d1 >= 0 && d2 >= 0 && d3 >= 0) || (d1 <= 0 && d2 <= 0 && d3 <= 0)) return true;
    }
    return false;
  }

  double cell_;
  const std::vector<std::array<glm::dvec3, 3>>& tris_;
  Aabb box_;
  int nx_ = 0, ny_ = 0;
  std::vector<std::vector<uint32_t>> cells_;
};

// Appends triangles (local double) to a flat-shaded mesh with `normal`.
void AppendTriangles(const std::vector<std::array<glm::dvec3, 3>>& tris, const glm::dvec3& normal, Mesh* mesh) {
  const glm::vec3 n(normal);
  for (const auto& t : tris) {
    for (const glm::dvec3& p : t) {
      mesh->indices.push_back(static_cast<uint32_t>(mesh->positions.size()));
      mesh->positions.emplace_back(glm::vec3(p));
      mesh->normals.push_back(n);
    }
  }
}

// A solid's triangles as SynthesizeOccluders takes them: the mesh's single-precision
// positions, so that the prisms are inside the geometry that is drawn and checked.
SolidMesh SolidFromTriangles(const std::vector<std::array<glm::dvec3, 3>>& tris) {
  Mesh mesh;
  AppendTriangles(tris, glm::dvec3(0.0, 0.0, 1.0), &mesh);
  return SolidMeshFromMesh(mesh);
}

}  // namespace

uint64_t CityImportSummary::Skipped() const {
  uint64_t n = 0;
  for (const auto& [reason, k] : skipped) n += k;
  return n;
}

uint64_t CityImportSummary::Repaired() const {
  uint64_t n = 0;
  for (const auto& [reason, k] : repaired) n += k;
  return n;
}

absl::StatusOr<Scene> BuildCityScene(const CityModel& model, const std::string& name,
                                     const CityImportOptions& options, CityImportSummary* summary_out,
                                     const RunControl& run) {
  const auto start = std::chrono::steady_clock::now();
  CityImportSummary local_summary;
  CityImportSummary& sum = summary_out != nullptr ? *summary_out : local_summary;
  sum.format = model.format;
  if (!options.crs.empty() && !IsCrsName(options.crs)) {
    return absl::InvalidArgumentError(absl::StrCat("'", options.crs,
                                                   "' names no coordinate reference system (expected AUTHORITY:CODE, "
                                                   "such as EPSG:28992)"));
  }
  sum.crs = model.crs.empty() ? options.crs : model.crs;
  if (!options.crs.empty() && !model.crs.empty() && options.crs != model.crs) {
    return absl::InvalidArgumentError(absl::StrCat("the file's coordinate reference system is ", model.crs,
                                                   ", not ", options.crs, " as the import was told"));
  }
  if (IsGeographicCrs(sum.crs)) {
    return absl::InvalidArgumentError(absl::StrCat(
        sum.crs, model.crs.empty() ? " (as the import was told)" : " (the file's)",
        " is a geographic coordinate reference system, in degrees: vistream reads projected coordinates in metres "
        "and reprojects nothing; reproject the model first (cjio's crs_reproject, or ogr2ogr)"));
  }
  for (const auto& [reason, n] : model.skipped) sum.skipped[reason] += n;
  for (const auto& [reason, n] : model.repaired) sum.repaired[reason] += n;
  if (options.lod && (*options.lod < 0 || *options.lod > 4)) {
    return absl::InvalidArgumentError(absl::StrCat("--lod ", *options.lod, " is not a level of detail (0 to 4)"));
  }
  if (!(options.terrain_tile_m > 0.0) || !std::isfinite(options.terrain_tile_m)) {
    return absl::InvalidArgumentError("the terrain tile size must be a positive number of metres");
  }

  // 1. What each object draws.
  struct Chosen {
    const CityObject* object;
    std::vector<const CityGeometry*> geometries;
  };
  std::vector<Chosen> chosen;
  std::vector<Chosen> terrain;
  sum.city_objects = model.objects.size();
  for (const CityObject& o : model.objects) {
    ++sum.objects_by_type[o.type];
    if (o.type == "Building") ++sum.buildings;
    if (o.type == "BuildingPart") ++sum.building_parts;
    if (o.geometries.empty()) continue;
    std::string lod_text;
    const bool is_terrain = IsTerrain(o.type);
    std::vector<const CityGeometry*> g =
        ChooseGeometries(o, is_terrain ? std::nullopt : options.lod, &sum.skipped, &lod_text);
    if (g.empty()) {
      if (options.lod) ++sum.skipped[absl::StrCat("no LoD ", *options.lod, " geometry")];
      continue;
    }
    ++sum.lods[lod_text];
    (is_terrain ? terrain : chosen).push_back({&o, std::move(g)});
  }

  // 2. The frame: origin at the rounded centre, z at the ground level.
  Aabb world;
  Aabb terrain_box;
  // Per axis, the objects holding the least and the greatest coordinate (for the error below).
  std::array<const CityObject*, 3> least{}, most{};
  for (const auto* list : {&chosen, &terrain}) {
    for (const Chosen& c : *list) {
      for (const CityGeometry* g : c.geometries) {
        ForEachSurface(*g, [&](const CitySurface& s, int) {
          auto extend = [&](const glm::dvec3& p) {
            for (int k = 0; k < 3; ++k) {
              if (world.Empty() || p[k] < world.min[k]) least[k] = c.object;
              if (world.Empty() || p[k] > world.max[k]) most[k] = c.object;
            }
            world.Extend(p);
            if (list == &terrain) terrain_box.Extend(p);
          };
          for (const glm::dvec3& p : s.outer) extend(p);
          for (const auto& hole : s.holes) {
            for (const glm::dvec3& p : hole) extend(p);
          }
        });
      }
    }
  }
  // One city: a coordinate thousands of kilometres off the rest is a mistake in the data (and
  // would leave the scene's single-precision meshes and its grids without meaning).
  for (int k = 0; k < 3 && !world.Empty(); ++k) {
    const double span = world.max[k] - world.min[k];
    if (!(span <= kMaxCitySpanM)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "the data spans %g m in %c, from object '%s' (%.17g) to object '%s' (%.17g): more than %g km; "
          "is a coordinate wrong?",
          span, "xyz"[k], least[k]->id, world.min[k], most[k]->id, world.max[k], kMaxCitySpanM / 1000.0));
    }
  }
  if (world.Empty()) {
    std::vector<std::string> reasons;
    for (const auto& [reason, n] : sum.skipped) reasons.push_back(absl::StrCat(reason, ": ", n));
    return absl::InvalidArgumentError(
        absl::StrCat("no city object with geometry to draw (", model.objects.size(), " objects read",
                     reasons.empty() ? "" : "; skipped: " + absl::StrJoin(reasons, ", "), ")"));
  }
  const glm::dvec3 origin(std::round(world.Centre().x), std::round(world.Centre().y),
                          terrain_box.Empty() ? world.min.z : terrain_box.min.z);
  if (!terrain_box.Empty()) {
    sum.terrain_min_z = terrain_box.min.z;
    sum.terrain_max_z = terrain_box.max.z;
  }

  Scene scene;
  scene.name = name;
  scene.origin = origin;
  scene.crs = sum.crs;

  // 3. Terrain: its triangles, tiled.
  std::vector<std::array<glm::dvec3, 3>> terrain_tris;
  for (const Chosen& c : terrain) {
    ++sum.terrain_objects;
    for (const CityGeometry* g : c.geometries) {
      ForEachSurface(*g, [&](const CitySurface& s, int) {
        absl::StatusOr<Triangulated> t = TriangulateSurface(s, origin, &sum.repaired);
        if (!t.ok()) {
          ++sum.skipped[absl::StrCat("terrain polygon not triangulated: ", t.status().message())];
          return;
        }
        if (t->dropped) {
          ++sum.repaired["rings without area dropped"];
          return;
        }
        ++sum.surfaces;
        for (auto tri : t->triangles) {
          // Terrain faces up: wind every triangle counter-clockwise from above.
          const double cross = (tri[1].x - tri[0].x) * (tri[2].y - tri[0].y) - (tri[1].y - tri[0].y) * (tri[2].x - tri[0].x);
          if (cross == 0.0) {
            ++sum.repaired["vertical terrain triangles dropped"];
            continue;
          }
          if (cross < 0.0) std::swap(tri[1], tri[2]);
          // The single-precision positions the mesh will hold.
          for (auto& p : tri) p = glm::dvec3(glm::vec3(p));
          terrain_tris.push_back(tri);
        }
      });
    }
  }
  if (!terrain_tris.empty()) sum.terrain_from = "TIN";

  // 4. Objects: meshes, floors closed; their solids wait for the ground.
  std::vector<std::vector<glm::dvec2>> roads;  // Road surfaces' outer rings, xy, for walks
  const bool derive_ground = terrain.empty() && options.ground == CityGround::kDerived;
  DerivedGroundInput ground_input;
  // A solid for the synthesis: its triangles and whether every polygon of it was triangulated.
  struct PendingSolid {
    std::vector<std::array<glm::dvec3, 3>> triangles;
    bool complete = true;
  };
  struct PendingObject {
    ObjectId id;
    bool building;
    std::vector<PendingSolid> solids;
  };
  std::vector<PendingObject> pending;
  // A building shell's floor for the derived ground: its lowest faces (FloorTriangles), or
  // without any (a floorless shell) the points of its lowest edges. In the mesh's single
  // precision, so that the terrain meets the floor that is drawn exactly.
  auto add_ground = [&](const std::vector<std::array<glm::dvec3, 3>>& shell) {
    std::vector<std::array<glm::dvec3, 3>> f = FloorTriangles(shell);
    for (auto& t : f) {
      for (auto& p : t) p = glm::dvec3(glm::vec3(p));
    }
    if (!f.empty()) {
      ground_input.floors.push_back(std::move(f));
      return;
    }
    double lowest = std::numeric_limits<double>::infinity();
    for (const auto& t : shell) {
      for (const glm::dvec3& p : t) lowest = std::min(lowest, p.z);
    }
    for (const auto& t : shell) {
      for (const glm::dvec3& p : t) {
        if (p.z <= lowest + 1e-3) ground_input.points.push_back(glm::dvec3(glm::vec3(p)));
      }
    }
  };
  Progress progress(run, "building the city", 2 * chosen.size() + 1);
  for (const Chosen& c : chosen) {
    if (progress.Cancelled()) return absl::CancelledError("city import cancelled");
    const CityObject& o = *c.object;
    if (o.type == "Road") {
      for (const CityGeometry* g : c.geometries) {
        ForEachSurface(*g, [&](const CitySurface& s, int) {
          std::vector<glm::dvec2> ring;
          for (const glm::dvec3& p : s.outer) ring.emplace_back(p.x - origin.x, p.y - origin.y);
          roads.push_back(std::move(ring));
        });
      }
    }
    const bool ground_surface = derive_ground && IsGroundSurface(o.type);
    Mesh mesh;
    // Per solid (index within the geometry list), its triangles; surfaces of surface
    // geometries of buildings are gathered as one candidate solid.
    std::vector<PendingSolid> solids;
    PendingSolid surface_shell;
    bool has_surface_shell = false;
    auto triangulate = [&](const CitySurface& s) -> std::optional<Triangulated> {
      absl::StatusOr<Triangulated> t = TriangulateSurface(s, origin, &sum.repaired);
      if (!t.ok()) {
        ++sum.skipped[absl::StrCat("polygon not triangulated: ", t.status().message())];
        return std::nullopt;
      }
      if (t->dropped) {
        ++sum.repaired["rings without area dropped"];
        return std::move(*t);
      }
      ++sum.surfaces;
      AppendTriangles(t->triangles, t->normal, &mesh);
      return std::move(*t);
    };
    for (const CityGeometry* g : c.geometries) {
      for (const CitySolid& solid : g->solids) {
        PendingSolid& out = solids.emplace_back();
        for (size_t sh = 0; sh < solid.shells.size(); ++sh) {
          std::vector<std::array<glm::dvec3, 3>> shell;
          bool shell_complete = true;
          for (const CitySurface& surface : solid.shells[sh]) {
            std::optional<Triangulated> t = triangulate(surface);
            if (!t) {
              shell_complete = false;
              continue;
            }
            shell.insert(shell.end(), t->triangles.begin(), t->triangles.end());
          }
          out.complete = out.complete && shell_complete;
          if (shell_complete) {
            const FloorResult floor = CloseFloor(shell);
            if (floor.outcome == FloorClosing::kClosed) {
              ++sum.repaired["solid closed with a floor"];
              AppendTriangles(floor.triangles, glm::dvec3(0.0, 0.0, -1.0), &mesh);
              shell.insert(shell.end(), floor.triangles.begin(), floor.triangles.end());
            } else if (floor.outcome == FloorClosing::kFailed) {
              ++sum.skipped[absl::StrCat("floor not closed: ", floor.why)];
            }
            // The exterior shell's floor is ground (a void's is not).
            if (derive_ground && IsBuilding(o.type) && sh == 0) add_ground(shell);
          }
          out.triangles.insert(out.triangles.end(), shell.begin(), shell.end());
        }
      }
      for (const CitySurface& surface : g->surfaces) {
        std::optional<Triangulated> t = triangulate(surface);
        if (ground_surface && t) {
          for (const auto& tri : t->triangles) {
            for (const glm::dvec3& p : tri) ground_input.points.push_back(glm::dvec3(glm::vec3(p)));
          }
        }
        if (!IsBuilding(o.type)) continue;
        if (!t) {
          surface_shell.complete = false;
          continue;
        }
        has_surface_shell = true;
        surface_shell.triangles.insert(surface_shell.triangles.end(), t->triangles.begin(), t->triangles.end());
      }
    }
    if (mesh.indices.empty()) {
      ++sum.skipped["object without a drawable polygon"];
      progress.Advance(2);
      continue;
    }
    const ObjectId id = scene.AddObject(o.id, std::move(mesh));
    scene.objects[id].type = o.type;
    if (has_surface_shell) {
      // A surface model's ground surfaces are ground as a solid's floor is (issue 46: files
      // without a TIN, such as Rotterdam's LoD2).
      if (derive_ground) add_ground(surface_shell.triangles);
      solids.push_back(std::move(surface_shell));
    }
    pending.push_back({id, IsBuilding(o.type), std::move(solids)});
    progress.Advance();
  }

  // The ground derived where the file has none.
  if (derive_ground) {
    const glm::dvec3 lo = world.min - origin, hi = world.max - origin;
    ground_input.lo = glm::dvec2(glm::vec2(glm::dvec2(lo)));
    ground_input.hi = glm::dvec2(glm::vec2(glm::dvec2(hi)));
    absl::StatusOr<DerivedGround> derived = DeriveGround(ground_input);
    if (derived.ok()) {
      sum.terrain_from = "derived";
      sum.ground_floors = derived->floors;
      sum.ground_floors_overlapping = derived->floors_overlapping;
      sum.ground_floor_points = derived->floor_points;
      sum.ground_surface_points = derived->surface_points;
      sum.ground_points_under_floors = derived->points_under_floors;
      sum.ground_corner_points = derived->corner_points;
      terrain_tris = std::move(derived->triangles);
      Aabb box;
      for (const auto& t : terrain_tris) {
        for (const glm::dvec3& p : t) box.Extend(p + origin);
      }
      sum.terrain_min_z = box.min.z;
      sum.terrain_max_z = box.max.z;
    } else {
      ++sum.skipped[absl::StrCat("ground not derived: ", derived.status().message())];
    }
  }

  // In a fixed order (by least corner), so that a TIN listed in any order gives the same tiles.
  for (auto& t : terrain_tris) std::rotate(t.begin(), std::min_element(t.begin(), t.end(), LexLess), t.end());
  std::sort(terrain_tris.begin(), terrain_tris.end(), [](const auto& a, const auto& b) {
    return std::lexicographical_compare(a.begin(), a.end(), b.begin(), b.end(), LexLess);
  });
  sum.terrain_triangles = terrain_tris.size();
  const GroundIndex ground(terrain_tris, 25.0);

  // Occluders of the objects' solids, on the ground. First each solid on its own; then the
  // building shells left open are closed by their neighbours and the ground where those close
  // them (scenes/shell_closure.h: surface models, issue 46), and synthesized again.
  struct Attempt {
    OccluderSynthesis r;
    std::string why;  // without an occluder: the reason
  };
  std::vector<std::vector<Attempt>> attempts(pending.size());
  std::vector<ShellToClose> shells;
  std::vector<std::pair<size_t, size_t>> shell_of;  // (pending, solid) of each entry of `shells`
  std::vector<double> ground_z_of(pending.size());
  for (size_t k = 0; k < pending.size(); ++k) {
    const PendingObject& po = pending[k];
    if (progress.Cancelled()) return absl::CancelledError("city import cancelled");
    const Aabb box = scene.objects[po.id].bounds;
    const double ground_z = ground_z_of[k] = ground.LowestUnder(box);
    const GroundSurface under = ground.Under(box);
    for (size_t i = 0; i < po.solids.size(); ++i) {
      const PendingSolid& solid = po.solids[i];
      Attempt& a = attempts[k].emplace_back();
      if (!solid.complete) {
        a.why = "a polygon could not be triangulated";
        continue;
      }
      a.r = SynthesizeOccluders(SolidFromTriangles(solid.triangles), ground_z, under, options.synthesis);
      if (a.r.defect != SolidDefect::kNone) a.why = SolidDefectName(a.r.defect);
      if (po.building) {
        shells.push_back({&solid.triangles, a.r.defect == SolidDefect::kOpen, under});
        shell_of.emplace_back(k, i);
      }
    }
    progress.Advance();
  }
  const std::vector<ShellClosure> closures = CloseShellsByNeighbours(shells);
  // A block of shells closed together (a bent party wall): its occluders synthesized once, on
  // the ground under all of it, and each house given the pieces within its own box (the
  // occluder set holds an occluder inside its object's box).
  auto close_block = [&](const ShellClosure& c) {
    Aabb box;
    for (uint32_t m : c.block) {
      for (const auto& t : closures[m].drawn) {
        for (const glm::dvec3& p : t) box.Extend(p);
      }
    }
    const double ground_z = ground.LowestUnder(box);
    OccluderSynthesis r = SynthesizeOccluders(SolidFromTriangles(c.triangles), ground_z, ground.Under(box),
                                              options.synthesis);
    if (r.defect != SolidDefect::kNone) {
      for (uint32_t m : c.block) {
        attempts[shell_of[m].first][shell_of[m].second].why =
            absl::StrCat(SolidDefectName(r.defect), " once closed with its neighbours");
      }
      return;
    }
    r.occluders = ShrinkOccluders(r.occluders, c.moved_m > 0.0 ? c.moved_m + 1e-6 : 0.0, options.synthesis.min_area_m2,
                                  ground_z);
    for (uint32_t m : c.block) {
      const auto [k, i] = shell_of[m];
      Aabb own;
      for (const auto& t : closures[m].drawn) {
        for (const glm::dvec3& p : t) own.Extend(p);
      }
      Attempt& a = attempts[k][i];
      a.r = OccluderSynthesis{};
      a.r.occluders = ClipOccluders(r.occluders, glm::dvec2(own.min), glm::dvec2(own.max), options.synthesis.min_area_m2);
      if (m == c.block.front()) {
        a.r.solid_volume_m3 = r.solid_volume_m3;
        a.r.occluder_volume_m3 = r.occluder_volume_m3;
      }
      a.why.clear();
      ++sum.repaired["shells closed by neighbours and ground"];
      ++sum.repaired["shells closed together with a neighbour (a bent party wall)"];
    }
  };
  for (size_t j = 0; j < closures.size(); ++j) {
    const ShellClosure& c = closures[j];
    if (c.outcome == ShellClosureOutcome::kNotOpen) continue;
    const auto [k, i] = shell_of[j];
    Attempt& a = attempts[k][i];
    if (c.outcome == ShellClosureOutcome::kClosedAsBlock) {
      if (c.block.front() == j) close_block(c);
      continue;
    }
    if (c.outcome != ShellClosureOutcome::kClosed) {
      a.why = ShellClosureName(c.outcome);
      continue;
    }
    OccluderSynthesis r =
        SynthesizeOccluders(SolidFromTriangles(c.triangles), ground_z_of[k], shells[j].ground, options.synthesis);
    if (r.defect != SolidDefect::kNone) {
      a.why = absl::StrCat(SolidDefectName(r.defect), " once closed by neighbours and ground");
      continue;
    }
    ++sum.repaired["shells closed by neighbours and ground"];
    // The closed shell lies within moved_m of the data: its prisms shrink by that much.
    r.occluders = ShrinkOccluders(r.occluders, c.moved_m > 0.0 ? c.moved_m + 1e-6 : 0.0, options.synthesis.min_area_m2,
                                  ground_z_of[k]);
    a.r = std::move(r);
    a.why.clear();
  }
  // Objects with an open shell draw it welded and split (ShellClosure::drawn): the surface the
  // occluders were made in, without the data's millimetre cracks between the shell and its
  // neighbours (through which a rasterizer sees into a building at the odd pixel), and with the
  // party walls the data leaves out towards a neighbour left open (through which a
  // viewer would see into this one).
  for (const ShellClosure& c : closures) {
    if (c.drawn_caps > 0) ++sum.repaired["party walls drawn towards a neighbour left open"];
  }
  {
    std::map<std::pair<size_t, size_t>, const ShellClosure*> redrawn;
    for (size_t j = 0; j < closures.size(); ++j) {
      if (!closures[j].drawn.empty()) redrawn[shell_of[j]] = &closures[j];
    }
    for (size_t k = 0; k < pending.size(); ++k) {
      if (redrawn.lower_bound({k, 0}) == redrawn.lower_bound({k + 1, 0})) continue;
      Mesh mesh;
      for (size_t i = 0; i < pending[k].solids.size(); ++i) {
        auto it = redrawn.find({k, i});
        const auto& tris = it != redrawn.end() ? it->second->drawn : pending[k].solids[i].triangles;
        for (const auto& t : tris) {
          const glm::dvec3 n = glm::cross(t[1] - t[0], t[2] - t[0]);
          const double len = glm::length(n);
          AppendTriangles({t}, len > 0.0 ? n / len : glm::dvec3(0.0, 0.0, 1.0), &mesh);
        }
      }
      Object& object = scene.objects[pending[k].id];
      object.mesh = std::move(mesh);
      object.bounds = object.mesh.Bounds();
      ++sum.repaired["objects drawn welded, split at T-junctions"];
    }
  }
  for (size_t k = 0; k < pending.size(); ++k) {
    const PendingObject& po = pending[k];
    bool got_occluder = false;
    for (Attempt& a : attempts[k]) {
      ++sum.solids;
      if (!a.why.empty()) {
        ++sum.without_occluder[a.why];
        continue;
      }
      sum.solid_volume_m3 += a.r.solid_volume_m3;
      sum.occluder_volume_m3 += a.r.occluder_volume_m3;
      if (a.r.occluders.empty()) {
        ++sum.without_occluder["no prism large enough"];
        continue;
      }
      got_occluder = true;
      for (Occluder25D& oc : a.r.occluders) {
        oc.object = po.id;
        scene.occluders.push_back(std::move(oc));
      }
    }
    if (po.building) {
      ++sum.buildings_drawn;
      sum.buildings_with_occluder += got_occluder;
    }
  }

  // 5. Terrain tiles: objects and their occluders. The ground is solid beneath the surface: where
  // the terrain ends above the scene's ground level, a skirt closes it down to z = 0 (so that no
  // line of sight slips under the terrain's edge, for the oracles as for the occluders).
  std::map<std::pair<int64_t, int64_t>, std::vector<std::array<glm::dvec3, 3>>> skirts;
  if (!terrain_tris.empty()) {
    auto key_of = [](const glm::dvec3& a, const glm::dvec3& b) {
      return LexLess(a, b) ? std::make_pair(a, b) : std::make_pair(b, a);
    };
    auto cmp = [](const std::pair<glm::dvec3, glm::dvec3>& u, const std::pair<glm::dvec3, glm::dvec3>& v) {
      return LexLess(u.first, v.first) || (u.first == v.first && LexLess(u.second, v.second));
    };
    std::map<std::pair<glm::dvec3, glm::dvec3>, int, decltype(cmp)> uses(cmp);
    for (const auto& t : terrain_tris) {
      for (int i = 0; i < 3; ++i) ++uses[key_of(t[i], t[(i + 1) % 3])];
    }
    for (const auto& t : terrain_tris) {
      for (int i = 0; i < 3; ++i) {
        const glm::dvec3 a = t[i], b = t[(i + 1) % 3];
        if (uses[key_of(a, b)] != 1 || (a.z <= 0.0 && b.z <= 0.0)) continue;
        // Counter-clockwise triangles from above: the outside is right of a -> b; the skirt
        // faces it.
        const glm::dvec3 a0(a.x, a.y, 0.0), b0(b.x, b.y, 0.0);
        const glm::dvec3 c = (t[0] + t[1] + t[2]) / 3.0;
        const auto tile = std::make_pair(static_cast<int64_t>(std::floor(c.x / options.terrain_tile_m)),
                                         static_cast<int64_t>(std::floor(c.y / options.terrain_tile_m)));
        if (a.z > 0.0) skirts[tile].push_back({a, a0, b0});
        if (b.z > 0.0) skirts[tile].push_back({a, b0, b});
        sum.terrain_skirt_triangles += (a.z > 0.0) + (b.z > 0.0);
      }
    }
    const bool derived = sum.terrain_from == "derived";
    const std::string terrain_name =
        derived ? "derived terrain" : (terrain.size() == 1 ? terrain.front().object->id : "terrain");
    std::map<std::pair<int64_t, int64_t>, std::vector<std::array<glm::dvec3, 3>>> tiles;
    for (const auto& t : terrain_tris) {
      const glm::dvec3 c = (t[0] + t[1] + t[2]) / 3.0;
      tiles[{static_cast<int64_t>(std::floor(c.x / options.terrain_tile_m)),
             static_cast<int64_t>(std::floor(c.y / options.terrain_tile_m))}]
          .push_back(t);
    }
    for (const auto& [key, tris] : tiles) {
      if (progress.Cancelled()) return absl::CancelledError("city import cancelled");
      Mesh mesh;
      for (const auto& t : tris) {
        const glm::dvec3 n = glm::normalize(glm::cross(t[1] - t[0], t[2] - t[0]));
        AppendTriangles({t}, n, &mesh);
      }
      for (const auto& t : skirts[key]) {
        const glm::dvec3 n = glm::normalize(glm::cross(t[1] - t[0], t[2] - t[0]));
        AppendTriangles({t}, n, &mesh);
      }
      const ObjectId id = scene.AddObject(absl::StrCat(terrain_name, "/tile ", key.first, ",", key.second), std::move(mesh));
      scene.terrain.push_back(id);
      scene.objects[id].type = derived ? kDerivedTerrainType : "TINRelief";
      ++sum.terrain_tiles;
      for (Occluder25D& oc : TerrainOccluders(tris, options.terrain_quantum_m, options.terrain_levels)) {
        oc.object = id;
        scene.occluders.push_back(std::move(oc));
        ++sum.terrain_occluders;
      }
    }
  }
  progress.Advance();
  progress.Finish();

  if (scene.objects.empty()) {
    return absl::InvalidArgumentError(absl::StrCat("no city object could be drawn (", model.objects.size(),
                                                   " objects read; ", sum.Skipped(), " skipped)"));
  }
  NormalizeOccluders(&scene);

  // 6. Walks from the data, over the scene's ground.
  if (options.walks > 0) {
    DeriveWalkOptions walk;
    walk.max_walks = options.walks;
    walk.bounds = std::make_pair(glm::dvec2(scene.bounds.min), glm::dvec2(scene.bounds.max));
    DerivedWalks derived;
    if (!roads.empty()) {
      walk.name_prefix = "road";
      // A metre from every building: pavements reach the walls.
      for (const Object& o : scene.objects) {
        if (!IsBuilding(o.type)) continue;
        const Mesh& m = o.mesh;
        for (size_t k = 0; k + 2 < m.indices.size(); k += 3) {
          walk.obstacles.push_back({glm::dvec2(m.positions[m.indices[k]]), glm::dvec2(m.positions[m.indices[k + 1]]),
                                    glm::dvec2(m.positions[m.indices[k + 2]])});
        }
      }
      walk.clearance_m = kWalkClearanceM;
      derived = DeriveRoadWalks(roads, walk);
      sum.walks_from = "roads";
    } else {
      walk.name_prefix = "walk";
      derived = DeriveFreeSpaceWalks(scene, {}, walk);
      sum.walks_from = "free space";
    }
    for (size_t i = 0; i < derived.paths.size(); ++i) {
      sum.walks.emplace_back(derived.paths[i].name, derived.lengths_m[i]);
    }
    sum.walk_notes = derived.notes;
    scene.paths = std::move(derived.paths);
  }
  sum.objects = scene.objects.size();
  sum.triangles = scene.TriangleCount();
  sum.occluders = scene.occluders.size();
  sum.build_s = SecondsSince(start);
  return scene;
}

bool IsCityModelPath(std::string_view path) {
  const std::string lower = absl::AsciiStrToLower(std::string(path));
  return absl::EndsWith(lower, ".gml") || absl::EndsWith(lower, ".xml") || absl::EndsWith(lower, ".json");
}

bool IsCrsName(std::string_view text) {
  const size_t colon = text.find(':');
  if (colon == std::string_view::npos || colon == 0 || colon + 1 == text.size()) return false;
  for (size_t k = 0; k < colon; ++k) {
    if (!absl::ascii_isalpha(static_cast<unsigned char>(text[k]))) return false;
  }
  for (size_t k = colon + 1; k < text.size(); ++k) {
    const unsigned char c = static_cast<unsigned char>(text[k]);
    if (!absl::ascii_isalnum(c) && c != '.' && c != '+' && c != '_' && c != '-') return false;
  }
  return true;
}

bool IsGeographicCrs(std::string_view crs) {
  const std::string first = absl::AsciiStrToUpper(std::string(crs.substr(0, crs.find('+'))));
  static constexpr std::string_view kGeographic[] = {
      "EPSG:4326", "EPSG:4979", "OGC:CRS84", "OGC:CRS84H", "CRS:84", "EPSG:4258", "EPSG:4937", "EPSG:4269",
      "EPSG:4283", "EPSG:7844", "EPSG:6668", "EPSG:4674", "EPSG:4490"};
  return std::find(std::begin(kGeographic), std::end(kGeographic), first) != std::end(kGeographic);
}

absl::StatusOr<Scene> ImportCity(const std::string& path, const CityImportOptions& options,
                                 CityImportSummary* summary, const RunControl& run) {
  const auto start = std::chrono::steady_clock::now();
  const std::string lower = absl::AsciiStrToLower(path);
  CityReadOptions read;
  read.keep_going = options.keep_going;
  absl::StatusOr<CityModel> model;
  if (absl::EndsWith(lower, ".gml") || absl::EndsWith(lower, ".xml")) {
    model = ReadCityGml(path, read, run);
  } else if (absl::EndsWith(lower, ".json")) {
    model = ReadCityJson(path, read, run);
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat(path, ": not a city model file name (CityGML: .gml or .xml; CityJSON: .json or .city.json)"));
  }
  if (!model.ok()) return model.status();
  const double read_s = SecondsSince(start);
  std::string name = options.name;
  if (name.empty()) {
    name = fs::path(path).filename().string();
    name = name.substr(0, name.find('.'));
  }
  absl::StatusOr<Scene> scene = BuildCityScene(*model, name, options, summary, run);
  if (summary != nullptr) summary->read_s = read_s;
  if (!scene.ok()) return absl::Status(scene.status().code(), absl::StrCat(path, ": ", scene.status().message()));
  return scene;
}

OccluderSynthesisSummary AddSynthesizedOccluders(Scene* scene, bool replace, const OccluderSynthesisOptions& options,
                                                 const RunControl& run) {
  OccluderSynthesisSummary sum;
  std::vector<bool> has(scene->objects.size(), false);
  for (const Occluder25D& oc : scene->occluders) has[oc.object] = true;
  if (replace) {
    scene->occluders.clear();
    std::fill(has.begin(), has.end(), false);
  }
  std::vector<bool> is_terrain(scene->objects.size(), false);
  std::vector<std::array<glm::dvec3, 3>> terrain_tris;
  for (ObjectId t : scene->terrain) {
    is_terrain[t] = true;
    const Mesh& m = scene->objects[t].mesh;
    for (size_t k = 0; k + 2 < m.indices.size(); k += 3) {
      terrain_tris.push_back({glm::dvec3(m.positions[m.indices[k]]), glm::dvec3(m.positions[m.indices[k + 1]]),
                              glm::dvec3(m.positions[m.indices[k + 2]])});
    }
  }
  const GroundIndex ground(terrain_tris, 25.0);
  Progress progress(run, "synthesizing occluders", scene->objects.size());
  for (Object& o : scene->objects) {
    if (progress.Cancelled()) break;
    progress.Advance();
    if (has[o.id]) continue;
    ++sum.objects;
    std::vector<Occluder25D> made;
    if (is_terrain[o.id]) {
      std::vector<std::array<glm::dvec3, 3>> tris;
      for (size_t k = 0; k + 2 < o.mesh.indices.size(); k += 3) {
        tris.push_back({glm::dvec3(o.mesh.positions[o.mesh.indices[k]]), glm::dvec3(o.mesh.positions[o.mesh.indices[k + 1]]),
                        glm::dvec3(o.mesh.positions[o.mesh.indices[k + 2]])});
      }
      made = TerrainOccluders(tris);
    } else {
      OccluderSynthesis r =
          SynthesizeOccluders(SolidMeshFromMesh(o.mesh), ground.LowestUnder(o.bounds), ground.Under(o.bounds), options);
      if (r.defect != SolidDefect::kNone) {
        ++sum.without_occluder[SolidDefectName(r.defect)];
        continue;
      }
      sum.solid_volume_m3 += r.solid_volume_m3;
      sum.occluder_volume_m3 += r.occluder_volume_m3;
      made = std::move(r.occluders);
    }
    if (made.empty()) {
      ++sum.without_occluder["no prism large enough"];
      continue;
    }
    ++sum.objects_with_occluder;
    for (Occluder25D& oc : made) {
      oc.object = o.id;
      scene->occluders.push_back(std::move(oc));
      ++sum.occluders;
    }
  }
  progress.Finish();
  std::stable_sort(scene->occluders.begin(), scene->occluders.end(),
                   [](const Occluder25D& a, const Occluder25D& b) { return a.object < b.object; });
  NormalizeOccluders(scene);
  return sum;
}

OcclusionStats ComputeOcclusionStats(const Scene& scene) {
  OcclusionStats st;
  std::vector<bool> is_terrain(scene.objects.size(), false);
  for (ObjectId t : scene.terrain) is_terrain[t] = true;
  std::vector<std::vector<const Occluder25D*>> of_object(scene.objects.size());
  std::vector<bool> has(scene.objects.size(), false);
  for (const Occluder25D& oc : scene.occluders) {
    if (is_terrain[oc.object]) {
      ++st.terrain_occluders;
      continue;
    }
    ++st.occluders;
    has[oc.object] = true;
    of_object[oc.object].push_back(&oc);
  }
  // The volume of the union of an object's occluders above its lowest point: a tier stands on
  // the ground through the tiers below it, and a tower's prism through its building's, so the
  // prisms overlap and their volumes do not add up. Slab by slab between the occluders'
  // heights, each slab's area the union of the footprints reaching above it.
  auto occluder_volume = [&](ObjectId id) {
    std::vector<const Occluder25D*>& ocs = of_object[id];
    std::sort(ocs.begin(), ocs.end(), [](const Occluder25D* a, const Occluder25D* b) { return a->height > b->height; });
    const double base = scene.objects[id].bounds.min.z;
    double volume = 0.0;
    std::vector<PolygonWithHoles> reaching;
    double plain_area = 0.0;  // the footprints' summed area: the slab's if CGAL refuses the union
    for (size_t k = 0; k < ocs.size();) {
      const double top = ocs[k]->height;
      for (; k < ocs.size() && ocs[k]->height == top; ++k) {
        Ring r = ocs[k]->footprint;
        const double area = SignedArea(r);
        if (area == 0.0) continue;
        if (area < 0.0) std::reverse(r.begin(), r.end());
        plain_area += std::abs(area);
        reaching.push_back(PolygonWithHoles{std::move(r), {}});
      }
      const double below = std::max(base, k < ocs.size() ? ocs[k]->height : base);
      if (!(top > below)) continue;
      double area = plain_area;
      if (absl::StatusOr<std::vector<PolygonWithHoles>> u = Union(reaching); u.ok()) {
        area = 0.0;
        for (const PolygonWithHoles& p : *u) {
          area += SignedArea(p.outer);
          for (const Ring& h : p.holes) area += SignedArea(h);  // clockwise: negative
        }
      }
      volume += area * (top - below);
    }
    return volume;
  };
  Aabb terrain_box;
  for (const Object& o : scene.objects) {
    ++st.objects_by_type[o.type.empty() ? "object" : o.type];
    if (is_terrain[o.id]) {
      ++st.terrain_objects;
      st.derived_terrain_objects += o.type == kDerivedTerrainType;
      st.terrain_triangles += o.mesh.TriangleCount();
      terrain_box.Extend(o.bounds);
      continue;
    }
    ++st.non_terrain_objects;
    if (!has[o.id]) continue;
    ++st.objects_with_occluder;
    if (const SolidMesh solid = SolidMeshFromMesh(o.mesh); !ClosesModTwo(solid.vertices, solid.triangles)) {
      // A surface model's house, closed by its neighbours and the ground (issue 46): its mesh
      // encloses nothing on its own, so neither its volume nor its occluders' are counted.
      ++st.open_objects_with_occluder;
      continue;
    }
    st.occluder_volume_m3 += occluder_volume(o.id);
    double six_v = 0.0;  // six times the signed volume, relative to the object's box corner
    const glm::dvec3 c = o.bounds.min;
    const Mesh& m = o.mesh;
    for (size_t k = 0; k + 2 < m.indices.size(); k += 3) {
      const glm::dvec3 a = glm::dvec3(m.positions[m.indices[k]]) - c;
      const glm::dvec3 b = glm::dvec3(m.positions[m.indices[k + 1]]) - c;
      const glm::dvec3 d = glm::dvec3(m.positions[m.indices[k + 2]]) - c;
      six_v += glm::dot(a, glm::cross(b, d));
    }
    st.solid_volume_m3 += std::abs(six_v) / 6.0;
  }
  st.terrain_min_z = scene.origin.z + (terrain_box.Empty() ? 0.0 : terrain_box.min.z);
  st.terrain_max_z = scene.origin.z + (terrain_box.Empty() ? 0.0 : terrain_box.max.z);
  return st;
}

}  // namespace vistream::scenes

