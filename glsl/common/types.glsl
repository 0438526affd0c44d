// Structs shared with Rust: each is the std430 twin of the struct of the same name in
// src/gpu_types.rs (tests/layout.rs proves the layouts agree). Binding numbers come from Rust as
// BINDING_* macros.
#ifndef VMLS_TYPES_GLSL
#define VMLS_TYPES_GLSL

struct RenderParams {
    vec4 eye;
    vec4 forward;
    vec4 right;
    vec4 up;
    vec4 box_min;
    vec4 box_max;
    vec4 background;
    vec4 grid_origin;
    vec4 grid_inv_spacing;
    vec4 inv_support;
    vec4 octree_root;
    ivec4 grid_dims;
    uint width;
    uint height;
    uint projection;
    uint tf_count;
    float tan_half_fov;
    float ortho_half_height;
    float step;
    float min_transmittance;
    float support_cells;
    float gauss_sigma;
    float gauss_weight;
    float _pad0;
    vec4 preint_range;
    uvec4 preint_dims;
    vec4 integrator;
    vec4 lighting;
    uvec4 iso_count;
};

struct IsoSurface {
    vec4 color_opacity;
    float value;
    float _pad0;
    float _pad1;
    float _pad2;
};

struct TfPoint {
    vec4 color_tau;
    float s;
    float _pad0;
    float _pad1;
    float _pad2;
};

struct Sample {
    vec4 pos_value;
    vec4 metric;
    vec4 metric_off;
};

struct MlsOut {
    float value;
    float gradient_x;
    float gradient_y;
    float gradient_z;
    uint neighbours;
    uint terms;
    uint _pad0;
    uint _pad1;
};

struct RayPush {
    uint row_offset;
    uint rows;
    uint first;
    uint last;
};

struct CountPush {
    uint count;
    uint iterations;
    uint _pad0;
    uint _pad1;
};

struct SplatParams {
    vec4 eye;
    vec4 forward;
    vec4 right;
    vec4 up;
    vec4 box_min;
    vec4 box_max;
    vec4 background;
    vec4 kernel_filter;
    vec4 lighting;
    uint width;
    uint height;
    uint projection;
    uint tf_count;
    float tan_half_fov;
    float ortho_half_height;
    float lateral_y;
    float zero_extinction;
    uint slabs;
    uint tiles_x;
    uint kernel_count;
    uint iso_count;
};

struct Splat {
    vec4 footprint0;
    vec4 footprint1;
    vec4 footprint2;
    vec4 footprint3;
    vec4 color;
    ivec4 bbox;
    uvec4 slabs;
};

struct RasterPush {
    uint tile_row;
    uint _pad0;
    uint _pad1;
    uint _pad2;
};

struct ScanPush {
    uint buckets;
    uint blocks;
    uint _pad0;
    uint _pad1;
};

#endif
