// LPV lookup: per pixel, the accumulated intensity SH trilinearly interpolated half a cell
// along the normal (cell centres, clamped at the grid's edge), the cosine-lobe integral
// E = max(0, Σ c·Â_l·Y_lm(−n))/h² (intensity over the cell's cross-section h² → radiance)
// and the diffuse reflection ρ_d/π·E. The accumulated volume comes packed as a 3D texture
// (`lpv_pack.wgsl`, `lpv_cell_texels()` texels a cell along x): a CPU device (llvmpipe) fetches
// a texel with one gathered load where it reads a storage buffer lane by lane per float, and
// every pixel reads 8 cells. CPU twin: math::lookup.
#include "lpv_common.wgsl"

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: LpvParams;
@group(0) @binding(2) var accum: texture_3d<f32>;
@group(0) @binding(3) var gbuffer_depth: texture_depth_2d;
@group(0) @binding(4) var gbuffer_normal: texture_2d<f32>;
@group(0) @binding(5) var gbuffer_diffuse: texture_2d<f32>;
@group(0) @binding(6) var gbuffer_specular: texture_2d<f32>;
@group(0) @binding(7) var radiance_indirect: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (any(id.xy >= frame.render_size)) {
        return;
    }
    let pixel = vec2<i32>(id.xy);
    if (textureLoad(gbuffer_specular, pixel, 0).a < 0.5) {
        textureStore(radiance_indirect, pixel, vec4<f32>(0.0, 0.0, 0.0, 1.0));
        return;
    }
    let depth = textureLoad(gbuffer_depth, pixel, 0);
    let uv = (vec2<f32>(pixel) + 0.5) / vec2<f32>(frame.render_size);
    let world = frame.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let p = world.xyz / world.w;
    let n = normalize(textureLoad(gbuffer_normal, pixel, 0).xyz);
    let rho_d = textureLoad(gbuffer_diffuse, pixel, 0).rgb;

    let dims = params.dims.xyz;
    let h = params.origin_cell.w;
    let hi = vec3<f32>(dims - 1u);
    let q = clamp((p + 0.5 * h * n - params.origin_cell.xyz) / h - 0.5, vec3<f32>(0.0), hi);
    let base = max(min(floor(q), hi - 1.0), vec3<f32>(0.0));
    let t = q - base;
    let b = vec3<i32>(base);
    let lobe = sh9(-n);
    var e = vec3<f32>(0.0);
    for (var corner = 0; corner < 8; corner++) {
        let bit = vec3<i32>(corner & 1, (corner >> 1) & 1, (corner >> 2) & 1);
        let wv = select(1.0 - t, t, bit == vec3<i32>(1));
        let w = wv.x * wv.y * wv.z;
        let coefficients = lpv_texel_cell(accum, min(b + bit, vec3<i32>(dims) - 1));
        for (var k = 0u; k < SH_COUNT; k++) {
            e += (w * clamped_cosine_factor(k) * lobe[k]) * coefficients[k];
        }
    }
    let radiance = rho_d / PI * max(e, vec3<f32>(0.0)) / (h * h);
    textureStore(radiance_indirect, pixel, vec4<f32>(radiance, 1.0));
}
