#include "gl/shader.h"

#include <array>
#include <string>

#include <absl/strings/str_cat.h>

namespace vistream::gl {

namespace {

absl::StatusOr<GLuint> Compile(const GlFunctions& gl, GLenum type, const char* source, const char* what) {
  const GLuint shader = gl.CreateShader(type);
  gl.ShaderSource(shader, 1, &source, nullptr);
  gl.CompileShader(shader);
  GLint ok = 0;
  gl.GetShaderiv(shader, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    std::array<char, 4096> log{};
    gl.GetShaderInfoLog(shader, log.size(), nullptr, log.data());
    gl.DeleteShader(shader);
    return absl::InternalError(absl::StrCat(what, " ", type == GL_VERTEX_SHADER ? "vertex" : "fragment",
                                            " shader does not compile: ", log.data()));
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
  GLint ok = 0;
  gl.GetProgramiv(program, GL_LINK_STATUS, &ok);
  if (!ok) {
    std::array<char, 4096> log{};
    gl.GetProgramInfoLog(program, log.size(), nullptr, log.data());
    gl.DeleteProgram(program);
    return absl::InternalError(absl::StrCat(what, " program does not link: ", log.data()));
  }
  return program;
}

}  // namespace vistream::gl
