// LPV injection: every VPL (RSM VAL) adds the lobe Φ/π·max(0, n·ω) (W/sr) in SH to the cell
// holding its position shifted half a cell along its normal (against self-lighting). Cells
// are summed with a compare-exchange float add. CPU twin: math::inject.
#include "lpv_common.wgsl"

@group(0) @binding(0) var<uniform> params: LpvParams;
@group(0) @binding(1) var<storage, read> vals: array<Val>;
@group(0) @binding(2) var<storage, read> val_count: array<u32>;
@group(0) @binding(3) var<storage, read_write> volume: array<atomic<u32>>;

fn add_f32(index: u32, value: f32) {
    var old = atomicLoad(&volume[index]);
    loop {
        let r = atomicCompareExchangeWeak(&volume[index], old, bitcast<u32>(bitcast<f32>(old) + value));
        if (r.exchanged) {
            break;
        }
        old = r.old_value;
    }
}

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    // Rows of at most 65535 workgroups, for RSMs with more than 4M texels.
    let i = id.x + id.y * groups.x * 64u;
    if (i >= min(val_count[0], arrayLength(&vals))) {
        return;
    }
    let val = vals[i];
    let n = val.normal.xyz;
    let h = params.origin_cell.w;
    let q = val.position_area.xyz + 0.5 * h * n;
    let c = vec3<i32>(floor((q - params.origin_cell.xyz) / h));
    if (!lpv_inside(c, params.dims.xyz)) {
        return;
    }
    let y = sh9(n);
    let base = lpv_cell_index(c, params.dims.xyz) * 3u * SH_COUNT;
    for (var ch = 0u; ch < 3u; ch++) {
        let scale = val.flux[ch] / PI;
        if (scale == 0.0) {
            continue;
        }
        for (var k = 0u; k < SH_COUNT; k++) {
            add_f32(base + ch * SH_COUNT + k, scale * clamped_cosine_factor(k) * y[k]);
        }
    }
}
