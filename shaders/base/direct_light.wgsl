// Direct lighting per pixel from the G-buffer: every punctual light (emitter proxies included) with its filtered
// shadow-map visibility, through the material model of DESIGN §3, plus emission.
#include "common.wgsl"

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> lights: array<Light>;
@group(0) @binding(2) var<storage, read> shadow_views: array<ShadowView>;
@group(0) @binding(3) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(4) var shadow_sampler: sampler_comparison;
@group(0) @binding(5) var gbuffer_depth: texture_depth_2d;
@group(0) @binding(6) var gbuffer_normal: texture_2d<f32>;
@group(0) @binding(7) var gbuffer_diffuse: texture_2d<f32>;
@group(0) @binding(8) var gbuffer_specular: texture_2d<f32>;
@group(0) @binding(9) var gbuffer_emissive: texture_2d<f32>;
@group(0) @binding(10) var radiance_direct: texture_storage_2d<rgba32float, write>;
// The lights and shadow views again as uniform blocks, which every pixel reads alike: a CPU
// device (Mesa's llvmpipe) reads a uniform block with one gathered load per value where it
// reads a storage buffer lane by lane under a per-lane test. A scene with more lights or views
// than a block holds reads the storage buffers (LIGHTS_IN_BLOCK false; `Rasterizer::new`).
const LIGHT_BLOCK: u32 = 256u;
const VIEW_BLOCK: u32 = 256u;
override LIGHTS_IN_BLOCK: bool = true;
@group(0) @binding(11) var<uniform> lights_block: array<Light, LIGHT_BLOCK>;
@group(0) @binding(12) var<uniform> shadow_views_block: array<ShadowView, VIEW_BLOCK>;

fn light_at(i: u32) -> Light {
    if (LIGHTS_IN_BLOCK) {
        return lights_block[i];
    }
    return lights[i];
}

fn shadow_view_at(i: u32) -> ShadowView {
    if (LIGHTS_IN_BLOCK) {
        return shadow_views_block[i];
    }
    return shadow_views[i];
}

// World position of a pixel centre from the depth buffer.
fn world_position(pixel: vec2<u32>, depth: f32) -> vec3<f32> {
    let uv = (vec2<f32>(pixel) + 0.5) / vec2<f32>(frame.render_size);
    let ndc = vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let world = frame.world_from_clip * ndc;
    return world.xyz / world.w;
}

// Which cube face (+X, −X, +Y, −Y, +Z, −Z) sees direction d from a point light.
fn cube_face(d: vec3<f32>) -> u32 {
    let a = abs(d);
    if (a.x >= a.y && a.x >= a.z) {
        return select(1u, 0u, d.x > 0.0);
    }
    if (a.y >= a.z) {
        return select(3u, 2u, d.y > 0.0);
    }
    return select(5u, 4u, d.z > 0.0);
}

// Fraction of the shadow-map footprint around p that shadow view `view_index` sees: bilinear
// comparison taps over a (2r+1)² texel grid of the view's tile. The receiver is pushed along
// its normal by a texel's world size so that flat surfaces do not shadow themselves.
fn visibility(view_index: u32, p: vec3<f32>, n: vec3<f32>) -> f32 {
    let view = shadow_view_at(view_index);
    var texel_world = view.texel.x;
    if (view.origin.w > 0.5) {
        texel_world = view.texel.x * length(p - view.origin.xyz);
    }
    let offset_p = p + n * (1.5 * texel_world);
    let clip = view.clip_from_world * vec4<f32>(offset_p, 1.0);
    if (clip.w <= 0.0) {
        return 1.0;
    }
    let ndc = clip.xyz / clip.w;
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    if (ndc.z > 1.0) {
        return 1.0;
    }
    // The view's [0, 1]² maps onto its tile; taps stay half a texel inside the tile so that
    // bilinear filtering never reads a neighbour's depths.
    let tile_origin = view.atlas_rect.xy;
    let tile_size = view.atlas_rect.z;
    let texel_uv = tile_size / view.texel.y;
    let tile_uv = tile_origin + clamp(uv, vec2<f32>(0.0), vec2<f32>(1.0)) * tile_size;
    let lo = tile_origin + vec2<f32>(0.5 * texel_uv);
    let hi = tile_origin + vec2<f32>(tile_size - 0.5 * texel_uv);
    let r = i32(frame.shadow_pcf_radius);
    var lit = 0.0;
    var taps = 0.0;
    for (var dy = -r; dy <= r; dy++) {
        for (var dx = -r; dx <= r; dx++) {
            let tap_uv = clamp(tile_uv + vec2<f32>(f32(dx), f32(dy)) * texel_uv, lo, hi);
            lit += textureSampleCompareLevel(shadow_maps, shadow_sampler, tap_uv, view.atlas_layer, ndc.z);
            taps += 1.0;
        }
    }
    return lit / taps;
}

@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= frame.render_size.x || id.y >= frame.render_size.y) {
        return;
    }
    let pixel = id.xy;
    let spec_tex = textureLoad(gbuffer_specular, pixel, 0);
    if (spec_tex.a < 0.5) {
        // Background: no surface, no light.
        textureStore(radiance_direct, pixel, vec4<f32>(0.0, 0.0, 0.0, 0.0));
        return;
    }
    let depth = textureLoad(gbuffer_depth, pixel, 0);
    let p = world_position(pixel, depth);
    let n = normalize(textureLoad(gbuffer_normal, pixel, 0).xyz);
    let diffuse_tex = textureLoad(gbuffer_diffuse, pixel, 0);
    let rho_d = diffuse_tex.rgb;
    let k = diffuse_tex.a;
    let rho_s = spec_tex.rgb;
    let wo = normalize(frame.camera_position.xyz - p);

    var radiance = textureLoad(gbuffer_emissive, pixel, 0).rgb;
    for (var i = 0u; i < frame.light_count; i++) {
        let light = light_at(i);
        var wi: vec3<f32>;
        var irradiance_normal: vec3<f32>;
        var view_index = light.first_shadow_view;
        if (light.kind == LIGHT_DIRECTIONAL) {
            wi = -light.direction.xyz;
            irradiance_normal = light.intensity.rgb;
        } else {
            let to_light = light.position.xyz - p;
            let d2 = max(dot(to_light, to_light), 1e-12);
            let d = sqrt(d2);
            wi = to_light / d;
            var falloff = range_window(light.direction.w, d) / d2;
            if (light.kind == LIGHT_SPOT) {
                falloff *= spot_attenuation(light, -wi);
            } else {
                view_index += cube_face(-wi);
                if (light.kind == LIGHT_EMITTER) {
                    falloff *= emitter_lobe(light, -wi);
                }
            }
            irradiance_normal = light.intensity.rgb * falloff;
        }
        let cos_i = dot(n, wi);
        if (cos_i <= 0.0 || all(irradiance_normal <= vec3<f32>(0.0))) {
            continue;
        }
        var v = 1.0;
        if (light.first_shadow_view != NO_SHADOW) {
            v = visibility(view_index, p, n);
        }
        radiance += brdf(rho_d, rho_s, k, n, wi, wo) * irradiance_normal * (cos_i * v);
    }
    textureStore(radiance_direct, pixel, vec4<f32>(radiance, 1.0));
}
