#include "techniques/guiding/em.h"

#include <algorithm>
#include <numeric>
#include <stdexcept>
#include <string>

namespace px::guiding {

void validate_fit_options(const FitOptions& o) {
    auto fail = [](const std::string& what) { throw std::invalid_argument("guiding fit: " + what); };
    if (o.max_components < 1 || o.max_components > kMaxComponents)
        fail("max_components must be in [1, " + std::to_string(kMaxComponents) + "]");
    if (o.initial_components < 1 || o.initial_components > o.max_components)
        fail("initial_components must be in [1, max_components]");
    if (!(o.kappa0 >= 0.0) || !(o.kappa_max > o.kappa0) || !std::isfinite(o.kappa_max))
        fail("need 0 <= kappa0 < kappa_max < inf");
    if (o.max_iterations < 1) fail("max_iterations must be at least 1");
    if (!(o.tolerance >= 0.0)) fail("tolerance must be >= 0");
    if (!(o.weight_prior >= 0.0) || !(o.mean_cosine_prior_strength >= 0.0)) fail("priors must be >= 0");
    if (!(o.mean_cosine_prior >= 0.0 && o.mean_cosine_prior < 1.0)) fail("mean_cosine_prior must be in [0, 1)");
    if (!(o.decay >= 0.0 && o.decay <= 1.0)) fail("decay must be in [0, 1]");
    if (!(o.split_threshold > 0.0) || !(o.merge_threshold >= 0.0)) fail("split/merge thresholds out of range");
    if (!(o.split_min_samples >= 0.0) || !(o.merge_min_samples >= 0.0)) fail("split/merge sample counts must be >= 0");
    if (o.max_batch < 2 * kMaxComponents + 1) fail("max_batch must be at least 2 * 16 + 1");
}

void Statistics::scale(double f) {
    for (auto& s : c) {
        s.weight *= f;
        s.count *= f;
        s.inv_distance *= f;
        s.direction = s.direction * f;
    }
}

Statistics Statistics::plus(const Statistics& o) const {
    Statistics r = *this;
    for (uint32_t k = 0; k < kMaxComponents; ++k) {
        r.c[k].weight += o.c[k].weight;
        r.c[k].count += o.c[k].count;
        r.c[k].inv_distance += o.c[k].inv_distance;
        r.c[k].direction += o.c[k].direction;
    }
    return r;
}

void Batch::add(const Vec3& dir, double w, double p, double inv_d) {
    direction.push_back(dir);
    weight.push_back(w);
    pdf.push_back(p);
    inv_distance.push_back(inv_d);
}

void initialise(Vmm& m, const FitOptions& o) {
    const uint32_t n = std::min(o.initial_components, o.max_components);
    const double golden = kPi * (3.0 - std::sqrt(5.0));
    m.count = n;
    for (uint32_t k = 0; k < n; ++k) {
        const double z = 1.0 - (2.0 * k + 1.0) / n;
        const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
        m.mu[k] = {r * std::cos(golden * k), r * std::sin(golden * k), z};
        m.kappa[k] = o.kappa0;
        m.weight[k] = 1.0 / n;
        m.distance[k] = kInfinity;
    }
}

namespace {

// The mixture's lobes prepared for many evaluations: log(pi_k C_k) once per E-step.
struct Lobes {
    uint32_t count = 0;
    double log_wc[kMaxComponents], kappa[kMaxComponents];
    Vec3 mu[kMaxComponents];
    explicit Lobes(const Vmm& m) : count(m.count) {
        for (uint32_t k = 0; k < count; ++k) {
            const bool uniform = m.kappa[k] < kKappaMin;
            log_wc[k] = m.weight[k] > 0.0 ? std::log(m.weight[k]) + vmf_log_norm(m.kappa[k]) : -HUGE_VAL;
            kappa[k] = uniform ? 0.0 : m.kappa[k];
            mu[k] = m.mu[k];
        }
    }
};

// Responsibilities of every lobe for direction w (log-sum-exp); returns log V(w).
double responsibilities(const Lobes& m, const Vec3& w, double* g) {
    double mx = -HUGE_VAL;
    for (uint32_t k = 0; k < m.count; ++k) {
        const Vec3 d = m.mu[k] - w;
        g[k] = m.log_wc[k] - 0.5 * m.kappa[k] * dot(d, d);
        mx = std::max(mx, g[k]);
    }
    if (!std::isfinite(mx)) {
        std::fill(g, g + m.count, 0.0);
        return -HUGE_VAL;
    }
    double sum = 0.0;
    for (uint32_t k = 0; k < m.count; ++k) sum += (g[k] = std::exp(g[k] - mx));
    const double inv = 1.0 / sum;
    for (uint32_t k = 0; k < m.count; ++k) g[k] *= inv;
    return mx + std::log(sum);
}

// E-step: this batch's statistics under m; returns the weighted mean log-likelihood.
double e_step(const Vmm& mix, const Batch& b, Statistics& st) {
    const Lobes m(mix);
    double g[kMaxComponents];
    double ll = 0.0, wsum = 0.0;
    for (size_t i = 0; i < b.size(); ++i) {
        const double w = b.weight[i];
        const double logv = responsibilities(m, b.direction[i], g);
        if (std::isfinite(logv)) {
            ll += w * logv;
            wsum += w;
        }
        for (uint32_t k = 0; k < m.count; ++k) {
            auto& c = st.c[k];
            const double wg = w * g[k];
            c.weight += wg;
            c.count += g[k];
            c.inv_distance += wg * b.inv_distance[i];
            c.direction += b.direction[i] * wg;
        }
    }
    return wsum > 0.0 ? ll / wsum : -HUGE_VAL;
}

// MAP direction and concentration of one lobe's statistics worth n effective samples
// (Ruppert et al. 2020: the mean cosine is pulled towards the prior by a pseudo-count).
void lobe_from_stats(const ComponentStats& c, double n, const FitOptions& o, Vec3& mu, double& kappa) {
    const double rl = length(c.direction);
    if (rl > 0.0) mu = c.direction * (1.0 / rl);
    double r = c.weight > 0.0 ? std::min(rl / c.weight, 1.0) : 0.0;
    const double a = o.mean_cosine_prior_strength;
    r = n + a > 0.0 ? (r * n + o.mean_cosine_prior * a) / (n + a) : o.mean_cosine_prior;
    r = std::min(r, mean_cosine(o.kappa_max));
    kappa = std::min(kappa_from_mean_cosine(r), o.kappa_max);
}

}  // namespace

void m_step(Vmm& m, const Statistics& st, const FitOptions& o) {
    double W = 0.0, N = 0.0;
    for (uint32_t k = 0; k < m.count; ++k) {
        W += st.c[k].weight;
        N += st.c[k].count;
    }
    if (!(W > 0.0)) return;
    const double v = o.weight_prior;
    for (uint32_t k = 0; k < m.count; ++k) {
        const auto& c = st.c[k];
        const double n = N * c.weight / W;  // effective samples of lobe k
        m.weight[k] = (n + v) / (N + m.count * v);
        lobe_from_stats(c, n, o, m.mu[k], m.kappa[k]);
        m.distance[k] = c.inv_distance > 0.0 ? c.weight / c.inv_distance : kInfinity;  // harmonic mean
    }
}

uint32_t run_em(VmmState& s, const Batch& b, const FitOptions& o, const Statistics& previous, double& log_likelihood) {
    double prev_ll = 0.0;
    uint32_t it = 0;
    while (it < o.max_iterations) {
        Statistics batch;
        const double ll = e_step(s.vmm, b, batch);
        s.stats = previous.plus(batch);
        m_step(s.vmm, s.stats, o);
        log_likelihood = ll;
        ++it;
        if (it > 1 && std::abs(ll - prev_ll) <= o.tolerance * std::abs(prev_ll)) break;
        prev_ll = ll;
    }
    return it;
}

std::vector<double> split_divergence(const Vmm& m, const Batch& b) {
    // chi^2(f || V) = int (f - V)^2 / V = E_q[g f^2 / (V q)] - 2 E_q[g f / q] + pi_k per lobe,
    // with f = L / int L estimated as w q / mean(w) (zero-weight samples count in the mean);
    // the last term is exact, so only samples with a non-zero weight are needed.
    std::vector<double> d(m.count, 0.0);
    double wsum = 0.0;
    for (double w : b.weight) wsum += w;
    const double n_all = std::max(b.total_samples, double(b.size()));
    if (!(wsum > 0.0)) return d;
    const double mean_w = wsum / n_all;
    double g[kMaxComponents];
    const Lobes lobes(m);
    for (size_t i = 0; i < b.size(); ++i) {
        const double logv = responsibilities(lobes, b.direction[i], g);
        const double q = b.pdf[i];
        const double f = b.weight[i] * q / mean_w;
        const double term = f * f / (std::exp(logv) * q) - 2.0 * f / q;
        if (!std::isfinite(term)) continue;
        for (uint32_t k = 0; k < m.count; ++k) d[k] += g[k] * term;
    }
    for (uint32_t k = 0; k < m.count; ++k) d[k] = d[k] / n_all + m.weight[k];
    return d;
}

uint32_t split_components(VmmState& s, const Batch& b, const FitOptions& o, Statistics& previous) {
    Vmm& m = s.vmm;
    const std::vector<double> div = split_divergence(m, b);
    double W = 0.0, N = 0.0;
    for (uint32_t k = 0; k < m.count; ++k) {
        W += s.stats.c[k].weight;
        N += s.stats.c[k].count;
    }
    if (!(W > 0.0)) return 0;
    std::vector<uint32_t> order;
    for (uint32_t k = 0; k < m.count; ++k)
        if (div[k] >= o.split_threshold && N * s.stats.c[k].weight / W > o.split_min_samples) order.push_back(k);
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t c) { return div[a] > div[c]; });

    uint32_t splits = 0;
    double g[kMaxComponents];
    const Lobes before(m);  // responsibilities refer to the mixture before any split
    for (uint32_t k : order) {
        if (m.count >= o.max_components) break;
        // PCA of lobe k's samples in the tangent plane of its mean: split along the main axis.
        Vec3 t, bt;
        make_basis(m.mu[k], t, bt);
        double sw = 0, mx = 0, my = 0, sxx = 0, sxy = 0, syy = 0;
        for (size_t i = 0; i < b.size(); ++i) {
            responsibilities(before, b.direction[i], g);
            const double w = b.weight[i] * g[k];
            if (!(w > 0.0)) continue;
            const double x = dot(b.direction[i], t), y = dot(b.direction[i], bt);
            sw += w;
            mx += w * x;
            my += w * y;
            sxx += w * x * x;
            sxy += w * x * y;
            syy += w * y * y;
        }
        if (!(sw > 0.0)) continue;
        mx /= sw;
        my /= sw;
        const double cxx = sxx / sw - mx * mx, cxy = sxy / sw - mx * my, cyy = syy / sw - my * my;
        const double half = 0.5 * (cxx + cyy), diff = 0.5 * (cxx - cyy);
        const double lambda = half + std::sqrt(diff * diff + cxy * cxy);
        if (!(lambda > 0.0)) continue;
        double ex = 1.0, ey = 0.0;
        if (std::abs(cxy) > 1e-300) {
            ex = lambda - cyy;
            ey = cxy;
        } else if (cyy > cxx) {
            ex = 0.0;
            ey = 1.0;
        }
        const double el = std::sqrt(ex * ex + ey * ey);
        const Vec3 centre = m.mu[k] + t * mx + bt * my;
        const Vec3 offset = (t * ex + bt * ey) * (std::sqrt(lambda) / el);
        const uint32_t j = m.count++;
        m.mu[j] = normalize(centre - offset);
        m.mu[k] = normalize(centre + offset);
        m.kappa[j] = m.kappa[k];
        m.weight[k] *= 0.5;
        m.weight[j] = m.weight[k];
        m.distance[j] = m.distance[k];
        // The lobes' history goes half to each child, along the child's direction.
        for (Statistics* st : {&previous, &s.stats}) {
            ComponentStats& c = st->c[k];
            const double r = 0.5 * length(c.direction);
            c.weight *= 0.5;
            c.count *= 0.5;
            c.inv_distance *= 0.5;
            st->c[j] = c;
            c.direction = m.mu[k] * r;
            st->c[j].direction = m.mu[j] * r;
        }
        ++splits;
    }
    return splits;
}

namespace {

// log of int v_i v_j / v_m over the sphere, in closed form: the integrand is exp(eta.w - c)
// times the norms, and int exp(eta.w) = 2 pi e^|eta| (1 - e^{-2|eta|}) / |eta|.
double log_cross(const Vec3& mi, double ki, const Vec3& mj, double kj, const Vec3& mm, double km) {
    auto eff = [](double k) { return k < kKappaMin ? 0.0 : k; };
    ki = eff(ki), kj = eff(kj), km = eff(km);
    const Vec3 eta = mi * ki + mj * kj - mm * km;
    const double h = length(eta);
    const double c = ki + kj - km;
    const double log_int = std::log(2.0 * kPi) + h + (h > 1e-8 ? std::log(-std::expm1(-2.0 * h) / h) : std::log(2.0));
    return vmf_log_norm(ki) + vmf_log_norm(kj) - vmf_log_norm(km) - c + log_int;
}

}  // namespace

double merge_metric(const Vmm& m, uint32_t k, uint32_t l, const Vec3& merged_mu, double merged_kappa) {
    const double wk = m.weight[k], wl = m.weight[l];
    if (!(wk + wl > 0.0)) return 0.0;
    const double a[2] = {wk / (wk + wl), wl / (wk + wl)};
    const uint32_t idx[2] = {k, l};
    double sum = 0.0;
    for (int i = 0; i < 2; ++i)
        for (int j = 0; j < 2; ++j) {
            const double lc = log_cross(m.mu[idx[i]], m.kappa[idx[i]], m.mu[idx[j]], m.kappa[idx[j]], merged_mu, merged_kappa);
            sum += a[i] * a[j] * std::exp(std::min(lc, 700.0));
        }
    return std::max(sum - 1.0, 0.0);
}

uint32_t merge_components(VmmState& s, const FitOptions& o) {
    Vmm& m = s.vmm;
    uint32_t merges = 0;
    while (m.count > 1) {
        double W = 0.0, N = 0.0;
        for (uint32_t k = 0; k < m.count; ++k) {
            W += s.stats.c[k].weight;
            N += s.stats.c[k].count;
        }
        double best = HUGE_VAL;
        uint32_t bk = 0, bl = 0;
        for (uint32_t k = 0; k < m.count; ++k)
            for (uint32_t l = k + 1; l < m.count; ++l) {
                ComponentStats c = s.stats.c[k];
                c.weight += s.stats.c[l].weight;
                c.direction += s.stats.c[l].direction;
                Vec3 mu = m.weight[k] >= m.weight[l] ? m.mu[k] : m.mu[l];
                double kappa = 0.0;
                lobe_from_stats(c, W > 0.0 ? N * c.weight / W : 0.0, o, mu, kappa);
                const double metric = merge_metric(m, k, l, mu, kappa);
                if (metric < best) {
                    best = metric;
                    bk = k;
                    bl = l;
                }
            }
        if (!(best <= o.merge_threshold)) break;
        // Statistics add up; lobe bl is replaced by the last one.
        ComponentStats& c = s.stats.c[bk];
        const ComponentStats& d = s.stats.c[bl];
        c.weight += d.weight;
        c.count += d.count;
        c.inv_distance += d.inv_distance;
        c.direction += d.direction;
        if (m.weight[bl] > m.weight[bk]) m.mu[bk] = m.mu[bl];  // direction if the statistics are empty
        const uint32_t last = m.count - 1;
        s.stats.c[bl] = s.stats.c[last];
        s.stats.c[last] = ComponentStats{};
        m.mu[bl] = m.mu[last];
        m.kappa[bl] = m.kappa[last];
        m.weight[bl] = m.weight[last];
        m.distance[bl] = m.distance[last];
        m.count = last;
        m_step(m, s.stats, o);
        ++merges;
    }
    return merges;
}

FitReport fit_batch(VmmState& s, const Batch& b, const FitOptions& o) {
    FitReport r;
    const uint32_t k = s.vmm.count ? s.vmm.count : std::min(o.initial_components, o.max_components);
    if (b.size() <= 2 * size_t(k)) return r;  // "EM only when N > 2K"
    if (s.vmm.count == 0) initialise(s.vmm, o);
    Statistics previous = s.stats;
    previous.scale(o.decay);
    r.iterations = run_em(s, b, o, previous, r.log_likelihood);
    r.fitted = true;
    s.new_samples += double(b.size());
    if (o.split_merge) {
        r.splits = split_components(s, b, o, previous);
        if (r.splits) r.iterations += run_em(s, b, o, previous, r.log_likelihood);
        if (s.new_samples > o.merge_min_samples) {
            r.merges = merge_components(s, o);
            s.new_samples = 0;
        }
    }
    ++s.fits;
    return r;
}

}  // namespace px::guiding
