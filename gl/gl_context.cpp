#include "gl/gl_context.h"

#include <vector>

#include <GL/osmesa.h>

#include "absl/status/status.h"

namespace vistream::gl {

struct GlContext::Impl {
  OSMesaContext context = nullptr;
  // OSMesa wants a colour buffer to make a context current; drawing goes to framebuffer
  // objects, so one pixel is enough.
  std::vector<unsigned char> pixel = std::vector<unsigned char>(4);
};

GlContext::GlContext(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

GlContext::~GlContext() {
  if (impl_ != nullptr && impl_->context != nullptr) OSMesaDestroyContext(impl_->context);
}

absl::StatusOr<std::unique_ptr<GlContext>> GlContext::CreateOffscreen() {
  const int attribs[] = {OSMESA_FORMAT, OSMESA_RGBA, OSMESA_DEPTH_BITS, 0, OSMESA_STENCIL_BITS, 0,
                         OSMESA_ACCUM_BITS, 0, OSMESA_PROFILE, OSMESA_CORE_PROFILE,
                         OSMESA_CONTEXT_MAJOR_VERSION, 4, OSMESA_CONTEXT_MINOR_VERSION, 5, 0};
  auto impl = std::make_unique<Impl>();
  impl->context = OSMesaCreateContextAttribs(attribs, nullptr);
  if (impl->context == nullptr) {
    return absl::UnavailableError("OSMesa could not create an OpenGL 4.5 core context");
  }
  auto context = std::unique_ptr<GlContext>(new GlContext(std::move(impl)));
  if (absl::Status s = context->MakeCurrent(); !s.ok()) return s;
  return context;
}

void* GlContext::ProcAddress(const char* name) { return reinterpret_cast<void*>(OSMesaGetProcAddress(name)); }

absl::Status GlContext::MakeCurrent() {
  if (!OSMesaMakeCurrent(impl_->context, impl_->pixel.data(), GL_UNSIGNED_BYTE, 1, 1)) {
    return absl::InternalError("OSMesaMakeCurrent failed");
  }
  return absl::OkStatus();
}

}  // namespace vistream::gl
