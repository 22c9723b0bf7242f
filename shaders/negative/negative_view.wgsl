// The per-view passes of second-order illumination with negative indirect lights (§A.3–A.8):
//
//   points_main       S_cam: world position, normal and eye distance of every pixel (low
//                     resolution off)
//   points_blocks     low resolution on: S_cam; S_locam, per 2×2 block the covered pixel
//                     nearest the block's median depth; and per 8×8 tile whether any pixel
//                     differs from its low-resolution parent by more than the discontinuity
//                     threshold. Flagged tiles are appended to a list whose length becomes
//                     the indirect dispatch of the patch passes
//   positive_low      E_s, E_neg and the weighted direction at every low-resolution point
//   positive_tiles    the same terms at full resolution in the flagged tiles (indirect)
//   positive_full     the same terms at every pixel (low resolution off)
//   select_negatives  M negative lights from the Halton camera candidates
//   negative_low / negative_tiles / negative_full   E_n from the negative lights, likewise
//   gather            ρ_d/π·max(0, E_s − E_n) into the view's indirect radiance, with the
//                     clamp's statistics per 8×8 tile
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
// device (Mesa's llvmpipe) reads a uniform block with one gathered load per value where it
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

// The variants of the light sums, fixed per pipeline (`NegativeMethod::new`), so that the
// loops over the lights carry no branch on them: llvmpipe runs every uniform branch inside a
// loop under a mask (bunny-box 640×480, N = 100: the positive pass 26.5 → 21.4 ms).
// WEIGHT_LITERAL, WEIGHT_ARRIVING or WEIGHT_PROPAGATION (§A.4).
override WEIGHT_MODE: u32 = 0u;
// false: 1/max(d², d²_min) (point lights); true: 1/(d² + r²) (each light the disc it stands for).
override DISC_FALLOFF: bool = false;

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

// The pixel's own terms where `full` (`has_full_terms`), its parent's otherwise.
fn terms_of(pixel: vec2<u32>, full: bool) -> PositiveTerms {
    if (full) {
        return full_terms[full_index(pixel)];
    }
    return low_terms[parent_index(pixel)];
}

fn terms_at(pixel: vec2<u32>) -> PositiveTerms {
    return terms_of(pixel, has_full_terms(pixel));
}

fn en_of(pixel: vec2<u32>, full: bool) -> vec3<f32> {
    if (full) {
        return full_en[full_index(pixel)].rgb;
    }
    return low_en[parent_index(pixel)].rgb;
}

// A Lambertian point light seen from p, per unit Φ/π, with the cosines left unnormalized:
// `d` = x_l − p, `emit` = max(0, −n_l·d)/(|d|²·D) with D = max(d², d²_min) (or d² + r² with
// the disc falloff), so that for a receiver normal n the arriving irradiance is
// Φ/π·emit·max(0, n·d) = Φ/π·max(0, n_l·t̂_{l→p})·max(0, n·t̂_{p→l})/D. Zero for an inactive
// light or one at p. One division a pair and no square root: on a CPU device (Mesa's
// llvmpipe) each is a slow vector instruction, and the normalized form took two divisions and
// a square root. The flux is applied by the caller, once per light for all its points.
struct Emitter {
    emit: f32,
    d: vec3<f32>,
    d2: f32,
    // 1 when the point falloff's d²_min guard replaced d².
    clamped: f32,
}

fn emitter(p: vec3<f32>, light: IndirectLight) -> Emitter {
    var out: Emitter;
    out.d = light.position.xyz - p;
    out.d2 = dot(out.d, out.d);
    var denominator = max(out.d2, params.d2_min);
    if (DISC_FALLOFF) {
        denominator = out.d2 + light.normal.w;
    }
    // |d|²·D > 0 also drops a light so near that the product underflows (|d| ≲ 1e-16 m), as
    // d² = 0 is dropped: its direction is not defined.
    let scale = out.d2 * denominator;
    let lit = light.position.w >= 0.5 && scale > 0.0;
    out.clamped = select(0.0, 1.0, lit && out.d2 < params.d2_min && !DISC_FALLOFF);
    let cos_l = max(0.0, -dot(light.normal.xyz, out.d));
    out.emit = select(0.0, cos_l / scale, lit);
    return out;
}

// Whether a light at `d` from a point of normal n lies behind its tangent plane by more than
// COPLANAR_COS: −n·t̂ > c, i.e. n·d < 0 and (n·d)² > c²·|d|², without the square root.
fn behind_plane(n_dot_d: f32, d2: f32) -> bool {
    return n_dot_d < 0.0 && n_dot_d * n_dot_d > COPLANAR_COS * COPLANAR_COS * d2;
}

// The light loops take a column of four pixels per invocation (pixel k of invocation (x, y)
// is (x, 4y + k)), so that each light, read once, serves four pixels: a CPU device (Mesa's
// llvmpipe) reads a uniform block at a loop-varying index with one gathered load per float,
// which was three quarters of the loops' time with one pixel per invocation (bunny-box
// 640×480 on lavapipe, N = 100: src/negative/README.md, "Four pixels per invocation").
const COLUMN: u32 = 4u;

struct PositiveSums {
    e_s: vec3<f32>,
    e_neg: vec3<f32>,
    direction: vec3<f32>,
    clamped: f32,
}

// One positive light's share of E_s, E_neg and D at `point` (flux_over_pi = Φ/π, y its
// luminance).
fn add_positive(sums: ptr<function, PositiveSums>, point: SurfacePoint, light: IndirectLight, flux_over_pi: vec3<f32>, y: f32) {
    let a = emitter(point.position.xyz, light);
    (*sums).clamped += a.clamped;
    let n_dot_d = dot(point.normal.xyz, a.d);
    (*sums).e_s += flux_over_pi * (a.emit * max(0.0, n_dot_d));
    // The share arriving from behind the tangent plane, per unit Φ/π.
    let behind = a.emit * select(0.0, -n_dot_d, behind_plane(n_dot_d, a.d2));
    (*sums).e_neg += flux_over_pi * behind;
    // Y(Φ/π·x) = Y(Φ/π)·x: the weights are luminances of the sums' terms.
    if (WEIGHT_MODE == WEIGHT_ARRIVING) {
        // The arriving intensity without the receiver's cosine: emit·|d|.
        (*sums).direction += (y * a.emit * sqrt(a.d2)) * light.normal.xyz;
    } else if (WEIGHT_MODE == WEIGHT_PROPAGATION) {
        // −t̂_{p→l} = −d/|d| (behind is 0 where d is).
        (*sums).direction += (y * behind * select(0.0, 1.0 / sqrt(a.d2), a.d2 > 0.0)) * -a.d;
    } else {
        (*sums).direction += (y * behind) * light.normal.xyz;
    }
}

fn positive_result(point: SurfacePoint, sums: PositiveSums) -> PositiveTerms {
    var t: PositiveTerms;
    t.e_s = vec4<f32>(0.0);
    t.e_neg = vec4<f32>(0.0);
    t.direction = vec4<f32>(0.0);
    if (point.position.w > 0.5) {
        t.e_s = vec4<f32>(sums.e_s, sums.clamped);
        t.e_neg = vec4<f32>(sums.e_neg, 0.0);
        t.direction = vec4<f32>(sums.direction, 0.0);
    }
    return t;
}

// E_s, E_neg and D at four points (zero where a point is uncovered).
fn positive_terms(q: array<SurfacePoint, COLUMN>) -> array<PositiveTerms, COLUMN> {
    var s0: PositiveSums;
    var s1: PositiveSums;
    var s2: PositiveSums;
    var s3: PositiveSums;
    for (var i = 0u; i < params.positive_count; i++) {
        let light = positive_light(i);
        let flux_over_pi = light.flux.rgb * (1.0 / PI);
        let y = luminance(flux_over_pi);
        add_positive(&s0, q[0], light, flux_over_pi, y);
        add_positive(&s1, q[1], light, flux_over_pi, y);
        add_positive(&s2, q[2], light, flux_over_pi, y);
        add_positive(&s3, q[3], light, flux_over_pi, y);
    }
    return array<PositiveTerms, COLUMN>(
        positive_result(q[0], s0),
        positive_result(q[1], s1),
        positive_result(q[2], s2),
        positive_result(q[3], s3),
    );
}

fn add_negative(e: ptr<function, vec3<f32>>, point: SurfacePoint, light: IndirectLight, flux_over_pi: vec3<f32>) {
    let a = emitter(point.position.xyz, light);
    *e += flux_over_pi * (a.emit * max(0.0, dot(point.normal.xyz, a.d)));
}

// E_n at four points (zero where a point is uncovered), as vec4 (rgb, 0).
fn negative_irradiance(q: array<SurfacePoint, COLUMN>) -> array<vec4<f32>, COLUMN> {
    let count = min(negative_state[0], params.negative_target);
    var e0 = vec3<f32>(0.0);
    var e1 = vec3<f32>(0.0);
    var e2 = vec3<f32>(0.0);
    var e3 = vec3<f32>(0.0);
    for (var i = 0u; i < count; i++) {
        let light = negatives_block[i];
        let flux_over_pi = light.flux.rgb * (1.0 / PI);
        add_negative(&e0, q[0], light, flux_over_pi);
        add_negative(&e1, q[1], light, flux_over_pi);
        add_negative(&e2, q[2], light, flux_over_pi);
        add_negative(&e3, q[3], light, flux_over_pi);
    }
    let zero = vec3<f32>(0.0);
    return array<vec4<f32>, COLUMN>(
        vec4<f32>(select(zero, e0, q[0].position.w > 0.5), 0.0),
        vec4<f32>(select(zero, e1, q[1].position.w > 0.5), 0.0),
        vec4<f32>(select(zero, e2, q[2].position.w > 0.5), 0.0),
        vec4<f32>(select(zero, e3, q[3].position.w > 0.5), 0.0),
    );
}

fn inside(pixel: vec2<u32>, size: vec2<u32>) -> bool {
    return pixel.x < size.x && pixel.y < size.y;
}

fn low_size() -> vec2<u32> {
    return vec2<u32>(params.low_width, params.low_height);
}

fn full_size() -> vec2<u32> {
    return vec2<u32>(params.full_width, params.full_height);
}

// The column of four low-resolution points from `first` down (uncovered past the image).
fn low_column(first: vec2<u32>) -> array<SurfacePoint, COLUMN> {
    var q: array<SurfacePoint, COLUMN>;
    for (var k = 0u; k < COLUMN; k++) {
        let pixel = first + vec2<u32>(0u, k);
        if (inside(pixel, low_size())) {
            q[k] = low_points[pixel.y * params.low_width + pixel.x];
        }
    }
    return q;
}

// The column of four full-resolution points from `first` down (uncovered past the image).
fn full_column(first: vec2<u32>) -> array<SurfacePoint, COLUMN> {
    var q: array<SurfacePoint, COLUMN>;
    for (var k = 0u; k < COLUMN; k++) {
        let pixel = first + vec2<u32>(0u, k);
        if (inside(pixel, full_size())) {
            q[k] = points[full_index(pixel)];
        }
    }
    return q;
}

// S_cam at one pixel from the G-buffer: world position, normal and eye distance (all zero
// where no surface covers it).
fn surface_point(pixel: vec2<u32>) -> SurfacePoint {
    var point: SurfacePoint;
    point.position = vec4<f32>(0.0);
    point.normal = vec4<f32>(0.0);
    let texel = vec2<i32>(pixel);
    if (textureLoad(gbuffer_specular, texel, 0).a > 0.5) {
        let depth = textureLoad(gbuffer_depth, texel, 0);
        let uv = (vec2<f32>(pixel) + 0.5) / vec2<f32>(f32(params.full_width), f32(params.full_height));
        let world = frame.world_from_clip * vec4<f32>(uv.x * 2.0 - 1.0, 1.0 - uv.y * 2.0, depth, 1.0);
        let p = world.xyz / world.w;
        point.position = vec4<f32>(p, 1.0);
        point.normal = vec4<f32>(normalize(textureLoad(gbuffer_normal, texel, 0).xyz), length(p - params.eye.xyz));
    }
    return point;
}

// S_cam at every pixel, for the passes at full resolution (low resolution off).
@compute @workgroup_size(8, 8, 1)
fn points_main(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.full_width || id.y >= params.full_height) {
        return;
    }
    points[full_index(id.xy)] = surface_point(id.xy);
}

// S_locam (§A.7): of a 2×2 block's covered children, the index of the one whose eye distance
// is nearest the block's median (4 when none is covered); the median of the covered
// distances, and not their average, since an average would invent a point on no surface.
// A sorting network with the uncovered children at +∞ and selects instead of a sort's loops:
// llvmpipe runs a data-dependent loop under a mask until every lane is done.
fn block_representative(children: array<SurfacePoint, 4>) -> u32 {
    var d: array<f32, 4>;
    var k = 0u;
    for (var j = 0u; j < 4u; j++) {
        let covered = children[j].position.w > 0.5;
        d[j] = select(3.4e38, children[j].normal.w, covered);
        k += select(0u, 1u, covered);
    }
    if (k == 0u) {
        return 4u;
    }
    // Sorted ascending: the k covered distances first.
    let a0 = min(d[0], d[1]);
    let a1 = max(d[0], d[1]);
    let a2 = min(d[2], d[3]);
    let a3 = max(d[2], d[3]);
    let s0 = min(a0, a2);
    let b2 = max(a0, a2);
    let b1 = min(a1, a3);
    let s3 = max(a1, a3);
    let s1 = min(b1, b2);
    let s2 = max(b1, b2);
    // k = 1: s0; 2: (s0 + s1)/2; 3: s1; 4: (s1 + s2)/2.
    var median = s0;
    if (k == 2u) {
        median = 0.5 * (s0 + s1);
    } else if (k == 3u) {
        median = s1;
    } else if (k == 4u) {
        median = 0.5 * (s1 + s2);
    }
    var best = 4u;
    var gap = 3.4e38;
    for (var j = 0u; j < 4u; j++) {
        let g = abs(d[j] - median);
        if (children[j].position.w > 0.5 && g < gap) {
            gap = g;
            best = j;
        }
    }
    return best;
}

// The discontinuity test (§A.7): a covered pixel is recomputed at full resolution when its
// parent is uncovered, lies more than τ_x pixel footprints away or turns its normal past τ_n.
fn discontinuous(p: SurfacePoint, parent: SurfacePoint) -> bool {
    if (p.position.w < 0.5) {
        return false;
    }
    if (parent.position.w < 0.5) {
        return true;
    }
    let footprint = p.normal.w * params.footprint_scale;
    return length(p.position.xyz - parent.position.xyz) > params.threshold_pos * footprint
        || dot(p.normal.xyz, parent.normal.xyz) < params.threshold_normal;
}

// The 2 × 2 tiles of a `points_blocks` workgroup: whether any pixel is discontinuous.
var<workgroup> tile_flagged: array<atomic<u32>, 4>;

// With low resolution on, one invocation per 2×2 block and one workgroup per 2 × 2 tiles of
// 8×8 pixels: S_cam of the block's four pixels, their representative S_locam, and each tile's
// flag (any pixel discontinuous from its parent), the flagged tiles appended to the list whose
// length becomes the indirect dispatch of the patch passes. One pass rather than three
// (points, downsample, classify) reads the G-buffer once and S_cam not at all.
@compute @workgroup_size(8, 8, 1)
fn points_blocks(@builtin(global_invocation_id) id: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(local_invocation_index) lindex: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    if (lindex < 4u) {
        atomicStore(&tile_flagged[lindex], 0u);
    }
    workgroupBarrier();
    if (inside(id.xy, low_size())) {
        var children: array<SurfacePoint, 4>;
        for (var j = 0u; j < 4u; j++) {
            let child = id.xy * 2u + vec2<u32>(j % 2u, j / 2u);
            if (inside(child, full_size())) {
                children[j] = surface_point(child);
                points[full_index(child)] = children[j];
            }
        }
        let best = block_representative(children);
        var parent: SurfacePoint;
        var broken = false;
        for (var j = 0u; j < 4u; j++) {
            if (j == best) {
                parent = children[j];
            }
        }
        for (var j = 0u; j < 4u; j++) {
            broken = broken || discontinuous(children[j], parent);
        }
        low_points[id.y * params.low_width + id.x] = parent;
        if (broken) {
            let local_tile = lid.x / 4u + 2u * (lid.y / 4u);
            atomicOr(&tile_flagged[local_tile], 1u);
        }
    }
    workgroupBarrier();
    if (lindex < 4u) {
        let tile_xy = wid.xy * 2u + vec2<u32>(lindex % 2u, lindex / 2u);
        let origin = tile_xy * TILE;
        if (inside(origin, full_size())) {
            let tile = tile_xy.y * params.tiles_x + tile_xy.x;
            let flagged = atomicLoad(&tile_flagged[lindex]);
            atomicStore(&tiles[tile_flag_slot(tile)], flagged);
            if (flagged != 0u) {
                let slot = atomicAdd(&tiles[0], 1u);
                atomicStore(&tiles[tile_list_slot(slot)], tile);
                // The tile's pixels inside the image, counted here rather than by an atomic
                // add in every invocation (which llvmpipe runs lane by lane).
                let size = min(vec2<u32>(TILE), full_size() - origin);
                atomicAdd(&tiles[3], size.x * size.y);
            }
        }
    }
}

@compute @workgroup_size(8, 8, 1)
fn positive_low(@builtin(global_invocation_id) id: vec3<u32>) {
    let first = vec2<u32>(id.x, id.y * COLUMN);
    let t = positive_terms(low_column(first));
    for (var k = 0u; k < COLUMN; k++) {
        let pixel = first + vec2<u32>(0u, k);
        if (inside(pixel, low_size())) {
            low_terms[pixel.y * params.low_width + pixel.x] = t[k];
        }
    }
}

// The first pixel of this invocation's column in the flagged tile `wid.x` of the list (a
// workgroup of 8 × 2 columns covers the 8 × 8 tile).
fn patch_column(wid: vec3<u32>, lid: vec3<u32>) -> vec2<u32> {
    let tile = atomicLoad(&tiles[tile_list_slot(wid.x)]);
    return vec2<u32>(tile % params.tiles_x, tile / params.tiles_x) * TILE + vec2<u32>(lid.x, lid.y * COLUMN);
}

fn store_full_terms(first: vec2<u32>, t: array<PositiveTerms, COLUMN>) {
    for (var k = 0u; k < COLUMN; k++) {
        let pixel = first + vec2<u32>(0u, k);
        if (inside(pixel, full_size())) {
            full_terms[full_index(pixel)] = t[k];
        }
    }
}

@compute @workgroup_size(8, 2, 1)
fn positive_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let first = patch_column(wid, lid);
    store_full_terms(first, positive_terms(full_column(first)));
}

@compute @workgroup_size(8, 8, 1)
fn positive_full(@builtin(global_invocation_id) id: vec3<u32>) {
    let first = vec2<u32>(id.x, id.y * COLUMN);
    store_full_terms(first, positive_terms(full_column(first)));
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
    let first = vec2<u32>(id.x, id.y * COLUMN);
    let e = negative_irradiance(low_column(first));
    for (var k = 0u; k < COLUMN; k++) {
        let pixel = first + vec2<u32>(0u, k);
        if (inside(pixel, low_size())) {
            low_en[pixel.y * params.low_width + pixel.x] = e[k];
        }
    }
}

fn store_full_en(first: vec2<u32>, e: array<vec4<f32>, COLUMN>) {
    for (var k = 0u; k < COLUMN; k++) {
        let pixel = first + vec2<u32>(0u, k);
        if (inside(pixel, full_size())) {
            full_en[full_index(pixel)] = e[k];
        }
    }
}

@compute @workgroup_size(8, 2, 1)
fn negative_tiles(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let first = patch_column(wid, lid);
    store_full_en(first, negative_irradiance(full_column(first)));
}

@compute @workgroup_size(8, 8, 1)
fn negative_full(@builtin(global_invocation_id) id: vec3<u32>) {
    let first = vec2<u32>(id.x, id.y * COLUMN);
    store_full_en(first, negative_irradiance(full_column(first)));
}

// The clamp's statistics of one pixel: (clamped, Y removed by the clamp, Y of ρ/π·E_s,
// covered) and (Y of ρ/π·E_n, positive lights that hit the d²_min guard).
struct PixelStats {
    s: vec4<f32>,
    n: vec2<f32>,
}

// One pixel of the gather: its indirect radiance stored, its statistics returned. `full`:
// whether its tile has terms of its own (`has_full_terms`, read once per tile).
fn gather_pixel(pixel: vec2<u32>, full: bool) -> PixelStats {
    var out: PixelStats;
    out.s = vec4<f32>(0.0);
    out.n = vec2<f32>(0.0);
    if (!inside(pixel, full_size())) {
        return out;
    }
    var radiance = vec3<f32>(0.0);
    if (points[full_index(pixel)].position.w > 0.5) {
        let rho = textureLoad(gbuffer_diffuse, vec2<i32>(pixel), 0).rgb / PI;
        let terms = terms_of(pixel, full);
        let positive = rho * terms.e_s.rgb;
        var negative = vec3<f32>(0.0);
        if (params.negative_target > 0u) {
            negative = rho * en_of(pixel, full);
        }
        let raw = positive - negative;
        radiance = max(raw, vec3<f32>(0.0));
        let removed = radiance - raw;
        out.s = vec4<f32>(select(0.0, 1.0, any(raw < vec3<f32>(0.0))), luminance(removed), luminance(positive), 1.0);
        out.n = vec2<f32>(luminance(negative), terms.e_s.w);
    }
    textureStore(radiance_indirect, vec2<i32>(pixel), vec4<f32>(radiance, 1.0));
    return out;
}

// A column of four pixels per invocation, 8 × 2 invocations per 8 × 8 tile, so that the
// statistics' workgroup reduction sums 16 entries, not 64: llvmpipe reads workgroup memory
// lane by lane and runs a barrier per SIMD row (640×480: the pass 9.6–10.2 → 7.3–7.4 ms).
var<workgroup> partial: array<vec4<f32>, 16>;
var<workgroup> partial_n: array<vec2<f32>, 16>;

@compute @workgroup_size(8, 2, 1)
fn gather(@builtin(local_invocation_id) lid3: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let first = wid.xy * TILE + vec2<u32>(lid3.x, lid3.y * COLUMN);
    // The workgroup is one tile: its flag is read once, not per pixel (an atomic load, which
    // llvmpipe runs lane by lane).
    let full = has_full_terms(wid.xy * TILE);
    var s = vec4<f32>(0.0);
    var n = vec2<f32>(0.0);
    for (var k = 0u; k < COLUMN; k++) {
        let p = gather_pixel(first + vec2<u32>(0u, k), full);
        s += p.s;
        n += p.n;
    }
    partial[lid] = s;
    partial_n[lid] = n;
    workgroupBarrier();
    if (lid == 0u) {
        var sum = vec4<f32>(0.0);
        var sum_n = vec2<f32>(0.0);
        for (var i = 0u; i < 16u; i++) {
            sum += partial[i];
            sum_n += partial_n[i];
        }
        let slot = (wid.y * groups.x + wid.x) * 2u;
        stats[slot] = sum;
        stats[slot + 1u] = vec4<f32>(sum_n, 0.0, 0.0);
    }
}
