#pragma once
// glTF 2.0 (.gltf and .glb) load and save with tinygltf. glTF is y-up; vistream is z-up:
// the conversion happens here and nowhere else ((x, y, z) z-up = (x, -z, y) glTF).
//
// vistream files keep the scene origin as the translation of one root node whose extras hold
// {"vistream": {"origin": true}}, objects as its child nodes (one mesh each) and occluders in
// each object node's extras: {"vistream": {"occluders": [{"footprint": [x0, y0, x1, y1, ...],
// "height": h}]}} in the node's frame, z-up metres, standing on the ground. The origin node's
// extras may name the coordinate reference system ({"vistream": {"origin": true, "crs":
// "EPSG:28992"}}, Scene::crs); terrain objects' nodes say {"vistream": {"terrain": true}}
// (Scene::terrain); an object's source type is {"vistream": {"type": "BuildingPart"}}.
// The origin node's extras may carry the scene's own walks (Scene::paths):
// {"vistream": {"origin": true, "paths": [{"name": "street 1", "waypoints": [x0, y0, x1, y1,
// ...]}]}}, scene-local z-up metres (x east, y north: not glTF axes); a path without a name,
// with fewer than 2 waypoints or a non-finite one, or named again, is warned about and skipped.

#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>

#include "scenes/scene.h"

namespace vistream::scenes {

// Loads any valid glTF 2.0 file with triangle meshes: node transforms applied in double,
// one object per mesh node (its triangle primitives merged), strips and fans converted,
// points and lines skipped with a warning, flat normals made where a mesh has none.
// Without a vistream origin node the origin is the rounded centre of the ground footprint.
// Decodes KHR_draco_mesh_compression (libdraco), EXT_meshopt_compression (meshoptimizer),
// KHR_mesh_quantization and sparse accessors (glTF 2.0, 3.6.2.3); an unsupported extension in
// extensionsRequired that changes geometry is an error naming it (appearance-only ones, such
// as KHR_materials_*, are ignored). Errors name the extension and element (bufferView, mesh,
// primitive, attribute) where compressed data does not decode.
// Warnings are appended to `warnings` when given. Errors name the file and the element.
absl::StatusOr<Scene> LoadGltf(const std::string& path, std::vector<std::string>* warnings = nullptr);

// The same, from bytes in memory (.glb when `binary`). External URIs resolve against
// `base_dir` and may not leave it; with an empty `base_dir` no file is read at all. Safe on
// untrusted input.
absl::StatusOr<Scene> LoadGltfFromMemory(std::string_view bytes, bool binary,
                                         const std::string& name, const std::string& base_dir = "",
                                         std::vector<std::string>* warnings = nullptr);

// Saves a validated scene; binary when `path` ends in .glb, otherwise .gltf with the buffer
// beside it as PATH_STEM.bin. Each object is one node and mesh whose POSITION, NORMAL and
// index accessors are its own ranges of three shared bufferViews (float vec3 y-up metres,
// uint32 object-local indices), POSITION with the object's own min/max (glTF 2.0, 3.6.2.4).
absl::Status SaveGltf(const Scene& scene, const std::string& path);

}  // namespace vistream::scenes
