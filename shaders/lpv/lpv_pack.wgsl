// Copies the injected volume (a buffer, which injection sums into with atomics) into the 3D
// texture the first propagation step reads (`lpv_cell_texels()` texels a cell, the last one
// zero-padded). One invocation per cell.
#include "lpv_common.wgsl"

@group(0) @binding(0) var<uniform> params: LpvParams;
@group(0) @binding(1) var<storage, read> injected: array<f32>;
@group(0) @binding(2) var packed: texture_storage_3d<rgba32float, write>;

@compute @workgroup_size(4, 4, 4)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let c = vec3<i32>(id);
    if (!lpv_inside(c, params.dims.xyz)) {
        return;
    }
    let stride = 3u * SH_COUNT;
    let cell = lpv_cell_index(c, params.dims.xyz) * stride;
    let texels = lpv_cell_texels();
    for (var t = 0u; t < texels; t++) {
        var texel = vec4<f32>(0.0);
        for (var i = 0u; i < 4u; i++) {
            let f = 4u * t + i;
            if (f < stride) {
                texel[i] = injected[cell + f];
            }
        }
        textureStore(packed, vec3<i32>(c.x * i32(texels) + i32(t), c.y, c.z), texel);
    }
}
