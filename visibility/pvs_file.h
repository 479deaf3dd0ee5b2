#pragma once
// The PVS file: every viewcell's potentially visible set for one scene and grid, as a server
// serves them. Written by `vistream agvs -o`; decoding is strict (the bytes may come from
// anywhere) and every error names the source and the byte offset.
//
// Layout, little-endian: "VSPVS001", u32 version (2, or 3 for a grid with per-cell bands),
// scene name (varint length + bytes), u64 object count, u64 scene fingerprint
// (scenes::SceneFingerprint; versions 2 and 3), grid (f64 cell size, base z, height, corner x,
// corner y; i32 nx, ny; version 3 only: nx * ny pairs of f64 z0, z1, each cell's band in id
// order), provenance (strategy name, u64 samples, f64 seconds, f64 estimated pixel error), then per
// cell in id order: varint count, then the ascending ids as varint gaps (first id, then each
// id minus the previous one minus one). Nothing may follow. A flat grid (no bands) is written
// as version 2, byte for byte what writers before bands wrote; versions 1 to 3 are read.

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include <absl/status/statusor.h>

#include "scenes/scene.h"
#include "visibility/global_pvs.h"
#include "visibility/viewcell_grid.h"

namespace vistream::visibility {

struct PvsFile {
  std::string scene;
  uint64_t scene_fingerprint = 0;  // 0: unknown (a version 1 file)
  double cell_size = 0.0, base_z = 0.0, height = 0.0;
  double corner_x = 0.0, corner_y = 0.0;
  int32_t nx = 0, ny = 0;
  std::vector<CellBand> bands;  // per cell, in id order (version 3); empty: every cell's is base_z..base_z + height
  std::string strategy;
  uint64_t samples = 0;
  double seconds = 0.0;
  double estimated_pixel_error = 0.0;
  GlobalPvs sets;  // cells nx * ny, objects: the scene's object count

  // Whether the file was made for `grid` (same cells and bands, exactly: a flat file does not
  // match a grid that follows terrain).
  bool Matches(const ViewcellGrid& grid) const;
};

std::string EncodePvsFile(const PvsFile& file);
// Reads a file EncodePvsFile wrote; errors name `where` and the field. With `scene_objects`,
// a file made for a scene of another object count is refused before its sets are allocated
// (a header alone may otherwise ask for up to 2 GiB of sets).
absl::StatusOr<PvsFile> DecodePvsFile(std::string_view bytes, const std::string& where,
                                      std::optional<uint64_t> scene_objects = std::nullopt);

// Where a file's sets came from: the sampling strategy or the dual-ray-space backend, and
// what it took (0 where it does not apply).
struct PvsProvenance {
  std::string strategy;
  uint64_t samples = 0;
  double seconds = 0.0;
  double estimated_pixel_error = 0.0;
};

// The file for `sets` (one set per cell of `grid`, ids of `scene`'s objects).
PvsFile MakePvsFile(const scenes::Scene& scene, const ViewcellGrid& grid, GlobalPvs sets,
                    const PvsProvenance& provenance);

// OK when `file` was made for `grid` (the same cells, exactly) and for `scene` (the same
// object count and, when the file records one, the same fingerprint: the same geometry and
// occluders); else INVALID_ARGUMENT naming `where`, the file's scene and what differs.
absl::Status CheckPvsFileMatches(const PvsFile& file, const ViewcellGrid& grid, const scenes::Scene& scene,
                                 const std::string& where);

// Reads `path`, decodes it strictly and checks it against `grid` and `scene`: the one call
// that serves a precomputed file. Errors: NOT_FOUND (cannot open), DATA_LOSS / INVALID_ARGUMENT
// from decoding, INVALID_ARGUMENT for a file made for another scene or grid; each names `path`.
absl::StatusOr<PvsFile> LoadPvsFile(const std::string& path, const ViewcellGrid& grid, const scenes::Scene& scene);

// One viewcell's PVS as a shared store holds it (server/pvs_store.h; issue 33), checkable on
// its own: "VSC1", u32 cell id, u32 object count, the ascending ids as varint gaps (as in the
// file), u32 CRC-32 (zlib's) of every byte before it; little-endian, nothing may follow.
std::string EncodeCellRecord(CellId cell, std::span<const scenes::ObjectId> objects);
// Reads a record EncodeCellRecord wrote for `cell` of a scene of `scene_objects` objects.
// Errors (DATA_LOSS, naming `where` and the byte offset): wrong magic, length or checksum,
// another cell's record, ids not ascending or not below `scene_objects`, bytes after the end.
absl::StatusOr<std::vector<scenes::ObjectId>> DecodeCellRecord(std::string_view bytes, CellId cell,
                                                                uint64_t scene_objects, const std::string& where);

// The per-cell lists of `sets` as ascending varint gaps, and back (shared with the sampler's
// saved state).
class ByteWriter;
class ByteReader;
void EncodeSets(const GlobalPvs& sets, ByteWriter* out);
absl::Status DecodeSets(ByteReader* in, GlobalPvs* sets);

}  // namespace vistream::visibility
