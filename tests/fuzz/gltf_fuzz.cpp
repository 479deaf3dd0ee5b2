// libFuzzer target: the glTF loader on untrusted bytes, as .glb and as .gltf.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "scenes/gltf_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  // No base folder: external URIs are refused, the fuzzer never reads the file system.
  (void)vistream::scenes::LoadGltfFromMemory(bytes, /*binary=*/true, "fuzz.glb");
  (void)vistream::scenes::LoadGltfFromMemory(bytes, /*binary=*/false, "fuzz.gltf");
  return 0;
}
