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

// A panorama's view direction at (u, v) of its image square ((0, 0): bottom left), in the frame
// Cycles defines its projections in (kernel/camera/projection.h): x forward, y left, z up;
// a zero vector outside the lens' image circle.
vec3 fisheye_direction(float theta, vec2 p, float r) {
    vec2 side = r > 0.0 ? p / r : vec2(0.0);
    return vec3(cos(theta), -sin(theta) * side.x, sin(theta) * side.y);
}

vec3 panorama_direction(vec2 uv) {
    vec4 range = scene.panorama_range;
    vec4 fisheye = scene.fisheye;  // fov, lens, sensor width, sensor height
    switch (scene.panorama_type) {
    case PANORAMA_EQUIRECTANGULAR: {
        float phi = -mix(range.x, range.y, uv.x), theta = 0.5 * PI - mix(range.z, range.w, uv.y);
        return vec3(sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta));
    }
    case PANORAMA_EQUIANGULAR_CUBEMAP_FACE:
        return normalize(vec3(1.0, tan((0.5 - uv.x) * 0.5 * PI), tan((uv.y - 0.5) * 0.5 * PI)));
    case PANORAMA_MIRRORBALL: {  // the ball's normal at (u, v) reflects a ray coming along +y
        vec2 p = 2.0 * uv - 1.0;
        if (dot(p, p) > 1.0) return vec3(0.0);
        vec3 n = vec3(p.x, -sqrt(max(1.0 - dot(p, p), 0.0)), p.y);
        return -reflect(vec3(0.0, -1.0, 0.0), n);
    }
    case PANORAMA_FISHEYE_EQUIDISTANT: {  // the angle grows with the radius, fov at the edge
        vec2 p = 2.0 * uv - 1.0;
        float r = length(p);
        return r > 1.0 ? vec3(0.0) : fisheye_direction(r * 0.5 * fisheye.x, p, r);
    }
    case PANORAMA_FISHEYE_EQUISOLID: {  // r = 2 f sin(theta / 2) on the sensor
        vec2 p = (uv - 0.5) * fisheye.zw;
        float r = length(p);
        if (r > 2.0 * fisheye.y * sin(0.25 * fisheye.x)) return vec3(0.0);
        return fisheye_direction(2.0 * asin(r / (2.0 * fisheye.y)), p, r);
    }
    case PANORAMA_FISHEYE_LENS_POLYNOMIAL: {
        vec2 p = (uv - 0.5) * fisheye.zw;
        float r = length(p);
        float theta = -(scene.fisheye_polynomial[0] +
                        r * (scene.fisheye_polynomial[1] +
                             r * (scene.fisheye_polynomial[2] +
                                  r * (scene.fisheye_polynomial[3] + r * scene.fisheye_polynomial[4]))));
        return abs(theta) > 0.5 * fisheye.x ? vec3(0.0) : fisheye_direction(theta, p, r);
    }
    default: {  // PANORAMA_CENTRAL_CYLINDRICAL
        float phi = -mix(range.x, range.y, uv.x);
        return normalize(vec3(cos(phi), sin(phi), mix(range.z, range.w, uv.y)));
    }
    }
}

// A point on the camera's aperture (camera space, world units) from a uniform u in [0, 1)^2.
vec2 camera_lens_point(vec2 u) {
    return scene.aperture_radius *
           aperture_sample(u, scene.aperture_blades, scene.aperture_rotation, scene.aperture_ratio);
}

// The camera ray through image position (x, y) in pixels (row 0 = top) and through `lens`, a
// point on the aperture (camera_lens_point; (0, 0): its centre, and a pinhole's only point),
// focused at the focus distance. t_min, t_max: the clip distances; depth_per_t: the Depth pass
// per unit of t (along the view axis; 1 for panoramas, as Cycles). False where a fisheye or
// mirror ball has no image: no ray.
bool camera_ray(vec2 xy, vec2 lens, out vec3 origin, out vec3 dir, out float t_min, out float t_max,
                out float depth_per_t) {
    vec4 window = scene.camera_window;
    float sx = mix(window.x, window.y, xy.x / float(params.width));
    float sy = mix(window.w, window.z, xy.y / float(params.height));
    vec3 origin_cam, dir_cam;
    float clip_scale;  // t per unit of clip distance
    if (!HAS(FEATURE_LENS)) {  // a pinhole: perspective or orthographic
        bool ortho = scene.camera_type == CAMERA_ORTHOGRAPHIC;
        origin_cam = ortho ? vec3(sx, sy, 0.0) : vec3(0.0);
        dir_cam = ortho ? vec3(0.0, 0.0, -1.0) : normalize(vec3(sx, sy, -1.0));
        depth_per_t = -dir_cam.z;
        clip_scale = 1.0 / depth_per_t;
    } else if (scene.camera_type == CAMERA_PERSPECTIVE) {
        // Cycles' thin lens: every ray through the pinhole ray's point on the plane of focus.
        vec3 pinhole = vec3(sx, sy, -1.0);
        origin_cam = vec3(lens, 0.0);
        dir_cam = normalize(scene.aperture_radius > 0.0 ? pinhole * scene.focus_distance - origin_cam : pinhole);
        clip_scale = length(pinhole);
        depth_per_t = -dir_cam.z;
    } else if (scene.camera_type == CAMERA_ORTHOGRAPHIC) {
        origin_cam = vec3(sx + lens.x, sy + lens.y, 0.0);
        dir_cam = scene.aperture_radius > 0.0 ? normalize(vec3(-lens, -scene.focus_distance)) : vec3(0.0, 0.0, -1.0);
        clip_scale = 1.0 / -dir_cam.z;
        depth_per_t = -dir_cam.z;
    } else {
        vec3 d = panorama_direction(vec2(sx, sy));
        if (d == vec3(0.0)) return false;
        if (scene.aperture_radius > 0.0) {  // Cycles: the lens turned to face the ray
            vec3 u_axis = vec3(1.0, 0.0, 0.0) - d.x * d;
            u_axis = dot(u_axis, u_axis) > 1e-12 ? normalize(u_axis) : vec3(0.0, 1.0, 0.0);
            vec3 p = lens.x * u_axis + lens.y * cross(d, u_axis);
            origin_cam = p;
            d = normalize(d * scene.focus_distance - p);
        } else {
            origin_cam = vec3(0.0);
        }
        // Cycles' panorama frame into Blender's camera (x right, y up, looking down -z), so
        // that the image centre looks forward (a mirror ball's frame looks along its -y).
        if (scene.panorama_type == PANORAMA_MIRRORBALL) {
            origin_cam = origin_cam.xzy;
            dir_cam = d.xzy;
        } else {
            origin_cam = vec3(-origin_cam.y, origin_cam.z, -origin_cam.x);
            dir_cam = vec3(-d.y, d.z, -d.x);
        }
        clip_scale = 1.0;
        depth_per_t = 1.0;
    }
    origin = transform_point(scene.camera_to_world, origin_cam);
    dir = normalize(transform_vector(scene.camera_to_world, dir_cam));
    t_min = scene.clip.x * clip_scale;
    t_max = scene.clip.y * clip_scale;
    return true;
}
#endif
