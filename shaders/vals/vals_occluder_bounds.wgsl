// The occlusion tree (CPU twin: `vals::math::occlusion_tree`). Three stages, one dispatch
// each, each reading what the one before wrote:
// - `cs_main`: every point's disc in world space, written at its place in the walk order (the
//   points' Morton order, `vals::math::walk_order`), so that a tile of consecutive discs is a
//   compact patch across instances too;
// - `cs_tiles`: per tile of `params.tile` discs of the walk, BOUNDS_VEC4S vec4 — the centre
//   and radius of a sphere around its disc centres; the half size of their box and the
//   largest disc radius (`vals::math::occluder_bounds`);
// - `cs_nodes`: per internal node (FANOUT children a node, level by level up to one root, after
//   the tiles), the same from the tiles under it (`vals::math::combine_bounds`: the box around
//   their boxes, a sphere from its centre around their spheres).
#include "vals_common.wgsl"

const TILE_MAX: u32 = 256u;
const FANOUT: u32 = 8u;
const BOUNDS_VEC4S: u32 = 2u;
// Levels of the tree at most: 8⁸ tiles are more than any point count.
const LEVELS_MAX: u32 = 9u;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> occluder_bounds: array<vec4<f32>>;
// Per disc of the walk: (centre, radius), (normal, 0).
@group(0) @binding(5) var<storage, read_write> occluder_discs: array<vec4<f32>>;
// Per point, its place in the walk.
@group(0) @binding(6) var<storage, read> occluder_walk: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let i = linear_index(gid, groups);
    if (i >= params.point_count) {
        return;
    }
    let point_meta = points_meta[i];
    let p = world_point(points_model[i], point_meta, instances[point_meta.y]);
    let place = occluder_walk[i];
    occluder_discs[2u * place] = vec4<f32>(p.position, p.disc_radius);
    occluder_discs[2u * place + 1u] = vec4<f32>(p.normal, 0.0);
}

@compute @workgroup_size(64, 1, 1)
fn cs_tiles(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let tile = clamp(params.tile, 1u, TILE_MAX);
    let index = linear_index(gid, groups);
    let first = index * tile;
    if (first >= params.point_count) {
        return;
    }
    let end = min(first + tile, params.point_count);
    var lo = vec3<f32>(3.4e38);
    var hi = vec3<f32>(-3.4e38);
    var max_disc_radius = 0.0;
    for (var i = first; i < end; i++) {
        let c = occluder_discs[2u * i];
        lo = min(lo, c.xyz);
        hi = max(hi, c.xyz);
        max_disc_radius = max(max_disc_radius, c.w);
    }
    let centre = 0.5 * (lo + hi);
    var radius = 0.0;
    for (var i = first; i < end; i++) {
        radius = max(radius, length(occluder_discs[2u * i].xyz - centre));
    }
    write_bounds(index, centre, radius, 0.5 * (hi - lo), max_disc_radius);
}

fn write_bounds(slot: u32, centre: vec3<f32>, radius: f32, half_extent: vec3<f32>, max_disc_radius: f32) {
    occluder_bounds[BOUNDS_VEC4S * slot] = vec4<f32>(centre, radius);
    occluder_bounds[BOUNDS_VEC4S * slot + 1u] = vec4<f32>(half_extent, max_disc_radius);
}

@compute @workgroup_size(64, 1, 1)
fn cs_nodes(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let tile = clamp(params.tile, 1u, TILE_MAX);
    let tiles = (params.point_count + tile - 1u) / tile;
    // Which internal level and node this invocation is, and the tiles under the node.
    var index = linear_index(gid, groups);
    var level_size = tiles;
    var slot = tiles;
    var span = 1u;
    var found = false;
    for (var level = 1u; level < LEVELS_MAX && level_size > 1u; level++) {
        level_size = (level_size + FANOUT - 1u) / FANOUT;
        span *= FANOUT;
        if (index < level_size) {
            slot += index;
            found = true;
            break;
        }
        index -= level_size;
        slot += level_size;
    }
    if (!found) {
        return;
    }
    let first = index * span;
    let end = min(first + span, tiles);
    // The root spans every tile; llvmpipe ends a loop after 65535 iterations per invocation,
    // so each loop takes 16 tiles an iteration (a million tiles).
    var node = Node(vec3<f32>(3.4e38), vec3<f32>(-3.4e38), 0.0);
    for (var t = first; t < end; t += 16u) {
        for_box(&node, t + 0u, end);
        for_box(&node, t + 1u, end);
        for_box(&node, t + 2u, end);
        for_box(&node, t + 3u, end);
        for_box(&node, t + 4u, end);
        for_box(&node, t + 5u, end);
        for_box(&node, t + 6u, end);
        for_box(&node, t + 7u, end);
        for_box(&node, t + 8u, end);
        for_box(&node, t + 9u, end);
        for_box(&node, t + 10u, end);
        for_box(&node, t + 11u, end);
        for_box(&node, t + 12u, end);
        for_box(&node, t + 13u, end);
        for_box(&node, t + 14u, end);
        for_box(&node, t + 15u, end);
    }
    let centre = 0.5 * (node.lo + node.hi);
    var radius = 0.0;
    for (var t = first; t < end; t += 16u) {
        radius = max(radius, reach(t + 0u, end, centre));
        radius = max(radius, reach(t + 1u, end, centre));
        radius = max(radius, reach(t + 2u, end, centre));
        radius = max(radius, reach(t + 3u, end, centre));
        radius = max(radius, reach(t + 4u, end, centre));
        radius = max(radius, reach(t + 5u, end, centre));
        radius = max(radius, reach(t + 6u, end, centre));
        radius = max(radius, reach(t + 7u, end, centre));
        radius = max(radius, reach(t + 8u, end, centre));
        radius = max(radius, reach(t + 9u, end, centre));
        radius = max(radius, reach(t + 10u, end, centre));
        radius = max(radius, reach(t + 11u, end, centre));
        radius = max(radius, reach(t + 12u, end, centre));
        radius = max(radius, reach(t + 13u, end, centre));
        radius = max(radius, reach(t + 14u, end, centre));
        radius = max(radius, reach(t + 15u, end, centre));
    }
    write_bounds(slot, centre, radius, 0.5 * (node.hi - node.lo), node.max_disc_radius);
}

// A node's box of disc centres and largest disc, grown tile by tile.
struct Node {
    lo: vec3<f32>,
    hi: vec3<f32>,
    max_disc_radius: f32,
}

// Grows `node` by tile `t`'s box and discs when t < end.
fn for_box(node: ptr<function, Node>, t: u32, end: u32) {
    if (t >= end) {
        return;
    }
    let sphere = occluder_bounds[BOUNDS_VEC4S * t];
    let sizes = occluder_bounds[BOUNDS_VEC4S * t + 1u];
    (*node).lo = min((*node).lo, sphere.xyz - sizes.xyz);
    (*node).hi = max((*node).hi, sphere.xyz + sizes.xyz);
    (*node).max_disc_radius = max((*node).max_disc_radius, sizes.w);
}

// How far tile `t`'s sphere reaches from `centre` (0 when t ≥ end).
fn reach(t: u32, end: u32, centre: vec3<f32>) -> f32 {
    if (t >= end) {
        return 0.0;
    }
    let sphere = occluder_bounds[BOUNDS_VEC4S * t];
    return length(sphere.xyz - centre) + sphere.w;
}
