// libFuzzer target: the PVS-file decoder (vistream-server --pvs-file, agvs heatmap --pvs) and
// the store's viewcell record decoder on untrusted bytes. With VISTREAM_FUZZ_SEED_DIR=DIR it first writes a valid file there (a small
// grid with a few sets), the seed CI starts from.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

#include "visibility/pvs_file.h"

namespace {

std::string SeedFile() {
  vistream::visibility::PvsFile f;
  f.scene = "seed";
  f.scene_fingerprint = 0x1234;
  f.cell_size = 10.0;
  f.base_z = 0.5;
  f.height = 2.0;
  f.nx = 3;
  f.ny = 2;
  f.strategy = "agvs";
  f.samples = 65536;
  f.seconds = 1.5;
  f.estimated_pixel_error = 0.25;
  f.sets = vistream::visibility::GlobalPvs(6, 70);
  for (uint32_t cell = 0; cell < 6; ++cell) {
    for (uint32_t object = cell; object < 70; object += 7 + cell) f.sets.Insert(cell, object);
  }
  return vistream::visibility::EncodePvsFile(f);
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  if (const char* dir = std::getenv("VISTREAM_FUZZ_SEED_DIR")) {
    std::ofstream(std::string(dir) + "/seed", std::ios::binary) << SeedFile();
    std::ofstream(std::string(dir) + "/seed_record", std::ios::binary)
        << vistream::visibility::EncodeCellRecord(3, std::vector<uint32_t>{0, 5, 6, 69});
  }
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  // As LoadPvsFile reads it: for a scene of the seed's object count (a file for another is
  // refused before its sets are allocated).
  (void)vistream::visibility::DecodePvsFile(bytes, "fuzz.pvs", 70);
  // The same bytes as one viewcell's record from the shared PVS store (server/pvs_store.h),
  // for a scene of 70 objects: a record is checked before any of it is used.
  (void)vistream::visibility::DecodeCellRecord(bytes, 3, 70, "fuzz:key:3");
  return 0;
}
