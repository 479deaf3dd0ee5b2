#pragma once
// Internal to scenes/: glTF is y-up, vistream z-up; the one conversion between them
// ((x, y, z) z-up = (x, -z, y) glTF), a rotation, so it maps normals the same way.

#include <string_view>

#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

namespace vistream::scenes::gltf_detail {

inline glm::dvec3 ZupFromGltf(const glm::dvec3& p) { return {p.x, -p.z, p.y}; }
inline glm::dvec3 GltfFromZup(const glm::dvec3& p) { return {p.x, p.z, -p.y}; }
// The matrix of ZupFromGltf (column-major).
inline const glm::dmat4 kZupFromGltf(1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 0, 0, 1);

inline bool EndsWith(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

}  // namespace vistream::scenes::gltf_detail
