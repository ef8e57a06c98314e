#include "techniques/guiding/selection.h"

#include <cmath>

namespace px::guiding {

void SelectionStats::scale(double f) {
    for (double& m : moment) m *= f;
    samples *= f;
}

void SelectionStats::add(double contribution, double pdf, double bsdf_pdf, double vmm_pdf, double scale) {
    if (!(contribution > 0.0 && pdf > 0.0 && bsdf_pdf > 0.0 && vmm_pdf >= 0.0) || !std::isfinite(contribution) ||
        !std::isfinite(pdf) || !std::isfinite(bsdf_pdf) || !std::isfinite(vmm_pdf))
        return;
    const double c2p = contribution * contribution * pdf * scale;
    for (uint32_t j = 0; j < kSelectionCandidates; ++j) {
        const double a = selection_candidate(j);
        moment[j] += c2p / (a * vmm_pdf + (1.0 - a) * bsdf_pdf);
    }
}

Selection choose_selection(const SelectionStats& s, double margin, double fallback) {
    Selection out;
    if (!(s.samples > 0.0) || !(s.moment[0] > 0.0)) {
        out.prob = fallback;
        return out;
    }
    uint32_t best = 0;
    for (uint32_t j = 1; j < kSelectionCandidates; ++j)
        if (s.moment[j] < s.moment[best]) best = j;
    if (best != 0 && !(s.moment[best] * (1.0 + margin) < s.moment[0])) best = 0;
    out.prob = selection_candidate(best);
    out.moment_bsdf = s.moment[0] / s.samples;
    out.moment_chosen = s.moment[best] / s.samples;
    return out;
}

}  // namespace px::guiding
