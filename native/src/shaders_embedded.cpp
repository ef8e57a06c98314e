#include "shaders_embedded.h"

#include "closesthit.spv.h"
#include "miss.spv.h"
#include "raygen.spv.h"
#include "sampling_test.spv.h"
#include "shadow_miss.spv.h"

namespace px {
#define PX_SHADER(NAME)                                                                     \
    const std::vector<uint32_t>& shader_##NAME() {                                          \
        static const std::vector<uint32_t> code(std::begin(spv_##NAME), std::end(spv_##NAME)); \
        return code;                                                                        \
    }
PX_SHADER(raygen)
PX_SHADER(closesthit)
PX_SHADER(miss)
PX_SHADER(shadow_miss)
PX_SHADER(sampling_test)
}  // namespace px
