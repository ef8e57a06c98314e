// The guiding field (thesis 4.6; Ruppert, Herholz & Lensch 2020): regions, their mixtures and
// their training, as the session drives it between frames:
//   after a frame:  field.add_samples(records read back from the GPU sample buffer)
//                   field.fit()                      (multithreaded; may refine regions)
//                   field.write_regions/write_lobes  (upload), and when layout_version()
//                   changed, field.write_nodes/aabbs (the region tree, the BLAS/TLAS)
// Robust training: a region's samples accumulate across frames (a reservoir per region)
// until it has guiding.min_samples of non-zero weight, then it fits (the thesis' clocks
// scene failed because regions trained on one frame's samples only, sec. 5.3.4).
// Deterministic: the same samples in the same order give the same field for a seed,
// whatever the number of threads (regions fit independently).
// Not thread-safe: one caller at a time (the fit may run on a worker thread while the GPU
// traces the next frame with the previously uploaded records).
#pragma once
#include "techniques/guiding/parallax.h"
#include "techniques/guiding/regions.h"
#include "techniques/guiding/selection.h"
#include "techniques/settings.h"

#include <vector>

namespace px {

// Path guiding's settings (the fields of GuidingParams) and passes (defined in guiding.cpp).
const SettingTable& guiding_table();
// Throws std::invalid_argument naming the setting (guiding_*) that is out of range or that
// contradicts another.
void validate_guiding_params(const GuidingParams& p);

namespace guiding {

struct FieldStats {
    uint32_t regions = 0;
    uint64_t samples_added = 0;     // accepted by add_samples (all time)
    uint64_t samples_dropped = 0;   // rejected: not finite, negative weight, pdf <= 0
    uint64_t region_fits = 0;       // all time
    // the last fit():
    uint32_t regions_fitted = 0;
    uint32_t splits = 0, merges = 0;  // lobes
    uint32_t refinements = 0;         // regions split
    uint32_t em_iterations = 0;       // summed over the regions fitted
    double fit_milliseconds = 0;
};

struct RegionInfo {
    uint64_t samples = 0;   // received since the field was built or reset (incl. zero weight)
    uint32_t pending = 0;   // non-zero samples waiting in the reservoir
    double seen = 0;        // non-zero samples offered since the last fit
    uint32_t components = 0;
    uint32_t fits = 0;
    Selection selection;    // the learnt guiding probability (guiding_adaptive_prob)
    double nee_prob = 1.0;  // the learnt probability of NEE (guiding_adaptive_nee)
    double region_choice = 0.0;  // the probability the region chose (selection.prob is the sampler's)
};

class GuidingField {
public:
    // scene_min/max: the scene's AABB. threads 0: one per hardware thread.
    GuidingField(const GuidingParams& params, const float scene_min[3], const float scene_max[3], uint32_t seed = 0,
                 const FitOptions& fit = FitOptions(), uint32_t threads = 0);

    // One frame's samples. A record whose region is NO_INDEX, out of range or not holding
    // its position is looked up from the position.
    void add_samples(const GuidingSample* samples, size_t count);
    // Fits every region with enough samples, then splits the regions with a mixture that
    // received more than region_threshold samples of non-zero weight (zero-weight samples
    // say nothing about the light: counted, they split rarely lit regions into pieces that
    // never gather min_samples again, and their mixtures stop learning).
    const FieldStats& fit();
    // Drops everything learnt: 2^region_splits untrained regions again.
    void reset();

    size_t region_count() const { return regions_.size(); }
    uint32_t region_of(const Vec3& p) const { return tree_.lookup(p); }
    const Aabb& region_bounds(uint32_t r) const { return tree_.bounds(r); }
    // Regions in a spatially coherent order (input order for lavapipe's BVH builder).
    std::vector<uint32_t> spatial_order() const { return tree_.spatial_order(); }
    // Bumped whenever regions change (build, reset, refinement): rebuild the region tree and TLAS.
    uint64_t layout_version() const { return layout_version_; }

    // GPU records: one GuidingRegion per region; GUIDING_MAX_COMPONENTS lobes per region;
    // 6 floats per region (VkAabbPositionsKHR), enlarged by a hair so lookups never fall
    // between regions (thesis 4.6.1).
    void write_regions(std::vector<GuidingRegion>& out) const;
    void write_lobes(std::vector<GuidingLobe>& out) const;
    void write_aabbs(std::vector<float>& out) const;
    void write_nodes(std::vector<GuidingNode>& out) const { tree_.write_nodes(out); }
    // The region tree (the device fit refines a copy of it: device_fit.h).
    const RegionTree& tree() const { return tree_; }
    // GPU bytes per region: its record, its lobes, its AABB and the tree's two nodes per leaf.
    static size_t gpu_bytes_per_region() {
        return sizeof(GuidingRegion) + GUIDING_MAX_COMPONENTS * sizeof(GuidingLobe) + 6 * sizeof(float) +
               2 * sizeof(GuidingNode);
    }

    const Vmm& mixture(uint32_t r) const { return regions_.at(r).state.vmm; }
    RegionInfo region_info(uint32_t r) const;
    const FieldStats& stats() const { return stats_; }
    const GuidingParams& params() const { return params_; }
    const FitOptions& fit_options() const { return fit_; }

    // With guiding_adaptive_prob: the learnt probabilities pay for the guided pipeline as a
    // whole (field.cpp); where they do not, every region's prob is 0.
    bool guiding_pays() const;
    // Some region samples its mixture or takes NEE with a probability below 1: the frames need
    // the guided pipeline.
    bool guides() const;

private:
    struct Region {
        VmmState state;
        std::vector<TrainingSample> pending;  // reservoir of non-zero samples since the last fit
        double seen_nonzero = 0, seen_zero = 0;
        Vec3 position_sum;
        double position_count = 0;
        uint64_t lit = 0;             // samples of non-zero weight since the region was made (refinement)
        uint64_t received_total = 0;  // incl. the parent's, for the GPU record
        FitReport last;
        SelectionStats selection_stats;  // guiding_adaptive_prob: decayed with the mixture's statistics
        Selection selection;             // chosen after the last fit
        NeeStats nee_stats;              // guiding_adaptive_nee: every record since the last fit ...
        double nee_prob = 1.0;           // ... and NEE's probability chosen then, from this many records
        double nee_records = 0.0;
    };
    Region make_region(uint32_t r) const;
    void fit_region(uint32_t r);
    void learn_selection(Region& reg);
    double region_prob(const Region& reg, bool pays) const;
    void refine(uint32_t r);
    size_t fit_threshold(const Region& reg) const;

    GuidingParams params_;
    FitOptions fit_;
    uint32_t seed_;
    uint32_t threads_;
    Aabb scene_;
    RegionTree tree_;
    std::vector<Region> regions_;
    uint64_t layout_version_ = 0;
    FieldStats stats_;
};

}  // namespace guiding
}  // namespace px
