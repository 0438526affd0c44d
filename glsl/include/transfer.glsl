// Piecewise-linear transfer function, twin of TransferFunction::lookup in src/render/transfer.rs:
// colour and extinction interpolated linearly in s between control points, clamped outside.
#ifndef VMLS_TRANSFER_GLSL
#define VMLS_TRANSFER_GLSL

layout(std430, binding = BINDING_TRANSFER) readonly buffer TransferBuf { TfPoint tf[]; };

// rgb = emitted colour, a = extinction τ per world unit.
vec4 transfer_lookup(float s, uint count) {
    if (s <= tf[0].s) {
        return tf[0].color_tau;
    }
    for (uint i = 1u; i < count; ++i) {
        if (s < tf[i].s) {
            float t = (s - tf[i - 1u].s) / (tf[i].s - tf[i - 1u].s);
            return mix(tf[i - 1u].color_tau, tf[i].color_tau, t);
        }
    }
    return tf[count - 1u].color_tau;
}

#endif
