// Step 1 — gather: every VAL at every sparse point. Each workgroup takes 64 invocations × 4
// points; the VAL list streams through workgroup memory `tile` records at a time, so every VAL
// is fetched from the buffer once per workgroup and read from workgroup memory once per
// invocation, not once per point. Writes the irradiance sums (in the slots the
// renormalized intensities later take), the averaged positions as f16 offsets from the point,
// and the occlusion spheres.
#include "vals_common.wgsl"

const GROUP: u32 = 64u;
const TILE_MAX: u32 = 256u;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read> vals: array<Val>;
@group(0) @binding(5) var<storage, read> val_count: array<u32>;
@group(0) @binding(6) var<storage, read_write> point_diffuse: array<vec4<u32>>;
@group(0) @binding(7) var<storage, read_write> point_glossy: array<vec4<u32>>;
@group(0) @binding(8) var<storage, read_write> point_extra: array<vec2<u32>>;
// With FLAG_VISIBILITY: per point, the VAL clusters' visibility V·255, four per word.
@group(0) @binding(9) var<storage, read> visibility: array<u32>;

const VISIBILITY_WORDS: u32 = 8u;

var<workgroup> tile_vals: array<Val, TILE_MAX>;
var<workgroup> shared_count: u32;

// Weighted moments Σw, Σw·l, Σw·l² of the VAL positions.
struct Moments {
    weight: f32,
    sum: vec3<f32>,
    sum_squares: vec3<f32>,
}

// Mean position (xyz) and sphere radius 2·max σ (w).
fn moments_mean_sphere(m: Moments) -> vec4<f32> {
    if (m.weight <= 0.0) {
        return vec4<f32>(0.0);
    }
    let mean = m.sum / m.weight;
    let variance = max(m.sum_squares / m.weight - mean * mean, vec3<f32>(0.0));
    return vec4<f32>(mean, 2.0 * sqrt(max(variance.x, max(variance.y, variance.z))));
}

// The running sums of one point.
struct Sums {
    diffuse: vec3<f32>,
    glossy: vec3<f32>,
    md: Moments,
    ms: Moments,
}

// Points per invocation: every VAL read from workgroup memory is used for this many points
// (register blocking), which on a CPU device halves the loads per pair at 2 and quarters them
// at 4. `GATHER_POINTS_PER_INVOCATION` in `src/vals/sparse.rs` sizes the dispatch.
const POINTS_PER_INVOCATION: u32 = 4u;

// This invocation's points' cluster visibility words (all 255s without FLAG_VISIBILITY).
var<private> point_visibility: array<u32, VISIBILITY_WORDS * POINTS_PER_INVOCATION>;

// V of the VAL's cluster (`flux.w`) at this invocation's point `slot`.
// VALs outside every cluster (appended external ones, w = 32) are not scaled.
fn val_visibility(val: Val, slot: u32) -> f32 {
    let cluster = u32(val.flux.w);
    if (cluster >= VISIBILITY_WORDS * 4u) {
        return 1.0;
    }
    let word = point_visibility[slot * VISIBILITY_WORDS + cluster / 4u];
    return f32((word >> (8u * (cluster % 4u))) & 255u) / 255.0;
}

// Adds one VAL's contribution at the point (x, n, k) with mirror direction r, scaled by its
// cluster's visibility there.
fn accumulate(sums: ptr<function, Sums>, point: WorldPoint, r: vec3<f32>, val: Val, slot: u32, glossy_on: bool, flux_weights: bool, use_visibility: bool) {
    let gw = disc_geometry(point.position, point.normal, val);
    var g = gw.x;
    if (use_visibility) {
        g *= val_visibility(val, slot);
    }
    let e = val.flux.rgb * (g / PI);
    var strength = val.position_area.w * g;
    if (flux_weights) {
        strength = (val.flux.r + val.flux.g + val.flux.b) / 3.0 * g;
    }
    let l = val.position_area.xyz;
    let wd = POSITION_EPSILON + strength;
    (*sums).diffuse += e;
    (*sums).md.weight += wd;
    (*sums).md.sum += wd * l;
    (*sums).md.sum_squares += wd * l * l;
    if (glossy_on) {
        var lobe_j = 0.0;
        if (g > 0.0) {
            lobe_j = lobe(r, gw.yzw, point.k);
        }
        let ws = POSITION_EPSILON + strength * lobe_j;
        (*sums).glossy += e * lobe_j;
        (*sums).ms.weight += ws;
        (*sums).ms.sum += ws * l;
        (*sums).ms.sum_squares += ws * l * l;
    }
}

// This invocation's points, their mirror directions and running sums. Indexed only by
// constants (`accumulate_all` is written out), so they stay in registers.
var<private> points: array<WorldPoint, POINTS_PER_INVOCATION>;
var<private> mirrors: array<vec3<f32>, POINTS_PER_INVOCATION>;
var<private> all_sums: array<Sums, POINTS_PER_INVOCATION>;

// One VAL at each of this invocation's points. Written out, not a loop: llvmpipe counts every
// loop iteration against its per-invocation limit (see the VAL loop below).
fn accumulate_all(val: Val, glossy_on: bool, flux_weights: bool, use_visibility: bool) {
    var s0 = all_sums[0];
    var s1 = all_sums[1];
    var s2 = all_sums[2];
    var s3 = all_sums[3];
    accumulate(&s0, points[0], mirrors[0], val, 0u, glossy_on, flux_weights, use_visibility);
    accumulate(&s1, points[1], mirrors[1], val, 1u, glossy_on, flux_weights, use_visibility);
    accumulate(&s2, points[2], mirrors[2], val, 2u, glossy_on, flux_weights, use_visibility);
    accumulate(&s3, points[3], mirrors[3], val, 3u, glossy_on, flux_weights, use_visibility);
    all_sums[0] = s0;
    all_sums[1] = s1;
    all_sums[2] = s2;
    all_sums[3] = s3;
}

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    if (lid == 0u) {
        shared_count = min(val_count[0], arrayLength(&vals));
    }
    let count = workgroupUniformLoad(&shared_count);
    let tile = clamp(params.tile, 1u, TILE_MAX);
    // The workgroup's GROUP · POINTS_PER_INVOCATION points, strided by GROUP so that the
    // invocations of a SIMD row read neighbouring points.
    let first = (linear_index(gid, groups) / GROUP) * GROUP * POINTS_PER_INVOCATION + lid;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let flux_weights = (params.flags & FLAG_FLUX_WEIGHTS) != 0u;
    let use_visibility = (params.flags & FLAG_VISIBILITY) != 0u;

    // Written out, not a loop, so that the per-slot arrays are indexed by constants only.
    var any_active = load_slot(0u, first, use_visibility);
    any_active = load_slot(1u, first, use_visibility) || any_active;
    any_active = load_slot(2u, first, use_visibility) || any_active;
    any_active = load_slot(3u, first, use_visibility) || any_active;

    for (var base = 0u; base < count; base += tile) {
        let m = min(tile, count - base);
        for (var i = lid; i < m; i += GROUP) {
            tile_vals[i] = vals[base + i];
        }
        workgroupBarrier();
        if (any_active) {
            // Unrolled by 16 not only for speed: Mesa's llvmpipe ends any loop after 65535
            // iterations per invocation (counted across re-entries), so a plain loop over
            // every VAL would silently stop at 65535 VALs there. Written out, not a nested
            // loop, which would count the same. This way it reaches 1M VALs.
            var j = 0u;
            let full = m - m % 16u;
            while (j < full) {
                accumulate_all(tile_vals[j + 0u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 1u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 2u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 3u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 4u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 5u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 6u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 7u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 8u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 9u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 10u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 11u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 12u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 13u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 14u], glossy_on, flux_weights, use_visibility);
                accumulate_all(tile_vals[j + 15u], glossy_on, flux_weights, use_visibility);
                j += 16u;
            }
            while (j < m) {
                accumulate_all(tile_vals[j], glossy_on, flux_weights, use_visibility);
                j += 1u;
            }
        }
        workgroupBarrier();
    }
    write_slot(0u, first, count, glossy_on);
    write_slot(1u, first, count, glossy_on);
    write_slot(2u, first, count, glossy_on);
    write_slot(3u, first, count, glossy_on);
}

// Slot q's point (`first + q·GROUP`), its visibility words, mirror direction and cleared sums;
// false when the slot is past the last point (it then gathers at a harmless placeholder and
// is never written).
fn load_slot(q: u32, first: u32, use_visibility: bool) -> bool {
    let index = first + q * GROUP;
    let is_active = index < params.point_count;
    for (var w = 0u; w < VISIBILITY_WORDS; w++) {
        point_visibility[q * VISIBILITY_WORDS + w] = 0xffffffffu;
        if (use_visibility && is_active) {
            point_visibility[q * VISIBILITY_WORDS + w] = visibility[index * VISIBILITY_WORDS + w];
        }
    }
    var point: WorldPoint;
    point.normal = vec3<f32>(0.0, 0.0, 1.0);
    var r = vec3<f32>(0.0, 0.0, 1.0);
    if (is_active) {
        let point_meta = points_meta[index];
        point = world_point(points_model[index], point_meta, instances[point_meta.y]);
        let wo = normalize(params.eye.xyz - point.position);
        r = reflect(-wo, point.normal);
    }
    points[q] = point;
    mirrors[q] = r;
    all_sums[q] = Sums();
    return is_active;
}

fn write_slot(q: u32, first: u32, count: u32, glossy_on: bool) {
    let index = first + q * GROUP;
    if (index < params.point_count) {
        write_point(index, points[q], all_sums[q], count, glossy_on);
    }
}

// The point's gathered sums into its slots: irradiance sums, mean positions as f16 offsets
// from the point, occlusion spheres.
fn write_point(index: u32, point: WorldPoint, sums: Sums, count: u32, glossy_on: bool) {
    let d = moments_mean_sphere(sums.md);
    var s = vec4<f32>(point.position, 0.0);
    if (glossy_on) {
        s = moments_mean_sphere(sums.ms);
    }
    // With no VAL at all the means are undefined: keep the lights on the point, dark.
    var off_d = d.xyz - point.position;
    var off_s = s.xyz - point.position;
    if (count == 0u) {
        off_d = vec3<f32>(0.0);
        off_s = vec3<f32>(0.0);
    }
    point_glossy[index] = vec4<u32>(rgb_bits(sums.glossy), pack2x16float(off_s.xy));
    if ((params.flags & FLAG_GLOSSY_ONLY) != 0u) {
        // Keep the diffuse halves of the shared words as the frame's update wrote them.
        let extra = point_extra[index];
        let z = unpack2x16float(extra.x);
        let spheres = unpack2x16float(extra.y);
        point_extra[index] = vec2<u32>(pack2x16float(vec2<f32>(z.x, off_s.z)), pack2x16float(vec2<f32>(spheres.x, s.w)));
        return;
    }
    point_diffuse[index] = vec4<u32>(rgb_bits(sums.diffuse), pack2x16float(off_d.xy));
    point_extra[index] = vec2<u32>(pack2x16float(vec2<f32>(off_d.z, off_s.z)), pack2x16float(vec2<f32>(d.w, s.w)));
}
