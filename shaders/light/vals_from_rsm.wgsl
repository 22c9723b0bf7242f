// Compacts every lit RSM texel of every view into one VAL buffer for all lights, in texel
// order (view, row, column), so the VAL list — and every sum over it — is the same from run to
// run and frame to frame. Texels that hit nothing or reflect nothing produce no VAL. Three
// passes: count the lit texels of each row, scan the counts into row offsets, write each row's
// VALs at its offset.
#include "vals_common.wgsl"

struct RsmSize {
    // Rows of all views together, in view order.
    rows: u32,
    views: u32,
    capacity: u32,
    // Cluster tiles per view side.
    tiles: u32,
}

// Where one view lives in the arrays (`RsmTile` in `src/light/rsm.rs`).
struct RsmTile {
    origin: vec2<u32>,
    layer: u32,
    side: u32,
    first_row: u32,
}

@group(0) @binding(0) var<uniform> size: RsmSize;
@group(0) @binding(1) var rsm_position_area: texture_2d_array<f32>;
@group(0) @binding(2) var rsm_normal: texture_2d_array<f32>;
@group(0) @binding(3) var rsm_flux: texture_2d_array<f32>;
@group(0) @binding(4) var<storage, read_write> vals: array<Val>;
@group(0) @binding(5) var<storage, read_write> val_count: array<u32>;
// Per row (view-major): its lit-texel count, then its first VAL's index.
@group(0) @binding(6) var<storage, read_write> row_offsets: array<u32>;
// Per tile over all views, CLUSTER_SAMPLE_SIDE² slots: 1 + the VAL at each stratum's centre
// texel (0: unlit; the buffer is cleared every frame).
@group(0) @binding(7) var<storage, read_write> cluster_samples: array<u32>;
// Per view, its tile; views may have different sides (the lights share the VALs by power).
@group(0) @binding(8) var<storage, read> view_tiles: array<RsmTile>;

// `src/light/rsm.rs` holds the same constants and the CPU twins of the functions below.
const MAX_CLUSTERS: u32 = 32u;
const CLUSTER_SAMPLE_SIDE: u32 = 4u;
const SAMPLE_CANDIDATES: u32 = 5u;

fn layer_tile(view: u32, side: u32, x: u32, y: u32) -> u32 {
    let tx = x * size.tiles / side;
    let ty = y * size.tiles / side;
    return view * size.tiles * size.tiles + ty * size.tiles + tx;
}

// The stratum of x in its tile if x is that stratum's centre texel, else CLUSTER_SAMPLE_SIDE.
// The stratum of coordinate `x` in its tile (one axis) and its role there: 1 the centre,
// 2 the first, 3 the last texel, 0 none; the centre wins where roles coincide
// (`light::rsm::stratum_role`).
fn stratum_role(side: u32, x: u32) -> vec2<u32> {
    // Tile t holds the texels with ⌊x·T/R⌋ = t: from ⌈t·R/T⌉ to ⌈(t+1)·R/T⌉.
    let t = x * size.tiles / side;
    let x0 = (t * side + size.tiles - 1u) / size.tiles;
    let x1 = ((t + 1u) * side + size.tiles - 1u) / size.tiles;
    let width = max(x1 - x0, 1u);
    // The stratum whose span [x0 + s·w/S, x0 + (s+1)·w/S) holds x.
    let stratum = ((x - x0 + 1u) * CLUSTER_SAMPLE_SIDE - 1u) / width;
    let first = x0 + stratum * width / CLUSTER_SAMPLE_SIDE;
    let last = x0 + (stratum + 1u) * width / CLUSTER_SAMPLE_SIDE - 1u;
    let centre = x0 + (2u * stratum + 1u) * width / (2u * CLUSTER_SAMPLE_SIDE);
    var role = 0u;
    if (x == centre) {
        role = 1u;
    } else if (x == first) {
        role = 2u;
    } else if (x == last) {
        role = 3u;
    }
    return vec2<u32>(stratum, role);
}

// The sample candidate a texel is, from its two axes' roles: 0 the stratum's centre, 1–4 its
// corners, SAMPLE_CANDIDATES none (`light::rsm::sample_candidate`).
fn sample_candidate(rx: u32, ry: u32) -> u32 {
    if (rx == 1u && ry == 1u) {
        return 0u;
    }
    if (rx >= 2u && ry >= 2u) {
        return 1u + (rx - 2u) + 2u * (ry - 2u);
    }
    return SAMPLE_CANDIDATES;
}

// The view whose rows hold `row`: the last with first_row ≤ row (binary search).
fn view_of_row(row: u32) -> u32 {
    var lo = 0u;
    var hi = size.views;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (view_tiles[mid].first_row <= row) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// Texel (x, y) of a view's tile in the arrays: xy and the physical layer (the CPU twin is
// `Rsm::physical_texel`).
fn rsm_texel(tile: RsmTile, x: u32, y: u32) -> vec3<i32> {
    return vec3<i32>(i32(tile.origin.x + x), i32(tile.origin.y + y), i32(tile.layer));
}

const SCAN_GROUP: u32 = 256u;

var<workgroup> block_sums: array<u32, SCAN_GROUP>;

fn lit(tile: RsmTile, x: u32, y: u32) -> bool {
    let t = rsm_texel(tile, x, y);
    return textureLoad(rsm_flux, t.xy, t.z, 0).a > 0.5;
}

@compute @workgroup_size(64, 1, 1)
fn count_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let row = id.x + id.y * 65535u * 64u;
    if (row >= size.rows) {
        return;
    }
    let tile = view_tiles[view_of_row(row)];
    let y = row - tile.first_row;
    var n = 0u;
    for (var x = 0u; x < tile.side; x++) {
        n += select(0u, 1u, lit(tile, x, y));
    }
    row_offsets[row] = n;
}

// One workgroup: each thread sums a contiguous block of rows, thread 0 scans the block sums,
// then every thread turns its rows' counts into offsets.
@compute @workgroup_size(256, 1, 1)
fn scan_rows(@builtin(local_invocation_index) lid: u32) {
    let rows = size.rows;
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
    if (row >= size.rows) {
        return;
    }
    let view = view_of_row(row);
    let tile = view_tiles[view];
    let y = row - tile.first_row;
    var slot = row_offsets[row];
    let stratum_y = stratum_role(tile.side, y);
    for (var x = 0u; x < tile.side; x++) {
        let t = rsm_texel(tile, x, y);
        let flux = textureLoad(rsm_flux, t.xy, t.z, 0);
        if (flux.a < 0.5 || slot >= size.capacity) {
            continue;
        }
        var val: Val;
        val.position_area = textureLoad(rsm_position_area, t.xy, t.z, 0);
        val.normal = vec4<f32>(normalize(textureLoad(rsm_normal, t.xy, t.z, 0).xyz), 0.0);
        // w: the VAL's cluster (a small integer, exact in f32).
        let cluster_tile = layer_tile(view, tile.side, x, y);
        val.flux = vec4<f32>(flux.rgb, f32(cluster_tile % MAX_CLUSTERS));
        vals[slot] = val;
        let stratum_x = stratum_role(tile.side, x);
        let candidate = sample_candidate(stratum_x.y, stratum_y.y);
        if (candidate < SAMPLE_CANDIDATES) {
            let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
            let stratum = stratum_y.x * CLUSTER_SAMPLE_SIDE + stratum_x.x;
            cluster_samples[(cluster_tile * per_tile + stratum) * SAMPLE_CANDIDATES + candidate] = slot + 1u;
        }
        slot += 1u;
    }
}
