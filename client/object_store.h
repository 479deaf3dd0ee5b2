#pragma once
// The client's local copy of what the server streamed (DESIGN.md "Server and client"): decoded
// objects within a memory budget, the PVS list of each viewcell it was sent, and the latest
// ε-mask. The render loop owns it and feeds it the connection's events; nothing here waits.
//
// Memory: the server keeps the client within Hello.memory_budget_bytes by the same accounting
// (24 bytes a vertex, 4 an index) and sends Evict hints for objects outside the current and
// adjacent PVSs; the store obeys them. Should it still be over budget, it evicts on its own:
// objects outside the current and adjacent PVSs first (least recently drawn first), then
// objects of adjacent cells only; never the current cell's.

#include <cstdint>
#include <map>
#include <optional>
#include <set>
#include <unordered_map>
#include <vector>

#include <glm/vec3.hpp>

#include "client/connection.h"
#include "proto/walkthrough.pb.h"

namespace vistream::client {

// The viewcell grid as SceneInfo describes it (scene-local metres).
struct GridInfo {
  double cell_size = 0.0, x0 = 0.0, y0 = 0.0, base_z = 0.0, height = 0.0;
  int nx = 0, ny = 0;

  static GridInfo From(const vistream::v1::ViewcellGrid& g);
  // The cell whose ground square holds (x, y), as the server decides it (points on a shared
  // edge belong to the cell above and to the right); none outside the grid.
  std::optional<uint32_t> CellAt(double x, double y) const;
  // The cell itself and its up to eight neighbours.
  std::vector<uint32_t> Neighbourhood(uint32_t cell) const;
  // Whether an eye height is inside the band the PVSs hold for.
  bool InBand(double z) const { return z >= base_z && z <= base_z + height; }
};

// Whether bit `t` of a mask's little-endian triangle bits is set (false past its end).
inline bool TriangleVisible(const std::vector<uint8_t>& bits, size_t t) {
  return t / 8 < bits.size() && ((bits[t / 8] >> (t % 8)) & 1u) != 0;
}

// An ε-mask decoded: per object, which triangles may be seen from anywhere in the box.
struct EpsilonMaskSet {
  glm::dvec3 box_min{0.0}, box_max{0.0};
  uint64_t generation = 0;  // increases with every mask received
  std::unordered_map<uint32_t, std::vector<uint8_t>> visible;  // bit t of object's triangle t

  bool Contains(const glm::dvec3& p) const {
    return p.x >= box_min.x && p.x <= box_max.x && p.y >= box_min.y && p.y <= box_max.y && p.z >= box_min.z &&
           p.z <= box_max.z;
  }
};

struct StoredObject {
  ReceivedObject data;
  uint64_t last_drawn_frame = 0;
};

class ObjectStore {
 public:
  explicit ObjectStore(uint64_t memory_budget_bytes) : budget_(memory_budget_bytes) {}

  // Applies the connection's events in order. Returns the ids the store evicted on its own to
  // stay within budget (tell the connection with Forget).
  std::vector<uint32_t> Apply(std::vector<Event> events, std::optional<uint32_t> current_cell);

  bool has_scene_info() const { return scene_info_.has_value(); }
  const vistream::v1::SceneInfo& scene_info() const { return *scene_info_; }
  const GridInfo& grid() const { return grid_; }

  const StoredObject* Find(uint32_t id) const;
  StoredObject* Find(uint32_t id);
  const std::unordered_map<uint32_t, StoredObject>& objects() const { return objects_; }
  // The latest PVS list of `cell`, if the server sent one.
  const std::vector<uint32_t>* Pvs(uint32_t cell) const;
  // Every PVS list held, by cell.
  const std::map<uint32_t, std::vector<uint32_t>>& pvs_lists() const { return pvs_; }
  // Whether `cell`'s PVS list and every object on it are held.
  bool CellComplete(uint32_t cell) const;
  const std::optional<EpsilonMaskSet>& mask() const { return mask_; }

  // Ids removed since the last call (by Evict hints, budget, or replaced): the renderer frees
  // their GPU buffers.
  std::vector<uint32_t> TakeRemoved();
  // Ids stored since the last call: the renderer uploads them.
  std::vector<uint32_t> TakeAdded();

  uint64_t held_bytes() const { return held_bytes_; }
  uint64_t max_held_bytes() const { return max_held_bytes_; }
  uint64_t budget() const { return budget_; }
  uint64_t evicted_by_server() const { return evicted_by_server_; }
  uint64_t evicted_by_budget() const { return evicted_by_budget_; }
  std::optional<std::string> failure() const { return failure_; }

 private:
  void Remove(uint32_t id);
  std::vector<uint32_t> EnforceBudget(std::optional<uint32_t> current_cell);

  uint64_t budget_;
  std::optional<vistream::v1::SceneInfo> scene_info_;
  GridInfo grid_;
  std::unordered_map<uint32_t, StoredObject> objects_;
  std::map<uint32_t, std::vector<uint32_t>> pvs_;
  std::optional<EpsilonMaskSet> mask_;
  uint64_t mask_generation_ = 0;
  std::vector<uint32_t> removed_, added_;
  uint64_t held_bytes_ = 0, max_held_bytes_ = 0;
  uint64_t evicted_by_server_ = 0, evicted_by_budget_ = 0;
  std::optional<std::string> failure_;
};

}  // namespace vistream::client
