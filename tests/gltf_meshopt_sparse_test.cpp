// glTF input beyond plain accessors (issue 20): EXT_meshopt_compression buffers (written here
// with meshoptimizer's encoders), sparse accessors, and required extensions vistream cannot
// read.
#include <cstring>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include "scenes/gltf_io.h"
#include "tests/gltf_test_util.h"

namespace vistream::scenes {
namespace {

using namespace gltf_test;  // NOLINT: the helpers of this suite
using nlohmann::json;

// --- EXT_meshopt_compression ---

struct MeshoptStreams {
  std::string vertices, indices;
};
MeshoptStreams MeshoptEncode(const SourceMesh& m) {
  const size_t count = m.xyz.size() / 3;
  std::vector<unsigned char> v(meshopt_encodeVertexBufferBound(count, 12));
  v.resize(meshopt_encodeVertexBuffer(v.data(), v.size(), m.xyz.data(), count, 12));
  std::vector<unsigned char> i(meshopt_encodeIndexBufferBound(m.indices.size(), count));
  i.resize(meshopt_encodeIndexBuffer(i.data(), i.size(), m.indices.data(), m.indices.size()));
  EXPECT_FALSE(v.empty() || i.empty());
  return {std::string(v.begin(), v.end()), std::string(i.begin(), i.end())};
}

// Each source mesh with meshopt-compressed views in the BIN chunk (buffer 0) over a fallback
// buffer without data (buffer 1), as gltfpack writes them. `cut` shortens every stream's
// declared length by that many bytes.
std::string MeshoptGlb(const std::vector<SourceMesh>& meshes, size_t cut = 0, const std::string* garbage = nullptr) {
  GlbBuilder b;
  b.Uses("EXT_meshopt_compression", true);
  size_t fallback = 0;
  json views = json::array();
  for (const SourceMesh& m : meshes) {
    MeshoptStreams s = MeshoptEncode(m);
    if (garbage != nullptr) s.vertices = s.indices = *garbage;
    const size_t count = m.xyz.size() / 3, vbytes = count * 12, ibytes = m.indices.size() * 4;
    const size_t vat = b.Append(s.vertices.data(), s.vertices.size());
    const size_t iat = b.Append(s.indices.data(), s.indices.size());
    b.j["bufferViews"].push_back(
        {{"buffer", 1}, {"byteOffset", fallback}, {"byteLength", vbytes}, {"byteStride", 12},
         {"extensions", {{"EXT_meshopt_compression", {{"buffer", 0}, {"byteOffset", vat},
                                                      {"byteLength", s.vertices.size() - cut}, {"byteStride", 12},
                                                      {"count", count}, {"mode", "ATTRIBUTES"}}}}}});
    b.j["bufferViews"].push_back(
        {{"buffer", 1}, {"byteOffset", fallback + vbytes}, {"byteLength", ibytes},
         {"extensions", {{"EXT_meshopt_compression", {{"buffer", 0}, {"byteOffset", iat},
                                                      {"byteLength", s.indices.size() - cut}, {"byteStride", 4},
                                                      {"count", m.indices.size()}, {"mode", "TRIANGLES"}}}}}});
    fallback += vbytes + ibytes;
    const int nv = static_cast<int>(b.j["bufferViews"].size());
    json pos = {{"bufferView", nv - 2}, {"componentType", 5126}, {"type", "VEC3"}, {"count", count}};
    pos.update(MinMax(m.xyz));
    const int pa = b.Accessor(pos);
    const int ia = b.Accessor({{"bufferView", nv - 1}, {"componentType", 5125}, {"type", "SCALAR"},
                               {"count", m.indices.size()}});
    b.Node(m.name, {{"attributes", {{"POSITION", pa}}}, {"indices", ia}, {"mode", 4}});
  }
  b.j["buffers"] = {json::object(),
                    {{"byteLength", fallback}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}}};
  return b.Bytes();
}

TEST(GltfMeshopt, CompressedBuffersDecodeToTheSourceTriangles) {
  const std::vector<SourceMesh> src = Source();
  const std::string glb = MeshoptGlb(src);
  MaybeWriteSeed("meshopt.glb", glb);
  absl::StatusOr<Scene> s = LoadGltfFromMemory(glb, true, "meshopt.glb");
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->objects.size(), src.size());
  for (size_t i = 0; i < src.size(); ++i) {
    EXPECT_EQ(s->objects[i].name, src[i].name);
    ExpectSameTriangles(SourceTriangles(src[i]), LoadedTriangles(*s, i), 0.0);  // lossless
  }
}

TEST(GltfMeshopt, TruncatedOrGarbageStreamIsAnErrorNamingTheExtension) {
  const std::vector<SourceMesh> src = {Source()[0]};
  const MeshoptStreams s = MeshoptEncode(src[0]);
  for (size_t cut = 1; cut < std::min(s.vertices.size(), s.indices.size()); ++cut) {
    absl::StatusOr<Scene> r = LoadGltfFromMemory(MeshoptGlb(src, cut), true, "cut.glb");
    ASSERT_FALSE(r.ok()) << "cut by " << cut;
    EXPECT_NE(r.status().message().find("bufferView 0: EXT_meshopt_compression"), std::string::npos) << r.status();
  }
  const std::string garbage(200, '\x5a');
  absl::StatusOr<Scene> r = LoadGltfFromMemory(MeshoptGlb(src, 0, &garbage), true, "garbage.glb");
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("EXT_meshopt_compression"), std::string::npos) << r.status();
}

TEST(GltfMeshopt, BadModeAndStrideAreErrorsNamingTheKey) {
  const std::vector<SourceMesh> src = {Source()[0]};
  const std::string glb = MeshoptGlb(src);
  // Re-write the JSON chunk with one field changed.
  auto with = [&glb](const char* key, const json& value) {
    const uint32_t length = *reinterpret_cast<const uint32_t*>(glb.data() + 12);
    GlbBuilder b;
    b.j = json::parse(glb.substr(20, length));
    b.j["bufferViews"][0]["extensions"]["EXT_meshopt_compression"][key] = value;
    const uint32_t bin_length = *reinterpret_cast<const uint32_t*>(glb.data() + 20 + length);
    b.bin = glb.substr(28 + length, bin_length);
    return b.Bytes();
  };
  absl::StatusOr<Scene> mode = LoadGltfFromMemory(with("mode", "SPIRAL"), true, "mode.glb");
  ASSERT_FALSE(mode.ok());
  EXPECT_NE(mode.status().message().find("mode 'SPIRAL'"), std::string::npos) << mode.status();
  absl::StatusOr<Scene> stride = LoadGltfFromMemory(with("byteStride", 6), true, "stride.glb");
  ASSERT_FALSE(stride.ok());
  EXPECT_NE(stride.status().message().find("byteStride 6"), std::string::npos) << stride.status();
  absl::StatusOr<Scene> huge = LoadGltfFromMemory(with("count", 1u << 30), true, "count.glb");
  ASSERT_FALSE(huge.ok());
  EXPECT_NE(huge.status().message().find("256 MiB"), std::string::npos) << huge.status();
}

// --- sparse accessors (glTF 2.0, 3.6.2.3) ---

// One triangle whose POSITION accessor is sparse: over `base` (or zeros when empty), the
// vertices at `indices` take `values`.
std::string SparseGlb(const std::vector<float>& base, size_t count, const std::vector<uint16_t>& indices,
                      const std::vector<float>& values) {
  GlbBuilder b;
  json pos = {{"componentType", 5126}, {"type", "VEC3"}, {"count", count}};
  if (!base.empty()) pos["bufferView"] = b.View(b.Append(base.data(), base.size() * 4), base.size() * 4);
  const int iv = b.View(b.Append(indices.data(), indices.size() * 2), indices.size() * 2);
  const int vv = b.View(b.Append(values.data(), values.size() * 4), values.size() * 4);
  pos["sparse"] = {{"count", indices.size()},
                   {"indices", {{"bufferView", iv}, {"componentType", 5123}}},
                   {"values", {{"bufferView", vv}}}};
  const int pa = b.Accessor(pos);
  b.Node("sparse", {{"attributes", {{"POSITION", pa}}}, {"mode", 4}});
  return b.Bytes();
}

TEST(GltfSparse, SparseValuesReplaceTheBaseValues) {
  // Base: a ground triangle (glTF y-up) of 2 m; vertex 2 moved by the sparse values.
  const std::vector<float> base = {0, 0, 0, 2, 0, 0, 0, 0, -2};
  const std::string glb = SparseGlb(base, 3, {2}, {0, 0, -5});
  MaybeWriteSeed("sparse.glb", glb);
  absl::StatusOr<Scene> s = LoadGltfFromMemory(glb, true, "sparse.glb");
  ASSERT_TRUE(s.ok()) << s.status();
  const SourceMesh want{"sparse", {0, 0, 0, 2, 0, 0, 0, 0, -5}, {0, 1, 2}};
  ExpectSameTriangles(SourceTriangles(want), LoadedTriangles(*s, 0), 0.0);
}

TEST(GltfSparse, SparseAccessorWithoutBufferViewStartsFromZeros) {
  absl::StatusOr<Scene> s = LoadGltfFromMemory(SparseGlb({}, 3, {1, 2}, {3, 0, 0, 0, 0, -4}), true, "zeros.glb");
  ASSERT_TRUE(s.ok()) << s.status();
  const SourceMesh want{"sparse", {0, 0, 0, 3, 0, 0, 0, 0, -4}, {0, 1, 2}};
  ExpectSameTriangles(SourceTriangles(want), LoadedTriangles(*s, 0), 0.0);
}

TEST(GltfSparse, SparseIndexOutOfRangeOrNotIncreasingIsAnErrorNamingTheAccessor) {
  const std::vector<float> base = {0, 0, 0, 2, 0, 0, 0, 0, -2};
  for (const std::vector<uint16_t>& bad : {std::vector<uint16_t>{0, 3}, std::vector<uint16_t>{2, 1}}) {
    absl::StatusOr<Scene> s = LoadGltfFromMemory(SparseGlb(base, 3, bad, {0, 0, 0, 0, 0, 0}), true, "bad.glb");
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.status().message().find("sparse accessor 0: sparse index 1"), std::string::npos) << s.status();
  }
  // More sparse values than the accessor has elements.
  absl::StatusOr<Scene> s = LoadGltfFromMemory(SparseGlb(base, 1, {0, 1}, {0, 0, 0, 0, 0, 0}), true, "many.glb");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("sparse.count 2"), std::string::npos) << s.status();
}

// --- extensions vistream cannot read ---

TEST(GltfExtensions, RequiredExtensionThatChangesGeometryIsRefusedNamingIt) {
  const std::vector<float> base = {0, 0, 0, 2, 0, 0, 0, 0, -2};
  GlbBuilder b;
  const int pa = b.Accessor({{"bufferView", b.View(b.Append(base.data(), 36), 36)}, {"componentType", 5126},
                             {"type", "VEC3"}, {"count", 3}});
  b.Node("instanced", {{"attributes", {{"POSITION", pa}}}, {"mode", 4}});
  b.Uses("EXT_mesh_gpu_instancing", true);
  const std::string glb = b.Bytes();
  absl::StatusOr<Scene> s = LoadGltfFromMemory(glb, true, "instanced.glb");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("instanced.glb: extensionsRequired: extension 'EXT_mesh_gpu_instancing' is "
                                      "not supported"),
            std::string::npos)
      << s.status();
  // The same refusal for .gltf text.
  absl::StatusOr<Scene> text = LoadGltfFromMemory(b.j.dump(), false, "instanced.gltf");
  ASSERT_FALSE(text.ok());
  EXPECT_NE(text.status().message().find("extension 'EXT_mesh_gpu_instancing'"), std::string::npos) << text.status();
  // The same file with the extension only used (optional) loads.
  b.j.erase("extensionsRequired");
  absl::StatusOr<Scene> optional = LoadGltfFromMemory(b.Bytes(), true, "optional.glb");
  EXPECT_TRUE(optional.ok()) << optional.status();
}

TEST(GltfExtensions, RequiredMaterialExtensionIsHarmless) {
  const std::vector<float> base = {0, 0, 0, 2, 0, 0, 0, 0, -2};
  GlbBuilder b;
  const int pa = b.Accessor({{"bufferView", b.View(b.Append(base.data(), 36), 36)}, {"componentType", 5126},
                             {"type", "VEC3"}, {"count", 3}});
  b.Node("unlit", {{"attributes", {{"POSITION", pa}}}, {"mode", 4}});
  b.Uses("KHR_materials_unlit", true);
  absl::StatusOr<Scene> s = LoadGltfFromMemory(b.Bytes(), true, "unlit.glb");
  EXPECT_TRUE(s.ok()) << s.status();
}

}  // namespace
}  // namespace vistream::scenes
