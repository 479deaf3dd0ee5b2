#include "visibility/pvs_file.h"

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>

#include <absl/strings/str_cat.h>
#include <zlib.h>

#include "visibility/bytes.h"

namespace vistream::visibility {

namespace {
constexpr char kMagic[8] = {'V', 'S', 'P', 'V', 'S', '0', '0', '1'};
constexpr uint32_t kVersion = 2;       // 1: without the scene fingerprint (still read)
constexpr uint32_t kBandsVersion = 3;  // version 2 with per-cell bands: written only for grids that have them
constexpr uint64_t kMaxObjects = uint64_t{1} << 32;
constexpr uint64_t kMaxCells = uint64_t{1} << 31;
}  // namespace

PvsFile MakePvsFile(const scenes::Scene& scene, const ViewcellGrid& grid, GlobalPvs sets,
                    const PvsProvenance& provenance) {
  PvsFile f;
  f.scene = scene.name;
  f.scene_fingerprint = scenes::SceneFingerprint(scene);
  f.cell_size = grid.cell_size();
  f.base_z = grid.base_z();
  f.height = grid.height();
  f.corner_x = grid.corner().x;
  f.corner_y = grid.corner().y;
  f.nx = grid.nx();
  f.ny = grid.ny();
  f.bands = grid.bands();
  f.strategy = provenance.strategy;
  f.samples = provenance.samples;
  f.seconds = provenance.seconds;
  f.estimated_pixel_error = provenance.estimated_pixel_error;
  f.sets = std::move(sets);
  return f;
}

absl::Status CheckPvsFileMatches(const PvsFile& file, const ViewcellGrid& grid, const scenes::Scene& scene,
                                 const std::string& where) {
  const size_t object_count = scene.objects.size();
  if (!file.Matches(grid)) {
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": made for another scene or viewcell grid (the file: scene '", file.scene, "', ", file.nx, " x ", file.ny, " cells of ",
        file.cell_size, " m at z ", file.base_z, "..", file.base_z + file.height,
        file.bands.empty() ? "" : " above the ground (bands following terrain)", "; this scene's grid: ", grid.nx(),
        " x ", grid.ny(), " cells of ", grid.cell_size(), " m at z ", grid.base_z(), "..",
        grid.base_z() + grid.height(), grid.has_bands() ? " above the ground (bands following terrain)" : "", ")"));
  }
  if (file.sets.object_count() != object_count) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": made for another scene ('", file.scene, "', ",
                                                   file.sets.object_count(), " objects; this scene has ",
                                                   object_count, ")"));
  }
  if (file.scene_fingerprint != 0 && file.scene_fingerprint != scenes::SceneFingerprint(scene)) {
    return absl::InvalidArgumentError(absl::StrCat(
        where, ": made for another scene ('", file.scene, "' with other geometry or occluders than this '", scene.name,
        "', though with as many objects): its sets would hide what this scene shows"));
  }
  return absl::OkStatus();
}

absl::StatusOr<PvsFile> LoadPvsFile(const std::string& path, const ViewcellGrid& grid, const scenes::Scene& scene) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) return absl::InvalidArgumentError(path + ": is a directory, not a PVS file");
  std::ifstream in(path, std::ios::binary);
  if (!in) return absl::NotFoundError(absl::StrCat("cannot open PVS file '", path, "'"));
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) return absl::DataLossError(absl::StrCat("cannot read PVS file '", path, "'"));
  absl::StatusOr<PvsFile> f = DecodePvsFile(bytes, path, scene.objects.size());
  if (!f.ok()) return f.status();
  if (absl::Status st = CheckPvsFileMatches(*f, grid, scene, path); !st.ok()) return st;
  return f;
}

bool PvsFile::Matches(const ViewcellGrid& grid) const {
  return nx == grid.nx() && ny == grid.ny() && cell_size == grid.cell_size() && base_z == grid.base_z() &&
         height == grid.height() && corner_x == grid.corner().x && corner_y == grid.corner().y &&
         bands == grid.bands();
}

void EncodeSets(const GlobalPvs& sets, ByteWriter* out) {
  for (CellId c = 0; c < sets.cell_count(); ++c) {
    const std::vector<scenes::ObjectId> ids = sets.Objects(c);
    out->PutVarint(ids.size());
    uint64_t next = 0;  // the smallest id the next one may be
    for (scenes::ObjectId id : ids) {
      out->PutVarint(id - next);
      next = uint64_t{id} + 1;
    }
  }
}

absl::Status DecodeSets(ByteReader* in, GlobalPvs* sets) {
  std::vector<scenes::ObjectId> ids;
  for (CellId c = 0; c < sets->cell_count(); ++c) {
    uint64_t count = 0;
    if (absl::Status st = in->GetVarint(&count, absl::StrCat("cell ", c, " count")); !st.ok()) return st;
    if (count > sets->object_count()) {
      return in->Error(absl::StrCat("cell ", c, " lists ", count, " objects, but the scene has ", sets->object_count()));
    }
    ids.clear();
    uint64_t next = 0;
    for (uint64_t k = 0; k < count; ++k) {
      uint64_t gap = 0;
      if (absl::Status st = in->GetVarint(&gap, absl::StrCat("cell ", c, " id ", k)); !st.ok()) return st;
      const uint64_t id = next + gap;
      if (gap >= sets->object_count() || id >= sets->object_count()) {
        return in->Error(absl::StrCat("cell ", c, " id ", k, " is past the scene's ", sets->object_count(), " objects"));
      }
      ids.push_back(static_cast<scenes::ObjectId>(id));
      next = id + 1;
    }
    sets->Assign(c, ids);
  }
  return absl::OkStatus();
}

namespace {
constexpr char kCellMagic[4] = {'V', 'S', 'C', '1'};

uint32_t Crc32(std::string_view bytes) {
  return static_cast<uint32_t>(::crc32(0L, reinterpret_cast<const Bytef*>(bytes.data()), static_cast<uInt>(bytes.size())));
}
}  // namespace

std::string EncodeCellRecord(CellId cell, std::span<const scenes::ObjectId> objects) {
  ByteWriter w;
  w.PutRaw(std::string_view(kCellMagic, sizeof(kCellMagic)));
  w.Put<uint32_t>(cell);
  w.Put<uint32_t>(static_cast<uint32_t>(objects.size()));
  uint64_t next = 0;
  for (scenes::ObjectId id : objects) {
    w.PutVarint(id - next);
    next = uint64_t{id} + 1;
  }
  w.Put<uint32_t>(Crc32(w.bytes()));
  return std::move(w.bytes());
}

absl::StatusOr<std::vector<scenes::ObjectId>> DecodeCellRecord(std::string_view bytes, CellId cell,
                                                                uint64_t scene_objects, const std::string& where) {
  auto loss = [](const absl::Status& st) { return absl::DataLossError(st.message()); };
  ByteReader r(bytes, where);
  constexpr size_t kMin = sizeof(kCellMagic) + 3 * sizeof(uint32_t);
  if (bytes.size() < kMin) return loss(r.Error(absl::StrCat("a record of ", bytes.size(), " bytes (at least ", kMin, ")")));
  if (bytes.substr(0, sizeof(kCellMagic)) != std::string_view(kCellMagic, sizeof(kCellMagic))) {
    return loss(r.Error("not a viewcell PVS record (no VSC1 magic)"));
  }
  uint32_t stored_crc = 0;
  std::memcpy(&stored_crc, bytes.data() + bytes.size() - sizeof(uint32_t), sizeof(uint32_t));
  const std::string_view body = bytes.substr(0, bytes.size() - sizeof(uint32_t));
  if (Crc32(body) != stored_crc) return loss(r.Error("checksum mismatch"));
  ByteReader in(body, where);
  char magic[sizeof(kCellMagic)];
  for (char& ch : magic) (void)in.Get(&ch, "the magic");
  uint32_t got_cell = 0, count = 0;
  if (absl::Status st = in.Get(&got_cell, "the cell"); !st.ok()) return loss(st);
  if (absl::Status st = in.Get(&count, "the count"); !st.ok()) return loss(st);
  if (got_cell != cell) return loss(in.Error(absl::StrCat("the record of cell ", got_cell, ", not of cell ", cell)));
  if (count > scene_objects || count > in.remaining()) {
    return loss(in.Error(absl::StrCat(count, " objects listed; the scene has ", scene_objects)));
  }
  std::vector<scenes::ObjectId> ids;
  ids.reserve(count);
  uint64_t next = 0;
  for (uint32_t k = 0; k < count; ++k) {
    uint64_t gap = 0;
    if (absl::Status st = in.GetVarint(&gap, absl::StrCat("id ", k)); !st.ok()) return loss(st);
    if (gap >= scene_objects || next + gap >= scene_objects) {
      return loss(in.Error(absl::StrCat("id ", k, " is past the scene's ", scene_objects, " objects")));
    }
    ids.push_back(static_cast<scenes::ObjectId>(next + gap));
    next = next + gap + 1;
  }
  if (!in.AtEnd()) return loss(in.Error(absl::StrCat(in.remaining(), " bytes after the last id")));
  return ids;
}

std::string EncodePvsFile(const PvsFile& f) {
  ByteWriter w;
  w.PutRaw(std::string_view(kMagic, sizeof(kMagic)));
  w.Put<uint32_t>(f.bands.empty() ? kVersion : kBandsVersion);
  w.PutString(f.scene);
  w.Put(static_cast<uint64_t>(f.sets.object_count()), uint64_t{f.scene_fingerprint}, f.cell_size, f.base_z, f.height,
        f.corner_x, f.corner_y, f.nx, f.ny);
  for (const CellBand& b : f.bands) w.Put(b.z0, b.z1);
  w.PutString(f.strategy);
  w.Put(f.samples, f.seconds, f.estimated_pixel_error);
  EncodeSets(f.sets, &w);
  return std::move(w.bytes());
}

absl::StatusOr<PvsFile> DecodePvsFile(std::string_view bytes, const std::string& where,
                                      std::optional<uint64_t> scene_objects) {
  ByteReader r(bytes, where);
  PvsFile f;
  if (absl::Status st = r.ExpectMagic(std::string_view(kMagic, sizeof(kMagic)), "PVS file"); !st.ok()) return st;
  uint32_t version = 0;
  if (absl::Status st = r.Get(&version, "the version"); !st.ok()) return st;
  if (version != 1 && version != kVersion && version != kBandsVersion) {
    return r.Error(absl::StrCat("version ", version, " is not supported (1 to ", kBandsVersion, ")"));
  }
  uint64_t objects = 0;
  absl::Status st = r.GetString(&f.scene, "the scene name", 4096);
  if (st.ok()) st = r.Get(&objects, "the object count");
  if (st.ok() && objects > kMaxObjects) st = r.Error(absl::StrCat("object count ", objects, " is too large"));
  if (st.ok() && version >= 2) st = r.Get(&f.scene_fingerprint, "the scene fingerprint");
  if (st.ok()) {
    st = r.Get(&f.cell_size, "the cell size", &f.base_z, "the base z", &f.height, "the height", &f.corner_x,
               "the corner x", &f.corner_y, "the corner y", &f.nx, "nx", &f.ny, "ny");
  }
  if (!st.ok()) return st;
  if (!(std::isfinite(f.cell_size) && f.cell_size > 0 && std::isfinite(f.height) && f.height > 0 &&
        std::isfinite(f.base_z) && std::isfinite(f.corner_x) && std::isfinite(f.corner_y))) {
    return r.Error("the grid has a non-finite or non-positive size");
  }
  if (f.nx <= 0 || f.ny <= 0 || static_cast<uint64_t>(f.nx) * static_cast<uint64_t>(f.ny) > kMaxCells) {
    return r.Error(absl::StrCat("grid of ", f.nx, " x ", f.ny, " cells is empty or too large"));
  }
  const uint64_t cells = static_cast<uint64_t>(f.nx) * static_cast<uint64_t>(f.ny);
  if (version == kBandsVersion) {
    // 16 bytes a band: refuse what the remaining bytes cannot hold before allocating them.
    if (cells > r.remaining() / 16) return r.Error(absl::StrCat("too few bytes left for ", cells, " cells' bands"));
    f.bands.resize(cells);
    for (uint64_t c = 0; c < cells; ++c) {
      CellBand& b = f.bands[c];
      if (st = r.Get(&b.z0, "the bands", &b.z1, "the bands"); !st.ok()) return st;
      if (!(std::isfinite(b.z0) && std::isfinite(b.z1) && b.z0 < b.z1)) {
        return r.Error(absl::StrCat("cell ", c, "'s band [", b.z0, ", ", b.z1, "] is empty or not finite"));
      }
    }
  }
  st = r.GetString(&f.strategy, "the strategy", 64);
  if (st.ok()) {
    st = r.Get(&f.samples, "the sample count", &f.seconds, "the seconds", &f.estimated_pixel_error,
               "the estimated pixel error");
  }
  if (!st.ok()) return st;
  // Every cell takes at least one byte: refuse what the remaining bytes cannot hold before
  // allocating the sets.
  if (cells > r.remaining()) return r.Error(absl::StrCat("too few bytes left for ", cells, " cells"));
  if (scene_objects && objects != *scene_objects) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": made for another scene ('", f.scene, "', ", objects,
                                                   " objects; this scene has ", *scene_objects, ")"));
  }
  if (cells * ((objects + 63) / 64) > (uint64_t{1} << 28)) {
    return r.Error(absl::StrCat(cells, " cells of ", objects, " objects would need more than 2 GiB of sets"));
  }
  f.sets = GlobalPvs(cells, objects);
  if (st = DecodeSets(&r, &f.sets); !st.ok()) return st;
  if (!r.AtEnd()) return r.Error(absl::StrCat(r.remaining(), " bytes follow the last cell"));
  return f;
}

}  // namespace vistream::visibility
