#include "techniques/guiding/field.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <string>
#include <thread>

namespace px {

// The ranges are guiding_table()'s (guiding.cpp); what remains relates settings.
void validate_guiding_params(const GuidingParams& p) {
    check_settings(&p, guiding_table().settings);
    if (p.max_regions < (1u << p.region_splits))
        throw std::invalid_argument("guiding_max_regions must be at least 2^guiding_region_splits (" +
                                    std::to_string(1u << p.region_splits) + "), got " + std::to_string(p.max_regions));
    if (!(p.lobes_phase == -1.0f || (p.lobes_phase >= 0.0f && p.lobes_phase < 1.0f)))
        throw std::invalid_argument("guiding_lobes_phase must be -1 (spheres at the regions' centres) or in [0, 1)");
}

namespace guiding {

namespace {

uint64_t splitmix64(uint64_t x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

bool contains(const Aabb& b, const Vec3& p, double pad) {
    return p.x >= b.lo.x - pad && p.x <= b.hi.x + pad && p.y >= b.lo.y - pad && p.y <= b.hi.y + pad &&
           p.z >= b.lo.z - pad && p.z <= b.hi.z + pad;
}

}  // namespace

GuidingField::GuidingField(const GuidingParams& params, const float scene_min[3], const float scene_max[3],
                           uint32_t seed, const FitOptions& fit, uint32_t threads)
    : params_(params), fit_(fit), seed_(seed) {
    validate_guiding_params(params);
    fit_.max_components = params.max_components;
    fit_.initial_components = std::min(fit_.initial_components, fit_.max_components);
    fit_.split_merge = params.split_merge != 0;
    validate_fit_options(fit_);
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(scene_min[a]) || !std::isfinite(scene_max[a]) || scene_min[a] > scene_max[a])
            throw std::invalid_argument("guiding: the scene bounds must be finite with min <= max");
    scene_.lo = {scene_min[0], scene_min[1], scene_min[2]};
    scene_.hi = {scene_max[0], scene_max[1], scene_max[2]};
    // A flat or empty scene still gets boxes with volume.
    const double pad = 1e-4 * (length(scene_.extent()) + 1e-3);
    scene_.lo = scene_.lo - Vec3(pad, pad, pad);
    scene_.hi = scene_.hi + Vec3(pad, pad, pad);
    threads_ = threads ? threads : std::max(1u, std::thread::hardware_concurrency());
    reset();
}

GuidingField::Region GuidingField::make_region(uint32_t r) const {
    Region reg;
    const Aabb& b = tree_.bounds(r);
    reg.state.vmm.pivot = (b.lo + b.hi) * 0.5;
    return reg;
}

void GuidingField::reset() {
    tree_.build(scene_, params_.region_splits);
    regions_.clear();
    for (uint32_t r = 0; r < tree_.size(); ++r) regions_.push_back(make_region(r));
    ++layout_version_;
    stats_ = FieldStats{};
    stats_.regions = uint32_t(regions_.size());
}

void GuidingField::add_samples(const GuidingSample* samples, size_t count) {
    const size_t cap = std::max<size_t>(fit_.max_batch, params_.min_samples);
    const double pad = 1e-6 * length(scene_.extent());
    for (size_t i = 0; i < count; ++i) {
        const GuidingSample& s = samples[i];
        const Vec3 p(s.position.x, s.position.y, s.position.z);
        if (!finite(p) || !std::isfinite(s.weight) || s.weight < 0.0f || !(s.pdf > 0.0f) || !std::isfinite(s.pdf) ||
            std::isnan(s.distance)) {
            ++stats_.samples_dropped;
            continue;
        }
        uint32_t r = s.region;
        if (r >= regions_.size() || !contains(tree_.bounds(r), p, pad)) r = tree_.lookup(p);
        if (r == NO_INDEX) {
            ++stats_.samples_dropped;
            continue;
        }
        ++stats_.samples_added;
        Region& reg = regions_[r];
        reg.position_sum += p;
        reg.position_count += 1.0;
        ++reg.received_total;
        reg.nee_stats.add(s.contribution, s.nee_light);
        if (s.weight == 0.0f) {
            reg.seen_zero += 1.0;
            continue;
        }
        reg.seen_nonzero += 1.0;
        ++reg.lit;
        const Vec3 w = unpack_direction(s.direction);
        const TrainingSample t{{s.position.x, s.position.y, s.position.z},
                               {float(w.x), float(w.y), float(w.z)},
                               s.pdf,
                               s.weight,
                               s.distance,
                               s.bsdf_pdf,
                               s.contribution};
        if (reg.pending.size() < cap) {
            reg.pending.push_back(t);
        } else {  // reservoir sampling (Vitter's algorithm R), a hash of (seed, region, count)
            const uint64_t n = uint64_t(reg.seen_nonzero);
            const uint64_t j = splitmix64((uint64_t(seed_) << 32) ^ (uint64_t(r) * 0x9e3779b1ull) ^ splitmix64(n)) % n;
            if (j < cap) reg.pending[j] = t;
        }
    }
}

size_t GuidingField::fit_threshold(const Region& reg) const {
    const uint32_t k = reg.state.vmm.count ? reg.state.vmm.count : fit_.initial_components;
    return std::max<size_t>(params_.min_samples, 2 * size_t(k) + 1);
}

void GuidingField::fit_region(uint32_t r) {
    Region& reg = regions_[r];
    const Aabb& box = tree_.bounds(r);
    const Vec3 pivot = reg.position_count > 0.0 ? reg.position_sum * (1.0 / reg.position_count) : (box.lo + box.hi) * 0.5;
    const bool parallax = params_.parallax != 0;
    if (parallax) move_pivot(reg.state, pivot);
    else reg.state.vmm.pivot = pivot;
    const double scale = reg.seen_nonzero / double(reg.pending.size());
    const Batch b = make_batch(reg.pending.data(), reg.pending.size(), scale, reg.seen_nonzero + reg.seen_zero, pivot,
                               parallax);
    reg.last = fit_batch(reg.state, b, fit_);
    if (reg.last.fitted) {
        learn_selection(reg);
        if (params_.adaptive_nee) {  // from every record since the last fit, older ones decayed
            reg.nee_prob = choose_nee_prob(reg.nee_stats, GUIDING_NEE_SHARE, GUIDING_NEE_MIN_PROB);
            reg.nee_records = reg.nee_stats.records;
        }
        reg.nee_stats.scale(fit_.decay);
        reg.pending.clear();
        reg.seen_nonzero = reg.seen_zero = 0.0;
    }
}

// The guiding probability (selection.h), from the batch just fitted, scored with the new mixture
// at each sample's own position and direction (as the sampler evaluates it), on top of the
// earlier batches' scores decayed as the mixture's statistics are.
void GuidingField::learn_selection(Region& reg) {
    if (!params_.adaptive_prob) return;
    const bool parallax = params_.parallax != 0;
    const double scale = reg.seen_nonzero / double(reg.pending.size());
    reg.selection_stats.scale(fit_.decay);
    for (const TrainingSample& t : reg.pending) {
        const Vec3 x(t.position[0], t.position[1], t.position[2]);
        const Vec3 w = normalize(Vec3(t.direction[0], t.direction[1], t.direction[2]));
        reg.selection_stats.add(t.contribution, t.pdf, t.bsdf_pdf, reg.state.vmm.pdf(w, x, parallax), scale);
    }
    reg.selection_stats.samples += reg.seen_nonzero + reg.seen_zero;
    reg.selection = choose_selection(reg.selection_stats, GUIDING_SELECTION_MARGIN, params_.prob,
                                     reg.nee_stats.continuation_share());
}

// With guiding_adaptive_prob, whether the learnt probabilities pay for the guided pipeline as a
// whole: the score they gain (selection.h), summed over the regions, against its cost
// (GUIDING_SELECTION_MARGIN; a region that gains alone is not enough where the others lose
// the pipeline's cost: veach_mis guided one glossy region at 1.3x the cost of every path).
// Where they do not, no region samples its mixture: the session then traces the plain
// pipeline (Guiding::spec_bit). True while nothing has been learnt.
bool GuidingField::guiding_pays() const {
    if (!params_.adaptive_prob) return true;
    double gain = 0.0, weight = 0.0;
    for (const Region& reg : regions_) {
        gain += reg.selection.gain() * reg.selection.weight;
        weight += reg.selection.weight;
    }
    return selection_pays(gain, weight, GUIDING_SELECTION_MARGIN);
}

// Whether the frames need the guided pipeline: some region samples its mixture, or NEE is
// thinned where most of the vertices are (the guided pipeline costs every path some 15-20%
// on lavapipe: thinning NEE in a few regions of the sun room did not pay for it, 1.29x MIS's
// error at equal time; in the glass scenes it is thinned everywhere).
bool GuidingField::guides() const {
    const bool pays = guiding_pays();
    double records = 0.0, thinned = 0.0;
    for (const Region& reg : regions_) {
        if (reg.state.vmm.count > 0 && region_prob(reg, pays) > 0.0) return true;
        records += reg.nee_records;
        if (params_.adaptive_nee && reg.nee_prob < 1.0) thinned += reg.nee_records;
    }
    return records > 0.0 && thinned >= 0.5 * records;
}

// The sampler's probability of the mixture: guiding_prob until the region has learnt its own.
double GuidingField::region_prob(const Region& reg, bool pays) const {
    if (!params_.adaptive_prob) return params_.prob;
    if (!pays) return 0.0;
    return reg.selection_stats.weight > 0.0 ? reg.selection.prob : params_.prob;
}

void GuidingField::refine(uint32_t r) {
    const uint32_t u = tree_.split(r);
    Region& parent = regions_[r];
    parent.state.stats.scale(0.5);  // each child inherits half of the evidence
    parent.state.new_samples *= 0.5;
    parent.selection_stats.scale(0.5);
    Region child;
    child.state = parent.state;
    child.received_total = parent.received_total;
    child.selection_stats = parent.selection_stats;
    child.selection = parent.selection;
    parent.nee_stats.scale(0.5);
    child.nee_stats = parent.nee_stats;
    child.nee_prob = parent.nee_prob;
    std::vector<TrainingSample> lower, upper;
    for (const TrainingSample& t : parent.pending)
        (tree_.lookup(Vec3(t.position[0], t.position[1], t.position[2])) == u ? upper : lower).push_back(t);
    const double kept = double(parent.pending.size());
    const double fl = kept > 0 ? lower.size() / kept : 0.5, fu = kept > 0 ? upper.size() / kept : 0.5;
    child.seen_nonzero = parent.seen_nonzero * fu;
    child.seen_zero = parent.seen_zero * fu;
    parent.seen_nonzero *= fl;
    parent.seen_zero *= fl;
    child.pending = std::move(upper);
    parent.pending = std::move(lower);
    parent.position_sum = Vec3();
    parent.position_count = 0.0;
    parent.lit = 0;
    regions_.push_back(std::move(child));
}

const FieldStats& GuidingField::fit() {
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<uint32_t> jobs;
    for (uint32_t r = 0; r < regions_.size(); ++r)
        if (regions_[r].pending.size() >= fit_threshold(regions_[r])) jobs.push_back(r);
    // Regions fit independently (no shared state), so the result does not depend on which
    // thread fits which region.
    std::atomic<size_t> next{0};
    auto worker = [&] {
        for (size_t i; (i = next.fetch_add(1)) < jobs.size();) fit_region(jobs[i]);
    };
    const size_t n_threads = std::min<size_t>(threads_, jobs.size());
    if (n_threads <= 1) {
        worker();
    } else {
        std::vector<std::thread> pool;
        for (size_t t = 0; t < n_threads; ++t) pool.emplace_back(worker);
        for (auto& t : pool) t.join();
    }
    stats_.regions_fitted = stats_.splits = stats_.merges = stats_.em_iterations = stats_.refinements = 0;
    for (uint32_t r : jobs) {
        const FitReport& rep = regions_[r].last;
        if (!rep.fitted) continue;
        ++stats_.regions_fitted;
        stats_.splits += rep.splits;
        stats_.merges += rep.merges;
        stats_.em_iterations += rep.iterations;
    }
    stats_.region_fits += stats_.regions_fitted;
    // Adaptive refinement (thesis 4.6.3), in region order: deterministic.
    if (params_.region_threshold > 0) {
        const double min_extent = 1e-6 * length(scene_.extent());
        const size_t n = regions_.size();
        for (uint32_t r = 0; r < n && regions_.size() < params_.max_regions; ++r) {
            // Only a region with a mixture splits (its children inherit it): splitting untrained
            // regions would divide their few lit samples where light is rare and keep them from
            // ever reaching min_samples.
            if (regions_[r].lit <= params_.region_threshold || regions_[r].state.vmm.count == 0) continue;
            const Aabb& b = tree_.bounds(r);
            if (b.extent()[b.longest_axis()] <= min_extent) continue;
            refine(r);
            ++stats_.refinements;
        }
        if (stats_.refinements) ++layout_version_;
    }
    stats_.regions = uint32_t(regions_.size());
    stats_.fit_milliseconds =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    return stats_;
}

RegionInfo GuidingField::region_info(uint32_t r) const {
    const Region& reg = regions_.at(r);
    RegionInfo i;
    i.samples = reg.received_total;
    i.pending = uint32_t(reg.pending.size());
    i.seen = reg.seen_nonzero;
    i.components = reg.state.vmm.count;
    i.fits = reg.state.fits;
    i.selection = reg.selection;
    i.region_choice = region_prob(reg, true);
    i.selection.prob = region_prob(reg, guiding_pays());
    i.nee_prob = params_.adaptive_nee ? reg.nee_prob : 1.0;
    return i;
}

void GuidingField::write_regions(std::vector<GuidingRegion>& out) const {
    out.resize(regions_.size());
    const bool pays = guiding_pays();
    for (uint32_t r = 0; r < regions_.size(); ++r) {
        const Aabb& b = tree_.bounds(r);
        const Region& reg = regions_[r];
        GuidingRegion& g = out[r];
        g.aabb_min = {float(b.lo.x), float(b.lo.y), float(b.lo.z)};
        g.aabb_max = {float(b.hi.x), float(b.hi.y), float(b.hi.z)};
        g.lobe_count = reg.state.vmm.count;
        g.fits = reg.state.fits;
        const Vec3& p = reg.state.vmm.pivot;
        g.pivot = {float(p.x), float(p.y), float(p.z)};
        g.samples = uint32_t(std::min<uint64_t>(reg.received_total, 0xffffffffu));
        g.prob = float(region_prob(reg, pays));
        g.nee_prob = params_.adaptive_nee ? float(reg.nee_prob) : 1.0f;
        g.score_bsdf = float(reg.selection.score_bsdf);
        g.score_chosen = float(reg.selection.score_chosen);
    }
}

void GuidingField::write_lobes(std::vector<GuidingLobe>& out) const {
    out.resize(regions_.size() * GUIDING_MAX_COMPONENTS);
    for (uint32_t r = 0; r < regions_.size(); ++r)
        write_gpu_lobes(regions_[r].state.vmm, params_.parallax != 0, &out[size_t(r) * GUIDING_MAX_COMPONENTS]);
}

void GuidingField::write_aabbs(std::vector<float>& out) const { tree_.write_aabbs(out); }

}  // namespace guiding
}  // namespace px
