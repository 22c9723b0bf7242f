// Light propagation volumes (seed 004, DESIGN §6): the grid parameters, the propagation face
// table and the spherical harmonics shared by the lpv_* passes. `src/peers/lpv/math.rs` is
// the CPU twin of every function here.
#include "vals_common.wgsl"

// SH coefficients per colour channel: 4 (LPV, two bands) or 9 (HO-LPV, three bands), set
// per pipeline. A cell holds 3·SH_COUNT floats: [channel][coefficient].
override SH_COUNT: u32 = 4u;

struct LpvParams {
    // xyz: the grid's min corner (world, m); w: cell size h (m).
    origin_cell: vec4<f32>,
    // xyz: cells per axis; w: cells in all.
    dims: vec4<u32>,
    // 1: attenuate the propagated flux by the geometry volume in this step.
    occlusion: u32,
    // Camera surfels for the geometry volume: one per stride×stride render pixels.
    surfel_stride: u32,
    pad0: u32,
    pad1: u32,
}

// Real SH up to band 2, the order of math::sh9.
fn sh9(d: vec3<f32>) -> array<f32, 9> {
    return array<f32, 9>(
        0.2820948,
        0.4886025 * d.y,
        0.4886025 * d.z,
        0.4886025 * d.x,
        1.0925484 * d.x * d.y,
        1.0925484 * d.y * d.z,
        0.31539157 * (3.0 * d.z * d.z - 1.0),
        1.0925484 * d.x * d.z,
        0.5462742 * (d.x * d.x - d.y * d.y),
    );
}

// Zonal factor of the clamped cosine for coefficient k: π, 2π/3, π/4 per band.
fn clamped_cosine_factor(k: u32) -> f32 {
    if (k == 0u) {
        return PI;
    }
    if (k < 4u) {
        return 2.0 * PI / 3.0;
    }
    return PI / 4.0;
}

fn lpv_cell_index(c: vec3<i32>, dims: vec3<u32>) -> u32 {
    let n = vec3<i32>(dims);
    return u32(c.x + n.x * (c.y + n.y * c.z));
}

fn lpv_inside(c: vec3<i32>, dims: vec3<u32>) -> bool {
    return all(c >= vec3<i32>(0)) && all(c < vec3<i32>(dims));
}

// rgba32float texels per cell of a light volume stored as a 3D texture (`lpv_propagate.wgsl`):
// its 3·SH_COUNT floats in order, the last texel zero-padded (3 for LPV, 7 for HO-LPV). Cell
// (x, y, z) starts at texel (x · lpv_cell_texels(), y, z).
fn lpv_cell_texels() -> u32 {
    return (3u * SH_COUNT + 3u) / 4u;
}

// The 3·SH_COUNT floats of cell c of a volume stored that way, as one vec3 (r, g, b) per
// coefficient.
fn lpv_texel_cell(volume: texture_3d<f32>, c: vec3<i32>) -> array<vec3<f32>, 9> {
    var floats: array<f32, 28>;
    let texels = lpv_cell_texels();
    for (var t = 0u; t < texels; t++) {
        let texel = textureLoad(volume, vec3<i32>(c.x * i32(texels) + i32(t), c.y, c.z), 0);
        floats[4u * t] = texel.x;
        floats[4u * t + 1u] = texel.y;
        floats[4u * t + 2u] = texel.z;
        floats[4u * t + 3u] = texel.w;
    }
    var coefficients: array<vec3<f32>, 9>;
    for (var k = 0u; k < SH_COUNT; k++) {
        coefficients[k] = vec3<f32>(floats[k], floats[SH_COUNT + k], floats[2u * SH_COUNT + k]);
    }
    return coefficients;
}
