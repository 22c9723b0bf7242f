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
// which keeps the pass near-linear in the points when most of the scene is far. Before that,
// the workgroup tests every super-tile once against a ball around all its receivers grown by
// their longest light distance (`ball_may_reach`, CPU twin `vals::math::ball_may_reach`, safe
// by the same argument): the receivers' own tests then run only on the few super-tiles near
// the group, so the pass no longer costs every point one test per super-tile of the scene.
// A tile or super-tile far from the point (radius ≤ `occlusion_far` × distance) counts whole,
// as a grey square of its discs' summed projected area from its area moments (`far_share`,
// CPU twin `vals::math::far_share`), per light: a point's lights each open, take whole or skip a
// slot, and the discs of an opened tile count only for the lights that opened it. The CPU
// twin of the whole traversal is `vals::math::occlusion`.
#include "vals_common.wgsl"
#include "vals_occluder_share.wgsl"

const GROUP: u32 = 64u;
const TILE_MAX: u32 = 256u;
const SUPER_TILE: u32 = 64u;
const BOUNDS_VEC4S: u32 = 5u;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> point_diffuse: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> point_glossy: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> point_extra: array<vec2<u32>>;
// Per tile, then per super-tile, BOUNDS_VEC4S vec4 (`vals_occluder_bounds.wgsl`).
@group(0) @binding(7) var<storage, read> occluder_bounds: array<vec4<f32>>;
// Per point, its disc in world space: (centre, radius), (normal, 0).
@group(0) @binding(8) var<storage, read> occluder_discs: array<vec4<f32>>;

// Super-tile masks of at most 32·MASK_WORDS super-tiles (a million points at tile 1); more
// and the group test is skipped.
const MASK_WORDS: u32 = 512u;

// Per receiver: position, and the distance to its farthest light with a sphere (< 0: none).
var<workgroup> group_receivers: array<vec4<f32>, GROUP>;
// The group's ball (centre, radius; radius < 0: nothing to occlude).
var<workgroup> group_ball: vec4<f32>;
// Bit s: super-tile s may hold an occluder of some receiver of the group.
var<workgroup> super_mask: array<atomic<u32>, MASK_WORDS>;
var<workgroup> super_words: array<u32, MASK_WORDS>;

// False only when no disc of the tile can take a share of the sphere (centre `light`, radius
// `sphere`) seen from x; see `vals::math::tile_may_occlude` for why each test is safe.
fn tile_may_occlude(x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, light: vec3<f32>, sphere: f32, bounds: vec4<f32>, max_disc_radius: f32, half_extent: vec3<f32>) -> bool {
    let to_light = light - x;
    let light_distance = length(to_light);
    if (sphere <= 0.0 || light_distance <= 0.0 || max_disc_radius <= 0.0) {
        return false;
    }
    let v = bounds.xyz - x;
    if (dot(n, v) + dot(abs(n), half_extent) <= 0.0) {
        return false;
    }
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

// `vals::math::OccluderBounds::projected_area`: Σπρ²|n·w| from above.
fn projected_area(slot: u32, w: vec3<f32>) -> f32 {
    let base = BOUNDS_VEC4S * slot;
    let area = occluder_bounds[base + 1u].y;
    let axes = occluder_bounds[base + 2u].xyz;
    let d = occluder_bounds[base + 3u].xyz;
    let o = occluder_bounds[base + 4u].xyz;
    let quadratic = d.x * w.x * w.x + d.y * w.y * w.y + d.z * w.z * w.z
        + 2.0 * (o.x * w.x * w.y + o.y * w.x * w.z + o.z * w.y * w.z);
    let cauchy_schwarz = sqrt(area * max(quadratic, 0.0));
    return min(cauchy_schwarz, dot(axes, abs(w)));
}

// The summed shares of the slot's discs when it is far, taken as a grey square of their
// summed projected area; −1 when it is not far (see `vals::math::far_share`).
fn far_share(slot: u32, x: vec3<f32>, n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, light: vec3<f32>, sphere: f32) -> f32 {
    let base = BOUNDS_VEC4S * slot;
    let bounds = occluder_bounds[base];
    let sizes = occluder_bounds[base + 1u];
    let to_light = light - x;
    let light_distance = length(to_light);
    let v = bounds.xyz - x;
    let distance = length(v);
    let r = bounds.w;
    let far = params.occlusion_far;
    if (far <= 0.0 || sphere <= 0.0 || light_distance <= 0.0 || sizes.z < 0.5
        || r + sizes.x > far * distance || distance + r >= light_distance || dot(n, v) <= r) {
        return -1.0;
    }
    let wl = to_light / light_distance;
    let wc = v / distance;
    let alpha = asin(min(r / distance, 1.0));
    let sphere_area = PI * sphere * sphere / (sphere * sphere + light_distance * light_distance);
    let rd = sizes.x;
    let nearest = distance - r;
    let disc_half = 0.5 * sqrt(PI * rd * rd / (rd * rd + nearest * nearest));
    let tile_side = 2.0 * (alpha + disc_half);
    let tile_area = tile_side * tile_side;
    let overlap = square_overlap(vec2<f32>(dot(wl, t), dot(wl, b)), sphere_area, vec2<f32>(dot(wc, t), dot(wc, b)), tile_area);
    let mean_radius2 = sizes.y / (PI * sizes.z);
    let area = projected_area(slot, wc) / (distance * distance + mean_radius2);
    let ramp = min((light_distance - distance) / sphere, 1.0);
    return area / sphere_area * (overlap / tile_area) * ramp;
}

// What one light of a point does with a slot: x = 0 skip it, 1 take it whole (y: the summed
// shares, z: the disc count), 2 open it.
fn visit_slot(slot: u32, rcv: Receiver, light: vec3<f32>, sphere: f32) -> vec3<f32> {
    let base = BOUNDS_VEC4S * slot;
    let half_extent = vec3<f32>(occluder_bounds[base + 2u].w, occluder_bounds[base + 3u].w, occluder_bounds[base + 4u].w);
    if (!tile_may_occlude(rcv.x, rcv.n, rcv.t, rcv.b, light, sphere, occluder_bounds[base], occluder_bounds[base + 1u].x, half_extent)) {
        return vec3<f32>(0.0);
    }
    let share = far_share(slot, rcv.x, rcv.n, rcv.t, rcv.b, light, sphere);
    if (share < 0.0) {
        return vec3<f32>(2.0, 0.0, 0.0);
    }
    return vec3<f32>(1.0, share, occluder_bounds[base + 1u].z);
}

// Π(1 − o) of k discs of s/k each, for `union`.
fn whole_visible(visit: vec3<f32>) -> f32 {
    return pow(max(1.0 - visit.y / visit.z, 0.0), visit.z);
}

// The CPU twin is `vals::math::group_ball`; invocation 0 runs it over the receivers.
fn compute_group_ball() -> vec4<f32> {
    var lo = vec3<f32>(3.4e38);
    var hi = vec3<f32>(-3.4e38);
    var reach = -1.0;
    for (var i = 0u; i < GROUP; i++) {
        let r = group_receivers[i];
        if (r.w >= 0.0) {
            lo = min(lo, r.xyz);
            hi = max(hi, r.xyz);
            reach = max(reach, r.w);
        }
    }
    if (reach < 0.0) {
        return vec4<f32>(0.0, 0.0, 0.0, -1.0);
    }
    let centre = 0.5 * (lo + hi);
    var radius = 0.0;
    for (var i = 0u; i < GROUP; i++) {
        let r = group_receivers[i];
        if (r.w >= 0.0) {
            radius = max(radius, length(r.xyz - centre));
        }
    }
    return vec4<f32>(centre, radius + reach);
}

// See `vals::math::ball_may_reach`.
fn ball_may_reach(ball: vec4<f32>, bounds: vec4<f32>) -> bool {
    if (ball.w < 0.0) {
        return false;
    }
    let limit = (ball.w + 1.001 * bounds.w) * 1.0001 + 1e-5;
    return length(bounds.xyz - ball.xyz) <= limit;
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

// One disc's shares of the lights that opened its tile.
fn add_occluder(shares: ptr<function, Shares>, rcv: Receiver, lights: PointLights, disc: Disc, open_d: bool, open_s: bool) {
    if (open_d) {
        let od = occluder_share(rcv.x, rcv.n, rcv.t, rcv.b, lights.diffuse_position, lights.diffuse_sphere, disc);
        (*shares).sum_d += od;
        (*shares).visible_d *= 1.0 - od;
    }
    if (open_s) {
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
    let supers = (tiles + SUPER_TILE - 1u) / SUPER_TILE;
    let words = (supers + 31u) / 32u;
    let grouped = words <= MASK_WORDS;

    // The group's super-tiles: its ball, then each invocation tests a 64th of the super-tiles.
    var reach = -1.0;
    if (is_active) {
        if (lights.diffuse_sphere > 0.0) {
            reach = length(lights.diffuse_position - point.position);
        }
        if (glossy_on && lights.glossy_sphere > 0.0) {
            reach = max(reach, length(lights.glossy_position - point.position));
        }
    }
    group_receivers[lid] = vec4<f32>(point.position, reach);
    for (var w = lid; w < min(words, MASK_WORDS); w += GROUP) {
        atomicStore(&super_mask[w], 0u);
    }
    workgroupBarrier();
    if (lid == 0u) {
        group_ball = compute_group_ball();
    }
    workgroupBarrier();
    if (grouped) {
        let ball = group_ball;
        for (var i = lid; i < supers; i += GROUP) {
            if (ball_may_reach(ball, occluder_bounds[BOUNDS_VEC4S * (tiles + i)])) {
                atomicOr(&super_mask[i / 32u], 1u << (i % 32u));
            }
        }
    }
    workgroupBarrier();
    for (var w = lid; w < min(words, MASK_WORDS); w += GROUP) {
        super_words[w] = atomicLoad(&super_mask[w]);
    }

    for (var w = 0u; w < words; w++) {
        // Every invocation reads the same word (the first load is also the barrier after the
        // copy); the loop inside has no barriers, so it may part ways.
        var bits = 0xffffffffu;
        if (grouped) {
            bits = workgroupUniformLoad(&super_words[w]);
        }
        for (var k = 0u; k < 32u; k++) {
            let super_index = 32u * w + k;
            if (!is_active || super_index >= supers || (bits & (1u << k)) == 0u) {
                continue;
            }
            // Each light opens, takes whole or skips the super-tile, then its tiles; an opened
            // tile's discs count for the lights that opened it. No barriers: each invocation
            // walks its own way through the tiles.
            let super_base = super_index * span;
            let rcv = Receiver(point.position, point.normal, t, b);
            var super_d = 0u;
            var super_s = 0u;
            let vd = visit_slot(tiles + super_index, rcv, lights.diffuse_position, lights.diffuse_sphere);
            super_d = u32(vd.x);
            if (super_d == 1u) {
                shares.sum_d += vd.y;
                shares.visible_d *= whole_visible(vd);
            }
            if (glossy_on) {
                let vs = visit_slot(tiles + super_index, rcv, lights.glossy_position, lights.glossy_sphere);
                super_s = u32(vs.x);
                if (super_s == 1u) {
                    shares.sum_s += vs.y;
                    shares.visible_s *= whole_visible(vs);
                }
            }
            if (super_d != 2u && super_s != 2u) {
                continue;
            }
            let super_end = min(super_base + span, params.point_count);
            for (var base = super_base; base < super_end; base += tile) {
                var tile_d = 0u;
                var tile_s = 0u;
                if (super_d == 2u) {
                    let vd = visit_slot(base / tile, rcv, lights.diffuse_position, lights.diffuse_sphere);
                    tile_d = u32(vd.x);
                    if (tile_d == 1u) {
                        shares.sum_d += vd.y;
                        shares.visible_d *= whole_visible(vd);
                    }
                }
                if (super_s == 2u) {
                    let vs = visit_slot(base / tile, rcv, lights.glossy_position, lights.glossy_sphere);
                    tile_s = u32(vs.x);
                    if (tile_s == 1u) {
                        shares.sum_s += vs.y;
                        shares.visible_s *= whole_visible(vs);
                    }
                }
                let open_d = tile_d == 2u;
                let open_s = tile_s == 2u;
                if (!open_d && !open_s) {
                    continue;
                }
                // The point's own disc is in the tile: at distance 0 from the point,
                // occluder_share gives it exactly 0, so it needs no test.
                let end = min(base + tile, params.point_count);
                for (var j = base; j < end; j++) {
                    let disc = Disc(occluder_discs[2u * j], occluder_discs[2u * j + 1u]);
                    add_occluder(&shares, rcv, lights, disc, open_d, open_s);
                }
            }
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
