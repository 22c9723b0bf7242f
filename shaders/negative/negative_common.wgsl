// Second-order illumination with negative indirect lights (seed 002): the records every pass
// shares (mirrored by #[repr(C)] types in src/negative/, checked against naga) and the point
// light that both positive and negative lights are (Lambertian emitter, no visibility).
#include "common.wgsl"

// Which RSM texel a positive light reads, and the factor that makes its flux Φ_l.
struct PositiveSample {
    layer: u32,
    texel_x: u32,
    texel_y: u32,
    light: u32,
    flux_scale: f32,
    pad0: f32,
    pad1: f32,
    pad2: f32,
}

struct IndirectLight {
    // xyz: world position; w: 1 when the light exists.
    position: vec4<f32>,
    // xyz: unit normal of its Lambertian emission; w: r² of the disc it stands for (m²).
    normal: vec4<f32>,
    // rgb: flux (W).
    flux: vec4<f32>,
}

struct SurfacePoint {
    // xyz: world position; w: 1 where a surface covers the pixel.
    position: vec4<f32>,
    // xyz: unit normal facing the eye; w: distance to the eye.
    normal: vec4<f32>,
}

struct PositiveTerms {
    // rgb: E_s (all positive lights, no visibility); a: lights that hit the d²_min guard.
    e_s: vec4<f32>,
    // rgb: E_neg (the lights behind the tangent plane).
    e_neg: vec4<f32>,
    // xyz: weighted direction D, not normalized.
    direction: vec4<f32>,
}

struct NegativeParams {
    eye: vec4<f32>,
    full_width: u32,
    full_height: u32,
    low_width: u32,
    low_height: u32,
    positive_count: u32,
    candidate_count: u32,
    negative_target: u32,
    // The weight and the falloff are pipeline constants (`negative_view.wgsl`).
    pad0: u32,
    lowres: u32,
    tiles_x: u32,
    d2_min: f32,
    threshold_pos: f32,
    threshold_normal: f32,
    // 2·tan(fov_y/2)/H: the pixel footprint at unit distance.
    footprint_scale: f32,
    omega_frustum: f32,
    pad1: u32,
}

const WEIGHT_LITERAL: u32 = 0u;
const WEIGHT_ARRIVING: u32 = 1u;
const WEIGHT_PROPAGATION: u32 = 2u;

// A light this close to a point's tangent plane (|cos| below it) counts as in the plane: it
// adds nothing to E_neg. Positions rebuilt from depth wobble by a fraction of a pixel, which
// would otherwise put a wall's own lights "behind" it.
const COPLANAR_COS: f32 = 0.01;

// Negative lights one frame may place (workgroup memory of the selection).
const MAX_NEGATIVES: u32 = 1024u;

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}
