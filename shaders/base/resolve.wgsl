// Box-filters the supersampled direct and indirect radiance down to the output size (N×N
// samples per output pixel). Indirect methods write `radiance_indirect`; for direct-only
// rendering `has_indirect` is 0 and the indirect output is black.

struct ResolveParams {
    output_size: vec2<u32>,
    ssaa: u32,
    has_indirect: u32,
}

@group(0) @binding(0) var<uniform> params: ResolveParams;
@group(0) @binding(1) var radiance_direct: texture_2d<f32>;
@group(0) @binding(2) var radiance_indirect: texture_2d<f32>;
@group(0) @binding(3) var output_direct: texture_storage_2d<rgba32float, write>;
@group(0) @binding(4) var output_indirect: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.output_size.x || id.y >= params.output_size.y) {
        return;
    }
    var direct = vec3<f32>(0.0);
    var indirect = vec3<f32>(0.0);
    let base = id.xy * params.ssaa;
    for (var sy = 0u; sy < params.ssaa; sy++) {
        for (var sx = 0u; sx < params.ssaa; sx++) {
            let s = base + vec2<u32>(sx, sy);
            direct += textureLoad(radiance_direct, s, 0).rgb;
            if (params.has_indirect != 0u) {
                indirect += textureLoad(radiance_indirect, s, 0).rgb;
            }
        }
    }
    let inv = 1.0 / f32(params.ssaa * params.ssaa);
    textureStore(output_direct, id.xy, vec4<f32>(direct * inv, 1.0));
    textureStore(output_indirect, id.xy, vec4<f32>(indirect * inv, 1.0));
}
