#include "gl/id_renderer.h"

#include "scenes/cluster_triangles.h"

#include <algorithm>
#include <cmath>
#include <string>

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include "absl/status/status.h"
#include "gl/shader.h"
#include "absl/strings/str_cat.h"
#include "glm/geometric.hpp"

namespace vistream::gl {

namespace {

constexpr const char* kVertexShader = R"(#version 450
layout(location = 0) in vec3 position;
layout(location = 1) in uint id_in;
uniform mat4 view_projection;
flat out uint id;
void main() {
  id = id_in;
  gl_Position = view_projection * vec4(position, 1.0);
}
)";

// After "#version 450" and "#define FRONT_FIRST 0 or 1".
constexpr const char* kFragmentShader = R"(
flat in uint id;
uniform bool use_mask;
uniform bool triangle_ids;    // each pixel names its triangle instead of its object
uniform usamplerBuffer mask;  // one flag per triangle of the scene
layout(location = 0) out uint seen;
void main() {
  if (use_mask && texelFetch(mask, gl_PrimitiveID).r == 0u) discard;
#if FRONT_FIRST
  // A face towards the eye wins a tie in depth with one away from it: reversed depth (larger is
  // nearer), it moves nearer by a millionth of its depth.
  gl_FragDepth = gl_FrontFacing ? gl_FragCoord.z * 1.000001 : gl_FragCoord.z;
#endif
  if (triangle_ids) {
    seen = (uint(gl_PrimitiveID) + 1u) | (gl_FrontFacing ? 0u : 0x80000000u);
  } else {
    seen = gl_FrontFacing ? id + 1u : 0x80000000u;
  }
}
)";

struct Vertex {
  float x, y, z;
  uint32_t id;
};

// An id target of `w` x `h`: 32-bit ids and float depth, in a new framebuffer. Whether it is
// complete; unbinds it.
bool MakeTarget(int w, int h, GLuint* ids, GLuint* depth, GLuint* fbo) {
  glGenTextures(1, ids);
  glBindTexture(GL_TEXTURE_2D, *ids);
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_R32UI, w, h);
  glGenRenderbuffers(1, depth);
  glBindRenderbuffer(GL_RENDERBUFFER, *depth);
  glRenderbufferStorage(GL_RENDERBUFFER, GL_DEPTH_COMPONENT32F, w, h);
  glGenFramebuffers(1, fbo);
  glBindFramebuffer(GL_FRAMEBUFFER, *fbo);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, *ids, 0);
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, *depth);
  const bool complete = glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  return complete;
}

// Column-major world-to-clip of a pinhole at `eye` looking along `forward` with `up`: view rows
// s, u, -f with the eye's translation, focal scales fx and fy, and reversed infinite depth
// (clip z = near, clip w = -view z).
void PinholeReversedInfinite(const glm::dvec3& eye, const glm::dvec3& forward, const glm::dvec3& up, double fx,
                             double fy, double near, double m[16]) {
  const glm::dvec3 f = glm::normalize(forward);
  const glm::dvec3 s = glm::normalize(glm::cross(f, up));
  const glm::dvec3 u = glm::cross(s, f);
  const glm::dvec3 rows[3] = {s, u, -f};
  double view[3][4];
  for (int r = 0; r < 3; ++r) {
    view[r][0] = rows[r].x;
    view[r][1] = rows[r].y;
    view[r][2] = rows[r].z;
    view[r][3] = -glm::dot(rows[r], eye);
  }
  for (int c = 0; c < 4; ++c) {
    m[4 * c + 0] = fx * view[0][c];
    m[4 * c + 1] = fy * view[1][c];
    m[4 * c + 2] = c == 3 ? near : 0.0;
    m[4 * c + 3] = -view[2][c];
  }
}

// The solid angle of the part [0, u] x [0, v] of a cube face at distance 1, signed.
double CornerAngle(double u, double v) { return std::atan2(u * v, std::sqrt(u * u + v * v + 1.0)); }

}  // namespace

IdRenderer::~IdRenderer() {
  if (context_ == nullptr || !context_->MakeCurrent().ok()) return;
  glDeleteProgram(cube_.id);
  glDeleteProgram(view_.id);
  glDeleteVertexArrays(1, &vao_);
  glDeleteBuffers(1, &vbo_);
  glDeleteBuffers(1, &ibo_);
  glDeleteFramebuffers(1, &fbo_);
  glDeleteTextures(1, &ids_);
  glDeleteRenderbuffers(1, &depth_);
  glDeleteBuffers(1, &mask_buffer_);
  glDeleteTextures(1, &mask_texture_);
  if (view_fbo_ != 0) {
    glDeleteFramebuffers(1, &view_fbo_);
    glDeleteTextures(1, &view_ids_);
    glDeleteRenderbuffers(1, &view_depth_);
  }
}

absl::StatusOr<std::unique_ptr<IdRenderer>> IdRenderer::Create(const scenes::Scene& scene, int size, bool levels) {
  if (size < 1 || size > 4096) return absl::InvalidArgumentError(absl::StrCat("id renderer: face size ", size));
  auto r = std::unique_ptr<IdRenderer>(new IdRenderer());
  absl::StatusOr<std::unique_ptr<GlContext>> context = GlContext::CreateOffscreen();
  if (!context.ok()) return context.status();
  r->context_ = std::move(*context);
  r->size_ = size;
  r->clip_control_ = GlContext::ProcAddress("glClipControl");
  if (r->clip_control_ == nullptr) return absl::UnavailableError("id renderer: the GL has no glClipControl");
  if (absl::Status s = r->Init(scene, levels); !s.ok()) return s;
  return r;
}

absl::Status IdRenderer::Init(const scenes::Scene& scene, bool levels) {
  // The cube's program writes no depth of its own (the GL keeps its early depth test).
  for (Program* p : {&cube_, &view_}) {
    const std::string fragment =
        absl::StrCat("#version 450\n#define FRONT_FIRST ", p == &view_ ? 1 : 0, kFragmentShader);
    absl::StatusOr<GLuint> program = LinkProgram(kVertexShader, fragment.c_str(), "id renderer");
    if (!program.ok()) return program.status();
    p->id = *program;
    p->view_projection = glGetUniformLocation(p->id, "view_projection");
    p->use_mask = glGetUniformLocation(p->id, "use_mask");
    p->triangle_ids = glGetUniformLocation(p->id, "triangle_ids");
    p->mask = glGetUniformLocation(p->id, "mask");
  }

  std::vector<Vertex> vertices;
  std::vector<uint32_t> indices;
  vertices.reserve(scene.VertexCount());
  indices.reserve(3 * scene.TriangleCount());
  first_triangle_.assign(scene.objects.size(), 0);
  for (const scenes::Object& o : scene.objects) {
    if (o.id < first_triangle_.size()) first_triangle_[o.id] = indices.size() / 3;
    if (!o.mesh.indices.empty()) {
      upload_first_.push_back(indices.size() / 3);
      upload_ids_.push_back(o.id);
    }
    const auto base = static_cast<uint32_t>(vertices.size());
    for (const glm::vec3& p : o.mesh.positions) vertices.push_back({p.x, p.y, p.z, o.id});
    for (uint32_t i : o.mesh.indices) indices.push_back(base + i);
  }
  full_index_count_ = indices.size();
  if (levels && !scene.levels.objects.empty()) {
    level_first_triangle_.resize(scene.objects.size());
    for (const scenes::Object& o : scene.objects) {
      if (o.id >= scene.levels.objects.size()) continue;
      for (const scenes::MeshLevel& level : scene.levels.objects[o.id]) {
        level_first_triangle_[o.id].push_back(indices.size() / 3);
        const auto base = static_cast<uint32_t>(vertices.size());
        for (const glm::vec3& p : level.mesh.positions) vertices.push_back({p.x, p.y, p.z, o.id});
        for (uint32_t i : level.mesh.indices) indices.push_back(base + i);
      }
    }
    // Cluster levels: each triangle with its own corners, tagged with the object it draws.
    cluster_first_triangle_.resize(scene.levels.clusters.size());
    for (size_t c = 0; c < scene.levels.clusters.size(); ++c) {
      const scenes::Cluster& cluster = scene.levels.clusters[c];
      for (const scenes::MeshLevel& level : cluster.levels) {
        cluster_first_triangle_[c].push_back(indices.size() / 3);
        const std::vector<uint32_t> owners = scenes::ClusterTriangleOwners(scene, cluster, level.mesh);
        for (size_t t = 0; t < owners.size(); ++t) {
          for (int v = 0; v < 3; ++v) {
            const glm::vec3& p = level.mesh.positions[level.mesh.indices[3 * t + v]];
            indices.push_back(static_cast<uint32_t>(vertices.size()));
            vertices.push_back({p.x, p.y, p.z, cluster.objects[owners[t]]});
          }
        }
      }
    }
  }
  index_count_ = indices.size();
  glGenVertexArrays(1, &vao_);
  glBindVertexArray(vao_);
  glGenBuffers(1, &vbo_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices.size() * sizeof(Vertex)), vertices.data(),
               GL_STATIC_DRAW);
  glGenBuffers(1, &ibo_);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo_);
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, static_cast<GLsizeiptr>(indices.size() * sizeof(uint32_t)), indices.data(),
               GL_STATIC_DRAW);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 3, GL_FLOAT, GL_FALSE, sizeof(Vertex), nullptr);
  glEnableVertexAttribArray(1);
  glVertexAttribIPointer(1, 1, GL_UNSIGNED_INT, sizeof(Vertex), reinterpret_cast<const void*>(3 * sizeof(float)));
  glBindVertexArray(0);

  glGenBuffers(1, &mask_buffer_);
  glGenTextures(1, &mask_texture_);

  if (!MakeTarget(size_, size_, &ids_, &depth_, &fbo_)) {
    return absl::InternalError("id renderer framebuffer is incomplete");
  }
  if (const GLenum err = glGetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("id renderer: GL error ", err, " while uploading the scene"));
  }

  weights_.resize(static_cast<size_t>(size_) * size_);
  for (int y = 0; y < size_; ++y) {
    const double v0 = 2.0 * y / size_ - 1.0, v1 = 2.0 * (y + 1) / size_ - 1.0;
    for (int x = 0; x < size_; ++x) {
      const double u0 = 2.0 * x / size_ - 1.0, u1 = 2.0 * (x + 1) / size_ - 1.0;
      weights_[static_cast<size_t>(y) * size_ + x] =
          CornerAngle(u1, v1) - CornerAngle(u0, v1) - CornerAngle(u1, v0) + CornerAngle(u0, v0);
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<std::array<std::vector<uint32_t>, 6>> IdRenderer::RenderCube(const glm::dvec3& eye) {
  if (absl::Status s = context_->MakeCurrent(); !s.ok()) return s;
  const glm::dvec3 forward[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  const glm::dvec3 up[6] = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 1, 0}, {0, 1, 0}};
  constexpr double kNear = 0.01;  // metres
  BeginPass(fbo_, size_, size_, cube_);
  std::array<std::vector<uint32_t>, 6> faces;
  for (int f = 0; f < 6; ++f) {
    double m[16];
    PinholeReversedInfinite(eye, forward[f], up[f], 1.0, 1.0, kNear, m);  // a 90-degree face
    DrawAndRead(m, size_, size_, full_index_count_, &faces[f]);
  }
  if (absl::Status ended = EndPass(); !ended.ok()) return ended;
  return faces;
}

void IdRenderer::BeginPass(unsigned fbo, int w, int h, const Program& program) {
  pass_ = &program;
  glBindFramebuffer(GL_FRAMEBUFFER, fbo);
  glViewport(0, 0, w, h);
  // Reversed depth: 1 at the near plane, 0 at infinity, in a float buffer.
  reinterpret_cast<PFNGLCLIPCONTROLPROC>(clip_control_)(GL_LOWER_LEFT, GL_ZERO_TO_ONE);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_GREATER);
  glDisable(GL_CULL_FACE);
  glUseProgram(program.id);
  glBindVertexArray(vao_);
  glUniform1i(program.use_mask, 0);
  glUniform1i(program.triangle_ids, 0);
}

absl::Status IdRenderer::EndPass() {
  glUniform1i(pass_->use_mask, 0);
  glUniform1i(pass_->triangle_ids, 0);
  reinterpret_cast<PFNGLCLIPCONTROLPROC>(clip_control_)(GL_LOWER_LEFT, GL_NEGATIVE_ONE_TO_ONE);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (const GLenum err = glGetError(); err != GL_NO_ERROR) {
    return absl::InternalError(absl::StrCat("id renderer: GL error ", err, " while drawing"));
  }
  return absl::OkStatus();
}

void IdRenderer::DrawAndRead(const double m[16], int w, int h, size_t index_count, std::vector<uint32_t>* out) {
  float mf[16];
  for (int k = 0; k < 16; ++k) mf[k] = static_cast<float>(m[k]);
  glUniformMatrix4fv(pass_->view_projection, 1, GL_FALSE, mf);
  const GLuint zero[4] = {0, 0, 0, 0};
  glClearBufferuiv(GL_COLOR, 0, zero);
  const GLfloat far_depth = 0.0f;
  glClearBufferfv(GL_DEPTH, 0, &far_depth);
  glDrawElements(GL_TRIANGLES, static_cast<GLsizei>(index_count), GL_UNSIGNED_INT, nullptr);
  out->resize(static_cast<size_t>(w) * h);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, w, h, GL_RED_INTEGER, GL_UNSIGNED_INT, out->data());
}

absl::StatusOr<std::vector<uint32_t>> IdRenderer::RenderView(const glm::dvec3& eye, const glm::dvec3& forward,
                                                             const glm::dvec3& up, double fov_y_rad, int width,
                                                             int height, const std::vector<uint8_t>* triangles) {
  return View(eye, forward, up, fov_y_rad, width, height, triangles, /*triangle_ids=*/false);
}

absl::StatusOr<std::vector<uint32_t>> IdRenderer::RenderViewTriangles(const glm::dvec3& eye, const glm::dvec3& forward,
                                                                      const glm::dvec3& up, double fov_y_rad, int width,
                                                                      int height) {
  return View(eye, forward, up, fov_y_rad, width, height, nullptr, /*triangle_ids=*/true);
}

uint32_t IdRenderer::ObjectOfTriangle(uint64_t t) const {
  const auto at = std::upper_bound(upload_first_.begin(), upload_first_.end(), t);
  return upload_ids_[static_cast<size_t>(at - upload_first_.begin()) - 1];
}

absl::StatusOr<std::vector<uint32_t>> IdRenderer::View(const glm::dvec3& eye, const glm::dvec3& forward,
                                                       const glm::dvec3& up, double fov_y_rad, int width, int height,
                                                       const std::vector<uint8_t>* triangles, bool triangle_ids) {
  if (width < 1 || height < 1 || width > 8192 || height > 8192) {
    return absl::InvalidArgumentError(absl::StrCat("id renderer: view size ", width, "x", height));
  }
  if (triangles != nullptr && triangles->size() != triangle_count()) {
    return absl::InvalidArgumentError(absl::StrCat("id renderer: ", triangles->size(), " triangle flags for a scene of ",
                                                   triangle_count(), " triangles"));
  }
  if (!(fov_y_rad > 0.0 && fov_y_rad < 3.1)) {
    return absl::InvalidArgumentError(absl::StrCat("id renderer: field of view ", fov_y_rad, " rad"));
  }
  if (absl::Status s = context_->MakeCurrent(); !s.ok()) return s;
  if (view_width_ != width || view_height_ != height) {
    if (view_fbo_ != 0) {
      glDeleteFramebuffers(1, &view_fbo_);
      glDeleteTextures(1, &view_ids_);
      glDeleteRenderbuffers(1, &view_depth_);
    }
    if (!MakeTarget(width, height, &view_ids_, &view_depth_, &view_fbo_)) {
      view_width_ = view_height_ = 0;
      return absl::InternalError("id renderer: view framebuffer is incomplete");
    }
    view_width_ = width;
    view_height_ = height;
  }
  constexpr double kNear = 0.01;  // metres
  BeginPass(view_fbo_, width, height, view_);
  if (triangles != nullptr) {
    glBindBuffer(GL_TEXTURE_BUFFER, mask_buffer_);
    glBufferData(GL_TEXTURE_BUFFER, static_cast<GLsizeiptr>(triangles->size()), triangles->data(), GL_STREAM_DRAW);
    glActiveTexture(GL_TEXTURE0);
    glBindTexture(GL_TEXTURE_BUFFER, mask_texture_);
    glTexBuffer(GL_TEXTURE_BUFFER, GL_R8UI, mask_buffer_);
    glUniform1i(view_.mask, 0);
  }
  glUniform1i(view_.use_mask, triangles != nullptr ? 1 : 0);
  glUniform1i(view_.triangle_ids, triangle_ids ? 1 : 0);
  const double fy = 1.0 / std::tan(0.5 * fov_y_rad), fx = fy * height / width;
  double m[16];
  PinholeReversedInfinite(eye, forward, up, fx, fy, kNear, m);
  std::vector<uint32_t> out;
  DrawAndRead(m, width, height, triangles != nullptr ? index_count_ : full_index_count_, &out);
  if (absl::Status ended = EndPass(); !ended.ok()) return ended;
  return out;
}

}  // namespace vistream::gl
