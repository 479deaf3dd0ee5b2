#pragma once
// A 3D city model as the CityGML and CityJSON readers give it, before triangulation: city
// objects with their geometries by level of detail, in the file's coordinate reference system.
// Both readers fill the same structure, so that one builder (scenes/city_import.h) makes the
// scene, the occluders and the counts for either format, and the same city read from CityGML
// and from CityJSON gives the same scene.
//
// Follows the CityJSON specification's geometry model (https://www.cityjson.org/specs/,
// section "Geometry objects"): a surface is a planar polygon with an outer ring and holes; a
// shell is a set of surfaces; a solid is an exterior shell and interior shells (voids).
// CityGML's gml:Solid, gml:MultiSurface, gml:CompositeSurface, gml:TriangulatedSurface map to
// the same types (CityGML 2.0, OGC 12-019, sections 10.2 and 10.3).

#include <cstdint>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/vec3.hpp>

#include "scenes/progress.h"

namespace vistream::scenes {

// One planar polygon. Rings are open (the first point is not repeated at the end), in the
// file's CRS units (metres for the projected CRSs cities use), double precision, as read:
// readers do not repair rings (the builder does, and counts what it repaired).
struct CitySurface {
  std::vector<glm::dvec3> outer;
  std::vector<std::vector<glm::dvec3>> holes;
};

// A closed volume: shells[0] is the exterior shell, the others bound voids. Whether it is
// really closed is for the builder to find out (scenes/occluder_synthesis.h).
struct CitySolid {
  std::vector<std::vector<CitySurface>> shells;
};

enum class CityGeometryType {
  kSolid,              // solids.size() == 1
  kMultiSolid,         // any number of solids
  kCompositeSolid,     // solids sharing faces; each one a solid of its own here
  kMultiSurface,       // surfaces
  kCompositeSurface,   // surfaces
  kTin,                // CityJSON "CompositeSurface" of a TINRelief, gml:TriangulatedSurface/Tin
};

struct CityGeometry {
  CityGeometryType type = CityGeometryType::kMultiSurface;
  // The level of detail as the file writes it ("1", "2", "2.2", "1.3"); its integer part is
  // what `--lod` selects.
  std::string lod;
  std::vector<CitySolid> solids;      // kSolid, kMultiSolid, kCompositeSolid
  std::vector<CitySurface> surfaces;  // kMultiSurface, kCompositeSurface, kTin
};

struct CityObject {
  std::string id;    // gml:id, or the CityJSON CityObjects key
  // The CityJSON type name for both formats: "Building", "BuildingPart",
  // "BuildingInstallation", "Bridge", "BridgePart", "Road", "TINRelief", "LandUse",
  // "PlantCover", "WaterBody", "GenericCityObject", ... (CityJSON 2.0, section "City Objects").
  // CityGML reader: bldg:Building -> "Building", dem:TINRelief -> "TINRelief", etc.
  std::string type;
  std::string parent;  // id of the object this one is a part of (a BuildingPart's Building); "" if none
  // Geometry at every LoD the file has. Geometry templates (CityJSON "GeometryInstance",
  // CityGML ImplicitGeometry) are already placed: transformed to world coordinates here.
  // Semantic surfaces of a CityGML building (bldg:WallSurface, RoofSurface, ...) belong to
  // the building or part whose boundary they are: their polygons are in its geometry, not in
  // objects of their own.
  std::vector<CityGeometry> geometries;
};

struct CityModel {
  std::string format;  // what was read: "CityJSON 1.1", "CityJSON 0.8", "CityGML 1.0", "CityGML 2.0"
  // The coordinate reference system as the file names it, normalised to "EPSG:<code>" where
  // the file gives an EPSG code (CityJSON metadata.referenceSystem, gml:Envelope/@srsName);
  // the file's text otherwise; "" when it names none.
  std::string crs;
  std::vector<CityObject> objects;  // in file order; ids unique
  // What the reader skipped or repaired, by reason ("geometry with unknown type", "vertex
  // index out of range", ...): objects or geometries it could not read are left out and
  // counted here; errors that make the whole file unreadable are returned instead.
  std::map<std::string, uint64_t> skipped;
  std::map<std::string, uint64_t> repaired;
};

struct CityReadOptions {
  // Malformed geometry in one object (a vertex index out of range, a NaN or infinite
  // coordinate, an empty solid, shell or ring, a ring of fewer than 3 points): by default an
  // error naming the object and the place (INVALID_ARGUMENT); with keep_going the object is
  // left out and counted in CityModel::skipped["malformed geometry"] instead.
  bool keep_going = false;
};

// CityJSON 0.1 to 0.9, 1.0, 1.1 and 2.0 (0.1 and 0.2 as "type": "CityModel" with a URL
// version; Den Haag's 0.8), as files (.json, .city.json) or bytes; `name` names the source in
// errors. Objects in file order; templates placed; MultiPoint and MultiLineString skipped and
// counted; progress one unit per city object. Errors: NOT_FOUND (no such file),
// INVALID_ARGUMENT naming the file and the JSON path of the problem (truncated or not JSON,
// "type" neither "CityJSON" nor "CityModel", a version this reader does not read, vertex
// indices out of range, ...), CANCELLED when run's flag was raised. The details:
// scenes/cityjson_read.cpp's header comment.
absl::StatusOr<CityModel> ReadCityJson(const std::string& path, const CityReadOptions& options = {},
                                       const RunControl& run = {});
absl::StatusOr<CityModel> ReadCityJsonFromMemory(std::string_view bytes, const std::string& name,
                                                 const CityReadOptions& options = {});

// CityGML 1.0 and 2.0 (.gml, .xml) through libcitygml, xlink references resolved. Errors as
// ReadCityJson's (a truncated or non-CityGML file: INVALID_ARGUMENT naming the file).
// scenes/citygml_read.cpp.
absl::StatusOr<CityModel> ReadCityGml(const std::string& path, const CityReadOptions& options = {},
                                      const RunControl& run = {});
absl::StatusOr<CityModel> ReadCityGmlFromMemory(std::string_view bytes, const std::string& name,
                                                const CityReadOptions& options = {});

}  // namespace vistream::scenes
