#version 450
#extension GL_EXT_control_flow_attributes : require
// Memory ceiling probes (stage `probe_memory`), one mode per variant:
//   PROBE_MODE 0: 32-bit gathers from a storage buffer at a random index per lane and load,
//   PROBE_MODE 1: the same gathers through a storage texel buffer (`imageLoad` of r32ui),
//   PROBE_MODE 2: streaming vec4 loads, consecutive lanes at consecutive addresses,
//   PROBE_COHERENT 1 (modes 0 and 1): each group of 8 consecutive invocations (one SIMD row on
//   llvmpipe) reads 8 consecutive words at a random base, as neighbouring rays read one octree
//   leaf or nearby grid rows,
//   PROBE_MODE 3: float adds by compare-and-swap loops (as splat_accumulate's sheet_add) at a
//   random one of PROBE_ATOMIC_WORDS words (a 512² image's four channels),
//   PROBE_MODE 4: a ray march's reads, as the fast path makes them: each 64 invocations are an
//   8×8 tile of parallel rays 0.3 cells apart, from a random point in a random direction; per
//   iteration every ray steps 0.5–0.9 cells and reads the 8 corners of its cell as rgba32ui
//   texels of a periodic MARCH_DIM³ grid (8 loads). Positions are fixed point (8 fractional
//   bits), so that the CPU twin walks the same cells.
// Every invocation makes `iterations` independent loads from PROBE_WORDS words (a power of two)
// and sums them (wrapping) so that none is dead. Twin: probe::memory_reference.

layout(local_size_x = 64) in;

#include "common/types.glsl"

layout(std430, binding = BINDING_PROBE) writeonly buffer ProbeBuf { uvec4 probe_out[]; };
#if PROBE_MODE == 1
layout(binding = BINDING_PROBE_TEXELS, r32ui) uniform readonly uimageBuffer probe_texels;
#elif PROBE_MODE == 4
layout(binding = BINDING_PROBE_TEXELS, rgba32ui) uniform readonly uimageBuffer probe_texels;
#elif PROBE_MODE == 2
layout(std430, binding = BINDING_PROBE_SOURCE) readonly buffer SourceBuf { uvec4 probe_vec4s[]; };
#elif PROBE_MODE == 3
layout(std430, binding = BINDING_PROBE_SOURCE) buffer AtomicBuf { uint probe_atomic[]; };
#else
layout(std430, binding = BINDING_PROBE_SOURCE) readonly buffer SourceBuf { uint probe_words[]; };
#endif
layout(push_constant) uniform Push { CountPush push; };

// A 32-bit integer hash (Wellons' lowbias32): uncorrelated indices for neighbouring lanes.
uint probe_hash(uint x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

#if PROBE_MODE == 4
// Twin of probe::march_start: a ray's fixed-point origin and step.
void march_start(uint id, out ivec3 origin, out ivec3 step) {
    uint h = probe_hash(id >> 6u);
    int mask = MARCH_DIM * 256 - 1;
    ivec3 start = ivec3(int(probe_hash(h) & uint(mask)), int(probe_hash(h + 1u) & uint(mask)),
                        int(probe_hash(h + 2u) & uint(mask)));
    step = ivec3(int(probe_hash(h + 3u) & 255u) - 128, int(probe_hash(h + 4u) & 255u) - 128, 128);
    origin = start + 77 * ivec3(int(id & 7u), int((id >> 3u) & 7u), 0);
}
#endif

void main() {
    uint id = gl_GlobalInvocationID.x;
    if (id >= push.count) {
        return;
    }
    uint sum = 0u;
#if PROBE_MODE == 4
    ivec3 origin, step;
    march_start(id, origin, step);
#endif
    for (uint it = 0u; it < push.iterations; ++it) {
#if PROBE_MODE == 4
        ivec3 cell = (origin + int(it) * step) >> 8;
        [[unroll]] for (int c = 0; c < 8; ++c) {
            ivec3 k = (cell + ivec3(c & 1, (c >> 1) & 1, c >> 2)) & (MARCH_DIM - 1);
            uvec4 v = imageLoad(probe_texels, k.x + MARCH_DIM * (k.y + MARCH_DIM * k.z));
            sum += v.x + v.y + v.z + v.w;
        }
#elif PROBE_MODE == 2
        uvec4 v = probe_vec4s[(it * push.count + id) & (PROBE_WORDS / 4u - 1u)];
        sum += v.x + v.y + v.z + v.w;
#elif PROBE_MODE == 3
        uint a = probe_hash(id * push.iterations + it) & (PROBE_ATOMIC_WORDS - 1u);
        uint old = probe_atomic[a];
        while (true) {
            uint seen = atomicCompSwap(probe_atomic[a], old, floatBitsToUint(uintBitsToFloat(old) + 1.0));
            if (seen == old) {
                break;
            }
            old = seen;
        }
        sum += 1u;
#else
#if PROBE_COHERENT == 1
        uint i = (probe_hash((id >> 3u) * push.iterations + it) & (PROBE_WORDS - 1u) & ~7u) | (id & 7u);
#else
        uint i = probe_hash(id * push.iterations + it) & (PROBE_WORDS - 1u);
#endif
#if PROBE_MODE == 1
        sum += imageLoad(probe_texels, int(i)).x;
#else
        sum += probe_words[i];
#endif
#endif
    }
    probe_out[id] = uvec4(sum, 0u, 0u, 0u);
}
