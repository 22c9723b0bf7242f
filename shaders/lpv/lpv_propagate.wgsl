// One LPV propagation step as a gather (seed 004 §3.2.3, §4.2). Every destination cell d
// collects, for each face f of the table (30 faces of 6 neighbours for LPV, 54 of 26 for
// HO-LPV), the flux Φ_f = Ω_f·max(0, I_src(ω_f))·V_f from the source d − offset, and
// re-emits it as the lobe Φ_f/π·max(0, n_f·ω) about the face's normal. Fluxes are summed per
// normal axis first, so the lobes are expanded six times per cell, not once per face; the
// table comes grouped by offset, so each source is read once per neighbour (26 or 6 times per
// cell, not 54 or 30; 8 % faster than per-axis order on lavapipe).
// V_f = 1 − clamp(B(−ω_f), 0, 1) with B the geometry volume at the midpoint of source and
// destination (off in the first step), trilinear in the destination's 8 corner GV cells (the
// weights follow from the offset alone; as a table they were 8 more floats a face to read,
// at a loop-varying index, which llvmpipe gathers per float: 11 % of LPV's propagation). The light volumes being read and written are 3D textures of
// `lpv_cell_texels()` rgba32float texels a cell along x (`lpv_pack.wgsl` packs the injected
// volume): a CPU device (Mesa's llvmpipe) fetches a texel at per-lane coordinates with one
// gathered load, where it reads workgroup memory or a storage buffer as a loop over the lanes
// per float; HO-LPV reads 26 × 27 floats a cell. The result is written to `dst` and added to
// `accum` (a buffer in the injected volume's layout, which the lookup reads).
// CPU twin: math::propagate.
#include "lpv_common.wgsl"

@group(0) @binding(0) var<uniform> params: LpvParams;
// A uniform block, read alike by every cell: a CPU device (Mesa's llvmpipe) reads a storage
// buffer lane by lane and a uniform block with one gathered load per value (Cornell 32³, 16
// steps on lavapipe: LPV's propagation 2.3× faster, HO-LPV's 1.8×).
const FACE_BLOCK: u32 = 64u;
@group(0) @binding(1) var<uniform> faces: array<LpvFace, FACE_BLOCK>;
@group(0) @binding(2) var src: texture_3d<f32>;
@group(0) @binding(3) var dst: texture_storage_3d<rgba32float, write>;
@group(0) @binding(4) var<storage, read_write> accum: array<f32>;
@group(0) @binding(5) var<storage, read> gv: array<vec4<f32>>;

// The coefficients of source cell c, zero outside the grid.
fn read_source(c: vec3<i32>) -> array<vec3<f32>, 9> {
    if (!lpv_inside(c, params.dims.xyz)) {
        return array<vec3<f32>, 9>();
    }
    return lpv_texel_cell(src, c);
}

// Cells per invocation along x, 1 or 2 (`peers::lpv::propagate_cells_along_x`): two
// neighbouring cells walk the face table together, so that each face record, read at a
// loop-varying index (one gathered load per float on a CPU device, Mesa's llvmpipe), serves
// both. More state per invocation than two cells' spills: four measured slower.
override CELLS_ALONG_X: u32 = 1u;

// One destination cell's state through the face loop.
struct Cell {
    d: vec3<i32>,
    inside: bool,
    // The geometry volume at the cell's 8 corners (corner i at (i & 1, i >> 1 & 1, i >> 2 & 1)).
    corners: array<vec4<f32>, 8>,
    // The current offset group's source coefficients.
    source: array<vec3<f32>, 9>,
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

// One face's flux into the cell; `new_source` at the first face of an offset group.
fn cell_face(c: ptr<function, Cell>, face: LpvFace, new_source: bool, occlusion: bool) {
    let o = face.offset.xyz;
    if (new_source) {
        (*c).source = read_source((*c).d - o);
    }
    var visibility = 1.0;
    if (occlusion) {
        // Trilinear weights of the midpoint d + 0.5 − o/2 in the cell's corner frame (CPU
        // twin: math::corner_weights).
        let u = 0.5 - 0.5 * vec3<f32>(o);
        let v = 1.0 - u;
        let b = (v.x * v.y * v.z) * (*c).corners[0] + (u.x * v.y * v.z) * (*c).corners[1]
            + (v.x * u.y * v.z) * (*c).corners[2] + (u.x * u.y * v.z) * (*c).corners[3]
            + (v.x * v.y * u.z) * (*c).corners[4] + (u.x * v.y * u.z) * (*c).corners[5]
            + (v.x * u.y * u.z) * (*c).corners[6] + (u.x * u.y * u.z) * (*c).corners[7];
        let back = vec4<f32>(face.y0.x, -face.y0.yzw);
        visibility = 1.0 - clamp(dot(b, back), 0.0, 1.0);
    }
    let y = array<f32, 9>(face.y0.x, face.y0.y, face.y0.z, face.y0.w, face.y1.x, face.y1.y, face.y1.z, face.y1.w, face.y2.x);
    var intensity = vec3<f32>(0.0);
    for (var k = 0u; k < SH_COUNT; k++) {
        intensity += y[k] * (*c).source[k];
    }
    let phi = (face.y2.y * visibility) * max(intensity, vec3<f32>(0.0));
    let a = face.offset.w;
    let zero = vec3<f32>(0.0);
    (*c).f0 += select(zero, phi, a == 0);
    (*c).f1 += select(zero, phi, a == 1);
    (*c).f2 += select(zero, phi, a == 2);
    (*c).f3 += select(zero, phi, a == 3);
    (*c).f4 += select(zero, phi, a == 4);
    (*c).f5 += select(zero, phi, a == 5);
}

// The cell's six lobes expanded, written to `dst` and added to `accum`.
fn cell_end(c: Cell) {
    if (!c.inside) {
        return;
    }
    var flux: array<vec3<f32>, 6>;
    flux[0] = c.f0;
    flux[1] = c.f1;
    flux[2] = c.f2;
    flux[3] = c.f3;
    flux[4] = c.f4;
    flux[5] = c.f5;
    var out: array<vec3<f32>, 9>;
    for (var a = 0u; a < 6u; a++) {
        let lobe = sh9(axis_vector(a));
        for (var k = 0u; k < SH_COUNT; k++) {
            out[k] += flux[a] * (lobe[k] * clamped_cosine_factor(k) / PI);
        }
    }
    let cell = lpv_cell_index(c.d, params.dims.xyz) * (3u * SH_COUNT);
    var floats: array<f32, 28>;
    for (var k = 0u; k < SH_COUNT; k++) {
        for (var ch = 0u; ch < 3u; ch++) {
            let index = ch * SH_COUNT + k;
            floats[index] = out[k][ch];
            accum[cell + index] += out[k][ch];
        }
    }
    let texels = lpv_cell_texels();
    for (var t = 0u; t < texels; t++) {
        let texel = vec4<f32>(floats[4u * t], floats[4u * t + 1u], floats[4u * t + 2u], floats[4u * t + 3u]);
        textureStore(dst, vec3<i32>(c.d.x * i32(texels) + i32(t), c.d.y, c.d.z), texel);
    }
}

@compute @workgroup_size(4, 4, 4)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let d = vec3<i32>(i32(id.x * CELLS_ALONG_X), i32(id.y), i32(id.z));
    if (!lpv_inside(d, params.dims.xyz)) {
        return;
    }
    let occlusion = params.occlusion != 0u;
    var first = cell_begin(d, occlusion);
    var second: Cell;
    if (CELLS_ALONG_X == 2u) {
        second = cell_begin(d + vec3<i32>(1, 0, 0), occlusion);
    }
    // Faces come grouped by source offset: each source's coefficients are read once per
    // group, and each face's flux goes to one of six per-axis sums.
    var last = vec3<i32>(2);
    for (var f = 0u; f < params.face_count; f++) {
        let face = faces[f];
        let new_source = any(face.offset.xyz != last);
        last = face.offset.xyz;
        cell_face(&first, face, new_source, occlusion);
        if (CELLS_ALONG_X == 2u) {
            cell_face(&second, face, new_source, occlusion);
        }
    }
    cell_end(first);
    if (CELLS_ALONG_X == 2u) {
        cell_end(second);
    }
}
