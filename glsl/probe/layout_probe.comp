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
};

vec4 v(float k) { return vec4(k, k + 0.25, k + 0.5, k + 0.75); }

void main() {
    render_params.eye = v(1.0);
    render_params.forward = v(2.0);
    render_params.right = v(3.0);
    render_params.up = v(4.0);
    render_params.box_min = v(5.0);
    render_params.box_max = v(6.0);
    render_params.background = v(7.0);
    render_params.grid_origin = v(8.0);
    render_params.grid_inv_spacing = v(9.0);
    render_params.inv_support = v(10.0);
    render_params.octree_root = v(11.0);
    render_params.grid_dims = ivec4(12, 13, 14, 15);
    render_params.width = 16u;
    render_params.height = 17u;
    render_params.projection = 18u;
    render_params.tf_count = 19u;
    render_params.tan_half_fov = 20.0;
    render_params.ortho_half_height = 21.0;
    render_params.step = 22.0;
    render_params.min_transmittance = 23.0;
    render_params.support_cells = 24.0;
    render_params.gauss_sigma = 25.0;
    render_params.gauss_weight = 26.0;
    render_params._pad0 = 27.0;
    render_params.preint_range = v(28.0);
    render_params.preint_dims = uvec4(29u, 30u, 31u, 32u);
    render_params.integrator = v(33.0);
    render_params.lighting = v(34.0);
    render_params.iso_count = uvec4(35u, 36u, 37u, 38u);

    iso_surface.color_opacity = v(1.0);
    iso_surface.value = 2.0;
    iso_surface._pad0 = 3.0;
    iso_surface._pad1 = 4.0;
    iso_surface._pad2 = 5.0;

    tf_point.color_tau = v(1.0);
    tf_point.s = 2.0;
    tf_point._pad0 = 3.0;
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

    ray_push = RayPush(1u, 2u, 3u, 4u);
    count_push = CountPush(1u, 2u, 3u, 4u);

    splat_params.eye = v(1.0);
    splat_params.forward = v(2.0);
    splat_params.right = v(3.0);
    splat_params.up = v(4.0);
    splat_params.box_min = v(5.0);
    splat_params.box_max = v(6.0);
    splat_params.background = v(7.0);
    splat_params.kernel_filter = v(8.0);
    splat_params.lighting = v(9.0);
    splat_params.width = 10u;
    splat_params.height = 11u;
    splat_params.projection = 12u;
    splat_params.tf_count = 13u;
    splat_params.tan_half_fov = 14.0;
    splat_params.ortho_half_height = 15.0;
    splat_params.lateral_y = 16.0;
    splat_params.zero_extinction = 17.0;
    splat_params.slabs = 18u;
    splat_params.tiles_x = 19u;
    splat_params.kernel_count = 20u;
    splat_params.iso_count = 21u;

    splat.footprint0 = v(1.0);
    splat.footprint1 = v(2.0);
    splat.footprint2 = v(3.0);
    splat.footprint3 = v(4.0);
    splat.color = v(5.0);
    splat.bbox = ivec4(6, 7, 8, 9);
    splat.slabs = uvec4(10u, 11u, 12u, 13u);

    scan_push = ScanPush(1u, 2u, 3u, 4u);
    raster_push = RasterPush(5u, 6u, 7u, 8u);
}
