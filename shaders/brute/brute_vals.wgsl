// Brute force: every pixel sums every VAL through the full BRDF with the same disc irradiance
// as the sparse method — no interpolation, no occlusion. The baseline that isolates the sparse
// method's interpolation error. Two entry points read the VAL list two ways
// (`peers::brute`): `cs_main` streams it through workgroup memory in tiles; `cs_window` reads
// one uniform window per dispatch (`val_windows.wgsl`) and carries each pixel's sum from window
// to window in `running`, adding the VALs in the same order as `cs_main`, to the same bits.
#include "vals_common.wgsl"
#include "val_windows.wgsl"

const GROUP: u32 = 64u;
const TILE_MAX: u32 = 256u;

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: SparseParams;
@group(0) @binding(2) var<storage, read> vals: array<Val>;
@group(0) @binding(3) var<storage, read> val_count: array<u32>;
@group(0) @binding(4) var gbuffer_depth: texture_depth_2d;
@group(0) @binding(5) var gbuffer_normal: texture_2d<f32>;
@group(0) @binding(6) var gbuffer_diffuse: texture_2d<f32>;
@group(0) @binding(7) var gbuffer_specular: texture_2d<f32>;
@group(0) @binding(8) var radiance_indirect: texture_storage_2d<rgba32float, write>;

// The window form's running sums, one per pixel (row-major over the render size).
@group(1) @binding(0) var<storage, read_write> running: array<vec4<f32>>;

var<workgroup> tile_vals: array<Val, TILE_MAX>;
var<workgroup> shared_count: u32;

// The material and view at one pixel.
struct Pixel {
    p: vec3<f32>,
    n: vec3<f32>,
    r: vec3<f32>,
    rho_d: vec3<f32>,
    specular_scale: vec3<f32>,
    k: f32,
}

// False in the build for a method without glossy light (`light::GlossyGather`): a uniform
// flag alone leaves the lobe's code in, and llvmpipe runs both sides of a branch.
override GLOSSY_GATHER: bool = true;

// One VAL's reflected radiance at the pixel.
fn val_radiance(px: Pixel, val: Val, glossy_on: bool) -> vec3<f32> {
    let t = disc_terms(px.p, px.n, val);
    var f = px.rho_d / PI;
    if (glossy_on && GLOSSY_GATHER) {
        f += px.specular_scale * disc_lobe(t, px.r, px.k);
    }
    return f * val.flux.rgb * (t.g / PI);
}

// The pixel's material and view, whether it is inside the target (`inside`), and whether
// it is inside and a surface covers it (`covered`).
struct PixelSetup {
    px: Pixel,
    inside: bool,
    covered: bool,
}

fn pixel_setup(id: vec3<u32>) -> PixelSetup {
    let inside = id.x < frame.render_size.x && id.y < frame.render_size.y;
    let pixel = vec2<i32>(min(id.xy, frame.render_size - 1u));
    let covered = textureLoad(gbuffer_specular, pixel, 0).a > 0.5;
    let depth = textureLoad(gbuffer_depth, pixel, 0);
    let uv = (vec2<f32>(pixel) + 0.5) / vec2<f32>(frame.render_size);
    let world = frame.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
    let p = world.xyz / world.w;
    let n = normalize(textureLoad(gbuffer_normal, pixel, 0).xyz);
    let diffuse_tex = textureLoad(gbuffer_diffuse, pixel, 0);
    let rho_d = diffuse_tex.rgb;
    let k = diffuse_tex.a;
    let rho_s = textureLoad(gbuffer_specular, pixel, 0).rgb;
    let wo = normalize(frame.camera_position.xyz - p);
    let r = reflect(-wo, n);
    let px = Pixel(p, n, r, rho_d, rho_s * ((k + 2.0) / (2.0 * PI)), k);
    return PixelSetup(px, inside, inside && covered);
}

@compute @workgroup_size(8, 8, 1)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    if (lid == 0u) {
        shared_count = min(val_count[0], arrayLength(&vals));
    }
    let count = workgroupUniformLoad(&shared_count);
    let tile = clamp(params.tile, 1u, TILE_MAX);
    let setup = pixel_setup(id);
    let inside = setup.inside;
    let is_active = setup.covered;
    let px = setup.px;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;

    var radiance = vec3<f32>(0.0);
    for (var base = 0u; base < count; base += tile) {
        let m = min(tile, count - base);
        for (var i = lid; i < m; i += GROUP) {
            tile_vals[i] = vals[base + i];
        }
        workgroupBarrier();
        if (is_active) {
            // Written out 16 at a time: Mesa's llvmpipe ends any loop after 65535 iterations
            // per invocation (see vals_gather.wgsl).
            var j = 0u;
            let full = m - m % 16u;
            while (j < full) {
                radiance += val_radiance(px, tile_vals[j + 0u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 1u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 2u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 3u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 4u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 5u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 6u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 7u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 8u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 9u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 10u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 11u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 12u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 13u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 14u], glossy_on);
                radiance += val_radiance(px, tile_vals[j + 15u], glossy_on);
                j += 16u;
            }
            while (j < m) {
                radiance += val_radiance(px, tile_vals[j], glossy_on);
                j += 1u;
            }
        }
        workgroupBarrier();
    }
    if (inside) {
        textureStore(radiance_indirect, vec2<i32>(id.xy), vec4<f32>(radiance, 1.0));
    }
}

@compute @workgroup_size(8, 8, 1)
fn cs_window(@builtin(global_invocation_id) id: vec3<u32>) {
    let count = min(val_count[0], arrayLength(&vals));
    // Past the last VAL: an earlier window has written the pixels.
    if (window_past_count(count)) {
        return;
    }
    let begin = window.first;
    let end = window_end(count);
    let setup = pixel_setup(id);
    let px = setup.px;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let at = id.y * frame.render_size.x + id.x;
    var radiance = vec3<f32>(0.0);
    if (begin > 0u && setup.inside) {
        radiance = running[at].xyz;
    }
    if (setup.covered) {
        // A plain loop: at most WINDOW_VALS steps per dispatch, far from llvmpipe's 65535-step
        // limit that makes `cs_main` unroll, and unrolling measured no faster here.
        let m = end - begin;
        for (var j = 0u; j < m; j++) {
            radiance += val_radiance(px, window_vals[j], glossy_on);
        }
    }
    if (!setup.inside) {
        return;
    }
    // The last window writes the pixel, the others its running sum.
    if (end < count) {
        running[at] = vec4<f32>(radiance, 0.0);
    } else {
        textureStore(radiance_indirect, vec2<i32>(id.xy), vec4<f32>(radiance, 1.0));
    }
}
