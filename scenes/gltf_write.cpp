#include "scenes/gltf_io.h"

#include "scenes/gltf_frame.h"
#include "scenes/levels.h"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <algorithm>
#include <filesystem>
#include <fstream>

#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/mat4x4.hpp>
#include <tiny_gltf.h>

namespace vistream::scenes {

namespace {

namespace fs = std::filesystem;
using gltf_detail::EndsWith;
using gltf_detail::GltfFromZup;

// Appends raw bytes of `values` to `buffer`, 4-byte aligned; returns the byte offset.
template <typename T>
size_t AppendBytes(const std::vector<T>& values, std::vector<unsigned char>* buffer) {
  while (buffer->size() % 4 != 0) buffer->push_back(0);
  const size_t offset = buffer->size();
  buffer->resize(offset + values.size() * sizeof(T));
  if (!values.empty()) std::memcpy(buffer->data() + offset, values.data(), values.size() * sizeof(T));
  return offset;
}

// The shortest decimal that reads back as the same float: min/max stay exact for float
// readers and the JSON stays short (3017.408, not 3017.407958984375).
double ShortFloat(double value) {
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), static_cast<float>(value));
  return std::strtod(std::string(buf, r.ptr).c_str(), nullptr);
}

}  // namespace

absl::Status SaveGltf(const Scene& scene, const std::string& path) {
  if (absl::Status s = ValidateScene(scene, path); !s.ok()) return s;
  const bool binary = EndsWith(path, ".glb");
  tinygltf::Model model;
  model.asset.version = "2.0";
  model.asset.generator = "vistream";
  model.buffers.resize(1);
  tinygltf::Buffer& buffer = model.buffers[0];

  if (absl::Status s = ValidateLevels(scene.levels, scene, path); !s.ok()) return s;
  // Every mesh written: the objects', then each object's levels, then each cluster's levels.
  std::vector<const Mesh*> meshes;
  for (const Object& o : scene.objects) meshes.push_back(&o.mesh);
  for (const auto& chain : scene.levels.objects) {
    for (const MeshLevel& l : chain) meshes.push_back(&l.mesh);
  }
  for (const Cluster& c : scene.levels.clusters) {
    for (const MeshLevel& l : c.levels) meshes.push_back(&l.mesh);
  }
  // Three interleaving-free streams, each one bufferView; each mesh's accessors are ranges
  // of them, so that every mesh has its own vertex count and bounds (viewers cull by them).
  std::vector<glm::vec3> positions, normals;
  std::vector<uint32_t> indices;
  size_t vertex_total = 0;
  for (const Mesh* m : meshes) vertex_total += m->positions.size();
  if (vertex_total > std::numeric_limits<uint32_t>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": more than 2^32 vertices"));
  }
  positions.reserve(vertex_total);
  normals.reserve(vertex_total);
  for (const Mesh* m : meshes) {
    for (const glm::vec3& p : m->positions) positions.emplace_back(GltfFromZup(glm::dvec3(p)));
    for (const glm::vec3& n : m->normals) normals.emplace_back(GltfFromZup(glm::dvec3(n)));
    indices.insert(indices.end(), m->indices.begin(), m->indices.end());  // mesh-local
  }
  const size_t pos_off = AppendBytes(positions, &buffer.data);
  const size_t nrm_off = AppendBytes(normals, &buffer.data);
  const size_t idx_off = AppendBytes(indices, &buffer.data);
  auto add_view = [&](size_t offset, size_t length, int target) {
    tinygltf::BufferView v;
    // Several accessors share the vertex views: glTF 2.0 (3.6.2.4) then wants the stride.
    if (target == TINYGLTF_TARGET_ARRAY_BUFFER) v.byteStride = sizeof(glm::vec3);
    v.buffer = 0;
    v.byteOffset = offset;
    v.byteLength = length;
    v.target = target;
    model.bufferViews.push_back(v);
  };
  add_view(pos_off, positions.size() * sizeof(glm::vec3), TINYGLTF_TARGET_ARRAY_BUFFER);
  add_view(nrm_off, normals.size() * sizeof(glm::vec3), TINYGLTF_TARGET_ARRAY_BUFFER);
  add_view(idx_off, indices.size() * sizeof(uint32_t), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER);

  // The origin node: its translation is the scene origin; objects are its children.
  tinygltf::Node root;
  root.name = scene.name.empty() ? "vistream" : scene.name;
  const glm::dvec3 origin = GltfFromZup(scene.origin);
  root.translation = {origin.x, origin.y, origin.z};
  tinygltf::Value::Object root_extras{{"origin", tinygltf::Value(true)}};
  if (!scene.crs.empty()) root_extras.emplace("crs", tinygltf::Value(scene.crs));
  if (!scene.paths.empty()) {
    tinygltf::Value::Array paths;
    for (const ScenePath& p : scene.paths) {
      tinygltf::Value::Array xy;
      xy.reserve(2 * p.waypoints.size());
      for (const glm::dvec2& w : p.waypoints) {
        xy.emplace_back(w.x);
        xy.emplace_back(w.y);
      }
      paths.emplace_back(tinygltf::Value::Object{{"name", tinygltf::Value(p.name)},
                                                 {"waypoints", tinygltf::Value(std::move(xy))}});
    }
    root_extras.emplace("paths", tinygltf::Value(std::move(paths)));
  }
  root.extras = tinygltf::Value(tinygltf::Value::Object{{"vistream", tinygltf::Value(std::move(root_extras))}});
  model.nodes.push_back(root);

  std::vector<std::vector<const Occluder25D*>> occluders(scene.objects.size());
  for (const Occluder25D& oc : scene.occluders) occluders[oc.object].push_back(&oc);

  auto add_accessor = [&](int view, size_t offset, size_t count, int ctype, int type) {
    tinygltf::Accessor a;
    a.bufferView = view;
    a.byteOffset = offset;
    a.count = count;
    a.componentType = ctype;
    a.type = type;
    model.accessors.push_back(a);
    return static_cast<int>(model.accessors.size() - 1);
  };
  size_t vertex_base = 0, index_base = 0;
  // The glTF mesh of the next entry of `meshes` (called in their order).
  auto add_mesh = [&](const Mesh& m) {
    const size_t nv = m.positions.size(), ni = m.indices.size();
    const int pa = add_accessor(0, vertex_base * sizeof(glm::vec3), nv, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                TINYGLTF_TYPE_VEC3);
    glm::dvec3 lo(INFINITY), hi(-INFINITY);  // POSITION needs min and max (glTF 2.0, 3.6.2.4)
    for (size_t k = vertex_base; k < vertex_base + nv; ++k) {
      lo = glm::min(lo, glm::dvec3(positions[k]));
      hi = glm::max(hi, glm::dvec3(positions[k]));
    }
    model.accessors[pa].minValues = {ShortFloat(lo.x), ShortFloat(lo.y), ShortFloat(lo.z)};
    model.accessors[pa].maxValues = {ShortFloat(hi.x), ShortFloat(hi.y), ShortFloat(hi.z)};
    const int na = add_accessor(1, vertex_base * sizeof(glm::vec3), nv, TINYGLTF_COMPONENT_TYPE_FLOAT,
                                TINYGLTF_TYPE_VEC3);
    const int ia = add_accessor(2, index_base * sizeof(uint32_t), ni, TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT,
                                TINYGLTF_TYPE_SCALAR);
    vertex_base += nv;
    index_base += ni;

    tinygltf::Primitive prim;
    prim.attributes["POSITION"] = pa;
    prim.attributes["NORMAL"] = na;
    prim.indices = ia;
    prim.mode = TINYGLTF_MODE_TRIANGLES;
    tinygltf::Mesh mesh;
    mesh.primitives.push_back(prim);
    model.meshes.push_back(std::move(mesh));
    return static_cast<int>(model.meshes.size() - 1);
  };
  std::vector<int> object_nodes;
  for (const Object& o : scene.objects) {
    tinygltf::Node node;
    node.name = o.name;
    node.mesh = add_mesh(o.mesh);
    tinygltf::Value::Object extras;
    if (!o.type.empty()) extras.emplace("type", tinygltf::Value(o.type));
    if (std::binary_search(scene.terrain.begin(), scene.terrain.end(), o.id)) {
      extras.emplace("terrain", tinygltf::Value(true));
    }
    if (!occluders[o.id].empty()) {
      tinygltf::Value::Array list;
      for (const Occluder25D* oc : occluders[o.id]) {
        tinygltf::Value::Array fp;
        for (const glm::dvec2& p : oc->footprint) {
          fp.emplace_back(p.x);
          fp.emplace_back(p.y);
        }
        list.emplace_back(tinygltf::Value::Object{{"footprint", tinygltf::Value(std::move(fp))},
                                                  {"height", tinygltf::Value(oc->height)}});
      }
      extras.emplace("occluders", tinygltf::Value(std::move(list)));
    }
    if (!extras.empty()) {
      node.extras = tinygltf::Value(tinygltf::Value::Object{{"vistream", tinygltf::Value(std::move(extras))}});
    }
    model.nodes.push_back(std::move(node));
    model.nodes[0].children.push_back(static_cast<int>(model.nodes.size() - 1));
    object_nodes.push_back(static_cast<int>(model.nodes.size() - 1));
  }
  // Levels: nodes outside the scene's hierarchy, in the origin node's frame (no transform of
  // their own), each with its measured error; an object's listed by MSFT_lod on its node.
  auto add_level = [&](const MeshLevel& l, const std::string& name) {
    tinygltf::Node node;
    node.name = name;
    node.mesh = add_mesh(l.mesh);
    node.extras = tinygltf::Value(
        tinygltf::Value::Object{{"vistream", tinygltf::Value(tinygltf::Value::Object{{"lod_error_m", tinygltf::Value(l.error_m)}})}});
    model.nodes.push_back(std::move(node));
    return static_cast<int>(model.nodes.size() - 1);
  };
  bool lod = false;
  for (size_t i = 0; i < scene.levels.objects.size(); ++i) {
    tinygltf::Value::Array ids;
    for (size_t k = 0; k < scene.levels.objects[i].size(); ++k) {
      ids.emplace_back(add_level(scene.levels.objects[i][k], absl::StrCat(scene.objects[i].name, " level ", k + 1)));
    }
    if (ids.empty()) continue;
    lod = true;
    model.nodes[object_nodes[i]].extensions["MSFT_lod"] =
        tinygltf::Value(tinygltf::Value::Object{{"ids", tinygltf::Value(std::move(ids))}});
  }
  if (!scene.levels.clusters.empty()) {
    tinygltf::Value::Array clusters;
    for (size_t c = 0; c < scene.levels.clusters.size(); ++c) {
      const Cluster& cl = scene.levels.clusters[c];
      tinygltf::Value::Array objects, nodes;
      for (const uint32_t o : cl.objects) objects.emplace_back(static_cast<int>(o));
      for (size_t k = 0; k < cl.levels.size(); ++k) {
        nodes.emplace_back(add_level(cl.levels[k], absl::StrCat("cluster ", c, " level ", k + 1)));
      }
      clusters.emplace_back(tinygltf::Value::Object{{"objects", tinygltf::Value(std::move(objects))},
                                                    {"nodes", tinygltf::Value(std::move(nodes))}});
    }
    auto origin_extras = model.nodes[0].extras.Get("vistream").Get<tinygltf::Value::Object>();
    origin_extras.emplace("clusters", tinygltf::Value(std::move(clusters)));
    model.nodes[0].extras = tinygltf::Value(tinygltf::Value::Object{{"vistream", tinygltf::Value(std::move(origin_extras))}});
  }
  if (lod) model.extensionsUsed.push_back("MSFT_lod");
  tinygltf::Scene s;
  s.name = scene.name;
  s.nodes = {0};
  model.scenes.push_back(s);
  model.defaultScene = 0;

  if (!binary) buffer.uri = fs::path(path).stem().string() + ".bin";
  tinygltf::TinyGLTF writer;
  if (binary) {
    // Written beside and renamed, so a reader never sees half a file, and a failed write (a
    // full disk, a file size limit) leaves what was there before: tinygltf does not check
    // its stream, so the stream is ours.
    const std::string tmp = path + ".tmp";
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out.is_open()) return absl::UnavailableError(absl::StrCat(path, ": cannot create: ", std::strerror(errno)));
    bool ok = false;
    try {
      ok = writer.WriteGltfSceneToStream(&model, out, /*prettyPrint=*/false, /*writeBinary=*/true);
    } catch (const std::exception& e) {
      out.close();
      fs::remove(tmp);
      return absl::InternalError(absl::StrCat(path, ": writing failed: ", e.what()));
    }
    out.close();
    if (!ok || out.fail()) {
      fs::remove(tmp);
      return absl::UnavailableError(absl::StrCat(path, ": cannot write (disk full, or a file size limit?)"));
    }
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) {
      fs::remove(tmp);
      return absl::UnavailableError(absl::StrCat(path, ": cannot write: ", ec.message()));
    }
    return absl::OkStatus();
  }
  bool ok = false;
  try {
    ok = writer.WriteGltfSceneToFile(&model, path, /*embedImages=*/true, /*embedBuffers=*/false, /*prettyPrint=*/false,
                                     /*writeBinary=*/false);
  } catch (const std::exception& e) {
    return absl::InternalError(absl::StrCat(path, ": writing failed: ", e.what()));
  }
  if (!ok) return absl::UnavailableError(absl::StrCat(path, ": cannot write file"));
  // tinygltf writes the JSON and its .bin without checking either stream: a write cut short
  // shows as a .bin shorter than the buffer or a JSON that does not end its object.
  const fs::path bin = fs::path(path).parent_path() / buffer.uri;
  std::error_code ec;
  const uintmax_t bin_size = fs::file_size(bin, ec);
  bool whole = !ec && bin_size == buffer.data.size();
  if (whole) {
    // tinygltf ends the JSON with a newline.
    std::ifstream in(path, std::ios::binary | std::ios::ate);
    whole = in.is_open() && in.tellg() >= 2;
    if (whole) {
      char end[2] = {};
      in.seekg(-2, std::ios::end);
      whole = in.read(end, 2) && end[0] == '}' && end[1] == '\n';
    }
  }
  if (!whole) return absl::UnavailableError(absl::StrCat(path, ": cannot write (disk full, or a file size limit?)"));
  return absl::OkStatus();
}

}  // namespace vistream::scenes
