// GENERATED from the propagation face tables (`src/peers/lpv/face_code.rs`, from
// `math::faces6` and `math::faces26`): do not edit. `VALGI_UPDATE_REFERENCES=1 cargo test
// --lib lpv_faces` writes it anew. One function per order gathers every face of one
// destination cell, its numbers as literals (see face_code.rs why): per neighbour, the
// source's coefficients and the geometry volume at the midpoint (only the nonzero
// corner weights); per face, Φ_f = Ω_f·V_f·max(0, Σ_k c_k·Y_k(ω_f)) added to the sum
// of its normal axis (`face_flux`, `lpv_propagate_cell.wgsl`).
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
