// Ray–hull clipping, f32 twin of src/samples/bvh.rs (stage `hull_segments`): the inside
// segments of a ray through a mesh's outward-facing boundary triangles, found through a BVH.
// Watertight ray–triangle test (Woop, Benthin, Wald, JCGT 2013) and a winding number, so a
// ray through a shared edge or vertex neither misses the surface nor flips inside and outside.
// Needs BINDING_HULL_NODES / BINDING_HULL_TRIS and HULL_MAX_HITS, HULL_HIT_MERGE from the host.
#ifndef VMLS_HULL_GLSL
#define VMLS_HULL_GLSL

// Both through texel views: every lane of a SIMD row reads its own node or triangle, a gather
// on lavapipe where a storage-buffer load is a loop over the lanes.
// Nodes in depth-first preorder (bvh.rs): nodes[2i] = (bits(lo), first), nodes[2i + 1] =
// (bits(hi), count) as integer texels (a float view could flush the small integers' bits as
// denormals); count 0: inner node, first child i + 1, `first` its escape past the subtree.
layout(rgba32ui, binding = BINDING_HULL_NODES) readonly uniform uimageBuffer hull_nodes;
// Three vertices per triangle, in leaf order.
layout(rgba32f, binding = BINDING_HULL_TRIS) readonly uniform imageBuffer hull_tris;

#define HULL_SEGMENTS (HULL_MAX_HITS / 2 + 1)

bool hull_slab(vec3 o, vec3 d, vec3 inv, vec3 lo, vec3 hi) {
    float t0 = 0.0;
    float t1 = 3.0e38;
    for (int a = 0; a < 3; ++a) {
        if (abs(d[a]) < 1e-30) {
            if (o[a] < lo[a] || o[a] > hi[a]) {
                return false;
            }
        } else {
            float ta = (lo[a] - o[a]) * inv[a];
            float tb = (hi[a] - o[a]) * inv[a];
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        }
    }
    return t0 <= t1;
}

// Signed hit: +t entering, −t leaving; 0 for a miss (or a hit at t ≤ 0, behind the eye).
float hull_intersect(vec3 o, vec3 d, int kx, int ky, int kz, vec3 shear, uint tri) {
    int at = int(3u * tri);
    vec3 a = imageLoad(hull_tris, at).xyz - o;
    vec3 b = imageLoad(hull_tris, at + 1).xyz - o;
    vec3 c = imageLoad(hull_tris, at + 2).xyz - o;
    float ax = a[kx] - shear.x * a[kz], ay = a[ky] - shear.y * a[kz];
    float bx = b[kx] - shear.x * b[kz], by = b[ky] - shear.y * b[kz];
    float cx = c[kx] - shear.x * c[kz], cy = c[ky] - shear.y * c[kz];
    float u = cx * by - cy * bx;
    float v = ax * cy - ay * cx;
    float w = bx * ay - by * ax;
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) {
        return 0.0;
    }
    float det = u + v + w;
    if (det == 0.0) {
        return 0.0;
    }
    float t = (u * shear.z * a[kz] + v * shear.z * b[kz] + w * shear.z * c[kz]) / det;
    if (!(t > 0.0)) {
        return 0.0;
    }
    return det < 0.0 ? -t : t;
}

// Writes the inside segments front to back; returns their number, or −1 when the ray crosses
// the hull more than HULL_MAX_HITS times.
int hull_segments(vec3 o, vec3 d, out vec2 seg[HULL_SEGMENTS]) {
    float hits[HULL_MAX_HITS];
    int n = 0;
    int kz = abs(d.x) > abs(d.y) ? (abs(d.x) > abs(d.z) ? 0 : 2) : (abs(d.y) > abs(d.z) ? 1 : 2);
    int kx = (kz + 1) % 3;
    int ky = (kx + 1) % 3;
    if (d[kz] < 0.0) {
        int t = kx;
        kx = ky;
        ky = t;
    }
    vec3 shear = vec3(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz]);
    vec3 inv = 1.0 / d;
    // Stackless walk (escape links): one index instead of a stack, which a dynamically
    // indexed local array would keep in memory. The root's escape is the node count.
    uint node = 0u;
    uint end = 1u;
    bool overflow = false;
    while (node < end) {
        uvec4 lo = imageLoad(hull_nodes, int(2u * node));
        uvec4 hi = imageLoad(hull_nodes, int(2u * node + 1u));
        bool hit = hull_slab(o, d, inv, uintBitsToFloat(lo.xyz), uintBitsToFloat(hi.xyz));
        if (hi.w == 0u) {
            if (node == 0u) {
                end = lo.w;
            }
            node = hit ? node + 1u : lo.w;
            continue;
        }
        if (hit) {
            for (uint k = lo.w; k < lo.w + hi.w; ++k) {
                float h = hull_intersect(o, d, kx, ky, kz, shear, k);
                if (h != 0.0) {
                    if (n == HULL_MAX_HITS) {
                        overflow = true;
                    } else {
                        hits[n] = h;
                        n += 1;
                    }
                }
            }
        }
        node += 1u;
    }
    if (overflow) {
        return -1;
    }
    // Insertion sort by distance; the sign is the step.
    for (int i = 1; i < n; ++i) {
        float h = hits[i];
        int j = i - 1;
        while (j >= 0 && abs(hits[j]) > abs(h)) {
            hits[j + 1] = hits[j];
            j -= 1;
        }
        hits[j + 1] = h;
    }
    // One crossing per run of same-direction hits at one distance (bvh.rs merge_coincident):
    // the triangles around a shared edge or vertex may each report it.
    int m = 0;
    for (int i = 0; i < n; ++i) {
        float h = hits[i];
        if (m > 0 && (h > 0.0) == (hits[m - 1] > 0.0) &&
            abs(h) - abs(hits[m - 1]) <= HULL_HIT_MERGE * abs(h)) {
            continue;
        }
        hits[m] = h;
        m += 1;
    }
    n = m;
    int w = 0;
    for (int i = 0; i < n; ++i) {
        w -= hits[i] > 0.0 ? 1 : -1;
    }
    int count = 0;
    float start = 0.0;
    bool inside = w > 0;
    for (int i = 0; i < n; ++i) {
        float t = abs(hits[i]);
        w += hits[i] > 0.0 ? 1 : -1;
        if (!inside && w > 0) {
            inside = true;
            start = t;
        } else if (inside && w <= 0) {
            inside = false;
            if (t > start) {
                seg[count] = vec2(start, t);
                count += 1;
            }
        }
    }
    return count;
}

#endif
