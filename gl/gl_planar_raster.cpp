#include "gl/gl_planar_raster.h"

#include <algorithm>
#include <array>
#include <bit>
#include <string>

#define GL_GLEXT_PROTOTYPES
#include <GL/gl.h>
#include <GL/glext.h>

#include "absl/status/status.h"
#include "gl/shader.h"

namespace vistream::gl {

namespace {

constexpr uint32_t kMaxRes = 256;

constexpr const char* kVertexShader = R"(#version 450
layout(location = 0) in vec2 uv;
layout(location = 1) in uvec2 blocker_in;
flat out uvec2 blocker;
void main() {
  blocker = blocker_in;
  gl_Position = vec4(uv * 2.0 - 1.0, 0.0, 1.0);
}
)";

// Blockers::PixelBounds, operation for operation (precise: no fused multiply-adds), so that a
// pixel passes here exactly when it passes on the CPU.
constexpr const char* kFragmentShader = R"(#version 450
layout(std430, binding = 0) readonly buffer Blockers {
  dvec4 params;  // eps, n
  dvec4 coeff[];  // a, b, c, 1 / b of each hull vertex
};
flat in uvec2 blocker;
layout(location = 0) out vec4 colour;
void main() {
  double eps = params.x, n = params.y;
  double i = double(floor(gl_FragCoord.x)), j = double(floor(gl_FragCoord.y));
  precise double v0 = j / n;
  precise double v1 = (j + 1.0lf) / n;
  double lo = 1.0e300lf, hi = -1.0e300lf;
  for (uint k = blocker.x; k < blocker.y; ++k) {
    dvec4 c = coeff[k];
    precise double ra = -eps - c.x - c.z * v1;
    precise double rb = eps - c.x - c.z * v0;
    if (c.y > 0.0lf) {
      precise double qa = ra * c.w;
      precise double qb = rb * c.w;
      hi = max(hi, qa);
      lo = min(lo, qb);
    } else {
      if (ra >= 0.0lf) hi = 1.0e300lf;
      if (rb <= 0.0lf) lo = -1.0e300lf;
    }
  }
  precise double first = ceil(lo * n);
  precise double last = floor(hi * n) - 1.0lf;
  if (!(first <= i && i <= last)) discard;
  colour = vec4(1.0);
}
)";

// The square [lo, hi]^2 clipped to {s_p g_p <= m_p} and {s_q g_q <= m_q}: convex, possibly empty.
void ClipSquare(const visibility::BlockerCoeff* const half_planes[2], const double signs[2], const double margins[2],
                double lo, double hi, std::vector<std::array<double, 2>>* poly, std::vector<std::array<double, 2>>* tmp) {
  *poly = {{lo, lo}, {hi, lo}, {hi, hi}, {lo, hi}};
  for (int h = 0; h < 2 && poly->size() >= 3; ++h) {
    const visibility::BlockerCoeff& c = *half_planes[h];
    auto f = [&](const std::array<double, 2>& p) { return signs[h] * (c.a + c.b * p[0] + c.c * p[1]) - margins[h]; };
    tmp->clear();
    for (size_t i = 0; i < poly->size(); ++i) {
      const auto& a = (*poly)[i];
      const auto& b = (*poly)[(i + 1) % poly->size()];
      const double fa = f(a), fb = f(b);
      if (fa <= 0) tmp->push_back(a);
      if ((fa < 0 && fb > 0) || (fa > 0 && fb < 0)) {
        const double t = fa / (fa - fb);
        tmp->push_back({a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])});
      }
    }
    poly->swap(*tmp);
  }
}

}  // namespace

absl::StatusOr<std::unique_ptr<GlPlanarRaster>> GlPlanarRaster::Create() {
  auto raster = std::unique_ptr<GlPlanarRaster>(new GlPlanarRaster());
  absl::StatusOr<std::unique_ptr<GlContext>> context = GlContext::CreateOffscreen();
  if (!context.ok()) return context.status();
  raster->context_ = std::move(*context);
  if (absl::Status s = raster->Init(); !s.ok()) return s;
  return raster;
}

absl::Status GlPlanarRaster::Init() {
  absl::StatusOr<GLuint> program = LinkProgram(kVertexShader, kFragmentShader, "planar raster");
  if (!program.ok()) return program.status();
  program_ = *program;

  glGenTextures(1, &texture_);
  glBindTexture(GL_TEXTURE_2D, texture_);
  glTexStorage2D(GL_TEXTURE_2D, 1, GL_R8, kMaxRes, kMaxRes);
  glGenFramebuffers(1, &fbo_);
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, texture_, 0);
  if (glCheckFramebufferStatus(GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE) {
    return absl::InternalError("planar raster framebuffer is incomplete");
  }

  glGenVertexArrays(1, &vao_);
  glBindVertexArray(vao_);
  glGenBuffers(1, &vbo_);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glEnableVertexAttribArray(0);
  glVertexAttribPointer(0, 2, GL_FLOAT, GL_FALSE, sizeof(Vertex), reinterpret_cast<const void*>(offsetof(Vertex, u)));
  glEnableVertexAttribArray(1);
  glVertexAttribIPointer(1, 2, GL_UNSIGNED_INT, sizeof(Vertex), reinterpret_cast<const void*>(offsetof(Vertex, begin)));
  glGenBuffers(1, &ssbo_);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, 0, ssbo_);

  glUseProgram(program_);
  glDisable(GL_DEPTH_TEST);
  glDisable(GL_BLEND);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  if (glGetError() != GL_NO_ERROR) return absl::InternalError("planar raster set-up raised a GL error");
  return absl::OkStatus();
}

GlPlanarRaster::~GlPlanarRaster() {
  if (context_ == nullptr || !context_->MakeCurrent().ok()) return;
  glDeleteBuffers(1, &ssbo_);
  glDeleteBuffers(1, &vbo_);
  glDeleteVertexArrays(1, &vao_);
  glDeleteFramebuffers(1, &fbo_);
  glDeleteTextures(1, &texture_);
  glDeleteProgram(program_);
}

const std::vector<uint8_t>& GlPlanarRaster::Render(const visibility::Blockers& blockers, uint32_t n) {
  // The blockers' hull vertices, for the shader's exact test (n is filled in per raster).
  next_coeffs_.assign({blockers.eps, 0.0, 0.0, 0.0});
  for (const visibility::BlockerCoeff& c : blockers.coeffs) next_coeffs_.insert(next_coeffs_.end(), {c.a, c.b, c.c, c.inv_b});
  next_groups_.clear();
  for (const visibility::Blocker& g : blockers.groups) next_groups_.emplace_back(g.begin, g.end);
  if (next_coeffs_ != coeffs_ || next_groups_ != groups_ || coeffs_.empty()) {
    coeffs_.swap(next_coeffs_);
    groups_.swap(next_groups_);
    for (auto& r : rasters_) r.clear();
  }
  std::vector<uint8_t>& pixels = rasters_[std::min(std::countr_zero(n), 8)];
  if (pixels.size() == static_cast<size_t>(n) * n) return pixels;
  coeffs_[1] = n;
  glBufferData(GL_SHADER_STORAGE_BUFFER, static_cast<GLsizeiptr>(coeffs_.size() * sizeof(double)), coeffs_.data(),
               GL_STREAM_DRAW);
  coeffs_[1] = 0.0;  // the key leaves n out

  // A convex blocker stops a ray iff the ray meets one of its hull edges, and the rays
  // meeting edge pq are those where g_p and g_q differ in sign: a trapeze, or a double
  // triangle when the edge's line crosses s1 or s2. Each half is RS clipped to two
  // half-planes, drawn a quarter pixel larger in every direction.
  const double grow = 0.25 / n;
  vertices_.clear();
  std::vector<std::array<double, 2>> poly, tmp;
  for (const visibility::Blocker& g : blockers.groups) {
    const uint32_t count = g.end - g.begin;
    if (count < 2) continue;  // a point blocks a line of rays: no pixel lies inside
    const uint32_t edges = count == 2 ? 1 : count;
    for (uint32_t e = 0; e < edges; ++e) {
      const visibility::BlockerCoeff& p = blockers.coeffs[g.begin + e];
      const visibility::BlockerCoeff& q = blockers.coeffs[g.begin + (e + 1) % count];
      for (double s : {1.0, -1.0}) {
        // {s g_p <= 0 <= s g_q}, each side moved out by `grow` in u and v.
        const visibility::BlockerCoeff* planes[2] = {&p, &q};
        const double signs[2] = {s, -s};
        const double margins[2] = {grow * (p.b + p.c), grow * (q.b + q.c)};
        ClipSquare(planes, signs, margins, -grow, 1.0 + grow, &poly, &tmp);
        for (size_t k = 1; k + 1 < poly.size(); ++k) {
          for (const auto& v : {poly[0], poly[k], poly[k + 1]}) {
            vertices_.push_back(Vertex{static_cast<float>(v[0]), static_cast<float>(v[1]), g.begin, g.end});
          }
        }
      }
    }
  }

  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, static_cast<GLsizei>(n), static_cast<GLsizei>(n));
  glClearColor(0, 0, 0, 0);
  glClear(GL_COLOR_BUFFER_BIT);
  glBindBuffer(GL_ARRAY_BUFFER, vbo_);
  glBufferData(GL_ARRAY_BUFFER, static_cast<GLsizeiptr>(vertices_.size() * sizeof(Vertex)), vertices_.data(),
               GL_STREAM_DRAW);
  glDrawArrays(GL_TRIANGLES, 0, static_cast<GLsizei>(vertices_.size()));
  pixels.resize(static_cast<size_t>(n) * n);
  glReadPixels(0, 0, static_cast<GLsizei>(n), static_cast<GLsizei>(n), GL_RED, GL_UNSIGNED_BYTE, pixels.data());
  return pixels;
}

bool GlPlanarRaster::Full(const visibility::Blockers& blockers, uint32_t n, std::span<const uint32_t> rows,
                          std::vector<uint32_t>* gap_rows) {
  const std::vector<uint8_t>& pixels = Render(blockers, n);
  gap_rows->clear();
  for (uint32_t j : rows) {
    const uint8_t* row = pixels.data() + static_cast<size_t>(j) * n;
    if (std::find(row, row + n, 0) != row + n) gap_rows->push_back(j);
  }
  return gap_rows->empty();
}

void GlPlanarRaster::Draw(const visibility::Blockers& blockers, uint32_t n, std::vector<uint8_t>* pixels) {
  const std::vector<uint8_t>& drawn = Render(blockers, n);
  pixels->resize(drawn.size());
  for (size_t k = 0; k < drawn.size(); ++k) (*pixels)[k] = drawn[k] != 0 ? 1 : 0;
}

}  // namespace vistream::gl
