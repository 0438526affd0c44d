// The ray caster's and the MLS kernels' RenderParams, read once into registers: kernels include
// this after types.glsl and call load_params() first thing in main. llvmpipe hoists nothing out
// of loops and compiles a storage-buffer read in divergent code as a loop over the SIMD lanes,
// even at a uniform address; a uniform-block read costs less but is still repeated at every use.
// Copying the block once measured fastest (BENCHMARKS.md, "Two lavapipe costs"). std140 and
// std430 agree on RenderParams, whose one array (TfBlock) is of vec4.
// The block is an array of PARAMS_COPIES indexed by gl_WorkGroupID.z, which is 0 in every
// dispatch (all are one workgroup deep): a load at a constant offset that feeds a branch or a
// loop bound is an "inlinable uniform" to lavapipe (Mesa 22.3, lvp_execute.c), which then
// compiles a new copy of the kernel with the values folded in at every pipeline bind for as
// long as folding halves the kernel, and never frees them: the general path's ray caster grew
// the process by 19 MB a 512² frame (BENCHMARKS.md, "lavapipe's uniform inlining"). A dynamic
// index is not inlinable; with one element NIR would fold it to 0, hence two copies.
#ifndef VMLS_PARAMS_GLSL
#define VMLS_PARAMS_GLSL

layout(std140, binding = BINDING_PARAMS) uniform ParamsBuf { RenderParams params_block[PARAMS_COPIES]; };

RenderParams params;

void load_params() {
    params = params_block[gl_WorkGroupID.z];
}

#endif
