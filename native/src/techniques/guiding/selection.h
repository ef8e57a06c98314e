// The guiding probability learnt per region (issue 35): the probability of sampling the mixture
// rather than the BSDF at a guided vertex, chosen to minimise the second moment of the
// one-sample MIS estimator (Müller et al. 2019/2020 learn the same BSDF-sampling fraction by
// gradient descent; here a grid of candidates is scored on the training records, which is
// deterministic and needs no learning rate). A record sampled with density p (the mixture of
// the time) that brought contribution C along its direction w scores candidate a by
//   M(a) += C^2 p / (a p_vmm(w) + (1 - a) p_bsdf(w)),
// an unbiased estimate of the second moment E[(g / p_a)^2] of sampling with a (g: the
// integrand; importance sampling of the records' own density). p_vmm is the freshly fitted
// mixture's, so the score judges the mixture the next frames will sample. A mixture costs its
// evaluations at every guided vertex: a candidate a > 0 must beat BSDF sampling alone (a = 0,
// no mixture read at all) by GUIDING_SELECTION_MARGIN.
#pragma once
#include "techniques/guiding/vmm.h"

#include <array>

namespace px::guiding {

// Candidates a_j = j / kSelectionCandidates, j = 0 .. kSelectionCandidates - 1: never 1, so the
// BSDF keeps covering what the mixture misses. (The device fit's too: fit.comp.)
constexpr uint32_t kSelectionCandidates = GUIDING_SELECTION_CANDIDATES;
inline double selection_candidate(uint32_t j) { return double(j) / kSelectionCandidates; }

struct SelectionStats {
    std::array<double, kSelectionCandidates> moment{};  // sum of C^2 p / p_a
    double samples = 0;                                  // records they stand for, unlit ones included
    void scale(double f);
    // One record with contribution > 0 (`scale`: records it stands for, reservoir subsampling).
    // Records of a delta lobe (bsdf_pdf 0) or with a density that is not finite are left out.
    void add(double contribution, double pdf, double bsdf_pdf, double vmm_pdf, double scale = 1.0);
};

struct Selection {
    double prob = 0;
    double moment_bsdf = 0, moment_chosen = 0;  // per record: M(0) and M(prob)
};

// The candidate of least second moment, 0 unless it beats BSDF sampling alone by `margin`
// (relative). `fallback` where the stats hold nothing.
Selection choose_selection(const SelectionStats& s, double margin, double fallback);

}  // namespace px::guiding
