// SPIR-V of every shader, compiled by glslangValidator at build time (CMakeLists.txt).
#pragma once
#include <cstdint>
#include <vector>

namespace px {
const std::vector<uint32_t>& shader_raygen();
const std::vector<uint32_t>& shader_raygen_split_loops();  // raygen.rgen with PX_SPLIT_LOOPS (SPLIT_WALK 0)
const std::vector<uint32_t>& shader_preview();
const std::vector<uint32_t>& shader_closesthit();
const std::vector<uint32_t>& shader_self_skip_any_hit();
const std::vector<uint32_t>& shader_miss();
const std::vector<uint32_t>& shader_shadow_miss();
const std::vector<uint32_t>& shader_sampling_test();
const std::vector<uint32_t>& shader_ic_hemisphere();
const std::vector<uint32_t>& shader_ic_finish();
const std::vector<uint32_t>& shader_adaptive();
const std::vector<uint32_t>& shader_guiding_query_miss();
const std::vector<uint32_t>& shader_guiding_query_intersection();
const std::vector<uint32_t>& shader_guiding_query_closest_hit();
const std::vector<uint32_t>& shader_guiding_fit();
}  // namespace px
