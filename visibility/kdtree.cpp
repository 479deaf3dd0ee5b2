#include "visibility/kdtree.h"

#include <algorithm>

namespace vistream::visibility {

namespace {

struct Builder {
  std::span<const Aabb> boxes;
  KdTreeOptions options;
  std::vector<glm::dvec3> centres;
  std::vector<KdNode>* nodes;
  std::vector<ObjectId>* objects;
  uint32_t depth = 0;

  // Builds the node for objects[first, first + count) and returns its index.
  int32_t Build(uint32_t first, uint32_t count, uint32_t level) {
    depth = std::max(depth, level);
    const auto index = static_cast<int32_t>(nodes->size());
    nodes->emplace_back();
    KdNode node;
    node.first = first;
    node.count = count;
    Aabb centre_box;
    for (uint32_t i = first; i < first + count; ++i) {
      const ObjectId id = (*objects)[i];
      node.bounds.Extend(boxes[id]);
      centre_box.Extend(centres[id]);
    }
    const glm::dvec3 extent = centre_box.Extent();
    int axis = 0;
    if (extent.y > extent[axis]) axis = 1;
    if (extent.z > extent[axis]) axis = 2;
    if (count <= options.leaf_size || level >= options.max_depth || extent[axis] <= 0.0) {
      (*nodes)[index] = node;
      return index;
    }
    const uint32_t half = count / 2;
    auto begin = objects->begin() + first;
    auto less = [&](ObjectId a, ObjectId b) {
      const double ca = centres[a][axis], cb = centres[b][axis];
      return ca < cb || (ca == cb && a < b);
    };
    std::nth_element(begin, begin + half, begin + count, less);
    node.axis = static_cast<uint8_t>(axis);
    node.split = centres[(*objects)[first + half]][axis];
    node.left = Build(first, half, level + 1);
    node.right = Build(first + half, count - half, level + 1);
    (*nodes)[index] = node;
    return index;
  }
};

}  // namespace

KdTree KdTree::Build(std::span<const Aabb> boxes, const KdTreeOptions& options) {
  KdTree tree;
  for (ObjectId id = 0; id < boxes.size(); ++id) {
    if (!boxes[id].Empty()) tree.objects_.push_back(id);
  }
  if (tree.objects_.empty()) return tree;
  Builder b;
  b.boxes = boxes;
  b.options = options;
  b.options.leaf_size = std::max<uint32_t>(1, options.leaf_size);
  b.centres.resize(boxes.size());
  for (size_t i = 0; i < boxes.size(); ++i) b.centres[i] = boxes[i].Centre();
  b.nodes = &tree.nodes_;
  b.objects = &tree.objects_;
  tree.nodes_.reserve(2 * tree.objects_.size() / b.options.leaf_size + 1);
  b.Build(0, static_cast<uint32_t>(tree.objects_.size()), 0);
  tree.depth_ = b.depth;
  return tree;
}

KdTree KdTree::Build(const scenes::Scene& scene, const KdTreeOptions& options) {
  std::vector<Aabb> boxes;
  boxes.reserve(scene.objects.size());
  for (const scenes::Object& o : scene.objects) boxes.push_back(o.bounds);
  return Build(boxes, options);
}

size_t KdTree::LeafCount() const {
  return static_cast<size_t>(std::count_if(nodes_.begin(), nodes_.end(),
                                           [](const KdNode& n) { return n.IsLeaf(); }));
}

}  // namespace vistream::visibility
