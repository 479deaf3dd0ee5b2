#include "client/renderer.h"

#include <algorithm>
#include <cmath>

#include <absl/strings/str_cat.h>
#include <glm/geometric.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "gl/shader.h"
#include "scenes/view_frustum.h"

namespace vistream::client {

namespace {

constexpr const char* kVertexShader = R"(#version 330 core
layout(location = 0) in vec3 position;
uniform mat4 view_projection;
out vec3 world;
void main() {
  world = position;
  gl_Position = view_projection * vec4(position, 1.0);
}
)";

// Flat shading: the face normal from the screen-space derivatives of the world position, so
// every triangle is lit as one face whatever normals its mesh carries.
constexpr const char* kFragmentShader = R"(#version 330 core
in vec3 world;
uniform vec3 colour;
uniform vec3 sun;
uniform float lit;
uniform vec3 eye;
uniform vec2 fog;  // start and end distance, metres; none when end <= start
uniform vec3 sky_colour;
out vec4 fragment;
vec3 Fogged(vec3 c) {
  if (fog.y <= fog.x) return c;
  float f = clamp((length(world - eye) - fog.x) / (fog.y - fog.x), 0.0, 1.0);
  return mix(c, sky_colour, f);
}
void main() {
  if (lit == 0.0) {
    fragment = vec4(Fogged(colour), 1.0);
    return;
  }
  vec3 n = normalize(cross(dFdx(world), dFdy(world)));
  float direct = max(dot(n, sun), 0.0);
  float sky = 0.5 + 0.5 * n.z;
  fragment = vec4(Fogged(colour * (0.30 + 0.15 * sky + 0.60 * direct)), 1.0);
}
)";

constexpr float kSky[3] = {0.62f, 0.77f, 0.92f};
constexpr float kGround[3] = {0.40f, 0.43f, 0.38f};

// A stone or brick tone per object, stable across runs.
glm::vec3 ObjectColour(uint32_t id) {
  uint32_t h = id * 2654435761u;
  h ^= h >> 15;
  const float a = static_cast<float>(h & 0xff) / 255.0f, b = static_cast<float>((h >> 8) & 0xff) / 255.0f;
  const float light = 0.72f + 0.22f * a;
  return {light, light * (0.86f + 0.10f * b), light * (0.74f + 0.14f * b)};
}

std::array<uint8_t, 3> ToRgb(const float c[3]) {
  return {static_cast<uint8_t>(std::lround(c[0] * 255.0f)), static_cast<uint8_t>(std::lround(c[1] * 255.0f)),
          static_cast<uint8_t>(std::lround(c[2] * 255.0f))};
}

}  // namespace

std::array<uint8_t, 3> Renderer::SkyRgb() { return ToRgb(kSky); }
std::array<uint8_t, 3> Renderer::GroundRgb() { return ToRgb(kGround); }

absl::StatusOr<std::unique_ptr<Renderer>> Renderer::Create(gl::GlContext* context, int width, int height,
                                                           bool offscreen, int samples) {
  if (samples < 0 || samples > 16) {
    return absl::InvalidArgumentError(absl::StrCat("renderer: ", samples, " samples is outside 0 .. 16"));
  }
  if (width < 1 || height < 1 || width > 8192 || height > 8192) {
    return absl::InvalidArgumentError(absl::StrCat("renderer: frame size ", width, "x", height,
                                                   " is outside 1x1 .. 8192x8192"));
  }
  auto r = std::unique_ptr<Renderer>(new Renderer(context, context->functions()));
  r->width_ = width;
  r->height_ = height;
  r->samples_ = samples;
  if (samples > 0) {
    GLint most = 0;
    r->gl_.GetIntegerv(GL_MAX_SAMPLES, &most);
    if (samples > most) {
      const auto* name = reinterpret_cast<const char*>(r->gl_.GetString(GL_RENDERER));
      return absl::InvalidArgumentError(absl::StrCat("renderer: ", samples, " samples asked for; this OpenGL (",
                                                     name != nullptr ? name : "unnamed", ") takes at most ", most,
                                                     " (--msaa)"));
    }
  }
  if (absl::Status s = r->Init(offscreen); !s.ok()) return s;
  return r;
}

absl::Status Renderer::Init(bool offscreen) {
  offscreen_ = offscreen;
  absl::StatusOr<GLuint> program = gl::LinkProgram(gl_, kVertexShader, kFragmentShader, "client renderer");
  if (!program.ok()) return program.status();
  program_ = *program;
  loc_view_projection_ = gl_.GetUniformLocation(program_, "view_projection");
  loc_colour_ = gl_.GetUniformLocation(program_, "colour");
  loc_sun_ = gl_.GetUniformLocation(program_, "sun");
  loc_lit_ = gl_.GetUniformLocation(program_, "lit");
  loc_eye_ = gl_.GetUniformLocation(program_, "eye");
  loc_fog_ = gl_.GetUniformLocation(program_, "fog");
  loc_sky_ = gl_.GetUniformLocation(program_, "sky_colour");
  gl_.GenVertexArrays(1, &ground_vao_);
  gl_.GenBuffers(1, &ground_vbo_);
  if (offscreen_ || samples_ > 0) {
    if (absl::Status s = MakeFramebuffer(); !s.ok()) return s;
  }
  if (const GLenum err = gl_.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("renderer: GL error ", err, " while setting up"));
  }
  return absl::OkStatus();
}

absl::Status Renderer::MakeFramebuffer() {
  FreeFramebuffer();
  // With samples, the frame is drawn multisampled and resolved into a second framebuffer to
  // be read (ReadRgb).
  auto storage = [&](GLenum format) {
    if (samples_ > 0) {
      gl_.RenderbufferStorageMultisample(GL_RENDERBUFFER, samples_, format, width_, height_);
    } else {
      gl_.RenderbufferStorage(GL_RENDERBUFFER, format, width_, height_);
    }
  };
  gl_.GenRenderbuffers(1, &colour_rb_);
  gl_.BindRenderbuffer(GL_RENDERBUFFER, colour_rb_);
  storage(GL_RGBA8);
  gl_.GenRenderbuffers(1, &depth_rb_);
  gl_.BindRenderbuffer(GL_RENDERBUFFER, depth_rb_);
  storage(GL_DEPTH_COMPONENT24);
  gl_.GenFramebuffers(1, &fbo_);
  gl_.BindFramebuffer(GL_FRAMEBUFFER, fbo_);
  gl_.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour_rb_);
  gl_.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth_rb_);
  if (gl_.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    return absl::InternalError(absl::StrCat("renderer: the ", samples_ > 0 ? absl::StrCat(samples_, "-sample ") : "",
                                            "framebuffer is incomplete"));
  }
  if (samples_ > 0 && offscreen_) {
    gl_.GenRenderbuffers(1, &resolve_rb_);
    gl_.BindRenderbuffer(GL_RENDERBUFFER, resolve_rb_);
    gl_.RenderbufferStorage(GL_RENDERBUFFER, GL_RGBA8, width_, height_);
    gl_.GenFramebuffers(1, &resolve_fbo_);
    gl_.BindFramebuffer(GL_FRAMEBUFFER, resolve_fbo_);
    gl_.FramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, resolve_rb_);
    if (gl_.CheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
      return absl::InternalError("renderer: the resolve framebuffer is incomplete");
    }
    gl_.BindFramebuffer(GL_FRAMEBUFFER, fbo_);
  }
  return absl::OkStatus();
}

void Renderer::FreeFramebuffer() {
  for (unsigned* f : {&fbo_, &resolve_fbo_}) {
    if (*f != 0) gl_.DeleteFramebuffers(1, f);
    *f = 0;
  }
  for (unsigned* rb : {&colour_rb_, &depth_rb_, &resolve_rb_}) {
    if (*rb != 0) gl_.DeleteRenderbuffers(1, rb);
    *rb = 0;
  }
}

absl::Status Renderer::Resize(int width, int height) {
  if (width < 1 || height < 1) return absl::OkStatus();  // a minimised window: keep the last size
  width_ = width;
  height_ = height;
  return offscreen_ || samples_ > 0 ? MakeFramebuffer() : absl::OkStatus();
}

Renderer::~Renderer() {
  if (context_ == nullptr || !context_->MakeCurrent().ok()) return;
  for (auto& [id, g] : gpu_) Free(g);
  for (auto& [id, g] : gpu_clusters_) FreeCluster(g);
  gl_.DeleteProgram(program_);
  gl_.DeleteVertexArrays(1, &ground_vao_);
  gl_.DeleteBuffers(1, &ground_vbo_);
  FreeFramebuffer();
}

void Renderer::Free(Gpu& g) {
  gl_.DeleteVertexArrays(1, &g.vao);
  gl_.DeleteBuffers(1, &g.vbo);
  gl_.DeleteBuffers(1, &g.ibo);
  for (MaskedIndices& m : g.masked) gl_.DeleteBuffers(1, &m.ibo);
  g.masked.clear();
}

void Renderer::Upload(uint32_t id, const StoredObject& o) {
  if (auto old = gpu_.find(id); old != gpu_.end()) Free(old->second);  // the level it replaces
  Gpu g;
  g.level = o.data.level;
  g.keeps_triangles = o.data.keeps_triangles;
  const scenes::Mesh& mesh = o.data.mesh;
  gl_.GenVertexArrays(1, &g.vao);
  gl_.BindVertexArray(g.vao);
  gl_.GenBuffers(1, &g.vbo);
  gl_.BindBuffer(GL_ARRAY_BUFFER, g.vbo);
  gl_.BufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(mesh.positions.size() * sizeof(glm::vec3)),
                 mesh.positions.data(), GL_STATIC_DRAW);
  gl_.GenBuffers(1, &g.ibo);
  gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);
  gl_.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(mesh.indices.size() * sizeof(uint32_t)),
                 mesh.indices.data(), GL_STATIC_DRAW);
  gl_.EnableVertexAttribArray(0);
  gl_.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(glm::vec3), nullptr);
  gl_.BindVertexArray(0);
  g.index_count = static_cast<uint32_t>(mesh.indices.size());
  gpu_[id] = g;
}

void Renderer::FreeCluster(GpuCluster& g) {
  Free(g.gpu);
  for (auto& [key, m] : g.masked) gl_.DeleteBuffers(1, &m.ibo);
  g.masked.clear();
}

void Renderer::UploadCluster(uint32_t id, const StoredCluster& c) {
  if (auto old = gpu_clusters_.find(id); old != gpu_clusters_.end()) {
    FreeCluster(old->second);
    gpu_clusters_.erase(old);
  }
  GpuCluster g;
  const scenes::Mesh& mesh = c.data.mesh;
  g.gpu.level = c.data.level;
  g.gpu.keeps_triangles = c.data.keeps_triangles;
  g.first_triangle = c.data.first_triangle;
  gl_.GenVertexArrays(1, &g.gpu.vao);
  gl_.BindVertexArray(g.gpu.vao);
  gl_.GenBuffers(1, &g.gpu.vbo);
  gl_.BindBuffer(GL_ARRAY_BUFFER, g.gpu.vbo);
  gl_.BufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(mesh.positions.size() * sizeof(glm::vec3)),
                 mesh.positions.data(), GL_STATIC_DRAW);
  gl_.GenBuffers(1, &g.gpu.ibo);
  gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.gpu.ibo);
  gl_.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(mesh.indices.size() * sizeof(uint32_t)),
                 mesh.indices.data(), GL_STATIC_DRAW);
  gl_.EnableVertexAttribArray(0);
  gl_.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(glm::vec3), nullptr);
  gl_.BindVertexArray(0);
  g.gpu.index_count = static_cast<uint32_t>(mesh.indices.size());
  gpu_clusters_[id] = std::move(g);
}

bool Renderer::DrawPiece(ObjectStore& store, const scenes::ViewFrustum& frustum, uint32_t id, uint32_t c, size_t k,
                         const EpsilonMaskSet* mask, uint64_t frame, FrameStats* stats,
                         std::vector<DrawnObject>* drawn) {
  GpuCluster& g = gpu_clusters_.at(c);
  const StoredCluster* held = store.FindCluster(c);
  if (held == nullptr || held->data.level != g.gpu.level) return false;  // the level uploaded is the store's
  const auto& [lo, hi] = held->piece_bounds[k];
  const uint32_t first = g.first_triangle[k], triangles = g.first_triangle[k + 1] - first;
  if (triangles == 0 || !frustum.MayOverlap(lo, hi)) return false;
  uint32_t count = 3 * triangles;
  const void* offset = reinterpret_cast<const void*>(static_cast<uintptr_t>(first) * 3 * sizeof(uint32_t));
  unsigned masked_ibo = 0;
  bool masked = false;
  if (mask != nullptr) {
    const std::vector<uint8_t>* bits = mask->Bits(id);
    if (bits == nullptr) return false;  // no triangle of it can be seen from the box
    if (g.gpu.keeps_triangles) {
      auto [it, fresh] = g.masked.try_emplace({mask->key, k});
      MaskedIndices& m = it->second;
      if (fresh) {
        if (g.masked.size() > kMaskedPerCluster) {
          // The least recently drawn list goes (not the one just made).
          auto oldest = g.masked.end();
          for (auto at = g.masked.begin(); at != g.masked.end(); ++at) {
            if (at == it) continue;
            if (oldest == g.masked.end() || at->second.last_frame < oldest->second.last_frame) oldest = at;
          }
          gl_.DeleteBuffers(1, &oldest->second.ibo);
          g.masked.erase(oldest);
        }
        std::vector<uint32_t> indices;
        const std::vector<uint32_t>& all = held->data.mesh.indices;
        for (uint32_t t = 0; t < triangles; ++t) {
          if (!visibility::MaskBit(*bits, t)) continue;
          const size_t at = 3 * (static_cast<size_t>(first) + t);
          indices.insert(indices.end(), all.begin() + static_cast<std::ptrdiff_t>(at),
                         all.begin() + static_cast<std::ptrdiff_t>(at + 3));
        }
        gl_.GenBuffers(1, &m.ibo);
        gl_.BindVertexArray(0);
        gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, m.ibo);
        gl_.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(indices.size() * sizeof(uint32_t)),
                       indices.data(), GL_STATIC_DRAW);
        m.mask_key = mask->key;
        m.count = static_cast<uint32_t>(indices.size());
      }
      m.last_frame = frame;
      masked = true;
      count = m.count;
      masked_ibo = m.ibo;
      offset = nullptr;
    }
  }
  if (count == 0) return false;
  gl_.BindVertexArray(g.gpu.vao);
  if (masked) gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, masked_ibo);
  const glm::vec3 colour = ObjectColour(id);
  gl_.Uniform3f(loc_colour_, colour.x, colour.y, colour.z);
  gl_.DrawElements(GL_TRIANGLES, static_cast<GLsizei>(count), GL_UNSIGNED_INT, offset);
  if (masked) gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.gpu.ibo);
  ++stats->objects_drawn;
  stats->triangles_drawn += count / 3;
  if (drawn != nullptr) drawn->push_back({id, masked, g.gpu.level, c});
  return true;
}

uint64_t Renderer::Sync(ObjectStore& store, const std::vector<uint32_t>& first, uint64_t budget_bytes) {
  // Cluster levels: few and needed whole; freed and uploaded at once.
  for (uint32_t id : store.TakeRemovedClusters()) {
    if (auto it = gpu_clusters_.find(id); it != gpu_clusters_.end() && store.FindCluster(id) == nullptr) {
      FreeCluster(it->second);
      gpu_clusters_.erase(it);
    }
  }
  for (uint32_t id : store.TakeAddedClusters()) {
    if (const StoredCluster* c = store.FindCluster(id)) UploadCluster(id, *c);
  }
  const std::vector<uint32_t> added = store.TakeAdded();
  const std::set<uint32_t> again(added.begin(), added.end());
  for (uint32_t id : store.TakeRemoved()) {
    pending_.erase(id);
    // Replaced by another level (or sent again): the copy uploaded is drawn until its
    // successor goes up (Upload frees it then).
    if (again.count(id) > 0 && store.Find(id) != nullptr) continue;
    auto it = gpu_.find(id);
    if (it != gpu_.end()) {
      Free(it->second);
      gpu_.erase(it);
    }
  }
  for (uint32_t id : added) pending_.insert(id);
  if (const std::vector<uint64_t> dropped = store.TakeDroppedMasks(); !dropped.empty()) {
    const std::set<uint64_t> keys(dropped.begin(), dropped.end());
    for (auto& [id, g] : gpu_) {
      std::erase_if(g.masked, [&](MaskedIndices& m) {
        if (keys.count(m.mask_key) == 0) return false;
        gl_.DeleteBuffers(1, &m.ibo);
        return true;
      });
    }
    for (auto& [id, g] : gpu_clusters_) {
      std::erase_if(g.masked, [&](auto& entry) {
        if (keys.count(entry.first.first) == 0) return false;
        gl_.DeleteBuffers(1, &entry.second.ibo);
        return true;
      });
    }
  }
  uint64_t uploaded = 0;
  bool any = false;
  auto take = [&](uint32_t id) {
    if (any && uploaded >= budget_bytes) return false;
    if (pending_.erase(id) == 0) return true;
    const StoredObject* o = store.Find(id);
    if (o == nullptr) return true;  // dropped again before it went up
    Upload(id, *o);
    uploaded += o->data.mesh.positions.size() * sizeof(glm::vec3) + o->data.mesh.indices.size() * sizeof(uint32_t);
    any = true;
    return true;
  };
  for (uint32_t id : first) {
    if (pending_.count(id) > 0 && !take(id)) return uploaded;
  }
  while (!pending_.empty()) {
    if (!take(*pending_.begin())) break;
  }
  return uploaded;
}

Renderer::MaskedIndices& Renderer::MaskedFor(Gpu& g, const StoredObject& o, const std::vector<uint8_t>& bits,
                                             uint64_t mask_key, uint64_t frame) {
  for (MaskedIndices& m : g.masked) {
    if (m.mask_key == mask_key) {
      m.last_frame = frame;
      return m;
    }
  }
  MaskedIndices* slot = nullptr;
  if (g.masked.size() < kMaskedPerObject) {
    slot = &g.masked.emplace_back();
    gl_.GenBuffers(1, &slot->ibo);
  } else {
    auto older = [](const MaskedIndices& a, const MaskedIndices& b) { return a.last_frame < b.last_frame; };
    slot = &*std::min_element(g.masked.begin(), g.masked.end(), older);
  }
  std::vector<uint32_t> indices;
  const std::vector<uint32_t>& all = o.data.mesh.indices;
  const size_t triangles = all.size() / 3;
  for (size_t t = 0; t < triangles; ++t) {
    if (visibility::MaskBit(bits, t)) {
      indices.insert(indices.end(), all.begin() + static_cast<std::ptrdiff_t>(3 * t),
                     all.begin() + static_cast<std::ptrdiff_t>(3 * t + 3));
    }
  }
  gl_.BindVertexArray(0);
  gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, slot->ibo);
  gl_.BufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(indices.size() * sizeof(uint32_t)),
                 indices.data(), GL_STATIC_DRAW);
  slot->mask_key = mask_key;
  slot->count = static_cast<uint32_t>(indices.size());
  slot->last_frame = frame;
  return *slot;
}

FrameStats Renderer::Draw(ObjectStore& store, const Camera& camera, const std::vector<uint32_t>& objects,
                          const EpsilonMaskSet* mask, uint64_t frame, std::vector<DrawnObject>* drawn,
                          std::optional<uint32_t> list_cell) {
  FrameStats stats;
  stats.mask_used = mask != nullptr;
  gl_.BindFramebuffer(GL_FRAMEBUFFER, fbo_);  // 0: the window's
  resolved_ = false;
  gl_.Viewport(0, 0, width_, height_);
  gl_.ClearColor(kSky[0], kSky[1], kSky[2], 1.0f);
  gl_.Clear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  gl_.Enable(GL_DEPTH_TEST);
  gl_.DepthFunc(GL_LESS);
  // Both sides drawn: an imported mesh's winding is not trusted.
  gl_.Disable(GL_CULL_FACE);
  gl_.UseProgram(program_);
  const glm::mat4 vp(camera.ViewProjection());
  gl_.UniformMatrix4fv(loc_view_projection_, 1, GL_FALSE, glm::value_ptr(vp));
  const glm::vec3 sun = glm::normalize(glm::vec3(0.62f, 0.45f, 0.64f));
  gl_.Uniform3f(loc_sun_, sun.x, sun.y, sun.z);
  gl_.Uniform1f(loc_lit_, 1.0f);
  gl_.Uniform3f(loc_eye_, static_cast<float>(camera.eye.x), static_cast<float>(camera.eye.y),
                static_cast<float>(camera.eye.z));
  gl_.Uniform2f(loc_fog_, static_cast<float>(fog_start_m_), static_cast<float>(fog_end_m_));
  gl_.Uniform3f(loc_sky_, kSky[0], kSky[1], kSky[2]);

  // The ground: a square around the eye reaching past the far plane's reach on the ground.
  if (store.has_scene_info()) {
    const float r = static_cast<float>(camera.far_m);
    const auto ex = static_cast<float>(camera.eye.x), ey = static_cast<float>(camera.eye.y);
    const float quad[] = {ex - r, ey - r, 0, ex + r, ey - r, 0, ex + r, ey + r, 0,
                          ex - r, ey - r, 0, ex + r, ey + r, 0, ex - r, ey + r, 0};
    gl_.BindVertexArray(ground_vao_);
    gl_.BindBuffer(GL_ARRAY_BUFFER, ground_vbo_);
    gl_.BufferData(GL_ARRAY_BUFFER, sizeof(quad), quad, GL_STREAM_DRAW);
    gl_.EnableVertexAttribArray(0);
    gl_.VertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, 3 * sizeof(float), nullptr);
    gl_.Uniform3f(loc_colour_, kGround[0], kGround[1], kGround[2]);
    gl_.Uniform1f(loc_lit_, 0.0f);
    gl_.DrawArrays(GL_TRIANGLES, 0, 6);
    gl_.Uniform1f(loc_lit_, 1.0f);
  }

  const scenes::ViewFrustum frustum = camera.Frustum();
  for (uint32_t id : objects) {
    if (list_cell.has_value() && !gpu_clusters_.empty()) {
      const auto piece = store.CoveringCluster(*list_cell, id);
      if (piece.has_value() && ClusterUploaded(piece->first)) {
        DrawPiece(store, frustum, id, piece->first, piece->second, mask, frame, &stats, drawn);
        continue;
      }
    }
    auto it = gpu_.find(id);
    if (it == gpu_.end()) continue;
    StoredObject* o = store.Find(id);
    if (o == nullptr) continue;
    if (!frustum.MayOverlap(o->data.bounds_min, o->data.bounds_max)) continue;
    Gpu& g = it->second;
    bool masked = false;
    uint32_t count = g.index_count;
    unsigned masked_ibo = 0;
    if (mask != nullptr) {
      const std::vector<uint8_t>* bits = mask->Bits(id);
      if (bits == nullptr) continue;  // no triangle of it can be seen from the box
      // The bits name the full mesh's triangles: they apply to the copy uploaded only if it
      // keeps them and is the store's (whose indices MaskedFor reads); else it is drawn whole.
      if (g.keeps_triangles && g.level == o->data.level && !pending_.count(id)) {
        const MaskedIndices& m = MaskedFor(g, *o, *bits, mask->key, frame);
        masked = true;
        count = m.count;
        masked_ibo = m.ibo;
      }
    }
    if (count == 0) continue;
    gl_.BindVertexArray(g.vao);
    if (masked) gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, masked_ibo);
    const glm::vec3 c = ObjectColour(id);
    gl_.Uniform3f(loc_colour_, c.x, c.y, c.z);
    gl_.DrawElements(GL_TRIANGLES, static_cast<GLsizei>(count), GL_UNSIGNED_INT, nullptr);
    if (masked) gl_.BindBuffer(GL_ELEMENT_ARRAY_BUFFER, g.ibo);  // the VAO keeps its own list
    o->last_drawn_frame = frame;
    ++stats.objects_drawn;
    stats.triangles_drawn += count / 3;
    if (drawn != nullptr) drawn->push_back({id, masked, g.level, std::nullopt});
  }
  gl_.BindVertexArray(0);
  return stats;
}

uint64_t Renderer::CountTriangles(const ObjectStore& store, const Camera& camera, const std::vector<uint32_t>& objects,
                                  std::optional<uint32_t> list_cell) const {
  const scenes::ViewFrustum frustum = camera.Frustum();
  uint64_t triangles = 0;
  for (uint32_t id : objects) {
    if (list_cell.has_value() && !gpu_clusters_.empty()) {
      const auto piece = store.CoveringCluster(*list_cell, id);
      if (piece.has_value() && ClusterUploaded(piece->first)) {
        const GpuCluster& g = gpu_clusters_.at(piece->first);
        const auto& [lo, hi] = store.FindCluster(piece->first)->piece_bounds[piece->second];
        if (frustum.MayOverlap(lo, hi)) {
          triangles += g.first_triangle[piece->second + 1] - g.first_triangle[piece->second];
        }
        continue;
      }
    }
    auto it = gpu_.find(id);
    if (it == gpu_.end()) continue;
    const StoredObject* o = store.Find(id);
    if (o == nullptr || !frustum.MayOverlap(o->data.bounds_min, o->data.bounds_max)) continue;
    triangles += it->second.index_count / 3;
  }
  return triangles;
}

void Renderer::Resolve() {
  const unsigned shown = samples_ > 0 ? resolve_fbo_ : fbo_;  // 0: the window's
  if (samples_ > 0 && !resolved_) {
    gl_.BindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
    gl_.BindFramebuffer(GL_DRAW_FRAMEBUFFER, shown);
    gl_.BlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  }
  resolved_ = true;
  gl_.BindFramebuffer(GL_FRAMEBUFFER, shown);
}

void Renderer::Finish() { gl_.Finish(); }

absl::StatusOr<std::vector<uint8_t>> Renderer::ReadRgb() {
  Resolve();
  std::vector<uint8_t> rgba(static_cast<size_t>(width_) * height_ * 4);
  gl_.PixelStorei(GL_PACK_ALIGNMENT, 1);
  gl_.ReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data());
  if (const GLenum err = gl_.GetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("renderer: GL error ", err, " while reading the frame"));
  }
  std::vector<uint8_t> rgb(static_cast<size_t>(width_) * height_ * 3);
  for (int y = 0; y < height_; ++y) {
    const uint8_t* src = rgba.data() + static_cast<size_t>(height_ - 1 - y) * width_ * 4;
    uint8_t* dst = rgb.data() + static_cast<size_t>(y) * width_ * 3;
    for (int x = 0; x < width_; ++x) {
      dst[3 * x] = src[4 * x];
      dst[3 * x + 1] = src[4 * x + 1];
      dst[3 * x + 2] = src[4 * x + 2];
    }
  }
  return rgb;
}

}  // namespace vistream::client
