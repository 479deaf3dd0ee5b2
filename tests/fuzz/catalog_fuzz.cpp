// libFuzzer target: the scene catalog parser on untrusted JSON.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "scenes/catalog.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  (void)vistream::scenes::ParseCatalogEntry(text, "fuzz.json", "/nonexistent");
  return 0;
}
