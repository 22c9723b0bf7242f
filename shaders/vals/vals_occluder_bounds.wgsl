// Bounds of every tile of occluder discs, for the occlusion pass to skip tiles that cannot
// hide any of a point's light and to take far ones whole (CPU twin:
// `vals::math::occluder_bounds`): per tile of `params.tile` points, BOUNDS_VEC4S vec4 — the
// centre and radius of a sphere around its disc centres; the largest disc radius, Σπρ² and
// the disc count; Σπρ²|n|; Σπρ² n nᵀ (diagonal, then xy, xz, yz), with the half size of the
// centres' box in the last three w — then the same for every
// super-tile of SUPER_TILE tiles, so that far regions cost the occlusion pass one test per
// super-tile. The tile invocations also write every point's disc in world space.
#include "vals_common.wgsl"

const TILE_MAX: u32 = 256u;
const SUPER_TILE: u32 = 64u;
const BOUNDS_VEC4S: u32 = 5u;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> occluder_bounds: array<vec4<f32>>;
// Per point, its disc in world space: (centre, radius), (normal, 0).
@group(0) @binding(5) var<storage, read_write> occluder_discs: array<vec4<f32>>;

fn point_at(i: u32) -> WorldPoint {
    let point_meta = points_meta[i];
    return world_point(points_model[i], point_meta, instances[point_meta.y]);
}

// The bounds of points [first, end) into slot `slot`.
fn write_bounds(first: u32, end: u32, slot: u32) {
    var lo = vec3<f32>(3.4e38);
    var hi = vec3<f32>(-3.4e38);
    var max_disc_radius = 0.0;
    var area = 0.0;
    var axes = vec3<f32>(0.0);
    var diagonal = vec3<f32>(0.0);
    var off = vec3<f32>(0.0);
    for (var i = first; i < end; i++) {
        let p = point_at(i);
        lo = min(lo, p.position);
        hi = max(hi, p.position);
        max_disc_radius = max(max_disc_radius, p.disc_radius);
        let a = PI * p.disc_radius * p.disc_radius;
        let n = p.normal;
        area += a;
        axes += a * abs(n);
        diagonal += a * n * n;
        off += a * vec3<f32>(n.x * n.y, n.x * n.z, n.y * n.z);
    }
    let centre = 0.5 * (lo + hi);
    var radius = 0.0;
    for (var i = first; i < end; i++) {
        radius = max(radius, length(point_at(i).position - centre));
    }
    let base = BOUNDS_VEC4S * slot;
    occluder_bounds[base] = vec4<f32>(centre, radius);
    occluder_bounds[base + 1u] = vec4<f32>(max_disc_radius, area, f32(end - first), 0.0);
    let half_extent = 0.5 * (hi - lo);
    occluder_bounds[base + 2u] = vec4<f32>(axes, half_extent.x);
    occluder_bounds[base + 3u] = vec4<f32>(diagonal, half_extent.y);
    occluder_bounds[base + 4u] = vec4<f32>(off, half_extent.z);
}

// One invocation per tile, then one per super-tile (SUPER_TILE tiles), whose bounds follow
// the tiles' in the buffer.
@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let tile = clamp(params.tile, 1u, TILE_MAX);
    let index = linear_index(gid, groups);
    let tiles = (params.point_count + tile - 1u) / tile;
    if (index < tiles) {
        let first = index * tile;
        for (var i = first; i < min(first + tile, params.point_count); i++) {
            let p = point_at(i);
            occluder_discs[2u * i] = vec4<f32>(p.position, p.disc_radius);
            occluder_discs[2u * i + 1u] = vec4<f32>(p.normal, 0.0);
        }
        write_bounds(first, min(first + tile, params.point_count), index);
        return;
    }
    let span = tile * SUPER_TILE;
    let first = (index - tiles) * span;
    if (first < params.point_count) {
        write_bounds(first, min(first + span, params.point_count), index);
    }
}
