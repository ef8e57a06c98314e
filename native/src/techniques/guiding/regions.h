// Guiding regions (thesis 4.6.1, 4.6.3): the scene AABB halved along its longest axis into
// 2^k boxes (a binary tree), the point lookup (the GPU walks the same tree: write_nodes) and
// adaptive refinement (a region splits in two).
#pragma once
#include "techniques/guiding/vmm.h"

#include <vector>

namespace px::guiding {

struct Aabb {
    Vec3 lo, hi;
    Vec3 extent() const { return hi - lo; }
    int longest_axis() const;
};

class RegionTree {
public:
    // 2^splits regions, numbered in depth-first (spatially coherent) order.
    void build(const Aabb& bounds, uint32_t splits);
    size_t size() const { return leaf_node_.size(); }
    const Aabb& bounds(uint32_t region) const { return nodes_[leaf_node_[region]].box; }
    const Aabb& root() const { return nodes_[0].box; }
    // The region holding p (points outside the scene box go to the nearest region); NO_INDEX
    // for a point that is not finite.
    uint32_t lookup(const Vec3& p) const;
    // Splits a region at the middle of its longest axis: it keeps the lower half, the upper
    // half becomes region size() (returned).
    uint32_t split(uint32_t region);
    // Regions in depth-first order of the tree (spatially coherent, for BVH builds).
    std::vector<uint32_t> spatial_order() const;
    // The tree for the GPU's walk (GuidingNode, shaders/shared/guiding.h); node 0 is the root.
    void write_nodes(std::vector<GuidingNode>& out) const;
    // 6 floats per region (VkAabbPositionsKHR), enlarged by a hair (1e-5 of the root's
    // diagonal) so lookups never fall between regions (thesis 4.6.1).
    void write_aabbs(std::vector<float>& out) const;

private:
    struct Node {
        Aabb box;
        int32_t child = -1;  // first of two children; -1: leaf
        int axis = 0;
        double split = 0.0;
        uint32_t region = 0;  // leaves
    };
    void subdivide(int32_t node, uint32_t depth);
    std::vector<Node> nodes_;
    std::vector<uint32_t> leaf_node_;  // region -> node
};

}  // namespace px::guiding
