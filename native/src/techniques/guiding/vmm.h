// von Mises-Fisher lobes and mixtures on the host (thesis 3.2.6; Jakob 2012): densities,
// sampling and the GPU records. The host mirror of shaders/techniques/guiding.glsl, in
// double precision: the fit (em.h) and the tests use it.
#pragma once
#include "../../../../shaders/shared/types.h"

#include <array>
#include <cmath>
#include <cstdint>

namespace px::guiding {

struct Vec3 {
    double x = 0, y = 0, z = 0;
    Vec3() = default;
    Vec3(double x_, double y_, double z_) : x(x_), y(y_), z(z_) {}
    double operator[](int i) const { return i == 0 ? x : i == 1 ? y : z; }
};
inline Vec3 operator+(const Vec3& a, const Vec3& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
inline Vec3 operator-(const Vec3& a, const Vec3& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline Vec3 operator*(const Vec3& a, double s) { return {a.x * s, a.y * s, a.z * s}; }
inline Vec3 operator*(double s, const Vec3& a) { return a * s; }
inline Vec3& operator+=(Vec3& a, const Vec3& b) { a = a + b; return a; }
inline double dot(const Vec3& a, const Vec3& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
    return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double length(const Vec3& a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalize(const Vec3& a) { return a * (1.0 / length(a)); }
inline bool finite(const Vec3& a) { return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z); }
// Orthonormal t, b with (t, b, n) right-handed (Duff et al. 2017, as make_basis in GLSL).
void make_basis(const Vec3& n, Vec3& t, Vec3& b);

constexpr uint32_t kMaxComponents = GUIDING_MAX_COMPONENTS;
constexpr double kKappaMin = 1e-3;  // GUIDING_KAPPA_MIN (a float there; uniform lobes get kappa 0 on the GPU)
constexpr double kInfinity = HUGE_VAL;
constexpr double kPi = 3.14159265358979323846;

// kappa / (2 pi (1 - exp(-2 kappa))) (thesis eq. 3.27); 1 / (4 pi) below kKappaMin.
double vmf_norm(double kappa);
double vmf_log_norm(double kappa);
// Density of direction w (unit) for a lobe (mu, kappa), and its log.
double vmf_pdf(const Vec3& mu, double kappa, const Vec3& w);
double vmf_log_pdf(const Vec3& mu, double kappa, const Vec3& w);
// Jakob 2012: a direction from uniform numbers u1, u2 in [0, 1).
Vec3 vmf_sample(const Vec3& mu, double kappa, double u1, double u2);
// Mean cosine A3(kappa) = E[mu.w] = coth(kappa) - 1/kappa, and its inverse (the ML kappa
// for a mean resultant length r, Banerjee et al. 2005, refined by Newton's method).
double mean_cosine(double kappa);
double kappa_from_mean_cosine(double r);

// A mixture (thesis eq. 3.28) in double precision. Lobe k points along mu[k] from `pivot`;
// with parallax its light lies at pivot + distance[k] * mu[k] (distance kInfinity: far away).
struct Vmm {
    uint32_t count = 0;
    std::array<double, kMaxComponents> weight{};
    std::array<double, kMaxComponents> kappa{};
    std::array<double, kMaxComponents> distance{};
    std::array<Vec3, kMaxComponents> mu{};
    Vec3 pivot;

    bool has_target(uint32_t k) const { return std::isfinite(distance[k]) && distance[k] > 0.0; }
    Vec3 target(uint32_t k) const { return pivot + mu[k] * distance[k]; }
    // Lobe k's mean direction at x (thesis eq. 4.5) with parallax, mu[k] without.
    Vec3 lobe_mu(uint32_t k, const Vec3& x, bool parallax) const;
    double pdf(const Vec3& w, const Vec3& x, bool parallax) const;
    // u0 picks a lobe by weight, u1 and u2 sample it.
    Vec3 sample(double u0, double u1, double u2, const Vec3& x, bool parallax) const;
};

// Lobe k as the shader reads it; without parallax its distance is -1 (mu at every point).
// `cdf` is the weight of lobes 0..k.
GuidingLobe to_gpu_lobe(const Vmm& m, uint32_t k, bool parallax, double cdf);
// All of m's lobes into out[0 .. kMaxComponents): the unused ones zeroed.
void write_gpu_lobes(const Vmm& m, bool parallax, GuidingLobe* out);

// GuidingSample.direction: octahedral snorm16 x 2 (Cigolle et al. 2014), as packSnorm2x16.
uint32_t pack_direction(const Vec3& w);
Vec3 unpack_direction(uint32_t packed);

}  // namespace px::guiding
