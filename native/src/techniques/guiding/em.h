// Fitting a VMM to weighted directions (thesis 3.2.7; Ruppert, Herholz & Lensch 2020):
// weighted stepwise EM with MAP priors on the weights and the concentrations, with
// sufficient statistics carried from batch to batch, then splitting and merging of lobes.
#pragma once
#include "techniques/guiding/vmm.h"

#include <vector>

namespace px::guiding {

// Defaults: the reference's (TECHNIQUES.md) and Ruppert et al. 2020's.
struct FitOptions {
    uint32_t max_components = 16;      // <= kMaxComponents
    uint32_t initial_components = 8;   // lobes of a first fit, spread over the sphere
    double kappa0 = 5.0;               // their concentration
    double kappa_max = 5e4;
    uint32_t max_iterations = 100;     // EM iterations per batch
    double tolerance = 0.005;          // stop at this relative change of the log-likelihood
    double weight_prior = 0.01;        // Dirichlet pseudo-samples per lobe (MAP weights)
    double mean_cosine_prior = 0.0;    // MAP prior on a lobe's mean cosine (i.e. on kappa) ...
    double mean_cosine_prior_strength = 0.2;  // ... worth this many samples
    double decay = 0.75;               // stepwise EM: weight of the previous batches' statistics
    bool split_merge = true;
    double split_threshold = 0.5;      // a lobe splits at this chi^2 divergence ...
    double split_min_samples = 4096;   // ... when it has more samples than this
    double merge_threshold = 0.025;    // two lobes merge below this chi^2 metric ...
    double merge_min_samples = 8192;   // ... checked after this many new samples
    uint32_t max_batch = 16384;        // reservoir size of one region's batch (GuidingField)
};
// Throws std::invalid_argument naming the option out of range.
void validate_fit_options(const FitOptions& o);

// Sufficient statistics of one lobe, summed over samples i with responsibility g_i:
// weight = sum w g, direction = sum w g omega, count = sum g, inv_distance = sum w g / d.
struct ComponentStats {
    double weight = 0, count = 0, inv_distance = 0;
    Vec3 direction;
};
struct Statistics {
    std::array<ComponentStats, kMaxComponents> c{};
    void scale(double f);
    Statistics plus(const Statistics& o) const;
};

// A region's mixture and what it has learnt so far.
struct VmmState {
    Vmm vmm;
    Statistics stats;         // of all batches so far, older ones decayed
    double new_samples = 0;   // samples since the last merge check
    uint32_t fits = 0;
};

// One batch of a region: the samples with a non-zero weight (directions already reprojected
// with parallax). Zero-weight samples only count: total_samples includes them.
struct Batch {
    std::vector<Vec3> direction;
    std::vector<double> weight;        // radiance / pdf (>0)
    std::vector<double> pdf;           // density the direction was sampled with
    std::vector<double> inv_distance;  // 1 / distance to the light (0: infinitely far)
    double total_samples = 0;
    size_t size() const { return direction.size(); }
    void add(const Vec3& dir, double w, double p, double inv_d);
};

struct FitReport {
    bool fitted = false;
    uint32_t iterations = 0;
    double log_likelihood = 0;  // weighted mean log density of the batch
    uint32_t splits = 0, merges = 0;
};

// Lobes of a first fit: a Fibonacci sphere of initial_components directions, kappa0, equal weights.
void initialise(Vmm& m, const FitOptions& o);

// Fits one batch (Ruppert et al. 2020): EM with the previous statistics decayed, then split
// and merge. Does nothing (fitted = false) unless the batch has more than 2K samples.
FitReport fit_batch(VmmState& s, const Batch& b, const FitOptions& o);

// Parts of fit_batch (tests).
// EM iterations on b with `previous` statistics; s.stats = previous + this batch's.
uint32_t run_em(VmmState& s, const Batch& b, const FitOptions& o, const Statistics& previous, double& log_likelihood);
// M-step: the MAP mixture of the statistics.
void m_step(Vmm& m, const Statistics& st, const FitOptions& o);
// Each lobe's share of the chi^2 divergence between the batch's radiance and the mixture.
std::vector<double> split_divergence(const Vmm& m, const Batch& b);
// Splits the lobes whose divergence exceeds the threshold (PCA split); refit follows.
uint32_t split_components(VmmState& s, const Batch& b, const FitOptions& o, Statistics& previous);
// chi^2 divergence between lobes k, l (as their sub-mixture) and the single lobe `merged`.
double merge_metric(const Vmm& m, uint32_t k, uint32_t l, const Vec3& merged_mu, double merged_kappa);
// Merges pairs of lobes while the best pair's metric is below the threshold.
uint32_t merge_components(VmmState& s, const FitOptions& o);

}  // namespace px::guiding
