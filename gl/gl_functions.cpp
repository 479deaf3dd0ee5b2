#include "gl/gl_functions.h"

#include <absl/strings/str_cat.h>

namespace vistream::gl {

absl::StatusOr<GlFunctions> GlFunctions::Load(void* (*loader)(const char*)) {
  GlFunctions f;
#define VISTREAM_GL_LOAD(name)                                                                     \
  f.name = reinterpret_cast<decltype(f.name)>(loader("gl" #name));                                 \
  if (f.name == nullptr) return absl::UnavailableError(absl::StrCat("the OpenGL context has no gl", #name));
  VISTREAM_GL_FUNCTIONS(VISTREAM_GL_LOAD)
#undef VISTREAM_GL_LOAD
  return f;
}

const GlFunctions& GlFunctions::Linked() {
  static const GlFunctions f = [] {
    GlFunctions out;
#define VISTREAM_GL_LINKED(name) out.name = &::gl##name;
    VISTREAM_GL_FUNCTIONS(VISTREAM_GL_LINKED)
#undef VISTREAM_GL_LINKED
    return out;
  }();
  return f;
}

}  // namespace vistream::gl
