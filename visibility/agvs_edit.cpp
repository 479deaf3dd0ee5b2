#include "visibility/agvs.h"
#include "visibility/agvs_internal.h"

// Filters over the sampled sets and dynamic edits (delete, insert, move objects).

namespace vistream::visibility {

// --- Filters ---

std::vector<scenes::ObjectId> GlobalSampler::Filtered(CellId cell, const FilterOptions& filter) const {
  const Impl& m = *impl_;
  std::vector<ObjectId> base = pvs_.Objects(cell);
  if (!filter.object_space && !filter.view_space) return base;
  std::vector<bool> in(pvs_.object_count(), false);
  for (ObjectId o : base) in[o] = true;
  std::vector<ObjectId> out = base;
  if (filter.view_space) {
    for (CellId n : grid_.Neighbours(cell)) {
      const std::vector<ObjectId> theirs = pvs_.Objects(n);
      size_t common = 0;
      for (ObjectId o : theirs) common += in[o];
      const size_t uni = base.size() + theirs.size() - common;
      if (uni == 0 || static_cast<double>(common) / static_cast<double>(uni) < filter.view_similarity) continue;
      for (ObjectId o : theirs) {
        if (!in[o] && m.objects[o].alive) {
          in[o] = true;
          out.push_back(o);
        }
      }
    }
  }
  if (filter.object_space && !base.empty()) {
    Aabb cell_box = grid_.CellBox(cell);
    cell_box.min -= m.frame;
    cell_box.max -= m.frame;
    const double n_v = static_cast<double>(std::max<uint64_t>(m.cell_samples[cell], 1));
    std::vector<int32_t> stack;
    for (ObjectId o : base) {
      const Impl::Object& obj = m.objects[o];
      const double e_g = 2.0 * BoxDistance(cell_box, obj.bounds) / std::sqrt(n_v);
      const double e_l = obj.radius / std::sqrt(static_cast<double>(std::max<uint64_t>(m.object_hits[o], 1)));
      const double e = filter.k * std::min(e_g, e_l);
      Aabb grown = obj.bounds;
      grown.min -= glm::dvec3(e);
      grown.max += glm::dvec3(e);
      if (m.tree.empty()) continue;
      stack.assign(1, 0);
      while (!stack.empty()) {
        const KdNode& node = m.tree.nodes()[stack.back()];
        stack.pop_back();
        if (!node.bounds.Overlaps(grown)) continue;
        if (!node.IsLeaf()) {
          stack.push_back(node.left);
          stack.push_back(node.right);
          continue;
        }
        for (ObjectId q : m.tree.LeafObjects(node)) {
          if (!in[q] && m.objects[q].bounds.Overlaps(grown)) {
            in[q] = true;
            out.push_back(q);
          }
        }
      }
    }
  }
  std::sort(out.begin(), out.end());
  return out;
}

GlobalPvs GlobalSampler::FilteredAll(const FilterOptions& filter) const {
  if (!filter.object_space && !filter.view_space) return pvs_;
  GlobalPvs out(pvs_.cell_count(), pvs_.object_count());
  for (CellId c = 0; c < pvs_.cell_count(); ++c) out.Assign(c, Filtered(c, filter));
  return out;
}

// --- Dynamic edits ---

namespace {
void EraseWitness(std::unordered_map<uint64_t, Witness>* w, CellId c, ObjectId o) {
  w->erase(uint64_t{c} << 32 | o);
}
}  // namespace

absl::Status GlobalSampler::DeleteObject(scenes::ObjectId id) {
  Impl& m = *impl_;
  if (id >= m.objects.size() || !m.objects[id].alive) {
    return absl::NotFoundError(absl::StrCat("delete: no object ", id));
  }
  if (!m.objects[id].indices.empty()) {
    rtcDetachGeometry(m.rtc, id);
    m.dirty = true;
  }
  Impl::ReleaseAlone(&m.objects[id]);
  m.objects[id].alive = false;
  for (CellId c = 0; c < pvs_.cell_count(); ++c) {
    if (pvs_.Contains(c, id)) {
      pvs_.Erase(c, id);
      EraseWitness(&m.witnesses, c, id);
      --stats_.entries;
    }
  }
  m.buffer.Forget(id);
  m.Rebuild();
  m.Commit();
  return absl::OkStatus();
}

namespace {
// Removes from every cell's set what `id` may now hide there.
void RemovePenumbra(GlobalSampler::Impl& m, const ViewcellGrid& grid, GlobalPvs* pvs, AgvsStats* stats, ObjectId id) {
  const Aabb& blocker = m.objects[id].bounds;
  for (CellId c = 0; c < pvs->cell_count(); ++c) {
    Aabb cell = grid.CellBox(c);
    cell.min -= m.frame;
    cell.max -= m.frame;
    for (ObjectId o : pvs->Objects(c)) {
      if (o == id || !BoxMeetsShaft(cell, m.objects[o].bounds, blocker)) continue;
      pvs->Erase(c, o);
      m.witnesses.erase(uint64_t{c} << 32 | o);
      --stats->entries;
    }
  }
}
}  // namespace

absl::StatusOr<scenes::ObjectId> GlobalSampler::InsertObject(const scenes::Mesh& mesh) {
  Impl& m = *impl_;
  Impl::Object o;
  if (mesh.indices.size() < 3) return absl::InvalidArgumentError("insert: the mesh has no triangle");
  if (!m.MakeObject(mesh, &o)) {
    return absl::InvalidArgumentError("insert: the mesh has a non-finite position, an index out of range or 2^29 triangles or more");
  }
  const auto id = static_cast<ObjectId>(m.objects.size());
  m.objects.push_back(std::move(o));
  m.Attach(id);
  pvs_.ResizeObjects(m.objects.size());
  m.object_hits.push_back(0);
  RemovePenumbra(m, grid_, &pvs_, &stats_, id);
  m.Rebuild();
  m.Commit();
  return id;
}

absl::Status GlobalSampler::MoveObject(scenes::ObjectId id, const glm::dvec3& offset) {
  Impl& m = *impl_;
  if (id >= m.objects.size() || !m.objects[id].alive) return absl::NotFoundError(absl::StrCat("move: no object ", id));
  if (!std::isfinite(offset.x) || !std::isfinite(offset.y) || !std::isfinite(offset.z)) {
    return absl::InvalidArgumentError("move: the offset is not finite");
  }
  if (absl::Status st = DeleteObject(id); !st.ok()) return st;
  Impl::Object& o = m.objects[id];
  o.bounds = Aabb{};
  for (glm::vec3& v : o.verts) {
    v = glm::vec3(glm::dvec3(v) + offset);
    o.bounds.Extend(glm::dvec3(v));
  }
  Impl::BuildTris(&o);
  o.alive = true;
  if (!o.indices.empty()) m.Attach(id);
  RemovePenumbra(m, grid_, &pvs_, &stats_, id);
  m.Rebuild();
  m.Commit();
  return absl::OkStatus();
}

}  // namespace vistream::visibility
