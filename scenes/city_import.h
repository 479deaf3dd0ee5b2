#pragma once
// 3D city models (CityGML 1.0/2.0, CityJSON 0.x/1.0/1.1/2.0) as vistream scenes: the readers
// (scenes/city_model.h) give city objects with geometry per level of detail; this builder
// picks the level of detail, triangulates the polygons, tiles the terrain, and synthesizes
// the occluders (scenes/occluder_synthesis.h). DESIGN.md "City models and terrain".
//
// Objects: every city object with geometry at the chosen LoD is one scene object named by its
// id (gml:id, CityJSON key); a Building whose BuildingParts carry the geometry and that has
// none of its own gives no object. The terrain (TINRelief) is cut into square tiles of
// `terrain_tile_m` (by triangle centroid), each an object named "<id>/tile <i>,<j>" and listed
// in Scene::terrain, so that a PVS holds only the terrain that can be seen.
//
// Level of detail: each object's highest (by the file's LoD text, "2.2" above "2"), or with
// `lod` the geometry whose LoD has that integer part; objects without it are skipped and
// counted ("no LoD <n> geometry"), but terrain keeps its highest (it is the ground).
//
// Frame: the scene origin is the file's CRS coordinates of the bounds' centre, rounded to
// whole metres in x and y, and z at the ground level: the TIN's lowest point, or without a
// TIN the lowest point of all geometry (also when a terrain is derived: it lies at or above
// that point, and its skirts close it down to it). Scene::crs is the file's.
//
// Polygons: rings cleaned (consecutive duplicate points, spikes), projected on the plane of
// their dominant normal axis and triangulated with holes (CGAL's constrained Delaunay
// triangulation, scenes/polygon.h, as the OSM import does); triangles wound to face the way
// the polygon's ring does (outward for solids as the specifications require). A polygon that
// cannot be triangulated (a self-crossing ring, a hole outside its ring, no area) is left out
// and counted; its object is kept.
//
// Floors: a Solid shell that is open only at its lowest height (the walls' lower edges form
// closed loops there: extruded LoD1 models such as the 3D BAG leave the ground surface out)
// gets the floor that closes it (scenes/solid_floor.h), drawn and counted in
// CityImportSummary::repaired["solid closed with a floor"]; anything else open stays open.
//
// Ground without a TIN (CityImportOptions::ground, default derived): a terrain is derived
// (scenes/derived_ground.h) from the floors of the Building and BuildingPart solids (their
// lowest faces, constrained: each footprint is exactly a set of terrain triangles at its floor's
// height) and the vertices of the ground-level surfaces: those of Road, Railway,
// TransportSquare, LandUse and WaterBody objects (the ground covers of a planar partition such
// as the Dutch BGT). PlantCover is not ground: 3D data sets lift it to the vegetation's height
// (Delft's reaches 16.8 m). The derived terrain takes the TIN's path below: tiles named
// "derived terrain/tile <i>,<j>" of type "DerivedTerrain", skirts, occluders; buildings on it
// occlude by the same GroundSurface test.
//
// Occluders: each solid of an object (and each closed MultiSurface/CompositeSurface of a
// Building or BuildingPart) through SynthesizeOccluders with the ground under it: the
// terrain's lowest height under the object's xy box (0 without terrain). Terrain tiles get
// TerrainOccluders. Solids without occluders are counted by SolidDefectName.

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>

#include "scenes/city_model.h"
#include "scenes/occluder_synthesis.h"
#include "scenes/progress.h"
#include "scenes/scene.h"

namespace vistream::scenes {

// What stands for the ground when the file has no terrain (TINRelief).
enum class CityGround {
  kDerived,  // a terrain derived from building floors and ground-level surfaces (the default)
  kNone,     // flat ground at the data's lowest point
};

// Whether `text` names a coordinate reference system as the importers write them: an
// authority and a code, "EPSG:28992", a compound "EPSG:7415+5109", "OGC:CRS84" (letters, a
// colon, then letters, digits, '.', '+', '_' or '-').
bool IsCrsName(std::string_view text);

// Whether `crs` (IsCrsName's form) is one of the common geographic systems, whose coordinates
// are degrees: WGS 84 (EPSG:4326, 4979, OGC:CRS84), ETRS89 (4258, 4937), NAD83 (4269), GDA94
// (4283), GDA2020 (7844), JGD2011 (6668), SIRGAS 2000 (4674), China 2000 (4490); a compound
// "EPSG:4326+..." by its first part. The importers read metres and reproject nothing, so a
// city model in such a CRS is refused (BuildCityScene).
bool IsGeographicCrs(std::string_view crs);

struct CityImportOptions {
  std::optional<int> lod;        // 0..4: the integer part of the LoD to use; none: each object's highest
  std::string name;              // the scene's name; default: the file name up to its first dot
  bool keep_going = false;       // CityReadOptions::keep_going
  // The CRS to record when the file names none ("EPSG:28992", IsCrsName); a file that names
  // another one is an error (INVALID_ARGUMENT naming both), and so is text that names none
  // and a geographic CRS (IsGeographicCrs: degrees, not metres), given or the file's.
  // Empty: the file's, or none.
  std::string crs;
  double terrain_tile_m = 100.0;  // edge of the terrain's tiles, > 0
  double terrain_quantum_m = 1.0;  // TerrainOccluders' height steps
  int terrain_levels = 16;         // TerrainOccluders' tiers per tile
  CityGround ground = CityGround::kDerived;  // only for files without a TINRelief
  OccluderSynthesisOptions synthesis;
  size_t walks = 3;  // walks to derive from the data (0: none)
};

struct CityImportSummary {
  std::string format;  // CityModel::format
  std::string crs;
  uint64_t city_objects = 0;                        // read from the file
  std::map<std::string, uint64_t> objects_by_type;  // city objects read, by type
  std::map<std::string, uint64_t> lods;             // LoD text chosen -> objects drawn with it
  uint64_t objects = 0;          // scene objects (terrain tiles included)
  uint64_t buildings = 0;        // Building objects in the file
  uint64_t building_parts = 0;   // BuildingPart objects in the file
  // Building and BuildingPart objects drawn (with geometry at the chosen LoD), and how many of
  // them got at least one occluder.
  uint64_t buildings_drawn = 0, buildings_with_occluder = 0;
  uint64_t surfaces = 0;   // polygons triangulated
  uint64_t triangles = 0;  // in the scene
  uint64_t solids = 0;     // given to the synthesis
  uint64_t occluders = 0;  // all, terrain included
  // Solids (and closed surfaces of buildings) that gave no occluder, by reason.
  std::map<std::string, uint64_t> without_occluder;
  double solid_volume_m3 = 0.0;     // of the closed solids
  double occluder_volume_m3 = 0.0;  // of their occluders above the ground
  // Terrain: TINRelief objects, their triangles, the tiles made of them, their occluders, and
  // the relief's lowest and highest heights (the file's CRS, metres).
  uint64_t terrain_objects = 0, terrain_triangles = 0, terrain_tiles = 0, terrain_occluders = 0;
  uint64_t terrain_skirt_triangles = 0;  // walls closing the terrain's edge down to the ground level
  double terrain_min_z = 0.0, terrain_max_z = 0.0;
  // Where the terrain came from: "TIN" (the file's TINRelief objects), "derived" (no TIN: the
  // ground derived from the data, terrain_objects 0), "" (none: flat ground).
  std::string terrain_from;
  // The derived terrain's inputs (scenes/derived_ground.h DerivedGround): building floors taken
  // and left out (over a lower floor), distinct floor corners, surface points taken and left
  // out (inside or on a floor), box corners added.
  uint64_t ground_floors = 0, ground_floors_overlapping = 0, ground_floor_points = 0;
  uint64_t ground_surface_points = 0, ground_points_under_floors = 0, ground_corner_points = 0;
  std::map<std::string, uint64_t> skipped;   // the reader's and the builder's, by reason
  std::map<std::string, uint64_t> repaired;  // likewise
  // Walks derived from the data (Scene::paths): on Road objects' surfaces where the file has
  // them, a metre clear of every building, else through the free space between the buildings
  // (scenes/derived_walks.h).
  std::string walks_from;  // "roads", "free space" or "" (none derived)
  std::vector<std::pair<std::string, double>> walks;  // name, length in metres
  std::vector<std::string> walk_notes;
  double read_s = 0.0, build_s = 0.0;

  uint64_t Skipped() const;
  uint64_t Repaired() const;
};

// The most a city model's drawn objects may span along any axis, in metres (1,000 km): one
// city, whose scene-local single-precision meshes keep centimetres.
inline constexpr double kMaxCitySpanM = 1e6;

// Builds the scene of a city model; `name` is the scene's name. Errors: INVALID_ARGUMENT when
// nothing drawable is left (with the skip reasons), when the objects span more than
// kMaxCitySpanM along an axis (naming the objects at either end), or `options` out of range;
// CANCELLED when run's flag was raised. `summary` is filled on every path after reading.
absl::StatusOr<Scene> BuildCityScene(const CityModel& model, const std::string& name,
                                     const CityImportOptions& options, CityImportSummary* summary = nullptr,
                                     const RunControl& run = {});

// Whether `path` names a city model: .gml or .xml (CityGML), .json (CityJSON, also .city.json).
bool IsCityModelPath(std::string_view path);

// Reads `path` (CityGML by .gml/.xml, CityJSON by .json) and builds its scene. Errors: the
// reader's (NOT_FOUND, INVALID_ARGUMENT naming the file and the object), BuildCityScene's.
absl::StatusOr<Scene> ImportCity(const std::string& path, const CityImportOptions& options,
                                 CityImportSummary* summary = nullptr, const RunControl& run = {});

// Occluders for a scene without them (a glTF model): every object whose mesh is closed gets
// SynthesizeOccluders' prisms on flat ground (ground_z 0; with Scene::terrain, the terrain's
// lowest height under the object), replacing the objects' occluders if `replace`, else only
// objects that have none. Terrain objects get TerrainOccluders. Returns the counts like
// CityImportSummary's occluders, without_occluder, volumes.
struct OccluderSynthesisSummary {
  uint64_t objects = 0;                // considered
  uint64_t objects_with_occluder = 0;  // that got at least one
  uint64_t occluders = 0;
  std::map<std::string, uint64_t> without_occluder;
  double solid_volume_m3 = 0.0, occluder_volume_m3 = 0.0;
};
OccluderSynthesisSummary AddSynthesizedOccluders(Scene* scene, bool replace, const OccluderSynthesisOptions& options = {},
                                                 const RunControl& run = {});

// What a scene holds and how much of it occludes: `vistream scene info`, `scene map` and the
// report show it. Volumes in m³; heights in the scene's CRS (origin.z added).
struct OcclusionStats {
  std::map<std::string, uint64_t> objects_by_type;  // Object::type ("" counted as "object")
  uint64_t objects_with_occluder = 0;               // non-terrain objects with at least one occluder
  uint64_t non_terrain_objects = 0;
  uint64_t occluders = 0, terrain_occluders = 0;
  // Of the non-terrain objects with occluders whose meshes are closed: their meshes' enclosed
  // volume (divergence theorem) and their occluders' volume above each object's lowest point.
  double solid_volume_m3 = 0.0, occluder_volume_m3 = 0.0;
  // Objects with occluders whose meshes are open (surface models closed by their neighbours
  // and the ground: issue 46), left out of the volumes.
  uint64_t open_objects_with_occluder = 0;
  uint64_t terrain_objects = 0, terrain_triangles = 0;
  // Of the terrain objects, those of a terrain the import derived (type "DerivedTerrain": the
  // file had no TIN), not read from the file.
  uint64_t derived_terrain_objects = 0;
  double terrain_min_z = 0.0, terrain_max_z = 0.0;  // world heights; equal when there is no terrain
};
OcclusionStats ComputeOcclusionStats(const Scene& scene);

}  // namespace vistream::scenes
