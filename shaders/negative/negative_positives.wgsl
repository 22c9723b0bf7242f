// Positive indirect lights (§A.2): each Halton sample reads its RSM texel — position, normal
// and the flux ρ_d·I(ω)·Ω_texel the RSM pass stored — and scales the flux to the share of the
// light's solid angle (or area) the sample stands for. Texels that hit nothing or face away
// from the light give an inactive light (their energy escapes, as in the paper).
#include "negative_common.wgsl"

struct SampleCount {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<uniform> sample_count: SampleCount;
@group(0) @binding(1) var<storage, read> samples: array<PositiveSample>;
@group(0) @binding(2) var rsm_position_area: texture_2d_array<f32>;
@group(0) @binding(3) var rsm_normal: texture_2d_array<f32>;
@group(0) @binding(4) var rsm_flux: texture_2d_array<f32>;
@group(0) @binding(5) var<storage, read_write> positives: array<IndirectLight>;

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    // Wrapped into y past the device's workgroups per dimension (`gpu::linear_groups`).
    let i = id.x + id.y * groups.x * 64u;
    if (i >= sample_count.count) {
        return;
    }
    let s = samples[i];
    let texel = vec2<i32>(i32(s.texel_x), i32(s.texel_y));
    let layer = i32(s.layer);
    let flux = textureLoad(rsm_flux, texel, layer, 0);
    var light: IndirectLight;
    light.position = vec4<f32>(0.0);
    light.normal = vec4<f32>(0.0);
    light.flux = vec4<f32>(0.0);
    if (flux.a > 0.5) {
        let position_area = textureLoad(rsm_position_area, texel, layer, 0);
        light.position = vec4<f32>(position_area.xyz, 1.0);
        // The sample stands for flux_scale texels' worth of area: r² = A·scale/π.
        let r2 = position_area.w * s.flux_scale / PI;
        light.normal = vec4<f32>(normalize(textureLoad(rsm_normal, texel, layer, 0).xyz), r2);
        light.flux = vec4<f32>(flux.rgb * s.flux_scale, 0.0);
    }
    positives[i] = light;
}
