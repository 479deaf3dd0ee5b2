#include "scenes/gltf_accessor.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include <absl/strings/str_cat.h>

namespace vistream::scenes::gltf_detail {

namespace {

// A sparse accessor without a bufferView has no bytes in the file to bound its size.
constexpr size_t kMaxDenseBytes = size_t{1} << 28;

template <typename T>
T Load(const unsigned char* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  return v;
}

}  // namespace

const unsigned char* ViewBytes(const tinygltf::Model& model, int view, size_t byte_offset, size_t length,
                               const std::string& what) {
  if (view < 0 || view >= static_cast<int>(model.bufferViews.size())) {
    throw LoadError{absl::StrCat(what, ": bufferView ", view, " does not exist")};
  }
  const tinygltf::BufferView& v = model.bufferViews[view];
  if (v.buffer < 0 || v.buffer >= static_cast<int>(model.buffers.size())) {
    throw LoadError{absl::StrCat(what, ": bufferView ", view, " has no valid buffer")};
  }
  const auto& data = model.buffers[v.buffer].data;
  if (v.byteOffset > data.size() || v.byteLength > data.size() - v.byteOffset || byte_offset > v.byteLength ||
      length > v.byteLength - byte_offset) {
    throw LoadError{absl::StrCat(what, ": bufferView ", view, " reads past the end of its buffer")};
  }
  return data.data() + v.byteOffset + byte_offset;
}

AccessorReader::AccessorReader(const tinygltf::Model& model, int index, std::string what)
    : what_(std::move(what)) {
  if (index < 0 || index >= static_cast<int>(model.accessors.size())) {
    throw LoadError{absl::StrCat(what_, ": accessor ", index, " does not exist")};
  }
  acc_ = &model.accessors[index];
  components_ = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(acc_->type));
  component_size_ = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(acc_->componentType));
  if (components_ <= 0 || component_size_ <= 0) {
    throw LoadError{absl::StrCat(what_, ": accessor ", index, " has an invalid type")};
  }
  if (acc_->sparse.isSparse) {
    MakeDense(model, index);
    return;
  }
  if (acc_->bufferView < 0 || acc_->bufferView >= static_cast<int>(model.bufferViews.size())) {
    throw LoadError{absl::StrCat(what_, ": accessor ", index, " has no valid bufferView")};
  }
  const tinygltf::BufferView& view = model.bufferViews[acc_->bufferView];
  const int stride = acc_->ByteStride(view);
  if (stride <= 0) throw LoadError{absl::StrCat(what_, ": accessor ", index, " has an invalid stride")};
  stride_ = static_cast<size_t>(stride);
  const size_t element = static_cast<size_t>(components_) * static_cast<size_t>(component_size_);
  // The last element must end inside the view, and the view inside the buffer.
  const size_t need = acc_->count == 0 ? 0 : (acc_->count - 1) * stride_ + element;
  try {
    base_ = ViewBytes(model, acc_->bufferView, acc_->byteOffset, need, what_);
  } catch (const LoadError&) {
    throw LoadError{absl::StrCat(what_, ": accessor ", index, " reads past the end of its buffer")};
  }
}

void AccessorReader::MakeDense(const tinygltf::Model& model, int index) {
  const std::string where = absl::StrCat(what_, ": sparse accessor ", index);
  const size_t element = static_cast<size_t>(components_) * static_cast<size_t>(component_size_);
  const size_t count = acc_->count;
  if (count > kMaxDenseBytes / element) {
    throw LoadError{absl::StrCat(where, ": ", count, " elements are more than 256 MiB")};
  }
  dense_.assign(count * element, 0);
  if (acc_->bufferView >= 0 && count > 0) {  // base values; without a bufferView they are zeros
    if (acc_->bufferView >= static_cast<int>(model.bufferViews.size())) {
      throw LoadError{absl::StrCat(where, ": bufferView ", acc_->bufferView, " does not exist")};
    }
    const int stride = acc_->ByteStride(model.bufferViews[acc_->bufferView]);
    if (stride <= 0) throw LoadError{absl::StrCat(where, ": invalid stride")};
    const unsigned char* src = ViewBytes(model, acc_->bufferView, acc_->byteOffset,
                                         (count - 1) * static_cast<size_t>(stride) + element, where);
    for (size_t i = 0; i < count; ++i) {
      std::memcpy(dense_.data() + i * element, src + i * static_cast<size_t>(stride), element);
    }
  }
  // The substitutions (3.6.2.3): strictly increasing indices, values tightly packed.
  const auto& sp = acc_->sparse;
  const int ict = sp.indices.componentType;
  const size_t isize = ict == TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE    ? 1
                       : ict == TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT ? 2
                       : ict == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT   ? 4
                                                                       : 0;
  if (isize == 0) throw LoadError{absl::StrCat(where, ": sparse.indices.componentType ", ict, " is not an unsigned integer")};
  if (sp.count < 1 || static_cast<size_t>(sp.count) > count) {
    throw LoadError{absl::StrCat(where, ": sparse.count ", sp.count, " is not in [1, ", count, "]")};
  }
  if (sp.indices.byteOffset < 0 || sp.values.byteOffset < 0) {
    throw LoadError{absl::StrCat(where, ": negative sparse byteOffset")};
  }
  const size_t n = static_cast<size_t>(sp.count);
  const unsigned char* idx = ViewBytes(model, sp.indices.bufferView, static_cast<size_t>(sp.indices.byteOffset),
                                       n * isize, where + ", sparse.indices");
  const unsigned char* val = ViewBytes(model, sp.values.bufferView, static_cast<size_t>(sp.values.byteOffset),
                                       n * element, where + ", sparse.values");
  uint64_t previous = 0;
  for (size_t k = 0; k < n; ++k) {
    const unsigned char* p = idx + k * isize;
    const uint64_t target = isize == 1 ? Load<uint8_t>(p) : isize == 2 ? Load<uint16_t>(p) : Load<uint32_t>(p);
    if (target >= count || (k > 0 && target <= previous)) {
      throw LoadError{absl::StrCat(where, ": sparse index ", k, " = ", target,
                                   " is out of range or not increasing (", count, " elements)")};
    }
    previous = target;
    std::memcpy(dense_.data() + target * element, val + k * element, element);
  }
  stride_ = element;
  base_ = dense_.data();
}

double AccessorReader::Get(size_t i, int c) const {
  const unsigned char* p = base_ + i * stride_ + static_cast<size_t>(c) * component_size_;
  switch (acc_->componentType) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return Load<float>(p);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: return Load<uint32_t>(p);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      const double v = Load<uint16_t>(p);
      return acc_->normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
      const double v = Load<uint8_t>(p);
      return acc_->normalized ? v / 255.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      const double v = Load<int16_t>(p);
      return acc_->normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      const double v = Load<int8_t>(p);
      return acc_->normalized ? std::max(v / 127.0, -1.0) : v;
    }
    default: return NAN;
  }
}

}  // namespace vistream::scenes::gltf_detail
