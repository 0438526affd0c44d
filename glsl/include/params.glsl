// The ray caster's and the MLS kernels' RenderParams, read once into registers: kernels include
// this after types.glsl and call load_params() first thing in main. llvmpipe hoists nothing out
// of loops and compiles a storage-buffer read in divergent code as a loop over the SIMD lanes,
// even at a uniform address; a uniform-block read costs less but is still repeated at every use.
// Copying the block once measured fastest (BENCHMARKS.md, "Two lavapipe costs"). std140 and
// std430 agree on RenderParams, which has no arrays.
#ifndef VMLS_PARAMS_GLSL
#define VMLS_PARAMS_GLSL

layout(std140, binding = BINDING_PARAMS) uniform ParamsBuf { RenderParams params_block; };

RenderParams params;

void load_params() {
    params = params_block;
}

#endif
