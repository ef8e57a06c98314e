// Light tree for picking one of many lights by its importance at the shading point
// (Conty Estevez & Kulla 2018, "Importance Sampling of Many Lights with Adaptive Tree
// Splitting"; Cycles' light tree). Traversed in shaders/lib/lights.glsl.
#pragma once
#include "../../../shaders/shared/types.h"

#include <cstdint>
#include <vector>

namespace px {

// Builds a binary tree over lights[i] for every i in `local` (local lights: emissive
// triangles, sphere, spot, rect, disk) with selection weights power[i] > 0, and sets
// lights[i].tree_node to each one's leaf. Node power is normalised to the root's (1).
// Splits at the centroid median along the widest axis: a balanced tree of depth log2(n).
std::vector<LightTreeNode> build_light_tree(std::vector<Light>& lights, const std::vector<uint32_t>& local,
                                            const std::vector<double>& power);

// Scenes with fewer local lights pick them from the power CDF (default 0: never; a process-wide
// test and benchmark knob on top of each session's light_tree setting).
uint32_t light_tree_min_lights();
void set_light_tree_min_lights(uint32_t n);

}  // namespace px
