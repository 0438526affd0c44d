// The splatting kernels' SplatParams, read once into registers: kernels include this after
// types.glsl and call load_params() first thing in main. Indexed by gl_WorkGroupID.z (0 in
// every dispatch) for the reason params.glsl gives: lavapipe's uniform inlining. std140 and
// std430 agree on SplatParams, whose one array (TfBlock) is of vec4.
#ifndef VMLS_SPLAT_PARAMS_GLSL
#define VMLS_SPLAT_PARAMS_GLSL

layout(std140, binding = BINDING_PARAMS) uniform ParamsBuf { SplatParams params_block[PARAMS_COPIES]; };

SplatParams params;

void load_params() {
    params = params_block[gl_WorkGroupID.z];
}

#endif
