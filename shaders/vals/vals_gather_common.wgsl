// The gather's shared half (`vals_gather.wgsl` in a compute pass, `vals_gather_raster.wgsl`
// in a fragment pass over a point target, the paper's form): the bindings, the running sums
// of one point, one VAL's contribution to them, and the sums written into the point's slots.
// An invocation gathers for up to POINT_SLOTS points (the compute form uses all of them, the
// fragment form one).
#include "vals_common.wgsl"

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

// False in the diffuse-only pipeline (`SparsePipelines::gather_diffuse`), which then has no
// glossy code at all: the uniform FLAG_GLOSSY alone leaves it in, and a CPU device (llvmpipe
// runs both sides of every branch under a mask) paid for the lobes with the flag off.
override GLOSSY_GATHER: bool = true;
// False in a pipeline for a solution without `--occlusion rays`: the cluster visibility
// lookup, per VAL, then goes too (a quarter of a diffuse gather's time on lavapipe).
override GATHER_VISIBILITY: bool = true;
// False in a pipeline for a solution without the disc occlusion (`sum`, `union`): the second
// position moments, which only size its light spheres, then go (3 of a diffuse pair's 32
// operations, and state that no longer spills: `+rays` 196–203 → 174–176 ms on lavapipe,
// 16k VALs × 4k points). Whatever the build, the spheres are written only for those modes
// (`params.occlusion_mode`), so every form of the gather writes the same slots.
override GATHER_SPHERES: bool = true;
// Room for the compute form's GATHER_SLOTS (at most 16; `vals_gather.wgsl`).
const POINT_SLOTS: u32 = 16u;

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

// Visibility V of a VAL's cluster (`flux.w`) at a point, from the point's cluster words (V·255,
// four clusters per word): `word` is the one holding the cluster. VALs outside every cluster
// (appended external ones, w = 32) are not scaled. Each form keeps its points' words where
// it reads them fastest (see each).
fn cluster_visibility(cluster: u32, word: u32) -> f32 {
    let v = f32((word >> (8u * (cluster % 4u))) & 255u) * (1.0 / 255.0);
    return select(v, 1.0, cluster >= VISIBILITY_WORDS * 4u);
}

// The cluster of a VAL, as `cluster_visibility` takes it.
fn val_cluster(val: Val) -> u32 {
    return u32(val.flux.w);
}

// Adds one VAL's contribution at the point (x, n, k) with mirror direction r, scaled by its
// cluster's visibility V there (1 without visibility).
fn accumulate(sums: ptr<function, Sums>, point: WorldPoint, r: vec3<f32>, val: Val, visibility: f32, glossy_on: bool, flux_weights: bool) {
    let t = disc_terms(point.position, point.normal, val);
    let g = t.g * visibility;
    // Per-VAL factors (the same at the invocation's four points, so computed once per VAL).
    // The weight's is picked before the product: llvmpipe runs both sides of a branch, so a
    // branch on the flag would cost both products at every pair.
    let weight_factor = select(val.position_area.w, (val.flux.r + val.flux.g + val.flux.b) * (1.0 / 3.0), flux_weights);
    let flux_over_pi = val.flux.rgb * (1.0 / PI);
    let l = val.position_area.xyz;
    let l2 = l * l;
    let strength = weight_factor * g;
    let wd = POSITION_EPSILON + strength;
    (*sums).diffuse += flux_over_pi * g;
    (*sums).md.weight += wd;
    (*sums).md.sum += wd * l;
    if (GATHER_SPHERES) {
        (*sums).md.sum_squares += wd * l2;
    }
    if (glossy_on && GLOSSY_GATHER) {
        let lobe_j = disc_lobe(t, r, point.k);
        let ws = POSITION_EPSILON + strength * lobe_j;
        (*sums).glossy += flux_over_pi * (g * lobe_j);
        (*sums).ms.weight += ws;
        (*sums).ms.sum += ws * l;
        if (GATHER_SPHERES) {
            (*sums).ms.sum_squares += ws * l2;
        }
    }
}

// Point `index`'s visibility word `w` (all clusters seen without visibility or past the
// last point).
fn visibility_word(index: u32, w: u32, use_visibility: bool) -> u32 {
    if (use_visibility && index < params.point_count) {
        return visibility[index * VISIBILITY_WORDS + w];
    }
    return 0xffffffffu;
}

// Slot q's point `index`, mirror direction and cleared sums; false when the slot is past the
// last point (it then gathers at a harmless placeholder and is never written).
fn load_slot(q: u32, index: u32) -> bool {
    let is_active = index < params.point_count;
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

// The invocation's points, their mirror directions and running sums. Indexed only by
// constants (the compute form's `accumulate_all` is written out), so they stay in registers.
var<private> points: array<WorldPoint, POINT_SLOTS>;
var<private> mirrors: array<vec3<f32>, POINT_SLOTS>;
var<private> all_sums: array<Sums, POINT_SLOTS>;

// The point's gathered sums into its slots: irradiance sums, mean positions as f16 offsets
// from the point, occlusion spheres.
fn write_point(index: u32, point: WorldPoint, sums: Sums, count: u32, glossy_on: bool) {
    var d = moments_mean_sphere(sums.md);
    var s = vec4<f32>(point.position, 0.0);
    if (glossy_on) {
        s = moments_mean_sphere(sums.ms);
    }
    if (params.occlusion_mode == 0u) {
        d.w = 0.0;
        s.w = 0.0;
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
