// Step 1 — gather: every VAL at every sparse point, GATHER_SLOTS points an invocation. Two
// entry points read the VAL list two ways (`GatherVals` in
// `src/vals/sparse.rs` picks one):
// - `cs_main` streams it through workgroup memory `tile` records at a time, so every VAL is
//   fetched from the buffer once per workgroup and read from workgroup memory once per
//   invocation, not once per point. Split over VAL slices (dispatch z > 1), each workgroup
//   gathers one slice and stores partial sums for `vals_gather_reduce.wgsl` instead.
// - `cs_window` reads one uniform window of WINDOW_VALS VALs per dispatch, one dispatch per
//   window, and carries each point's running sums from window to window in the partial-sums
//   buffer (see there why).
// Both write the irradiance sums (in the slots the renormalized intensities later take), the
// averaged positions as f16 offsets from the point, and the occlusion spheres.
#include "vals_gather_partials.wgsl"
#include "val_windows.wgsl"

const GROUP: u32 = 64u;
const TILE_MAX: u32 = 256u;
// Invocations per workgroup of the window form: a CPU device runs whole workgroups on its
// threads, and small ones let the last round take only what is left (see `cs_window`).
const WINDOW_GROUP: u32 = 16u;

// The distance between an invocation's points: GROUP in the tile form (a workgroup's points
// are a block, each invocation's strided through it), every invocation of the dispatch in the
// window form (each invocation's points strided through all of them).
var<private> slot_stride: u32;

var<workgroup> tile_vals: array<Val, TILE_MAX>;
var<workgroup> shared_count: u32;

// Points per invocation, 4, 8 or 16 (`vals::sparse::gather_points_per_invocation` picks it
// and sizes the dispatch): every VAL read from workgroup memory, and its per-VAL factors, serve
// this many points (register blocking). On llvmpipe, where every invocation reads each VAL
// itself, 16 points ran the gather 1.4–2.1× faster than 4 (16k VALs × 4k points: diffuse 90 →
// 44 ms, +rays 174 → 123); a GPU keeps the 4 it was measured with. The code for slots past
// GATHER_SLOTS is compiled out, so the arrays below stay in registers either way.
override GATHER_SLOTS: u32 = 4u;

// Each group of four slots' cluster visibility words, word w of slot 4g + i in lane i of
// visibility_words[g][w], picked by `slot_words`: the word index comes from the VAL, the same
// for the whole workgroup, and every index here is a constant once the slot code is written
// out, so the words stay in registers. On an H200 this gathered `+rays` 10–13 % faster than a
// private array indexed by the cluster (16k VALs × 4k points 0.76 against 0.84 ms, 512k × 4k
// 28.5–29.0 against 32.3–33.8 ms, same run); on lavapipe it measured the same within the noise.
var<private> visibility_words: array<array<vec4<u32>, 8>, 4>;

fn words_of(first: u32, w: u32, use_visibility: bool) -> vec4<u32> {
    return vec4<u32>(
        visibility_word(first, w, use_visibility),
        visibility_word(first + slot_stride, w, use_visibility),
        visibility_word(first + 2u * slot_stride, w, use_visibility),
        visibility_word(first + 3u * slot_stride, w, use_visibility),
    );
}

// The eight words of the four slots from point `first` on.
fn group_words(first: u32, use_visibility: bool) -> array<vec4<u32>, 8> {
    return array<vec4<u32>, 8>(
        words_of(first, 0u, use_visibility),
        words_of(first, 1u, use_visibility),
        words_of(first, 2u, use_visibility),
        words_of(first, 3u, use_visibility),
        words_of(first, 4u, use_visibility),
        words_of(first, 5u, use_visibility),
        words_of(first, 6u, use_visibility),
        words_of(first, 7u, use_visibility),
    );
}

// True on a CPU device (`vals::sparse::VisibilityLookup`): llvmpipe runs every case of a switch under
// a mask, and with the switch the gather took 10–15 % longer on lavapipe (16k VALs × 4k points,
// with or without visibility, since the lookup ran either way before GATHER_VISIBILITY). A
// GPU branches on the uniform word index, and keeps the switch it was measured with.
override VISIBILITY_SELECT_TREE: bool = true;

// Word w of the four slots of group g.
fn slot_words(g: u32, w: u32) -> vec4<u32> {
    let words = visibility_words[g];
    if (VISIBILITY_SELECT_TREE) {
        let b0 = (w & 1u) != 0u;
        let b1 = (w & 2u) != 0u;
        let low = select(select(words[0], words[1], b0), select(words[2], words[3], b0), b1);
        let high = select(select(words[4], words[5], b0), select(words[6], words[7], b0), b1);
        return select(low, high, (w & 4u) != 0u);
    }
    switch w {
        case 0u: { return words[0]; }
        case 1u: { return words[1]; }
        case 2u: { return words[2]; }
        case 3u: { return words[3]; }
        case 4u: { return words[4]; }
        case 5u: { return words[5]; }
        case 6u: { return words[6]; }
        default: { return words[7]; }
    }
}

// One VAL at the four points of slot group g. Written out, not a loop: llvmpipe counts every
// loop iteration against its per-invocation limit (see the VAL loop below).
fn accumulate_group(g: u32, val: Val, glossy_on: bool, flux_weights: bool, use_visibility: bool) {
    var v = vec4<f32>(1.0);
    if (use_visibility && GATHER_VISIBILITY) {
        let cluster = val_cluster(val);
        let words = slot_words(g, min(cluster / 4u, VISIBILITY_WORDS - 1u));
        v = vec4<f32>(
            cluster_visibility(cluster, words.x),
            cluster_visibility(cluster, words.y),
            cluster_visibility(cluster, words.z),
            cluster_visibility(cluster, words.w),
        );
    }
    let q = 4u * g;
    var s0 = all_sums[q];
    var s1 = all_sums[q + 1u];
    var s2 = all_sums[q + 2u];
    var s3 = all_sums[q + 3u];
    accumulate(&s0, points[q], mirrors[q], val, v.x, glossy_on, flux_weights);
    accumulate(&s1, points[q + 1u], mirrors[q + 1u], val, v.y, glossy_on, flux_weights);
    accumulate(&s2, points[q + 2u], mirrors[q + 2u], val, v.z, glossy_on, flux_weights);
    accumulate(&s3, points[q + 3u], mirrors[q + 3u], val, v.w, glossy_on, flux_weights);
    all_sums[q] = s0;
    all_sums[q + 1u] = s1;
    all_sums[q + 2u] = s2;
    all_sums[q + 3u] = s3;
}

// One VAL at each of this invocation's points.
fn accumulate_all(val: Val, glossy_on: bool, flux_weights: bool, use_visibility: bool) {
    accumulate_group(0u, val, glossy_on, flux_weights, use_visibility);
    if (GATHER_SLOTS > 4u) {
        accumulate_group(1u, val, glossy_on, flux_weights, use_visibility);
    }
    if (GATHER_SLOTS > 8u) {
        accumulate_group(2u, val, glossy_on, flux_weights, use_visibility);
        accumulate_group(3u, val, glossy_on, flux_weights, use_visibility);
    }
}

// Slot group g's points (from `first`, strided by `slot_stride`), their words, cleared sums;
// true when one of them is a point.
fn load_group(g: u32, first: u32, use_visibility: bool) -> bool {
    let q = 4u * g;
    let base = first + q * slot_stride;
    var any_active = load_slot(q, base);
    any_active = load_slot(q + 1u, base + slot_stride) || any_active;
    any_active = load_slot(q + 2u, base + 2u * slot_stride) || any_active;
    any_active = load_slot(q + 3u, base + 3u * slot_stride) || any_active;
    visibility_words[g] = group_words(base, use_visibility);
    return any_active;
}

// Slot group g's sums: into the points' slots, or with `to_partials` into the partial sums
// of `slice`.
fn write_group(g: u32, first: u32, count: u32, glossy_on: bool, to_partials: bool, slice: u32) {
    let q = 4u * g;
    write_slot(q, first, count, glossy_on, to_partials, slice);
    write_slot(q + 1u, first, count, glossy_on, to_partials, slice);
    write_slot(q + 2u, first, count, glossy_on, to_partials, slice);
    write_slot(q + 3u, first, count, glossy_on, to_partials, slice);
}

// Slot group g's running sums as an earlier window left them.
fn resume_group(g: u32, first: u32) {
    let q = 4u * g;
    resume_slot(q, first + q * slot_stride);
    resume_slot(q + 1u, first + (q + 1u) * slot_stride);
    resume_slot(q + 2u, first + (q + 2u) * slot_stride);
    resume_slot(q + 3u, first + (q + 3u) * slot_stride);
}

fn resume_slot(q: u32, index: u32) {
    if (index < params.point_count) {
        all_sums[q] = partial_load(index * PARTIAL_VEC4S);
    }
}

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    if (lid == 0u) {
        shared_count = min(val_count[0], arrayLength(&vals));
    }
    let count = workgroupUniformLoad(&shared_count);
    let tile = clamp(params.tile, 1u, TILE_MAX);
    // This workgroup's slice of the VAL list: all of it unless the gather is split.
    let slices = groups.z;
    let chunk = (count + slices - 1u) / slices;
    let begin = min(gid.z * chunk, count);
    let end = min(begin + chunk, count);
    // The workgroup's GROUP · GATHER_SLOTS points, strided by GROUP so that the invocations
    // of a SIMD row read neighbouring points.
    slot_stride = GROUP;
    let first = (linear_index(gid, groups) / GROUP) * GROUP * GATHER_SLOTS + lid;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let flux_weights = (params.flags & FLAG_FLUX_WEIGHTS) != 0u;
    let use_visibility = (params.flags & FLAG_VISIBILITY) != 0u;

    let any_active = load_groups(first, use_visibility);

    for (var base = begin; base < end; base += tile) {
        let m = min(tile, end - base);
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
    write_groups(first, count, glossy_on, slices > 1u, gid.z);
}

fn write_groups(first: u32, count: u32, glossy_on: bool, to_partials: bool, slice: u32) {
    write_group(0u, first, count, glossy_on, to_partials, slice);
    if (GATHER_SLOTS > 4u) {
        write_group(1u, first, count, glossy_on, to_partials, slice);
    }
    if (GATHER_SLOTS > 8u) {
        write_group(2u, first, count, glossy_on, to_partials, slice);
        write_group(3u, first, count, glossy_on, to_partials, slice);
    }
}

// This invocation's points, their words and cleared sums; true when one of them is a point.
// Written out, not a loop, so that the per-slot arrays are indexed by constants only.
fn load_groups(first: u32, use_visibility: bool) -> bool {
    var any_active = load_group(0u, first, use_visibility);
    if (GATHER_SLOTS > 4u) {
        any_active = load_group(1u, first, use_visibility) || any_active;
    }
    if (GATHER_SLOTS > 8u) {
        any_active = load_group(2u, first, use_visibility) || any_active;
        any_active = load_group(3u, first, use_visibility) || any_active;
    }
    return any_active;
}

fn write_slot(q: u32, first: u32, count: u32, glossy_on: bool, to_partials: bool, slice: u32) {
    let index = first + q * slot_stride;
    if (index >= params.point_count) {
        return;
    }
    if (to_partials) {
        partial_store((slice * params.point_count + index) * PARTIAL_VEC4S, all_sums[q]);
    } else {
        write_point(index, points[q], all_sums[q], count, glossy_on);
    }
}


// The window form, for a CPU device (`val_windows.wgsl`): the VAL each step reads is the
// same for the whole workgroup, so from a uniform window it costs one load where workgroup
// memory costs one per lane. Each point's sums go to the partial-sums buffer after a window
// and come back before the next as the same f32 values, so the VALs are added in the order
// `cs_main` adds them, to the same bits. Invocation i takes points i, i + T, i + 2T, … (T the
// dispatch's invocations, about points / GATHER_SLOTS), so every invocation but the last few
// has all its slots filled, and WINDOW_GROUP-invocation workgroups leave the CPU threads at
// most one small workgroup apart: with 64-invocation blocks of GROUP · GATHER_SLOTS points,
// 4423 points took five blocks, three rounds of two threads, for 8 % more points than 4095
// took in two (lavapipe, `src/vals/README.md`).
@compute @workgroup_size(WINDOW_GROUP, 1, 1)
fn cs_window(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let count = min(val_count[0], arrayLength(&vals));
    // Past the last VAL: an earlier window has written the points.
    if (window_past_count(count)) {
        return;
    }
    let begin = window.first;
    let end = window_end(count);
    slot_stride = groups.x * groups.y * WINDOW_GROUP;
    let first = gid.x + gid.y * groups.x * WINDOW_GROUP;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let flux_weights = (params.flags & FLAG_FLUX_WEIGHTS) != 0u;
    let use_visibility = (params.flags & FLAG_VISIBILITY) != 0u;
    let any_active = load_groups(first, use_visibility);
    if (begin > 0u) {
        resume_group(0u, first);
        if (GATHER_SLOTS > 4u) {
            resume_group(1u, first);
        }
        if (GATHER_SLOTS > 8u) {
            resume_group(2u, first);
            resume_group(3u, first);
        }
    }
    if (any_active) {
        // A plain loop: at most WINDOW_VALS steps per dispatch, far from llvmpipe's 65535-step
        // limit that makes `cs_main` unroll, and unrolling measured no faster here.
        let m = end - begin;
        for (var j = 0u; j < m; j++) {
            accumulate_all(window_vals[j], glossy_on, flux_weights, use_visibility);
        }
    }
    // The last window writes the points, the others their running sums.
    write_groups(first, count, glossy_on, end < count, 0u);
}
