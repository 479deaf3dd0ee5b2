#include "gl/gl_context.h"

#include <vector>

#include <GL/osmesa.h>
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"

namespace vistream::gl {

struct GlContext::Impl {
  OSMesaContext context = nullptr;
  GLFWwindow* window = nullptr;  // a window context instead
  GlFunctions functions;
  // OSMesa wants a colour buffer to make a context current; drawing goes to framebuffer
  // objects, so one pixel is enough.
  std::vector<unsigned char> pixel = std::vector<unsigned char>(4);
};

GlContext::GlContext(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

GlContext::~GlContext() {
  if (impl_ == nullptr) return;
  if (impl_->context != nullptr) OSMesaDestroyContext(impl_->context);
  if (impl_->window != nullptr) {
    glfwDestroyWindow(impl_->window);
    glfwTerminate();
  }
}

namespace {
std::string& GlfwError() {
  static thread_local std::string error;
  return error;
}
void OnGlfwError(int /*code*/, const char* description) { GlfwError() = description; }
}  // namespace

absl::StatusOr<std::unique_ptr<GlContext>> GlContext::CreateWindowed(int width, int height, const std::string& title,
                                                                     bool vsync) {
  glfwSetErrorCallback(OnGlfwError);
  if (!glfwInit()) {
    return absl::UnavailableError(absl::StrCat("cannot open a window: ", GlfwError(),
                                               " (run with --headless, or under a display, e.g. xvfb-run)"));
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_SAMPLES, 0);
  glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
  GLFWwindow* window = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (window == nullptr) {
    const std::string why = GlfwError();
    glfwTerminate();
    return absl::UnavailableError(absl::StrCat("cannot open an OpenGL 3.3 core window: ", why));
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(vsync ? 1 : 0);
  auto impl = std::make_unique<Impl>();
  impl->window = window;
  absl::StatusOr<GlFunctions> f =
      GlFunctions::Load([](const char* name) { return reinterpret_cast<void*>(glfwGetProcAddress(name)); });
  if (!f.ok()) {
    glfwDestroyWindow(window);
    glfwTerminate();
    return f.status();
  }
  impl->functions = *f;
  return std::unique_ptr<GlContext>(new GlContext(std::move(impl)));
}

const GlFunctions& GlContext::functions() const { return impl_->functions; }

void* GlContext::window() const { return impl_->window; }

void GlContext::SwapBuffers() {
  if (impl_->window != nullptr) glfwSwapBuffers(impl_->window);
}

void GlContext::FramebufferSize(int* width, int* height) const {
  *width = *height = 0;
  if (impl_->window != nullptr) glfwGetFramebufferSize(impl_->window, width, height);
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
  impl->functions = GlFunctions::Linked();
  auto context = std::unique_ptr<GlContext>(new GlContext(std::move(impl)));
  if (absl::Status s = context->MakeCurrent(); !s.ok()) return s;
  return context;
}

void* GlContext::ProcAddress(const char* name) { return reinterpret_cast<void*>(OSMesaGetProcAddress(name)); }

absl::Status GlContext::MakeCurrent() {
  if (impl_->window != nullptr) {
    // Released first: GLX skips making current a context it thinks is current already, but
    // an OSMesa context made current since (the id renderer of --verify) took the GL dispatch
    // both share (libglapi), and the window's calls would reach it.
    glfwMakeContextCurrent(nullptr);
    glfwMakeContextCurrent(impl_->window);
    return absl::OkStatus();
  }
  if (!OSMesaMakeCurrent(impl_->context, impl_->pixel.data(), GL_UNSIGNED_BYTE, 1, 1)) {
    return absl::InternalError("OSMesaMakeCurrent failed");
  }
  return absl::OkStatus();
}

}  // namespace vistream::gl
