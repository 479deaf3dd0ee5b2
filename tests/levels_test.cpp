// Levels of detail (issue 45): measured errors checked by brute-force sampling, the choice
// checked from random eye points, the compact level codec, bad levels, glTF MSFT_lod.
#include "scenes/levels.h"

#include <algorithm>
#include <cmath>
#include <fstream>

#include <gtest/gtest.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <nlohmann/json.hpp>

#include "scenes/building.h"
#include "scenes/cluster_triangles.h"
#include "scenes/city_generator.h"
#include "scenes/geometry_codec.h"
#include "scenes/gltf_io.h"
#include "scenes/level_choice.h"
#include "scenes/mesh.h"
#include "scenes/random.h"
#include "tests/test_util.h"

namespace vistream::scenes {
namespace {

using testing::TempDir;

// Brute force: the distance from p to the nearest triangle of `meshes`.
double DistanceToSurface(const glm::dvec3& p, const std::vector<const Mesh*>& meshes) {
  double best = INFINITY;
  for (const Mesh* m : meshes) {
    for (size_t t = 0; t + 2 < m->indices.size(); t += 3) {
      const glm::dvec3 a(m->positions[m->indices[t]]), b(m->positions[m->indices[t + 1]]), c(m->positions[m->indices[t + 2]]);
      best = std::min(best, glm::distance(p, ClosestPointOnTriangle(p, a, b, c)));
    }
  }
  return best;
}

// Random points on the triangles of `m` (uniform barycentric), its vertices and edge midpoints.
std::vector<glm::dvec3> SurfaceSamples(const Mesh& m, Rng& rng, int per_triangle) {
  std::vector<glm::dvec3> out;
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    const glm::dvec3 a(m.positions[m.indices[t]]), b(m.positions[m.indices[t + 1]]), c(m.positions[m.indices[t + 2]]);
    out.insert(out.end(), {a, b, c, 0.5 * (a + b), 0.5 * (b + c), 0.5 * (a + c)});
    for (int k = 0; k < per_triangle; ++k) {
      double u = rng.Uniform(0.0, 1.0), v = rng.Uniform(0.0, 1.0);
      if (u + v > 1.0) {
        u = 1.0 - u;
        v = 1.0 - v;
      }
      out.push_back(a + u * (b - a) + v * (c - a));
    }
  }
  return out;
}

// A few buildings of the 1998 paper's dense city (stacked tiers among them), as their own scene.
Scene SmallTown(size_t objects) {
  const Scene city = GenerateTestCity(/*dense=*/true, 3);
  Scene s;
  s.name = "town";
  for (size_t i = 0; i < objects && i < city.objects.size(); ++i) s.AddObject(city.objects[i].name, city.objects[i].mesh);
  return s;
}

LevelOptions SmallOptions() {
  LevelOptions o;
  o.cluster_tiles_m = {60.0, 240.0};
  o.threads = 2;
  return o;
}

TEST(Levels, MeasuredErrorBoundsTheDistanceBetweenLevelAndOriginalBothWays) {
  const Scene town = SmallTown(40);
  const absl::StatusOr<SceneLevels> levels = MakeLevels(town, SmallOptions());
  ASSERT_TRUE(levels.ok()) << levels.status();
  Rng rng(11);
  size_t checked = 0, simplified = 0;
  auto check = [&](const MeshLevel& level, const std::vector<const Mesh*>& originals, const std::string& what) {
    double worst = 0.0;
    for (const glm::dvec3& p : SurfaceSamples(level.mesh, rng, 6)) worst = std::max(worst, DistanceToSurface(p, originals));
    for (const Mesh* m : originals) {
      for (const glm::dvec3& p : SurfaceSamples(*m, rng, 6)) worst = std::max(worst, DistanceToSurface(p, {&level.mesh}));
    }
    EXPECT_LE(worst, level.error_m + 1e-4) << what;
    ++checked;
  };
  for (size_t o = 0; o < town.objects.size(); ++o) {
    for (size_t k = 0; k < levels->objects[o].size(); ++k) {
      const MeshLevel& l = levels->objects[o][k];
      if (l.mesh.TriangleCount() < town.objects[o].mesh.TriangleCount()) ++simplified;
      check(l, {&town.objects[o].mesh}, "object " + std::to_string(o) + " level " + std::to_string(k + 1));
    }
  }
  for (size_t c = 0; c < levels->clusters.size(); ++c) {
    std::vector<const Mesh*> originals;
    for (uint32_t o : levels->clusters[c].objects) originals.push_back(&town.objects[o].mesh);
    for (const MeshLevel& l : levels->clusters[c].levels) check(l, originals, "cluster " + std::to_string(c));
  }
  EXPECT_GT(checked, town.objects.size());  // every object has its snapped level, and more
  EXPECT_GT(simplified, 0u);                // stacked tiers simplify
  EXPECT_FALSE(levels->clusters.empty());
}

TEST(Levels, ErrorOfAShiftedBoxIsTheShift) {
  Mesh box, shifted;
  const std::vector<glm::dvec2> square{{0, 0}, {10, 0}, {10, 10}, {0, 10}};
  AppendConvexPrism(square, 0.0, 10.0, &box);
  std::vector<glm::dvec2> moved = square;
  for (auto& p : moved) p.x += 0.3;
  AppendConvexPrism(moved, 0.0, 10.0, &shifted);
  const double e = MeasureLevelError(shifted, {&box}, 0.01);
  EXPECT_GE(e, 0.3 - 1e-6);
  EXPECT_LE(e, 0.3 + 0.01 + 1e-6);
  EXPECT_NEAR(MeasureLevelError(box, {&box}, 0.01), 0.01, 1e-9);  // identical: the tolerance only
  // The same, translated far away (query-relative: a UTM-sized offset changes nothing).
  Mesh far_box = box, far_shifted = shifted;
  for (auto* m : {&far_box, &far_shifted}) {
    for (auto& p : m->positions) p += glm::vec3(4096.0f, -2048.0f, 0.0f);
  }
  EXPECT_NEAR(MeasureLevelError(far_shifted, {&far_box}, 0.01), e, 1e-3);
}

TEST(Levels, ChainsGetCoarserAndValidate) {
  const Scene town = SmallTown(60);
  const absl::StatusOr<SceneLevels> levels = MakeLevels(town, SmallOptions());
  ASSERT_TRUE(levels.ok()) << levels.status();
  ASSERT_EQ(levels->objects.size(), town.objects.size());
  EXPECT_TRUE(ValidateLevels(*levels, town, "town").ok());
  for (size_t o = 0; o < town.objects.size(); ++o) {
    const auto& chain = levels->objects[o];
    ASSERT_FALSE(chain.empty()) << o;
    // The first level is the object's own triangles, snapped: within the first target.
    EXPECT_EQ(chain[0].mesh.TriangleCount(), town.objects[o].mesh.TriangleCount());
    EXPECT_LE(chain[0].error_m, SmallOptions().object_errors_m[0]);
    for (size_t k = 1; k < chain.size(); ++k) {
      EXPECT_GT(chain[k].error_m, chain[k - 1].error_m);
      EXPECT_LT(chain[k].mesh.TriangleCount(), chain[k - 1].mesh.TriangleCount());
    }
  }
  for (const Cluster& c : levels->clusters) {
    EXPECT_GE(c.objects.size(), 2u);
    EXPECT_TRUE(std::is_sorted(c.objects.begin(), c.objects.end()));
    for (uint32_t o : c.objects) EXPECT_TRUE(c.bounds.Contains(town.objects[o].bounds));
  }
}

TEST(Levels, BadOptionsAndCancellationAreErrors) {
  const Scene town = SmallTown(4);
  LevelOptions o = SmallOptions();
  o.object_errors_m = {1.0, 0.5};
  EXPECT_EQ(MakeLevels(town, o).status().code(), absl::StatusCode::kInvalidArgument);
  o = SmallOptions();
  o.max_triangle_share = 1.5;
  EXPECT_EQ(MakeLevels(town, o).status().code(), absl::StatusCode::kInvalidArgument);
  std::atomic<bool> cancel{true};
  const absl::StatusOr<SceneLevels> cancelled = MakeLevels(SmallTown(200), SmallOptions(), RunControl{nullptr, &cancel});
  EXPECT_EQ(cancelled.status().code(), absl::StatusCode::kCancelled);
}

// A scene with levels whose chains include a simplified level, for the checks below.
struct Leveled {
  Scene scene;
  size_t simplified_object = 0;  // an object with at least 2 levels
};

Leveled LeveledTown() {
  Leveled l;
  l.scene = SmallTown(30);
  l.scene.origin = glm::dvec3(699000.0, 5710000.0, 0.0);
  absl::StatusOr<SceneLevels> levels = MakeLevels(l.scene, SmallOptions());
  EXPECT_TRUE(levels.ok()) << levels.status();
  l.scene.levels = *std::move(levels);
  for (size_t o = 0; o < l.scene.objects.size(); ++o) {
    if (l.scene.levels.objects[o].size() >= 2) {
      l.simplified_object = o;
      break;
    }
  }
  EXPECT_GE(l.scene.levels.objects[l.simplified_object].size(), 2u);
  return l;
}

// Cluster levels as pieces (issue 45): made levels keep each object's triangles in one run,
// objects ascending; a level that keeps the objects' triangles gives each its own; a simplified
// one gives each triangle to the object whose box is nearest its centroid (brute force agrees);
// grouping again changes nothing.
TEST(Levels, ClusterLevelsComeInOneRunPerObject) {
  const Leveled l = LeveledTown();
  size_t simplified = 0, kept = 0;
  for (const Cluster& c : l.scene.levels.clusters) {
    size_t full = 0;
    for (uint32_t o : c.objects) full += l.scene.objects[o].mesh.TriangleCount();
    for (const MeshLevel& level : c.levels) {
      const std::vector<uint32_t> owners = ClusterTriangleOwners(l.scene, c, level.mesh);
      ASSERT_EQ(owners.size(), level.mesh.TriangleCount());
      EXPECT_TRUE(std::is_sorted(owners.begin(), owners.end()));
      const std::vector<uint32_t> counts = ClusterObjectTriangles(l.scene, c, level.mesh);
      ASSERT_EQ(counts.size(), c.objects.size());
      if (level.mesh.TriangleCount() == full) {
        ++kept;
        for (size_t k = 0; k < c.objects.size(); ++k) {
          EXPECT_EQ(counts[k], l.scene.objects[c.objects[k]].mesh.TriangleCount());
        }
        continue;
      }
      ++simplified;
      for (size_t t = 0; t < owners.size(); ++t) {
        glm::dvec3 p(0.0);
        for (int v = 0; v < 3; ++v) p += glm::dvec3(level.mesh.positions[level.mesh.indices[3 * t + v]]);
        p /= 3.0;
        double best = 1e300;
        uint32_t want = 0;
        for (uint32_t k = 0; k < c.objects.size(); ++k) {
          Aabb at;
          at.Extend(p);
          const double d = BoxDistance(at, l.scene.objects[c.objects[k]].bounds);
          if (d < best - 1e-9) {
            best = d;
            want = k;
          }
        }
        Aabb at;
        at.Extend(p);
        EXPECT_NEAR(BoxDistance(at, l.scene.objects[c.objects[owners[t]]].bounds), best, 1e-6)
            << "triangle " << t << " given to " << owners[t] << ", nearest " << want;
      }
    }
  }
  EXPECT_GT(kept, 0u);
  EXPECT_GT(simplified, 0u);
  SceneLevels again = l.scene.levels;
  GroupClusterTriangles(l.scene, &again);
  for (size_t c = 0; c < again.clusters.size(); ++c) {
    for (size_t k = 0; k < again.clusters[c].levels.size(); ++k) {
      EXPECT_EQ(again.clusters[c].levels[k].mesh.indices, l.scene.levels.clusters[c].levels[k].mesh.indices);
    }
  }
}

TEST(Levels, ValidateNamesTheBadLevel) {
  const Leveled good = LeveledTown();
  const size_t o = good.simplified_object;
  auto expect_bad = [&](SceneLevels levels, const std::string& needle) {
    const absl::Status s = ValidateLevels(levels, good.scene, "file.glb");
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << needle;
    EXPECT_NE(s.message().find("file.glb"), std::string::npos) << s;
    EXPECT_NE(s.message().find(needle), std::string::npos) << s;
  };
  const std::string object = "object " + std::to_string(o) + " ('" + good.scene.objects[o].name + "'), level ";
  SceneLevels bad = good.scene.levels;
  bad.objects[o][0].error_m = -1.0;
  expect_bad(bad, object + "1: error -1 m is not finite and positive");
  bad = good.scene.levels;
  bad.objects[o][1].error_m = bad.objects[o][0].error_m;
  expect_bad(bad, object + "2: error");
  bad = good.scene.levels;
  std::swap(bad.objects[o][0].mesh, bad.objects[o][1].mesh);  // the finer level after the coarser
  expect_bad(bad, object + "2: ");
  bad = good.scene.levels;
  bad.objects[o][0].mesh.indices[4] = 100000;
  expect_bad(bad, object + "1: index 4 = 100000 is out of range");
  bad = good.scene.levels;
  bad.objects.pop_back();
  expect_bad(bad, "levels for 29 objects, but the scene has 30");
  bad = good.scene.levels;
  ASSERT_FALSE(bad.clusters.empty());
  std::reverse(bad.clusters[0].objects.begin(), bad.clusters[0].objects.end());
  expect_bad(bad, "cluster 0: objects are not sorted");
}

TEST(LevelCodec, RoundTripGivesTheSameTrianglesPointsAndNormals) {
  const Leveled l = LeveledTown();
  size_t meshes = 0;
  for (const auto& chain : l.scene.levels.objects) {
    for (const MeshLevel& level : chain) {
      const Mesh& m = level.mesh;
      const EncodedLevelMesh e = EncodeLevelMesh(m);
      const absl::StatusOr<Mesh> back = DecodeLevelMesh(e.vertex_count, e.index_count, e.step_log2, e.origin, e.wide,
                                                        e.vertices, e.indices, "test");
      ASSERT_TRUE(back.ok()) << back.status();
      ASSERT_EQ(back->indices.size(), m.indices.size());
      EXPECT_EQ(back->positions.size(), m.positions.size());
      for (size_t t = 0; t < m.indices.size(); t += 3) {
        // The same three corners, perhaps starting at another one, each with the same normal.
        bool found = false;
        for (int r = 0; r < 3 && !found; ++r) {
          bool same = true;
          for (int k = 0; k < 3; ++k) {
            const uint32_t a = m.indices[t + k], b = back->indices[t + (k + r) % 3];
            same = same && m.positions[a] == back->positions[b] && glm::distance(m.normals[a], back->normals[b]) < 1e-6f;
          }
          found = same;
        }
        EXPECT_TRUE(found) << "triangle " << t / 3;
      }
      EXPECT_LT(e.EncodedBytes(), EncodeMesh(m).EncodedBytes());
      ++meshes;
    }
  }
  EXPECT_GT(meshes, 30u);
}

TEST(LevelCodec, MalformedInputIsAnErrorNamingWhere) {
  const Leveled l = LeveledTown();
  const EncodedLevelMesh e = EncodeLevelMesh(l.scene.levels.objects[0][0].mesh);
  auto decode = [&](uint32_t vc, uint32_t ic, int32_t step, std::string_view v, std::string_view i) {
    return DecodeLevelMesh(vc, ic, step, e.origin, e.wide, v, i, "object 7");
  };
  for (const auto& s : {decode(e.vertex_count, e.index_count, 3, e.vertices, e.indices).status(),
                        decode(e.vertex_count, e.index_count, -11, e.vertices, e.indices).status(),
                        decode(e.vertex_count, e.index_count, e.step_log2, e.vertices.substr(0, 5), e.indices).status(),
                        decode(e.vertex_count, e.index_count, e.step_log2, e.vertices, e.indices.substr(0, 3)).status(),
                        decode(e.vertex_count, e.index_count + 1, e.step_log2, e.vertices, e.indices).status(),
                        decode(2, e.index_count, e.step_log2, e.vertices, e.indices).status()}) {
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << s;
    EXPECT_NE(s.message().find("object 7"), std::string::npos) << s;
  }
  // Every truncation of the vertex bytes is an error, never a crash.
  for (size_t n = 0; n < e.vertices.size(); ++n) {
    EXPECT_FALSE(decode(e.vertex_count, e.index_count, e.step_log2, e.vertices.substr(0, n), e.indices).ok());
  }
}

// The largest distance in pixels between the images of p and p + d on a 1280x720 screen with a
// 60 degree vertical field of view, eye at `eye` looking along `dir`; negative when either
// point is outside the view.
double ProjectedShiftPixels(const glm::dvec3& eye, const glm::dvec3& dir, const glm::dvec3& p, const glm::dvec3& d) {
  const glm::dmat4 view = glm::lookAt(eye, eye + dir, glm::dvec3(0, 0, 1));
  const glm::dmat4 proj = glm::perspective(glm::radians(60.0), 1280.0 / 720.0, 0.1, 1e5);
  auto pixel = [&](const glm::dvec3& q, glm::dvec2* out) {
    const glm::dvec4 c = proj * view * glm::dvec4(q, 1.0);
    if (c.w <= 0) return false;
    const glm::dvec3 ndc = glm::dvec3(c) / c.w;
    if (std::abs(ndc.x) > 1 || std::abs(ndc.y) > 1) return false;
    *out = glm::dvec2((ndc.x + 1) * 640.0, (ndc.y + 1) * 360.0);
    return true;
  };
  glm::dvec2 a, b;
  if (!pixel(p, &a) || !pixel(p + d, &b)) return -1.0;
  return glm::distance(a, b);
}

TEST(LevelChoice, ErrorPixelsBoundsTheImageOfAnyShiftAnywhereOnScreen) {
  const ScreenSpec screen;  // 1280x720, 60 degrees
  Rng rng(5);
  size_t seen = 0;
  double tightest = 0.0;
  for (int i = 0; i < 200000; ++i) {
    const glm::dvec3 eye(rng.Uniform(-5, 5), rng.Uniform(-5, 5), rng.Uniform(0.5, 2.5));
    const double yaw = rng.Uniform(0, 6.283), pitch = rng.Uniform(-0.5, 0.5);
    const glm::dvec3 dir(std::cos(yaw) * std::cos(pitch), std::sin(yaw) * std::cos(pitch), std::sin(pitch));
    const double dist = rng.Uniform(5, 500);
    const glm::dvec3 p = eye + dist * glm::normalize(glm::dvec3(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1)));
    const double e = rng.Uniform(0.001, 0.05) * dist;
    const glm::dvec3 d = e * glm::normalize(glm::dvec3(rng.Uniform(-1, 1), rng.Uniform(-1, 1), rng.Uniform(-1, 1)));
    const double px = ProjectedShiftPixels(eye, dir, p, d);
    if (px < 0) continue;
    ++seen;
    const double bound = ErrorPixels(e, glm::distance(eye, p), screen);
    ASSERT_LE(px, bound * (1 + 1e-9)) << "eye " << eye.x << "," << eye.y << " point at " << dist << " m";
    tightest = std::max(tightest, px / bound);
  }
  EXPECT_GT(seen, 1000u);
  EXPECT_GT(tightest, 0.5);  // the bound is not loose by more than 2x somewhere on screen
}

TEST(LevelChoice, ChosenLevelIsNeverCoarserThanTauAllowsFromAnyEyePoint) {
  const Leveled l = LeveledTown();
  const LevelIndex index(l.scene, l.scene.levels);
  const ScreenSpec screen;
  Rng rng(9);
  std::vector<uint32_t> pvs(l.scene.objects.size());
  for (uint32_t o = 0; o < pvs.size(); ++o) pvs[o] = o;
  size_t coarse = 0, clusters = 0;
  SceneLevels objects_only = l.scene.levels;
  objects_only.clusters.clear();
  const LevelIndex objects_index(l.scene, objects_only);
  for (const LevelIndex* index_used : {&index, &objects_index}) {
    for (const double tau : {0.5, 1.0, 4.0, 64.0}) {
      for (int cell = 0; cell < 20; ++cell) {
        const double x = rng.Uniform(l.scene.bounds.min.x - 3000, l.scene.bounds.max.x + 3000);
        const double y = rng.Uniform(l.scene.bounds.min.y - 3000, l.scene.bounds.max.y + 3000);
        Aabb region;
        region.Extend(glm::dvec3(x, y, 0.5));
        region.Extend(glm::dvec3(x + 50, y + 50, 2.5));
        const std::vector<DrawItem> items = ChooseLevels(*index_used, pvs, region, screen, tau);
        // Every PVS object drawn by exactly one item.
        std::vector<int> drawn(pvs.size(), 0);
        for (const DrawItem& it : items) {
          if (it.kind == DrawItem::Kind::kObject) ++drawn[it.id];
          else for (uint32_t o : l.scene.levels.clusters[it.id].objects) ++drawn[o];
        }
        for (uint32_t o : pvs) EXPECT_EQ(drawn[o], 1) << "object " << o;
        for (int s = 0; s < 50; ++s) {
          const glm::dvec3 eye(rng.Uniform(region.min.x, region.max.x), rng.Uniform(region.min.y, region.max.y),
                               rng.Uniform(region.min.z, region.max.z));
          Aabb at;
          at.Extend(eye);
          for (const DrawItem& it : items) {
            if (it.level == 0) continue;
            const bool object = it.kind == DrawItem::Kind::kObject;
            const double error = object ? l.scene.levels.objects[it.id][it.level - 1].error_m
                                        : l.scene.levels.clusters[it.id].levels[it.level - 1].error_m;
            const Aabb& bounds = object ? l.scene.objects[it.id].bounds : l.scene.levels.clusters[it.id].bounds;
            EXPECT_LE(ErrorPixels(error, BoxDistance(at, bounds), screen), tau);
            coarse += object && it.level > 1 ? 1 : 0;
            clusters += object ? 0 : 1;
          }
        }
      }
    }
  }
  EXPECT_GT(coarse, 0u);
  EXPECT_GT(clusters, 0u);
}

TEST(LevelChoice, ALargerToleranceNeverChoosesFinerBytes) {
  const Leveled l = LeveledTown();
  const LevelIndex index(l.scene, l.scene.levels);
  std::vector<uint32_t> pvs(l.scene.objects.size());
  for (uint32_t o = 0; o < pvs.size(); ++o) pvs[o] = o;
  Aabb region;
  region.Extend(glm::dvec3(l.scene.bounds.min.x - 300, l.scene.bounds.min.y - 300, 0.5));
  region.Extend(glm::dvec3(l.scene.bounds.min.x - 250, l.scene.bounds.min.y - 250, 2.5));
  auto bytes = [&](double tau, bool clusters = false) {
    uint64_t b = 0;
    for (const DrawItem& it : ChooseLevels(index, pvs, region, ScreenSpec{}, tau, clusters)) {
      b += it.kind == DrawItem::Kind::kObject ? index.ObjectBytes(it.id, it.level) : index.ClusterBytes(it.id, it.level);
    }
    return b;
  };
  uint64_t full = 0;
  for (uint32_t o : pvs) full += index.ObjectBytes(o, 0);
  const uint64_t b1 = bytes(0.5), b2 = bytes(2.0), b3 = bytes(32.0);
  EXPECT_LT(b1, full);
  EXPECT_LE(b2, b1);
  EXPECT_LE(b3, b2);
  // Clusters are taken only where no dearer (and they may be refused for their triangles where
  // coarse object levels draw fewer, so bytes need not fall with tau there).
  size_t with_clusters = 0;
  for (const double tau : {0.5, 2.0, 32.0}) {
    EXPECT_LE(bytes(tau, true), bytes(tau));
    for (const DrawItem& it : ChooseLevels(index, pvs, region, ScreenSpec{}, tau)) {
      with_clusters += it.kind == DrawItem::Kind::kCluster ? 1 : 0;
    }
  }
  EXPECT_GT(with_clusters, 0u);
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

TEST(GltfLevels, LevelsRoundTripAsMsftLod) {
  const Leveled l = LeveledTown();
  for (const std::string ext : {".glb", ".gltf"}) {
    const std::string path = TempDir() + "/levels" + ext;
    ASSERT_TRUE(SaveGltf(l.scene, path).ok());
    const absl::StatusOr<Scene> back = LoadGltf(path);
    ASSERT_TRUE(back.ok()) << back.status();
    ASSERT_EQ(back->levels.objects.size(), l.scene.levels.objects.size());
    for (size_t o = 0; o < l.scene.objects.size(); ++o) {
      ASSERT_EQ(back->levels.objects[o].size(), l.scene.levels.objects[o].size()) << o;
      for (size_t k = 0; k < l.scene.levels.objects[o].size(); ++k) {
        EXPECT_EQ(back->levels.objects[o][k].error_m, l.scene.levels.objects[o][k].error_m);
        EXPECT_EQ(back->levels.objects[o][k].mesh.positions, l.scene.levels.objects[o][k].mesh.positions);
        EXPECT_EQ(back->levels.objects[o][k].mesh.indices, l.scene.levels.objects[o][k].mesh.indices);
      }
    }
    ASSERT_EQ(back->levels.clusters.size(), l.scene.levels.clusters.size());
    for (size_t c = 0; c < l.scene.levels.clusters.size(); ++c) {
      EXPECT_EQ(back->levels.clusters[c].objects, l.scene.levels.clusters[c].objects);
      EXPECT_EQ(back->levels.clusters[c].bounds, l.scene.levels.clusters[c].bounds);
      EXPECT_EQ(back->levels.clusters[c].levels.size(), l.scene.levels.clusters[c].levels.size());
    }
    EXPECT_EQ(back->objects.size(), l.scene.objects.size());  // levels are not objects
  }
  const nlohmann::json j = nlohmann::json::parse(ReadFile(TempDir() + "/levels.gltf"));
  EXPECT_NE(std::find(j["extensionsUsed"].begin(), j["extensionsUsed"].end(), "MSFT_lod"), j["extensionsUsed"].end());
  EXPECT_TRUE(j["nodes"][1]["extensions"]["MSFT_lod"]["ids"].is_array());
}

TEST(GltfLevels, BadLevelsAreErrorsNamingTheFileAndTheObject) {
  const Leveled l = LeveledTown();
  const std::string path = TempDir() + "/bad_levels.gltf";
  ASSERT_TRUE(SaveGltf(l.scene, path).ok());
  const nlohmann::json good = nlohmann::json::parse(ReadFile(path));
  const size_t o = l.simplified_object;
  const nlohmann::json& ids = good["nodes"][1 + o]["extensions"]["MSFT_lod"]["ids"];
  const int first = ids[0], second = ids[1];
  const std::string object = "object " + std::to_string(o) + " ('" + l.scene.objects[o].name + "'), level ";
  auto expect_bad = [&](const nlohmann::json& j, const std::string& needle) {
    std::ofstream(path) << j.dump();
    const absl::StatusOr<Scene> s = LoadGltf(path);
    ASSERT_FALSE(s.ok()) << needle;
    EXPECT_NE(s.status().message().find(path), std::string::npos) << s.status();
    EXPECT_NE(s.status().message().find(needle), std::string::npos) << s.status();
  };
  nlohmann::json j = good;
  j["nodes"][first]["extras"]["vistream"].erase("lod_error_m");
  expect_bad(j, object + "1 (node " + std::to_string(first));
  j = good;
  j["nodes"][first]["extras"]["vistream"]["lod_error_m"] = -0.5;
  expect_bad(j, "lod_error_m is not a finite number of metres above 0");
  j = good;  // the coarser level listed first, errors made to increase: the finer has more triangles
  j["nodes"][1 + o]["extensions"]["MSFT_lod"]["ids"] = {second, first};
  j["nodes"][first]["extras"]["vistream"]["lod_error_m"] = 1000.0;
  expect_bad(j, object + "2: ");
  j = good;  // a level's positions cut to 3: its indices run past them
  const int level_mesh = good["nodes"][second]["mesh"];
  const int level_positions = good["meshes"][level_mesh]["primitives"][0]["attributes"]["POSITION"];
  j["accessors"][level_positions]["count"] = 3;
  expect_bad(j, object + "2 (node " + std::to_string(second));
  j = good;
  j["nodes"][1 + o]["extensions"]["MSFT_lod"]["ids"] = {100000};
  expect_bad(j, "MSFT_lod ids[0] (100000) is not a node with a mesh (");
  j = good;
  j["nodes"][0]["extras"]["vistream"]["clusters"][0]["objects"] = {5, 3};
  expect_bad(j, "cluster 0: objects are not sorted");
}

}  // namespace
}  // namespace vistream::scenes
