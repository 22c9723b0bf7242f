// Step 1 — gather, drawn as the paper draws it (`--gather raster`): one fragment per sparse
// point on a RASTER_WIDTH-wide target (point i is texel (i mod W, i div W)), each looping over
// every VAL straight from the buffer, with no workgroup memory. Same sums, same slots as the
// compute form in `vals_gather.wgsl` (the shared half is `vals_gather_common.wgsl`); the
// fragment writes them to the storage buffers and its colour output is discarded.
#include "vals_gather_common.wgsl"

// `RASTER_GATHER_WIDTH` in `src/vals/sparse.rs`, which sizes the target.
const RASTER_WIDTH: u32 = 256u;

// The point's cluster visibility words. An array indexed by the cluster here: on an H200 it
// measured 433 ms against 494 ms for the switch the compute form uses (512k VALs × 4k points),
// which pays off there only because its word index is shared by the workgroup.
var<private> point_words: array<u32, VISIBILITY_WORDS>;

// V of the VAL's cluster at the point (1 without visibility).
fn visibility_of(val: Val, use_visibility: bool) -> f32 {
    if (!use_visibility) {
        return 1.0;
    }
    let cluster = val_cluster(val);
    return cluster_visibility(cluster, point_words[min(cluster / 4u, VISIBILITY_WORDS - 1u)]);
}

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
    if (!load_slot(0u, index)) {
        return vec4<f32>(0.0);
    }
    for (var w = 0u; w < VISIBILITY_WORDS; w++) {
        point_words[w] = visibility_word(index, w, use_visibility);
    }
    let count = min(val_count[0], arrayLength(&vals));
    let point = points[0];
    let r = mirrors[0];
    var sums = Sums();
    // Unrolled by 16 for llvmpipe's limit of 65535 iterations per loop (see vals_gather.wgsl).
    var j = 0u;
    let full = count - count % 16u;
    while (j < full) {
        accumulate(&sums, point, r, vals[j + 0u], visibility_of(vals[j + 0u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 1u], visibility_of(vals[j + 1u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 2u], visibility_of(vals[j + 2u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 3u], visibility_of(vals[j + 3u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 4u], visibility_of(vals[j + 4u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 5u], visibility_of(vals[j + 5u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 6u], visibility_of(vals[j + 6u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 7u], visibility_of(vals[j + 7u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 8u], visibility_of(vals[j + 8u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 9u], visibility_of(vals[j + 9u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 10u], visibility_of(vals[j + 10u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 11u], visibility_of(vals[j + 11u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 12u], visibility_of(vals[j + 12u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 13u], visibility_of(vals[j + 13u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 14u], visibility_of(vals[j + 14u], use_visibility), glossy_on, flux_weights);
        accumulate(&sums, point, r, vals[j + 15u], visibility_of(vals[j + 15u], use_visibility), glossy_on, flux_weights);
        j += 16u;
    }
    while (j < count) {
        accumulate(&sums, point, r, vals[j], visibility_of(vals[j], use_visibility), glossy_on, flux_weights);
        j += 1u;
    }
    write_point(index, point, sums, count, glossy_on);
    return vec4<f32>(0.0);
}
