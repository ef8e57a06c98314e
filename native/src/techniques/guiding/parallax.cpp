#include "techniques/guiding/parallax.h"

namespace px::guiding {

double sample_distance(float d) {
    return d >= 0.0f && d < float(GUIDING_DISTANCE_INFINITE) ? double(d) : kInfinity;
}

Batch make_batch(const TrainingSample* samples, size_t count, double weight_scale, double total_samples,
                 const Vec3& pivot, bool parallax) {
    Batch b;
    b.total_samples = total_samples;
    for (size_t i = 0; i < count; ++i) {
        const TrainingSample& s = samples[i];
        if (!(s.weight > 0.0f)) continue;
        Vec3 w = normalize(Vec3(s.direction[0], s.direction[1], s.direction[2]));
        const double d = sample_distance(s.distance);
        double inv_d = 0.0;
        if (std::isfinite(d)) {
            inv_d = 1.0 / std::max(d, 1e-30);
            if (parallax) {
                const Vec3 x(s.position[0], s.position[1], s.position[2]);
                const Vec3 to = x + w * d - pivot;  // the light's point seen from the pivot
                const double len = length(to);
                if (len > 1e-9 * (d + length(x - pivot))) {
                    w = to * (1.0 / len);
                    inv_d = 1.0 / len;
                }
            }
        }
        b.add(w, double(s.weight) * weight_scale, double(s.pdf), inv_d);
    }
    return b;
}

void move_pivot(VmmState& s, const Vec3& pivot) {
    Vmm& m = s.vmm;
    for (uint32_t k = 0; k < m.count; ++k) {
        if (!m.has_target(k)) continue;
        const Vec3 to = m.target(k) - pivot;
        const double len = length(to);
        if (!(len > 1e-9 * m.distance[k])) continue;
        m.mu[k] = to * (1.0 / len);
        m.distance[k] = len;
        ComponentStats& c = s.stats.c[k];
        c.direction = m.mu[k] * length(c.direction);
        c.inv_distance = c.weight / len;
    }
    m.pivot = pivot;
}

}  // namespace px::guiding
