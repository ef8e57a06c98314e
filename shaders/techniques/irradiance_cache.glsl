// Irradiance cache (thesis 3.2.3, 4.4, 4.4.1; Ward, Rubinstein & Clear 1988; Ward & Heckbert
// 1992). Entries hold the indirect irradiance E at a point. A query reads the entries listed in
// the cells of the lookup grid around the point (IC_GRID_LEVELS in techniques.h) and adds the
// usable ones' weighted values (eq. 3.18). The thesis found them with zero-length rays into an
// AABB TLAS of the entries; on a GPU without RT cores that hit group made every ray of the
// pipeline slower (bench/results/gpu_ic_consistent), so the lookup is plain shader code.
// Uncovered vertices queue creation requests, which the host turns into jobs for
// ic_hemisphere.rgen and ic_finish.comp after the frame (creation never runs inline).
// - ic_mode thesis: a diffuse vertex that finds entries around it is shaded with emission + NEE
//   + albedo/pi * E(x) (thesis eq. 3.17) and ends its path. Biased; the bias never goes away.
// - ic_mode consistent: the path goes on. Its sample also yields the cache's estimate A (the
//   path up to the first diffuse vertex and its NEE, plus albedo/pi * E there), and the film
//   sums A - B against the path's own B (PASS_IC_RESIDUAL). The image B is shrunk toward A by
//   James-Stein factors that tend to 1 as B's variance vanishes (ic_combine in
//   native/src/techniques/irradiance_cache.cpp).
//
// Entry points that cannot trace rays (compute) define PX_NO_TRACE and get only the entries and
// the weight maths.

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

bool ic_consistent() { return tech.ic.mode == IC_MODE_CONSISTENT; }

#ifndef PX_NO_TRACE
layout(set = 0, binding = BINDING_IC_GRID, scalar) readonly buffer IcGridBuffer { uint ic_grid_starts[]; };  // after a header
layout(set = 0, binding = BINDING_IC_GRID_ENTRIES, scalar) readonly buffer IcGridEntryBuffer { IcCandidate ic_grid_candidates[]; };
// Consistent mode: pixels handed back to the paths (ic_hand_over, irradiance_cache.cpp): 1 where the
// cache could no longer lower the error enough to pay for its queries.
layout(set = 0, binding = BINDING_IC_PATHS_ONLY, scalar) readonly buffer IcPathsOnlyBuffer { uint ic_paths_only[]; };
layout(set = 0, binding = BINDING_IC_REUSE, scalar) buffer IcReuseBuffer { IcReuseRecord ic_reuse_records[]; };
layout(set = 0, binding = BINDING_IC_QUEUE, scalar) buffer IcQueueBuffer {
    uint ic_queue_count;
    uint ic_queue_uncovered;  // prepare frames: paths whose first diffuse vertex had no entry
    uint ic_queue_pad0, ic_queue_pad1;
    IcRequest ic_requests[];
};

// The weighted mean of the usable entries around (p, n) (eq. 3.18), their mean gradient
// lengths and the nearest one's validity radius; false where there is none. Consistent mode
// reads the first IC_QUERY_MAX_ENTRIES usable entries, not all: its image leans on them only
// where they beat the paths.
bool ic_lookup(vec3 p, vec3 n, out vec3 irradiance, out vec2 gradient_lengths, out float radius) {
    irradiance = vec3(0.0);
    gradient_lengths = vec2(0.0);
    radius = 0.0;
    if (!USES(TECH_IC)) return false;
    float weight = 0.0, nearest = INFINITY_F;
    uint found = 0u;
    uint most = ic_consistent() ? IC_QUERY_MAX_ENTRIES : 0xffffffffu;
    for (uint level = 0u; level < IC_GRID_LEVELS && found < most; ++level) {
        if ((tech.ic.grid_levels >> level & 1u) == 0u) continue;
        ivec3 c = ivec3(floor(p / (tech.ic.grid_cell * float(1u << level))));
        uint bucket = IC_GRID_HEADER + ic_grid_starts[2u * level] +
                      ic_grid_bucket(c.x, c.y, c.z, ic_grid_starts[2u * level + 1u]);
        uint end = ic_grid_starts[bucket + 1u];
        for (uint k = ic_grid_starts[bucket]; k < end && found < most; ++k) {
            IcCandidate c = ic_grid_candidates[k];
            float d = length(p - c.position);
            if (d >= c.reach) continue;  // outside its influence sphere
            IcEntry e = ic_entries[c.slot];
            float w = ic_weight(e, p, n);
            if (!(w > 0.0)) continue;
            irradiance += w * ic_entry_irradiance(e, p, n);
            weight += w;
            gradient_lengths += w * vec2(length(e.grad_t), length(e.grad_r));
            if (d < nearest) {
                nearest = d;
                radius = c.reach;
            }
            ++found;
        }
    }
    if (!(weight > 0.0)) return false;
    irradiance /= weight;
    gradient_lengths /= weight;
    return true;
}

// Queues a creation request at (p, n); the host makes the entry after this frame (thesis 4.4).
// Requests past the queue's capacity are left for a later host step (the host counts them).
void ic_request(vec3 p, vec3 n, uint pixel, uint sample_index) {
    uint i = atomicAdd(ic_queue_count, 1u);
    if (i >= tech.ic.queue_capacity) return;
    ic_requests[i] = IcRequest(p, pixel, n, sample_index);
}

#ifdef PX_TRACE_LOOP
// ---- hooks of the trace loop (lib/integrator.glsl, techniques.glsl) ----------------------

// A path's use of the cache.
struct IcOptions {
    bool use;      // shade diffuse vertices from the irradiance cache where it has entries
    bool glossy;   // ... and glossy ones (ADRRS' estimate, thesis 4.4 "IC on glossy")
    bool combine;  // consistent mode: the first diffuse vertex yields the cache's estimate, the path goes on
    bool create;   // queue cache creation requests at uncovered diffuse vertices
    bool prepare;  // prepare frame: stop at the first diffuse vertex after the query
    uint pixel;    // for creation requests (their order on the host)
};

IcOptions ic_no_options() { return IcOptions(false, false, false, false, false, 0u); }

// FRAME_IC_PREPARE: camera paths only queue cache entries.
bool ic_prepare_frame() { return USES(TECH_IC) && params.mode == FRAME_IC_PREPARE; }

// Camera paths. ADRRS alone fills the cache in its prepare frames only: no entry jobs, rebuilds
// or new adjoint grids between the frames it renders.
IcOptions ic_camera_options(uint pixel_index, bool estimate_frame) {
    IcOptions o;
    bool shade = tech.ic.shade != 0u && !estimate_frame;
    o.use = (shade && !ic_consistent()) || estimate_frame;
    o.glossy = estimate_frame && tech.adrrs.ic_glossy != 0u;
    bool handed_over = USES(TECH_IC) && shade && ic_consistent() && params.mode == FRAME_RENDER &&
                       ic_paths_only[pixel_index] != 0u;
    o.combine = shade && ic_consistent() && !handed_over;
    o.create = USES(TECH_IC) && !estimate_frame && !handed_over &&
               (tech.ic.shade != 0u || params.mode == FRAME_IC_PREPARE);
    o.prepare = ic_prepare_frame();
    o.pixel = pixel_index;
    return o;
}

// ADRRS' split copies of a pixel's paths (in consistent mode their sums join B only).
IcOptions ic_split_options(uint pixel_index) {
    bool shade = tech.ic.shade != 0u && !ic_consistent();
    return IcOptions(shade, false, false, shade, false, pixel_index);
}

// Entry rays (ic_hemisphere.rgen) read existing entries, never queue new ones.
IcOptions ic_hemisphere_options() { return IcOptions(true, false, false, false, false, 0u); }

// Consistent mode: a pixel's last query, which its next samples reuse where their first
// diffuse vertex lies within IC_REUSE_REACH of its nearest entry's reach and faces the same
// way (ic_lookup_first), in this frame and the next ones until a host step changes the entries
// (BINDING_IC_REUSE). A query cost the H100 50-80% of an MIS path at 1280 px; the cache's value
// varies little across a pixel's footprint, and any A keeps the image consistent (ic_combine).
struct IcReuse {
    vec3 position;
    float radius;  // the nearest entry's reach; 0: nothing to reuse
    vec3 normal;
    vec3 irradiance;
    vec2 gradients;
    bool changed;  // a new query replaced the pixel's record
};

IcReuse ic_no_reuse() { return IcReuse(vec3(0.0), 0.0, vec3(0.0), vec3(0.0), vec2(0.0), false); }

// What a path found at its first diffuse vertex (the IC passes, consistent mode's estimate).
struct IcPath {
    bool recorded;
    vec3 irradiance;  // cache value at the first diffuse vertex (0: no entry there)
    vec2 gradients;   // its entries' mean |g_t|, |g_r|
    float radius;     // the nearest entry's validity radius (0: no entry)
    // Consistent mode: A - B = `estimate` - B, `estimate` = throughput * albedo/pi * E at the
    // first diffuse vertex plus the path's radiance once that vertex's NEE is in (until then
    // `waiting`).
    bool combined;
    bool waiting;
    vec3 estimate;
    IcReuse reuse;  // carried from the pixel's previous samples (ic_next_path)
};

IcPath ic_path() { return IcPath(false, vec3(0.0), vec2(0.0), 0.0, false, false, vec3(0.0), ic_no_reuse()); }

// A pixel's first path: with its record of the last query, where the entries are still those.
IcPath ic_first_path(IcOptions o) {
    IcPath path = ic_path();
    if (!USES(TECH_IC) || !o.combine) return path;
    IcReuseRecord r = ic_reuse_records[o.pixel];
    if (r.stamp == tech.ic.reuse_stamp)
        path.reuse = IcReuse(r.position, r.radius, r.normal, r.irradiance, unpackHalf2x16(r.gradients), false);
    return path;
}

// After a pixel's last path: its newest query for the next frame.
void ic_end_pixel(IcOptions o, IcPath path) {
    if (!USES(TECH_IC) || !o.combine || !path.reuse.changed) return;
    IcReuse u = path.reuse;
    ic_reuse_records[o.pixel] = IcReuseRecord(u.position, u.radius, u.normal, tech.ic.reuse_stamp, u.irradiance,
                                              packHalf2x16(u.gradients));
}

// The next sample of the same pixel: a fresh path that keeps the last query for reuse.
IcPath ic_next_path(IcPath previous) {
    IcPath path = ic_path();
    path.reuse = previous.reuse;
    return path;
}

// The cache at (p, n) for the first diffuse vertex of a consistent-mode path: the pixel's last
// query where it is near enough, else a new one (remembered where it found entries).
bool ic_lookup_first(inout IcReuse reuse, vec3 p, vec3 n, out vec3 irradiance, out vec2 gradients,
                     out float radius) {
    if (reuse.radius > 0.0 && distance(p, reuse.position) < IC_REUSE_REACH * reuse.radius &&
        dot(n, reuse.normal) > IC_REUSE_COS) {
        irradiance = reuse.irradiance;
        gradients = reuse.gradients;
        radius = reuse.radius;
        return true;
    }
    if (!ic_lookup(p, n, irradiance, gradients, radius)) return false;
    reuse = IcReuse(p, radius, n, irradiance, gradients, true);
    return true;
}

// The cache at a vertex.
struct IcVertex {
    bool found;       // entries (or ADRRS' adjoint, adrrs_vertex_adjoint) cover the vertex
    vec3 irradiance;  // their indirect irradiance
    bool shaded;      // the vertex is shaded from the cache: the path ends after its NEE
    bool stop;        // prepare frame: the path ends here, before NEE
};

// Irradiance cache at diffuse vertices (thesis 4.4): where entries cover this point the
// path ends here with NEE + albedo/pi * E; elsewhere it may queue a new entry and goes on.
// With ADRRS the cache's adjoint grid is read at every non-delta vertex (adrrs.glsl);
// `handled` false leaves the vertex to it.
IcVertex ic_vertex(inout IcPath path, IcOptions o, Surface surf, bool delta, vec3 p, vec3 n, bool resumed,
                   vec3 throughput, uint segments, inout vec3 radiance, inout Rng rng, out bool handled) {
    IcVertex v = IcVertex(false, vec3(0.0), false, false);
    bool ic_surface = surf.type == MATERIAL_DIFFUSE || ((USES(TECH_ADRRS) || o.glossy) && !delta);
    // Consistent mode asks the cache once, at the path's first diffuse vertex.
    bool first_diffuse = o.combine && !path.recorded && surf.type == MATERIAL_DIFFUSE;
    handled = USES(TECH_IC) && ic_surface && !resumed && (o.use || o.prepare || first_diffuse);
    if (!handled) return v;
    vec2 gradients;
    float radius;
    if (first_diffuse && !o.use && !o.prepare)
        v.found = ic_lookup_first(path.reuse, p, n, v.irradiance, gradients, radius);
    else
        v.found = ic_lookup(p, n, v.irradiance, gradients, radius);
    if (!path.recorded) {
        path.irradiance = v.irradiance;
        path.gradients = gradients;
        path.radius = radius;
        path.recorded = true;
    }
    if (v.found && first_diffuse) {
        path.combined = path.waiting = true;
        path.estimate = throughput * surf.albedo * INV_PI * v.irradiance;
    } else if (v.found && o.use && (surf.type == MATERIAL_DIFFUSE || o.glossy)) {
        radiance += throughput * surf.albedo * INV_PI * v.irradiance;
        v.shaded = true;
    } else if (!v.found && o.create && rnd(rng) < (o.prepare ? tech.ic.prepare_create_prob : tech.ic.create_prob)) {
        ic_request(p, n, o.pixel, segments);
    }
    if (o.prepare) {
        if (!v.found) atomicAdd(ic_queue_uncovered, 1u);
        v.stop = true;
    }
    return v;
}

// After a pending shadow ray (trace_path): the radiance holds the NEE of every vertex so far.
// The first call after the cached vertex marks where the part the cache stands in for begins.
void ic_light_resolved(inout IcPath path, vec3 radiance) {
    if (!USES(TECH_IC) || !path.waiting) return;
    path.estimate += radiance;
    path.waiting = false;
}

// The IC passes of a pixel: sums over its samples.
struct IcPixel {
    vec3 irradiance;
    vec2 gradients;
    float radius;
    vec4 residual;  // consistent mode: sum of A - B per sample (rgb) and of |A - B|^2 (a)
};

IcPixel ic_pixel() { return IcPixel(vec3(0.0), vec2(0.0), 0.0, vec4(0.0)); }

// `radiance`: the sample's (B).
void ic_add_sample(inout IcPixel px, IcPath path, vec3 radiance) {
    if (!USES(TECH_IC)) return;
    // Colour highlight (thesis fig. 4.13): the irradiance less its white part.
    vec3 e = tech.ic.highlight != 0u ? path.irradiance - vec3(min(path.irradiance.x, min(path.irradiance.y, path.irradiance.z))) : path.irradiance;
    if (!any(isinf(e)) && !any(isnan(e))) px.irradiance += e;
    px.gradients += path.gradients / max(tech.ic.gradient_max, 1e-6);
    px.radius += path.radius;
    if (path.combined) {
        vec3 d = path.estimate - radiance;
        if (!any(isinf(d)) && !any(isnan(d))) px.residual += vec4(d, dot(d, d));
    }
}

void ic_write_passes(IcPixel px, uint pixel_index) {
    if (!USES(TECH_IC)) return;
    film_add(PASS_IC_IRRADIANCE, pixel_index, vec4(px.irradiance, 0.0));
    film_add(PASS_IC_GRADIENTS, pixel_index, vec4(px.gradients, 0.0, 0.0));
    film_add(PASS_IC_RADIUS, pixel_index, vec4(px.radius, 0.0, 0.0, 0.0));
    if (ic_consistent()) film_add(PASS_IC_RESIDUAL, pixel_index, vec4(px.residual));
}
#endif
#endif
