// GENERATED from the propagation face tables (`src/peers/lpv/face_code.rs`, from
// `math::faces6` and `math::faces26`): do not edit. `VALGI_UPDATE_REFERENCES=1 cargo test
// --lib lpv_faces` writes it anew. One function per order gathers every face of one
// destination cell, its numbers as literals (see face_code.rs why): per neighbour, the
// source's coefficients and the geometry volume at the midpoint (only the nonzero
// corner weights); per face, Φ_f = Ω_f·V_f·max(0, Σ_k c_k·Y_k(ω_f)) added to the sum
// of its normal axis (`face_flux`, `lpv_propagate_cell.wgsl`). One more per order ends
// the cell's step: the six axes' fluxes re-emitted as clamped-cosine lobes, stored.
#include "lpv_propagate_cell.wgsl"

// 6 neighbours, 30 faces, 4 SH terms.
fn lpv_faces(c: ptr<function, Cell>, occlusion: bool) {
    var source: array<vec3<f32>, 9>;
    var blocker = vec4<f32>(0.0);
    source = read_source((*c).d - vec3<i32>(-1, 0, 0));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[3] + (*c).corners[5] + (*c).corners[7]) * 0.25;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[3] * -0.4886025,
        blocker, vec4<f32>(0.2820948, 0.0, 0.0, 0.4886025), 0.40066966, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.21850967
        + source[3] * -0.43701935,
        blocker, vec4<f32>(0.2820948, -0.21850967, 0.0, 0.43701935), 0.42343134, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.21850967
        + source[3] * -0.43701935,
        blocker, vec4<f32>(0.2820948, 0.21850967, 0.0, 0.43701935), 0.42343134, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.21850967
        + source[3] * -0.43701935,
        blocker, vec4<f32>(0.2820948, 0.0, -0.21850967, 0.43701935), 0.42343134, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.21850967
        + source[3] * -0.43701935,
        blocker, vec4<f32>(0.2820948, 0.0, 0.21850967, 0.43701935), 0.42343134, occlusion);
    source = read_source((*c).d - vec3<i32>(0, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[3] + (*c).corners[6] + (*c).corners[7]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.43701935
        + source[3] * 0.21850967,
        blocker, vec4<f32>(0.2820948, 0.43701935, 0.0, -0.21850967), 0.42343134, occlusion);
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.43701935
        + source[3] * -0.21850967,
        blocker, vec4<f32>(0.2820948, 0.43701935, 0.0, 0.21850967), 0.42343134, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.4886025,
        blocker, vec4<f32>(0.2820948, 0.4886025, 0.0, 0.0), 0.40066966, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.43701935
        + source[2] * 0.21850967,
        blocker, vec4<f32>(0.2820948, 0.43701935, -0.21850967, 0.0), 0.42343134, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.43701935
        + source[2] * -0.21850967,
        blocker, vec4<f32>(0.2820948, 0.43701935, 0.21850967, 0.0), 0.42343134, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[5] + (*c).corners[6] + (*c).corners[7]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.43701935
        + source[3] * 0.21850967,
        blocker, vec4<f32>(0.2820948, 0.0, 0.43701935, -0.21850967), 0.42343134, occlusion);
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.43701935
        + source[3] * -0.21850967,
        blocker, vec4<f32>(0.2820948, 0.0, 0.43701935, 0.21850967), 0.42343134, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.21850967
        + source[2] * -0.43701935,
        blocker, vec4<f32>(0.2820948, -0.21850967, 0.43701935, 0.0), 0.42343134, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.21850967
        + source[2] * -0.43701935,
        blocker, vec4<f32>(0.2820948, 0.21850967, 0.43701935, 0.0), 0.42343134, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.4886025,
        blocker, vec4<f32>(0.2820948, 0.0, 0.4886025, 0.0), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1] + (*c).corners[2] + (*c).corners[3]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.43701935
        + source[3] * 0.21850967,
        blocker, vec4<f32>(0.2820948, 0.0, -0.43701935, -0.21850967), 0.42343134, occlusion);
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.43701935
        + source[3] * -0.21850967,
        blocker, vec4<f32>(0.2820948, 0.0, -0.43701935, 0.21850967), 0.42343134, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.21850967
        + source[2] * 0.43701935,
        blocker, vec4<f32>(0.2820948, -0.21850967, -0.43701935, 0.0), 0.42343134, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.21850967
        + source[2] * 0.43701935,
        blocker, vec4<f32>(0.2820948, 0.21850967, -0.43701935, 0.0), 0.42343134, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.4886025,
        blocker, vec4<f32>(0.2820948, 0.0, -0.4886025, 0.0), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1] + (*c).corners[4] + (*c).corners[5]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.43701935
        + source[3] * 0.21850967,
        blocker, vec4<f32>(0.2820948, -0.43701935, 0.0, -0.21850967), 0.42343134, occlusion);
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.43701935
        + source[3] * -0.21850967,
        blocker, vec4<f32>(0.2820948, -0.43701935, 0.0, 0.21850967), 0.42343134, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.4886025,
        blocker, vec4<f32>(0.2820948, -0.4886025, 0.0, 0.0), 0.40066966, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.43701935
        + source[2] * 0.21850967,
        blocker, vec4<f32>(0.2820948, -0.43701935, -0.21850967, 0.0), 0.42343134, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.43701935
        + source[2] * -0.21850967,
        blocker, vec4<f32>(0.2820948, -0.43701935, 0.21850967, 0.0), 0.42343134, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 0, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[2] + (*c).corners[4] + (*c).corners[6]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[3] * 0.4886025,
        blocker, vec4<f32>(0.2820948, 0.0, 0.0, -0.4886025), 0.40066966, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.21850967
        + source[3] * 0.43701935,
        blocker, vec4<f32>(0.2820948, -0.21850967, 0.0, -0.43701935), 0.42343134, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.21850967
        + source[3] * 0.43701935,
        blocker, vec4<f32>(0.2820948, 0.21850967, 0.0, -0.43701935), 0.42343134, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.21850967
        + source[3] * 0.43701935,
        blocker, vec4<f32>(0.2820948, 0.0, -0.21850967, -0.43701935), 0.42343134, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.21850967
        + source[3] * 0.43701935,
        blocker, vec4<f32>(0.2820948, 0.0, 0.21850967, -0.43701935), 0.42343134, occlusion);
}

// 26 neighbours, 54 faces, 9 SH terms.
fn holpv_faces(c: ptr<function, Cell>, occlusion: bool) {
    var source: array<vec3<f32>, 9>;
    var blocker = vec4<f32>(0.0);
    source = read_source((*c).d - vec3<i32>(-1, -1, -1));
    if (occlusion) {
        blocker = (*c).corners[7];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.23700704
        + source[3] * -0.35551053
        + source[4] * 0.38560534
        + source[5] * 0.25707024
        + source[6] * -0.0927622
        + source[7] * 0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * -0.23700704
        + source[3] * -0.23700704
        + source[4] * 0.38560537
        + source[5] * 0.38560534
        + source[6] * -0.0927622
        + source[7] * 0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, 0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.35551053
        + source[3] * -0.23700704
        + source[4] * 0.25707024
        + source[5] * 0.38560537
        + source[6] * 0.18552452
        + source[7] * 0.38560537,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.35551053, 0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[3] + (*c).corners[7]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[3] * -0.40654185
        + source[4] * 0.5042531
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, 0.2710279, 0.0, 0.40654185), 0.25069195, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[3] * -0.2710279
        + source[4] * 0.5042531
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, 0.40654185, 0.0, 0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, -1, 1));
    if (occlusion) {
        blocker = (*c).corners[3];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.23700704
        + source[3] * -0.35551053
        + source[4] * 0.38560534
        + source[5] * -0.25707024
        + source[6] * -0.0927622
        + source[7] * -0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * 0.23700704
        + source[3] * -0.23700704
        + source[4] * 0.38560537
        + source[5] * -0.38560534
        + source[6] * -0.0927622
        + source[7] * -0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, -0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.35551053
        + source[3] * -0.23700704
        + source[4] * 0.25707024
        + source[5] * -0.38560537
        + source[6] * 0.18552452
        + source[7] * -0.38560537,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.35551053, 0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[5] + (*c).corners[7]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.2710279
        + source[3] * -0.40654185
        + source[6] * -0.024260888
        + source[7] * 0.5042531
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, 0.2710279, 0.40654185), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.40654185
        + source[3] * -0.2710279
        + source[6] * 0.33965248
        + source[7] * 0.5042531
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, 0.40654185, 0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, 0, 0));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[3] + (*c).corners[5] + (*c).corners[7]) * 0.25;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[3] * -0.4886025
        + source[6] * -0.31539157
        + source[8] * 0.5462742,
        blocker, vec4<f32>(0.2820948, 0.0, 0.0, 0.4886025), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[3]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.2710279
        + source[3] * -0.40654185
        + source[6] * -0.024260888
        + source[7] * -0.5042531
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, -0.2710279, 0.40654185), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.40654185
        + source[3] * -0.2710279
        + source[6] * 0.33965248
        + source[7] * -0.5042531
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, -0.40654185, 0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, 1, -1));
    if (occlusion) {
        blocker = (*c).corners[5];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.23700704
        + source[3] * -0.35551053
        + source[4] * -0.38560534
        + source[5] * -0.25707024
        + source[6] * -0.0927622
        + source[7] * 0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * -0.23700704
        + source[3] * -0.23700704
        + source[4] * -0.38560537
        + source[5] * -0.38560534
        + source[6] * -0.0927622
        + source[7] * 0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, 0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.35551053
        + source[3] * -0.23700704
        + source[4] * -0.25707024
        + source[5] * -0.38560537
        + source[6] * 0.18552452
        + source[7] * 0.38560537,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.35551053, 0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[5]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[3] * -0.40654185
        + source[4] * -0.5042531
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, -0.2710279, 0.0, 0.40654185), 0.25069195, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[3] * -0.2710279
        + source[4] * -0.5042531
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, -0.40654185, 0.0, 0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(-1, 1, 1));
    if (occlusion) {
        blocker = (*c).corners[1];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.23700704
        + source[3] * -0.35551053
        + source[4] * -0.38560534
        + source[5] * 0.25707024
        + source[6] * -0.0927622
        + source[7] * -0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * 0.23700704
        + source[3] * -0.23700704
        + source[4] * -0.38560537
        + source[5] * 0.38560534
        + source[6] * -0.0927622
        + source[7] * -0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, -0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.35551053
        + source[3] * -0.23700704
        + source[4] * -0.25707024
        + source[5] * 0.38560537
        + source[6] * 0.18552452
        + source[7] * -0.38560537,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.35551053, 0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(0, -1, -1));
    if (occlusion) {
        blocker = ((*c).corners[6] + (*c).corners[7]) * 0.5;
    }
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[2] * -0.2710279
        + source[5] * 0.5042531
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, 0.40654185, 0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[2] * -0.40654185
        + source[5] * 0.5042531
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, 0.2710279, 0.40654185, 0.0), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(0, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[3] + (*c).corners[6] + (*c).corners[7]) * 0.25;
    }
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.4886025
        + source[6] * -0.31539157
        + source[8] * -0.5462742,
        blocker, vec4<f32>(0.2820948, 0.4886025, 0.0, 0.0), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(0, -1, 1));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[3]) * 0.5;
    }
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[2] * 0.2710279
        + source[5] * -0.5042531
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, 0.40654185, -0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[2] * 0.40654185
        + source[5] * -0.5042531
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, 0.2710279, -0.40654185, 0.0), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[5] + (*c).corners[6] + (*c).corners[7]) * 0.25;
    }
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.4886025
        + source[6] * 0.63078314,
        blocker, vec4<f32>(0.2820948, 0.0, 0.4886025, 0.0), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1] + (*c).corners[2] + (*c).corners[3]) * 0.25;
    }
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.4886025
        + source[6] * 0.63078314,
        blocker, vec4<f32>(0.2820948, 0.0, -0.4886025, 0.0), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 1, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[5]) * 0.5;
    }
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[2] * -0.2710279
        + source[5] * -0.5042531
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, -0.40654185, 0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[2] * -0.40654185
        + source[5] * -0.5042531
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, -0.2710279, 0.40654185, 0.0), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1] + (*c).corners[4] + (*c).corners[5]) * 0.25;
    }
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.4886025
        + source[6] * -0.31539157
        + source[8] * -0.5462742,
        blocker, vec4<f32>(0.2820948, -0.4886025, 0.0, 0.0), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(0, 1, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1]) * 0.5;
    }
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[2] * 0.2710279
        + source[5] * 0.5042531
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, -0.40654185, -0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[2] * 0.40654185
        + source[5] * 0.5042531
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, -0.2710279, -0.40654185, 0.0), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(1, -1, -1));
    if (occlusion) {
        blocker = (*c).corners[6];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.23700704
        + source[3] * 0.35551053
        + source[4] * -0.38560534
        + source[5] * 0.25707024
        + source[6] * -0.0927622
        + source[7] * -0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * -0.23700704
        + source[3] * 0.23700704
        + source[4] * -0.38560537
        + source[5] * 0.38560534
        + source[6] * -0.0927622
        + source[7] * -0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, 0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.35551053
        + source[3] * 0.23700704
        + source[4] * -0.25707024
        + source[5] * 0.38560537
        + source[6] * 0.18552452
        + source[7] * -0.38560537,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.35551053, -0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(1, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[6]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[3] * 0.40654185
        + source[4] * -0.5042531
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, 0.2710279, 0.0, -0.40654185), 0.25069195, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[3] * 0.2710279
        + source[4] * -0.5042531
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, 0.40654185, 0.0, -0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(1, -1, 1));
    if (occlusion) {
        blocker = (*c).corners[2];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.23700704
        + source[3] * 0.35551053
        + source[4] * -0.38560534
        + source[5] * -0.25707024
        + source[6] * -0.0927622
        + source[7] * 0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * 0.23700704
        + source[3] * 0.23700704
        + source[4] * -0.38560537
        + source[5] * -0.38560534
        + source[6] * -0.0927622
        + source[7] * 0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, -0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.35551053
        + source[3] * 0.23700704
        + source[4] * -0.25707024
        + source[5] * -0.38560537
        + source[6] * 0.18552452
        + source[7] * 0.38560537,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.35551053, -0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[6]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.2710279
        + source[3] * 0.40654185
        + source[6] * -0.024260888
        + source[7] * -0.5042531
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, 0.2710279, -0.40654185), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.40654185
        + source[3] * 0.2710279
        + source[6] * 0.33965248
        + source[7] * -0.5042531
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, 0.40654185, -0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 0, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[2] + (*c).corners[4] + (*c).corners[6]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[3] * 0.4886025
        + source[6] * -0.31539157
        + source[8] * 0.5462742,
        blocker, vec4<f32>(0.2820948, 0.0, 0.0, -0.4886025), 0.40066966, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[2]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.2710279
        + source[3] * 0.40654185
        + source[6] * -0.024260888
        + source[7] * 0.5042531
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, -0.2710279, -0.40654185), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.40654185
        + source[3] * 0.2710279
        + source[6] * 0.33965248
        + source[7] * 0.5042531
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, -0.40654185, -0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 1, -1));
    if (occlusion) {
        blocker = (*c).corners[4];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.23700704
        + source[3] * 0.35551053
        + source[4] * 0.38560534
        + source[5] * -0.25707024
        + source[6] * -0.0927622
        + source[7] * -0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * -0.23700704
        + source[3] * 0.23700704
        + source[4] * 0.38560537
        + source[5] * -0.38560534
        + source[6] * -0.0927622
        + source[7] * -0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, 0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.35551053
        + source[3] * 0.23700704
        + source[4] * 0.25707024
        + source[5] * -0.38560537
        + source[6] * 0.18552452
        + source[7] * -0.38560537,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.35551053, -0.23700704), 0.17273939, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[4]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[3] * 0.40654185
        + source[4] * 0.5042531
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, -0.2710279, 0.0, -0.40654185), 0.25069195, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[3] * 0.2710279
        + source[4] * 0.5042531
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, -0.40654185, 0.0, -0.2710279), 0.25069195, occlusion);
    source = read_source((*c).d - vec3<i32>(1, 1, 1));
    if (occlusion) {
        blocker = (*c).corners[0];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.23700704
        + source[3] * 0.35551053
        + source[4] * 0.38560534
        + source[5] * 0.25707024
        + source[6] * -0.0927622
        + source[7] * 0.38560534
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * 0.23700704
        + source[3] * 0.23700704
        + source[4] * 0.38560537
        + source[5] * 0.38560534
        + source[6] * -0.0927622
        + source[7] * 0.25707024
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, -0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.35551053
        + source[3] * 0.23700704
        + source[4] * 0.25707024
        + source[5] * 0.38560537
        + source[6] * 0.18552452
        + source[7] * 0.38560537,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.35551053, -0.23700704), 0.17273939, occlusion);
}

fn holpv_step_source(c: vec3<i32>) -> array<vec3<f32>, 9> {
    if (!lpv_inside(c, params.dims.xyz)) {
        return array<vec3<f32>, 9>();
    }
    let t0 = textureLoad(src, vec3<i32>(c.x * 5 + 0, c.y, c.z), 0);
    let t1 = textureLoad(src, vec3<i32>(c.x * 5 + 1, c.y, c.z), 0);
    let t2 = textureLoad(src, vec3<i32>(c.x * 5 + 2, c.y, c.z), 0);
    let t3 = textureLoad(src, vec3<i32>(c.x * 5 + 3, c.y, c.z), 0);
    let t4 = textureLoad(src, vec3<i32>(c.x * 5 + 4, c.y, c.z), 0);
    return array<vec3<f32>, 9>(
        vec3<f32>(t0.x, t1.z, t3.x),
        vec3<f32>(t0.y, t1.w, t3.y),
        vec3<f32>(t0.z, t2.x, t3.z),
        vec3<f32>(t0.w, t2.y, t3.w),
        vec3<f32>(0.0),
        vec3<f32>(0.0),
        vec3<f32>(t1.x, t2.z, t4.x),
        vec3<f32>(0.0),
        vec3<f32>(t1.y, t2.w, t4.y),
    );
}

// 26 neighbours, 54 faces, 6 SH terms (the sources a step wrote).
fn holpv_step_faces(c: ptr<function, Cell>, occlusion: bool) {
    var source: array<vec3<f32>, 9>;
    var blocker = vec4<f32>(0.0);
    source = holpv_step_source((*c).d - vec3<i32>(-1, -1, -1));
    if (occlusion) {
        blocker = (*c).corners[7];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.23700704
        + source[3] * -0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * -0.23700704
        + source[3] * -0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, 0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.35551053
        + source[3] * -0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.35551053, 0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[3] + (*c).corners[7]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[3] * -0.40654185
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, 0.2710279, 0.0, 0.40654185), 0.25069195, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[3] * -0.2710279
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, 0.40654185, 0.0, 0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, -1, 1));
    if (occlusion) {
        blocker = (*c).corners[3];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.23700704
        + source[3] * -0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * 0.23700704
        + source[3] * -0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, -0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.35551053
        + source[3] * -0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.35551053, 0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[5] + (*c).corners[7]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.2710279
        + source[3] * -0.40654185
        + source[6] * -0.024260888
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, 0.2710279, 0.40654185), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.40654185
        + source[3] * -0.2710279
        + source[6] * 0.33965248
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, 0.40654185, 0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, 0, 0));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[3] + (*c).corners[5] + (*c).corners[7]) * 0.25;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[3] * -0.4886025
        + source[6] * -0.31539157
        + source[8] * 0.5462742,
        blocker, vec4<f32>(0.2820948, 0.0, 0.0, 0.4886025), 0.40066966, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[3]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.2710279
        + source[3] * -0.40654185
        + source[6] * -0.024260888
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, -0.2710279, 0.40654185), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.40654185
        + source[3] * -0.2710279
        + source[6] * 0.33965248
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, -0.40654185, 0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, 1, -1));
    if (occlusion) {
        blocker = (*c).corners[5];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.23700704
        + source[3] * -0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * -0.23700704
        + source[3] * -0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, 0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.35551053
        + source[3] * -0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.35551053, 0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[1] + (*c).corners[5]) * 0.5;
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[3] * -0.40654185
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, -0.2710279, 0.0, 0.40654185), 0.25069195, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[3] * -0.2710279
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, -0.40654185, 0.0, 0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(-1, 1, 1));
    if (occlusion) {
        blocker = (*c).corners[1];
    }
    (*c).f1 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.23700704
        + source[3] * -0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.23700704, 0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * 0.23700704
        + source[3] * -0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, -0.23700704, 0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.35551053
        + source[3] * -0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.35551053, 0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, -1, -1));
    if (occlusion) {
        blocker = ((*c).corners[6] + (*c).corners[7]) * 0.5;
    }
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[2] * -0.2710279
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, 0.40654185, 0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[2] * -0.40654185
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, 0.2710279, 0.40654185, 0.0), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[3] + (*c).corners[6] + (*c).corners[7]) * 0.25;
    }
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.4886025
        + source[6] * -0.31539157
        + source[8] * -0.5462742,
        blocker, vec4<f32>(0.2820948, 0.4886025, 0.0, 0.0), 0.40066966, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, -1, 1));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[3]) * 0.5;
    }
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[2] * 0.2710279
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, 0.40654185, -0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[2] * 0.40654185
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, 0.2710279, -0.40654185, 0.0), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[5] + (*c).corners[6] + (*c).corners[7]) * 0.25;
    }
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.4886025
        + source[6] * 0.63078314,
        blocker, vec4<f32>(0.2820948, 0.0, 0.4886025, 0.0), 0.40066966, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1] + (*c).corners[2] + (*c).corners[3]) * 0.25;
    }
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.4886025
        + source[6] * 0.63078314,
        blocker, vec4<f32>(0.2820948, 0.0, -0.4886025, 0.0), 0.40066966, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, 1, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[5]) * 0.5;
    }
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[2] * -0.2710279
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, -0.40654185, 0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[2] * -0.40654185
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, -0.2710279, 0.40654185, 0.0), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1] + (*c).corners[4] + (*c).corners[5]) * 0.25;
    }
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.4886025
        + source[6] * -0.31539157
        + source[8] * -0.5462742,
        blocker, vec4<f32>(0.2820948, -0.4886025, 0.0, 0.0), 0.40066966, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(0, 1, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[1]) * 0.5;
    }
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[2] * 0.2710279
        + source[6] * -0.024260888
        + source[8] * -0.37818986,
        blocker, vec4<f32>(0.2820948, -0.40654185, -0.2710279, 0.0), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[2] * 0.40654185
        + source[6] * 0.33965248
        + source[8] * -0.16808437,
        blocker, vec4<f32>(0.2820948, -0.2710279, -0.40654185, 0.0), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, -1, -1));
    if (occlusion) {
        blocker = (*c).corners[6];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.23700704
        + source[3] * 0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * -0.23700704
        + source[3] * 0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, 0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * -0.35551053
        + source[3] * 0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, 0.23700704, 0.35551053, -0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, -1, 0));
    if (occlusion) {
        blocker = ((*c).corners[2] + (*c).corners[6]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.2710279
        + source[3] * 0.40654185
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, 0.2710279, 0.0, -0.40654185), 0.25069195, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.40654185
        + source[3] * 0.2710279
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, 0.40654185, 0.0, -0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, -1, 1));
    if (occlusion) {
        blocker = (*c).corners[2];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.23700704
        + source[3] * 0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f3 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.35551053
        + source[2] * 0.23700704
        + source[3] * 0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, 0.35551053, -0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * -0.23700704
        + source[2] * 0.35551053
        + source[3] * 0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, 0.23700704, -0.35551053, -0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, 0, -1));
    if (occlusion) {
        blocker = ((*c).corners[4] + (*c).corners[6]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.2710279
        + source[3] * 0.40654185
        + source[6] * -0.024260888
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, 0.2710279, -0.40654185), 0.25069195, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[2] * -0.40654185
        + source[3] * 0.2710279
        + source[6] * 0.33965248
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, 0.40654185, -0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, 0, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[2] + (*c).corners[4] + (*c).corners[6]) * 0.25;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[3] * 0.4886025
        + source[6] * -0.31539157
        + source[8] * 0.5462742,
        blocker, vec4<f32>(0.2820948, 0.0, 0.0, -0.4886025), 0.40066966, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, 0, 1));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[2]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.2710279
        + source[3] * 0.40654185
        + source[6] * -0.024260888
        + source[8] * 0.37818986,
        blocker, vec4<f32>(0.2820948, 0.0, -0.2710279, -0.40654185), 0.25069195, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[2] * 0.40654185
        + source[3] * 0.2710279
        + source[6] * 0.33965248
        + source[8] * 0.16808437,
        blocker, vec4<f32>(0.2820948, 0.0, -0.40654185, -0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, 1, -1));
    if (occlusion) {
        blocker = (*c).corners[4];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.23700704
        + source[3] * 0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * -0.23700704
        + source[3] * 0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, 0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f5 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * -0.35551053
        + source[3] * 0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, -0.23700704, 0.35551053, -0.23700704), 0.17273939, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, 1, 0));
    if (occlusion) {
        blocker = ((*c).corners[0] + (*c).corners[4]) * 0.5;
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.2710279
        + source[3] * 0.40654185
        + source[6] * -0.31539157
        + source[8] * 0.2101055,
        blocker, vec4<f32>(0.2820948, -0.2710279, 0.0, -0.40654185), 0.25069195, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.40654185
        + source[3] * 0.2710279
        + source[6] * -0.31539157
        + source[8] * -0.2101055,
        blocker, vec4<f32>(0.2820948, -0.40654185, 0.0, -0.2710279), 0.25069195, occlusion);
    source = holpv_step_source((*c).d - vec3<i32>(1, 1, 1));
    if (occlusion) {
        blocker = (*c).corners[0];
    }
    (*c).f0 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.23700704
        + source[3] * 0.35551053
        + source[6] * -0.0927622
        + source[8] * 0.16066888,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.23700704, -0.35551053), 0.17273939, occlusion);
    (*c).f2 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.35551053
        + source[2] * 0.23700704
        + source[3] * 0.23700704
        + source[6] * -0.0927622
        + source[8] * -0.16066888,
        blocker, vec4<f32>(0.2820948, -0.35551053, -0.23700704, -0.23700704), 0.17273939, occlusion);
    (*c).f4 += face_flux(
        source[0] * 0.2820948
        + source[1] * 0.23700704
        + source[2] * 0.35551053
        + source[3] * 0.23700704
        + source[6] * 0.18552452,
        blocker, vec4<f32>(0.2820948, -0.23700704, -0.35551053, -0.23700704), 0.17273939, occlusion);
}

fn lpv_end(c: Cell) {
    let l0 = c.f0 * 0.2820948 + c.f1 * 0.2820948 + c.f2 * 0.2820948 + c.f3 * 0.2820948 + c.f4 * 0.2820948 + c.f5 * 0.2820948;
    let l1 = c.f2 * 0.325735 + c.f3 * -0.325735;
    let l2 = c.f4 * 0.325735 + c.f5 * -0.325735;
    let l3 = c.f0 * 0.325735 + c.f1 * -0.325735;
    let cell = lpv_cell_index(c.d, params.dims.xyz) * 12u;
    accum[cell + 0u] += l0.x;
    accum[cell + 1u] += l1.x;
    accum[cell + 2u] += l2.x;
    accum[cell + 3u] += l3.x;
    accum[cell + 4u] += l0.y;
    accum[cell + 5u] += l1.y;
    accum[cell + 6u] += l2.y;
    accum[cell + 7u] += l3.y;
    accum[cell + 8u] += l0.z;
    accum[cell + 9u] += l1.z;
    accum[cell + 10u] += l2.z;
    accum[cell + 11u] += l3.z;
    textureStore(dst, vec3<i32>(c.d.x * 3 + 0, c.d.y, c.d.z), vec4<f32>(l0.x, l1.x, l2.x, l3.x));
    textureStore(dst, vec3<i32>(c.d.x * 3 + 1, c.d.y, c.d.z), vec4<f32>(l0.y, l1.y, l2.y, l3.y));
    textureStore(dst, vec3<i32>(c.d.x * 3 + 2, c.d.y, c.d.z), vec4<f32>(l0.z, l1.z, l2.z, l3.z));
}

fn holpv_end(c: Cell) {
    let l0 = c.f0 * 0.2820948 + c.f1 * 0.2820948 + c.f2 * 0.2820948 + c.f3 * 0.2820948 + c.f4 * 0.2820948 + c.f5 * 0.2820948;
    let l1 = c.f2 * 0.325735 + c.f3 * -0.325735;
    let l2 = c.f4 * 0.325735 + c.f5 * -0.325735;
    let l3 = c.f0 * 0.325735 + c.f1 * -0.325735;
    let l6 = c.f0 * -0.07884789 + c.f1 * -0.07884789 + c.f2 * -0.07884789 + c.f3 * -0.07884789 + c.f4 * 0.15769579 + c.f5 * 0.15769579;
    let l8 = c.f0 * 0.13656855 + c.f1 * 0.13656855 + c.f2 * -0.13656855 + c.f3 * -0.13656855;
    let cell = lpv_cell_index(c.d, params.dims.xyz) * 27u;
    accum[cell + 0u] += l0.x;
    accum[cell + 1u] += l1.x;
    accum[cell + 2u] += l2.x;
    accum[cell + 3u] += l3.x;
    accum[cell + 6u] += l6.x;
    accum[cell + 8u] += l8.x;
    accum[cell + 9u] += l0.y;
    accum[cell + 10u] += l1.y;
    accum[cell + 11u] += l2.y;
    accum[cell + 12u] += l3.y;
    accum[cell + 15u] += l6.y;
    accum[cell + 17u] += l8.y;
    accum[cell + 18u] += l0.z;
    accum[cell + 19u] += l1.z;
    accum[cell + 20u] += l2.z;
    accum[cell + 21u] += l3.z;
    accum[cell + 24u] += l6.z;
    accum[cell + 26u] += l8.z;
    textureStore(dst, vec3<i32>(c.d.x * 5 + 0, c.d.y, c.d.z), vec4<f32>(l0.x, l1.x, l2.x, l3.x));
    textureStore(dst, vec3<i32>(c.d.x * 5 + 1, c.d.y, c.d.z), vec4<f32>(l6.x, l8.x, l0.y, l1.y));
    textureStore(dst, vec3<i32>(c.d.x * 5 + 2, c.d.y, c.d.z), vec4<f32>(l2.y, l3.y, l6.y, l8.y));
    textureStore(dst, vec3<i32>(c.d.x * 5 + 3, c.d.y, c.d.z), vec4<f32>(l0.z, l1.z, l2.z, l3.z));
    textureStore(dst, vec3<i32>(c.d.x * 5 + 4, c.d.y, c.d.z), vec4<f32>(l6.z, l8.z, 0.0, 0.0));
}
