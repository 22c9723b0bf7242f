// One LPV propagation step as a gather (seed 004 §3.2.3, §4.2). Every destination cell d
// collects, for each face f of its neighbours (30 faces of 6 neighbours for LPV, 54 of 26 for
// HO-LPV), the flux Φ_f = Ω_f·max(0, I_src(ω_f))·V_f from the source d − offset, and
// re-emits it as the lobe Φ_f/π·max(0, n_f·ω) about the face's normal. Fluxes are summed per
// normal axis first, so the lobes are expanded six times per cell, not once per face; each
// source is read once per neighbour (26 or 6 times per cell, not 54 or 30).
// V_f = 1 − clamp(B(−ω_f), 0, 1) with B the geometry volume at the midpoint of source and
// destination (off in the first step), trilinear in the destination's 8 corner GV cells.
// The faces are written out with their numbers as literals (`lpv_faces.wgsl`, generated from
// the face tables by `src/peers/lpv/face_code.rs`): read from a table at the loop's index,
// one gathered load per float on a CPU device (Mesa's llvmpipe), they were most of LPV's
// propagation. The light volumes being read and written are 3D textures of
// `lpv_cell_texels()` rgba32float texels a cell along x (`lpv_pack.wgsl` packs the injected
// volume): a CPU device fetches a texel at per-lane coordinates with one gathered load, where
// it reads workgroup memory or a storage buffer as a loop over the lanes per float. A step
// writes only the coefficients the axes' lobes have, so HO-LPV's first step reads 26 × 27
// floats a cell and every later one 26 × 18 (`holpv_step_faces`). The result is written to `dst` and added to `accum` (a buffer
// in the injected volume's layout, which the lookup reads).
// CPU twin: math::propagate.
#include "lpv_faces.wgsl"

// True in HO-LPV's pipeline for the steps after the first (`peers::lpv::face_code::
// steps_read_fewer_coefficients`): their sources are volumes a step wrote, which hold only the
// coefficients the axes' lobes have (`holpv_step_source`); the first step reads the injected
// volume, every coefficient.
override STEP_SOURCES: bool = false;

// Every face of the order this pipeline is built for (SH_COUNT and STEP_SOURCES are pipeline
// constants, so the other functions are compiled out).
fn cell_faces(c: ptr<function, Cell>, occlusion: bool) {
    if (SH_COUNT == 9u) {
        if (STEP_SOURCES) {
            holpv_step_faces(c, occlusion);
        } else {
            holpv_faces(c, occlusion);
        }
    } else {
        lpv_faces(c, occlusion);
    }
}

// The cell's six lobes expanded, written to `dst` and added to `accum` (`lpv_end` and
// `holpv_end` in `lpv_faces.wgsl`; SH_COUNT is a pipeline constant, so one is compiled).
fn cell_end(c: Cell) {
    if (!c.inside) {
        return;
    }
    if (SH_COUNT == 9u) {
        holpv_end(c);
    } else {
        lpv_end(c);
    }
}

@compute @workgroup_size(4, 4, 4)
fn cs_main(@builtin(global_invocation_id) id: vec3<u32>) {
    let d = vec3<i32>(id);
    if (!lpv_inside(d, params.dims.xyz)) {
        return;
    }
    let occlusion = params.occlusion != 0u;
    var cell = cell_begin(d, occlusion);
    cell_faces(&cell, occlusion);
    cell_end(cell);
}
