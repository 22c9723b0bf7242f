// One destination cell of an LPV propagation step (`lpv_propagate.wgsl`): the step's bindings,
// the cell's state through its faces and one face's flux. The faces themselves and the
// re-emitted lobes are in `lpv_faces.wgsl`.
#include "lpv_common.wgsl"

@group(0) @binding(0) var<uniform> params: LpvParams;
@group(0) @binding(1) var src: texture_3d<f32>;
@group(0) @binding(2) var dst: texture_storage_3d<rgba32float, write>;
@group(0) @binding(3) var<storage, read_write> accum: array<f32>;
@group(0) @binding(4) var<storage, read> gv: array<vec4<f32>>;

// The coefficients of source cell c, zero outside the grid.
fn read_source(c: vec3<i32>) -> array<vec3<f32>, 9> {
    if (!lpv_inside(c, params.dims.xyz)) {
        return array<vec3<f32>, 9>();
    }
    return lpv_texel_cell(src, c);
}

// One destination cell's state through the face loop.
struct Cell {
    d: vec3<i32>,
    inside: bool,
    // The geometry volume at the cell's 8 corners (corner i at (i & 1, i >> 1 & 1, i >> 2 & 1)).
    corners: array<vec4<f32>, 8>,
    // Flux per face-normal axis (+x −x +y −y +z −z).
    f0: vec3<f32>,
    f1: vec3<f32>,
    f2: vec3<f32>,
    f3: vec3<f32>,
    f4: vec3<f32>,
    f5: vec3<f32>,
}

fn cell_begin(d: vec3<i32>, occlusion: bool) -> Cell {
    var c: Cell;
    c.d = d;
    c.inside = lpv_inside(d, params.dims.xyz);
    if (occlusion && c.inside) {
        let gd = vec3<i32>(params.dims.xyz) + 1;
        for (var i = 0; i < 8; i++) {
            let g = d + vec3<i32>(i & 1, (i >> 1) & 1, (i >> 2) & 1);
            c.corners[i] = gv[u32(g.x + gd.x * (g.y + gd.y * g.z))];
        }
    }
    return c;
}

// One face's flux Ω_f·V_f·max(0, I_src(ω_f)), given the source's intensity toward the face
// and, with occlusion, the geometry volume at the midpoint and Y at −ω_f (the blocker seen
// from the source).
fn face_flux(intensity: vec3<f32>, blocker: vec4<f32>, back: vec4<f32>, solid_angle: f32, occlusion: bool) -> vec3<f32> {
    var visibility = 1.0;
    if (occlusion) {
        visibility = 1.0 - clamp(dot(blocker, back), 0.0, 1.0);
    }
    return (solid_angle * visibility) * max(intensity, vec3<f32>(0.0));
}
