#include "shaders_embedded.h"

#include "closesthit.spv.h"
#include "self_skip_any_hit.spv.h"
#include "guiding_fit.spv.h"
#include "guiding_query_closest_hit.spv.h"
#include "guiding_query_intersection.spv.h"
#include "guiding_query_miss.spv.h"
#include "adaptive.spv.h"
#include "ic_finish.spv.h"
#include "ic_hemisphere.spv.h"
#include "miss.spv.h"
#include "preview.spv.h"
#include "raygen.spv.h"
#include "raygen_split_loops.spv.h"
#include "sampling_test.spv.h"
#include "shadow_miss.spv.h"

namespace px {
#define PX_SHADER(NAME)                                                                     \
    const std::vector<uint32_t>& shader_##NAME() {                                          \
        static const std::vector<uint32_t> code(std::begin(spv_##NAME), std::end(spv_##NAME)); \
        return code;                                                                        \
    }
PX_SHADER(raygen)
PX_SHADER(raygen_split_loops)
PX_SHADER(preview)
PX_SHADER(closesthit)
PX_SHADER(self_skip_any_hit)
PX_SHADER(miss)
PX_SHADER(shadow_miss)
PX_SHADER(sampling_test)
PX_SHADER(ic_hemisphere)
PX_SHADER(ic_finish)
PX_SHADER(adaptive)
PX_SHADER(guiding_query_miss)
PX_SHADER(guiding_query_intersection)
PX_SHADER(guiding_query_closest_hit)
PX_SHADER(guiding_fit)
}  // namespace px
