#pragma once
// A kd-tree over objects with tight node boxes (z included): the hierarchy the dual-ray-space
// traversal culls top-down. Objects go to the side of the split their box centre lies on, so
// a node's box is exactly the union of its objects' boxes and sibling boxes may overlap;
// an occluded node box therefore proves every object below it occluded.

#include <cstdint>
#include <span>
#include <vector>

#include "scenes/aabb.h"
#include "scenes/scene.h"

namespace vistream::visibility {

using scenes::Aabb;
using scenes::ObjectId;

struct KdNode {
  Aabb bounds;              // tight: the union of the boxes of the objects below
  uint32_t first = 0;       // leaf: range [first, first + count) of KdTree::objects()
  uint32_t count = 0;       // objects below this node (leaf or inner)
  int32_t left = -1;        // inner: children; the left child always follows its parent
  int32_t right = -1;
  uint8_t axis = 0;         // inner: split axis (0 x, 1 y, 2 z)
  double split = 0.0;       // inner: box centres < split went left, > split right
  bool IsLeaf() const { return left < 0; }
};

struct KdTreeOptions {
  uint32_t leaf_size = 4;   // a node with at most this many objects is a leaf
  uint32_t max_depth = 48;  // deeper nodes become leaves whatever their size
};

class KdTree {
 public:
  KdTree() = default;
  // Builds over `boxes` (object i has box boxes[i]); empty boxes are left out. Splits the
  // longest axis of the node's box-centre bounds at the median centre (ties by object id,
  // so the tree is the same on every platform).
  static KdTree Build(std::span<const Aabb> boxes, const KdTreeOptions& options = {});
  static KdTree Build(const scenes::Scene& scene, const KdTreeOptions& options = {});

  const std::vector<KdNode>& nodes() const { return nodes_; }
  const KdNode& root() const { return nodes_.front(); }
  bool empty() const { return nodes_.empty(); }
  // Objects of a leaf, by id.
  std::span<const ObjectId> LeafObjects(const KdNode& leaf) const {
    return {objects_.data() + leaf.first, leaf.count};
  }
  // Every object below `node`: leaves store contiguous ranges, so this is one span too.
  std::span<const ObjectId> ObjectsBelow(const KdNode& node) const {
    return {objects_.data() + node.first, node.count};
  }
  uint32_t depth() const { return depth_; }
  size_t LeafCount() const;

 private:
  std::vector<KdNode> nodes_;
  std::vector<ObjectId> objects_;
  uint32_t depth_ = 0;
};

}  // namespace vistream::visibility
