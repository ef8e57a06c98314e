#include "techniques/guiding/regions.h"

#include <algorithm>

namespace px::guiding {

int Aabb::longest_axis() const {
    const Vec3 e = extent();
    return e.x >= e.y && e.x >= e.z ? 0 : e.y >= e.z ? 1 : 2;
}

static double& axis_ref(Vec3& v, int a) { return a == 0 ? v.x : a == 1 ? v.y : v.z; }

void RegionTree::build(const Aabb& bounds, uint32_t splits) {
    nodes_.assign(1, Node{});
    nodes_[0].box = bounds;
    leaf_node_.clear();
    subdivide(0, splits);
}

void RegionTree::subdivide(int32_t node, uint32_t depth) {
    if (depth == 0) {
        nodes_[node].region = uint32_t(leaf_node_.size());
        leaf_node_.push_back(uint32_t(node));
        return;
    }
    const Aabb box = nodes_[node].box;
    const int a = box.longest_axis();
    // A float plane: the GPU's walk (float positions) then picks the same side as lookup().
    const double mid = double(float(0.5 * (box.lo[a] + box.hi[a])));
    const int32_t c = int32_t(nodes_.size());
    nodes_[node].child = c;
    nodes_[node].axis = a;
    nodes_[node].split = mid;
    nodes_.resize(nodes_.size() + 2);
    nodes_[c].box = nodes_[c + 1].box = box;
    axis_ref(nodes_[c].box.hi, a) = mid;
    axis_ref(nodes_[c + 1].box.lo, a) = mid;
    subdivide(c, depth - 1);
    subdivide(c + 1, depth - 1);
}

uint32_t RegionTree::lookup(const Vec3& p) const {
    if (!finite(p) || nodes_.empty()) return NO_INDEX;
    int32_t n = 0;
    while (nodes_[n].child >= 0) n = nodes_[n].child + (p[nodes_[n].axis] >= nodes_[n].split ? 1 : 0);
    return nodes_[n].region;
}

uint32_t RegionTree::split(uint32_t region) {
    const int32_t node = int32_t(leaf_node_[region]);
    const Aabb box = nodes_[node].box;
    const int a = box.longest_axis();
    // A float plane: the GPU's walk (float positions) then picks the same side as lookup().
    const double mid = double(float(0.5 * (box.lo[a] + box.hi[a])));
    const int32_t c = int32_t(nodes_.size());
    nodes_.resize(nodes_.size() + 2);
    Node& parent = nodes_[node];
    parent.child = c;
    parent.axis = a;
    parent.split = mid;
    nodes_[c].box = nodes_[c + 1].box = box;
    axis_ref(nodes_[c].box.hi, a) = mid;
    axis_ref(nodes_[c + 1].box.lo, a) = mid;
    const uint32_t upper = uint32_t(leaf_node_.size());
    nodes_[c].region = region;
    nodes_[c + 1].region = upper;
    leaf_node_[region] = uint32_t(c);
    leaf_node_.push_back(uint32_t(c + 1));
    return upper;
}

void RegionTree::write_nodes(std::vector<GuidingNode>& out) const {
    out.resize(nodes_.size());
    for (size_t i = 0; i < nodes_.size(); ++i) {
        const Node& n = nodes_[i];
        out[i].split = float(n.split);
        out[i].link = n.child < 0 ? (n.region << 2) | GUIDING_NODE_LEAF : (uint32_t(n.child) << 2) | uint32_t(n.axis);
    }
}

void RegionTree::write_aabbs(std::vector<float>& out) const {
    out.resize(leaf_node_.size() * 6);
    const double pad = 1e-5 * length(root().extent());
    for (uint32_t r = 0; r < leaf_node_.size(); ++r) {
        const Aabb& b = bounds(r);
        for (int a = 0; a < 3; ++a) {
            out[6 * r + a] = float(b.lo[a] - pad);
            out[6 * r + 3 + a] = float(b.hi[a] + pad);
        }
    }
}

std::vector<uint32_t> RegionTree::spatial_order() const {
    std::vector<uint32_t> order;
    order.reserve(leaf_node_.size());
    std::vector<int32_t> stack{0};
    while (!stack.empty()) {
        const int32_t n = stack.back();
        stack.pop_back();
        if (nodes_[n].child < 0) {
            order.push_back(nodes_[n].region);
        } else {
            stack.push_back(nodes_[n].child + 1);
            stack.push_back(nodes_[n].child);
        }
    }
    return order;
}

}  // namespace px::guiding
