// Compacts every lit RSM texel of every layer into one VAL buffer for all lights, in texel
// order (layer, row, column), so the VAL list — and every sum over it — is the same from run to
// run and frame to frame. Texels that hit nothing or reflect nothing produce no VAL. Three
// passes: count the lit texels of each row, scan the counts into row offsets, write each row's
// VALs at its offset.
#include "vals_common.wgsl"

struct RsmSize {
    resolution: u32,
    layers: u32,
    capacity: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> size: RsmSize;
@group(0) @binding(1) var rsm_position_area: texture_2d_array<f32>;
@group(0) @binding(2) var rsm_normal: texture_2d_array<f32>;
@group(0) @binding(3) var rsm_flux: texture_2d_array<f32>;
@group(0) @binding(4) var<storage, read_write> vals: array<Val>;
@group(0) @binding(5) var<storage, read_write> val_count: array<u32>;
// Per row (layer-major): its lit-texel count, then its first VAL's index.
@group(0) @binding(6) var<storage, read_write> row_offsets: array<u32>;

const SCAN_GROUP: u32 = 256u;

var<workgroup> block_sums: array<u32, SCAN_GROUP>;

fn lit(x: u32, row: u32) -> bool {
    let layer = i32(row / size.resolution);
    let texel = vec2<i32>(i32(x), i32(row % size.resolution));
    return textureLoad(rsm_flux, texel, layer, 0).a > 0.5;
}

@compute @workgroup_size(64, 1, 1)
fn count_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let row = id.x + id.y * 65535u * 64u;
    if (row >= size.resolution * size.layers) {
        return;
    }
    var n = 0u;
    for (var x = 0u; x < size.resolution; x++) {
        n += select(0u, 1u, lit(x, row));
    }
    row_offsets[row] = n;
}

// One workgroup: each thread sums a contiguous block of rows, thread 0 scans the block sums,
// then every thread turns its rows' counts into offsets.
@compute @workgroup_size(256, 1, 1)
fn scan_rows(@builtin(local_invocation_index) lid: u32) {
    let rows = size.resolution * size.layers;
    let per = (rows + SCAN_GROUP - 1u) / SCAN_GROUP;
    let start = min(lid * per, rows);
    let end = min(start + per, rows);
    var sum = 0u;
    for (var r = start; r < end; r++) {
        sum += row_offsets[r];
    }
    block_sums[lid] = sum;
    workgroupBarrier();
    if (lid == 0u) {
        var total = 0u;
        for (var i = 0u; i < SCAN_GROUP; i++) {
            let s = block_sums[i];
            block_sums[i] = total;
            total += s;
        }
        val_count[0] = min(total, size.capacity);
    }
    workgroupBarrier();
    var offset = block_sums[lid];
    for (var r = start; r < end; r++) {
        let n = row_offsets[r];
        row_offsets[r] = offset;
        offset += n;
    }
}

@compute @workgroup_size(64, 1, 1)
fn write_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let row = id.x + id.y * 65535u * 64u;
    if (row >= size.resolution * size.layers) {
        return;
    }
    let layer = i32(row / size.resolution);
    let y = i32(row % size.resolution);
    var slot = row_offsets[row];
    for (var x = 0u; x < size.resolution; x++) {
        let texel = vec2<i32>(i32(x), y);
        let flux = textureLoad(rsm_flux, texel, layer, 0);
        if (flux.a < 0.5 || slot >= size.capacity) {
            continue;
        }
        var val: Val;
        val.position_area = textureLoad(rsm_position_area, texel, layer, 0);
        val.normal = vec4<f32>(normalize(textureLoad(rsm_normal, texel, layer, 0).xyz), 0.0);
        val.flux = vec4<f32>(flux.rgb, 0.0);
        vals[slot] = val;
        slot += 1u;
    }
}
