// Knots and interval emission (stage composite_interval): f32 twin of
// src/raycast/interval.rs. A knot is vec4(t, s, ∇f·d, defined ? 1 : 0). Isosurface
// crossings are located by Illinois regula falsi; a near-tangent double crossing is found from
// the cubic Hermite through two knots' values and directional derivatives, and the interval is
// split at the extremum. Needs `params`, mls_evaluate and, for RAY_METHOD != 0, preint.glsl.
#ifndef VMLS_INTERVAL_GLSL
#define VMLS_INTERVAL_GLSL

// A knot's w is 1 (defined) or 0 (undefined); PENDING marks a knot not evaluated yet, the ray
// inside a run of empty blocks (at its start, or past a chunk's end).
#define PENDING (-1.0)

// A point on the ray: (t, s, ∇f·d, defined ? 1 : 0); its gradient is returned separately.
vec4 knot_gradient(vec3 o, vec3 d, float t, inout uint evaluations, out vec3 gradient) {
    MlsResult m = mls_evaluate(o + d * t);
    evaluations += 1u;
    gradient = m.gradient;
    return vec4(t, m.value, dot(m.gradient, d), m.terms > 0u ? 1.0 : 0.0);
}

vec4 knot(vec3 o, vec3 d, float t, inout uint evaluations) {
    vec3 unused;
    return knot_gradient(o, d, t, evaluations, unused);
}

#if MAX_ISO > 0
// Whether f crosses v in (a, e] (twin of interval::crosses).
bool crosses(float sa, float se, float v) {
    return (sa - v) * (se - v) < 0.0 || (se == v && sa != v);
}

// The isosurface values in registers (load_isos() at the start of main): the fixed-step loop
// tests them every interval, and a storage-buffer read is a loop over the lanes on llvmpipe.
vec4 iso_values = vec4(0.0);

void load_isos() {
    [[unroll]] for (int i = 0; i < MAX_ISO; ++i) {
        if (uint(i) < params.integrator.iso_count) {
            iso_values[i] = isos[i].value;
        }
    }
}
#endif

// Whether emit_interval does more with [a, e] than composite its table segment: both ends
// defined and an isosurface crossed, or a near-tangent double crossing possible (the
// preconditions of split_at_extremum). A cheap test for the hot loop of the fixed-step
// integrator; false without isosurfaces.
bool needs_surfaces(vec4 a, vec4 e) {
#if MAX_ISO > 0
    bool turn = a.z * e.z < 0.0;
    float sign_f = a.z > 0.0 ? 1.0 : -1.0;
    float top = max(sign_f * a.y, sign_f * e.y);
    bool any = false;
    [[unroll]] for (int i = 0; i < MAX_ISO; ++i) {
        float v = iso_values[i];
        bool live = uint(i) < params.integrator.iso_count;
        any = any || (live && (crosses(a.y, e.y, v) || (turn && sign_f * v > top)));
    }
    return any && a.w != 0.0 && e.w != 0.0;
#else
    return false;
#endif
}

#if MAX_ISO > 0

const uint LOCATE_ITERATIONS = 12u;
const uint EXTREMUM_ITERATIONS = 3u;
const uint HERMITE_BISECTIONS = 24u;

// Regula falsi (Illinois) for f = v between knots a and e; returns t, the gradient there.
// A knot exactly at v is re-evaluated for its gradient (knots do not carry one).
float locate_crossing(vec3 o, vec3 d, vec4 a, vec4 e, float v, inout uint evaluations,
                      out vec3 gradient) {
    if (e.y == v) {
        knot_gradient(o, d, e.x, evaluations, gradient);
        return e.x;
    }
    gradient = vec3(0.0);
    vec2 lo = vec2(a.x, a.y - v);
    vec2 hi = vec2(e.x, e.y - v);
    float width = e.x - a.x;
    float best = e.x;
    for (uint it = 0u; it < LOCATE_ITERATIONS; ++it) {
        float t = clamp(lo.x - lo.y * (hi.x - lo.x) / (hi.y - lo.y), lo.x, hi.x);
        vec3 g;
        vec4 k = knot_gradient(o, d, t, evaluations, g);
        if (k.w == 0.0) {
            return best;
        }
        best = t;
        gradient = g;
        float fk = k.y - v;
        if (abs(fk) <= 1e-6 || hi.x - lo.x <= 1e-6 * width) {
            break;
        }
        if ((fk < 0.0) == (lo.y < 0.0)) {
            lo = vec2(t, fk);
            hi.y *= 0.5;
        } else {
            hi = vec2(t, fk);
            lo.y *= 0.5;
        }
    }
    return best;
}

// The extremum of the cubic Hermite on u in [0, 1] with end values p0, p1 and end derivatives
// m0, m1 of opposite signs: (u, p(u)) where p'(u) = 0, by bisection (twin of
// interval::hermite_extremum).
vec2 hermite_extremum(float p0, float p1, float m0, float m1) {
    float delta = p1 - p0;
    float b = 3.0 * delta - 2.0 * m0 - m1;
    float c = m0 + m1 - 2.0 * delta;
    float lo = 0.0;
    float hi = 1.0;
    for (uint i = 0u; i < HERMITE_BISECTIONS; ++i) {
        float u = 0.5 * (lo + hi);
        float slope = m0 + u * (2.0 * b + 3.0 * c * u);
        if ((slope > 0.0) == (m0 > 0.0)) {
            lo = u;
        } else {
            hi = u;
        }
    }
    float u = 0.5 * (lo + hi);
    return vec2(u, p0 + u * (m0 + u * (b + c * u)));
}

// For knots a, e whose directional derivative changes sign: true and the knot m at the extremum
// between them once f there reaches the nearest isosurface beyond both ends on the extremum's
// side (twin of interval::split_at_extremum).
bool split_at_extremum(vec3 o, vec3 d, vec4 a, vec4 e, inout uint evaluations, out vec4 m) {
    m = e;
    if (a.w == 0.0 || e.w == 0.0 || !(a.z * e.z < 0.0)) {
        return false;
    }
    // Work in the extremum's orientation: a maximum of sign·f.
    float sign_f = a.z > 0.0 ? 1.0 : -1.0;
    float top = max(sign_f * a.y, sign_f * e.y);
    float v = 0.0;
    bool found = false;
    [[unroll]] for (int i = 0; i < MAX_ISO; ++i) {
        float vi = sign_f * isos[i].value;
        if (uint(i) < params.integrator.iso_count && vi > top && (!found || vi < v)) {
            v = vi;
            found = true;
        }
    }
    if (!found) {
        return false;
    }
    vec3 lo = vec3(a.x, sign_f * a.y, sign_f * a.z);
    vec3 hi = vec3(e.x, sign_f * e.y, sign_f * e.z);
    for (uint it = 0u; it < EXTREMUM_ITERATIONS; ++it) {
        float w = hi.x - lo.x;
        vec2 up = hermite_extremum(lo.y, hi.y, lo.z * w, hi.z * w);
        if (v - up.y > up.y - max(lo.y, hi.y)) {
            return false;
        }
        vec4 k = knot(o, d, lo.x + up.x * w, evaluations);
        if (k.w == 0.0) {
            return false;
        }
        float s = sign_f * k.y;
        if (s >= v) {
            m = k;
            return true;
        }
        float g = sign_f * k.z;
        if (g > 0.0) {
            lo = vec3(k.x, s, g);
        } else if (g < 0.0) {
            hi = vec3(k.x, s, g);
        } else {
            return false;
        }
    }
    return false;
}

// Crossings of [a, e], sorted by t: up to MAX_ISO (t, iso index) pairs; returns their count.
uint find_crossings(vec3 o, vec3 d, vec4 a, vec4 e, inout uint evaluations,
                    out vec4 hit_t, out vec3 hit_g[MAX_ISO], out uvec4 hit_i) {
    uint n = 0u;
    hit_t = vec4(0.0);
    hit_i = uvec4(0u);
    [[unroll]] for (int i = 0; i < MAX_ISO; ++i) {
        hit_g[i] = vec3(0.0);
        if (uint(i) < params.integrator.iso_count && crosses(a.y, e.y, isos[i].value)) {
            vec3 g;
            float t = locate_crossing(o, d, a, e, isos[i].value, evaluations, g);
            // Sorted insertion with constant indices only: find the slot, shift, store.
            uint slot = n;
            [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
                if (uint(j) < n && hit_t[j] > t && uint(j) < slot) {
                    slot = uint(j);
                }
            }
            [[unroll]] for (int j = MAX_ISO - 1; j > 0; --j) {
                if (uint(j) > slot && uint(j) <= n) {
                    hit_t[j] = hit_t[j - 1];
                    hit_g[j] = hit_g[j - 1];
                    hit_i[j] = hit_i[j - 1];
                }
            }
            [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
                if (uint(j) == slot) {
                    hit_t[j] = t;
                    hit_g[j] = g;
                    hit_i[j] = uint(i);
                }
            }
            n += 1u;
        }
    }
    return n;
}

#endif

#if MAX_ISO > 0
// Composites the shaded isosurfaces crossed in (a, e].
void emit_surfaces(vec3 o, vec3 d, vec4 a, vec4 e, inout vec3 color, inout float transmittance,
                   inout uint evaluations) {
    vec4 hit_t;
    vec3 hit_g[MAX_ISO];
    uvec4 hit_i;
    uint n = find_crossings(o, d, a, e, evaluations, hit_t, hit_g, hit_i);
    [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
        if (uint(j) < n) {
            IsoSurface iso = isos[hit_i[j]];
            color += transmittance * shade_surface(iso, hit_g[j], d);
            transmittance *= 1.0 - iso.color_opacity.a;
        }
    }
}
#endif

// Composites the shaded isosurfaces crossed between two knots (midpoint samples), including
// near-tangent double crossings (twin of interval::emit_crossings).
void emit_crossings(vec3 o, vec3 d, vec4 a, vec4 e, inout vec3 color, inout float transmittance,
                    inout uint evaluations) {
#if MAX_ISO > 0
    if (params.integrator.iso_count == 0u || a.w == 0.0 || e.w == 0.0) {
        return;
    }
    vec4 m;
    bool split = split_at_extremum(o, d, a, e, evaluations, m);
    for (uint piece = 0u; piece < (split ? 2u : 1u); ++piece) {
        emit_surfaces(o, d, piece == 0u ? a : m, split && piece == 0u ? m : e, color,
                      transmittance, evaluations);
    }
#endif
}

// The cubic Hermite's Bézier hull (x = lo, y = hi) and z = D, its largest departure from the
// chord, for end values f0, f1 and end derivatives m0, m1 per unit of its interval (twin of
// bezier_hull).
vec3 bezier_hull(float f0, float f1, float m0, float m1) {
    float delta = f1 - f0;
    float b1 = f0 + m0 / 3.0;
    float b2 = f1 - m1 / 3.0;
    return vec3(min(min(f0, f1), min(b1, b2)), max(max(f0, f1), max(b1, b2)),
                max(abs(m0 - delta), abs(m1 - delta)) / 3.0);
}

// The cubic Hermite's value at the middle of its interval (twin of hermite_midpoint).
float hermite_midpoint(float f0, float f1, float m0, float m1) {
    return 0.5 * (f0 + f1) + 0.125 * (m0 - m1);
}

#if RAY_METHOD != 0
// (C, α) of [a, e] of exactly len: table `level` for full-length intervals, else the clipped
// composite; undefined ends contribute nothing (twin of interval::knot_segment).
vec4 knot_segment(vec4 a, vec4 e, float len, bool full, uint level) {
    if (a.w == 0.0 || e.w == 0.0) {
        return vec4(0.0);
    }
    // The clipped composite costs a masked iteration, not its lookups, when every lane is full.
    vec4 clipped = preint_segment_if(!full, a.y, e.y, len);
    return full ? preint_lookup(level, a.y, e.y) : clipped;
}

// (C, α) of [a, e] from table `level`, which must be its length; undefined ends contribute
// nothing (knot_segment without the clipped composite, which costs a masked loop iteration).
vec4 table_segment(uint level, vec4 a, vec4 e) {
    vec4 c = preint_lookup(level, a.y, e.y);
    return a.w != 0.0 && e.w != 0.0 ? c : vec4(0.0);
}

// (C, α) of a full-length interval of the fixed-step integrator: table 0, or with
// INTERVAL_HERMITE two lookups of table 1 (half the step) through the cubic Hermite's predicted
// midpoint where both ends are defined and no isosurface value lies in the Hermite's hull (twin
// of hermite_segment and knot_segment). Both cases make the same two lookups with selected
// arguments: llvmpipe would run both sides of a branch.
vec4 full_segment(vec4 a, vec4 e) {
#if INTERVAL_HERMITE == 1
    float l = e.x - a.x;
    float m0 = l * a.z;
    float m1 = l * e.z;
    vec3 h = bezier_hull(a.y, e.y, m0, m1);
    bool defined = a.w != 0.0 && e.w != 0.0;
    bool halves = defined;
#if MAX_ISO > 0
    [[unroll]] for (int i = 0; i < MAX_ISO; ++i) {
        float v = iso_values[i];
        halves = halves && !(uint(i) < params.integrator.iso_count && h.x <= v && v <= h.y);
    }
#endif
    float sm = hermite_midpoint(a.y, e.y, m0, m1);
    vec4 c0 = preint_lookup(halves ? 1u : 0u, a.y, halves ? sm : e.y);
    vec4 c1 = preint_lookup(1u, sm, e.y);
    vec4 both = vec4(c0.rgb + (1.0 - c0.a) * c1.rgb, c0.a + (1.0 - c0.a) * c1.a);
    return defined ? (halves ? both : c0) : vec4(0.0);
#else
    return knot_segment(a, e, e.x - a.x, true, 0u);
#endif
}

#if MAX_ISO > 0
// Composites [a, e] of exactly len, split at the isosurfaces it crosses; `plain`, when
// use_plain, is its table segment, else the clipped composite is looked up (twin of
// interval::emit_monotone).
void emit_monotone(vec3 o, vec3 d, vec4 a, vec4 e, float len, vec4 plain, bool use_plain,
                   inout vec3 color, inout float transmittance, inout uint evaluations) {
    if (a.w == 0.0 || e.w == 0.0) {
        return;
    }
    vec4 hit_t;
    vec3 hit_g[MAX_ISO];
    uvec4 hit_i;
    uint n = find_crossings(o, d, a, e, evaluations, hit_t, hit_g, hit_i);
    float scale = len / (e.x - a.x);
    float t = a.x;
    float s = a.y;
    [[unroll]] for (int j = 0; j < MAX_ISO; ++j) {
        if (uint(j) < n) {
            IsoSurface iso = isos[hit_i[j]];
            float piece = (hit_t[j] - t) * scale;
            if (piece > 0.0) {
                vec4 c = preint_segment(s, iso.value, piece);
                color += transmittance * c.rgb;
                transmittance *= 1.0 - c.a;
            }
            color += transmittance * shade_surface(iso, hit_g[j], d);
            transmittance *= 1.0 - iso.color_opacity.a;
            t = hit_t[j];
            s = iso.value;
        }
    }
    float piece = (e.x - t) * scale;
    if (n == 0u && use_plain) {
        color += transmittance * plain.rgb;
        transmittance *= 1.0 - plain.a;
    } else if (piece > 0.0) {
        vec4 c = preint_segment(s, e.y, piece);
        color += transmittance * c.rgb;
        transmittance *= 1.0 - c.a;
    }
}
#endif

// Composites [a, e] of exactly len, split at isosurface crossings and, for a near-tangent
// double crossing, at the extremum between them (twin of interval::emit_interval). `plain` is
// the interval's knot_segment, already looked up by the caller, used as it is when no
// isosurface is crossed.
void emit_interval(vec3 o, vec3 d, vec4 a, vec4 e, float len, vec4 plain,
                   inout vec3 color, inout float transmittance, inout uint evaluations) {
#if MAX_ISO > 0
    if (params.integrator.iso_count > 0u) {
        vec4 m;
        bool split = split_at_extremum(o, d, a, e, evaluations, m);
        float scale = len / (e.x - a.x);
        // One call site for the pieces: GLSL inlines every call, and lavapipe's compile time
        // grows with the inlined copies of the root finder.
        for (uint piece = 0u; piece < (split ? 2u : 1u); ++piece) {
            vec4 pa = piece == 0u ? a : m;
            vec4 pe = split && piece == 0u ? m : e;
            emit_monotone(o, d, pa, pe, (pe.x - pa.x) * scale, plain, !split, color,
                          transmittance, evaluations);
        }
        return;
    }
#endif
    color += transmittance * plain.rgb;
    transmittance *= 1.0 - plain.a;
}
#endif

#endif
