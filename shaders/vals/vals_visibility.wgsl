// Visibility of the VAL clusters at the sparse points (`--occlusion rays`): for each point and
// cluster, shadow rays through the scene's BVH to the VALs at the cluster's sample strata,
// weighted by what each would contribute (flux · disc geometry), give the visible fraction
// V ∈ [0, 1], stored as one byte. The gather then scales every VAL by its cluster's V, so a
// point sees the light that reaches it through a doorway and not the light behind the wall.
// A depth sensor's VALs (mixed reality) add their image's tiles as clusters after the RSM's,
// and the sensor's depth blocks rays too (group 2; without a sensor it has no tiles and no
// frame).
// CPU twin: `vals::visibility::cluster_visibility`.
#include "vals_common.wgsl"
#include "bvh.wgsl"

const MAX_CLUSTERS: u32 = 32u;
// Also CLUSTER_SAMPLE_SIDE, the strata per tile side.
#include "sensor_occluder.wgsl"
// Ray ends are pulled off both surfaces by this fraction of the segment's length.
const RAY_OFFSET: f32 = 2e-3;
// Most RSM tiles a cluster shoots at (each CLUSTER_SAMPLE_SIDE² rays): with more tiles than
// MAX_CLUSTERS · this (hundreds of lights), an evenly strided subset stands for the rest.
const MAX_RAY_TILES: u32 = 4u;
// False in the pipeline for solutions without a depth sensor: a uniform test alone leaves the
// sensor's candidates and depth march in every ray's code, and llvmpipe runs both sides of a
// branch (and a loop's body once) under a mask.
override SENSOR_RAYS: bool = true;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
// The VALs as texels (`ValTexels` in `src/vals/sparse.rs`): VAL i at texels 3i..3i+2, read
// with the BVH's texel addressing. Every lane of a workgroup (one cluster) reads the same
// sample VAL; llvmpipe reads that from a storage buffer lane by lane.
@group(0) @binding(4) var val_texels: texture_2d<u32>;
@group(0) @binding(5) var<storage, read> cluster_samples: array<u32>;
// Per point MAX_CLUSTERS / 4 words, four clusters' V·255 per word (low byte first); cleared
// before the pass, each invocation ORs in its byte.
@group(0) @binding(6) var<storage, read_write> visibility: array<atomic<u32>>;
// Last frame's bytes, blended in by params.visibility_history percent.
@group(0) @binding(7) var<storage, read> visibility_history: array<u32>;

// Strata on even rows and columns of a tile's CLUSTER_SAMPLE_SIDE² grid: a 2×2 grid spread
// over the tile.
fn is_coarse_stratum(s: u32) -> bool {
    return ((s % CLUSTER_SAMPLE_SIDE) & 1u) == 0u && ((s / CLUSTER_SAMPLE_SIDE) & 1u) == 0u;
}

// The sample VAL of one stratum slot as a shadow ray's target.
struct StratumSample {
    // Φ·g at the point (0: no VAL in the stratum, or it does not reach the point).
    weight: f32,
    // Both ray ends are pulled off their surfaces by this (RAY_OFFSET · distance).
    offset: f32,
    // The ray's far end, pulled off the VAL's surface along its normal.
    end: vec3<f32>,
}

fn val_texel_record(i: u32) -> Val {
    return Val(
        bitcast<vec4<f32>>(bvh_texel(val_texels, 3u * i)),
        bitcast<vec4<f32>>(bvh_texel(val_texels, 3u * i + 1u)),
        bitcast<vec4<f32>>(bvh_texel(val_texels, 3u * i + 2u)),
    );
}

// Candidate `k` of stratum `s` of tile `tile`: an RSM tile's sample slot, or past the RSM's
// tiles a sensor tile's surfel (area 0: none).
fn candidate_val(tile: u32, s: u32, k: u32) -> Val {
    if (SENSOR_RAYS && tile >= params.rsm_tiles) {
        return sensor_stratum_sample(tile - params.rsm_tiles, s, k);
    }
    let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
    let slot = cluster_samples[(tile * per_tile + s) * SAMPLE_CANDIDATES + k];
    var val: Val;
    if (slot == 0u) {
        val.position_area = vec4<f32>(0.0);
        return val;
    }
    return val_texel_record(slot - 1u);
}

// Stratum `s` of tile `tile` as a ray target: its first candidate (centre, then corners)
// whose VAL reaches the point.
fn stratum_sample(point: WorldPoint, tile: u32, s: u32) -> StratumSample {
    var out: StratumSample;
    for (var k = 0u; k < SAMPLE_CANDIDATES; k++) {
        let val = candidate_val(tile, s, k);
        if (val.position_area.w <= 0.0) {
            continue;
        }
        let g = disc_terms(point.position, point.normal, val).g;
        let weight = g * (val.flux.r + val.flux.g + val.flux.b);
        if (!(weight > 0.0)) {
            continue;
        }
        let l = val.position_area.xyz;
        out.weight = weight;
        out.offset = RAY_OFFSET * length(l - point.position);
        out.end = l + val.normal.xyz * out.offset;
        return out;
    }
    return out;
}

fn sample_visible(point: WorldPoint, sample: StratumSample) -> bool {
    let start = point.position + point.normal * sample.offset;
    if (!SENSOR_RAYS) {
        return !segment_occluded(start, sample.end);
    }
    return !segment_occluded(start, sample.end) && !sensor_blocks(start, sample.end);
}

// V of `cluster` at the point: the weighted fraction of its strata's samples the rays see.
fn cluster_visibility(point: WorldPoint, cluster: u32) -> f32 {
    let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
    var seen = 0.0;
    var total = 0.0;
    let all_tiles = params.rsm_tiles + sensor_tile_count();
    var tiles_in_cluster = 0u;
    if (cluster < all_tiles) {
        tiles_in_cluster = (all_tiles - cluster + MAX_CLUSTERS - 1u) / MAX_CLUSTERS;
    }
    let stride = max(1u, (tiles_in_cluster + MAX_RAY_TILES - 1u) / MAX_RAY_TILES) * MAX_CLUSTERS;
    let adaptive = (params.flags & FLAG_ADAPTIVE_RAYS) != 0u;
    for (var tile = cluster; tile < all_tiles; tile += stride) {
        // Adaptive: the 2×2 coarse strata (even row and column) first; when every one of them
        // that reaches the point gives the same answer, the other strata are taken to give it
        // too (their weights still count), else they get their own rays.
        var coarse_seen = false;
        var coarse_hidden = false;
        for (var s = 0u; s < per_tile; s++) {
            if (adaptive && !is_coarse_stratum(s)) {
                continue;
            }
            let sample = stratum_sample(point, tile, s);
            if (sample.weight <= 0.0) {
                continue;
            }
            total += sample.weight;
            if (sample_visible(point, sample)) {
                seen += sample.weight;
                coarse_seen = true;
            } else {
                coarse_hidden = true;
            }
        }
        if (!adaptive) {
            continue;
        }
        let unanimous = coarse_seen != coarse_hidden;
        for (var s = 0u; s < per_tile; s++) {
            if (is_coarse_stratum(s)) {
                continue;
            }
            let sample = stratum_sample(point, tile, s);
            if (sample.weight <= 0.0) {
                continue;
            }
            total += sample.weight;
            if (unanimous) {
                seen += select(0.0, sample.weight, coarse_seen);
            } else if (sample_visible(point, sample)) {
                seen += sample.weight;
            }
        }
    }
    // A cluster none of whose samples reaches the point keeps V = 1: the rays say nothing
    // about it, and its VALs contribute little there.
    if (total <= 0.0) {
        return 1.0;
    }
    return seen / total;
}

// One invocation per (point, cluster): x = point, y = cluster.
@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    // Points along x (wrapping into z past the device's limit), clusters along y.
    let index = gid.x + gid.z * groups.x * 64u;
    let cluster = gid.y;
    if (index >= params.point_count || cluster >= MAX_CLUSTERS) {
        return;
    }
    let point_meta = points_meta[index];
    let point = world_point(points_model[index], point_meta, instances[point_meta.y]);
    let word = index * (MAX_CLUSTERS / 4u) + cluster / 4u;
    let shift = 8u * (cluster % 4u);
    var v = clamp(cluster_visibility(point, cluster), 0.0, 1.0);
    let keep = f32(min(params.visibility_history, 100u)) / 100.0;
    if (keep > 0.0) {
        let previous = f32((visibility_history[word] >> shift) & 255u) / 255.0;
        v = mix(v, previous, keep);
    }
    let byte = u32(round(v * 255.0));
    atomicOr(&visibility[word], byte << shift);
}
