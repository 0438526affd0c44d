#version 450
// Stage splat_project: f32 twin of src/splat/project.rs ([EWA] §4-6). One invocation per
// kernel: ray-space Jacobian, footprint, resampling filter, conic, bounding box, depth and
// sheet range, culling guards; counts one entry per (image tile, sheet) it touches into the
// bucket tile * sheets + sheet (splat_scan and splat_bin sort by it).
// Variant macros: SPLAT_POST (0 pre-shaded, 1 post-shaded), SPLAT_ANTIALIAS (0 ewa, 1 swan,
// 2 none, 3 auto), SPLAT_ORTHO (0 perspective, 1 orthographic), SPLAT_EXACT (per-pixel ray integrals
// instead of the affine footprint; perspective only), SPLAT_SURFACES (surface splats of
// isosurfaces: metric_off.w = 1 + isosurface index, pos_value.w = the metric's scale).
#extension GL_EXT_control_flow_attributes : enable

layout(local_size_x = 64) in;

#include "common/types.glsl"

#include "splat/splat_params.glsl"
layout(rgba32f, binding = BINDING_SPLAT_KERNELS) readonly uniform imageBuffer kernel_texels;
layout(rgba32f, binding = BINDING_SPLATS) writeonly uniform imageBuffer splat_texels;
layout(rgba32ui, binding = BINDING_SPLAT_WORDS) writeonly uniform uimageBuffer splat_words;
#define SPLAT_WRITE
layout(std430, binding = BINDING_BUCKET_COUNTS) buffer CountBuf { uint bucket_counts[]; };
layout(std430, binding = BINDING_SPLAT_STATS) buffer StatsBuf { uint stats[]; };

#include "splat/splat.glsl"

#if SPLAT_POST == 0
#include "common/transfer.glsl"
#endif
#if SPLAT_SURFACES == 1
#include "common/shading.glsl"
// Tangential over normal standard deviation (src/splat/surface.rs FLATNESS).
const float FLATNESS = 10.0;
#endif

// SplatCounts order: projected, near, outside, degenerate, empty.
const uint CULL_NEAR = 1u;
const uint CULL_OUTSIDE = 2u;
const uint CULL_DEGENERATE = 3u;
const uint CULL_EMPTY = 4u;
// SplatCounts::oversized (slots 5 to 7 belong to other stages).
const uint CULL_OVERSIZED = 8u;

const float MIN_VARIANCE = 1e-6;

// A kernel's entries start every SHEET_STEP sheets of its range (each covers that many).
#if SPLAT_RING > 0
const uint SHEET_STEP = uint(SPLAT_RING);
#else
const uint SHEET_STEP = 1u;
#endif

Splat culled(uint reason) {
    atomicAdd(stats[reason], 1u);
    Splat s;
    s.footprint0 = vec4(0.0);
    s.footprint1 = vec4(0.0);
    s.footprint2 = vec4(0.0);
    s.footprint3 = vec4(0.0);
    s.color = vec4(0.0);
    s.bbox = ivec4(0);
    s.slabs = uvec4(1u, 0u, 0u, 0u);
    return s;
}

// M^-1 of the metric (xx, yy, zz, xy, xz, yz); false when singular.
bool metric_inverse(vec4 m, vec4 mo, out mat3 inv) {
    float a = m.x, b = m.y, c = m.z, d = m.w, e = mo.x, f = mo.y;
    float c00 = b * c - f * f;
    float c01 = e * f - d * c;
    float c02 = d * f - b * e;
    float c11 = a * c - e * e;
    float c12 = d * e - a * f;
    float c22 = a * b - d * d;
    float det = a * c00 + d * c01 + e * c02;
    if (!(det > 0.0) || isinf(det)) {
        return false;
    }
    float i = 1.0 / det;
    // Symmetric: column-major equals row-major.
    inv = mat3(c00, c01, c02, c01, c11, c12, c02, c12, c22) * i;
    return true;
}

// Twin of cutoff_conic in src/splat/project.rs: the image-plane ellipse of the rays within
// `cut` of the kernel centre, d'^T (K - cut^2 Q) d' <= 0 with K = [r]x^T adj(P) [r]x. Writes
// (centre x, centre y, half width, half height) in pixels; false when it is not an ellipse.
bool cutoff_conic(mat3 qm, mat3 jm, vec3 r, float cut, out vec4 box) {
    // Cross-product matrix of r (columns), so that x * d = r x d.
    mat3 x = mat3(0.0, r.z, -r.y, -r.z, 0.0, r.x, r.y, -r.x, 0.0);
    mat3 hm = transpose(x) * jm * x - qm * (cut * cut);
    float h00 = hm[0][0], h01 = hm[1][0], h11 = hm[1][1];
    float h02 = hm[2][0], h12 = hm[2][1], h22 = hm[2][2];
    float det = h00 * h11 - h01 * h01;
    box = vec4(0.0);
    if (!(h00 > 0.0) || !(det > 0.0) || isinf(det)) {
        return false;
    }
    float cx = -(h11 * h02 - h01 * h12) / det;
    float cy = -(h00 * h12 - h01 * h02) / det;
    float f0 = h22 + h02 * cx + h12 * cy;
    if (!(f0 < 0.0)) {
        return false;
    }
    float f = params.focal;
    box = vec4(params.centre_x + f * cx, params.centre_y - f * cy,
               f * sqrt(-f0 * h11 / det), f * sqrt(-f0 * h00 / det));
    return true;
}

Splat project(Sample k) {
    vec3 p = k.pos_value.xyz;
    float value = k.pos_value.w;
    float volume = k.metric_off.z;
    float opacity = 0.0;
#if SPLAT_POST == 1
    float weight = value * volume;
    vec3 color = vec3(0.0);
#else
    float weight;
    vec3 color;
#if SPLAT_SURFACES == 1
    if (k.metric_off.w > 0.5) {
        IsoSurface iso = isos[uint(k.metric_off.w) - 1u];
#if SPLAT_ORTHO == 1
        vec3 view = params.camera.forward.xyz;
#else
        vec3 view = normalize(p - params.camera.eye.xyz);
#endif
        vec4 m = k.metric, mo = k.metric_off;
        float rho2 = m.x * view.x * view.x + m.y * view.y * view.y + m.z * view.z * view.z
                   + 2.0 * (m.w * view.x * view.y + mo.x * view.x * view.z + mo.y * view.y * view.z);
        float c = sqrt(clamp((rho2 / value - 1.0) / (FLATNESS * FLATNESS - 1.0), 0.0, 1.0));
        weight = volume * c;
        color = shade_cos(iso, c);
        opacity = iso.color_opacity.a;
    } else
#endif
    {
        vec4 ct = transfer_lookup(value, params.tf_count);
        weight = ct.a * volume;
        color = ct.rgb;
    }
#endif
    if (weight == 0.0) {
        return culled(CULL_EMPTY);
    }
    mat3 minv;
    if (!metric_inverse(k.metric, k.metric_off, minv)) {
        return culled(CULL_DEGENERATE);
    }
    float sigma = params.sigma;
    mat3 v_obj = minv * (sigma * sigma);
    vec3 right = params.camera.right.xyz, up = params.camera.up.xyz, fwd = params.camera.forward.xyz;
    vec3 d = p - params.camera.eye.xyz;
    vec3 u = vec3(dot(d, right), dot(d, up), dot(d, fwd));
    float cutoff = params.cutoff;
    float reach = cutoff * sqrt(max(dot(fwd, v_obj * fwd), 0.0));
    if (u.z - reach <= params.near) {
        return culled(CULL_NEAR);
    }
    float f = params.focal;
    vec2 centre;
    float t;
    // Rows of A = J W, stored as the columns of `at` (at = transpose(A)).
#if SPLAT_ORTHO == 1
    centre = vec2(params.centre_x + f * u.x, params.centre_y - f * u.y);
    t = u.z;
    mat3 at = mat3(f * right, -f * up, fwd);
#else
    float l = length(u);
    float inv = 1.0 / u.z;
    float cx = clamp(u.x * inv, -params.lateral_x, params.lateral_x);
    float cy = clamp(u.y * inv, -params.lateral_y, params.lateral_y);
    centre = vec2(params.centre_x + f * u.x * inv, params.centre_y - f * u.y * inv);
    t = l;
    vec3 j0 = vec3(f * inv, 0.0, -f * cx * inv);
    vec3 j1 = vec3(0.0, -f * inv, f * cy * inv);
    vec3 j2 = u / l;
    // Row i of J W is sum_k J[i][k] W[k] with W's rows right, up, forward.
    mat3 at = mat3(j0.x * right + j0.y * up + j0.z * fwd,
                   j1.x * right + j1.y * up + j1.z * fwd,
                   j2.x * right + j2.y * up + j2.z * fwd);
#endif
    // V = A V'' A^T; with at = A^T: V = transpose(at) * v_obj * at.
    mat3 v = transpose(at) * v_obj * at;
    vec3 vhat = vec3(v[0][0], v[1][0], v[1][1]);
    vec2 vxt = vec2(v[2][0], v[2][1]);
    float vtt = v[2][2];
    float det_hat = vhat.x * vhat.z - vhat.y * vhat.y;
    vec3 vf = vec3(max(vhat.x, MIN_VARIANCE), vhat.y, max(vhat.z, MIN_VARIANCE));
    float lowpass = params.lowpass;
#if SPLAT_ANTIALIAS == 0 || SPLAT_ANTIALIAS == 3
    // The screen low-pass added (twin: screen_lowpass): EWA's lowpass I, or auto's
    // sum of max(lowpass - lambda_i, 0) e_i e_i^T over the eigenpairs of vf.
#if SPLAT_ANTIALIAS == 0
    vec3 dl = vec3(lowpass, 0.0, lowpass);
#else
    float mean = 0.5 * (vf.x + vf.z);
    float r = sqrt(0.25 * (vf.x - vf.z) * (vf.x - vf.z) + vf.y * vf.y);
    float l2 = mean - r;
    float d1 = max(lowpass - (mean + r), 0.0);
    float d2 = max(lowpass - l2, 0.0);
    float g = r > 0.0 ? (d1 - d2) / (2.0 * r) : 0.0;
    vec3 dl = vec3(d2 + g * (vf.x - l2), g * vf.y, d2 + g * (vf.z - l2));
#endif
    vf += dl;
#elif SPLAT_ANTIALIAS == 1
    float mean = 0.5 * (vf.x + vf.z);
    float r = sqrt(0.25 * (vf.x - vf.z) * (vf.x - vf.z) + vf.y * vf.y);
    float minor = max(mean - r, MIN_VARIANCE);
    vf *= max(lowpass / minor, 1.0);
#endif
    float det_f = vf.x * vf.z - vf.y * vf.y;
    if (!(det_hat > 0.0) || !(det_f > 0.0) || isinf(det_f)) {
        return culled(CULL_DEGENERATE);
    }
    vec2 slope = vec2(vhat.z * vxt.x - vhat.y * vxt.y, vhat.x * vxt.y - vhat.y * vxt.x) / det_hat;
    float cond = max(vtt - dot(slope, vxt), 1e-12 * vtt);
    float amplitude = weight * abs(determinant(at)) / (6.283185307179586 * sqrt(det_f));
    vec3 conic = vec3(vf.z, -vf.y, vf.x) / det_f;
#if SPLAT_EXACT == 0
    float checks_exact = 0.0;
    vec4 box = vec4(centre, cutoff * sqrt(vf.x), cutoff * sqrt(vf.z));
#else
    // Perspective-exact footprint: the filtered covariance in object space (the screen
    // low-pass dl pulled back through A), its precision and adjugate in the camera frame.
    mat3 a_mat = transpose(at);
#if SPLAT_ANTIALIAS == 0 || SPLAT_ANTIALIAS == 3
    mat3 ai = inverse(a_mat);
    mat3 v_f = v_obj + ai * mat3(dl.x, dl.y, 0.0, dl.y, dl.z, 0.0, 0.0, 0.0, 0.0) * transpose(ai);
#elif SPLAT_ANTIALIAS == 1
    mat3 v_f = v_obj * (vf.x / max(vhat.x, MIN_VARIANCE));
#else
    mat3 v_f = v_obj;
#endif
    mat3 p_obj = inverse(v_f);
    float det_p = determinant(p_obj);
    if (!(det_p > 0.0) || isinf(det_p)) {
        return culled(CULL_DEGENERATE);
    }
    mat3 e_rows = transpose(mat3(right, up, fwd));
    mat3 qm = e_rows * p_obj * transpose(e_rows);
    mat3 jm = e_rows * v_f * transpose(e_rows) * det_p;
    float ray_amp = weight * sqrt(det_p) / 6.283185307179586;
    float checks_exact = qm[0][0] + qm[1][0] + qm[1][1] + qm[2][0] + qm[2][1] + qm[2][2]
                       + jm[0][0] + jm[1][0] + jm[1][1] + jm[2][0] + jm[2][1] + jm[2][2] + ray_amp;
    vec4 box;
    if (!cutoff_conic(qm, jm, -u, cutoff, box)) {
        return culled(CULL_DEGENERATE);
    }
#endif
    float w = float(params.camera.width), h = float(params.camera.height);
    // Within the frame's window (a brick's: the pixels and sheets it can own).
    ivec4 bbox = ivec4(
        max(int(min(max(ceil(box.x - box.z), 0.0), w)), params.pixel_window.x),
        max(int(min(max(ceil(box.y - box.w), 0.0), h)), params.pixel_window.y),
        min(int(max(min(floor(box.x + box.z), w - 1.0), -1.0)), params.pixel_window.z),
        min(int(max(min(floor(box.y + box.w), h - 1.0), -1.0)), params.pixel_window.w));
    float spread = slope.x * (vf.x * slope.x + vf.y * slope.y)
                 + slope.y * (vf.y * slope.x + vf.z * slope.y);
    float depth_reach = cutoff * (sqrt(max(spread, 0.0)) + sqrt(cond));
#if SPLAT_EXACT == 1
    // The affine reach does not bound off-centre rays near the eye; the kernel's cutoff
    // ellipsoid does (lambda_max bounded by the largest Gershgorin row sum).
    vec3 one = vec3(1.0);
    float gershgorin = max(max(dot(abs(v_f[0]), one), dot(abs(v_f[1]), one)), dot(abs(v_f[2]), one));
    depth_reach = max(depth_reach, cutoff * sqrt(gershgorin));
#endif
#if SPLAT_WIDEN == 1
    // A kernel the quadrature widens reaches that much further (twin: thinner_than in
    // src/splat/project.rs): its affine deviation, or for exact footprints a lower bound over
    // every direction, sigma^2 / the metric's Gershgorin bound on its largest eigenvalue.
    float widened = params.slab_world / float(QUADRATURE_MAX_SHEET);
#if SPLAT_EXACT == 1
    vec4 wm = k.metric, wmo = k.metric_off;
    float lmax = max(max(wm.x + abs(wm.w) + abs(wmo.x), wm.y + abs(wm.w) + abs(wmo.y)),
                     wm.z + abs(wmo.x) + abs(wmo.y));
    float thinnest = sigma * sigma / lmax;
#else
    float thinnest = cond;
#endif
    if (thinnest < widened * widened) {
        depth_reach += cutoff * widened;
    }
#endif
    float slab0 = params.slab0_world, slab = params.slab_world;
    float first = max(floor((t - depth_reach - slab0) / slab), float(params.sheet_first));
    float last = min(floor((t + depth_reach - slab0) / slab), float(params.sheet_last));
    float checks = amplitude + conic.x + conic.y + conic.z + slope.x + slope.y + t + cond
                 + checks_exact;
    if (isnan(checks) || isinf(checks)) {
        return culled(CULL_DEGENERATE);
    }
    if (bbox.x > bbox.z || bbox.y > bbox.w || last < 0.0 || first >= float(params.slabs)
        || first > last) {
        return culled(CULL_OUTSIDE);
    }
    uvec4 rect = tile_rect(bbox);
    uint tiles = (rect.z - rect.x + 1u) * (rect.w - rect.y + 1u);
    uint s0 = uint(max(first, 0.0));
    uint s1 = uint(min(last, float(params.slabs - 1u)));
#if SPLAT_SPLIT == 0
    // Whole kernels go to the sheet of their centre.
    s0 = uint(clamp(floor((t - slab0) / slab), 0.0, float(params.slabs - 1u)));
    s1 = s0;
    if (s0 < params.sheet_first || s0 > params.sheet_last) {
        return culled(CULL_OUTSIDE);
    }
#endif
#if SPLAT_RING > 0
    // Ring registers: one entry per tile and per SPLAT_RING sheets.
    uint per_tile = (s1 - s0) / uint(SPLAT_RING) + 1u;
#else
    uint per_tile = s1 - s0 + 1u;
#endif
    // splat_bin writes a kernel's entries in one invocation: bounded (src/splat/mod.rs).
    if (float(per_tile) * float(tiles) > float(SPLAT_MAX_KERNEL_ENTRIES)) {
        return culled(CULL_OVERSIZED);
    }
    Splat s;
#if SPLAT_EXACT == 0
    s.footprint0 = vec4(centre, t, sqrt(cond));
    s.footprint1 = vec4(conic, amplitude);
    s.footprint2 = vec4(slope, 0.0, 0.0);
    s.footprint3 = vec4(0.0);
#else
    s.footprint0 = vec4(qm[0][0], qm[1][0], qm[1][1], qm[2][0]);
    s.footprint1 = vec4(qm[2][1], qm[2][2], -u.x, -u.y);
    s.footprint2 = vec4(jm[0][0], jm[1][0], jm[1][1], jm[2][0]);
    s.footprint3 = vec4(jm[2][1], jm[2][2], -u.z, ray_amp);
#endif
    s.color = vec4(color, opacity);
    s.bbox = bbox;
    s.slabs = uvec4(s0, s1, tiles, (s1 - s0 + 1u) * tiles);
    return s;
}

void main() {
    load_params();
    uint stride = gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    for (uint i = gl_GlobalInvocationID.x; i < params.kernel_count; i += stride) {
        atomicAdd(stats[0], 1u);
        Sample k;
        k.pos_value = imageLoad(kernel_texels, int(3u * i));
        k.metric = imageLoad(kernel_texels, int(3u * i + 1u));
        k.metric_off = imageLoad(kernel_texels, int(3u * i + 2u));
        Splat s = project(k);
        store_splat(i, s);
        if (s.slabs.x > s.slabs.y) {
            continue;
        }
        uvec4 r = tile_rect(s.bbox);
        for (uint ty = r.y; ty <= r.w; ++ty) {
            for (uint tx = r.x; tx <= r.z; ++tx) {
                uint first = (ty * params.tiles_x + tx) * params.slabs;
                for (uint k = s.slabs.x; k <= s.slabs.y; k += SHEET_STEP) {
                    atomicAdd(bucket_counts[first + k], 1u);
                }
            }
        }
    }
}
