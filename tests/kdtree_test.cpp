#include "visibility/kdtree.h"

#include <algorithm>
#include <functional>

#include <gtest/gtest.h>

#include "scenes/random.h"

namespace vistream::visibility {
namespace {

// Random boxes: clustered, of mixed sizes, some thin, some duplicates.
std::vector<Aabb> RandomBoxes(uint64_t seed, size_t n) {
  scenes::Rng rng(seed);
  std::vector<Aabb> boxes;
  for (size_t i = 0; i < n; ++i) {
    if (i > 0 && rng.Chance(0.05)) {
      boxes.push_back(boxes[rng.Below(i)]);  // an exact duplicate
      continue;
    }
    const glm::dvec3 c(rng.Uniform(-1000, 1000), rng.Uniform(-1000, 1000), 0);
    const glm::dvec3 e(rng.Uniform(0, 40), rng.Uniform(0, 40), rng.Uniform(0, 200));
    boxes.push_back(Aabb{glm::dvec3(c.x, c.y, 0), c + e});
  }
  return boxes;
}

void CheckInvariants(const KdTree& tree, std::span<const Aabb> boxes, const KdTreeOptions& options) {
  ASSERT_FALSE(tree.empty());
  const auto& nodes = tree.nodes();
  std::vector<int> seen(boxes.size(), 0);
  std::function<void(int32_t, uint32_t)> visit = [&](int32_t index, uint32_t level) {
    const KdNode& node = nodes[index];
    // Tight: the node box is exactly the union of the boxes of the objects below.
    Aabb tight;
    for (ObjectId id : tree.ObjectsBelow(node)) tight.Extend(boxes[id]);
    ASSERT_EQ(node.bounds, tight) << "node " << index;
    if (node.IsLeaf()) {
      EXPECT_TRUE(node.count <= options.leaf_size || level >= options.max_depth ||
                  std::all_of(tree.LeafObjects(node).begin(), tree.LeafObjects(node).end(),
                              [&](ObjectId id) { return boxes[id].Centre() == boxes[tree.LeafObjects(node)[0]].Centre(); }))
          << "leaf " << index << " holds " << node.count;
      for (ObjectId id : tree.LeafObjects(node)) ++seen[id];
      return;
    }
    ASSERT_EQ(node.left, index + 1);
    const KdNode &l = nodes[node.left], &r = nodes[node.right];
    // Nested, and the children partition the parent's objects.
    EXPECT_TRUE(node.bounds.Contains(l.bounds));
    EXPECT_TRUE(node.bounds.Contains(r.bounds));
    EXPECT_EQ(l.count + r.count, node.count);
    EXPECT_EQ(l.first, node.first);
    EXPECT_EQ(r.first, node.first + l.count);
    Aabb both = l.bounds;
    both.Extend(r.bounds);
    EXPECT_EQ(both, node.bounds);
    for (ObjectId id : tree.ObjectsBelow(l)) EXPECT_LE(boxes[id].Centre()[node.axis], node.split);
    for (ObjectId id : tree.ObjectsBelow(r)) EXPECT_GE(boxes[id].Centre()[node.axis], node.split);
    visit(node.left, level + 1);
    visit(node.right, level + 1);
  };
  visit(0, 0);
  for (size_t id = 0; id < boxes.size(); ++id) {
    ASSERT_EQ(seen[id], boxes[id].Empty() ? 0 : 1) << "object " << id << " reached " << seen[id] << " times";
  }
}

TEST(KdTree, InvariantsHoldOnRandomScenes) {
  for (uint64_t seed = 1; seed <= 6; ++seed) {
    for (uint32_t leaf : {1u, 4u, 16u}) {
      const std::vector<Aabb> boxes = RandomBoxes(seed, 300 * seed);
      const KdTreeOptions options{.leaf_size = leaf};
      SCOPED_TRACE(::testing::Message() << "seed " << seed << " leaf " << leaf);
      CheckInvariants(KdTree::Build(boxes, options), boxes, options);
    }
  }
}

TEST(KdTree, DepthLimitMakesLeaves) {
  const std::vector<Aabb> boxes = RandomBoxes(11, 2000);
  const KdTreeOptions options{.leaf_size = 1, .max_depth = 4};
  const KdTree tree = KdTree::Build(boxes, options);
  EXPECT_LE(tree.depth(), 4u);
  EXPECT_EQ(tree.LeafCount(), 16u);
  CheckInvariants(tree, boxes, options);
}

TEST(KdTree, EmptyBoxesAreLeftOutAndEmptyInputGivesEmptyTree) {
  EXPECT_TRUE(KdTree::Build(std::vector<Aabb>{}).empty());
  EXPECT_TRUE(KdTree::Build(std::vector<Aabb>(3)).empty());
  std::vector<Aabb> boxes = RandomBoxes(3, 50);
  boxes[7] = Aabb();
  const KdTree tree = KdTree::Build(boxes);
  EXPECT_EQ(tree.root().count, 49u);
  CheckInvariants(tree, boxes, {});
}

TEST(KdTree, CoincidentObjectsShareALeaf) {
  const std::vector<Aabb> boxes(20, Aabb{glm::dvec3(0), glm::dvec3(1)});
  const KdTree tree = KdTree::Build(boxes, {.leaf_size = 2});
  ASSERT_EQ(tree.nodes().size(), 1u);
  EXPECT_EQ(tree.root().count, 20u);
}

TEST(KdTree, SameInputSameTree) {
  const std::vector<Aabb> boxes = RandomBoxes(5, 1000);
  const KdTree a = KdTree::Build(boxes), b = KdTree::Build(boxes);
  ASSERT_EQ(a.nodes().size(), b.nodes().size());
  EXPECT_TRUE(std::equal(a.ObjectsBelow(a.root()).begin(), a.ObjectsBelow(a.root()).end(),
                         b.ObjectsBelow(b.root()).begin()));
}

}  // namespace
}  // namespace vistream::visibility
