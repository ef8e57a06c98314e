// The camera's rays (SceneInfo camera_window, camera_to_world, clip).
#ifndef PARALLAX_CAMERA_GLSL
#define PARALLAX_CAMERA_GLSL

// A camera sample's position in its pixel ((0.5, 0.5): the centre; the filter's tails reach
// into the neighbours), drawn from the pixel filter: its inverted CDF (render/pixel_filter.h),
// interpolated, in x and in y. Importance-sampled, so every sample weighs 1 (Ernst et al. 2006).
float pixel_filter_offset(float u) {
    float x = u * float(PIXEL_FILTER_TABLE_SIZE - 1u);
    uint i = min(uint(x), PIXEL_FILTER_TABLE_SIZE - 2u);
    return mix(pixel_filter_table[i], pixel_filter_table[i + 1u], x - float(i));
}

vec2 pixel_filter_sample(vec2 u) {
    // A one-pixel box is a plain jitter: no table reads, and no branch on a frame parameter
    // (either cost the H200 5-8% of its PT frames, bench/results/regression_issue32_final).
    if (FILTER_FROM_TABLE == 0u) return u;
    return vec2(0.5 + pixel_filter_offset(u.x), 0.5 + pixel_filter_offset(u.y));
}

// The camera ray through image position (x, y) in pixels (row 0 = top); t_min, t_max from the
// clip distances, axis_cos = cos of the angle to the view axis.
void camera_ray(vec2 xy, out vec3 origin, out vec3 dir, out float t_min, out float t_max, out float axis_cos) {
    vec4 window = scene.camera_window;
    float sx = mix(window.x, window.y, xy.x / float(params.width));
    float sy = mix(window.w, window.z, xy.y / float(params.height));
    vec3 origin_cam, dir_cam;
    if (scene.camera_type == CAMERA_ORTHOGRAPHIC) {
        origin_cam = vec3(sx, sy, 0.0);
        dir_cam = vec3(0.0, 0.0, -1.0);
    } else {
        origin_cam = vec3(0.0);
        dir_cam = normalize(vec3(sx, sy, -1.0));
    }
    axis_cos = -dir_cam.z;  // clip distances are along the view axis
    origin = transform_point(scene.camera_to_world, origin_cam);
    dir = normalize(transform_vector(scene.camera_to_world, dir_cam));
    t_min = scene.clip.x / axis_cos;
    t_max = scene.clip.y / axis_cos;
}
#endif
