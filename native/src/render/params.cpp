#include "render/params.h"

#include "techniques/adrrs.h"
#include "techniques/guiding/field.h"
#include "techniques/irradiance_cache.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>

namespace px {

namespace {

constexpr FieldRef kEngine{};  // an engine setting: no core field (the core is progressive)

// Cycles' denoising enumerations (CyclesRenderSettings: denoising_input_passes, _prefilter, _quality).
std::vector<EnumItem> denoising_input_items() {
    return {{"RGB", "None", "Don't use utility passes for denoising", 0},
            {"RGB_ALBEDO", "Albedo", "Use albedo pass for denoising", 1},
            {"RGB_ALBEDO_NORMAL", "Albedo and Normal", "Use albedo and normal passes for denoising", 2}};
}
std::vector<EnumItem> denoising_prefilter_items() {
    return {{"NONE", "None", "No prefiltering, use when guiding passes are noise-free", 0},
            {"FAST", "Fast",
             "Denoise color and guiding passes together. Improves quality when guiding passes are noisy using "
             "least amount of extra processing time", 1},
            {"ACCURATE", "Accurate",
             "Prefilter noisy guiding passes before denoising color. Improves quality when guiding passes are noisy "
             "using extra processing time", 2}};
}
std::vector<EnumItem> denoising_quality_items() {
    return {{"HIGH", "High", "High quality", 0},
            {"BALANCED", "Balanced", "Balanced between performance and quality", 1},
            {"FAST", "Fast", "High performance", 2}};
}

// The base path tracer's settings and the film's own passes.
const SettingTable& base_table() {
    static const SettingTable table{"base",
        {
            // Sampling
            int_setting("samples", kEngine, 128, 1, 1 << 24, "Samples", "Samples per pixel to render", "sampling"),
            float_setting("time_limit", kEngine, 0.0, 0.0, 1e7, "Time Limit",
                          "Stop after this many seconds, even if fewer samples are done (0 = no limit)", "sampling").with_unit("time"),
            int_setting("samples_per_frame", PX_FIELD(RenderParams, samples_per_frame), 1, 1, 4096,
                        "Samples per Frame",
                        "Samples per pixel in one GPU submission: more is faster overall, fewer updates the image "
                        "more often", "sampling"),
            int_setting("seed", PX_FIELD(RenderParams, seed), 0, 0, INT32_MAX, "Seed",
                        "Random seed; the same seed gives the same image on the same device", "sampling"),
            // Adaptive sampling (Cycles' names, defaults and ranges; render/adaptive.h)
            bool_setting("use_adaptive_sampling", PX_FIELD(RenderParams, use_adaptive_sampling), true,
                         "Adaptive Sampling",
                         "Stop sampling pixels whose estimated noise fell below the threshold (Cycles' adaptive "
                         "sampling): fewer samples where the image is flat", "sampling").in_group("Adaptive Sampling"),
            float_setting("adaptive_threshold", PX_FIELD(RenderParams, adaptive_threshold), 0.01, 0.0, 1.0,
                          "Noise Threshold",
                          "Noise level at which a pixel stops sampling; lower values reduce noise at the cost of "
                          "render time (0: automatic, from the sample count, as Cycles)", "sampling")
                .in_group("Adaptive Sampling"),
            int_setting("adaptive_min_samples", PX_FIELD(RenderParams, adaptive_min_samples), 0, 0, 4096,
                        "Min Samples",
                        "Samples every pixel takes before it may stop, to find noisy features first (0: automatic, "
                        "from the threshold, as Cycles)", "sampling").in_group("Adaptive Sampling"),
            // The viewport's (the engine maps them onto the fields above: addon/engine/viewport.py)
            bool_setting("use_preview_adaptive_sampling", kEngine, true, "Adaptive Sampling",
                         "Adaptive sampling in the viewport", "sampling").in_group("Viewport"),
            float_setting("preview_adaptive_threshold", kEngine, 0.1, 0.0, 1.0, "Noise Threshold",
                          "The viewport's noise threshold (0: automatic, from the viewport's sample count)",
                          "sampling").in_group("Viewport"),
            // Light paths (Cycles' names, defaults and ranges; a bounce counts towards the budget
            // of its sampled lobe's kind, as Cycles' labels: BsdfSample.kind in bsdf.glsl)
            int_setting("max_depth", PX_FIELD(RenderParams, max_depth), 12, 0, 1024, "Total",
                        "Maximum number of bounces, bounded by the leeway's discrete bounces (Cycles' Max "
                        "Bounces: Total, which counts every bounce, is this with a leeway of 0)", "light_paths")
                .in_group("Max Bounces"),
            int_setting("depth_leeway", PX_FIELD(RenderParams, depth_leeway), 4, 0, 1024, "Discrete Leeway",
                        "Specular (delta) bounces that do not count towards the Total, so light through glass "
                        "and mirrors is not cut short (thesis, sec. 3.1; Parallax's own, 0 counts as Cycles)",
                        "light_paths").in_group("Max Bounces"),
            int_setting("diffuse_bounces", PX_FIELD(RenderParams, diffuse_bounces), 4, 0, 1024, "Diffuse",
                        "Maximum number of diffuse reflection bounces, bounded by total maximum", "light_paths")
                .in_group("Max Bounces"),
            int_setting("glossy_bounces", PX_FIELD(RenderParams, glossy_bounces), 4, 0, 1024, "Glossy",
                        "Maximum number of glossy reflection bounces, bounded by total maximum", "light_paths")
                .in_group("Max Bounces"),
            int_setting("transmission_bounces", PX_FIELD(RenderParams, transmission_bounces), 12, 0, 1024,
                        "Transmission", "Maximum number of transmission bounces, bounded by total maximum",
                        "light_paths").in_group("Max Bounces"),
            float_setting("sample_clamp_direct", PX_FIELD(RenderParams, sample_clamp_direct), 0.0, 0.0, 1e6,
                          "Direct Light",
                          "If non-zero, the maximum value for a direct sample, higher values will be scaled down to "
                          "avoid too much noise and slow convergence at the cost of accuracy (biased)", "light_paths")
                .in_group("Clamping"),
            float_setting("sample_clamp_indirect", PX_FIELD(RenderParams, sample_clamp_indirect), 10.0, 0.0, 1e6,
                          "Indirect Light",
                          "If non-zero, the maximum value for an indirect sample, higher values will be scaled down "
                          "to avoid too much noise and slow convergence at the cost of accuracy (biased)",
                          "light_paths").in_group("Clamping"),
            float_setting("blur_glossy", PX_FIELD(RenderParams, blur_glossy), 1.0, 0.0, 10.0, "Filter Glossy",
                          "Adaptively blur glossy shaders after blurry bounces, to reduce noise at the cost of "
                          "accuracy (biased; 0: off)", "light_paths").in_group("Caustics"),
            int_setting("rr_start_depth", PX_FIELD(RenderParams, rr_start_depth), 3, 0, 1024, "Russian Roulette",
                        "First bounce at which Russian roulette may end a low-throughput path (survival "
                        "probability the square root of the throughput, as Cycles), reweighting the survivors; 0 = "
                        "off", "light_paths"),
            // Film: the pixel filter, importance-sampled (render/pixel_filter.h)
            enum_setting("pixel_filter_type", PX_FIELD(RenderParams, pixel_filter_type), FILTER_BLACKMAN_HARRIS,
                         {{"BOX", "Box", "Box filter", FILTER_BOX},
                          {"GAUSSIAN", "Gaussian", "Gaussian filter", FILTER_GAUSSIAN},
                          {"BLACKMAN_HARRIS", "Blackman-Harris", "Blackman-Harris filter", FILTER_BLACKMAN_HARRIS}},
                         "Pixel Filter", "Pixel filter type", "film"),
            float_setting("filter_width", PX_FIELD(RenderParams, filter_width), 1.5, 0.01, 10.0, "Width",
                          "Pixel filter width", "film").with_unit("pixel"),
            // Lights
            enum_setting("method", PX_FIELD(RenderParams, method), METHOD_MIS,
                         {{"mis", "MIS",
                           "Next event estimation and BSDF sampling, combined with multiple importance sampling "
                           "(Veach 1997): robust on every material and light size", METHOD_MIS},
                          {"nee", "Next Event Estimation",
                           "Sample a light at every vertex; emission hit by BSDF sampling is ignored except on delta "
                           "bounces", METHOD_NEE},
                          {"pt", "Path Tracing", "BSDF sampling only: lights are found by chance (the reference)",
                           METHOD_PT}},
                         "Method", "How paths find the lights", "lights"),
            int_setting("light_samples", PX_FIELD(RenderParams, light_samples), 1, 1, 64, "Light Samples",
                        "Light samples (shadow rays) per path vertex", "lights"),
            bool_setting("light_tree", PX_FIELD(RenderParams, light_tree), true, "Light Tree",
                         "Pick among the local lights (lamps, emissive meshes) by their estimated contribution at the "
                         "shading point, through a tree over them (Conty Estevez & Kulla 2018), as Cycles' Light "
                         "Tree; off: by emitted power alone", "lights"),
            enum_setting("mis_heuristic", PX_FIELD(RenderParams, mis_heuristic), HEURISTIC_POWER,
                         {{"power", "Power", "Power heuristic, exponent 2 (Veach 1997, eq. 9.13)", HEURISTIC_POWER},
                          {"balance", "Balance", "Balance heuristic (Veach 1997, eq. 9.10)", HEURISTIC_BALANCE}},
                         "MIS Heuristic", "How MIS weighs light and BSDF samples", "lights"),
            // Denoising (engine settings: parallax_core.denoise runs OIDN on the film's passes).
            // Cycles' names, items and defaults (CyclesRenderSettings).
            bool_setting("use_denoising", kEngine, true, "Use Denoising",
                         "Denoise the rendered image with OpenImageDenoise (Combined gets the denoised image, "
                         "Noisy Image the undenoised one)", "denoising"),
            enum_setting("denoising_input_passes", kEngine, 2, denoising_input_items(), "Denoising Input Passes",
                         "Passes used by the denoiser to distinguish noise from shader and geometry detail",
                         "denoising"),
            enum_setting("denoising_prefilter", kEngine, 2, denoising_prefilter_items(), "Denoising Prefilter",
                         "Prefilter noisy guiding (albedo and normal) passes to improve denoising quality",
                         "denoising"),
            enum_setting("denoising_quality", kEngine, 0, denoising_quality_items(), "Denoising Quality",
                         "Overall denoising quality", "denoising"),
            bool_setting("use_preview_denoising", kEngine, false, "Use Viewport Denoising",
                         "Denoise the image in the 3D viewport (on a thread of its own: edits do not wait for it)",
                         "denoising").in_group("Viewport"),
            int_setting("preview_denoising_start_sample", kEngine, 1, 0, 1 << 24, "Start Denoising",
                        "Sample to start denoising the preview at", "denoising").in_group("Viewport"),
            enum_setting("preview_denoising_input_passes", kEngine, 1, denoising_input_items(),
                         "Viewport Denoising Input Passes",
                         "Passes used by the denoiser to distinguish noise from shader and geometry detail",
                         "denoising").in_group("Viewport"),
            enum_setting("preview_denoising_prefilter", kEngine, 1, denoising_prefilter_items(),
                         "Viewport Denoising Prefilter",
                         "Prefilter noisy guiding (albedo and normal) passes to improve denoising quality",
                         "denoising").in_group("Viewport"),
            enum_setting("preview_denoising_quality", kEngine, 1, denoising_quality_items(),
                         "Viewport Denoising Quality", "Overall denoising quality", "denoising").in_group("Viewport"),
            // The viewport's first frame (not a user setting).
            bool_setting("preview", PX_FIELD(RenderParams, preview), false, "Preview",
                         "First-hit shading only (preview.rgen): compiles in a fraction of the path tracer's time; "
                         "the viewport's first frame", ""),
        },
        {
            {"combined", "Combined", 4, "RGBA", "The rendered image", PASS_COMBINED, ""},
            {"depth", "Depth", 1, "Z", "Distance to the first hit along the camera axis", PASS_DEPTH, ""},
            {"normal", "Normal", 3, "XYZ", "World shading normal of the first hit", PASS_NORMAL, ""},
            {"albedo", "Denoising Albedo", 3, "RGB", "Albedo at the first non-specular hit (the denoising albedo)",
             PASS_ALBEDO, ""},
            {"ray_depth", "Ray Depth", 1, "X", "Mean number of path segments traced per pixel", PASS_RAY_DEPTH, ""},
            // Where NEE pays: near 1 its shadow rays find their lights, near 0 they are wasted.
            {"nee_visibility", "NEE Visibility", 1, "X",
             "Fraction of the pixel's NEE shadow rays that reached their light (0 where none was traced)",
             PASS_NEE_VISIBILITY, "", "", true},
            // Adaptive sampling at work: low where the image is flat (Cycles' Sample Count).
            {"sample_count", "Sample Count", 1, "X", "Samples the pixel took (fewer where adaptive sampling stopped it)",
             PASS_SAMPLE_COUNT, ""},
            // Cycles' Noisy Image: Combined before the denoiser (which then fills Combined).
            {"noisy_image", "Noisy Image", 4, "RGBA", "The rendered image before denoising (with Use Denoising on)",
             0, "use_denoising", "", false, true},
        }};
    return table;
}

// The tables in order, each with the offset of its technique's Params struct in RenderParams.
// The one place that lists the techniques' tables.
struct Block {
    const SettingTable& table;
    size_t offset;
};
std::vector<Block> blocks() {
    return {{base_table(), 0},
            {ic_table(), offsetof(RenderParams, ic)},
            {adrrs_table(), offsetof(RenderParams, adrrs)},
            {guiding_table(), offsetof(RenderParams, guiding)}};
}

}  // namespace

const std::vector<SettingInfo>& settings() {
    static const std::vector<SettingInfo> all = [] {
        std::vector<SettingInfo> rows;
        for (const Block& b : blocks())
            for (SettingInfo r : b.table.settings) {
                r.technique = b.table.technique;
                if (r.core()) r.field.offset += b.offset;
                rows.push_back(r);
            }
        return rows;
    }();
    return all;
}

const std::vector<PassInfo>& passes() {
    static const std::vector<PassInfo> all = [] {
        std::vector<PassInfo> rows;
        for (const Block& b : blocks())
            for (PassInfo p : b.table.passes) {
                p.technique = b.table.technique;
                rows.push_back(p);
            }
        return rows;
    }();
    return all;
}

const SettingInfo& setting(const std::string& name) {
    for (const SettingInfo& r : settings())
        if (name == r.name) return r;
    std::string names;
    for (const SettingInfo& r : settings()) names += std::string(names.empty() ? "" : ", ") + r.name;
    throw std::invalid_argument("unknown setting '" + name + "' (settings: " + names + ")");
}

const PassInfo& pass(const std::string& name) {
    for (const PassInfo& p : passes())
        if (name == p.name) return p;
    std::string names;
    for (const PassInfo& p : passes()) names += std::string(names.empty() ? "" : ", ") + p.name;
    throw std::invalid_argument("unknown pass '" + name + "' (passes: " + names + ")");
}

RenderParams::RenderParams() {
    write_defaults(this, settings());
}

bool RenderParams::operator==(const RenderParams& o) const {
    return std::memcmp(this, &o, sizeof(RenderParams)) == 0;  // 4-byte fields only: no padding
}

void set_setting(RenderParams& p, const std::string& name, const SettingValue& value) {
    const SettingInfo& row = setting(name);
    if (!row.core()) throw std::invalid_argument(name + " is the engine's setting, not the core's");
    write_setting(&p, row, value);
}

uint32_t light_path_limits(const RenderParams& p) {
    // A path's kind counts reach at most its scatters, max_depth + depth_leeway where it may go on.
    const uint32_t deepest = p.max_depth + p.depth_leeway;
    const bool budgets = std::min({p.diffuse_bounces, p.glossy_bounces, p.transmission_bounces}) < deepest;
    const bool clamp = p.sample_clamp_direct > 0.0f || p.sample_clamp_indirect > 0.0f;
    return (budgets ? LIMIT_KIND_BOUNCES : 0u) | (clamp ? LIMIT_CLAMP : 0u) |
           (p.blur_glossy > 0.0f ? LIMIT_BLUR_GLOSSY : 0u);
}

const SettingInfo& technique_switch(const std::string& name) {
    for (const SettingInfo& r : settings())
        if (name == r.technique) return r;
    throw std::invalid_argument("unknown technique '" + name + "'");
}

bool technique_on(const RenderParams& p, const std::string& name) {
    return read_setting(&p, technique_switch(name)) != 0;
}

void validate(const RenderParams& p) {
    check_settings(&p, settings());
    validate_guiding_params(p.guiding);  // the relations between guiding's settings
    if (!p.preview) return;
    std::string on;
    for (const Block& b : blocks())
        if (std::strcmp(b.table.technique, "base") != 0 && technique_on(p, b.table.technique))
            on += std::string(on.empty() ? "" : ", ") + technique_switch(b.table.technique).name;
    if (!on.empty()) throw std::invalid_argument("preview frames use no technique: turn " + on + " off");
}

}  // namespace px
