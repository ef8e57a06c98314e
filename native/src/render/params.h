// The render settings: px::RenderParams and the one list of setting and pass rows (the base
// path tracer's, then each technique's) that parallax_core exports as SETTINGS and PASSES.
// Defaults and ranges are the rows' (techniques/settings.h); nothing else restates them.
#pragma once
#include "../../../shaders/shared/types.h"
#include "techniques/settings.h"

#include <string>
#include <vector>

namespace px {

struct RenderParams {
    uint32_t method{};
    uint32_t mis_heuristic{};
    uint32_t samples_per_frame{};
    uint32_t max_depth{};
    uint32_t depth_leeway{};
    uint32_t rr_start_depth{};  // 0: no Russian roulette
    // Cycles' light paths: bounce budgets per kind of scattering, sample clamps (0: off),
    // Filter Glossy (0: off), and the pixel filter (render/pixel_filter.h).
    uint32_t diffuse_bounces{};
    uint32_t glossy_bounces{};
    uint32_t transmission_bounces{};
    float sample_clamp_direct{};
    float sample_clamp_indirect{};
    float blur_glossy{};
    uint32_t pixel_filter_type{};
    float filter_width{};
    uint32_t light_samples{};
    uint32_t seed{};
    // The viewport's first frame: preview.rgen's first-hit shading, which compiles quickly.
    uint32_t preview{};
    // Local lights picked through the light tree (Cycles' Light Tree); 0: by power.
    uint32_t light_tree{};
    // Adaptive sampling (Cycles' settings): pixels whose noise estimate fell below the threshold
    // stop sampling (render/adaptive.h).
    uint32_t use_adaptive_sampling{};
    float adaptive_threshold{};
    uint32_t adaptive_min_samples{};  // 0: automatic, from the threshold
    IcParams ic{};          // irradiance cache (techniques/irradiance_cache.h)
    AdrrsParams adrrs{};    // adjoint-driven Russian roulette and splitting (techniques/adrrs.h)
    GuidingParams guiding{};  // path guiding (techniques/guiding/guiding.h)
    RenderParams();  // every setting at its row's default
    bool operator==(const RenderParams& o) const;
};

// Every setting, in order: the base path tracer's (with the engine's samples and time_limit,
// which have no core field), then each technique's. Field offsets are within RenderParams.
const std::vector<SettingInfo>& settings();
// The row called `name`; std::invalid_argument listing the names if there is none.
const SettingInfo& setting(const std::string& name);
// Every pass in film order: the film's own, then each technique's.
const std::vector<PassInfo>& passes();
const PassInfo& pass(const std::string& name);  // std::invalid_argument listing the names

// The setting that switches technique `name` on: the first row of its table (ic, rrs,
// guiding), a bool, or an enum whose item "off" (value 0) turns it off.
const SettingInfo& technique_switch(const std::string& name);
// Whether technique `name` is switched on in `p` (its switch is not 0).
bool technique_on(const RenderParams& p, const std::string& name);

// The LIMIT_* bits of the light-path limits that can change a render with these settings (a
// pipeline carries only those): a kind's bounce budget below the deepest path Max Bounces and
// the leeway allow, a clamp that is set, Filter Glossy where it is not 0.
uint32_t light_path_limits(const RenderParams& p);

// Writes one setting (type, range and enum name checked: std::invalid_argument naming it).
void set_setting(RenderParams& p, const std::string& name, const SettingValue& value);
// Every setting within its range, and the checks that relate settings (a technique's own,
// and that preview frames use no technique). std::invalid_argument naming the setting.
void validate(const RenderParams& p);

}  // namespace px
