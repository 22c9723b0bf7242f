// Shared by the sparse virtual-area-light passes (DESIGN §4): the VAL record, the packed
// sparse-point buffers and the four evaluation functions. `src/vals/math.rs` is the CPU twin
// of every function here.
#include "common.wgsl"

// A disc light made from one RSM texel.
struct Val {
    // xyz: world position; w: area A (m²), the footprint had the surface faced the light.
    position_area: vec4<f32>,
    // xyz: unit normal.
    normal: vec4<f32>,
    // rgb: reflected flux Φ (W).
    flux: vec4<f32>,
}

// Per-frame parameters of the sparse passes.
struct SparseParams {
    // xyz: the eye whose direction the glossy lobes use.
    eye: vec4<f32>,
    point_count: u32,
    instance_count: u32,
    // Bit 0: glossy on; bit 1: flux weights (else geometric).
    flags: u32,
    // 0 off, 1 sum, 2 union.
    occlusion_mode: u32,
    tile: u32,
    vertex_count: u32,
    // RSM cluster tiles over all layers (`--occlusion rays`).
    rsm_tiles: u32,
    // Percent of the last frame's cluster visibility kept in this frame's.
    visibility_history: u32,
}

// Where an instance's vertices, points and links start in the flat buffers.
struct InstanceRange {
    vertex_offset: u32,
    // The mesh's vertices, twice for a two-sided sheet (front lights, then back lights).
    vertex_count: u32,
    point_offset: u32,
    link_offset: u32,
    // A two-sided sheet's back-face lights start this many vertices after vertex_offset
    // (0: one-sided).
    back_offset: u32,
}

const FLAG_GLOSSY: u32 = 1u;
const FLAG_FLUX_WEIGHTS: u32 = 2u;
// Per-view glossy eye: recompute the glossy half only; the diffuse half stays as it is.
const FLAG_GLOSSY_ONLY: u32 = 4u;
// `--occlusion rays`: scale each VAL by its cluster's visibility at the point.
const FLAG_VISIBILITY: u32 = 8u;
// `--visibility-rays adaptive`: a tile's coarse strata first, the rest only where they disagree.
const FLAG_ADAPTIVE_RAYS: u32 = 16u;
const POSITION_EPSILON: f32 = 1e-12;
const COS_MIN: f32 = 1e-2;
const WEIGHT_EPSILON: f32 = 1e-6;
// vals::math::BLEND_GAIN_MAX: the most a vertex's blended diffuse light may give it over the
// mean of its links' lights evaluated there.
const BLEND_GAIN_MAX: f32 = 2.0;

// Octahedral unit-vector encoding in two snorm16 (the points' normals).
fn oct_decode(packed: u32) -> vec3<f32> {
    let e = unpack2x16snorm(packed);
    var n = vec3<f32>(e.x, e.y, 1.0 - abs(e.x) - abs(e.y));
    if (n.z < 0.0) {
        let sx = select(-1.0, 1.0, n.x >= 0.0);
        let sy = select(-1.0, 1.0, n.y >= 0.0);
        n = vec3<f32>((1.0 - abs(n.y)) * sx, (1.0 - abs(n.x)) * sy, n.z);
    }
    return normalize(n);
}

// A sparse point in world space, decoded from its static model-space record.
struct WorldPoint {
    position: vec3<f32>,
    normal: vec3<f32>,
    k: f32,
    disc_radius: f32,
}

fn world_point(model: vec4<u32>, point_meta: vec2<u32>, instance: InstanceData) -> WorldPoint {
    var out: WorldPoint;
    let p = vec3<f32>(bitcast<f32>(model.x), bitcast<f32>(model.y), bitcast<f32>(model.z));
    out.position = (instance.world_from_model * vec4<f32>(p, 1.0)).xyz;
    let normal_from_model = mat3x3<f32>(instance.normal_from_model[0].xyz, instance.normal_from_model[1].xyz, instance.normal_from_model[2].xyz);
    out.normal = normalize(normal_from_model * oct_decode(model.w));
    let k_radius = unpack2x16float(point_meta.x);
    out.k = k_radius.x;
    out.disc_radius = k_radius.y;
    return out;
}

// One disc VAL seen from the receiver (x, n): d = l − x, |d|², and
// g = max(0, n·ω̂)·max(0, −n_j·ω̂)/(|d|² + r_j²) (`vals::math::disc_geometry`), written with the
// cosines' 1/|d| folded into the denominator, g = max(0, n·d)·max(0, −n_j·d)/(|d|²·(|d|² + r_j²)),
// so that a diffuse sum needs no square root and no ω̂ (on lavapipe the gather measured the
// same within its noise; the fold is for devices where inverseSqrt is a slower unit's work).
// g is 0 where d = 0.
struct DiscTerms {
    d: vec3<f32>,
    dist2: f32,
    g: f32,
}

fn disc_terms(x: vec3<f32>, n: vec3<f32>, val: Val) -> DiscTerms {
    var t: DiscTerms;
    t.d = val.position_area.xyz - x;
    t.dist2 = dot(t.d, t.d);
    let cosines = max(dot(n, t.d), 0.0) * max(-dot(val.normal.xyz, t.d), 0.0);
    let denominator = t.dist2 * (t.dist2 + val.position_area.w * (1.0 / PI));
    t.g = select(0.0, cosines / denominator, denominator > 0.0);
    return t;
}

// The Phong lobe toward the disc, max(0, r·ω̂)^k, where its g is above 0 (0 elsewhere, as the
// CPU twin's gather has it).
fn disc_lobe(t: DiscTerms, r: vec3<f32>, k: f32) -> f32 {
    let cosine = max(dot(r, t.d) * inverseSqrt(max(t.dist2, 1e-30)), 0.0);
    return select(0.0, pow(cosine, k), t.g > 0.0);
}

fn lobe(r: vec3<f32>, w: vec3<f32>, k: f32) -> f32 {
    return pow(max(dot(r, w), 0.0), k);
}

// cos/d² toward a point light at l (times I gives irradiance).
fn diffuse_point_factor(x: vec3<f32>, n: vec3<f32>, l: vec3<f32>) -> f32 {
    let d = l - x;
    let dist2 = dot(d, d);
    if (dist2 <= 0.0) {
        return 0.0;
    }
    return max(dot(n, d * inverseSqrt(dist2)), 0.0) / dist2;
}

// lobe·cos/d² toward a point light at l.
fn glossy_point_factor(x: vec3<f32>, n: vec3<f32>, r: vec3<f32>, k: f32, l: vec3<f32>) -> f32 {
    let d = l - x;
    let dist2 = dot(d, d);
    if (dist2 <= 0.0) {
        return 0.0;
    }
    let w = d * inverseSqrt(dist2);
    return lobe(r, w, k) * max(dot(n, w), 0.0) / dist2;
}

fn rgb_bits(c: vec3<f32>) -> vec3<u32> {
    return bitcast<vec3<u32>>(c);
}

fn bits_rgb(v: vec4<u32>) -> vec3<f32> {
    return bitcast<vec3<f32>>(v.xyz);
}

// A point's two lights, decoded: positions are stored as f16 offsets from the point.
struct PointLights {
    diffuse_position: vec3<f32>,
    diffuse: vec3<f32>,
    glossy_position: vec3<f32>,
    glossy: vec3<f32>,
    diffuse_sphere: f32,
    glossy_sphere: f32,
}

fn decode_lights(x: vec3<f32>, d: vec4<u32>, s: vec4<u32>, extra: vec2<u32>) -> PointLights {
    var out: PointLights;
    let z = unpack2x16float(extra.x);
    let spheres = unpack2x16float(extra.y);
    out.diffuse_position = x + vec3<f32>(unpack2x16float(d.w), z.x);
    out.glossy_position = x + vec3<f32>(unpack2x16float(s.w), z.y);
    out.diffuse = bits_rgb(d);
    out.glossy = bits_rgb(s);
    out.diffuse_sphere = spheres.x;
    out.glossy_sphere = spheres.y;
    return out;
}

// Duff et al. 2017 orthonormal basis; src/vals/math.rs builds the same one.
fn tangent_frame_t(n: vec3<f32>) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    return vec3<f32>(1.0 + sign * n.x * n.x * a, sign * n.x * n.y * a, -sign * n.x);
}

fn tangent_frame_b(n: vec3<f32>) -> vec3<f32> {
    let sign = select(-1.0, 1.0, n.z >= 0.0);
    let a = -1.0 / (sign + n.z);
    return vec3<f32>(n.x * n.y * a, sign + n.y * n.y * a, -n.y);
}

// The index of a 64-wide kernel's thread when its groups wrap into a second dimension
// (`gpu::linear_groups`): `groups` is the dispatch's `num_workgroups`.
fn linear_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * 64u;
}
