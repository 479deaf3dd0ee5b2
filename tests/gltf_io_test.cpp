#include "scenes/gltf_io.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>
#include <tiny_gltf.h>
#include <absl/strings/str_join.h>

#include "scenes/building.h"
#include "scenes/city_generator.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

using testing::TempDir;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void WriteFile(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// A small vistream scene: two buildings, one stacked, at a UTM-like origin.
Scene SmallScene() {
  Scene s;
  s.name = "small";
  s.origin = glm::dvec3(699123.0, 5710456.0, 0.0);
  const glm::dvec2 u(1, 0), v(0, 1);
  AddBuilding(&s, "house", {{FrameRect({0, 0}, u, v, 0, 10, 0, 8), 0, 12}});
  AddBuilding(&s, "tower", {{FrameRect({30, 5}, u, v, 0, 20, 0, 20), 0, 30},
                            {FrameRect({30, 5}, u, v, 5, 15, 5, 15), 30, 80.5}});
  return s;
}

void ExpectSameScene(const Scene& a, const Scene& b) {
  ASSERT_EQ(a.objects.size(), b.objects.size());
  EXPECT_EQ(a.origin, b.origin);
  for (size_t i = 0; i < a.objects.size(); ++i) {
    const Object &x = a.objects[i], &y = b.objects[i];
    EXPECT_EQ(x.id, y.id);
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.mesh.positions, y.mesh.positions) << "object " << i;
    EXPECT_EQ(x.mesh.indices, y.mesh.indices) << "object " << i;
    ASSERT_EQ(x.mesh.normals.size(), y.mesh.normals.size());
    for (size_t k = 0; k < x.mesh.normals.size(); ++k) {
      EXPECT_NEAR(glm::distance(x.mesh.normals[k], y.mesh.normals[k]), 0.0, 1e-6);
    }
    EXPECT_EQ(x.bounds, y.bounds);
  }
  ASSERT_EQ(a.occluders.size(), b.occluders.size());
  for (size_t i = 0; i < a.occluders.size(); ++i) {
    EXPECT_EQ(a.occluders[i].footprint, b.occluders[i].footprint);
    EXPECT_EQ(a.occluders[i].height, b.occluders[i].height);
    EXPECT_EQ(a.occluders[i].object, b.occluders[i].object);
  }
}

TEST(GltfIo, GlbRoundTripKeepsMeshesOccludersAndOrigin) {
  const Scene scene = SmallScene();
  const std::string path = TempDir() + "/small.glb";
  ASSERT_TRUE(SaveGltf(scene, path).ok());
  absl::StatusOr<Scene> loaded = LoadGltf(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameScene(scene, *loaded);
}

TEST(GltfIo, SavingIntoAMissingFolderSaysItCannotCreateTheFile) {
  const std::string path = TempDir() + "/no-such-folder/small.glb";
  const absl::Status s = SaveGltf(SmallScene(), path);
  EXPECT_EQ(s.code(), absl::StatusCode::kUnavailable) << s;
  EXPECT_NE(s.message().find(path + ": cannot create: No such file or directory"), std::string::npos) << s;
}

TEST(GltfIo, GltfWithExternalBufferRoundTrips) {
  const Scene scene = GenerateTestCity(/*dense=*/true, 3);
  const std::string path = TempDir() + "/city1.gltf";
  ASSERT_TRUE(SaveGltf(scene, path).ok());
  EXPECT_TRUE(std::filesystem::exists(TempDir() + "/city1.bin"));
  absl::StatusOr<Scene> loaded = LoadGltf(path);
  ASSERT_TRUE(loaded.ok()) << loaded.status();
  ExpectSameScene(scene, *loaded);
}

TEST(GltfIo, FileIsYUpOnDisk) {
  // A tall thin box: in the file its long axis must be glTF's y.
  Scene s;
  AddBuilding(&s, "pole", {{FrameRect({0, 0}, {1, 0}, {0, 1}, 0, 1, 0, 1), 0, 50}});
  const std::string path = TempDir() + "/pole.glb";
  ASSERT_TRUE(SaveGltf(s, path).ok());
  tinygltf::TinyGLTF reader;
  tinygltf::Model model;
  std::string err, warn;
  ASSERT_TRUE(reader.LoadBinaryFromFile(&model, &err, &warn, path)) << err;
  const tinygltf::Accessor& pos = model.accessors[model.meshes[0].primitives[0].attributes.at("POSITION")];
  ASSERT_EQ(pos.maxValues.size(), 3u);
  EXPECT_DOUBLE_EQ(pos.maxValues[1], 50.0);  // glTF y is vistream z
  EXPECT_DOUBLE_EQ(pos.minValues[2], -1.0);  // glTF z is minus vistream y
}

TEST(GltfIo, EachMeshHasItsOwnAccessorsAndBounds) {
  // Viewers cull by an accessor's min/max: each object's POSITION accessor holds only its
  // own vertices, and its bounds are its building's (SmallScene's boxes, glTF y-up, local).
  const Scene scene = SmallScene();
  const std::string path = TempDir() + "/bounds.glb";
  ASSERT_TRUE(SaveGltf(scene, path).ok());
  tinygltf::TinyGLTF reader;
  tinygltf::Model model;
  std::string err, warn;
  ASSERT_TRUE(reader.LoadBinaryFromFile(&model, &err, &warn, path)) << err;
  ASSERT_EQ(model.meshes.size(), 2u);
  const std::vector<double> want_min[2] = {{0, 0, -8}, {30, 0, -25}};
  const std::vector<double> want_max[2] = {{10, 12, 0}, {50, 80.5, -5}};
  for (size_t m = 0; m < 2; ++m) {
    const tinygltf::Primitive& prim = model.meshes[m].primitives[0];
    const tinygltf::Accessor& pos = model.accessors[prim.attributes.at("POSITION")];
    EXPECT_EQ(pos.count, scene.objects[m].mesh.positions.size()) << "mesh " << m;
    EXPECT_EQ(model.accessors[prim.attributes.at("NORMAL")].count, pos.count) << "mesh " << m;
    EXPECT_EQ(pos.minValues, want_min[m]) << "mesh " << m;
    EXPECT_EQ(pos.maxValues, want_max[m]) << "mesh " << m;
  }
  EXPECT_NE(model.meshes[0].primitives[0].attributes.at("POSITION"),
            model.meshes[1].primitives[0].attributes.at("POSITION"));
}

// --- A file written by another tool: tinygltf's own writer, not vistream's. ---

struct ForeignBuilder {
  tinygltf::Model model;
  ForeignBuilder() {
    model.asset.version = "2.0";
    model.asset.generator = "some other tool";
    model.buffers.resize(1);
  }
  int View(const void* data, size_t bytes) {
    auto& buf = model.buffers[0].data;
    while (buf.size() % 4) buf.push_back(0);
    tinygltf::BufferView v;
    v.buffer = 0;
    v.byteOffset = buf.size();
    v.byteLength = bytes;
    buf.insert(buf.end(), static_cast<const unsigned char*>(data), static_cast<const unsigned char*>(data) + bytes);
    model.bufferViews.push_back(v);
    return static_cast<int>(model.bufferViews.size() - 1);
  }
  int Accessor(int view, int ctype, int type, size_t count) {
    tinygltf::Accessor a;
    a.bufferView = view;
    a.componentType = ctype;
    a.type = type;
    a.count = count;
    model.accessors.push_back(a);
    return static_cast<int>(model.accessors.size() - 1);
  }
  int Positions(const std::vector<float>& xyz) {
    const int a = Accessor(View(xyz.data(), xyz.size() * 4), TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3,
                           xyz.size() / 3);
    std::vector<double> lo(3, 1e300), hi(3, -1e300);
    for (size_t i = 0; i < xyz.size(); ++i) {
      lo[i % 3] = std::min<double>(lo[i % 3], xyz[i]);
      hi[i % 3] = std::max<double>(hi[i % 3], xyz[i]);
    }
    model.accessors[a].minValues = lo;
    model.accessors[a].maxValues = hi;
    return a;
  }
  int Mesh(int positions, int indices, int mode) {
    tinygltf::Primitive p;
    p.attributes["POSITION"] = positions;
    p.indices = indices;
    p.mode = mode;
    tinygltf::Mesh m;
    m.primitives.push_back(p);
    model.meshes.push_back(m);
    return static_cast<int>(model.meshes.size() - 1);
  }
  int Node(const std::string& name, int mesh) {
    tinygltf::Node n;
    n.name = name;
    n.mesh = mesh;
    model.nodes.push_back(n);
    return static_cast<int>(model.nodes.size() - 1);
  }
  std::string Save(const std::string& file, bool binary) {
    const std::string path = TempDir() + "/" + file;
    tinygltf::TinyGLTF writer;
    EXPECT_TRUE(writer.WriteGltfSceneToFile(&model, path, true, true, false, binary));
    return path;
  }
};

// A unit triangle in glTF's xz plane (the ground, y-up): (0,0,0), (1,0,0), (0,0,-1).
const std::vector<float> kGroundTriangle = {0, 0, 0, 1, 0, 0, 0, 0, -1};

TEST(GltfIo, LoadsForeignFileWithTransformsHierarchyAndNoNormals) {
  ForeignBuilder f;
  const int pos = f.Positions(kGroundTriangle);
  const std::vector<uint16_t> idx = {0, 1, 2};
  const int ia = f.Accessor(f.View(idx.data(), 6), TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR, 3);
  const int mesh = f.Mesh(pos, ia, TINYGLTF_MODE_TRIANGLES);
  // parent: translate (100, 0, -200) in glTF = (100, 200, 0) z-up; child: rotate 90° about
  // glTF +y (the vertical) and scale 2.
  const int parent = f.Node("parent", -1);
  const int child = f.Node("child", mesh);
  f.model.nodes[parent].translation = {100, 0, -200};
  f.model.nodes[parent].children = {child};
  const double s = std::sqrt(0.5);
  f.model.nodes[child].rotation = {0, s, 0, s};
  f.model.nodes[child].scale = {2, 2, 2};
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {parent};
  f.model.defaultScene = 0;
  const std::string path = f.Save("foreign.glb", true);

  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadGltf(path, &warnings);
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_EQ(scene->objects.size(), 1u);
  EXPECT_EQ(scene->objects[0].name, "child");
  // Rotating 90° about the vertical turns z-up +x into +y; glTF (0,0,-1) is z-up +y, goes to -x.
  const glm::dvec3 expected[3] = {{100, 200, 0}, {100, 202, 0}, {98, 200, 0}};
  const Mesh& m = scene->objects[0].mesh;
  ASSERT_EQ(m.TriangleCount(), 1u);
  for (int k = 0; k < 3; ++k) {
    const glm::dvec3 world = scene->origin + glm::dvec3(m.positions[m.indices[k]]);
    EXPECT_NEAR(glm::distance(world, expected[k]), 0.0, 1e-4) << "vertex " << k;
  }
  // No normals in the file: flat ones are made, facing up for this counter-clockwise triangle.
  EXPECT_NEAR(m.normals[m.indices[0]].z, 1.0, 1e-6);
  EXPECT_TRUE(scene->occluders.empty());
}

TEST(GltfIo, ConvertsStripsAndFansAndSkipsLinesWithWarning) {
  ForeignBuilder f;
  const int pos = f.Positions({0, 0, 0, 1, 0, 0, 0, 0, -1, 1, 0, -1});
  const int strip = f.Node("strip", f.Mesh(pos, -1, TINYGLTF_MODE_TRIANGLE_STRIP));
  // A fan walks the polygon's outline: (0,0), (1,0), (1,1), (0,1) in z-up.
  const int fan_pos = f.Positions({0, 0, 0, 1, 0, 0, 1, 0, -1, 0, 0, -1});
  const int fan = f.Node("fan", f.Mesh(fan_pos, -1, TINYGLTF_MODE_TRIANGLE_FAN));
  const int lines = f.Node("lines", f.Mesh(pos, -1, TINYGLTF_MODE_LINE));
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {strip, fan, lines};
  const std::string path = f.Save("modes.gltf", false);
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadGltf(path, &warnings);
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_EQ(scene->objects.size(), 2u);
  EXPECT_EQ(scene->objects[0].mesh.TriangleCount(), 2u);
  EXPECT_EQ(scene->objects[1].mesh.TriangleCount(), 2u);
  // Strip winding alternates: both triangles must face up like the first.
  for (const Object& o : scene->objects) {
    for (const glm::vec3& n : o.mesh.normals) EXPECT_GT(n.z, 0.99f) << o.name;
  }
  bool warned = false;
  for (const std::string& w : warnings) warned |= w.find("'lines'") != std::string::npos && w.find("skipped") != std::string::npos;
  EXPECT_TRUE(warned) << "no warning for the line primitive";
}

tinygltf::Value OccluderExtras(std::vector<double> footprint, double height) {
  tinygltf::Value::Array fp;
  for (double x : footprint) fp.emplace_back(x);
  tinygltf::Value::Object oc{{"footprint", tinygltf::Value(fp)}, {"height", tinygltf::Value(height)}};
  tinygltf::Value::Array list{tinygltf::Value(oc)};
  return tinygltf::Value(tinygltf::Value::Object{
      {"vistream", tinygltf::Value(tinygltf::Value::Object{{"occluders", tinygltf::Value(list)}})}});
}

TEST(GltfIo, OccluderExtrasFollowTheNodeTransform) {
  ForeignBuilder f;
  const int pos = f.Positions(kGroundTriangle);
  const int node = f.Node("box", f.Mesh(pos, -1, TINYGLTF_MODE_TRIANGLES));
  f.model.nodes[node].extras = OccluderExtras({0, 0, 4, 0, 4, 2, 0, 2}, 10);
  // Rotate 90° about the vertical, lift the scale to 3, move to z-up (50, 60).
  const double s = std::sqrt(0.5);
  f.model.nodes[node].rotation = {0, s, 0, s};
  f.model.nodes[node].scale = {3, 3, 3};
  f.model.nodes[node].translation = {50, 0, -60};
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {node};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("occ.glb", true));
  ASSERT_TRUE(scene.ok()) << scene.status();
  ASSERT_EQ(scene->occluders.size(), 1u);
  const Occluder25D& oc = scene->occluders[0];
  EXPECT_DOUBLE_EQ(oc.height, 30.0);
  EXPECT_GT(SignedArea(oc.footprint), 0.0);
  const glm::dvec2 expected[4] = {{50, 60}, {50, 72}, {44, 72}, {44, 60}};  // (x,y) -> (-y, x) * 3
  for (int k = 0; k < 4; ++k) {
    const glm::dvec2 world = glm::dvec2(scene->origin) + oc.footprint[k];
    EXPECT_NEAR(glm::distance(world, expected[k]), 0.0, 1e-9) << "corner " << k;
  }
}

TEST(GltfIo, TiltedOccluderIsDroppedWithWarning) {
  ForeignBuilder f;
  const int node = f.Node("tilted", f.Mesh(f.Positions(kGroundTriangle), -1, TINYGLTF_MODE_TRIANGLES));
  f.model.nodes[node].extras = OccluderExtras({0, 0, 1, 0, 1, 1}, 5);
  f.model.nodes[node].rotation = {0.3826834, 0, 0, 0.9238795};  // 45° about x: not vertical
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {node};
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("tilted.glb", true), &warnings);
  ASSERT_TRUE(scene.ok()) << scene.status();
  EXPECT_TRUE(scene->occluders.empty());
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings.back().find("tilts"), std::string::npos) << warnings.back();
}

TEST(GltfIo, MalformedOccluderExtrasNameTheNodeAndKey) {
  ForeignBuilder f;
  const int node = f.Node("bad", f.Mesh(f.Positions(kGroundTriangle), -1, TINYGLTF_MODE_TRIANGLES));
  f.model.nodes[node].extras = OccluderExtras({0, 0, 1, 0, 1}, 5);  // odd count
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {node};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("badocc.glb", true));
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("'bad'"), std::string::npos) << scene.status();
  EXPECT_NE(scene.status().message().find("occluders[0].footprint"), std::string::npos) << scene.status();
}

TEST(GltfIo, ForeignFileTranslatedFarAwayLoadsToTheSameLocalGeometry) {
  auto build = [](double dx, double dy, const std::string& file) {
    ForeignBuilder f;
    const int node = f.Node("tri", f.Mesh(f.Positions(kGroundTriangle), -1, TINYGLTF_MODE_TRIANGLES));
    f.model.nodes[node].translation = {12.0 + dx, 0, -(34.0 + dy)};
    f.model.scenes.push_back(tinygltf::Scene{});
    f.model.scenes[0].nodes = {node};
    return LoadGltf(f.Save(file, true));
  };
  absl::StatusOr<Scene> near = build(0, 0, "near.glb");
  absl::StatusOr<Scene> far = build(500000, 5000000, "far.glb");
  ASSERT_TRUE(near.ok() && far.ok());
  EXPECT_EQ(far->origin - near->origin, glm::dvec3(500000, 5000000, 0));
  EXPECT_EQ(near->objects[0].mesh.positions, far->objects[0].mesh.positions);
}

// --- Bad input: clear errors, never a crash. ---

TEST(GltfIo, EveryTruncationOfAGlbIsRejected) {
  const std::string path = TempDir() + "/trunc-src.glb";
  ASSERT_TRUE(SaveGltf(SmallScene(), path).ok());
  const std::string bytes = ReadFile(path);
  ASSERT_GT(bytes.size(), 100u);
  for (size_t n = 0; n < bytes.size(); ++n) {
    absl::StatusOr<Scene> scene = LoadGltfFromMemory(std::string_view(bytes.data(), n), true, "cut.glb");
    ASSERT_FALSE(scene.ok()) << "accepted a .glb cut to " << n << " of " << bytes.size() << " bytes";
    ASSERT_NE(scene.status().message().find("cut.glb"), std::string::npos) << scene.status();
  }
  // A file cut short but whose header still claims the whole length (tinygltf copies what the
  // header says): named before anything is read.
  std::string claims = bytes.substr(0, bytes.size() - 5);
  const absl::StatusOr<Scene> lying = LoadGltfFromMemory(claims, true, "claims.glb");
  ASSERT_FALSE(lying.ok());
  EXPECT_NE(lying.status().message().find("the .glb header says " + std::to_string(bytes.size()) + " bytes, the file has " +
                                          std::to_string(bytes.size() - 5)),
            std::string::npos)
      << lying.status();
  // A chunk claiming more than the file holds.
  std::string chunk = bytes;
  chunk[12] = static_cast<char>(0xff), chunk[13] = static_cast<char>(0xff);
  const absl::StatusOr<Scene> past = LoadGltfFromMemory(chunk, true, "chunk.glb");
  ASSERT_FALSE(past.ok());
  EXPECT_NE(past.status().message().find("chunk at byte 12"), std::string::npos) << past.status();
  // And from a file on disk, with the .glb extension but no magic.
  const std::string cut = TempDir() + "/truncated.glb";
  WriteFile(cut, bytes.substr(0, 3));
  absl::StatusOr<Scene> scene = LoadGltf(cut);
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("truncated.glb"), std::string::npos);
}

TEST(GltfIo, NanCoordinateIsRejectedNamingTheObject) {
  ForeignBuilder f;
  std::vector<float> xyz = kGroundTriangle;
  xyz[4] = std::nanf("");
  const int node = f.Node("broken", f.Mesh(f.Positions(xyz), -1, TINYGLTF_MODE_TRIANGLES));
  f.model.accessors[0].minValues = {0, 0, -1};  // tinygltf would write NaN into the JSON
  f.model.accessors[0].maxValues = {1, 0, 0};
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {node};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("nan.glb", true));
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("'broken'"), std::string::npos) << scene.status();
  EXPECT_NE(scene.status().message().find("non-finite"), std::string::npos) << scene.status();
}

TEST(GltfIo, FileWithoutTrianglesIsAnEmptySceneError) {
  ForeignBuilder f;
  f.Node("empty", -1);
  f.model.buffers.clear();
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {0};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("empty.gltf", false));
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("no triangle meshes"), std::string::npos) << scene.status();
}

TEST(GltfIo, IndexOutOfRangeIsRejected) {
  ForeignBuilder f;
  const int pos = f.Positions(kGroundTriangle);
  const std::vector<uint32_t> idx = {0, 1, 7};
  const int ia = f.Accessor(f.View(idx.data(), 12), TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, 3);
  f.Node("oob", f.Mesh(pos, ia, TINYGLTF_MODE_TRIANGLES));
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {0};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("oob.glb", true));
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("out of range"), std::string::npos) << scene.status();
}

TEST(GltfIo, AccessorPastTheBufferIsRejected) {
  ForeignBuilder f;
  const int pos = f.Positions(kGroundTriangle);
  f.model.accessors[pos].count = 1000;  // claims far more than the view holds
  f.Node("long", f.Mesh(pos, -1, TINYGLTF_MODE_TRIANGLES));
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {0};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("past.glb", true));
  ASSERT_FALSE(scene.ok());
}

TEST(GltfIo, NodeCycleIsRejected) {
  ForeignBuilder f;
  const int a = f.Node("a", f.Mesh(f.Positions(kGroundTriangle), -1, TINYGLTF_MODE_TRIANGLES));
  const int b = f.Node("b", -1);
  f.model.nodes[a].children = {b};
  f.model.nodes[b].children = {a};
  f.model.scenes.push_back(tinygltf::Scene{});
  f.model.scenes[0].nodes = {a};
  absl::StatusOr<Scene> scene = LoadGltf(f.Save("cycle.gltf", false));
  ASSERT_FALSE(scene.ok());
  EXPECT_NE(scene.status().message().find("cycle"), std::string::npos) << scene.status();
}

TEST(GltfIo, MissingFileAndGarbageAreErrors) {
  absl::StatusOr<Scene> missing = LoadGltf(TempDir() + "/does-not-exist.glb");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("does-not-exist.glb"), std::string::npos);
  const std::string garbage = TempDir() + "/garbage.gltf";
  WriteFile(garbage, "{\"asset\": {\"version\": \"2.0\"}, \"nodes\": [{\"mesh\": 5}], \"scenes\": [{\"nodes\": [0]}]}");
  absl::StatusOr<Scene> scene = LoadGltf(garbage);
  ASSERT_FALSE(scene.ok());
  const std::string not_json = TempDir() + "/notjson.gltf";
  WriteFile(not_json, "{ this is not json");
  EXPECT_FALSE(LoadGltf(not_json).ok());
}

TEST(GltfIo, ExternalBuffersMayNotLeaveTheFilesFolder) {
  // A valid .gltf + .bin pair, then the same JSON pointing at ../ and at an absolute path.
  const std::string dir = TempDir() + "/confined";
  std::filesystem::create_directories(dir);
  ASSERT_TRUE(SaveGltf(SmallScene(), dir + "/ok.gltf").ok());
  ASSERT_TRUE(LoadGltf(dir + "/ok.gltf").ok());
  std::filesystem::copy_file(dir + "/ok.bin", TempDir() + "/secret.bin",
                             std::filesystem::copy_options::overwrite_existing);
  const std::string json = ReadFile(dir + "/ok.gltf");
  const size_t at = json.find("\"ok.bin\"");
  ASSERT_NE(at, std::string::npos);
  for (const std::string& uri : {std::string("../secret.bin"), TempDir() + "/secret.bin"}) {
    std::string hostile = json;
    hostile.replace(at, 8, "\"" + uri + "\"");
    WriteFile(dir + "/hostile.gltf", hostile);
    absl::StatusOr<Scene> scene = LoadGltf(dir + "/hostile.gltf");
    ASSERT_FALSE(scene.ok()) << "read " << uri;
    // A relative escape is refused by name; tinygltf joins even an absolute URI below the
    // folder, where it is not found.
    const bool relative = uri.front() != '/';
    EXPECT_NE(scene.status().message().find(relative ? "outside" : "not found"), std::string::npos)
        << scene.status();
  }
  // From memory without a folder, not even the neighbouring file may be read.
  EXPECT_FALSE(LoadGltfFromMemory(json, false, "mem.gltf").ok());
  EXPECT_TRUE(LoadGltfFromMemory(json, false, "mem.gltf", dir).ok());
}

TEST(GltfIo, SaveRejectsAnInvalidScene) {
  Scene empty;
  const absl::Status s = SaveGltf(empty, TempDir() + "/empty-out.glb");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no objects"), std::string::npos) << s;
}

}  // namespace
}  // namespace vistream::scenes

namespace vistream::scenes {
namespace {

TEST(GltfIo, PathsRoundTripInTheOriginNodeAndLeaveTheFingerprintAlone) {
  Scene scene = SmallScene();
  const uint64_t before = SceneFingerprint(scene);
  scene.paths = {{"street 1", {{0.5, -3.25}, {100.125, -3.25}, {100.125, 250.0}}},
                 {"street 2 (Rue Grimaldi)", {{-1e5, 2e5}, {1.0 / 3.0, 0.1}}}};
  EXPECT_EQ(SceneFingerprint(scene), before);
  ASSERT_TRUE(ValidateScene(scene, "small").ok());
  for (const char* file : {"paths.glb", "paths.gltf"}) {
    const std::string path = TempDir() + "/" + file;
    ASSERT_TRUE(SaveGltf(scene, path).ok());
    std::vector<std::string> warnings;
    absl::StatusOr<Scene> back = LoadGltf(path, &warnings);
    ASSERT_TRUE(back.ok()) << back.status();
    EXPECT_TRUE(warnings.empty()) << warnings.front();
    ExpectSameScene(scene, *back);
    ASSERT_EQ(back->paths.size(), 2u) << file;
    for (size_t i = 0; i < 2; ++i) {
      EXPECT_EQ(back->paths[i].name, scene.paths[i].name);
      EXPECT_EQ(back->paths[i].waypoints, scene.paths[i].waypoints);  // doubles, exactly
    }
    EXPECT_EQ(SceneFingerprint(*back), before);
  }
  // A scene without paths writes none.
  const std::string plain = TempDir() + "/nopaths.gltf";
  ASSERT_TRUE(SaveGltf(SmallScene(), plain).ok());
  EXPECT_EQ(ReadFile(plain).find("\"paths\""), std::string::npos);
}

TEST(GltfIo, BadPathsAreWarnedAboutAndSkipped) {
  Scene scene = SmallScene();
  scene.paths = {{"good", {{0, 0}, {10, 0}}}};
  const std::string path = TempDir() + "/badpaths.gltf";
  ASSERT_TRUE(SaveGltf(scene, path).ok());
  nlohmann::json j = nlohmann::json::parse(ReadFile(path));
  nlohmann::json* origin = nullptr;
  for (nlohmann::json& n : j["nodes"]) {
    if (n.contains("extras") && n["extras"]["vistream"].value("origin", false)) origin = &n;
  }
  ASSERT_NE(origin, nullptr);
  nlohmann::json& paths = (*origin)["extras"]["vistream"]["paths"];
  ASSERT_EQ(paths.size(), 1u);
  for (const char* bad : {R"({"name": "", "waypoints": [0, 0, 1, 1]})", R"({"name": "odd", "waypoints": [0, 0, 1]})",
                          R"({"name": "one point", "waypoints": [0, 0]})", R"({"name": "text", "waypoints": [0, "x", 1, 1]})",
                          R"({"name": "good", "waypoints": [5, 5, 6, 6]})", "7", R"({"name": "fine", "waypoints": [1, 2, 3, 4]})"}) {
    paths.push_back(nlohmann::json::parse(bad));
  }
  WriteFile(path, j.dump());
  std::vector<std::string> warnings;
  absl::StatusOr<Scene> back = LoadGltf(path, &warnings);
  ASSERT_TRUE(back.ok()) << back.status();
  ASSERT_EQ(back->paths.size(), 2u);
  EXPECT_EQ(back->paths[0].name, "good");
  EXPECT_EQ(back->paths[0].waypoints, (std::vector<glm::dvec2>{{0, 0}, {10, 0}}));
  EXPECT_EQ(back->paths[1].name, "fine");
  EXPECT_EQ(warnings.size(), 6u);
  for (const std::string& w : warnings) EXPECT_NE(w.find("extras.vistream.paths["), std::string::npos) << w;
  EXPECT_NE(absl::StrJoin(warnings, "\n").find("a second path named 'good'"), std::string::npos);
}

TEST(Scene, ValidateSceneChecksPaths) {
  Scene scene = SmallScene();
  scene.paths = {{"a", {{0, 0}}}};
  EXPECT_NE(ValidateScene(scene, "x").message().find("path 0 ('a'): needs at least 2 waypoints"), std::string::npos);
  scene.paths = {{"", {{0, 0}, {1, 1}}}};
  EXPECT_NE(ValidateScene(scene, "x").message().find("has no name"), std::string::npos);
  scene.paths = {{"n", {{0, 0}, {std::nan(""), 1}}}};
  EXPECT_NE(ValidateScene(scene, "x").message().find("not finite"), std::string::npos);
}

}  // namespace
}  // namespace vistream::scenes
