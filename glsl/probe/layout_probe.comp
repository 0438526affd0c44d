#version 450
// Layout probe (stage `layout_probe`): writes every field of every struct shared with Rust with
// a distinct number, in declaration order starting at 1 for each struct. tests/layout.rs reads
// the bytes back through the Rust twins and checks each field holds its number.

layout(local_size_x = 1) in;

#include "common/types.glsl"

layout(std430, binding = BINDING_PROBE) writeonly buffer ProbeBuf {
    RenderParams render_params;
    TfPoint tf_point;
    Sample sample_;
    MlsOut mls_out;
    RayPush ray_push;
    CountPush count_push;
    IsoSurface iso_surface;
    SplatParams splat_params;
    Splat splat;
    ScanPush scan_push;
    RasterPush raster_push;
    NextPush next_push;
    PackPush pack_push;
    PlanPush plan_push;
    WalkPush walk_push;
};

vec4 v(float k) { return vec4(k, k + 0.25, k + 0.5, k + 0.75); }

void main() {
    render_params.camera.eye = v(1.0);
    render_params.camera.forward = v(2.0);
    render_params.camera.right = v(3.0);
    render_params.camera.up = v(4.0);
    render_params.camera.width = 5u;
    render_params.camera.height = 6u;
    render_params.camera.projection = 7u;
    render_params.camera.tan_half_fov = 8.0;
    render_params.camera.ortho_half_height = 9.0;
    render_params.camera._pad0 = 10.0;
    render_params.camera._pad1 = 11.0;
    render_params.camera._pad2 = 12.0;
    render_params.field.grid_origin = v(13.0);
    render_params.field.grid_inv_spacing = v(14.0);
    render_params.field.inv_support = v(15.0);
    render_params.field.octree_root = v(16.0);
    render_params.field.grid_dims = ivec4(17, 18, 19, 20);
    render_params.field.support_cells = 21.0;
    render_params.field.gauss_sigma = 22.0;
    render_params.field.gauss_weight = 23.0;
    render_params.field._pad0 = 24.0;
    render_params.integrator.box_min = v(25.0);
    render_params.integrator.box_max = v(26.0);
    render_params.integrator.background = v(27.0);
    render_params.integrator.step_world = 28.0;
    render_params.integrator.min_transmittance = 29.0;
    render_params.integrator.epsilon = 30.0;
    render_params.integrator.early_termination = 31.0;
    render_params.integrator.spacing_world = 32.0;
    render_params.integrator.l_min_world = 33.0;
    render_params.integrator.tf_count = 34u;
    render_params.integrator.iso_count = 35u;
    render_params.integrator.clip_min = v(101.0);
    render_params.integrator.clip_max = v(102.0);
    render_params.tables.s_min = 36.0;
    render_params.tables.s_max = 37.0;
    render_params.tables.longest_world = 38.0;
    render_params.tables.resolution = 39u;
    render_params.tables.lengths = 40u;
    render_params.tables.peak = 41.0;
    render_params.tables.occupied0 = 42u;
    render_params.tables.occupied1 = 43u;
    render_params.lighting = v(44.0);
    for (int i = 0; i < 16; ++i) {
        render_params.tf.s_tau[i] = v(45.0 + float(i));
    }
    for (int i = 0; i < 16; ++i) {
        render_params.sensitivity.pieces[i] = v(61.0 + float(i));
    }

    iso_surface.color_opacity = v(1.0);
    iso_surface.value = 2.0;
    iso_surface._pad0 = 3.0;
    iso_surface._pad1 = 4.0;
    iso_surface._pad2 = 5.0;

    tf_point.color_tau = v(1.0);
    tf_point.s = 2.0;
    tf_point.tau = 3.0;
    tf_point._pad1 = 4.0;
    tf_point._pad2 = 5.0;

    sample_.pos_value = v(1.0);
    sample_.metric = v(2.0);
    sample_.metric_off = v(3.0);

    mls_out.value = 1.0;
    mls_out.gradient_x = 2.0;
    mls_out.gradient_y = 3.0;
    mls_out.gradient_z = 4.0;
    mls_out.neighbours = 5u;
    mls_out.terms = 6u;
    mls_out._pad0 = 7u;
    mls_out._pad1 = 8u;

    ray_push = RayPush(1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u);
    count_push = CountPush(1u, 2u, 3u, 4u);

    splat_params.camera.eye = v(1.0);
    splat_params.camera.forward = v(2.0);
    splat_params.camera.right = v(3.0);
    splat_params.camera.up = v(4.0);
    splat_params.camera.width = 5u;
    splat_params.camera.height = 6u;
    splat_params.camera.projection = 7u;
    splat_params.camera.tan_half_fov = 8.0;
    splat_params.camera.ortho_half_height = 9.0;
    splat_params.camera._pad0 = 10.0;
    splat_params.camera._pad1 = 11.0;
    splat_params.camera._pad2 = 12.0;
    splat_params.box_min = v(13.0);
    splat_params.box_max = v(14.0);
    splat_params.background = v(15.0);
    splat_params.lighting = v(16.0);
    splat_params.near = 17.0;
    splat_params.focal = 18.0;
    splat_params.centre_x = 19.0;
    splat_params.centre_y = 20.0;
    splat_params.slab0_world = 21.0;
    splat_params.slab_world = 22.0;
    splat_params.early_termination = 23.0;
    splat_params.zero_extinction = 24.0;
    splat_params.cutoff = 25.0;
    splat_params.lowpass = 26.0;
    splat_params.sigma = 27.0;
    splat_params.lateral_x = 28.0;
    splat_params.lateral_y = 29.0;
    splat_params.tf_count = 30u;
    splat_params.iso_count = 31u;
    splat_params.slabs = 32u;
    splat_params.tiles_x = 33u;
    splat_params.kernel_count = 34u;
    splat_params.sheet_first = 35u;
    splat_params.sheet_last = 36u;
    splat_params.cell_min = v(37.0);
    splat_params.cell_max = v(38.0);
    splat_params.pixel_window = ivec4(39, 40, 41, 42);
    splat_params.tables.s_min = 43.0;
    splat_params.tables.s_max = 44.0;
    splat_params.tables.longest_world = 45.0;
    splat_params.tables.resolution = 46u;
    splat_params.tables.lengths = 47u;
    splat_params.tables.peak = 48.0;
    splat_params.tables.occupied0 = 49u;
    splat_params.tables.occupied1 = 50u;
    for (int i = 0; i < 16; ++i) {
        splat_params.tf.s_tau[i] = v(51.0 + float(i));
    }

    splat.footprint0 = v(1.0);
    splat.footprint1 = v(2.0);
    splat.footprint2 = v(3.0);
    splat.footprint3 = v(4.0);
    splat.color = v(5.0);
    splat.bbox = ivec4(6, 7, 8, 9);
    splat.slabs = uvec4(10u, 11u, 12u, 13u);

    scan_push = ScanPush(1u, 2u, 3u, 4u);
    raster_push = RasterPush(5u, 6u, 7u, 8u, 9u, 10u, 11u, 12u);

    next_push.row_offset = 1u;
    next_push.rows = 2u;
    next_push.args_slot = 3u;
    next_push.cols = 4u;

    pack_push.count = 1u;
    pack_push.composite = 2u;
    pack_push._pad0 = 3u;
    pack_push._pad1 = 4u;
    pack_push.background = v(5.0);

    plan_push = PlanPush(1u, 2u, 3u, 4u, 5u, 6u, 7u, 8u, 9u, 10u, 11u, 12u);
    walk_push = WalkPush(1u, 2u, 3u, 4u);
}
