// The techniques of the thesis (ch. 4) in the trace loop: each one's hooks are in its own file
// (irradiance_cache.glsl, adrrs.glsl with ears.glsl, guiding_field.glsl) and guard themselves with USES(), so
// a pipeline without a technique compiles none of its code. This file is the one list of
// them: the per-path options and state the trace loop carries, and the hooks that consult more
// than one technique. Included by lib/integrator.glsl after its base structs (PathOptions,
// PathState, Vertex).
#define PX_TRACE_LOOP
#include "irradiance_cache.glsl"
#include "adrrs.glsl"  // includes ears.glsl
#include "guiding_field.glsl"

// Techniques whose paths may end at a vertex with its NEE even under METHOD_PT: the cache
// (a vertex shaded from it) and ADRRS (its estimate frames). Other PT pipelines trace no shadow ray.
const uint TECHNIQUES_ENDING_WITH_NEE = TECHNIQUES & (TECH_IC | TECH_ADRRS);

// What the techniques do on one path (set by the caller; PathOptions holds the base's).
struct TechniqueOptions {
    IcOptions ic;
    AdrrsOptions adrrs;
    GuidingOptions guiding;
};

TechniqueOptions no_techniques() {
    return TechniqueOptions(ic_no_options(), adrrs_no_options(), guiding_no_options());
}

// Camera paths of pixel `local` of this dispatch (P pixels); `px` gets the pixel's pass sums.
struct TechniquePixel {
    IcPixel ic;
    AdrrsPixel adrrs;
    GuidingPixel guiding;
    vec4 ears;  // EARS' factors summed and counted, its relative costs summed and counted (RRS passes)
};

TechniqueOptions camera_techniques(uint pixel_index, uint local, uint P, out TechniquePixel px) {
    bool estimate_frame = adrrs_estimate_frame();
    TechniqueOptions o;
    o.ic = ic_camera_options(pixel_index, estimate_frame);
    o.guiding = guiding_camera_options(pixel_index, estimate_frame);
    o.adrrs = adrrs_camera_options(pixel_index, local, P, px.adrrs);
    px.ic = ic_pixel();
    px.guiding = guiding_pixel();
    px.ears = vec4(0.0);
    return o;
}

// Sample s of the pixel (npix: the film's pixels).
// half_sample: the sample goes to adaptive sampling's half buffer (so do its split copies).
void techniques_sample(inout TechniqueOptions o, uint s, uint pixel_index, uint npix, bool half_sample) {
    guiding_sample_options(o.guiding, s, pixel_index, npix);
    adrrs_sample_options(o.adrrs, half_sample);
}

// A split copy's (adrrs.glsl's split queue).
TechniqueOptions split_techniques(uint pixel_index, uint local, uint P, bool half_sample) {
    TechniqueOptions o = no_techniques();
    o.ic = ic_split_options(pixel_index);
    o.adrrs = adrrs_split_options(pixel_index, local, P);
    o.adrrs.half_sample = half_sample;
    o.guiding = guiding_split_options();
    return o;
}

// The techniques' own frames (cache preparation, ADRRS estimates): what the frame makes is
// written here; true: the film is left alone.
bool techniques_frame_output(vec3 sum_radiance, uint pixel_index) {
    if (ic_prepare_frame()) return true;
    return adrrs_frame_output(sum_radiance, pixel_index);
}

// The per-path state of the techniques (trace_path's, beside its PathState).
struct TechniquePath {
    IcPath ic;
    GuidingPath guiding;
    vec4 ears;  // EARS' factors summed and counted, the relative cost at the first decision (ears_factor)
};

TechniquePath technique_path(TechniqueOptions o) {
    return TechniquePath(ic_first_path(o.ic), guiding_path(o.guiding), vec4(0.0));
}

// The next path of the same pixel (or walk): what a technique carries from path to path kept.
TechniquePath technique_next_path(TechniqueOptions o, TechniquePath previous) {
    return TechniquePath(ic_next_path(previous.ic), guiding_path(o.guiding), vec4(0.0));
}

// The techniques at a vertex: the guiding mixture there, and the cached (or adjoint)
// irradiance of the cache and ADRRS.
struct TechniqueVertex {
    GuidingVertex guiding;
    IcVertex ic;
    bool last;  // the path ends after this vertex's NEE (shaded from the cache, or an estimate)
};

TechniqueVertex techniques_vertex(inout TechniquePath path, TechniqueOptions o, Vertex v, float t, bool resumed,
                                  vec3 throughput, uint segments, inout vec3 radiance, inout Rng rng) {
    TechniqueVertex tv;
    tv.guiding = guiding_vertex(path.guiding, o.guiding, v.surf, v.roughness, v.delta, t, v.sh.p);
    bool handled;
    tv.ic = ic_vertex(path.ic, o.ic, v.surf, v.delta, v.sh.p, v.ns, resumed, throughput, segments, radiance, rng,
                      handled);
    if (!handled) adrrs_vertex_adjoint(o.adrrs, v.surf, v.delta, v.sh.p, v.ns, resumed, tv.ic.found, tv.ic.irradiance);
    tv.last = tv.ic.shaded || (o.adrrs.first_vertex_only && !v.delta);
    return tv;
}

// The path's radiance now holds the NEE of every vertex so far (a pending shadow ray was traced).
void techniques_light_resolved(inout TechniquePath path, vec3 radiance) {
    ic_light_resolved(path.ic, radiance);
}

// `radiance`: the sample's, as added to the film.
void techniques_add_sample(inout TechniquePixel px, TechniqueOptions o, TechniquePath path, vec3 radiance, uint s,
                           uvec2 pixel, vec3 origin, vec3 dir, float first_t) {
    ic_add_sample(px.ic, path.ic, radiance);
    guiding_add_sample(px.guiding, o.guiding, s, pixel, origin, dir, first_t);
    if (ears_on()) px.ears += path.ears;
}

// After the pixel's (or walk's) last path.
void techniques_end_pixel(TechniqueOptions o, TechniquePath last) {
    ic_end_pixel(o.ic, last.ic);
}

void techniques_write_passes(TechniquePixel px, uint pixel_index) {
    ic_write_passes(px.ic, pixel_index);
    guiding_write_passes(px.guiding, pixel_index);
    adrrs_write_passes(px.adrrs, pixel_index);
    if (ears_on()) {
        film_add(PASS_RRS_FACTOR, pixel_index, vec4(px.ears.xy, 0.0, 0.0));
        film_add(PASS_RRS_COST, pixel_index, vec4(px.ears.zw, 0.0, 0.0));
    }
}
