// The per-view passes of second-order illumination with negative indirect lights (§A.3–A.8):
//
//   points            S_cam: world position, normal and eye distance of every pixel
//   downsample        S_locam: per 2×2 block the covered pixel nearest the block's median depth
//   positive_low      E_s, E_neg and the weighted direction at every low-resolution point
//   classify          per 8×8 tile: does any pixel differ from its low-resolution parent by
//                     more than the discontinuity threshold? Flagged tiles are appended to a
//                     list whose length becomes the indirect dispatch of the patch passes
//   positive_tiles    the same terms at full resolution in the flagged tiles (indirect)
//   positive_full     the same terms at every pixel (low resolution off)
//   select_negatives  M negative lights from the Halton camera candidates
//   negative_low / negative_tiles / negative_full   E_n from the negative lights, likewise
//   gather            ρ_d/π·max(0, E_s − E_n) into the view's indirect radiance, with the
//                     clamp's statistics per workgroup
//
// A pixel reads its full-resolution terms where its tile was recomputed and its parent's
// (nearest-parent upsampling) elsewhere.
#include "negative_common.wgsl"

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: NegativeParams;
@group(0) @binding(2) var gbuffer_depth: texture_depth_2d;
@group(0) @binding(3) var gbuffer_normal: texture_2d<f32>;
@group(0) @binding(4) var gbuffer_diffuse: texture_2d<f32>;
@group(0) @binding(5) var gbuffer_specular: texture_2d<f32>;
@group(0) @binding(6) var radiance_indirect: texture_storage_2d<rgba32float, write>;
@group(0) @binding(7) var<storage, read> positives: array<IndirectLight>;
@group(0) @binding(8) var<storage, read_write> points: array<SurfacePoint>;
@group(0) @binding(9) var<storage, read_write> low_points: array<SurfacePoint>;
@group(0) @binding(10) var<storage, read_write> low_terms: array<PositiveTerms>;
@group(0) @binding(11) var<storage, read_write> full_terms: array<PositiveTerms>;
// [0]: flagged tiles, [1], [2]: 1 (the indirect dispatch's y and z), [3]: recomputed pixels,
// then one flag per tile, then the list of flagged tiles.
@group(0) @binding(12) var<storage, read_write> tiles: array<atomic<u32>>;
@group(0) @binding(13) var<storage, read> candidates: array<u32>;
@group(0) @binding(14) var<storage, read_write> negatives: array<IndirectLight>;
// [0]: negative lights placed, [1]: K, the candidates tried.
@group(0) @binding(15) var<storage, read_write> negative_state: array<u32>;
@group(0) @binding(16) var<storage, read_write> low_en: array<vec4<f32>>;
@group(0) @binding(17) var<storage, read_write> full_en: array<vec4<f32>>;
// Per gather workgroup: (clamped pixels, Y removed by the clamp, Y of ρ/π·E_s, covered
// pixels), (Y of ρ/π·E_n, positive lights that hit the d²_min guard, summed over pixels, 0, 0).
@group(0) @binding(18) var<storage, read_write> stats: array<vec4<f32>>;
// The lights every pixel loops over, read alike by all invocations, as uniform blocks: a CPU
// device (Mesa's llvmpipe) reads a uniform block with one scalar load per value where it
// reads a storage buffer, or workgroup memory, lane by lane under a per-lane test (bunny-box
// 640×480 on lavapipe, N = 100: the positive pass 315 → 41 ms). Each block holds LIGHT_BLOCK
// lights, copied in after the pass that writes them; with more positive lights than that
// (`--positive` × the scene's lights) the positive loop reads `positives` instead
// (POSITIVES_IN_BLOCK false; `NegativeMethod::new`). M ≤ 1024 always fits.
const LIGHT_BLOCK: u32 = 1024u;
override POSITIVES_IN_BLOCK: bool = true;
@group(0) @binding(19) var<uniform> positives_block: array<IndirectLight, LIGHT_BLOCK>;
@group(0) @binding(20) var<uniform> negatives_block: array<IndirectLight, LIGHT_BLOCK>;

// Positive light i (i < params.positive_count).
fn positive_light(i: u32) -> IndirectLight {
    if (POSITIVES_IN_BLOCK) {
        return positives_block[i];
    }
    return positives[i];
}

const TILE: u32 = 8u;
const TILE_HEADER: u32 = 4u;
const SELECT_GROUP: u32 = 256u;

fn tile_count() -> u32 {
    return params.tiles_x * ((params.full_height + TILE - 1u) / TILE);
}

fn tile_flag_slot(tile: u32) -> u32 {
    return TILE_HEADER + tile;
}

fn tile_list_slot(i: u32) -> u32 {
    return TILE_HEADER + tile_count() + i;
}

fn full_index(pixel: vec2<u32>) -> u32 {
    return pixel.y * params.full_width + pixel.x;
}

fn parent_index(pixel: vec2<u32>) -> u32 {
    return (pixel.y / 2u) * params.low_width + pixel.x / 2u;
}

fn tile_of(pixel: vec2<u32>) -> u32 {
    return (pixel.y / TILE) * params.tiles_x + pixel.x / TILE;
}

// Whether the pixel's own terms were computed (its tile recomputed, or no low resolution).
fn has_full_terms(pixel: vec2<u32>) -> bool {
    if (params.lowres == 0u) {
        return true;
    }
    return atomicLoad(&tiles[tile_flag_slot(tile_of(pixel))]) != 0u;
}

fn terms_at(pixel: vec2<u32>) -> PositiveTerms {
    if (has_full_terms(pixel)) {
        return full_terms[full_index(pixel)];
    }
    return low_terms[parent_index(pixel)];
}

fn en_at(pixel: vec2<u32>) -> vec3<f32> {
    if (has_full_terms(pixel)) {
        return full_en[full_index(pixel)].rgb;
    }
    return low_en[parent_index(pixel)].rgb;
}

// Emitter side of a Lambertian point light seen from p: Φ/π·max(0, n_l·t̂_{l→p})/max(d², d²_min)
// (or /(d² + r²) with the disc falloff)
// in rgb and t̂_{p→l} in `to_light`; zero for an inactive light.
struct Arriving {
    rgb: vec3<f32>,
    to_light: vec3<f32>,
    // 1 when the point falloff's d²_min guard replaced d².
    clamped: f32,
}

fn arriving(p: vec3<f32>, light: IndirectLight) -> Arriving {
    var out: Arriving;
    out.rgb = vec3<f32>(0.0);
    out.to_light = vec3<f32>(0.0, 0.0, 1.0);
    out.clamped = 0.0;
    let d = light.position.xyz - p;
    let d2 = dot(d, d);
    if (light.position.w < 0.5 || d2 <= 0.0) {
        return out;
    }
    out.to_light = d / sqrt(d2);
    let cos_l = max(0.0, dot(light.normal.xyz, -out.to_light));
    var denominator = max(d2, params.d2_min);
    if (params.falloff == 1u) {
        denominator = d2 + light.normal.w;
    } else if (d2 < params.d2_min) {
        out.clamped = 1.0;
    }
    out.rgb = light.flux.rgb / PI * cos_l / denominator;
    return out;
}

fn positive_terms(point: SurfacePoint) -> PositiveTerms {
    var t: PositiveTerms;
    t.e_s = vec4<f32>(0.0);
    t.e_neg = vec4<f32>(0.0);
    t.direction = vec4<f32>(0.0);
    if (point.position.w < 0.5) {
        return t;
    }
    let p = point.position.xyz;
    let n = point.normal.xyz;
    var e_s = vec3<f32>(0.0);
    var e_neg = vec3<f32>(0.0);
    var dir = vec3<f32>(0.0);
    var clamped = 0.0;
    for (var i = 0u; i < params.positive_count; i++) {
        let light = positive_light(i);
        let a = arriving(p, light);
        clamped += a.clamped;
        let cos_p = dot(n, a.to_light);
        e_s += a.rgb * max(0.0, cos_p);
        let behind = a.rgb * select(0.0, -cos_p, -cos_p > COPLANAR_COS);
        e_neg += behind;
        if (params.weight_mode == WEIGHT_ARRIVING) {
            dir += luminance(a.rgb) * light.normal.xyz;
        } else if (params.weight_mode == WEIGHT_PROPAGATION) {
            dir += luminance(behind) * -a.to_light;
        } else {
            dir += luminance(behind) * light.normal.xyz;
        }
    }
    t.e_s = vec4<f32>(e_s, clamped);
    t.e_neg = vec4<f32>(e_neg, 0.0);
    t.direction = vec4<f32>(dir, 0.0);
    return t;
}

fn negative_irradiance(point: SurfacePoint) -> vec3<f32> {
    if (point.position.w < 0.5) {
        return vec3<f32>(0.0);
    }
    let count = min(negative_state[0], params.negative_target);
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < count; i++) {
        let a = arriving(point.position.xyz, negatives_block[i]);
        e += a.rgb * max(0.0, dot(point.normal.xyz, a.to_light));
    }
    return e;
}

@compute @workgroup_size(8, 8, 1)
fn points_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.full_width || id.y >= params.full_height) {
        return;
    }
    let pixel = vec2<i32>(id.xy);
    var point: SurfacePoint;
    point.position = vec4<f32>(0.0);
    point.normal = vec4<f32>(0.0);
    if (textureLoad(gbuffer_specular, pixel, 0).a > 0.5) {
        let depth = textureLoad(gbuffer_depth, pixel, 0);
        let uv = (vec2<f32>(pixel) + 0.5) / vec2<f32>(f32(params.full_width), f32(params.full_height));
        let world = frame.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
        let p = world.xyz / world.w;
        point.position = vec4<f32>(p, 1.0);
        point.normal = vec4<f32>(normalize(textureLoad(gbuffer_normal, pixel, 0).xyz), length(p - params.eye.xyz));
    }
    points[full_index(id.xy)] = point;
}

@compute @workgroup_size(8, 8, 1)
fn downsample(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.low_width || id.y >= params.low_height) {
        return;
    }
    // The covered children's eye distances, sorted, give the median; the child nearest it
    // stands for the block (averaging would invent points on no surface).
    var d: array<f32, 4>;
    var idx: array<u32, 4>;
    var k = 0u;
    for (var j = 0u; j < 4u; j++) {
        let child = id.xy * 2u + vec2<u32>(j % 2u, j / 2u);
        if (child.x < params.full_width && child.y < params.full_height) {
            let p = points[full_index(child)];
            if (p.position.w > 0.5) {
                d[k] = p.normal.w;
                idx[k] = full_index(child);
                k += 1u;
            }
        }
    }
    var out: SurfacePoint;
    out.position = vec4<f32>(0.0);
    out.normal = vec4<f32>(0.0);
    if (k > 0u) {
        var sorted = d;
        for (var a = 1u; a < k; a++) {
            var b = a;
            while (b > 0u && sorted[b - 1u] > sorted[b]) {
                let tmp = sorted[b];
                sorted[b] = sorted[b - 1u];
                sorted[b - 1u] = tmp;
                b -= 1u;
            }
        }
        var median = sorted[k / 2u];
        if (k % 2u == 0u) {
            median = 0.5 * (sorted[k / 2u - 1u] + sorted[k / 2u]);
        }
        var best = 0u;
        var gap = 3.4e38;
        for (var j = 0u; j < k; j++) {
            if (abs(d[j] - median) < gap) {
                gap = abs(d[j] - median);
                best = j;
            }
        }
        out = points[idx[best]];
    }
    low_points[id.y * params.low_width + id.x] = out;
}

@compute @workgroup_size(8, 8, 1)
fn positive_low(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.low_width || id.y >= params.low_height) {
        return;
    }
    let i = id.y * params.low_width + id.x;
    low_terms[i] = positive_terms(low_points[i]);
}

var<workgroup> tile_flagged: atomic<u32>;
var<workgroup> tile_pixels: atomic<u32>;

// One workgroup per tile: flag it when any pixel is discontinuous from its parent.
@compute @workgroup_size(8, 8, 1)
fn classify(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    if (lid == 0u) {
        atomicStore(&tile_flagged, 0u);
        atomicStore(&tile_pixels, 0u);
    }
    workgroupBarrier();
    if (id.x < params.full_width && id.y < params.full_height) {
        atomicAdd(&tile_pixels, 1u);
        let p = points[full_index(id.xy)];
        let parent = low_points[parent_index(id.xy)];
        if (p.position.w > 0.5) {
            var broken = parent.position.w < 0.5;
            if (!broken) {
                let footprint = p.normal.w * params.footprint_scale;
                broken = length(p.position.xyz - parent.position.xyz) > params.threshold_pos * footprint
                    || dot(p.normal.xyz, parent.normal.xyz) < params.threshold_normal;
            }
            if (broken) {
                atomicOr(&tile_flagged, 1u);
            }
        }
    }
    workgroupBarrier();
    if (lid == 0u) {
        let tile = wid.y * params.tiles_x + wid.x;
        let flagged = atomicLoad(&tile_flagged);
        atomicStore(&tiles[tile_flag_slot(tile)], flagged);
        if (flagged != 0u) {
            let slot = atomicAdd(&tiles[0], 1u);
            atomicStore(&tiles[tile_list_slot(slot)], tile);
            atomicAdd(&tiles[3], atomicLoad(&tile_pixels));
        }
    }
}

// The pixel of this invocation in the flagged tile `wid.x` of the list.
fn patch_pixel(wid: vec3<u32>, lid: vec3<u32>) -> vec2<u32> {
    let tile = atomicLoad(&tiles[tile_list_slot(wid.x)]);
    return vec2<u32>(tile % params.tiles_x, tile / params.tiles_x) * TILE + lid.xy;
}

@compute @workgroup_size(8, 8, 1)
fn positive_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let pixel = patch_pixel(wid, lid);
    if (pixel.x >= params.full_width || pixel.y >= params.full_height) {
        return;
    }
    let i = full_index(pixel);
    full_terms[i] = positive_terms(points[i]);
}

@compute @workgroup_size(8, 8, 1)
fn positive_full(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.full_width || id.y >= params.full_height) {
        return;
    }
    let i = full_index(id.xy);
    full_terms[i] = positive_terms(points[i]);
}

var<workgroup> accepted: array<u32, SELECT_GROUP>;
var<workgroup> picked: array<u32, MAX_NEGATIVES>;
var<workgroup> picked_count: u32;
var<workgroup> tried: u32;

// One workgroup walks the Halton candidates 256 at a time; thread 0 keeps them in order, so
// the lights are the ones the CPU twin picks.
@compute @workgroup_size(256, 1, 1)
fn select_negatives(@builtin(local_invocation_index) lid: u32) {
    let target_count = min(params.negative_target, MAX_NEGATIVES);
    if (lid == 0u) {
        picked_count = 0u;
        tried = 0u;
    }
    workgroupBarrier();
    let chunks = (params.candidate_count + SELECT_GROUP - 1u) / SELECT_GROUP;
    for (var chunk = 0u; chunk < chunks; chunk++) {
        if (workgroupUniformLoad(&picked_count) >= target_count) {
            break;
        }
        let c = chunk * SELECT_GROUP + lid;
        var ok = 0u;
        if (c < params.candidate_count) {
            let pixel_index = candidates[c];
            let pixel = vec2<u32>(pixel_index % params.full_width, pixel_index / params.full_width);
            let t = terms_at(pixel);
            if (points[pixel_index].position.w > 0.5 && luminance(t.e_neg.rgb) > 0.0 && dot(t.direction.xyz, t.direction.xyz) > 0.0) {
                ok = 1u;
            }
        }
        accepted[lid] = ok;
        workgroupBarrier();
        if (lid == 0u) {
            for (var j = 0u; j < SELECT_GROUP; j++) {
                let c = chunk * SELECT_GROUP + j;
                if (c >= params.candidate_count || picked_count >= target_count) {
                    break;
                }
                tried = c + 1u;
                if (accepted[j] != 0u) {
                    picked[picked_count] = candidates[c];
                    picked_count += 1u;
                }
            }
        }
        workgroupBarrier();
    }
    let count = workgroupUniformLoad(&picked_count);
    let k = f32(max(workgroupUniformLoad(&tried), 1u));
    for (var m = lid; m < count; m += SELECT_GROUP) {
        let pixel_index = picked[m];
        let pixel = vec2<u32>(pixel_index % params.full_width, pixel_index / params.full_width);
        let point = points[pixel_index];
        let t = terms_at(pixel);
        let to_eye = point.position.xyz - params.eye.xyz;
        let area = params.omega_frustum / k * dot(to_eye, to_eye);
        var light: IndirectLight;
        light.position = vec4<f32>(point.position.xyz, 1.0);
        light.normal = vec4<f32>(normalize(t.direction.xyz), area / PI);
        light.flux = vec4<f32>(t.e_neg.rgb * area, 0.0);
        negatives[m] = light;
    }
    if (lid == 0u) {
        negative_state[0] = count;
        negative_state[1] = u32(k);
    }
}

@compute @workgroup_size(8, 8, 1)
fn negative_low(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.low_width || id.y >= params.low_height) {
        return;
    }
    let i = id.y * params.low_width + id.x;
    low_en[i] = vec4<f32>(negative_irradiance(low_points[i]), 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn negative_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let pixel = patch_pixel(wid, lid);
    if (pixel.x >= params.full_width || pixel.y >= params.full_height) {
        return;
    }
    let i = full_index(pixel);
    full_en[i] = vec4<f32>(negative_irradiance(points[i]), 0.0);
}

@compute @workgroup_size(8, 8, 1)
fn negative_full(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.full_width || id.y >= params.full_height) {
        return;
    }
    let i = full_index(id.xy);
    full_en[i] = vec4<f32>(negative_irradiance(points[i]), 0.0);
}

var<workgroup> partial: array<vec4<f32>, 64>;
var<workgroup> partial_n: array<vec2<f32>, 64>;

@compute @workgroup_size(8, 8, 1)
fn gather(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    var s = vec4<f32>(0.0);
    var yn = 0.0;
    var clamped_lights = 0.0;
    if (id.x < params.full_width && id.y < params.full_height) {
        let pixel = vec2<i32>(id.xy);
        var radiance = vec3<f32>(0.0);
        if (points[full_index(id.xy)].position.w > 0.5) {
            let rho = textureLoad(gbuffer_diffuse, pixel, 0).rgb / PI;
            let terms = terms_at(id.xy);
            let positive = rho * terms.e_s.rgb;
            clamped_lights = terms.e_s.w;
            var negative = vec3<f32>(0.0);
            if (params.negative_target > 0u) {
                negative = rho * en_at(id.xy);
            }
            let raw = positive - negative;
            radiance = max(raw, vec3<f32>(0.0));
            let removed = radiance - raw;
            s = vec4<f32>(select(0.0, 1.0, any(raw < vec3<f32>(0.0))), luminance(removed), luminance(positive), 1.0);
            yn = luminance(negative);
        }
        textureStore(radiance_indirect, pixel, vec4<f32>(radiance, 1.0));
    }
    partial[lid] = s;
    partial_n[lid] = vec2<f32>(yn, clamped_lights);
    workgroupBarrier();
    if (lid == 0u) {
        var sum = vec4<f32>(0.0);
        var sum_n = vec2<f32>(0.0);
        for (var i = 0u; i < 64u; i++) {
            sum += partial[i];
            sum_n += partial_n[i];
        }
        let slot = (wid.y * groups.x + wid.x) * 2u;
        stats[slot] = sum;
        stats[slot + 1u] = vec4<f32>(sum_n, 0.0, 0.0);
    }
}
