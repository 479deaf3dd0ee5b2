// Draco-compressed glTF input (issue 20): files written here with libdraco's encoder load to
// the triangles of their uncompressed source.
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
#include <nlohmann/json.hpp>

#include "scenes/building.h"
#include "scenes/gltf_io.h"
#include "tests/gltf_test_util.h"

namespace vistream::scenes {
namespace {

using namespace gltf_test;  // NOLINT: the helpers of this suite
using nlohmann::json;

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

TEST(GltfDraco, DracoMeshDecodesToTheSourceTriangles) {
  const std::vector<SourceMesh> src = Source();
  const std::string glb = DracoGlb(src, /*quantization_bits=*/0);
  MaybeWriteSeed("draco.glb", glb);
  absl::StatusOr<Scene> s = LoadGltfFromMemory(glb, true, "draco.glb");
  ASSERT_TRUE(s.ok()) << s.status();
  ASSERT_EQ(s->objects.size(), src.size());
  for (size_t i = 0; i < src.size(); ++i) {
    EXPECT_EQ(s->objects[i].name, src[i].name);
    ExpectSameTriangles(SourceTriangles(src[i]), LoadedTriangles(*s, i), 0.0);  // lossless
  }
}

TEST(GltfDraco, QuantizedDracoMeshIsWithinTheQuantizationStep) {
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

TEST(GltfDraco, EveryTruncatedOrCorruptDracoStreamIsAnErrorNamingTheExtension) {
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

TEST(GltfDraco, DracoAttributeIdMissingFromTheStreamIsAnError) {
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
