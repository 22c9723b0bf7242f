// Appends VALs made outside the RSM (the surfels of a depth-sensor frame) after the RSM's
// VALs in the same buffer, so every VAL consumer gathers both. The producer's candidates are
// `rows × row_length` records; a candidate whose area is not positive is an empty slot and is
// skipped. Row order is kept (deterministic VAL list). Two passes: count each row's valid
// candidates (and record the RSM's count as the base), then write each row at the base plus
// the counts of the rows before it — a linear prefix per thread, cheap for the few hundred
// rows of a sensor frame.
#include "vals_common.wgsl"

struct AppendSize {
    rows: u32,
    row_length: u32,
    // Slots of the whole VAL buffer (RSM + external).
    capacity: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> size: AppendSize;
@group(0) @binding(1) var<storage, read> candidates: array<Val>;
@group(0) @binding(2) var<storage, read_write> vals: array<Val>;
@group(0) @binding(3) var<storage, read_write> val_count: array<u32>;
// Per row its valid-candidate count; slot `rows` holds the VAL count before the append.
@group(0) @binding(4) var<storage, read_write> row_counts: array<u32>;

// The cluster id of VALs that come from no RSM tile (`light::rsm::UNCLUSTERED`).
const UNCLUSTERED: u32 = 32u;

fn valid(c: Val) -> bool {
    return c.position_area.w > 0.0;
}

@compute @workgroup_size(64, 1, 1)
fn count_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let row = id.x;
    if (row >= size.rows) {
        return;
    }
    if (row == 0u) {
        row_counts[size.rows] = val_count[0];
    }
    var n = 0u;
    for (var x = 0u; x < size.row_length; x++) {
        n += select(0u, 1u, valid(candidates[row * size.row_length + x]));
    }
    row_counts[row] = n;
}

@compute @workgroup_size(64, 1, 1)
fn append_rows(@builtin(global_invocation_id) id: vec3<u32>) {
    let row = id.x;
    if (row >= size.rows) {
        return;
    }
    let base = row_counts[size.rows];
    var slot = base;
    for (var r = 0u; r < row; r++) {
        slot += row_counts[r];
    }
    if (row + 1u == size.rows) {
        val_count[0] = min(slot + row_counts[row], size.capacity);
    }
    for (var x = 0u; x < size.row_length; x++) {
        let c = candidates[row * size.row_length + x];
        if (!valid(c) || slot >= size.capacity) {
            continue;
        }
        // Outside every RSM cluster (w = MAX_CLUSTERS): no cluster visibility scales it.
        var appended = c;
        appended.flux.w = f32(UNCLUSTERED);
        vals[slot] = appended;
        slot += 1u;
    }
}
