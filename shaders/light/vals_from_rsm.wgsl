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
    // Cluster tiles per layer side.
    tiles: u32,
    // Views per physical layer side: pack² views share one array layer as tiles.
    pack: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> size: RsmSize;
@group(0) @binding(1) var rsm_position_area: texture_2d_array<f32>;
@group(0) @binding(2) var rsm_normal: texture_2d_array<f32>;
@group(0) @binding(3) var rsm_flux: texture_2d_array<f32>;
@group(0) @binding(4) var<storage, read_write> vals: array<Val>;
@group(0) @binding(5) var<storage, read_write> val_count: array<u32>;
// Per row (layer-major): its lit-texel count, then its first VAL's index.
@group(0) @binding(6) var<storage, read_write> row_offsets: array<u32>;
// Per tile over all layers, CLUSTER_SAMPLE_SIDE² slots: 1 + the VAL at each stratum's centre
// texel (0: unlit; the buffer is cleared every frame).
@group(0) @binding(7) var<storage, read_write> cluster_samples: array<u32>;

// `src/light/rsm.rs` holds the same two constants and the CPU twins of the three functions
// below.
const MAX_CLUSTERS: u32 = 32u;
const CLUSTER_SAMPLE_SIDE: u32 = 4u;

fn layer_tile(layer: u32, x: u32, y: u32) -> u32 {
    let tx = x * size.tiles / size.resolution;
    let ty = y * size.tiles / size.resolution;
    return layer * size.tiles * size.tiles + ty * size.tiles + tx;
}

// The stratum of x in its tile if x is that stratum's centre texel, else CLUSTER_SAMPLE_SIDE.
fn sample_stratum(x: u32) -> u32 {
    let t = x * size.tiles / size.resolution;
    let x0 = t * size.resolution / size.tiles;
    let x1 = (t + 1u) * size.resolution / size.tiles;
    let width = max(x1 - x0, 1u);
    let stratum = (x - x0) * CLUSTER_SAMPLE_SIDE / width;
    let centre = x0 + (2u * stratum + 1u) * width / (2u * CLUSTER_SAMPLE_SIDE);
    return select(CLUSTER_SAMPLE_SIDE, stratum, centre == x);
}

// Texel (x, y) of view `layer` in the packed arrays: xy and the physical layer (the CPU twin
// is `Rsm::physical_texel`).
fn rsm_texel(layer: u32, x: u32, y: u32) -> vec3<i32> {
    let per_layer = size.pack * size.pack;
    let slot = layer % per_layer;
    return vec3<i32>(
        i32((slot % size.pack) * size.resolution + x),
        i32((slot / size.pack) * size.resolution + y),
        i32(layer / per_layer),
    );
}

const SCAN_GROUP: u32 = 256u;

var<workgroup> block_sums: array<u32, SCAN_GROUP>;

fn lit(x: u32, row: u32) -> bool {
    let t = rsm_texel(row / size.resolution, x, row % size.resolution);
    return textureLoad(rsm_flux, t.xy, t.z, 0).a > 0.5;
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
    let stratum_y = sample_stratum(u32(y));
    for (var x = 0u; x < size.resolution; x++) {
        let t = rsm_texel(u32(layer), x, u32(y));
        let flux = textureLoad(rsm_flux, t.xy, t.z, 0);
        if (flux.a < 0.5 || slot >= size.capacity) {
            continue;
        }
        var val: Val;
        val.position_area = textureLoad(rsm_position_area, t.xy, t.z, 0);
        val.normal = vec4<f32>(normalize(textureLoad(rsm_normal, t.xy, t.z, 0).xyz), 0.0);
        // w: the VAL's cluster (a small integer, exact in f32).
        let tile = layer_tile(u32(layer), x, u32(y));
        val.flux = vec4<f32>(flux.rgb, f32(tile % MAX_CLUSTERS));
        vals[slot] = val;
        let stratum_x = sample_stratum(x);
        if (stratum_x < CLUSTER_SAMPLE_SIDE && stratum_y < CLUSTER_SAMPLE_SIDE) {
            let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
            cluster_samples[tile * per_tile + stratum_y * CLUSTER_SAMPLE_SIDE + stratum_x] = slot + 1u;
        }
        slot += 1u;
    }
}
