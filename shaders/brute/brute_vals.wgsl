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

// The window form takes a column of four pixels per invocation (pixel k of invocation (x, y)
// is (x, 4y + k)), so that each VAL, read once from the window, serves four pixels: a CPU
// device (Mesa's llvmpipe) reads a uniform block at a loop-varying index with one gathered
// load per float (`src/vals/README.md`, "How lavapipe loads memory"). Each pixel adds the VALs
// in the same order as with one pixel per invocation, to the same bits.
const COLUMN: u32 = 4u;

// The pixel's sum before this window: its running sum after the first window, else zero.
fn running_before(setup: PixelSetup, pixel: vec2<u32>, begin: u32) -> vec3<f32> {
    if (begin > 0u && setup.inside) {
        return running[pixel.y * frame.render_size.x + pixel.x].xyz;
    }
    return vec3<f32>(0.0);
}

// The last window writes the pixel, the others its running sum.
fn write_window_sum(setup: PixelSetup, pixel: vec2<u32>, radiance: vec3<f32>, last: bool) {
    if (!setup.inside) {
        return;
    }
    if (last) {
        textureStore(radiance_indirect, vec2<i32>(pixel), vec4<f32>(radiance, 1.0));
    } else {
        running[pixel.y * frame.render_size.x + pixel.x] = vec4<f32>(radiance, 0.0);
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
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let p0 = vec2<u32>(id.x, id.y * COLUMN);
    let p1 = p0 + vec2<u32>(0u, 1u);
    let p2 = p0 + vec2<u32>(0u, 2u);
    let p3 = p0 + vec2<u32>(0u, 3u);
    let s0 = pixel_setup(vec3<u32>(p0, 0u));
    let s1 = pixel_setup(vec3<u32>(p1, 0u));
    let s2 = pixel_setup(vec3<u32>(p2, 0u));
    let s3 = pixel_setup(vec3<u32>(p3, 0u));
    var r0 = running_before(s0, p0, begin);
    var r1 = running_before(s1, p1, begin);
    var r2 = running_before(s2, p2, begin);
    var r3 = running_before(s3, p3, begin);
    if (s0.covered || s1.covered || s2.covered || s3.covered) {
        // Uncovered pixels of the column sum too (their setup may not be finite) and keep
        // their running sum below.
        var a0 = r0;
        var a1 = r1;
        var a2 = r2;
        var a3 = r3;
        // A plain loop: at most WINDOW_VALS steps per dispatch, far from llvmpipe's 65535-step
        // limit that makes `cs_main` unroll, and unrolling measured no faster here.
        let m = end - begin;
        for (var j = 0u; j < m; j++) {
            let val = window_vals[j];
            a0 += val_radiance(s0.px, val, glossy_on);
            a1 += val_radiance(s1.px, val, glossy_on);
            a2 += val_radiance(s2.px, val, glossy_on);
            a3 += val_radiance(s3.px, val, glossy_on);
        }
        r0 = select(r0, a0, s0.covered);
        r1 = select(r1, a1, s1.covered);
        r2 = select(r2, a2, s2.covered);
        r3 = select(r3, a3, s3.covered);
    }
    let last = end >= count;
    write_window_sum(s0, p0, r0, last);
    write_window_sum(s1, p1, r1, last);
    write_window_sum(s2, p2, r2, last);
    write_window_sum(s3, p3, r3, last);
}
