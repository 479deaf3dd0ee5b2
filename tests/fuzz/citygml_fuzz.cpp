// libFuzzer target: the CityGML reader (expat pre-scan, then libcitygml) on untrusted bytes,
// with and without keep_going.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "scenes/city_model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  vistream::scenes::CityReadOptions options;
  options.keep_going = size > 0 && (data[size - 1] & 1) != 0;
  (void)vistream::scenes::ReadCityGmlFromMemory(bytes, "fuzz.gml", options);
  return 0;
}
