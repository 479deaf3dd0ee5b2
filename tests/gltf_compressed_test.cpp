// Compressed and sparse glTF input (issue 20): files written here with the encoders of the
// extensions (libdraco, meshoptimizer) load to the triangles of their uncompressed source.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <glm/geometric.hpp>
#include <gtest/gtest.h>
#include <meshoptimizer.h>
#include <nlohmann/json.hpp>

#include "scenes/building.h"
#include "scenes/gltf_io.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

using nlohmann::json;
using Triangle = std::array<glm::dvec3, 3>;

// The source: two buildings' meshes, in glTF's frame (y-up): (x, y, z) z-up = (x, -z, y).
struct SourceMesh {
  std::string name;
  std::vector<float> xyz;  // glTF frame
  std::vector<uint32_t> indices;
};
std::vector<SourceMesh> Source() {
  Scene s;
  const glm::dvec2 u(1, 0), v(0, 1);
  AddBuilding(&s, "house", {{FrameRect({3.25, 1.5}, u, v, 0, 10, 0, 8), 0, 12}});
  AddBuilding(&s, "tower", {{FrameRect({30.25, 5.5}, u, v, 0, 20, 0, 20), 0, 30},
                            {FrameRect({30.25, 5.5}, u, v, 5, 15, 5, 15), 30, 80.5}});
  std::vector<SourceMesh> out;
  for (const Object& o : s.objects) {
    SourceMesh m{o.name, {}, o.mesh.indices};
    for (const glm::vec3& p : o.mesh.positions) m.xyz.insert(m.xyz.end(), {p.x, p.z, -p.y});
    out.push_back(std::move(m));
  }
  return out;
}

// A triangle list as a canonical set: each triangle rotated to start at its smallest corner
// (winding kept), the list sorted. z-up world coordinates.
bool Less(const glm::dvec3& a, const glm::dvec3& b) {
  return a.x != b.x ? a.x < b.x : a.y != b.y ? a.y < b.y : a.z < b.z;
}
std::vector<Triangle> Canonical(std::vector<Triangle> tris) {
  for (Triangle& t : tris) {
    const int k = Less(t[1], t[0]) ? (Less(t[2], t[1]) ? 2 : 1) : (Less(t[2], t[0]) ? 2 : 0);
    std::rotate(t.begin(), t.begin() + k, t.end());
  }
  std::sort(tris.begin(), tris.end(), [](const Triangle& a, const Triangle& b) {
    for (int i = 0; i < 3; ++i) {
      if (a[i] != b[i]) return Less(a[i], b[i]);
    }
    return false;
  });
  return tris;
}
std::vector<Triangle> SourceTriangles(const SourceMesh& m) {
  std::vector<Triangle> tris;
  auto p = [&m](uint32_t i) { return glm::dvec3(m.xyz[3 * i], -m.xyz[3 * i + 2], m.xyz[3 * i + 1]); };
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) tris.push_back({p(m.indices[t]), p(m.indices[t + 1]), p(m.indices[t + 2])});
  return Canonical(tris);
}
std::vector<Triangle> LoadedTriangles(const Scene& s, size_t object) {
  std::vector<Triangle> tris;
  const Mesh& m = s.objects[object].mesh;
  auto p = [&](uint32_t i) { return s.origin + glm::dvec3(m.positions[i]); };
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) tris.push_back({p(m.indices[t]), p(m.indices[t + 1]), p(m.indices[t + 2])});
  return Canonical(tris);
}
void ExpectSameTriangles(const std::vector<Triangle>& want, const std::vector<Triangle>& got, double tolerance) {
  ASSERT_EQ(want.size(), got.size());
  for (size_t t = 0; t < want.size(); ++t) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(glm::distance(want[t][k], got[t][k]), 0.0, tolerance) << "triangle " << t << " corner " << k;
    }
  }
}

// A .glb written by hand: JSON and one BIN chunk (glTF 2.0, 4.4).
struct GlbBuilder {
  json j = {{"asset", {{"version", "2.0"}, {"generator", "vistream tests"}}},
            {"scenes", {{{"nodes", json::array()}}}},
            {"scene", 0}};
  std::string bin;

  size_t Append(const void* data, size_t bytes) {
    while (bin.size() % 4) bin.push_back('\0');
    const size_t at = bin.size();
    bin.append(static_cast<const char*>(data), bytes);
    return at;
  }
  int View(size_t offset, size_t length, int buffer = 0) {
    j["bufferViews"].push_back({{"buffer", buffer}, {"byteOffset", offset}, {"byteLength", length}});
    return static_cast<int>(j["bufferViews"].size() - 1);
  }
  int Accessor(json a) {
    j["accessors"].push_back(std::move(a));
    return static_cast<int>(j["accessors"].size() - 1);
  }
  void Node(const std::string& name, json primitive) {
    j["meshes"].push_back({{"primitives", {std::move(primitive)}}});
    j["nodes"].push_back({{"name", name}, {"mesh", j["meshes"].size() - 1}});
    j["scenes"][0]["nodes"].push_back(j["nodes"].size() - 1);
  }
  void Uses(const std::string& extension, bool required) {
    j["extensionsUsed"].push_back(extension);
    if (required) j["extensionsRequired"].push_back(extension);
  }
  std::string Bytes() {
    if (!j.contains("buffers")) j["buffers"] = json::array({json::object()});
    while (bin.size() % 4) bin.push_back('\0');
    j["buffers"][0]["byteLength"] = bin.size();
    std::string text = j.dump();
    while (text.size() % 4) text.push_back(' ');
    std::string out = "glTF";
    auto u32 = [&out](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
    u32(2);
    u32(static_cast<uint32_t>(28 + text.size() + bin.size()));
    u32(static_cast<uint32_t>(text.size()));
    out += "JSON";
    out += text;
    u32(static_cast<uint32_t>(bin.size()));
    out += std::string("BIN\0", 4);
    out += bin;
    return out;
  }
};

json MinMax(const std::vector<float>& xyz) {
  std::vector<double> lo(3, 1e300), hi(3, -1e300);
  for (size_t i = 0; i < xyz.size(); ++i) {
    lo[i % 3] = std::min<double>(lo[i % 3], xyz[i]);
    hi[i % 3] = std::max<double>(hi[i % 3], xyz[i]);
  }
  return {{"min", lo}, {"max", hi}};
}

// --- KHR_draco_mesh_compression ---

struct DracoStream {
  std::string bytes;
  int position_id = -1;
  size_t points = 0, faces = 0;
};
DracoStream DracoEncode(const SourceMesh& m, int quantization_bits) {
  const size_t faces = m.indices.size() / 3;
  draco::TriangleSoupMeshBuilder builder;
  builder.Start(static_cast<int>(faces));
  const int att = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  for (size_t f = 0; f < faces; ++f) {
    builder.SetAttributeValuesForFace(att, draco::FaceIndex(static_cast<uint32_t>(f)), &m.xyz[3 * m.indices[3 * f]],
                                      &m.xyz[3 * m.indices[3 * f + 1]], &m.xyz[3 * m.indices[3 * f + 2]]);
  }
  std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  EXPECT_NE(mesh, nullptr);
  draco::Encoder encoder;
  if (quantization_bits > 0) encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, quantization_bits);
  draco::EncoderBuffer out;
  const draco::Status status = encoder.EncodeMeshToBuffer(*mesh, &out);
  EXPECT_TRUE(status.ok()) << status.error_msg_string();
  return {std::string(out.data(), out.size()), static_cast<int>(mesh->attribute(att)->unique_id()), mesh->num_points(),
          mesh->num_faces()};
}

// Each source mesh a Draco primitive (accessors without bufferViews, as the extension says).
std::string DracoGlb(const std::vector<SourceMesh>& meshes, int quantization_bits) {
  GlbBuilder b;
  b.Uses("KHR_draco_mesh_compression", true);
  for (const SourceMesh& m : meshes) {
    const DracoStream d = DracoEncode(m, quantization_bits);
    const int view = b.View(b.Append(d.bytes.data(), d.bytes.size()), d.bytes.size());
    json pos = {{"componentType", 5126}, {"type", "VEC3"}, {"count", d.points}};
    pos.update(MinMax(m.xyz));
    const int pa = b.Accessor(pos);
    const int ia = b.Accessor({{"componentType", 5125}, {"type", "SCALAR"}, {"count", d.faces * 3}});
    b.Node(m.name, {{"attributes", {{"POSITION", pa}}},
                    {"indices", ia},
                    {"mode", 4},
                    {"extensions", {{"KHR_draco_mesh_compression",
                                     {{"bufferView", view}, {"attributes", {{"POSITION", d.position_id}}}}}}}});
  }
  return b.Bytes();
}

TEST(GltfCompressed, DracoMeshDecodesToTheSourceTriangles) {
  const std::vector<SourceMesh> src = Source();
  absl::StatusOr<Scene> s = LoadGltfFromMemory(DracoGlb(src, /*quantization_bits=*/0), true, "draco.glb");
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->objects.size(), src.size());
  for (size_t i = 0; i < src.size(); ++i) {
    EXPECT_EQ(s->objects[i].name, src[i].name);
    ExpectSameTriangles(SourceTriangles(src[i]), LoadedTriangles(*s, i), 0.0);  // lossless
  }
}

TEST(GltfCompressed, QuantizedDracoMeshIsWithinTheQuantizationStep) {
  const std::vector<SourceMesh> src = Source();
  const int bits = 11;
  absl::StatusOr<Scene> s = LoadGltfFromMemory(DracoGlb(src, bits), true, "draco11.glb");
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->objects.size(), src.size());
  for (size_t i = 0; i < src.size(); ++i) {
    // Draco quantizes every component on one grid over the mesh's largest extent.
    const json mm = MinMax(src[i].xyz);
    double range = 0.0;
    for (int c = 0; c < 3; ++c) range = std::max(range, mm["max"][c].get<double>() - mm["min"][c].get<double>());
    const double step = range / ((1 << bits) - 1);
    // Half a step per component, over three components.
    ExpectSameTriangles(SourceTriangles(src[i]), LoadedTriangles(*s, i), 0.5 * step * std::sqrt(3.0) + 1e-5);
  }
}

TEST(GltfCompressed, EveryTruncatedOrCorruptDracoStreamIsAnErrorNamingTheExtension) {
  const SourceMesh m = Source()[0];
  const DracoStream d = DracoEncode(m, 0);
  auto glb_with = [&](const std::string& stream) {
    GlbBuilder b;
    b.Uses("KHR_draco_mesh_compression", true);
    const int view = b.View(b.Append(stream.data(), stream.size()), stream.size());
    const int pa = b.Accessor({{"componentType", 5126}, {"type", "VEC3"}, {"count", d.points}});
    b.Node("x", {{"attributes", {{"POSITION", pa}}},
                 {"extensions", {{"KHR_draco_mesh_compression",
                                  {{"bufferView", view}, {"attributes", {{"POSITION", d.position_id}}}}}}}});
    return b.Bytes();
  };
  for (size_t n = 1; n < d.bytes.size(); ++n) {  // every truncation (a view of 0 bytes is invalid glTF)
    absl::StatusOr<Scene> s = LoadGltfFromMemory(glb_with(d.bytes.substr(0, n)), true, "cut.glb");
    ASSERT_FALSE(s.ok()) << "truncated to " << n << " bytes";
    EXPECT_NE(s.status().message().find("KHR_draco_mesh_compression"), std::string::npos) << s.status();
  }
  absl::StatusOr<Scene> garbage = LoadGltfFromMemory(glb_with(std::string(64, '\x5a')), true, "garbage.glb");
  ASSERT_FALSE(garbage.ok());
  EXPECT_NE(garbage.status().message().find("KHR_draco_mesh_compression"), std::string::npos) << garbage.status();
  // Every single flipped byte: an error or some mesh, never a crash (ASan runs this too).
  for (size_t i = 0; i < d.bytes.size(); ++i) {
    std::string flipped = d.bytes;
    flipped[i] = static_cast<char>(flipped[i] ^ 0xff);
    (void)LoadGltfFromMemory(glb_with(flipped), true, "flipped.glb");
  }
}

TEST(GltfCompressed, DracoAttributeIdMissingFromTheStreamIsAnError) {
  const SourceMesh m = Source()[0];
  const DracoStream d = DracoEncode(m, 0);
  GlbBuilder b;
  b.Uses("KHR_draco_mesh_compression", true);
  const int view = b.View(b.Append(d.bytes.data(), d.bytes.size()), d.bytes.size());
  const int pa = b.Accessor({{"componentType", 5126}, {"type", "VEC3"}, {"count", d.points}});
  b.Node("x", {{"attributes", {{"POSITION", pa}}},
               {"extensions", {{"KHR_draco_mesh_compression", {{"bufferView", view}, {"attributes", {{"POSITION", 7}}}}}}}});
  absl::StatusOr<Scene> s = LoadGltfFromMemory(b.Bytes(), true, "id.glb");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.status().message().find("mesh 0, primitive 0: KHR_draco_mesh_compression: attribute POSITION: Draco id 7"),
            std::string::npos)
      << s.status();
}

}  // namespace
}  // namespace vistream::scenes
