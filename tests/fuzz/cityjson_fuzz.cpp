// libFuzzer target: the CityJSON reader on untrusted bytes, once failing on the first malformed
// object and once with keep_going. Seeds: tests/citymodel/*.city.json (.ci/run copies them).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "scenes/city_model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  vistream::scenes::CityReadOptions options;
  (void)vistream::scenes::ReadCityJsonFromMemory(bytes, "fuzz.city.json", options);
  options.keep_going = true;
  (void)vistream::scenes::ReadCityJsonFromMemory(bytes, "fuzz.city.json", options);
  return 0;
}
