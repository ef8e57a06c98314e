// EARS' learnt statistics, host side (Rath et al. 2022, "EARS: Efficiency-Aware Russian Roulette
// and Splitting"; shaders/techniques/ears.glsl). Owned by the RRS technique (adrrs.h), which
// gives EARS its pixel estimate and split queue.
//
// Training runs in iterations that end where the image estimate is refreshed (each time the
// samples double): paths sum their records per cell into the learning table
// (BINDING_EARS_CELLS); at an iteration's end the host reads the sums once, turns each cell's
// into the factors the next iteration decides by (BINDING_EARS_FACTORS), together with the
// image's cost and relative variance per sample, and clears the sums. A cell keeps its last
// factors until an iteration gives it enough records again.
#pragma once
#include "scene/scene.h"
#include "techniques/technique.h"

namespace px {

class EarsStatistics {
public:
    explicit EarsStatistics(Context& ctx);
    // New scene, settings or image: the grid spans the scene's box, every statistic is dropped.
    // `grid`: cells along the box's longest axis; `min_records`: the records a cell needs before
    // its factors are trusted (TECHNIQUES.md: don't trust the factors before they settle).
    void configure(bool enabled, const SceneHost& scene, uint32_t width, uint32_t height, uint32_t grid,
                   uint32_t min_records);
    void reset();  // statistics dropped; learning waits for the next image estimate
    void bind(DescriptorSet& set) const;
    // The grid, the image's factor and whether paths learn and decide, into `params`
    // (AdrrsParams' ears_* fields).
    void write_params(AdrrsParams& params) const;
    // An iteration ends: the pixel estimate was just refreshed to `estimate` (luminance per
    // pixel). The learnt sums become the factors; learning goes on in the unit of the
    // estimate's mean.
    void end_iteration(const std::vector<float>& estimate);

    void stats(StatList& out) const;

private:
    Context& ctx_;
    bool enabled_ = false;
    Buffer cells_, factors_, pixels_, records_;
    uint32_t threads_ = 0;
    uint32_t slots_ = 1, min_records_ = 1;
    float grid_min_[3] = {0, 0, 0};
    float cell_ = 0.0f;
    bool learning_ = false;  // paths record (an estimate exists)
    bool active_ = false;    // the factors hold statistics
    float scale_ = 1.0f;
    float image_factor_ = 0.0f;
    uint32_t iterations_ = 0, cells_with_factors_ = 0, full_slots_ = 0;
    double image_cost_ = 0, image_variance_ = 0, fit_milliseconds_ = 0;
    std::vector<EarsFactor> factors_host_;
};

}  // namespace px
