#pragma once
// Internal to scenes/ (the glTF reader and its decoders): typed, bounds-checked reading of
// glTF 2.0 accessors (spec 3.6.2), sparse accessors (3.6.2.3) included. Safe on untrusted
// models: every offset, count and index is checked before use.

#include <cstddef>
#include <string>
#include <vector>

#include <glm/vec3.hpp>
#include <tiny_gltf.h>

namespace vistream::scenes::gltf_detail {

// Bad data found while reading the model; `what` names the element (and the file's own
// name is prefixed by the caller).
struct LoadError {
  std::string what;
};

// The bytes [byte_offset, byte_offset + length) of bufferView `view`, checked to lie inside
// the view and the view inside its buffer. Throws LoadError naming `what` otherwise.
const unsigned char* ViewBytes(const tinygltf::Model& model, int view, size_t byte_offset, size_t length,
                               const std::string& what);

class AccessorReader {
 public:
  // Reads accessor `index` of `model`; `what` names the user (node, mesh, primitive) in
  // errors. A sparse accessor is made dense here (its base values, or zeros, with the sparse
  // values substituted); it may not exceed 256 MiB dense.
  AccessorReader(const tinygltf::Model& model, int index, std::string what);

  size_t count() const { return acc_->count; }
  int components() const { return components_; }
  int type() const { return acc_->type; }
  int component_type() const { return acc_->componentType; }

  // Component c (< components()) of element i (< count()), as double; normalized integers
  // are scaled as glTF 2.0, 3.11 says.
  double Get(size_t i, int c) const;
  glm::dvec3 Vec3(size_t i) const { return {Get(i, 0), Get(i, 1), Get(i, 2)}; }

 private:
  void MakeDense(const tinygltf::Model& model, int index);

  std::string what_;
  const tinygltf::Accessor* acc_ = nullptr;
  const unsigned char* base_ = nullptr;
  size_t stride_ = 0;
  int components_ = 0;
  int component_size_ = 0;
  std::vector<unsigned char> dense_;  // a sparse accessor's values, tightly packed
};

}  // namespace vistream::scenes::gltf_detail
