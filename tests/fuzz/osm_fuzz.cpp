// libFuzzer target: the OpenStreetMap importer on untrusted files. The first byte picks the
// format (even: XML, odd: PBF); the rest is the file.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

#include "scenes/osm_import.h"
#include "scenes/progress.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string path = "/tmp/vistream-osm-fuzz-" + std::to_string(getpid()) +
                           ((data[0] & 1) != 0 ? ".osm.pbf" : ".osm");
  if (FILE* f = std::fopen(path.c_str(), "wb")) {
    std::fwrite(data + 1, 1, size - 1, f);
    std::fclose(f);
    (void)vistream::scenes::ImportOsm(path, {});
    std::remove(path.c_str());
  }
  return 0;
}
