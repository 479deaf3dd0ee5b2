#include "scenes/gltf_io.h"

#include "scenes/gltf_accessor.h"
#include "scenes/gltf_decode.h"
#include "scenes/gltf_frame.h"
#include "scenes/levels.h"

#include <cmath>
#include <cstring>
#include <algorithm>
#include <filesystem>
#include <fstream>
#include <unordered_set>

#include <absl/strings/str_cat.h>
#include <absl/strings/str_join.h>
#include <glm/geometric.hpp>
#include <glm/mat3x3.hpp>
#include <glm/mat4x4.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <tiny_gltf.h>

namespace vistream::scenes {

namespace {

namespace fs = std::filesystem;

using gltf_detail::AccessorReader;
using gltf_detail::EndsWith;
using gltf_detail::kZupFromGltf;
using gltf_detail::LoadError;
using gltf_detail::ZupFromGltf;

const glm::dmat4 kGltfFromZup = glm::inverse(kZupFromGltf);

constexpr int kMaxNodeDepth = 256;

glm::dmat4 LocalMatrix(const tinygltf::Node& node) {
  if (node.matrix.size() == 16) return glm::make_mat4(node.matrix.data());
  glm::dmat4 m(1.0);
  if (node.translation.size() == 3) {
    m = glm::translate(m, glm::dvec3(node.translation[0], node.translation[1], node.translation[2]));
  }
  if (node.rotation.size() == 4) {
    // glTF stores x, y, z, w; glm's constructor takes w first.
    const glm::dquat q(node.rotation[3], node.rotation[0], node.rotation[1], node.rotation[2]);
    m = m * glm::mat4_cast(glm::normalize(q));
  }
  if (node.scale.size() == 3) {
    m = glm::scale(m, glm::dvec3(node.scale[0], node.scale[1], node.scale[2]));
  }
  return m;
}

struct PendingObject {
  std::string name;
  std::vector<glm::dvec3> positions;  // world, z-up
  std::vector<glm::dvec3> normals;    // world, z-up, unit
  std::vector<uint32_t> indices;
  std::vector<Occluder25D> occluders;  // world footprints, z-up
  bool terrain = false;                // extras.vistream.terrain
  // The node's frame is the origin node's: its occluders are kept as written, already
  // scene-local (exact doubles: nothing added and taken away again).
  bool occluders_local = false;
  std::string type;                    // extras.vistream.type
  std::vector<int> lod_nodes;          // MSFT_lod ids: its coarser levels, finest first
  glm::dmat4 gltf_parent{1.0};         // the frame its LOD nodes are in (its parent's, glTF)
};

class GltfImporter {
 public:
  GltfImporter(const tinygltf::Model& model, std::string file, std::vector<std::string>* warnings)
      : model_(model), file_(std::move(file)), warnings_(warnings) {}

  Scene Import() {
    std::vector<int> roots;
    if (!model_.scenes.empty()) {
      int s = model_.defaultScene;
      if (s < 0 || s >= static_cast<int>(model_.scenes.size())) s = 0;
      roots = model_.scenes[s].nodes;
    } else {
      // No scene: every node that is nobody's child is a root.
      std::vector<bool> child(model_.nodes.size(), false);
      for (const auto& n : model_.nodes) {
        for (int c : n.children) {
          if (c >= 0 && c < static_cast<int>(child.size())) child[c] = true;
        }
      }
      for (size_t i = 0; i < child.size(); ++i) {
        if (!child[i]) roots.push_back(static_cast<int>(i));
      }
    }
    for (int r : roots) Visit(r, glm::dmat4(1.0), 0);
    return Finish();
  }

 private:
  void Warn(std::string w) {
    if (warnings_ != nullptr) warnings_->push_back(absl::StrCat(file_, ": ", w));
  }
  std::string NodeName(int index) const {
    const auto& n = model_.nodes[index];
    return n.name.empty() ? absl::StrCat("node ", index) : absl::StrCat("node ", index, " ('", n.name, "')");
  }

  void Visit(int index, const glm::dmat4& parent, int depth) {
    if (index < 0 || index >= static_cast<int>(model_.nodes.size())) {
      throw LoadError{absl::StrCat("node ", index, " does not exist")};
    }
    if (depth > kMaxNodeDepth || !on_path_.insert(index).second) {
      throw LoadError{absl::StrCat(NodeName(index), ": the node hierarchy has a cycle or is deeper than ",
                                   kMaxNodeDepth)};
    }
    const tinygltf::Node& node = model_.nodes[index];
    const glm::dmat4 local = LocalMatrix(node);
    const glm::dmat4 world = parent * local;  // glTF frame
    if (depth == 0 && IsOriginNode(node)) {
      if (origin_node_ >= 0) Warn("more than one vistream origin node; the first is used");
      else {
        origin_node_ = index;
        origin_ = ZupFromGltf(glm::dvec3(local[3]));
        origin_world_ = kZupFromGltf * world;
        origin_gltf_world_ = world;
        name_ = node.name;
        const tinygltf::Value& crs = VistreamExtra(node, "crs");
        if (crs.IsString()) crs_ = crs.Get<std::string>();
        else if (crs.Type() != tinygltf::NULL_TYPE) Warn(absl::StrCat(NodeName(index), ": extras.vistream.crs is not a string; ignored"));
        ReadPaths(index);
      }
    }
    if (node.mesh >= 0) ImportMesh(index, parent, world);
    else if (Occluders(node).IsArray()) Warn(absl::StrCat(NodeName(index), ": occluders on a node without a mesh ignored"));
    for (int c : node.children) Visit(c, world, depth + 1);
    on_path_.erase(index);
  }

  static bool IsOriginNode(const tinygltf::Node& node) {
    if (!node.extras.IsObject() || !node.extras.Has("vistream")) return false;
    const auto& v = node.extras.Get("vistream");
    return v.IsObject() && v.Has("origin") && v.Get("origin").IsBool() && v.Get("origin").Get<bool>();
  }
  // extras.vistream.KEY of `node`; a null value when absent.
  static const tinygltf::Value& VistreamExtra(const tinygltf::Node& node, const char* key) {
    static const tinygltf::Value kNone;
    if (!node.extras.IsObject() || !node.extras.Has("vistream")) return kNone;
    const auto& v = node.extras.Get("vistream");
    if (!v.IsObject() || !v.Has(key)) return kNone;
    return v.Get(key);
  }
  static const tinygltf::Value& Occluders(const tinygltf::Node& node) { return VistreamExtra(node, "occluders"); }

  // extras.vistream.paths of the origin node: walks in scene-local metres. A path that is not
  // an object with a non-empty name and 2n >= 4 finite numbers is warned about and skipped.
  void ReadPaths(int index) {
    const tinygltf::Value& list = VistreamExtra(model_.nodes[index], "paths");
    if (list.Type() == tinygltf::NULL_TYPE) return;
    const std::string where = absl::StrCat(NodeName(index), ": extras.vistream.paths");
    if (!list.IsArray()) {
      Warn(absl::StrCat(where, " is not an array; ignored"));
      return;
    }
    for (size_t k = 0; k < list.ArrayLen(); ++k) {
      const std::string pw = absl::StrCat(where, "[", k, "]");
      const tinygltf::Value& p = list.Get(static_cast<int>(k));
      if (!p.IsObject() || !p.Has("name") || !p.Get("name").IsString() || p.Get("name").Get<std::string>().empty()) {
        Warn(absl::StrCat(pw, ": expected an object with a non-empty 'name'; skipped"));
        continue;
      }
      const std::string name = p.Get("name").Get<std::string>();
      static const tinygltf::Value kNone;
      const tinygltf::Value& xy = p.Has("waypoints") ? p.Get("waypoints") : kNone;
      if (!xy.IsArray() || xy.ArrayLen() < 4 || xy.ArrayLen() % 2 != 0) {
        Warn(absl::StrCat(pw, " ('", name, "').waypoints: expected an array of 2n >= 4 numbers (x, y pairs); skipped"));
        continue;
      }
      ScenePath path;
      path.name = name;
      for (size_t i = 0; i < xy.ArrayLen(); i += 2) {
        const tinygltf::Value &x = xy.Get(static_cast<int>(i)), &y = xy.Get(static_cast<int>(i + 1));
        if (!x.IsNumber() || !y.IsNumber() || !std::isfinite(x.GetNumberAsDouble()) ||
            !std::isfinite(y.GetNumberAsDouble())) {
          path.waypoints.clear();
          Warn(absl::StrCat(pw, " ('", name, "').waypoints[", i, "]: not a finite number pair; skipped"));
          break;
        }
        path.waypoints.emplace_back(x.GetNumberAsDouble(), y.GetNumberAsDouble());
      }
      if (path.waypoints.empty()) continue;
      if (std::any_of(paths_.begin(), paths_.end(), [&](const ScenePath& q) { return q.name == name; })) {
        Warn(absl::StrCat(pw, ": a second path named '", name, "'; skipped"));
        continue;
      }
      paths_.push_back(std::move(path));
    }
  }

  void ImportMesh(int node_index, const glm::dmat4& gltf_parent, const glm::dmat4& gltf_world) {
    const tinygltf::Node& node = model_.nodes[node_index];
    const std::string what = NodeName(node_index);
    PendingObject obj;
    ReadTriangles(node_index, gltf_world, what, &obj);
    obj.name = node.name.empty() ? model_.meshes[node.mesh].name : node.name;
    if (obj.name.empty()) obj.name = absl::StrCat("object", pending_.size());
    const glm::dmat4 world = kZupFromGltf * gltf_world;
    ImportOccluders(node, world, what, &obj);
    if (obj.indices.empty()) {
      Warn(absl::StrCat(what, ": no triangles; skipped"));
      return;
    }
    const tinygltf::Value& terrain = VistreamExtra(node, "terrain");
    if (terrain.IsBool()) obj.terrain = terrain.Get<bool>();
    else if (terrain.Type() != tinygltf::NULL_TYPE) Warn(absl::StrCat(what, ": extras.vistream.terrain is not a boolean; ignored"));
    const tinygltf::Value& type = VistreamExtra(node, "type");
    if (type.IsString()) obj.type = type.Get<std::string>();
    else if (type.Type() != tinygltf::NULL_TYPE) Warn(absl::StrCat(what, ": extras.vistream.type is not a string; ignored"));
    obj.lod_nodes = LodNodes(node, what);
    obj.gltf_parent = gltf_parent;
    pending_.push_back(std::move(obj));
  }

  // MSFT_lod's ids of `node` (its coarser levels, finest first); empty without the extension.
  std::vector<int> LodNodes(const tinygltf::Node& node, const std::string& what) const {
    const auto it = node.extensions.find("MSFT_lod");
    if (it == node.extensions.end()) return {};
    const tinygltf::Value& ids = it->second.IsObject() && it->second.Has("ids") ? it->second.Get("ids") : tinygltf::Value();
    if (!ids.IsArray()) throw LoadError{absl::StrCat(what, ": MSFT_lod has no array of ids")};
    std::vector<int> out;
    for (size_t k = 0; k < ids.ArrayLen(); ++k) {
      const tinygltf::Value& id = ids.Get(static_cast<int>(k));
      if (!id.IsInt() || id.Get<int>() < 0 || id.Get<int>() >= static_cast<int>(model_.nodes.size()) ||
          model_.nodes[id.Get<int>()].mesh < 0) {
        const std::string value = id.IsInt() ? std::to_string(id.Get<int>()) : std::string("not a whole number");
        throw LoadError{absl::StrCat(what, ": MSFT_lod ids[", k, "] (", value, ") is not a node with a mesh (",
                                     model_.nodes.size(), " nodes)")};
      }
      out.push_back(id.Get<int>());
    }
    return out;
  }

  // The triangles of node `node_index`'s mesh, in `gltf_world` (the node's glTF world matrix),
  // appended to `obj` as z-up world positions and unit normals.
  void ReadTriangles(int node_index, const glm::dmat4& gltf_world, const std::string& what, PendingObject* out) {
    const tinygltf::Node& node = model_.nodes[node_index];
    if (node.mesh >= static_cast<int>(model_.meshes.size())) {
      throw LoadError{absl::StrCat(what, ": mesh ", node.mesh, " does not exist")};
    }
    PendingObject& obj = *out;
    const glm::dmat4 world = kZupFromGltf * gltf_world;                 // glTF local -> z-up world
    const glm::dmat3 normal_matrix = glm::transpose(glm::inverse(glm::dmat3(world)));
    const bool mirrored = glm::determinant(glm::dmat3(world)) < 0.0;
    const tinygltf::Mesh& mesh = model_.meshes[node.mesh];
    for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
      const tinygltf::Primitive& prim = mesh.primitives[pi];
      const std::string pwhat = absl::StrCat(what, ", mesh ", node.mesh, ", primitive ", pi);
      if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
          prim.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        Warn(absl::StrCat(pwhat, ": mode ", prim.mode, " is not triangles; skipped"));
        continue;
      }
      const auto pos_it = prim.attributes.find("POSITION");
      if (pos_it == prim.attributes.end()) {
        Warn(absl::StrCat(pwhat, ": no POSITION attribute; skipped"));
        continue;
      }
      AccessorReader pos(model_, pos_it->second, pwhat);
      if (pos.type() != TINYGLTF_TYPE_VEC3) throw LoadError{absl::StrCat(pwhat, ": POSITION is not VEC3")};
      std::vector<uint32_t> corners;  // triangle list in this primitive's vertex numbering
      std::vector<uint32_t> seq;
      if (prim.indices >= 0) {
        AccessorReader idx(model_, prim.indices, pwhat);
        const int ct = idx.component_type();
        if (idx.type() != TINYGLTF_TYPE_SCALAR ||
            (ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT && ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
             ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE)) {
          throw LoadError{absl::StrCat(pwhat, ": indices must be unsigned integer scalars")};
        }
        seq.resize(idx.count());
        for (size_t i = 0; i < idx.count(); ++i) {
          const double v = idx.Get(i, 0);
          if (!(v < static_cast<double>(pos.count()))) {
            throw LoadError{absl::StrCat(pwhat, ": index ", i, " = ", v, " is out of range (",
                                         pos.count(), " vertices)")};
          }
          seq[i] = static_cast<uint32_t>(v);
        }
      } else {
        seq.resize(pos.count());
        for (size_t i = 0; i < seq.size(); ++i) seq[i] = static_cast<uint32_t>(i);
      }
      if (prim.mode == TINYGLTF_MODE_TRIANGLES) {
        if (seq.size() % 3 != 0) Warn(absl::StrCat(pwhat, ": index count not a multiple of 3; tail dropped"));
        corners.assign(seq.begin(), seq.begin() + static_cast<long>(seq.size() / 3 * 3));
      } else {
        for (size_t i = 2; i < seq.size(); ++i) {
          if (prim.mode == TINYGLTF_MODE_TRIANGLE_FAN) corners.insert(corners.end(), {seq[0], seq[i - 1], seq[i]});
          else if (i % 2 == 0) corners.insert(corners.end(), {seq[i - 2], seq[i - 1], seq[i]});
          else corners.insert(corners.end(), {seq[i - 1], seq[i - 2], seq[i]});
        }
      }
      if (mirrored) {
        for (size_t t = 0; t + 2 < corners.size(); t += 3) std::swap(corners[t + 1], corners[t + 2]);
      }
      // Read only the vertices this primitive uses: objects may share one large vertex
      // accessor (vistream's own files do) and each reads its range through its indices.
      std::vector<uint32_t> used(corners.begin(), corners.end());
      std::sort(used.begin(), used.end());
      used.erase(std::unique(used.begin(), used.end()), used.end());
      auto local = [&used](uint32_t v) {
        return static_cast<uint32_t>(std::lower_bound(used.begin(), used.end(), v) - used.begin());
      };
      std::vector<glm::dvec3> world_pos(used.size());
      for (size_t k = 0; k < used.size(); ++k) {
        world_pos[k] = glm::dvec3(world * glm::dvec4(pos.Vec3(used[k]), 1.0));
      }
      for (uint32_t& c : corners) c = local(c);

      const auto nrm_it = prim.attributes.find("NORMAL");
      const auto base = static_cast<uint32_t>(obj.positions.size());
      if (nrm_it != prim.attributes.end()) {
        AccessorReader nrm(model_, nrm_it->second, pwhat);
        if (nrm.type() != TINYGLTF_TYPE_VEC3 || nrm.count() != pos.count()) {
          throw LoadError{absl::StrCat(pwhat, ": NORMAL must be VEC3 with one per position")};
        }
        for (size_t k = 0; k < used.size(); ++k) {
          obj.positions.push_back(world_pos[k]);
          glm::dvec3 n = normal_matrix * nrm.Vec3(used[k]);
          const double len = glm::length(n);
          obj.normals.push_back(len > 0.0 ? n / len : glm::dvec3(0, 0, 1));
        }
        for (uint32_t c : corners) obj.indices.push_back(base + c);
      } else {
        // Flat normals: every triangle gets its own three vertices.
        for (size_t t = 0; t + 2 < corners.size(); t += 3) {
          const glm::dvec3 &a = world_pos[corners[t]], &b = world_pos[corners[t + 1]], &c = world_pos[corners[t + 2]];
          glm::dvec3 n = glm::cross(b - a, c - a);
          const double len = glm::length(n);
          n = len > 0.0 ? n / len : glm::dvec3(0, 0, 1);
          for (const glm::dvec3* p : {&a, &b, &c}) {
            obj.indices.push_back(static_cast<uint32_t>(obj.positions.size()));
            obj.positions.push_back(*p);
            obj.normals.push_back(n);
          }
        }
      }
    }
  }

  void ImportOccluders(const tinygltf::Node& node, const glm::dmat4& world, const std::string& what,
                       PendingObject* obj) {
    const tinygltf::Value& list = Occluders(node);
    if (list.Type() == tinygltf::NULL_TYPE) return;
    obj->occluders_local = origin_node_ >= 0 && world == origin_world_;
    const std::string where = absl::StrCat(what, ": extras.vistream.occluders");
    if (!list.IsArray()) throw LoadError{absl::StrCat(where, ": expected an array")};
    // The node's transform (z-up in, z-up out) must keep prisms vertical and on the ground.
    const glm::dmat4 m = world * kGltfFromZup;
    const double tol = 1e-9 * (1.0 + std::abs(m[2][2]));
    const bool vertical = std::abs(m[0][2]) <= tol && std::abs(m[1][2]) <= tol &&
                          std::abs(m[2][0]) <= tol && std::abs(m[2][1]) <= tol && m[2][2] > 0.0;
    for (size_t k = 0; k < list.ArrayLen(); ++k) {
      const std::string ow = absl::StrCat(where, "[", k, "]");
      const tinygltf::Value& oc = list.Get(static_cast<int>(k));
      if (!oc.IsObject() || !oc.Has("footprint") || !oc.Has("height")) {
        throw LoadError{absl::StrCat(ow, ": expected an object with 'footprint' and 'height'")};
      }
      const tinygltf::Value& fp = oc.Get("footprint");
      const tinygltf::Value& h = oc.Get("height");
      if (!fp.IsArray() || fp.ArrayLen() < 6 || fp.ArrayLen() % 2 != 0) {
        throw LoadError{absl::StrCat(ow, ".footprint: expected an array of 2n >= 6 numbers (x, y pairs)")};
      }
      if (!h.IsNumber() || !std::isfinite(h.GetNumberAsDouble()) || h.GetNumberAsDouble() < 0.0) {
        throw LoadError{absl::StrCat(ow, ".height: expected a finite non-negative number")};
      }
      if (!vertical) {
        Warn(absl::StrCat(ow, ": the node transform tilts the prism; occluder dropped"));
        continue;
      }
      Occluder25D out;
      for (size_t i = 0; i < fp.ArrayLen(); i += 2) {
        const tinygltf::Value &x = fp.Get(static_cast<int>(i)), &y = fp.Get(static_cast<int>(i + 1));
        if (!x.IsNumber() || !y.IsNumber()) throw LoadError{absl::StrCat(ow, ".footprint[", i, "]: not a number")};
        if (obj->occluders_local) {
          out.footprint.emplace_back(x.GetNumberAsDouble(), y.GetNumberAsDouble());
          continue;
        }
        const glm::dvec3 p = glm::dvec3(m * glm::dvec4(x.GetNumberAsDouble(), y.GetNumberAsDouble(), 0.0, 1.0));
        out.footprint.emplace_back(p.x, p.y);
      }
      // Where the prism's foot lands, relative to the scene origin (visited before objects).
      const double base = obj->occluders_local ? 0.0 : m[3][2] - origin_.z;
      const double top = obj->occluders_local ? h.GetNumberAsDouble() : base + m[2][2] * h.GetNumberAsDouble();
      if (base > 1e-6 * (1.0 + std::abs(top))) {
        Warn(absl::StrCat(ow, ": the prism does not stand on the ground (z = ", base, "); occluder dropped"));
        continue;
      }
      out.height = std::max(0.0, top);
      obj->occluders.push_back(std::move(out));
    }
  }

  Scene Finish() {
    Scene scene;
    if (pending_.empty()) throw LoadError{"no triangle meshes in the file"};
    if (origin_node_ < 0) {
      // A foreign file: centre the local frame on the footprint, rounded to whole metres so
      // that translating the file by whole metres translates nothing else.
      Aabb box;
      for (const auto& o : pending_) {
        for (const auto& p : o.positions) box.Extend(p);
      }
      origin_ = glm::dvec3(std::round(box.Centre().x), std::round(box.Centre().y), 0.0);
    }
    scene.origin = origin_;
    scene.crs = crs_;
    scene.paths = std::move(paths_);
    scene.name = name_.empty() ? fs::path(file_).stem().string() : name_;
    for (auto& o : pending_) {
      Mesh mesh;
      mesh.positions.reserve(o.positions.size());
      for (const auto& p : o.positions) mesh.positions.emplace_back(glm::vec3(p - origin_));
      mesh.normals.reserve(o.normals.size());
      for (const auto& n : o.normals) mesh.normals.emplace_back(glm::vec3(n));
      mesh.indices = std::move(o.indices);
      const ObjectId id = scene.AddObject(std::move(o.name), std::move(mesh));
      if (o.terrain) scene.terrain.push_back(id);
      scene.objects[id].type = std::move(o.type);
      for (auto& oc : o.occluders) {
        if (o.occluders_local) {
          oc.object = id;
          scene.occluders.push_back(std::move(oc));
          continue;
        }
        for (auto& p : oc.footprint) p -= glm::dvec2(origin_);
        oc.object = id;
        scene.occluders.push_back(std::move(oc));
      }
    }
    NormalizeOccluders(&scene);
    ReadLevels(&scene);
    return scene;
  }

  // One coarser level: node `index`'s mesh in `gltf_parent`'s frame, with its measured error
  // (extras.vistream.lod_error_m, required).
  MeshLevel ReadLevel(int index, const glm::dmat4& gltf_parent, const std::string& what) {
    PendingObject tmp;
    ReadTriangles(index, gltf_parent * LocalMatrix(model_.nodes[index]), what, &tmp);
    const tinygltf::Value& error = VistreamExtra(model_.nodes[index], "lod_error_m");
    if (error.Type() == tinygltf::NULL_TYPE) throw LoadError{absl::StrCat(what, ": extras.vistream.lod_error_m is missing")};
    if (!error.IsNumber() || !std::isfinite(error.GetNumberAsDouble()) || !(error.GetNumberAsDouble() > 0.0)) {
      throw LoadError{absl::StrCat(what, ": extras.vistream.lod_error_m is not a finite number of metres above 0")};
    }
    MeshLevel level;
    level.error_m = error.GetNumberAsDouble();
    for (const auto& p : tmp.positions) level.mesh.positions.emplace_back(glm::vec3(p - origin_));
    for (const auto& n : tmp.normals) level.mesh.normals.emplace_back(glm::vec3(n));
    level.mesh.indices = std::move(tmp.indices);
    return level;
  }

  // Levels of detail (scenes/level_types.h): MSFT_lod on object nodes, clusters in the origin
  // node's extras.vistream.clusters ([{"objects": [ids], "nodes": [LOD nodes, finest first]}],
  // their nodes in the origin node's frame). Checked with ValidateLevels.
  void ReadLevels(Scene* scene) {
    const tinygltf::Value& clusters =
        origin_node_ >= 0 ? VistreamExtra(model_.nodes[origin_node_], "clusters") : tinygltf::Value();
    const bool any = clusters.Type() != tinygltf::NULL_TYPE ||
                     std::any_of(pending_.begin(), pending_.end(), [](const PendingObject& o) { return !o.lod_nodes.empty(); });
    if (!any) return;
    SceneLevels& levels = scene->levels;
    levels.objects.resize(scene->objects.size());
    for (size_t i = 0; i < pending_.size(); ++i) {
      const auto& ids = pending_[i].lod_nodes;
      for (size_t k = 0; k < ids.size(); ++k) {
        const std::string what = absl::StrCat("object ", i, " ('", scene->objects[i].name, "'), level ", k + 1, " (",
                                              NodeName(ids[k]), ")");
        levels.objects[i].push_back(ReadLevel(ids[k], pending_[i].gltf_parent, what));
      }
    }
    if (clusters.Type() != tinygltf::NULL_TYPE) {
      if (!clusters.IsArray()) throw LoadError{"extras.vistream.clusters of the origin node is not an array"};
      for (size_t c = 0; c < clusters.ArrayLen(); ++c) {
        const tinygltf::Value& entry = clusters.Get(static_cast<int>(c));
        const std::string what = absl::StrCat("cluster ", c);
        if (!entry.IsObject() || !entry.Has("objects") || !entry.Get("objects").IsArray() || !entry.Has("nodes") ||
            !entry.Get("nodes").IsArray()) {
          throw LoadError{absl::StrCat(what, ": needs arrays \"objects\" and \"nodes\"")};
        }
        Cluster cluster;
        const tinygltf::Value& objects = entry.Get("objects");
        for (size_t k = 0; k < objects.ArrayLen(); ++k) {
          const tinygltf::Value& o = objects.Get(static_cast<int>(k));
          if (!o.IsInt() || o.Get<int>() < 0) throw LoadError{absl::StrCat(what, ": object ", k, " is not an object id")};
          cluster.objects.push_back(static_cast<uint32_t>(o.Get<int>()));
        }
        const tinygltf::Value& nodes = entry.Get("nodes");
        for (size_t k = 0; k < nodes.ArrayLen(); ++k) {
          const tinygltf::Value& n = nodes.Get(static_cast<int>(k));
          if (!n.IsInt() || n.Get<int>() < 0 || n.Get<int>() >= static_cast<int>(model_.nodes.size()) ||
              model_.nodes[n.Get<int>()].mesh < 0) {
            throw LoadError{absl::StrCat(what, ": node ", k, " is not a node with a mesh")};
          }
          cluster.levels.push_back(
              ReadLevel(n.Get<int>(), origin_gltf_world_, absl::StrCat(what, ", level ", k + 1, " (", NodeName(n.Get<int>()), ")")));
        }
        for (const uint32_t o : cluster.objects) {
          if (o < scene->objects.size()) cluster.bounds.Extend(scene->objects[o].bounds);
        }
        for (const MeshLevel& l : cluster.levels) cluster.bounds.Extend(l.mesh.Bounds());
        levels.clusters.push_back(std::move(cluster));
      }
    }
    if (absl::Status s = ValidateLevels(levels, *scene, "levels"); !s.ok()) throw LoadError{std::string(s.message())};
  }

  const tinygltf::Model& model_;
  std::string file_;
  std::vector<std::string>* warnings_;
  std::unordered_set<int> on_path_;
  std::vector<PendingObject> pending_;
  int origin_node_ = -1;
  glm::dvec3 origin_{0.0};
  glm::dmat4 origin_world_{1.0};  // the origin node's world matrix, z-up (as ImportMesh's `world`)
  glm::dmat4 origin_gltf_world_{1.0};  // the same in glTF's frame
  std::string name_;
  std::string crs_;
  std::vector<ScenePath> paths_;
};

// External buffers and images may only come from the glTF file's own folder (or below);
// with no folder, from nowhere. A hostile file cannot make the loader read /etc/passwd.
struct FileAccess {
  fs::path root;  // empty: no file access
};

bool Allowed(const FileAccess& access, const std::string& path) {
  if (access.root.empty()) return false;
  const fs::path p = fs::weakly_canonical(fs::path(path));
  const auto [root_end, p_it] = std::mismatch(access.root.begin(), access.root.end(), p.begin(), p.end());
  return root_end == access.root.end();
}

// Existence is answered truthfully (without a folder, without looking) so that the read
// below, not a misleading "file not found", reports why a file is refused.
bool ConfinedFileExists(const std::string& path, void* user) {
  if (static_cast<FileAccess*>(user)->root.empty()) return true;
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

std::string NoExpansion(const std::string& path, void*) { return path; }

bool ConfinedReadWholeFile(std::vector<unsigned char>* out, std::string* err, const std::string& path,
                           void* user) {
  const FileAccess& access = *static_cast<FileAccess*>(user);
  if (!Allowed(access, path)) {
    if (err != nullptr) {
      *err += access.root.empty() ? "external file '" + path + "' refused: in-memory input has no folder\n"
                                  : "external file '" + path + "' is outside the glTF file's folder\n";
    }
    return false;
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    if (err != nullptr) *err += "cannot open external file '" + path + "'\n";
    return false;
  }
  out->assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  return true;
}

bool RefuseWrite(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err != nullptr) *err += "the loader writes no files\n";
  return false;
}

bool SkipImages(tinygltf::Image*, const int, std::string*, std::string*, int, int, const unsigned char*,
                int, void*) {
  return true;  // vistream draws flat-shaded geometry; images are never decoded
}

absl::StatusOr<Scene> Convert(bool ok, const std::string& err, const std::string& warn,
                              tinygltf::Model* model, const std::string& name,
                              std::vector<std::string>* warnings) {
  if (!ok) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": not a valid glTF file: ", err.empty() ? "unknown error" : err));
  }
  if (warnings != nullptr && !warn.empty()) warnings->push_back(absl::StrCat(name, ": ", warn));
  try {
    gltf_detail::DecodeCompressed(model);
    GltfImporter importer(*model, name, warnings);
    Scene scene = importer.Import();
    if (absl::Status s = ValidateScene(scene, name); !s.ok()) return s;
    return scene;
  } catch (const LoadError& e) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": ", e.what));
  }
}

}  // namespace

// tinygltf trusts a .glb's declared lengths (it copies that many bytes): check them first
// (glTF 2.0, 4.4: a 12-byte header whose length is the file's, then chunks of an 8-byte header
// and their bytes, each within the file).
static absl::Status CheckGlbLayout(std::string_view bytes, const std::string& name) {
  auto u32 = [&](size_t at) {
    uint32_t v = 0;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  if (bytes.size() < 12) return absl::InvalidArgumentError(absl::StrCat(name, ": a .glb shorter than its header"));
  if (u32(8) != bytes.size()) {
    return absl::InvalidArgumentError(
        absl::StrCat(name, ": the .glb header says ", u32(8), " bytes, the file has ", bytes.size()));
  }
  for (size_t at = 12; at < bytes.size();) {
    if (bytes.size() - at < 8) return absl::InvalidArgumentError(absl::StrCat(name, ": a .glb chunk header is cut at byte ", at));
    const uint64_t length = u32(at);
    if (length > bytes.size() - at - 8) {
      return absl::InvalidArgumentError(
          absl::StrCat(name, ": the .glb chunk at byte ", at, " says ", length, " bytes, past the end of the file"));
    }
    at += 8 + length;
  }
  return absl::OkStatus();
}

absl::StatusOr<Scene> LoadGltfFromMemory(std::string_view bytes, bool binary, const std::string& name,
                                         const std::string& base_dir,
                                         std::vector<std::string>* warnings) {
  if (binary) {
    if (absl::Status st = CheckGlbLayout(bytes, name); !st.ok()) return st;
  }
  tinygltf::TinyGLTF loader;
  loader.SetImageLoader(&SkipImages, nullptr);
  FileAccess access;
  if (!base_dir.empty()) access.root = fs::weakly_canonical(fs::absolute(base_dir));
  loader.SetFsCallbacks(tinygltf::FsCallbacks{&ConfinedFileExists, &NoExpansion, &ConfinedReadWholeFile,
                                              &RefuseWrite, &access});
  tinygltf::Model model;
  std::string err, warn;
  bool ok = false;
  std::string rewritten;
  try {
    bytes = gltf_detail::PrepareCompressed(bytes, binary, &rewritten);
  } catch (const LoadError& e) {
    return absl::InvalidArgumentError(absl::StrCat(name, ": ", e.what));
  } catch (const std::exception& e) {  // nlohmann::json, should hostile input get past its parser
    return absl::InvalidArgumentError(absl::StrCat(name, ": not a valid glTF file: ", e.what()));
  }
  try {
    if (binary) {
      ok = loader.LoadBinaryFromMemory(&model, &err, &warn,
                                       reinterpret_cast<const unsigned char*>(bytes.data()),
                                       static_cast<unsigned int>(bytes.size()), base_dir);
    } else {
      ok = loader.LoadASCIIFromString(&model, &err, &warn, bytes.data(),
                                      static_cast<unsigned int>(bytes.size()), base_dir);
    }
  } catch (const std::exception& e) {  // nlohmann::json may throw on hostile input
    ok = false;
    err = e.what();
  }
  return Convert(ok, err, warn, &model, name, warnings);
}

absl::StatusOr<Scene> LoadGltf(const std::string& path, std::vector<std::string>* warnings) {
  // A directory opens as a stream on Linux and then throws on its first read.
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": is a directory, not a glTF file"));
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat(path, ": cannot open file"));
  in.seekg(0, std::ios::end);
  const auto size = static_cast<size_t>(in.tellg());
  in.seekg(0, std::ios::beg);
  std::string bytes(size, '\0');
  if (size > 0 && !in.read(bytes.data(), static_cast<std::streamsize>(size))) {
    return absl::DataLossError(absl::StrCat(path, ": read failed"));
  }
  if (bytes.size() > std::numeric_limits<unsigned int>::max()) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": file larger than 4 GiB"));
  }
  // A .glb starts with the magic "glTF", whatever its extension.
  const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  if (!binary && EndsWith(path, ".glb")) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": not a valid .glb file (bad magic)"));
  }
  std::string base = fs::path(path).parent_path().string();
  if (base.empty()) base = ".";
  return LoadGltfFromMemory(bytes, binary, path, base, warnings);
}

}  // namespace vistream::scenes
