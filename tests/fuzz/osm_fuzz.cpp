// libFuzzer target: the OpenStreetMap importer on untrusted files. The first byte picks the
// format (even: XML, odd: PBF); the rest is the file. With VISTREAM_FUZZ_SEED_DIR=DIR it first
// writes there each tests/osm/*.osm file as PBF (libosmium's writer, behind a leading 1), the
// PBF seeds CI starts from beside the XML ones.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include <osmium/io/pbf_output.hpp>
#include <osmium/io/reader.hpp>
#include <osmium/io/writer.hpp>
#include <osmium/io/xml_input.hpp>

#include "scenes/osm_import.h"
#include "scenes/progress.h"

namespace {

void WritePbfSeeds(const std::filesystem::path& dir) {
  const std::filesystem::path osm = std::filesystem::path(VISTREAM_SOURCE_DIR) / "tests" / "osm";
  for (const auto& entry : std::filesystem::directory_iterator(osm)) {
    if (entry.path().extension() != ".osm" || std::filesystem::file_size(entry.path()) == 0) continue;
    const std::filesystem::path pbf = dir / (entry.path().stem().string() + ".osm.pbf");
    {
      osmium::io::Reader reader(entry.path().string());
      osmium::io::Writer writer(osmium::io::File(pbf.string(), "pbf"), reader.header(), osmium::io::overwrite::allow);
      while (osmium::memory::Buffer buffer = reader.read()) writer(std::move(buffer));
      writer.close();
      reader.close();
    }
    std::ifstream in(pbf, std::ios::binary);
    const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(dir / (entry.path().stem().string() + ".pbf-seed"), std::ios::binary) << '\x01' << bytes;
    std::filesystem::remove(pbf);
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("VISTREAM_FUZZ_SEED_DIR")) WritePbfSeeds(dir);
  return 0;
}

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
