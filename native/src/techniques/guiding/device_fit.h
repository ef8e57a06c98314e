// Guiding mixtures fitted on the device (issue 13; shaders/techniques/guiding/fit.comp): the
// frame's training samples stay where the trace loop wrote them; compute passes bin them by
// region, lit before unlit (a stable counting sort: count, a three-pass parallel scan, scatter;
// the EM reads only the lit samples, which are all that carry its statistics) and run the host
// fit's algorithm (em.h) per region, one workgroup each (the pivot's position sums in several),
// writing the GuidingRegion/GuidingLobe records the sampler reads. The host only records the
// dispatches: no readback, no upload. The fit state (statistics, mixtures, pivots) lives in
// device buffers across frames.
// Differences from the host field (field.h), by design: each frame's samples of a region are
// batch of stepwise EM (the previous statistics decayed) once the region has guiding_min_samples
// lit samples, those of earlier frames kept on the device until then (as the host field's
// reservoir, without its cap of max_batch: a batch is all of them). Samples without a valid
// region are dropped (the trace loop sets one).
// Each fit also learns its regions' guiding probability (selection.h, as the host field's
// learn_selection) and writes it into the GuidingRegion records.
// Adaptive refinement (refine()) is split between host and device: the host reads 32 bytes per
// region (GuidingFitTally: lit samples received since the region was made), decides the splits
// by the host field's rule and splits its region tree (the tree, the node buffer and the TLAS
// stay host-built); the REFINE pass then gives each child its parent's mixture and half of the
// statistics and moves the pending samples, on the device. The buffers grow with a copy.
#pragma once
#include "techniques/guiding/em.h"
#include "techniques/guiding/regions.h"
#include "vk/pipeline.h"

#include <memory>
#include <vector>

namespace px {
#include "../../../../shaders/shared/guiding_fit.h"
}  // namespace px

namespace px::guiding {

class DeviceFit {
public:
    // `regions` regions, all untrained; `options` as the host fit's (validated). A region fits
    // once it has min_samples lit samples (guiding_min_samples; more than 2K in any case),
    // kept across frames until then. Its probability of sampling the mixture is `prob`
    // (guiding_prob) until it learnt its own, always with `adaptive_prob` off.
    DeviceFit(Context& ctx, uint32_t regions, const FitOptions& options, bool parallax, uint32_t min_samples = 1,
              float prob = 0.5f, bool adaptive_prob = true);
    // The frame's sample buffer and the records the sampler reads (regions: GuidingRegion[regions],
    // lobes: GuidingLobe[regions * GUIDING_MAX_COMPONENTS]); again whenever one is re-created.
    void bind(const Buffer& samples, const Buffer& regions, const Buffer& lobes);
    // Records the passes over the first `sample_count` GuidingSample slots, with barriers
    // before (the trace's writes) and after (the sampler's reads).
    void record(VkCommandBuffer cmd, uint32_t sample_count);
    uint32_t region_count() const { return regions_; }
    // Adaptive refinement, GuidingField::fit's rule (field.cpp): after a record() has completed,
    // reads its received counts and splits, in region order, each region of `tree` (whose
    // regions are this fit's) with a mixture that received more than `threshold` lit samples since
    // it was made, while there are fewer than `max_regions` regions and its box is longer than
    // 1e-6 of the root's diagonal. The splits go to the device (the REFINE pass; submitted and
    // waited for), growing the fit's buffers and `regions`/`lobes` (re-created with a copy and
    // bound: the caller rebinds them elsewhere). Returns the regions split.
    // Reads the tally first (read_tally()).
    uint32_t refine(RegionTree& tree, uint32_t threshold, uint32_t max_regions, Buffer& regions, Buffer& lobes);
    // After a record() has completed: reads the regions' tally (refinement's counts and the
    // learnt probability's sums) and updates guiding_pays().
    const std::vector<GuidingFitTally>& read_tally();
    // GuidingField::guiding_pays's rule on the last tally read: with adaptive_prob, whether the
    // learnt probabilities' score gained, summed over the regions, beats BSDF sampling alone by
    // GUIDING_SELECTION_MARGIN (true while nothing was learnt, and with adaptive_prob off).
    bool guiding_pays() const { return pays_; }
    // Some region with a mixture samples it (prob > 0) and guiding pays, on the last tally read.
    bool mixture_sampled() const { return mixture_sampled_; }
    // What children inherited (GuidingFitRegion samples and fits, counted again in each child):
    // the sums over the regions less these are the samples received and the fits run.
    uint64_t inherited_samples() const { return inherited_samples_; }
    uint64_t inherited_fits() const { return inherited_fits_; }

    // Readbacks for tests, stats and benchmarks (never in the frame loop).
    std::vector<GuidingFitRegion> read_states() const;
    std::vector<GuidingFitLobe> read_lobes() const;
    // The last record()'s bins: first sorted slot of each region's lit then unlit samples, the
    // dropped bin's, the total (2 regions + 2), and the sample index of each slot.
    std::vector<uint32_t> read_starts() const;
    std::vector<uint32_t> read_sorted(uint32_t sample_count) const;
    // Region r's mixture as the host's type (distances <= 0 become kInfinity).
    Vmm mixture(uint32_t r) const;

private:
    void ensure_capacity(uint32_t sample_count);
    Context& ctx_;
    uint32_t regions_, capacity_;  // regions, and those the buffers hold
    GuidingFitPush push_{};
    std::unique_ptr<DescriptorSet> set_;
    Buffer states_, lobes_state_, counts_, starts_, sorted_, pending_, scan_partials_, position_parts_;
    Buffer tally_, splits_;  // host-visible: read / written by refine()
    std::vector<GuidingFitTally> tally_read_;
    bool pays_ = true, mixture_sampled_ = false;
    uint64_t inherited_samples_ = 0, inherited_fits_ = 0;
    uint32_t block_size_ = 0, block_count_ = 0, scan_tiles_ = 0, sorted_capacity_ = 0, position_parts_count_ = 1;
    size_t samples_bytes_ = 0;
};

}  // namespace px::guiding
