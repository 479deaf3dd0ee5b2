#include "scenes/gltf_decode.h"

#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include <absl/strings/str_cat.h>
#include <draco/compression/decode.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include "scenes/gltf_accessor.h"

namespace vistream::scenes::gltf_detail {

namespace {

constexpr char kDraco[] = "KHR_draco_mesh_compression";
constexpr char kMeshopt[] = "EXT_meshopt_compression";
// Decoded data has no size bound in the file (a few compressed bytes can claim millions of
// vertices), so each decoded view or attribute is capped.
constexpr size_t kMaxDecodedBytes = size_t{1} << 28;

// Extensions a file may require that this reader honours, or that change only appearance
// (vistream draws flat-shaded geometry): anything else required changes what the geometry
// is (instancing, other compression) and is refused.
bool SupportedRequired(std::string_view name) {
  for (std::string_view prefix : {"KHR_materials_", "KHR_texture_", "EXT_texture_"}) {
    if (name.substr(0, prefix.size()) == prefix) return true;
  }
  return name == kDraco || name == kMeshopt || name == "KHR_mesh_quantization" || name == "KHR_lights_punctual";
}

uint32_t ReadU32(const char* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  return v;  // .glb is little-endian, as is every platform vistream builds on
}
void AppendU32(std::string* out, uint32_t v) { out->append(reinterpret_cast<const char*>(&v), 4); }

// The JSON rewrite of PrepareCompressed; false when nothing had to change.
bool RewriteJson(nlohmann::json* j) {
  if (!j->is_object()) return false;
  if (auto it = j->find("extensionsRequired"); it != j->end() && it->is_array()) {
    for (const auto& e : *it) {
      if (e.is_string() && !SupportedRequired(e.get<std::string>())) {
        throw LoadError{absl::StrCat("extensionsRequired: extension '", e.get<std::string>(),
                                     "' is not supported (vistream reads ", kDraco, ", ", kMeshopt,
                                     " and KHR_mesh_quantization)")};
      }
    }
  }
  bool changed = false;
  if (auto meshes = j->find("meshes"); meshes != j->end() && meshes->is_array()) {
    for (auto& mesh : *meshes) {
      if (!mesh.is_object() || !mesh.contains("primitives") || !mesh["primitives"].is_array()) continue;
      for (auto& prim : mesh["primitives"]) {
        if (!prim.is_object() || !prim.contains("extensions") || !prim["extensions"].is_object() ||
            !prim["extensions"].contains(kDraco)) {
          continue;
        }
        changed |= prim.erase("indices") > 0;  // Draco's faces replace them
      }
    }
  }
  if (auto buffers = j->find("buffers"); buffers != j->end() && buffers->is_array()) {
    for (auto& buffer : *buffers) {
      if (!buffer.is_object() || buffer.contains("uri") || !buffer.contains("extensions")) continue;
      const auto& ext = buffer["extensions"];
      if (!ext.is_object() || !ext.contains(kMeshopt) || !ext[kMeshopt].is_object()) continue;
      const auto& fallback = ext[kMeshopt].value("fallback", nlohmann::json(false));
      if (!fallback.is_boolean() || !fallback.get<bool>()) continue;
      // Its views are all decoded from another buffer; four zero bytes satisfy tinygltf.
      buffer["uri"] = "data:application/octet-stream;base64,AAAAAA==";
      buffer["byteLength"] = 4;
      changed = true;
    }
  }
  return changed;
}

// An extension object's integer member, or `fallback` when absent; errors name `what`.
size_t UnsignedMember(const tinygltf::Value& ext, const char* key, const std::string& what, bool required,
                      size_t fallback = 0) {
  if (!ext.Has(key)) {
    if (required) throw LoadError{absl::StrCat(what, ": '", key, "' is missing")};
    return fallback;
  }
  const tinygltf::Value& v = ext.Get(key);
  if (!v.IsNumber()) throw LoadError{absl::StrCat(what, ": '", key, "' is not a number")};
  const double d = v.GetNumberAsDouble();
  if (!(d >= 0.0 && d <= 9007199254740992.0) || d != static_cast<double>(static_cast<uint64_t>(d))) {
    throw LoadError{absl::StrCat(what, ": '", key, "' is not a non-negative integer")};
  }
  return static_cast<size_t>(d);
}

std::string StringMember(const tinygltf::Value& ext, const char* key, const std::string& fallback) {
  if (!ext.Has(key) || !ext.Get(key).IsString()) return fallback;
  return ext.Get(key).Get<std::string>();
}

int AddBuffer(tinygltf::Model* model, std::vector<unsigned char> data) {
  tinygltf::Buffer b;
  b.data = std::move(data);
  model->buffers.push_back(std::move(b));
  return static_cast<int>(model->buffers.size() - 1);
}

// EXT_meshopt_compression on bufferView `v`: its data becomes the decoded bytes.
void DecodeMeshoptView(tinygltf::Model* model, int v) {
  const std::string what = absl::StrCat("bufferView ", v, ": ", kMeshopt);
  const tinygltf::Value& ext = model->bufferViews[v].extensions.at(std::string(kMeshopt));
  if (!ext.IsObject()) throw LoadError{absl::StrCat(what, ": not an object")};
  const size_t buffer = UnsignedMember(ext, "buffer", what, true);
  const size_t offset = UnsignedMember(ext, "byteOffset", what, false);
  const size_t length = UnsignedMember(ext, "byteLength", what, true);
  const size_t stride = UnsignedMember(ext, "byteStride", what, true);
  const size_t count = UnsignedMember(ext, "count", what, true);
  const std::string mode = StringMember(ext, "mode", "");
  const std::string filter = StringMember(ext, "filter", "NONE");
  if (buffer >= model->buffers.size()) throw LoadError{absl::StrCat(what, ": buffer ", buffer, " does not exist")};
  const auto& src = model->buffers[buffer].data;
  if (offset > src.size() || length > src.size() - offset) {
    throw LoadError{absl::StrCat(what, ": byteOffset + byteLength pass the end of buffer ", buffer)};
  }
  if (stride == 0 || count > kMaxDecodedBytes / stride) {
    throw LoadError{absl::StrCat(what, ": count x byteStride is zero or more than 256 MiB")};
  }
  std::vector<unsigned char> out(count * stride);
  const unsigned char* in = src.data() + offset;
  int rc = 0;
  // meshoptimizer asserts its preconditions rather than checking them: check them here.
  if (mode == "ATTRIBUTES") {
    if (stride % 4 != 0 || stride > 256) throw LoadError{absl::StrCat(what, ": ATTRIBUTES byteStride ", stride, " is not a multiple of 4 up to 256")};
    rc = meshopt_decodeVertexBuffer(out.data(), count, stride, in, length);
  } else if (mode == "TRIANGLES" || mode == "INDICES") {
    if (stride != 2 && stride != 4) throw LoadError{absl::StrCat(what, ": ", mode, " byteStride ", stride, " is not 2 or 4")};
    if (mode == "TRIANGLES") {
      if (count % 3 != 0) throw LoadError{absl::StrCat(what, ": TRIANGLES count ", count, " is not a multiple of 3")};
      rc = meshopt_decodeIndexBuffer(out.data(), count, stride, in, length);
    } else {
      rc = meshopt_decodeIndexSequence(out.data(), count, stride, in, length);
    }
  } else {
    throw LoadError{absl::StrCat(what, ": mode '", mode, "' is not ATTRIBUTES, TRIANGLES or INDICES")};
  }
  if (rc != 0) throw LoadError{absl::StrCat(what, ": the ", mode, " data does not decode (meshoptimizer error ", rc, ")")};
  if (filter != "NONE") {
    if (mode != "ATTRIBUTES") throw LoadError{absl::StrCat(what, ": filter ", filter, " on ", mode, " data")};
    if (filter == "OCTAHEDRAL" && (stride == 4 || stride == 8)) meshopt_decodeFilterOct(out.data(), count, stride);
    else if (filter == "QUATERNION" && stride == 8) meshopt_decodeFilterQuat(out.data(), count, stride);
    else if (filter == "EXPONENTIAL") meshopt_decodeFilterExp(out.data(), count, stride);
    else throw LoadError{absl::StrCat(what, ": filter '", filter, "' with byteStride ", stride, " is not supported")};
  }
  tinygltf::BufferView& view = model->bufferViews[v];
  view.buffer = AddBuffer(model, std::move(out));
  view.byteOffset = 0;
  view.byteLength = count * stride;
  view.extensions.erase(std::string(kMeshopt));
}

// A new tightly packed bufferView over a new buffer holding `data`, and an accessor on it.
int AddAccessor(tinygltf::Model* model, std::vector<unsigned char> data, int component_type, int type,
                size_t count) {
  tinygltf::BufferView view;
  view.byteLength = data.size();
  view.buffer = AddBuffer(model, std::move(data));
  model->bufferViews.push_back(std::move(view));
  tinygltf::Accessor a;
  a.bufferView = static_cast<int>(model->bufferViews.size() - 1);
  a.componentType = component_type;
  a.type = type;
  a.count = count;
  model->accessors.push_back(std::move(a));
  return static_cast<int>(model->accessors.size() - 1);
}

// KHR_draco_mesh_compression on a primitive: its indices and compressed attributes become
// new accessors of the decoded triangles and points.
void DecodeDracoPrimitive(tinygltf::Model* model, tinygltf::Primitive* prim, const std::string& where) {
  const std::string what = absl::StrCat(where, ": ", kDraco);
  const tinygltf::Value ext = prim->extensions.at(std::string(kDraco));  // a copy: model grows
  if (!ext.IsObject()) throw LoadError{absl::StrCat(what, ": not an object")};
  if (prim->mode != TINYGLTF_MODE_TRIANGLES && prim->mode != TINYGLTF_MODE_TRIANGLE_STRIP) {
    throw LoadError{absl::StrCat(what, ": mode ", prim->mode, " is not triangles")};
  }
  const size_t view = UnsignedMember(ext, "bufferView", what, true);
  if (view >= model->bufferViews.size()) throw LoadError{absl::StrCat(what, ": bufferView ", view, " does not exist")};
  const unsigned char* bytes =
      ViewBytes(*model, static_cast<int>(view), 0, model->bufferViews[view].byteLength, what);
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(bytes), model->bufferViews[view].byteLength);
  auto type = draco::Decoder::GetEncodedGeometryType(&buffer);
  if (!type.ok()) throw LoadError{absl::StrCat(what, ": not Draco data (", type.status().error_msg_string(), ")")};
  if (type.value() != draco::TRIANGULAR_MESH) throw LoadError{absl::StrCat(what, ": Draco data is not a triangle mesh")};
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&buffer);
  if (!decoded.ok()) {
    throw LoadError{absl::StrCat(what, ": Draco data does not decode (", decoded.status().error_msg_string(), ")")};
  }
  const draco::Mesh& mesh = *decoded.value();
  const size_t points = mesh.num_points(), faces = mesh.num_faces();
  if (faces > kMaxDecodedBytes / 12) throw LoadError{absl::StrCat(what, ": more than 256 MiB of indices")};
  std::vector<unsigned char> index_bytes(faces * 12);
  for (size_t f = 0; f < faces; ++f) {
    const draco::Mesh::Face& face = mesh.face(draco::FaceIndex(static_cast<uint32_t>(f)));
    for (int k = 0; k < 3; ++k) {
      const uint32_t p = face[k].value();
      if (p >= points) throw LoadError{absl::StrCat(what, ": face ", f, " names point ", p, " of ", points)};
      std::memcpy(index_bytes.data() + (f * 3 + k) * 4, &p, 4);
    }
  }
  prim->indices = AddAccessor(model, std::move(index_bytes), TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                              TINYGLTF_TYPE_SCALAR, faces * 3);
  prim->mode = TINYGLTF_MODE_TRIANGLES;  // Draco stores a strip as its triangles

  if (!ext.Has("attributes") || !ext.Get("attributes").IsObject()) {
    throw LoadError{absl::StrCat(what, ": 'attributes' is missing or not an object")};
  }
  const tinygltf::Value& attributes = ext.Get("attributes");
  for (const std::string& name : attributes.Keys()) {
    const std::string awhat = absl::StrCat(what, ": attribute ", name);
    const tinygltf::Value& id = attributes.Get(name);
    if (!id.IsInt()) throw LoadError{absl::StrCat(awhat, ": the Draco id is not an integer")};
    const draco::PointAttribute* att = mesh.GetAttributeByUniqueId(static_cast<uint32_t>(id.GetNumberAsInt()));
    if (att == nullptr) throw LoadError{absl::StrCat(awhat, ": Draco id ", id.GetNumberAsInt(), " is not in the stream")};
    const auto acc_it = prim->attributes.find(name);
    if (acc_it == prim->attributes.end() || acc_it->second < 0 ||
        acc_it->second >= static_cast<int>(model->accessors.size())) {
      throw LoadError{absl::StrCat(awhat, ": the primitive has no valid accessor for it")};
    }
    const int gltf_type = model->accessors[acc_it->second].type;
    const int n = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(gltf_type));
    if (n <= 0 || n > 4 || n != att->num_components()) {
      throw LoadError{absl::StrCat(awhat, ": ", static_cast<int>(att->num_components()),
                                   " Draco components for accessor type ", gltf_type)};
    }
    if (points > kMaxDecodedBytes / (4 * static_cast<size_t>(n))) {
      throw LoadError{absl::StrCat(awhat, ": more than 256 MiB decoded")};
    }
    std::vector<unsigned char> values(points * 4 * static_cast<size_t>(n));
    float v[4];
    for (size_t p = 0; p < points; ++p) {
      const draco::PointIndex pi(static_cast<uint32_t>(p));
      if (!att->is_mapping_identity() && p >= att->indices_map_size()) {
        throw LoadError{absl::StrCat(awhat, ": point ", p, " has no value")};
      }
      const draco::AttributeValueIndex avi = att->mapped_index(pi);
      if (avi.value() >= att->size() || !att->ConvertValue<float>(avi, static_cast<int8_t>(n), v)) {
        throw LoadError{absl::StrCat(awhat, ": point ", p, " has no value")};
      }
      std::memcpy(values.data() + p * 4 * static_cast<size_t>(n), v, 4 * static_cast<size_t>(n));
    }
    acc_it->second = AddAccessor(model, std::move(values), TINYGLTF_COMPONENT_TYPE_FLOAT, gltf_type, points);
  }
  prim->extensions.erase(std::string(kDraco));
}

}  // namespace

std::string_view PrepareCompressed(std::string_view bytes, bool binary, std::string* storage) {
  std::string_view json_text = bytes;
  if (binary) {
    // .glb (glTF 2.0, 4.4): 12-byte header, then the JSON chunk's length, type and bytes.
    if (bytes.size() < 20 || bytes.substr(0, 4) != "glTF") return bytes;
    const uint32_t json_length = ReadU32(bytes.data() + 12);
    if (ReadU32(bytes.data() + 16) != 0x4E4F534Au || json_length > bytes.size() - 20) return bytes;
    json_text = bytes.substr(20, json_length);
  }
  // Most files use neither: skip the second parse of their JSON.
  if (json_text.find(kDraco) == std::string_view::npos && json_text.find(kMeshopt) == std::string_view::npos &&
      json_text.find("extensionsRequired") == std::string_view::npos) {
    return bytes;
  }
  nlohmann::json j = nlohmann::json::parse(json_text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded() || !RewriteJson(&j)) return bytes;
  std::string text = j.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  if (!binary) {
    *storage = std::move(text);
    return *storage;
  }
  while (text.size() % 4 != 0) text.push_back(' ');
  const std::string_view rest = bytes.substr(20 + json_text.size());  // the BIN chunk, as it was
  const size_t total = 20 + text.size() + rest.size();
  if (total > std::numeric_limits<uint32_t>::max()) return bytes;
  storage->clear();
  storage->reserve(total);
  storage->append("glTF");
  AppendU32(storage, 2);
  AppendU32(storage, static_cast<uint32_t>(total));
  AppendU32(storage, static_cast<uint32_t>(text.size()));
  AppendU32(storage, 0x4E4F534Au);
  storage->append(text);
  storage->append(rest);
  return *storage;
}

void DecodeCompressed(tinygltf::Model* model) {
  const std::string meshopt(kMeshopt), draco(kDraco);
  for (size_t v = 0; v < model->bufferViews.size(); ++v) {
    if (model->bufferViews[v].extensions.count(meshopt) != 0) DecodeMeshoptView(model, static_cast<int>(v));
  }
  for (size_t m = 0; m < model->meshes.size(); ++m) {
    for (size_t p = 0; p < model->meshes[m].primitives.size(); ++p) {
      tinygltf::Primitive& prim = model->meshes[m].primitives[p];
      if (prim.extensions.count(draco) == 0) continue;
      DecodeDracoPrimitive(model, &prim, absl::StrCat("mesh ", m, ", primitive ", p));
    }
  }
}

}  // namespace vistream::scenes::gltf_detail
