#pragma once
// Internal to scenes/: the compressed-geometry glTF extensions, decoded around tinygltf
// (Debian's tinygltf is built without them):
//   KHR_draco_mesh_compression  (Khronos extension spec; decoded with libdraco)
//   EXT_meshopt_compression     (Khronos-registered EXT spec; decoded with meshoptimizer)
// and the check of `extensionsRequired` (glTF 2.0, 3.12): a file that requires an extension
// that changes geometry and is not one of these is refused naming it. Safe on untrusted bytes.

#include <string>
#include <string_view>

#include <tiny_gltf.h>

namespace vistream::scenes::gltf_detail {

// Before tinygltf parses `bytes` (a .glb when `binary`, else .gltf JSON): returns the bytes
// to parse instead, either `bytes` itself or a copy in `*storage` whose JSON is rewritten so
// tinygltf accepts it (a Draco primitive's `indices` dropped: they come from the Draco
// stream; a meshopt fallback buffer, which has no data, given an empty one). Malformed input
// is returned unchanged for tinygltf to report. Throws LoadError naming an unsupported
// required extension.
std::string_view PrepareCompressed(std::string_view bytes, bool binary, std::string* storage);

// After tinygltf parsed the prepared bytes: decodes every meshopt bufferView and every Draco
// primitive into new buffers, views and accessors of `model` (float attributes, uint32
// triangle indices), so the reader sees plain glTF. Throws LoadError naming the extension
// and the element (bufferView, mesh and primitive) when data cannot be decoded.
void DecodeCompressed(tinygltf::Model* model);

}  // namespace vistream::scenes::gltf_detail
