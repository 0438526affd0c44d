// Shaded isosurfaces: f32 twin of src/view/shading.rs (stage shade_surface). Blinn–Phong with
// a headlight and two-sided normals: rgb = color·(ambient + diffuse·|n·l|) + specular·|n·l|^k,
// premultiplied by the opacity. Needs `params` declared by the kernel.
#ifndef VMLS_SHADING_GLSL
#define VMLS_SHADING_GLSL

layout(std430, binding = BINDING_ISO) readonly buffer IsoBuf { IsoSurface isos[]; };

vec3 shade_cos(IsoSurface iso, float c) {
    vec4 light = params.lighting;
    float lit = light.x + light.y * c;
    float spec = light.z * pow(c, light.w);
    return iso.color_opacity.a * (iso.color_opacity.rgb * lit + spec);
}

vec3 shade_surface(IsoSurface iso, vec3 gradient, vec3 dir) {
    float len = length(gradient);
    return shade_cos(iso, len > 1e-12 ? abs(dot(gradient / len, -dir)) : 1.0);
}

#endif
