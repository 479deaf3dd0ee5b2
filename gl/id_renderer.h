#pragma once
// Renders which object each pixel sees: the measured side of the pixel error. Every triangle
// of a scene goes to the GPU once, tagged with its object; a view is a cube map around a
// point (six 90-degree faces), so that the whole sphere of directions is covered, as the
// sampler's uniform camera rays cover it. Depth is reversed 32-bit float, so that buildings
// a metre apart a kilometre away are still told apart. Needs a GL 4.5 context
// (client/gl_context.h); makes its own.

#include <array>
#include <cstdint>
#include <memory>
#include <vector>

#include "absl/status/statusor.h"
#include "gl/gl_context.h"
#include "glm/vec3.hpp"
#include "scenes/scene.h"

namespace vistream::gl {

// What a pixel sees: nothing, the front of object id - 1, or a back face (the eye is inside a
// solid, or sees through a crack).
inline constexpr uint32_t kNothing = 0;
inline constexpr uint32_t kBackFace = 0x80000000u;

class IdRenderer {
 public:
  // Uploads the scene's triangles; faces of `size` x `size` pixels. With `levels`, each
  // object's levels of detail (scene.levels.objects, issue 45) go up too, after the scene's
  // triangles and tagged with their object: RenderView's flags may then pick a level's
  // triangles instead of the full mesh's (a client drawing levels against the full scene).
  // Errors: no context, a size outside 1..4096, GL failing.
  static absl::StatusOr<std::unique_ptr<IdRenderer>> Create(const scenes::Scene& scene, int size,
                                                            bool levels = false);
  ~IdRenderer();
  IdRenderer(const IdRenderer&) = delete;
  IdRenderer& operator=(const IdRenderer&) = delete;

  int size() const { return size_; }
  // The six faces (+x, -x, +y, -y, +z, -z) seen from `eye` (scene-local metres), each size²
  // values, row by row: kNothing, object id + 1, or kBackFace set.
  absl::StatusOr<std::array<std::vector<uint32_t>, 6>> RenderCube(const glm::dvec3& eye);
  // What each pixel of a pinhole view sees (row by row, bottom row first; values as above):
  // the eye at `eye` looking along unit `forward` with `up` (scene-local, z up), vertical field
  // of view `fov_y_rad`, `width` x `height` pixels. Without `triangles`, the full scene (no
  // level). With `triangles`, only the triangles whose flag is non-zero are drawn (one byte per
  // triangle uploaded, triangle_count(), in the order of FirstTriangle, levels after the
  // scene's): the client's drawn set against the full scene. Where a face towards the eye and
  // one away from it lie at the same depth (a level simplified to a sheet seen from its two
  // sides, back to back), the face towards the eye is seen. Errors: sizes outside 1..8192, a
  // flag array of the wrong length, GL failing.
  absl::StatusOr<std::vector<uint32_t>> RenderView(const glm::dvec3& eye, const glm::dvec3& forward,
                                                   const glm::dvec3& up, double fov_y_rad, int width, int height,
                                                   const std::vector<uint8_t>* triangles);
  // The full scene from the same pinhole as RenderView without `triangles`, each pixel naming
  // the triangle it sees instead of its object: kNothing, or the triangle's index among the
  // scene's uploaded triangles (FirstTriangle(object) + its index in the object's mesh) + 1,
  // with kBackFace set where the triangle faces away. The same rasterization as RenderView's
  // full view: pixel for pixel, the object of the triangle is the object RenderView names.
  // Errors: as RenderView's.
  absl::StatusOr<std::vector<uint32_t>> RenderViewTriangles(const glm::dvec3& eye, const glm::dvec3& forward,
                                                            const glm::dvec3& up, double fov_y_rad, int width,
                                                            int height);
  // The object whose full mesh holds uploaded triangle `t` (t < the scene's own triangles).
  uint32_t ObjectOfTriangle(uint64_t t) const;
  // The index of object `id`'s first triangle among the triangles uploaded: its full mesh's
  // (level 0), or, when made with levels, its level `level`'s (1 .. its level count).
  uint64_t FirstTriangle(uint32_t id, uint32_t level = 0) const {
    return level == 0 ? first_triangle_[id] : level_first_triangle_[id][level - 1];
  }
  // With levels, the first triangle of cluster `c`'s level `level` (1 ..): its triangles as the
  // scene holds them (each object's run together: scenes/cluster_triangles.h, which the caller's
  // scene must be grouped by), each tagged with the object it draws.
  uint64_t FirstClusterTriangle(uint32_t c, uint32_t level) const { return cluster_first_triangle_[c][level - 1]; }
  // Triangles uploaded: the scene's, and with levels theirs.
  uint64_t triangle_count() const { return index_count_ / 3; }
  // Whether the levels went up (Create's `levels`).
  bool has_levels() const { return !level_first_triangle_.empty(); }
  // The solid angle of pixel (x, y) of any face; the 6 size² weights sum to 4 pi.
  double PixelSolidAngle(int x, int y) const { return weights_[static_cast<size_t>(y) * size_ + x]; }

 private:
  IdRenderer() = default;
  absl::Status Init(const scenes::Scene& scene, bool levels);

  std::unique_ptr<GlContext> context_;
  int size_ = 0;
  // A linked program and its uniforms: the cube's, and the views' (a front face wins a tie).
  struct Program {
    unsigned id = 0;
    int view_projection = -1, use_mask = -1, mask = -1, triangle_ids = -1;
  };
  Program cube_, view_;
  const Program* pass_ = nullptr;  // the program of the pass under way
  unsigned vao_ = 0, vbo_ = 0, ibo_ = 0, fbo_ = 0, ids_ = 0, depth_ = 0;
  size_t index_count_ = 0;       // every triangle uploaded
  size_t full_index_count_ = 0;  // the scene's own (the full view, the cube)
  std::vector<uint64_t> first_triangle_;
  std::vector<std::vector<uint64_t>> level_first_triangle_;  // [object][level - 1]
  std::vector<std::vector<uint64_t>> cluster_first_triangle_;  // [cluster][level - 1]
  // The scene's objects with triangles in upload order: each one's first triangle and its id.
  std::vector<uint64_t> upload_first_;
  std::vector<uint32_t> upload_ids_;
  unsigned mask_buffer_ = 0, mask_texture_ = 0;
  unsigned view_fbo_ = 0, view_ids_ = 0, view_depth_ = 0;
  int view_width_ = 0, view_height_ = 0;
  // Draws the first `index_count` indices with `m` (column-major, reversed infinite depth)
  // into the bound framebuffer of `w` x `h` and reads it back.
  void DrawAndRead(const double m[16], int w, int h, size_t index_count, std::vector<uint32_t>* out);
  // RenderView and RenderViewTriangles.
  absl::StatusOr<std::vector<uint32_t>> View(const glm::dvec3& eye, const glm::dvec3& forward, const glm::dvec3& up,
                                             double fov_y_rad, int width, int height,
                                             const std::vector<uint8_t>* triangles, bool triangle_ids);
  // The GL state of a pass into `fbo` of `w` x `h` with `program` (reversed depth, the scene's
  // buffers, no mask), and back to the defaults after it (pass_'s), with GL's error if any.
  void BeginPass(unsigned fbo, int w, int h, const Program& program);
  absl::Status EndPass();
  void* clip_control_ = nullptr;  // glClipControl
  std::vector<double> weights_;
};

}  // namespace vistream::gl
