#pragma once
// The scene model: objects with triangle meshes, 2.5D occluders, bounds and a
// double-precision origin. Everything is in scene-local metres, z up, ground at z = 0;
// world position = origin + local position.

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/status.h>
#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "scenes/aabb.h"
#include "scenes/level_types.h"
#include "scenes/mesh.h"

namespace vistream::scenes {

using ObjectId = uint32_t;

struct Object {
  ObjectId id = 0;  // dense: objects[i].id == i
  std::string name;
  Mesh mesh;
  Aabb bounds;  // of mesh.positions, in double
  // What the source calls it: a city model's object type ("Building", "BuildingPart",
  // "TINRelief", "Road", ...); empty where the source has none (generated, OSM, plain glTF).
  std::string type;
};

// A vertical prism standing on the ground: a simple polygon footprint (counter-clockwise in
// xy) extruded from z = 0 to z = height. It lies inside the solid of object `object`, so
// occlusion computed from occluders is conservative for the real geometry.
struct Occluder25D {
  std::vector<glm::dvec2> footprint;
  double height = 0.0;
  ObjectId object = 0;
};

// A walk the data itself gives (streets of an OSM import, roads of a city model, or free space
// between buildings; scenes/derived_walks.h): a polyline in scene-local metres (xy, the eye
// stands above it). Catalog entries may declare walks of their own (scenes/catalog.h WalkPath);
// these come with the scene, also in glTF files.
struct ScenePath {
  std::string name;
  std::vector<glm::dvec2> waypoints;  // scene-local metres, at least 2
};

struct Scene {
  std::string name;
  glm::dvec3 origin{0.0};  // world coordinates of local (0, 0, 0), e.g. UTM metres
  std::vector<Object> objects;
  std::vector<Occluder25D> occluders;
  Aabb bounds;  // union of object bounds
  // The coordinate reference system of `origin` ("EPSG:28992"); empty when unknown (generated
  // scenes, glTF files that do not say). Imports keep the source's.
  std::string crs;
  // Objects whose meshes are the terrain's surface (sorted ids): the ground is solid beneath
  // them, and viewcells follow them. Empty: flat ground at z = 0.
  std::vector<ObjectId> terrain;
  // Walks the data gives (ScenePath); empty when it gives none. Not part of SceneFingerprint:
  // they do not change what is visible.
  std::vector<ScenePath> paths;
  // Levels of detail (scenes/levels.h makes them; glTF keeps them, MSFT_lod); empty when the
  // scene has none. Not part of SceneFingerprint: levels change what is drawn, not what is
  // visible.
  SceneLevels levels;

  size_t TriangleCount() const;
  size_t VertexCount() const;
  // Adds an object with the next dense id and returns that id. Bounds are computed here.
  ObjectId AddObject(std::string name, Mesh mesh);
};

// Checks one mesh: whole triangles, a normal per position, finite positions and normals,
// indices in range. INVALID_ARGUMENT starting with `what` (a file and an object, say).
absl::Status ValidateMesh(const Mesh& mesh, const std::string& what);

// Checks the invariants every consumer relies on: at least one object, dense ids, finite
// coordinates, indices in range, normals per position, finite occluders referencing existing
// objects, terrain ids sorted, distinct and existing, paths named with at least 2 finite
// waypoints. `where` names the source (a file path) in the message.
absl::Status ValidateScene(const Scene& scene, const std::string& where);

// A 64-bit digest of what visibility depends on: every object's mesh (positions, indices) and
// every occluder (object, footprint, height), in order, and the terrain's ids. Two scenes that differ anywhere in
// those differ here (but for a 2^-64 chance); the name and origin do not count. Never 0.
uint64_t SceneFingerprint(const Scene& scene);

// Makes every occluder footprint counter-clockwise and drops repeated closing vertices.
// Degenerate footprints (zero area, repeated vertices) are kept: visibility must cope.
void NormalizeOccluders(Scene* scene);

}  // namespace vistream::scenes
