// The hull segments cache (twin: src/raycast/segments.rs): each pixel's inside segments of a
// mesh's hull as a camera's first frame walked them (hull_segments, HULL_CACHED 2 keeps them),
// which its later frames read instead of walking the hull's BVH again (HULL_CACHED 1; a walk was
// about half of a 512² frame on the room-fire mesh). Per pixel RAY_SEGMENT_TEXELS rgba32f texels
// holding, in order, the segment count (−1: more crossings than HULL_MAX_HITS) and the
// segments' (t_in, t_out). Needs HULL_MAX_HITS and the declaration of `ray_segments` before it
// (writable with RAY_SEGMENTS_WRITE, else read-only).
#ifndef VMLS_SEGMENTS_GLSL
#define VMLS_SEGMENTS_GLSL

#ifndef HULL_SEGMENTS
#define HULL_SEGMENTS (HULL_MAX_HITS / 2 + 1)
#endif
#define RAY_SEGMENT_FLOATS (2 * HULL_SEGMENTS + 1)
#define RAY_SEGMENT_TEXELS ((RAY_SEGMENT_FLOATS + 3) / 4)

#ifdef RAY_SEGMENTS_WRITE
void segments_store(uint pixel, int count, vec2 seg[HULL_SEGMENTS]) {
    float f[4 * RAY_SEGMENT_TEXELS];
    f[0] = float(count);
    [[unroll]] for (int i = 0; i < HULL_SEGMENTS; ++i) {
        vec2 s = i < count ? seg[i] : vec2(0.0);
        f[1 + 2 * i] = s.x;
        f[2 + 2 * i] = s.y;
    }
    [[unroll]] for (int k = RAY_SEGMENT_FLOATS; k < 4 * RAY_SEGMENT_TEXELS; ++k) {
        f[k] = 0.0;
    }
    int base = int(pixel) * RAY_SEGMENT_TEXELS;
    [[unroll]] for (int t = 0; t < RAY_SEGMENT_TEXELS; ++t) {
        imageStore(ray_segments, base + t, vec4(f[4 * t], f[4 * t + 1], f[4 * t + 2], f[4 * t + 3]));
    }
}
#else
// The count, as hull_segments returns it, and the segments.
int segments_load(uint pixel, out vec2 seg[HULL_SEGMENTS]) {
    float f[4 * RAY_SEGMENT_TEXELS];
    int base = int(pixel) * RAY_SEGMENT_TEXELS;
    [[unroll]] for (int t = 0; t < RAY_SEGMENT_TEXELS; ++t) {
        vec4 v = imageLoad(ray_segments, base + t);
        f[4 * t] = v.x;
        f[4 * t + 1] = v.y;
        f[4 * t + 2] = v.z;
        f[4 * t + 3] = v.w;
    }
    [[unroll]] for (int i = 0; i < HULL_SEGMENTS; ++i) {
        seg[i] = vec2(f[1 + 2 * i], f[2 + 2 * i]);
    }
    // Written by segments_store for this pixel (the host's key says so); clamped all the same,
    // since the ray caster indexes its segments by it.
    return clamp(int(f[0]), -1, HULL_SEGMENTS);
}
#endif

#endif
