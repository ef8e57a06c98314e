// The guiding probability learnt per region (issue 35): the probability of sampling the mixture
// rather than the BSDF at a guided vertex. Müller et al. (2019, "Practical path guiding in
// production") learn this BSDF-sampling fraction by gradient descent on the KL divergence
// between the one-sample MIS density p_a = a p_vmm + (1 - a) p_bsdf and the integrand; here a
// grid of candidates is scored on the training records, which is deterministic and needs no
// learning rate. A record sampled with density p (the mixture of the time) that brought
// contribution C along its direction w adds to candidate a
//   S(a) += (C / p) log(a p_vmm(w) + (1 - a) p_bsdf(w)),
// so that S(a) / sum(C / p) estimates E_target[log p_a], the cross-entropy that KL(target || p_a)
// differs from by a constant: the larger, the closer p_a is to the integrand. It is linear in
// C, so the noise of the paths below the vertex averages out (a score of C^2, the second
// moment, is dominated by it: it saw a 10% gain where guiding cut the image's error 8x).
// p_vmm is the freshly fitted mixture's, so the score judges the mixture the next frames will
// sample. A mixture costs its evaluations at every guided vertex: a candidate a > 0 must gain
// log(1 + GUIDING_SELECTION_MARGIN) nats per unit of weight over BSDF sampling alone (a = 0,
// no mixture read at all), the density on the integrand 1 + margin times as high (geometric
// mean).
#pragma once
#include "techniques/guiding/vmm.h"

#include <array>
#include <cmath>

namespace px::guiding {

// Candidates a_j = j / kSelectionCandidates, j = 0 .. kSelectionCandidates - 1: never 1, so the
// BSDF keeps covering what the mixture misses. (The device fit's too: fit.comp.)
constexpr uint32_t kSelectionCandidates = GUIDING_SELECTION_CANDIDATES;
inline double selection_candidate(uint32_t j) { return double(j) / kSelectionCandidates; }

struct SelectionStats {
    std::array<double, kSelectionCandidates> score{};  // sum of (C / p) log p_a
    double weight = 0;                                  // sum of C / p
    double samples = 0;                                 // records they stand for, unlit ones included
    void scale(double f);
    // One record with contribution > 0 (`scale`: records it stands for, reservoir subsampling).
    // Records of a delta lobe (bsdf_pdf 0) or with a density that is not finite are left out.
    void add(double contribution, double pdf, double bsdf_pdf, double vmm_pdf, double scale = 1.0);
};

struct Selection {
    double prob = 0;
    double score_bsdf = 0, score_chosen = 0;  // per unit of weight: S(0) and S(prob) (mean log density)
    double weight = 0;                        // SelectionStats::weight
    double share = 1;                         // the continuation's share of the vertices' light
    double gain() const { return share * (score_chosen - score_bsdf); }
};

// The candidate of largest score, 0 unless its gain over BSDF sampling alone, times `share`,
// reaches log(1 + margin). `share` (NeeStats::continuation_share): guiding only changes the
// continuation's part of a vertex's estimate, so where NEE brings most of the light (veach_mis'
// plates: gains of 0.5-1.9 nats, and guiding lost 1.4x at equal time) a gain counts that much
// less. `fallback` where the stats hold nothing.
Selection choose_selection(const SelectionStats& s, double margin, double fallback, double share = 1.0);

// The global rule (GuidingField::guiding_pays, DeviceFit::guiding_pays): the regions' gains
// summed with their weights reach log(1 + margin) per unit of weight; true with no weight yet.
inline bool selection_pays(double weighted_gain, double weight, double margin) {
    return !(weight > 0.0) || weighted_gain >= std::log(1.0 + margin) * weight;
}

// NEE's probability learnt per region (guiding_adaptive_nee; issue 35, "learn where NEE pays"):
// NEE is taken with probability q (its light then counts 1 / q; MIS weights use q times the
// light pdf, integrator.glsl), q = NEE's share of the light at the region's vertices (as if
// always taken) over GUIDING_NEE_SHARE, at least GUIDING_NEE_MIN_PROB and at most 1: NEE in full
// wherever it brings a fair part of the light, a tenth of the shadow rays where they bring none
// (a lamp behind glass). Measured alternatives: a variance-optimal q = sqrt(B / (A c)) from the
// records' second moments thinned NEE in the Cornell box (A, the continuation's, holds the
// noise of the whole path below the vertex: 1.7x the error at equal time); q from the fraction
// of shadow rays that reach a light thinned it in the sun room's shade, where the rare lit ones
// carry the sun (1.27x).
struct NeeStats {
    double records = 0, continuation = 0;  // every record: count, sum of contribution
    double traced = 0, lit = 0, light = 0;  // records whose vertex traced a shadow ray: count, lit, sum of light
    void scale(double f);
    // One record (nee_light < 0: no shadow ray traced at its vertex).
    void add(double contribution, double nee_light);
    // The continuation's share of the light at the region's vertices, NEE's counted as if always taken.
    double continuation_share() const;
};
// q; 1 until the stats hold min_traced shadow rays.
double choose_nee_prob(const NeeStats& s, double full_share, double min_prob, double min_traced = 32);

}  // namespace px::guiding
