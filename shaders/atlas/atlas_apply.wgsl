// Indirect radiance from the atlas irradiance: L = ρ_d/π · E per pixel, with ρ_d from the
// G-buffer (textures stay sharp because the atlas stores irradiance, not radiance). The
// glossy part of indirect light is not in the atlas (diffuse transport only).

struct ApplyParams {
    render_size: vec2<u32>,
    // 1: the lookup drew the atlas debug view's colours; they are written as they are.
    debug: u32,
    pad: u32,
}

@group(0) @binding(0) var<uniform> params: ApplyParams;
@group(0) @binding(1) var irradiance: texture_2d<f32>;
@group(0) @binding(2) var gbuffer_diffuse: texture_2d<f32>;
@group(0) @binding(3) var radiance_indirect: texture_storage_2d<rgba32float, write>;

const INV_PI: f32 = 0.31830988618379067;

@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.render_size.x || id.y >= params.render_size.y) {
        return;
    }
    let e = textureLoad(irradiance, id.xy, 0);
    if (params.debug != 0u) {
        textureStore(radiance_indirect, id.xy, vec4<f32>(e.rgb * e.a, 1.0));
        return;
    }
    let rho = textureLoad(gbuffer_diffuse, id.xy, 0).rgb;
    textureStore(radiance_indirect, id.xy, vec4<f32>(rho * INV_PI * e.rgb * e.a, 1.0));
}

// `sparse+atlas`: the VAL bounce (drawn by the sparse apply pass into `vals_indirect`) plus
// ρ_d/π · E of an atlas baked with --from-bounce 2, so each bounce is counted once.
@group(0) @binding(4) var vals_indirect: texture_2d<f32>;

@compute @workgroup_size(8, 8, 1)
fn cs_add(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.render_size.x || id.y >= params.render_size.y) {
        return;
    }
    let e = textureLoad(irradiance, id.xy, 0);
    if (params.debug != 0u) {
        textureStore(radiance_indirect, id.xy, vec4<f32>(e.rgb * e.a, 1.0));
        return;
    }
    let rho = textureLoad(gbuffer_diffuse, id.xy, 0).rgb;
    let vals = textureLoad(vals_indirect, id.xy, 0).rgb;
    textureStore(radiance_indirect, id.xy, vec4<f32>(vals + rho * INV_PI * e.rgb * e.a, 1.0));
}
