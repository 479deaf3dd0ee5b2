#include "gl/shader.h"

#include <array>
#include <optional>
#include <string>

#include <absl/strings/str_cat.h>

namespace vistream::gl {

namespace {

// The info log of a shader or program whose `status` (GL_COMPILE_STATUS, GL_LINK_STATUS) is
// false, after deleting it; nullopt when it compiled or linked. The shader's and the program's
// entry points (get_iv, get_log, destroy) have the same signatures.
template <typename GetIv, typename GetLog, typename Destroy>
std::optional<std::string> FailureLog(GLuint object, GLenum status, GetIv get_iv, GetLog get_log, Destroy destroy) {
  GLint ok = 0;
  get_iv(object, status, &ok);
  if (ok) return std::nullopt;
  std::array<char, 4096> log{};
  get_log(object, log.size(), nullptr, log.data());
  destroy(object);
  return std::string(log.data());
}

absl::StatusOr<GLuint> Compile(const GlFunctions& gl, GLenum type, const char* source, const char* what) {
  const GLuint shader = gl.CreateShader(type);
  gl.ShaderSource(shader, 1, &source, nullptr);
  gl.CompileShader(shader);
  if (std::optional<std::string> log =
          FailureLog(shader, GL_COMPILE_STATUS, gl.GetShaderiv, gl.GetShaderInfoLog, gl.DeleteShader)) {
    return absl::InternalError(absl::StrCat(what, " ", type == GL_VERTEX_SHADER ? "vertex" : "fragment",
                                            " shader does not compile: ", *log));
  }
  return shader;
}

}  // namespace

absl::StatusOr<GLuint> LinkProgram(const GlFunctions& gl, const char* vertex, const char* fragment, const char* what) {
  absl::StatusOr<GLuint> vs = Compile(gl, GL_VERTEX_SHADER, vertex, what);
  if (!vs.ok()) return vs.status();
  absl::StatusOr<GLuint> fs = Compile(gl, GL_FRAGMENT_SHADER, fragment, what);
  if (!fs.ok()) {
    gl.DeleteShader(*vs);
    return fs.status();
  }
  const GLuint program = gl.CreateProgram();
  gl.AttachShader(program, *vs);
  gl.AttachShader(program, *fs);
  gl.LinkProgram(program);
  gl.DeleteShader(*vs);
  gl.DeleteShader(*fs);
  if (std::optional<std::string> log =
          FailureLog(program, GL_LINK_STATUS, gl.GetProgramiv, gl.GetProgramInfoLog, gl.DeleteProgram)) {
    return absl::InternalError(absl::StrCat(what, " program does not link: ", *log));
  }
  return program;
}

}  // namespace vistream::gl
