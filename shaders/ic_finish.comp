#version 460
#extension GL_GOOGLE_include_directive : require
#define PX_NO_TRACE
#include "lib/common.glsl"
#include "techniques/irradiance_cache.glsl"

layout(local_size_x = 64) in;
layout(set = 0, binding = BINDING_IC_JOBS, scalar) readonly buffer IcJobBuffer { IcJob ic_jobs[]; };
layout(set = 0, binding = BINDING_IC_SAMPLES, scalar) readonly buffer IcSampleBuffer { IcSample ic_samples[]; };

vec3 ic_radiance(uint job, uint j, uint k) { return ic_samples[job * IC_STRATA + j * tech.ic.phi + k].radiance; }
float ic_distance(uint job, uint j, uint k) { return ic_samples[job * IC_STRATA + j * tech.ic.phi + k].distance; }

// Turns one job's M x N hemisphere samples (M = tech.ic.theta, N = tech.ic.phi strata) into an
// entry (or refreshes one):
//   E = pi / (M N) sum L_jk                                   (thesis eq. 3.20)
//   R = M N / sum 1/r_jk, clamped to [R_min, 64 R_min]       (Ward et al. 1988; escaped: 1/r = 0)
// and the gradients of Ward & Heckbert 1992 from how the strata's boundaries move:
//   rotation:    g_r = n x (pi/(M N)) sum_jk L_jk tan(theta_j) u_k
//   translation: g_t = sum_k u_k (2 pi / N) sum_{j>0} sin(th_j-) cos^2(th_j-) (L_jk - L_j-1,k) / min(r)
//                    + sum_k v_k- sum_j (sin(th_j+) - sin(th_j-)) (L_jk - L_j,k-1) / min(r)
// (u_k: the stratum's azimuth, v_k-: normal to the boundary between k-1 and k; the azimuthal
// term is the cosine-weighted area swept by a boundary under parallax, d phi = dx / (r sin th)).
// Gradients are of luminance, stored relative to E's luminance and clamped to ic_gradient_max.
void main() {
    uint job_index = gl_GlobalInvocationID.x;
    if (job_index >= params.ic_job_count) return;
    IcJob job = ic_jobs[job_index];
    if (job.kind == IC_JOB_UPDATE) job.normal = ic_entries[job.slot].normal;  // the host sends none
    const uint theta_strata = tech.ic.theta, phi_strata = tech.ic.phi;
    const float M = float(theta_strata), N = float(phi_strata);

    vec3 sum = vec3(0.0);
    float inverse_distances = 0.0;
    vec2 rot = vec2(0.0), trans = vec2(0.0);
    for (uint j = 0u; j < theta_strata; ++j) {
        float sin_lo = sqrt(float(j) / M), sin_hi = sqrt(float(j + 1u) / M);
        float sin_c = sqrt((float(j) + 0.5) / M), cos_c = sqrt(max(0.0, 1.0 - sin_c * sin_c));
        float cos_lo = sqrt(max(0.0, 1.0 - sin_lo * sin_lo));
        for (uint k = 0u; k < phi_strata; ++k) {
            vec3 l = ic_radiance(job_index, j, k);
            float r = ic_distance(job_index, j, k);
            sum += l;
            inverse_distances += 1.0 / max(r, 1e-6);
            float lum = luminance(l);
            float phi_c = 2.0 * PI * (float(k) + 0.5) / N, phi_lo = 2.0 * PI * float(k) / N;
            vec2 u_k = vec2(cos(phi_c), sin(phi_c));
            vec2 v_k = vec2(-sin(phi_lo), cos(phi_lo));
            rot += (PI / (M * N)) * lum * (sin_c / cos_c) * u_k;
            uint k_prev = (k + phi_strata - 1u) % phi_strata;
            float r_phi = min(r, ic_distance(job_index, j, k_prev));
            trans += v_k * (sin_hi - sin_lo) * (lum - luminance(ic_radiance(job_index, j, k_prev))) / max(r_phi, 1e-6);
            if (j > 0u) {
                float r_theta = min(r, ic_distance(job_index, j - 1u, k));
                trans += u_k * (2.0 * PI / N) * sin_lo * cos_lo * cos_lo *
                         (lum - luminance(ic_radiance(job_index, j - 1u, k))) / max(r_theta, 1e-6);
            }
        }
    }
    vec3 irradiance = sum * (PI / (M * N));
    vec3 tangent, bitangent;
    make_basis(job.normal, tangent, bitangent);
    float lum_e = luminance(irradiance);
    float scale = lum_e > 0.0 ? 1.0 / lum_e : 0.0;
    vec3 grad_r = cross(job.normal, (rot.x * tangent + rot.y * bitangent) * scale);
    vec3 grad_t = (trans.x * tangent + trans.y * bitangent) * scale;
    // Gradient-limited radius (Krivanek et al. 2008): R <= E / |grad_t E|, so within the
    // influence radius a R the irradiance changes by at most about a. Where irradiance varies
    // steeply (next to a small bright source) entries shrink instead of smearing it out.
    float min_r = tech.ic.min_radius;
    float radius = M * N / max(inverse_distances, 1e-30);
    if (length(grad_t) > 0.0) radius = min(radius, 1.0 / length(grad_t));
    radius = clamp(radius, min_r, IC_MAX_RADIUS_FACTOR * min_r);
    float g_max = tech.ic.gradient_max;
    if (length(grad_r) > g_max) grad_r *= g_max / length(grad_r);
    if (length(grad_t) > g_max) grad_t *= g_max / length(grad_t);

    if (job.kind == IC_JOB_UPDATE) {
        // Refresh: the entry becomes the mean of all its estimates (weight n/(n+1) on the old
        // value), so refreshes converge it; the reference capped that weight at 0.95, which
        // leaves a noise floor. The entry keeps its place and radius, so its grid cells stay.
        IcEntry e = ic_entries[job.slot];
        float keep = float(e.updates) / float(e.updates + 1u);
        e.irradiance = mix(irradiance, e.irradiance, keep);
        e.grad_r = mix(grad_r, e.grad_r, keep);
        e.grad_t = mix(grad_t, e.grad_t, keep);
        e.updates += 1u;
        ic_entries[job.slot] = e;
        return;
    }
    IcEntry e;
    e.position = job.position;
    e.radius = radius;
    e.normal = job.normal;
    e.updates = 1u;
    e.irradiance = irradiance;
    e.grad_t = grad_t;
    e.grad_r = grad_r;
    e.pad0 = e.pad1 = e.pad2 = 0.0;
    ic_entries[job.slot] = e;
}
