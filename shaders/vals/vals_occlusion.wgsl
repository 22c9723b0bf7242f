// Occlusion (optional): every other sparse point is an occluder disc. Seen from x, the light
// sphere and each disc are projected onto x's unit tangent disc and treated as axis-aligned
// squares of their projected areas; a disc hides overlap/sphere-area of the light, ramped to 0
// between the sphere's front and its centre. Shares add (`sum`, the paper's) or combine as
// independent blockers (`union`: 1 − Π(1 − o_i)). Intensities are scaled by 1 − o in place.
// A tile of discs none of which can take a share of a point's light sphere is skipped
// (`tile_may_occlude`, from `vals_occluder_bounds.wgsl`'s bounds; CPU twin
// `vals::math::tile_may_occlude`): the result is the same to the bit, and far tiles cost one
// test instead of a tile of discs — and a super-tile of SUPER_TILE tiles none of which can is
// skipped with one test (its bounds contain all its discs' centres, so the same test is safe),
// which keeps the pass near-linear in the points when most of the scene is far.
#include "vals_common.wgsl"
#include "vals_occluder_share.wgsl"

const GROUP: u32 = 64u;
const TILE_MAX: u32 = 256u;
const SUPER_TILE: u32 = 64u;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> point_diffuse: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> point_glossy: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> point_extra: array<vec2<u32>>;
// Per tile, then per super-tile: (centre of its disc centres, radius), (largest disc radius,
// 0, 0, 0).
@group(0) @binding(7) var<storage, read> occluder_bounds: array<vec4<f32>>;

var<workgroup> tile_discs: array<Disc, TILE_MAX>;
// 1 when some invocation of the workgroup needs the current tile (super-tile).
var<workgroup> tile_needed: u32;
var<workgroup> super_needed: u32;

// Whether the tile or super-tile in bounds slot `slot` may hide one of the point's lights.
fn slot_may_occlude(slot: u32, x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, lights: PointLights, glossy_on: bool) -> bool {
    let bounds = occluder_bounds[2u * slot];
    let max_disc_radius = occluder_bounds[2u * slot + 1u].x;
    return tile_may_occlude(x, n, t, b, lights.diffuse_position, lights.diffuse_sphere, bounds, max_disc_radius)
        || (glossy_on && tile_may_occlude(x, n, t, b, lights.glossy_position, lights.glossy_sphere, bounds, max_disc_radius));
}

// False only when no disc of the tile can take a share of the sphere (centre `light`, radius
// `sphere`) seen from x; see `vals::math::tile_may_occlude` for why each test is safe.
fn tile_may_occlude(x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, light: vec3<f32>, sphere: f32, bounds: vec4<f32>, max_disc_radius: f32) -> bool {
    let to_light = light - x;
    let light_distance = length(to_light);
    if (sphere <= 0.0 || light_distance <= 0.0 || max_disc_radius <= 0.0) {
        return false;
    }
    let v = bounds.xyz - x;
    let distance = length(v);
    let r = bounds.w;
    if (distance <= r * 1.001 + 1e-6) {
        return true;
    }
    if (dot(n, v) + r < 0.0 || distance - r >= light_distance) {
        return false;
    }
    let wl = to_light / light_distance;
    let wc = v / distance;
    let alpha = asin(min(r / distance, 1.0));
    let sphere_area = PI * sphere * sphere / (sphere * sphere + light_distance * light_distance);
    let nearest = distance - r;
    let disc_area = PI * max_disc_radius * max_disc_radius / (max_disc_radius * max_disc_radius + nearest * nearest);
    let reach = 0.5 * sqrt(sphere_area) + 0.5 * sqrt(disc_area) + alpha + 1e-4;
    return abs(dot(wl - wc, t)) < reach && abs(dot(wl - wc, b)) < reach;
}

// Running occlusion of one point's two lights: Σo and Π(1 − o) per channel.
struct Shares {
    sum_d: f32,
    visible_d: f32,
    sum_s: f32,
    visible_s: f32,
}

struct Receiver {
    x: vec3<f32>,
    n: vec3<f32>,
    t: vec3<f32>,
    b: vec3<f32>,
}

fn add_occluder(shares: ptr<function, Shares>, rcv: Receiver, lights: PointLights, disc: Disc, glossy_on: bool) {
    let od = occluder_share(rcv.x, rcv.n, rcv.t, rcv.b, lights.diffuse_position, lights.diffuse_sphere, disc);
    (*shares).sum_d += od;
    (*shares).visible_d *= 1.0 - od;
    if (glossy_on) {
        let os = occluder_share(rcv.x, rcv.n, rcv.t, rcv.b, lights.glossy_position, lights.glossy_sphere, disc);
        (*shares).sum_s += os;
        (*shares).visible_s *= 1.0 - os;
    }
}

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let tile = clamp(params.tile, 1u, TILE_MAX);
    let index = linear_index(gid, groups);
    let is_active = index < params.point_count;
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    var point: WorldPoint;
    var lights: PointLights;
    var t = vec3<f32>(0.0);
    var b = vec3<f32>(0.0);
    var d = vec4<u32>(0u);
    var s = vec4<u32>(0u);
    if (is_active) {
        let point_meta = points_meta[index];
        point = world_point(points_model[index], point_meta, instances[point_meta.y]);
        d = point_diffuse[index];
        s = point_glossy[index];
        lights = decode_lights(point.position, d, s, point_extra[index]);
        t = tangent_frame_t(point.normal);
        b = tangent_frame_b(point.normal);
    }
    var shares = Shares(0.0, 1.0, 0.0, 1.0);
    let tiles = (params.point_count + tile - 1u) / tile;
    let span = tile * SUPER_TILE;
    for (var super_base = 0u; super_base < params.point_count; super_base += span) {
        // Uniform control flow around the barriers: every invocation runs every iteration and
        // only the active ones vote.
        var super_may = false;
        if (is_active) {
            super_may = slot_may_occlude(tiles + super_base / span, point.position, point.normal, t, b, lights, glossy_on);
        }
        if (lid == 0u) {
            super_needed = 0u;
        }
        workgroupBarrier();
        if (super_may) {
            super_needed = 1u;
        }
        if (workgroupUniformLoad(&super_needed) == 0u) {
            continue;
        }
        let super_end = min(super_base + span, params.point_count);
        for (var base = super_base; base < super_end; base += tile) {
            var needed = false;
            if (is_active && super_may) {
                needed = slot_may_occlude(base / tile, point.position, point.normal, t, b, lights, glossy_on);
            }
            if (lid == 0u) {
                tile_needed = 0u;
            }
            workgroupBarrier();
            if (needed) {
                tile_needed = 1u;
            }
            if (workgroupUniformLoad(&tile_needed) == 0u) {
                continue;
            }
            let m = min(tile, params.point_count - base);
            for (var i = lid; i < m; i += GROUP) {
                let point_meta = points_meta[base + i];
                let p = world_point(points_model[base + i], point_meta, instances[point_meta.y]);
                tile_discs[i] = Disc(vec4<f32>(p.position, p.disc_radius), vec4<f32>(p.normal, 0.0));
            }
            workgroupBarrier();
            if (is_active && needed) {
                // The point's own disc is in the list: at distance 0 from the point,
                // occluder_share gives it exactly 0, so it needs no test. Written out 4 at a
                // time for llvmpipe's loop limit (see vals_gather.wgsl).
                let rcv = Receiver(point.position, point.normal, t, b);
                var j = 0u;
                let full = m - m % 4u;
                while (j < full) {
                    add_occluder(&shares, rcv, lights, tile_discs[j + 0u], glossy_on);
                    add_occluder(&shares, rcv, lights, tile_discs[j + 1u], glossy_on);
                    add_occluder(&shares, rcv, lights, tile_discs[j + 2u], glossy_on);
                    add_occluder(&shares, rcv, lights, tile_discs[j + 3u], glossy_on);
                    j += 4u;
                }
                while (j < m) {
                    add_occluder(&shares, rcv, lights, tile_discs[j], glossy_on);
                    j += 1u;
                }
            }
            workgroupBarrier();
        }
    }
    if (!is_active) {
        return;
    }
    var od = min(shares.sum_d, 1.0);
    var os = min(shares.sum_s, 1.0);
    if (params.occlusion_mode == 2u) {
        od = 1.0 - shares.visible_d;
        os = 1.0 - shares.visible_s;
    }
    point_glossy[index] = vec4<u32>(rgb_bits(lights.glossy * (1.0 - os)), s.w);
    if ((params.flags & FLAG_GLOSSY_ONLY) == 0u) {
        point_diffuse[index] = vec4<u32>(rgb_bits(lights.diffuse * (1.0 - od)), d.w);
    }
}
