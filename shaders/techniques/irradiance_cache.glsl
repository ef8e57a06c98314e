// Irradiance cache (thesis 3.2.3, 4.4, 4.4.1; Ward, Rubinstein & Clear 1988; Ward & Heckbert
// 1992). Entries hold the indirect irradiance E at a point; a diffuse vertex that finds entries
// around it is shaded with emission + NEE + albedo/pi * E(x) (thesis eq. 3.17) and ends its
// path. Entries are found by a zero-length ray into their own AABB TLAS: ic_query.rint accepts
// the entries whose influence sphere holds the origin and ic_query.rahit adds their weighted
// values (eq. 3.18). Uncovered vertices queue creation requests, which the host turns into
// jobs for ic_hemisphere.rgen and ic_finish.comp after the frame (creation never runs inline).
//
// Entry points that cannot trace rays (intersection, any-hit, compute) define PX_NO_TRACE
// and get only the bindings and the weight maths.

layout(set = 0, binding = BINDING_TECH_PARAMS, scalar) readonly buffer TechParamsBuffer { TechniqueParams tech; };
layout(set = 0, binding = BINDING_IC_ENTRIES, scalar) buffer IcEntryBuffer { IcEntry ic_entries[]; };

// Ward et al. 1988: w_i(x) = 1 / (|x - x_i| / R_i + sqrt(1 - n . n_i)), usable when w_i > 1/a.
// With the visibility check, an entry lying in front of x (Ward's d_i < 0) is skipped: it sits
// above the surface at x and sees other occluders, the cause of light leaking into corners.
float ic_weight(IcEntry e, vec3 p, vec3 n) {
    float d = length(p - e.position) / e.radius + sqrt(max(0.0, 1.0 - dot(n, e.normal)));
    float w = 1.0 / max(d, 1e-6);
    if (w <= 1.0 / tech.ic.accuracy) return 0.0;
    if (tech.ic.visibility_check != 0u && dot(p - e.position, 0.5 * (n + e.normal)) < -1e-3) return 0.0;
    return w;
}

// E_i extrapolated to (x, n) with the first-order terms of Ward & Heckbert 1992:
// E_i (1 + (n_i x n) . g_r + (x - x_i) . g_t), the gradients stored relative to E_i.
vec3 ic_entry_irradiance(IcEntry e, vec3 p, vec3 n) {
    if (tech.ic.gradients == 0u) return e.irradiance;
    float f = 1.0 + dot(cross(e.normal, n), e.grad_r) + dot(p - e.position, e.grad_t);
    return e.irradiance * max(f, 0.0);
}

#ifndef PX_NO_TRACE
layout(set = 0, binding = BINDING_IC_TLAS) uniform accelerationStructureEXT ic_tlas;
layout(set = 0, binding = BINDING_IC_QUEUE, scalar) buffer IcQueueBuffer {
    uint ic_queue_count;
    uint ic_queue_uncovered;  // prepare frames: paths whose first diffuse vertex had no entry
    uint ic_queue_pad0, ic_queue_pad1;
    IcRequest ic_requests[];
};
layout(location = 2) rayPayloadEXT IcQuery ic_query;

// The weighted mean of the usable entries around (p, n) (eq. 3.18) and their mean gradient
// lengths; false where there is none.
bool ic_lookup(vec3 p, vec3 n, out vec3 irradiance, out vec2 gradient_lengths) {
    irradiance = vec3(0.0);
    gradient_lengths = vec2(0.0);
    if (!USES(TECH_IC)) return false;
    ic_query.position = p;
    ic_query.normal = n;
    ic_query.weighted_irradiance = vec3(0.0);
    ic_query.weight = 0.0;
    ic_query.weighted_gradients = vec2(0.0);
    traceRayEXT(ic_tlas, gl_RayFlagsSkipClosestHitShaderEXT, 0xff, 0, 0, MISS_IC_QUERY, p, 0.0, n, IC_QUERY_T, 2);
    if (!(ic_query.weight > 0.0)) return false;
    irradiance = ic_query.weighted_irradiance / ic_query.weight;
    gradient_lengths = ic_query.weighted_gradients / ic_query.weight;
    return true;
}

// Queues a creation request at (p, n); the host makes the entry after this frame (thesis 4.4).
// Requests past the queue's capacity are left for a later frame (the host counts them).
void ic_request(vec3 p, vec3 n, uint pixel, uint sample_index) {
    uint i = atomicAdd(ic_queue_count, 1u);
    if (i >= tech.ic.queue_capacity) return;
    ic_requests[i] = IcRequest(p, pixel, n, sample_index);
}
#endif
