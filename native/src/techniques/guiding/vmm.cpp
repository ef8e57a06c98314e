#include "techniques/guiding/vmm.h"

#include <algorithm>

namespace px::guiding {

void make_basis(const Vec3& n, Vec3& t, Vec3& b) {
    const double s = n.z >= 0.0 ? 1.0 : -1.0;
    const double a = -1.0 / (s + n.z);
    const double c = n.x * n.y * a;
    t = {1.0 + s * n.x * n.x * a, s * c, -s * n.x};
    b = {c, s + n.y * n.y * a, -n.y};
}

double vmf_log_norm(double kappa) {
    if (kappa < kKappaMin) return -std::log(4.0 * kPi);
    return std::log(kappa) - std::log(2.0 * kPi) - std::log(-std::expm1(-2.0 * kappa));
}

double vmf_norm(double kappa) { return std::exp(vmf_log_norm(kappa)); }

// kappa (mu.w - 1) = -kappa |mu - w|^2 / 2 for unit vectors: no cancellation near the mean.
double vmf_log_pdf(const Vec3& mu, double kappa, const Vec3& w) {
    if (kappa < kKappaMin) return -std::log(4.0 * kPi);
    const Vec3 d = mu - w;
    return vmf_log_norm(kappa) - 0.5 * kappa * dot(d, d);
}

double vmf_pdf(const Vec3& mu, double kappa, const Vec3& w) { return std::exp(vmf_log_pdf(mu, kappa, w)); }

Vec3 vmf_sample(const Vec3& mu, double kappa, double u1, double u2) {
    const double phi = 2.0 * kPi * u2;
    double omc;  // 1 - cos(theta)
    if (kappa < kKappaMin) {
        omc = 2.0 * u1;
    } else {  // Jakob 2012 eq. 9: log(u1 + (1 - u1) e^{-2 kappa}) = log1p(-(1 - u1)(1 - e^{-2 kappa}))
        const double a = -(1.0 - u1) * -std::expm1(-2.0 * kappa);
        omc = a > -1.0 ? std::min(-std::log1p(a) / kappa, 2.0) : 2.0;
    }
    const double sin_t = std::sqrt(std::max(0.0, omc * (2.0 - omc)));
    Vec3 t, b;
    make_basis(mu, t, b);
    return normalize(t * (sin_t * std::cos(phi)) + b * (sin_t * std::sin(phi)) + mu * (1.0 - omc));
}

double mean_cosine(double kappa) {
    if (kappa < 1e-2) return kappa / 3.0 - kappa * kappa * kappa / 45.0;
    if (kappa > 20.0) return 1.0 - 1.0 / kappa;  // coth(kappa) = 1 to double precision
    return 1.0 / std::tanh(kappa) - 1.0 / kappa;
}

static double mean_cosine_derivative(double kappa) {
    if (kappa < 1e-2) return 1.0 / 3.0 - kappa * kappa / 15.0;
    if (kappa > 20.0) return 1.0 / (kappa * kappa);
    const double s = std::sinh(kappa);
    return 1.0 / (kappa * kappa) - 1.0 / (s * s);
}

double kappa_from_mean_cosine(double r) {
    if (!(r > 0.0)) return 0.0;
    if (r >= 1.0) return kInfinity;
    if (r >= 0.95) return 1.0 / (1.0 - r);  // A3(kappa) = 1 - 1/kappa for kappa >= 20
    // Newton's method on A3(kappa) = r from Banerjee et al.'s estimate, kept inside [lo, hi].
    double lo = 0.0, hi = 20.0;
    double k = std::min(r * (3.0 - r * r) / (1.0 - r * r), hi);
    for (int i = 0; i < 50; ++i) {
        const double f = mean_cosine(k) - r;
        if (f > 0.0) hi = k; else lo = k;
        double next = k - f / mean_cosine_derivative(k);
        if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
        if (std::abs(next - k) <= 1e-13 * k) return next;
        k = next;
    }
    return k;
}

Vec3 Vmm::lobe_mu(uint32_t k, const Vec3& x, bool parallax) const {
    if (parallax && has_target(k)) {
        const Vec3 d = target(k) - x;
        const double len2 = dot(d, d);
        if (len2 > 1e-12 * distance[k] * distance[k]) return d * (1.0 / std::sqrt(len2));
    }
    return mu[k];
}

double Vmm::pdf(const Vec3& w, const Vec3& x, bool parallax) const {
    double p = 0.0;
    for (uint32_t k = 0; k < count; ++k) p += weight[k] * vmf_pdf(lobe_mu(k, x, parallax), kappa[k], w);
    return p;
}

Vec3 Vmm::sample(double u0, double u1, double u2, const Vec3& x, bool parallax) const {
    uint32_t k = 0;
    double cdf = weight[0];
    while (k + 1 < count && u0 >= cdf) cdf += weight[++k];
    return vmf_sample(lobe_mu(k, x, parallax), kappa[k], u1, u2);
}

GuidingLobe to_gpu_lobe(const Vmm& m, uint32_t k, bool parallax, double cdf) {
    GuidingLobe l{};
    l.mu = {float(m.mu[k].x), float(m.mu[k].y), float(m.mu[k].z)};
    const bool uniform = m.kappa[k] < kKappaMin;  // kappa 0: the shader's test agrees in float
    l.kappa = uniform ? 0.0f : float(m.kappa[k]);
    l.weight = float(m.weight[k]);
    l.norm = float(vmf_norm(m.kappa[k]));
    l.exp_m2k = uniform ? 1.0f : float(std::exp(-2.0 * m.kappa[k]));
    const bool target = parallax && m.has_target(k);
    l.distance = target ? float(m.distance[k]) : -1.0f;
    const Vec3 t = target ? m.target(k) : Vec3();
    l.target = {float(t.x), float(t.y), float(t.z)};
    l.cdf = float(cdf);
    return l;
}

void write_gpu_lobes(const Vmm& m, bool parallax, GuidingLobe* out) {
    double total = 0.0;
    for (uint32_t k = 0; k < m.count; ++k) total += m.weight[k];
    double cdf = 0.0;
    for (uint32_t k = 0; k < kMaxComponents; ++k) {
        if (k < m.count) {
            cdf += m.weight[k];
            out[k] = to_gpu_lobe(m, k, parallax, k + 1 == m.count ? 1.0 : cdf / total);
        } else {
            out[k] = GuidingLobe{};
        }
    }
}

static uint32_t snorm16(double v) {
    const long q = std::lround(std::clamp(v, -1.0, 1.0) * 32767.0);
    return uint32_t(uint16_t(int16_t(q)));
}

static double from_snorm16(uint32_t bits) {
    return std::max(double(int16_t(uint16_t(bits & 0xffffu))) / 32767.0, -1.0);
}

uint32_t pack_direction(const Vec3& w) {
    const double l1 = std::abs(w.x) + std::abs(w.y) + std::abs(w.z);
    double px = w.x / l1, py = w.y / l1;
    if (w.z < 0.0) {
        const double ox = (1.0 - std::abs(py)) * (px >= 0.0 ? 1.0 : -1.0);
        const double oy = (1.0 - std::abs(px)) * (py >= 0.0 ? 1.0 : -1.0);
        px = ox;
        py = oy;
    }
    return snorm16(px) | (snorm16(py) << 16);
}

Vec3 unpack_direction(uint32_t packed) {
    const double px = from_snorm16(packed), py = from_snorm16(packed >> 16);
    Vec3 w{px, py, 1.0 - std::abs(px) - std::abs(py)};
    if (w.z < 0.0) {
        const double ox = (1.0 - std::abs(py)) * (px >= 0.0 ? 1.0 : -1.0);
        const double oy = (1.0 - std::abs(px)) * (py >= 0.0 ? 1.0 : -1.0);
        w.x = ox;
        w.y = oy;
    }
    return normalize(w);
}

}  // namespace px::guiding
