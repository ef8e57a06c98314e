#include "techniques/guiding/selection.h"

#include <algorithm>
#include <cmath>

namespace px::guiding {

void SelectionStats::scale(double f) {
    for (double& v : score) v *= f;
    weight *= f;
    samples *= f;
}

void SelectionStats::add(double contribution, double pdf, double bsdf_pdf, double vmm_pdf, double scale) {
    if (!(contribution > 0.0 && pdf > 0.0 && bsdf_pdf > 0.0 && vmm_pdf >= 0.0) || !std::isfinite(contribution) ||
        !std::isfinite(pdf) || !std::isfinite(bsdf_pdf) || !std::isfinite(vmm_pdf))
        return;
    const double w = contribution / pdf * scale;
    for (uint32_t j = 0; j < kSelectionCandidates; ++j) {
        const double a = selection_candidate(j);
        score[j] += w * std::log(a * vmm_pdf + (1.0 - a) * bsdf_pdf);
    }
    weight += w;
}

Selection choose_selection(const SelectionStats& s, double margin, double fallback, double share) {
    Selection out;
    out.share = share;
    if (!(s.weight > 0.0)) {
        out.prob = fallback;
        return out;
    }
    uint32_t best = 0;
    for (uint32_t j = 1; j < kSelectionCandidates; ++j)
        if (s.score[j] > s.score[best]) best = j;
    if (best != 0 && !(share * (s.score[best] - s.score[0]) >= std::log(1.0 + margin) * s.weight)) best = 0;
    out.prob = selection_candidate(best);
    out.score_bsdf = s.score[0] / s.weight;
    out.score_chosen = s.score[best] / s.weight;
    out.weight = s.weight;
    return out;
}

void NeeStats::scale(double f) {
    records *= f;
    continuation *= f;
    traced *= f;
    lit *= f;
    light *= f;
}

void NeeStats::add(double contribution, double nee_light) {
    if (!std::isfinite(contribution) || !std::isfinite(nee_light) || contribution < 0.0) return;
    records += 1.0;
    continuation += contribution;
    if (nee_light < 0.0) return;
    traced += 1.0;
    lit += nee_light > 0.0 ? 1.0 : 0.0;
    light += nee_light;
}

double NeeStats::continuation_share() const {
    const double c = records > 0.0 ? continuation / records : 0.0, l = traced > 0.0 ? light / traced : 0.0;
    return c + l > 0.0 ? c / (c + l) : 1.0;
}

double choose_nee_prob(const NeeStats& s, double full_share, double min_prob, double min_traced) {
    if (!(s.traced >= min_traced)) return 1.0;
    return std::clamp((1.0 - s.continuation_share()) / full_share, min_prob, 1.0);
}

}  // namespace px::guiding
