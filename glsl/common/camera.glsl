// Primary rays and box clipping, twin of src/view/camera.rs.
#ifndef VMLS_CAMERA_GLSL
#define VMLS_CAMERA_GLSL

// Ray through the centre of pixel (px, py), row 0 at the top (the scene contract's convention).
void camera_ray(uvec2 pixel, out vec3 origin, out vec3 dir) {
    float w = float(params.camera.width);
    float h = float(params.camera.height);
    float sx = 2.0 * (float(pixel.x) + 0.5) / w - 1.0;
    float sy = 1.0 - 2.0 * (float(pixel.y) + 0.5) / h;
    if (params.camera.projection == 0u) {
        float dx = sx * params.camera.tan_half_fov * w / h;
        float dy = sy * params.camera.tan_half_fov;
        origin = params.camera.eye.xyz;
        dir = normalize(params.camera.forward.xyz + dx * params.camera.right.xyz + dy * params.camera.up.xyz);
    } else {
        float hh = params.camera.ortho_half_height;
        origin = params.camera.eye.xyz + sx * hh * w / h * params.camera.right.xyz + sy * hh * params.camera.up.xyz;
        dir = params.camera.forward.xyz;
    }
}

// Slab test against [lo, hi]; t0 ≥ 0 (rays start at the eye). False when the ray misses.
// Axis-parallel rays are handled explicitly instead of relying on 1/0 = ∞.
bool clip_box(vec3 o, vec3 d, vec3 lo, vec3 hi, out float t0, out float t1) {
    t0 = 0.0;
    t1 = 3.0e38;
    for (int a = 0; a < 3; ++a) {
        if (abs(d[a]) < 1e-30) {
            if (o[a] < lo[a] || o[a] > hi[a]) {
                return false;
            }
        } else {
            float inv = 1.0 / d[a];
            float ta = (lo[a] - o[a]) * inv;
            float tb = (hi[a] - o[a]) * inv;
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    return t1 > t0;
}

#endif
