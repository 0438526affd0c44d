// Structs shared with Rust: each is the std430 twin of the struct of the same name in
// src/gpu_types.rs (tests/layout.rs proves the layouts agree). Binding numbers come from Rust as
// BINDING_* macros.
#ifndef VMLS_TYPES_GLSL
#define VMLS_TYPES_GLSL

// The camera of a frame, one definition for the ray caster and the splatter (twin:
// CameraBlock). Positions are frame-relative; eye.w and the vectors' w are unused.
struct CameraBlock {
    vec4 eye;
    vec4 forward;
    vec4 right;
    vec4 up;
    uint width;
    uint height;
    uint projection;  // 0 perspective, 1 orthographic
    float tan_half_fov;
    float ortho_half_height;
    float _pad0;
    float _pad1;
    float _pad2;
};

// The field's lattice, supports and octree (twin: FieldBlock).
struct FieldBlock {
    vec4 grid_origin;
    vec4 grid_inv_spacing;
    vec4 inv_support;
    vec4 octree_root;  // centre xyz, half side w
    ivec4 grid_dims;
    float support_cells;
    float gauss_sigma;
    float gauss_weight;
    float _pad0;
};

// The ray caster's integrator, lengths in world units (twin: IntegratorBlock).
struct IntegratorBlock {
    vec4 box_min;
    vec4 box_max;
    vec4 background;
    float step_world;
    float min_transmittance;
    float epsilon;
    float early_termination;
    float spacing_world;
    float l_min_world;
    uint tf_count;
    uint iso_count;
    vec4 clip_min;
    vec4 clip_max;
};

// The preintegration tables (twin: TableBlock).
struct TableBlock {
    float s_min;
    float s_max;
    float longest_world;
    uint resolution;
    uint lengths;
    float peak;
    // Table 0's occupied bins (bits 0-31, 32-63; preint_clear).
    uint occupied0;
    uint occupied1;
};

// The transfer function's (s, τ), two points a vec4, for the exact opacity's unrolled scan
// (twin: TfBlock).
struct TfBlock {
    vec4 s_tau[16];
};

// The transfer function's pieces of change (s_a, s_b, rate or -1 for a step, jump), for the
// Hermite criterion's unrolled sensitivity scan (twin: SensitivityBlock).
struct SensitivityBlock {
    vec4 pieces[16];
};

struct RenderParams {
    CameraBlock camera;
    FieldBlock field;
    IntegratorBlock integrator;
    TableBlock tables;
    vec4 lighting;  // Blinn-Phong ambient, diffuse, specular, shininess
    TfBlock tf;
    SensitivityBlock sensitivity;
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
    float tau;
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
    uint col_offset;
    uint cols;
    uint _pad0;
    uint _pad1;
};

struct NextPush {
    uint row_offset;
    uint rows;
    uint args_slot;
    uint cols;
};

struct PackPush {
    uint count;
    uint composite;
    uint _pad0;
    uint _pad1;
    vec4 background;
};

struct PlanPush {
    uint buckets;
    uint capacity;
    uint max_entries;
    uint bin_groups;
    uint tiles_x;
    uint tiles_y;
    uint segments;
    uint band_rows;
    uint chunk;
    uint sheet_cost;
    uint steps;
    uint resumes;
};

struct CountPush {
    uint count;
    uint iterations;
    uint _pad0;
    uint _pad1;
};

struct SplatParams {
    CameraBlock camera;
    vec4 box_min;
    vec4 box_max;
    vec4 background;
    vec4 lighting;
    float near;
    float focal;
    float centre_x;
    float centre_y;
    float slab0_world;
    float slab_world;
    float early_termination;
    float zero_extinction;
    float cutoff;
    float lowpass;
    float sigma;
    float lateral_x;
    float lateral_y;
    uint tf_count;
    uint iso_count;
    uint slabs;
    uint tiles_x;
    uint kernel_count;
    uint sheet_first;
    uint sheet_last;
    vec4 cell_min;
    vec4 cell_max;
    ivec4 pixel_window;
    TableBlock tables;
    TfBlock tf;
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
    uint pass;
    uint last_pass;
    uint chunk;
    uint sheet_cost;
    uint band;
    uint _pad0;
    uint _pad1;
};

struct WalkPush {
    uint tiles;
    uint tiles_x;
    uint slabs;
    uint band_rows;
};

struct ScanPush {
    uint buckets;
    uint blocks;
    uint _pad0;
    uint _pad1;
};

#endif
