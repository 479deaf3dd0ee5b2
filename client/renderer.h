#pragma once
// The client's renderer (OpenGL 3.3 core, GLM): draws a viewcell's PVS from the object store,
// or an ε-mask's triangles while the eye is inside its box, with view-frustum culling; flat
// per-face shading under a sun, a ground plane and a sky colour. Each object goes to the GPU
// once (its own buffers), within a per-frame upload budget so that a burst of arrivals never
// makes a frame hitch. The same renderer serves the window and the off-screen front ends: GL
// calls go through the context's function table (gl/gl_functions.h).

#include <array>
#include <map>
#include <cstdint>
#include <memory>
#include <optional>
#include <set>
#include <unordered_map>
#include <vector>

#include <absl/status/statusor.h>
#include <glm/mat4x4.hpp>
#include <glm/vec3.hpp>

#include "client/camera.h"
#include "client/object_store.h"
#include "gl/gl_context.h"

namespace vistream::client {

// What a frame drew: an object whole, or only its ε-mask triangles.
struct DrawnObject {
  uint32_t id = 0;
  bool masked = false;
  uint32_t level = 0;  // the level of detail drawn (0: full; issue 45), or the cluster's
  std::optional<uint32_t> cluster;  // drawn as its piece of this cluster level (issue 45)
};

struct FrameStats {
  uint32_t objects_drawn = 0;
  uint64_t triangles_drawn = 0;
  bool mask_used = false;
};

class Renderer {
 public:
  // `context` must stay current while the renderer is used. With `offscreen` the renderer draws
  // into its own `width` x `height` framebuffer (read back with ReadRgb); otherwise into the
  // window's. Errors: GL failing (shaders, framebuffer).
  // `samples`: multisample antialiasing (0 none, up to 16): the frame is drawn into a
  // multisample framebuffer of the renderer's and resolved (Resolve) into the single-sample one
  // that is read or shown (off-screen its own, else the window's). Errors (INVALID_ARGUMENT):
  // more samples than the OpenGL takes (GL_MAX_SAMPLES; llvmpipe 4).
  static absl::StatusOr<std::unique_ptr<Renderer>> Create(gl::GlContext* context, int width, int height,
                                                          bool offscreen, int samples = 0);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Frees the buffers of objects (and masks) the store dropped and uploads objects it gained: those in
  // `first` before any other, at most `budget_bytes` of vertex and index data a call (at least
  // one object, so that an object larger than the budget still goes up). Returns bytes uploaded.
  uint64_t Sync(ObjectStore& store, const std::vector<uint32_t>& first, uint64_t budget_bytes);
  // Whether `id` can be drawn: uploaded. An object the store replaced by another level stays
  // drawable at the level uploaded before until the new one goes up (never a gap).
  bool Uploaded(uint32_t id) const { return gpu_.count(id) > 0; }
  // The level of detail of `id` on the GPU (0: full); none when not uploaded.
  std::optional<uint32_t> UploadedLevel(uint32_t id) const {
    auto it = gpu_.find(id);
    return it == gpu_.end() ? std::nullopt : std::optional<uint32_t>(it->second.level);
  }
  size_t pending_uploads() const { return pending_.size(); }

  // Draws `objects` (ids; those not uploaded are skipped) as seen by `camera`; with `mask`, only
  // the masked triangles of masked objects (objects the mask lists no triangle of are not
  // drawn); an object held at a level that does not keep its triangles
  // (ReceivedObject::keeps_triangles), or still drawn at the level it had before a new one
  // arrived, is drawn whole when the mask lists it. `drawn`, if given, receives what was drawn.
  // `frame` stamps the objects' last use.
  // The masked index lists are built on first use and kept per object for the last few masks
  // (by EpsilonMaskSet::key), so that frames switching between masks build nothing.
  // With `list_cell` (issue 45), an object that a cluster chosen by that cell's list stands for
  // and that is uploaded is drawn as its piece of the cluster (ObjectStore::CoveringCluster;
  // masked through its bits where the cluster level keeps the objects' triangles, else whole).
  FrameStats Draw(ObjectStore& store, const Camera& camera, const std::vector<uint32_t>& objects,
                  const EpsilonMaskSet* mask, uint64_t frame, std::vector<DrawnObject>* drawn,
                  std::optional<uint32_t> list_cell = std::nullopt);
  // The triangles Draw would draw of `objects` without a mask (uploaded, in the view frustum),
  // counted without drawing.
  uint64_t CountTriangles(const ObjectStore& store, const Camera& camera, const std::vector<uint32_t>& objects,
                          std::optional<uint32_t> list_cell = std::nullopt) const;
  // Whether cluster `id` is uploaded (its pieces can be drawn).
  bool ClusterUploaded(uint32_t id) const { return gpu_clusters_.count(id) > 0; }
  // The frame drawn, into the single-sample framebuffer that is read or shown, and binds that
  // (what is drawn over the frame, the overlay, is drawn there after this). Without samples it
  // binds the framebuffer drawn into. Once a frame; ReadRgb calls it.
  void Resolve();
  // Waits until the frame is drawn (for frame timing).
  void Finish();
  // The last frame as RGB bytes, top row first (width x height x 3), resolved. Errors: GL failing.
  absl::StatusOr<std::vector<uint8_t>> ReadRgb();

  // The colours of sky and ground pixels in ReadRgb (neither is lit).
  static std::array<uint8_t, 3> SkyRgb();
  static std::array<uint8_t, 3> GroundRgb();

  // Distance fog towards the sky colour (scenes::FogSpec, the catalog's effects.fog): none
  // nearer than `start_m` from the eye, whole from `end_m`. end <= start: none (the default).
  void SetFog(double start_m, double end_m) {
    fog_start_m_ = start_m;
    fog_end_m_ = end_m;
  }

  int width() const { return width_; }
  int height() const { return height_; }
  // Resizes the off-screen framebuffer or the window viewport.
  absl::Status Resize(int width, int height);

 private:
  // An object's triangles of one mask, as an index buffer.
  struct MaskedIndices {
    uint64_t mask_key = 0;  // EpsilonMaskSet::key
    unsigned ibo = 0;
    uint32_t count = 0;
    uint64_t last_frame = 0;
  };
  static constexpr size_t kMaskedPerObject = 4;  // masks' index lists kept per object
  struct Gpu {
    unsigned vao = 0, vbo = 0, ibo = 0;
    uint32_t index_count = 0;
    uint32_t level = 0;            // the level of detail uploaded
    bool keeps_triangles = true;   // mask bits apply to it (while it is the store's level)
    std::vector<MaskedIndices> masked;  // at most kMaskedPerObject, the least recently drawn replaced
  };
  Renderer(gl::GlContext* context, const gl::GlFunctions& gl) : context_(context), gl_(gl) {}
  absl::Status Init(bool offscreen);
  absl::Status MakeFramebuffer();
  void FreeFramebuffer();
  void Free(Gpu& g);
  void Upload(uint32_t id, const StoredObject& o);
  // The masked index list of `o` for `mask_key`, built (or rebuilt over the least recently used
  // one) from `bits` when missing.
  MaskedIndices& MaskedFor(Gpu& g, const StoredObject& o, const std::vector<uint8_t>& bits, uint64_t mask_key,
                           uint64_t frame);

  gl::GlContext* context_;
  gl::GlFunctions gl_;
  int width_ = 0, height_ = 0;
  bool offscreen_ = false;
  int samples_ = 0;
  double fog_start_m_ = 0.0, fog_end_m_ = 0.0;
  unsigned program_ = 0, fbo_ = 0, colour_rb_ = 0, depth_rb_ = 0, ground_vao_ = 0, ground_vbo_ = 0;
  unsigned resolve_fbo_ = 0, resolve_rb_ = 0;  // off-screen with samples_ > 0: the single-sample copy ReadRgb reads
  bool resolved_ = false;                      // the frame drawn is resolved (Resolve)
  int loc_view_projection_ = -1, loc_colour_ = -1, loc_sun_ = -1, loc_lit_ = -1, loc_eye_ = -1, loc_fog_ = -1,
      loc_sky_ = -1;
  std::unordered_map<uint32_t, Gpu> gpu_;
  std::set<uint32_t> pending_;
  // Cluster levels (issue 45): one buffer set each; masked index lists per (mask, piece).
  struct GpuCluster {
    Gpu gpu;
    std::vector<uint32_t> first_triangle;  // DecodedCluster's
    std::map<std::pair<uint64_t, size_t>, MaskedIndices> masked;
  };
  static constexpr size_t kMaskedPerCluster = 512;
  std::unordered_map<uint32_t, GpuCluster> gpu_clusters_;
  void UploadCluster(uint32_t id, const StoredCluster& c);
  void FreeCluster(GpuCluster& g);
  // Draws object `id`'s piece of cluster `c` (its `k`-th object); false when there is nothing
  // to draw of it.
  bool DrawPiece(ObjectStore& store, const scenes::ViewFrustum& frustum, uint32_t id, uint32_t c, size_t k,
                 const EpsilonMaskSet* mask, uint64_t frame, FrameStats* stats, std::vector<DrawnObject>* drawn);
};

}  // namespace vistream::client
