// Appends VALs made outside the RSM (the surfels of a depth-sensor frame) after the RSM's
// VALs in the same buffer, so every VAL consumer gathers both. The producer's candidates are
// `rows × row_length` records; a candidate whose area is not positive is an empty slot and is
// skipped. Row order is kept (deterministic VAL list). Two passes, one workgroup per row
// (a GPU needs the parallelism: one invocation per row left 480 threads looping over 640
// candidates each, 0.56 ms of a 4 ms sensor frame on an H200): count each row's valid
// candidates (and record the RSM's count as the base), then write each row at the base plus
// the counts of the rows before it, each invocation's run of candidates at its place in a
// workgroup prefix sum of the runs' counts.
#include "vals_common.wgsl"

struct AppendSize {
    rows: u32,
    row_length: u32,
    // Slots of the whole VAL buffer (RSM + external).
    capacity: u32,
    // The tile of the candidates' tile 0 (`flux.w` holds a candidate's tile), after the RSM's
    // tiles; NO_EXTERNAL_TILES: the candidates are in no cluster.
    first_tile: u32,
}

@group(0) @binding(0) var<uniform> size: AppendSize;
@group(0) @binding(1) var<storage, read> candidates: array<Val>;
@group(0) @binding(2) var<storage, read_write> vals: array<Val>;
@group(0) @binding(3) var<storage, read_write> val_count: array<u32>;
// Per row its valid-candidate count; slot `rows` holds the VAL count before the append.
@group(0) @binding(4) var<storage, read_write> row_counts: array<u32>;

// The cluster id of VALs in no cluster (`light::rsm::UNCLUSTERED`).
const UNCLUSTERED: u32 = 32u;
const MAX_CLUSTERS: u32 = 32u;
const NO_EXTERNAL_TILES: u32 = 0xffffffffu;

fn valid(c: Val) -> bool {
    return c.position_area.w > 0.0;
}

// Invocations per workgroup: `APPEND_GROUP` in `src/light/rsm.rs`.
const GROUP: u32 = 64u;

var<workgroup> shared_sum: atomic<u32>;
var<workgroup> run_counts: array<u32, GROUP>;

// The workgroup's row (dispatches past the per-dimension limit wrap into y).
fn row_of(wid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return wid.x + wid.y * groups.x;
}

@compute @workgroup_size(64, 1, 1)
fn count_rows(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let row = row_of(wid, groups);
    if (lid == 0u) {
        atomicStore(&shared_sum, 0u);
    }
    workgroupBarrier();
    if (row < size.rows) {
        var n = 0u;
        for (var x = lid; x < size.row_length; x += GROUP) {
            n += select(0u, 1u, valid(candidates[row * size.row_length + x]));
        }
        atomicAdd(&shared_sum, n);
    }
    workgroupBarrier();
    if (row < size.rows && lid == 0u) {
        row_counts[row] = atomicLoad(&shared_sum);
        if (row == 0u) {
            row_counts[size.rows] = val_count[0];
        }
    }
}

@compute @workgroup_size(64, 1, 1)
fn append_rows(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let row = row_of(wid, groups);
    let row_active = row < size.rows;
    if (lid == 0u) {
        atomicStore(&shared_sum, 0u);
    }
    workgroupBarrier();
    // The counts of the rows before this one, summed by the whole workgroup.
    if (row_active) {
        var before = 0u;
        for (var r = lid; r < row; r += GROUP) {
            before += row_counts[r];
        }
        atomicAdd(&shared_sum, before);
    }
    workgroupBarrier();
    var slot = atomicLoad(&shared_sum);
    if (row_active) {
        slot += row_counts[size.rows];
    }
    // Each invocation takes a run of `segment` neighbouring candidates: it counts its valid
    // ones, one workgroup prefix sum over the 64 counts places every run, and each run is
    // written in order (one prefix sum per row, not one per 64 candidates).
    let length = size.row_length;
    let segment = (length + GROUP - 1u) / GROUP;
    let first = min(lid * segment, length);
    let last = min(first + segment, length);
    var own = 0u;
    if (row_active) {
        for (var x = first; x < last; x++) {
            own += select(0u, 1u, valid(candidates[row * length + x]));
        }
    }
    run_counts[lid] = own;
    workgroupBarrier();
    // Inclusive prefix sum of the 64 counts (Hillis–Steele).
    for (var offset = 1u; offset < GROUP; offset *= 2u) {
        var add = 0u;
        if (lid >= offset) {
            add = run_counts[lid - offset];
        }
        workgroupBarrier();
        run_counts[lid] += add;
        workgroupBarrier();
    }
    var at = slot + run_counts[lid] - own;
    if (row_active) {
        for (var x = first; x < last; x++) {
            let c = candidates[row * length + x];
            if (!valid(c) || at >= size.capacity) {
                continue;
            }
            // A sensor tile becomes the cluster of its tile after the RSM's (folded into
            // MAX_CLUSTERS like theirs); without tiles, no cluster visibility scales it.
            var appended = c;
            var cluster = UNCLUSTERED;
            if (size.first_tile != NO_EXTERNAL_TILES) {
                cluster = (size.first_tile + u32(c.flux.w)) % MAX_CLUSTERS;
            }
            appended.flux.w = f32(cluster);
            vals[at] = appended;
            at += 1u;
        }
    }
    slot += run_counts[GROUP - 1u];
    if (row_active && lid == 0u && row + 1u == size.rows) {
        val_count[0] = min(slot, size.capacity);
    }
}
