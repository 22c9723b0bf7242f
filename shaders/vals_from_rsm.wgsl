// Compacts every lit RSM texel of every layer into one VAL buffer for all lights. Texels that
// hit nothing or reflect nothing produce no VAL, so later passes loop over real lights only.
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
@group(0) @binding(5) var<storage, read_write> val_count: array<atomic<u32>>;

@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= size.resolution || id.y >= size.resolution || id.z >= size.layers) {
        return;
    }
    let texel = vec2<i32>(id.xy);
    let layer = i32(id.z);
    let flux = textureLoad(rsm_flux, texel, layer, 0);
    if (flux.a < 0.5) {
        return;
    }
    let slot = atomicAdd(&val_count[0], 1u);
    if (slot >= size.capacity) {
        return;
    }
    var val: Val;
    val.position_area = textureLoad(rsm_position_area, texel, layer, 0);
    val.normal = vec4<f32>(normalize(textureLoad(rsm_normal, texel, layer, 0).xyz), 0.0);
    val.flux = vec4<f32>(flux.rgb, 0.0);
    vals[slot] = val;
}
