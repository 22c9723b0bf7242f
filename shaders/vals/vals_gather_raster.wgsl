// Step 1 — gather, drawn as the paper draws it (`--gather raster`): one fragment per sparse
// point on a RASTER_WIDTH-wide target (point i is texel (i mod W, i div W)), each looping over
// every VAL straight from the buffer, with no workgroup memory. Same sums, same slots as the
// compute form in `vals_gather.wgsl` (the shared half is `vals_gather_common.wgsl`); the
// fragment writes them to the storage buffers and its colour output is discarded.
#include "vals_gather_common.wgsl"

// `RASTER_GATHER_WIDTH` in `src/vals/sparse.rs`, which sizes the target.
const RASTER_WIDTH: u32 = 256u;

// One triangle that covers the whole target.
@vertex
fn vs_main(@builtin(vertex_index) vertex: u32) -> @builtin(position) vec4<f32> {
    let corner = vec2<f32>(f32((vertex << 1u) & 2u), f32(vertex & 2u));
    return vec4<f32>(corner * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_main(@builtin(position) position: vec4<f32>) -> @location(0) vec4<f32> {
    let index = u32(position.y) * RASTER_WIDTH + u32(position.x);
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let flux_weights = (params.flags & FLAG_FLUX_WEIGHTS) != 0u;
    let use_visibility = (params.flags & FLAG_VISIBILITY) != 0u;
    if (!load_slot(0u, index, use_visibility)) {
        return vec4<f32>(0.0);
    }
    let count = min(val_count[0], arrayLength(&vals));
    let point = points[0];
    let r = mirrors[0];
    var sums = Sums();
    // Unrolled by 16 for llvmpipe's limit of 65535 iterations per loop (see vals_gather.wgsl).
    var j = 0u;
    let full = count - count % 16u;
    while (j < full) {
        accumulate(&sums, point, r, vals[j + 0u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 1u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 2u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 3u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 4u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 5u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 6u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 7u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 8u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 9u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 10u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 11u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 12u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 13u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 14u], 0u, glossy_on, flux_weights, use_visibility);
        accumulate(&sums, point, r, vals[j + 15u], 0u, glossy_on, flux_weights, use_visibility);
        j += 16u;
    }
    while (j < count) {
        accumulate(&sums, point, r, vals[j], 0u, glossy_on, flux_weights, use_visibility);
        j += 1u;
    }
    write_point(index, point, sums, count, glossy_on);
    return vec4<f32>(0.0);
}
