// The passes of splat_raster a band takes (twin: RasterWalk::passes in src/splat/plan.rs):
// its tiles walk at most `entries` entries through `steps` sheets, one loop iteration per
// entry and `sheet_cost` per sheet; a pass stops before `chunk`, and every pass but the last
// makes more than chunk - 2 sheet_cost of progress. No overflow: entries stay below the
// list's maxTexelBufferElements, and chunk below 2^30.
#ifndef VMLS_WALKS_GLSL
#define VMLS_WALKS_GLSL

uint raster_passes(uint entries, uint steps, uint chunk, uint sheet_cost) {
    uint walk = entries + steps * sheet_cost;
    uint progress = chunk - 2u * sheet_cost;
    return walk <= chunk ? 1u : (walk + progress - 1u) / progress;
}

#endif
