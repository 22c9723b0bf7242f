// Step 1 — gather: every VAL at every sparse point. Each workgroup takes 64 invocations × 4
// points; the VAL list streams through workgroup memory `tile` records at a time, so every VAL
// is fetched from the buffer once per workgroup and read from workgroup memory once per
// invocation, not once per point. Writes the irradiance sums (in the slots the
// renormalized intensities later take), the averaged positions as f16 offsets from the point,
// and the occlusion spheres. Split over VAL slices (dispatch z > 1), each workgroup gathers
// one slice and stores partial sums for `vals_gather_reduce.wgsl` instead.
#include "vals_gather_partials.wgsl"

const GROUP: u32 = 64u;
const TILE_MAX: u32 = 256u;

var<workgroup> tile_vals: array<Val, TILE_MAX>;
var<workgroup> shared_count: u32;

// Points per invocation: every VAL read from workgroup memory is used for this many points
// (register blocking), which on a CPU device halves the loads per pair at 2 and quarters them
// at 4. `GATHER_POINTS_PER_INVOCATION` in `src/vals/sparse.rs` sizes the dispatch; the slots
// are the shared half's POINT_SLOTS.
const POINTS_PER_INVOCATION: u32 = POINT_SLOTS;

// The four points' cluster visibility words, one variable per word (lane q: slot q), picked
// by `slot_words`: the word index comes from the VAL, the same for the whole workgroup, so
// the variables can stay in registers. On an H200 this gathered `+rays` 10–13 %
// faster than a private array indexed by the cluster (16k VALs × 4k points 0.76 against
// 0.84 ms, 512k × 4k 28.5–29.0 against 32.3–33.8 ms, same run); on lavapipe it measured the
// same within the noise.
var<private> vis0: vec4<u32>;
var<private> vis1: vec4<u32>;
var<private> vis2: vec4<u32>;
var<private> vis3: vec4<u32>;
var<private> vis4: vec4<u32>;
var<private> vis5: vec4<u32>;
var<private> vis6: vec4<u32>;
var<private> vis7: vec4<u32>;

fn words_of(first: u32, w: u32, use_visibility: bool) -> vec4<u32> {
    return vec4<u32>(
        visibility_word(first, w, use_visibility),
        visibility_word(first + GROUP, w, use_visibility),
        visibility_word(first + 2u * GROUP, w, use_visibility),
        visibility_word(first + 3u * GROUP, w, use_visibility),
    );
}

fn load_visibility(first: u32, use_visibility: bool) {
    vis0 = words_of(first, 0u, use_visibility);
    vis1 = words_of(first, 1u, use_visibility);
    vis2 = words_of(first, 2u, use_visibility);
    vis3 = words_of(first, 3u, use_visibility);
    vis4 = words_of(first, 4u, use_visibility);
    vis5 = words_of(first, 5u, use_visibility);
    vis6 = words_of(first, 6u, use_visibility);
    vis7 = words_of(first, 7u, use_visibility);
}

// True on a CPU device (`vals::sparse::VisibilityLookup`): llvmpipe runs every case of a switch under
// a mask, and with the switch the gather took 10–15 % longer on lavapipe (16k VALs × 4k points,
// with or without visibility, since the lookup ran either way before GATHER_VISIBILITY). A
// GPU branches on the uniform word index, and keeps the switch it was measured with.
override VISIBILITY_SELECT_TREE: bool = true;

fn slot_words(w: u32) -> vec4<u32> {
    if (VISIBILITY_SELECT_TREE) {
        let b0 = (w & 1u) != 0u;
        let b1 = (w & 2u) != 0u;
        let low = select(select(vis0, vis1, b0), select(vis2, vis3, b0), b1);
        let high = select(select(vis4, vis5, b0), select(vis6, vis7, b0), b1);
        return select(low, high, (w & 4u) != 0u);
    }
    switch w {
        case 0u: { return vis0; }
        case 1u: { return vis1; }
        case 2u: { return vis2; }
        case 3u: { return vis3; }
        case 4u: { return vis4; }
        case 5u: { return vis5; }
        case 6u: { return vis6; }
        default: { return vis7; }
    }
}

// One VAL at each of this invocation's points. Written out, not a loop: llvmpipe counts every
// loop iteration against its per-invocation limit (see the VAL loop below).
fn accumulate_all(val: Val, glossy_on: bool, flux_weights: bool, use_visibility: bool) {
    var v = vec4<f32>(1.0);
    if (use_visibility && GATHER_VISIBILITY) {
        let cluster = val_cluster(val);
        let words = slot_words(min(cluster / 4u, VISIBILITY_WORDS - 1u));
        v = vec4<f32>(
            cluster_visibility(cluster, words.x),
            cluster_visibility(cluster, words.y),
            cluster_visibility(cluster, words.z),
            cluster_visibility(cluster, words.w),
        );
    }
    var s0 = all_sums[0];
    var s1 = all_sums[1];
    var s2 = all_sums[2];
    var s3 = all_sums[3];
    accumulate(&s0, points[0], mirrors[0], val, v.x, glossy_on, flux_weights);
    accumulate(&s1, points[1], mirrors[1], val, v.y, glossy_on, flux_weights);
    accumulate(&s2, points[2], mirrors[2], val, v.z, glossy_on, flux_weights);
    accumulate(&s3, points[3], mirrors[3], val, v.w, glossy_on, flux_weights);
    all_sums[0] = s0;
    all_sums[1] = s1;
    all_sums[2] = s2;
    all_sums[3] = s3;
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
    // The workgroup's GROUP · POINTS_PER_INVOCATION points, strided by GROUP so that the
    // invocations of a SIMD row read neighbouring points.
    let first = (linear_index(gid, groups) / GROUP) * GROUP * POINTS_PER_INVOCATION + lid;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let flux_weights = (params.flags & FLAG_FLUX_WEIGHTS) != 0u;
    let use_visibility = (params.flags & FLAG_VISIBILITY) != 0u;

    // Written out, not a loop, so that the per-slot arrays are indexed by constants only.
    var any_active = load_slot(0u, first + 0u * GROUP);
    any_active = load_slot(1u, first + 1u * GROUP) || any_active;
    any_active = load_slot(2u, first + 2u * GROUP) || any_active;
    any_active = load_slot(3u, first + 3u * GROUP) || any_active;
    load_visibility(first, use_visibility);

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
    write_slot(0u, first, count, glossy_on, gid.z, slices);
    write_slot(1u, first, count, glossy_on, gid.z, slices);
    write_slot(2u, first, count, glossy_on, gid.z, slices);
    write_slot(3u, first, count, glossy_on, gid.z, slices);
}

fn write_slot(q: u32, first: u32, count: u32, glossy_on: bool, slice: u32, slices: u32) {
    let index = first + q * GROUP;
    if (index >= params.point_count) {
        return;
    }
    if (slices > 1u) {
        partial_store((slice * params.point_count + index) * PARTIAL_VEC4S, all_sums[q]);
    } else {
        write_point(index, points[q], all_sums[q], count, glossy_on);
    }
}

