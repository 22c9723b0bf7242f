// Occlusion (optional): every other sparse point is an occluder disc. Seen from x, the light
// sphere and each disc are projected onto x's unit tangent disc and treated as axis-aligned
// squares of their projected areas; a disc hides overlap/sphere-area of the light, ramped to 0
// between the sphere's front and its centre. Shares add (`sum`, the paper's) or combine as
// independent blockers (`union`: 1 − Π(1 − o_i)). Intensities are scaled by 1 − o in place.
// The discs are walked depth first through the tree `vals_occluder_bounds.wgsl` builds (tiles
// of consecutive discs in walk order, FANOUT-ary internal nodes above them). Each light of a
// point skips a node none of whose discs can take a share of its sphere (`tile_may_occlude`,
// CPU twin `vals::math::tile_may_occlude`: the result is the same to the bit) or opens it; an
// opened tile's discs count for the lights that opened it, an opened node's children are taken
// nearest first, and a light closes once more discs cannot change it (`still_open`). Each
// invocation walks on its own, without barriers. The CPU twin of the whole walk is
// `vals::math::occlusion`.
#include "vals_common.wgsl"
#include "vals_occluder_share.wgsl"

const TILE_MAX: u32 = 256u;
const FANOUT: u32 = 8u;
const BOUNDS_VEC4S: u32 = 2u;
const LEVELS_MAX: u32 = 9u;
// Pending nodes at most: FANOUT − 1 siblings per level below the root, and the node itself.
const STACK_MAX: u32 = 64u;
// Below this visible fraction a light is closed under `union` (`vals::math::VISIBLE_CLOSED`).
const VISIBLE_CLOSED: f32 = 9.5367431640625e-7;

@group(0) @binding(0) var<storage, read> params: SparseParams;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> points_model: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> points_meta: array<vec2<u32>>;
@group(0) @binding(4) var<storage, read_write> point_diffuse: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> point_glossy: array<vec4<u32>>;
@group(0) @binding(6) var<storage, read> point_extra: array<vec2<u32>>;
// Per node of the tree (tiles, then internal levels), BOUNDS_VEC4S vec4
// (`vals_occluder_bounds.wgsl`).
@group(0) @binding(7) var<storage, read> occluder_bounds: array<vec4<f32>>;
// Per disc of the walk: (centre, radius), (normal, 0).
@group(0) @binding(8) var<storage, read> occluder_discs: array<vec4<f32>>;

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

// Whether one light of a point opens the node in bounds slot `slot` (else it skips it).
fn opens(slot: u32, rcv: Receiver, light: vec3<f32>, sphere: f32) -> bool {
    let sizes = occluder_bounds[BOUNDS_VEC4S * slot + 1u];
    return tile_may_occlude(rcv.x, rcv.n, rcv.t, rcv.b, light, sphere, occluder_bounds[BOUNDS_VEC4S * slot], sizes.w, sizes.xyz);
}

// Whether more discs can still change what a light keeps (`vals::math::light_still_open`):
// under `sum` a light whose shares reach 1 is hidden whole; under `union` one whose visible
// part is below VISIBLE_CLOSED keeps less than that fraction of its power, whatever comes next.
fn still_open(sum: f32, visible: f32) -> bool {
    if (params.occlusion_mode == 2u) {
        return visible >= VISIBLE_CLOSED;
    }
    return sum < 1.0;
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

// The walk's state: pending nodes (see the entry layout in `cs_main`) and where each level of
// the tree starts among the nodes.
struct Walk {
    stack: array<u32, STACK_MAX>,
    top: u32,
    level_start: array<u32, LEVELS_MAX>,
}

// One node off the stack: each light still open for it opens or skips it; an opened tile's
// discs count for the lights that opened it, an opened internal node's children go on the
// stack, last first, so that they come off in order. Nothing when the stack is empty.
fn walk_step(walk: ptr<function, Walk>, shares: ptr<function, Shares>, rcv: Receiver, lights: PointLights, tile: u32) {
    if ((*walk).top == 0u) {
        return;
    }
    (*walk).top -= 1u;
    let entry = (*walk).stack[(*walk).top];
    let k = entry & 0x3ffffffu;
    let level = (entry >> 26u) & 0xfu;
    let slot = (*walk).level_start[level] + k;
    let open_d = (entry & (1u << 30u)) != 0u
        && still_open((*shares).sum_d, (*shares).visible_d)
        && opens(slot, rcv, lights.diffuse_position, lights.diffuse_sphere);
    let open_s = (entry & (1u << 31u)) != 0u
        && still_open((*shares).sum_s, (*shares).visible_s)
        && opens(slot, rcv, lights.glossy_position, lights.glossy_sphere);
    if (!open_d && !open_s) {
        return;
    }
    if (level == 0u) {
        // The point's own disc is in its tile: at distance 0 from the point, occluder_share
        // gives it exactly 0, so it needs no test. Written out 16 at a time for llvmpipe's
        // loop limit (above): this loop runs again for every tile the walk opens.
        let first = k * tile;
        let end = min(first + tile, params.point_count);
        var j = first;
        let full = first + (end - first) / 16u * 16u;
        while (j < full) {
            add_disc(shares, rcv, lights, j + 0u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 1u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 2u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 3u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 4u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 5u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 6u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 7u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 8u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 9u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 10u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 11u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 12u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 13u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 14u, open_d, open_s);
            add_disc(shares, rcv, lights, j + 15u, open_d, open_s);
            j += 16u;
        }
        while (j < end) {
            add_disc(shares, rcv, lights, j, open_d, open_s);
            j += 1u;
        }
        return;
    }
    let below = (*walk).level_start[level] - (*walk).level_start[level - 1u];
    let first = k * FANOUT;
    let flags = ((level - 1u) << 26u) | (select(0u, 1u, open_d) << 30u) | (select(0u, 1u, open_s) << 31u);
    // FANOUT (8) children at most, written out rather than looped (the loop limit above).
    let count = min(first + FANOUT, below) - min(first, below);
    let child_start = (*walk).level_start[level - 1u] + first;
    var order: ChildOrder;
    set_child(&order, rcv, child_start, count, 0u);
    set_child(&order, rcv, child_start, count, 1u);
    set_child(&order, rcv, child_start, count, 2u);
    set_child(&order, rcv, child_start, count, 3u);
    set_child(&order, rcv, child_start, count, 4u);
    set_child(&order, rcv, child_start, count, 5u);
    set_child(&order, rcv, child_start, count, 6u);
    set_child(&order, rcv, child_start, count, 7u);
    // A 19-comparator sorting network for 8 keys (`vals::math`'s tests check that it sorts).
    order_swap(&order, 0u, 2u);
    order_swap(&order, 1u, 3u);
    order_swap(&order, 4u, 6u);
    order_swap(&order, 5u, 7u);
    order_swap(&order, 0u, 4u);
    order_swap(&order, 1u, 5u);
    order_swap(&order, 2u, 6u);
    order_swap(&order, 3u, 7u);
    order_swap(&order, 0u, 1u);
    order_swap(&order, 2u, 3u);
    order_swap(&order, 4u, 5u);
    order_swap(&order, 6u, 7u);
    order_swap(&order, 2u, 4u);
    order_swap(&order, 3u, 5u);
    order_swap(&order, 1u, 4u);
    order_swap(&order, 3u, 6u);
    order_swap(&order, 1u, 2u);
    order_swap(&order, 3u, 4u);
    order_swap(&order, 5u, 6u);
    // Farthest first on the stack, so the nearest comes off first.
    push_child(walk, flags, first, count, order.id[7]);
    push_child(walk, flags, first, count, order.id[6]);
    push_child(walk, flags, first, count, order.id[5]);
    push_child(walk, flags, first, count, order.id[4]);
    push_child(walk, flags, first, count, order.id[3]);
    push_child(walk, flags, first, count, order.id[2]);
    push_child(walk, flags, first, count, order.id[1]);
    push_child(walk, flags, first, count, order.id[0]);
}

// An opened node's children with their distances from the receiver, sorted nearest first.
struct ChildOrder {
    key: array<f32, 8>,
    id: array<u32, 8>,
}

// Child `i`'s key: how far the receiver is from its sphere (`vals::math::child_order`); a
// missing child sorts last.
fn set_child(order: ptr<function, ChildOrder>, rcv: Receiver, child_start: u32, count: u32, i: u32) {
    let bounds = occluder_bounds[BOUNDS_VEC4S * (child_start + min(i, count - 1u))];
    (*order).key[i] = select(3.0e38, length(bounds.xyz - rcv.x) - bounds.w, i < count);
    (*order).id[i] = i;
}

// One comparator: by key, ties by child index, so the order is the CPU's stable sort.
fn order_swap(order: ptr<function, ChildOrder>, a: u32, b: u32) {
    let ka = (*order).key[a];
    let kb = (*order).key[b];
    let ia = (*order).id[a];
    let ib = (*order).id[b];
    if (ka > kb || (ka == kb && ia > ib)) {
        (*order).key[a] = kb;
        (*order).key[b] = ka;
        (*order).id[a] = ib;
        (*order).id[b] = ia;
    }
}

// Child `i` of the `count` children from `first`, if there is one.
fn push_child(walk: ptr<function, Walk>, flags: u32, first: u32, count: u32, i: u32) {
    if (i < count && (*walk).top < STACK_MAX) {
        (*walk).stack[(*walk).top] = flags | (first + i);
        (*walk).top += 1u;
    }
}

fn add_disc(shares: ptr<function, Shares>, rcv: Receiver, lights: PointLights, j: u32, open_d: bool, open_s: bool) {
    add_occluder(shares, rcv, lights, Disc(occluder_discs[2u * j], occluder_discs[2u * j + 1u]), open_d, open_s);
}

@compute @workgroup_size(64, 1, 1)
fn cs_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let tile = clamp(params.tile, 1u, TILE_MAX);
    let index = linear_index(gid, groups);
    if (index >= params.point_count) {
        return;
    }
    let glossy_on = (params.flags & FLAG_GLOSSY) != 0u;
    let point_meta = points_meta[index];
    let point = world_point(points_model[index], point_meta, instances[point_meta.y]);
    let d = point_diffuse[index];
    let s = point_glossy[index];
    let lights = decode_lights(point.position, d, s, point_extra[index]);
    let t = tangent_frame_t(point.normal);
    let b = tangent_frame_b(point.normal);
    var shares = Shares(0.0, 1.0, 0.0, 1.0);
    // The tree's levels: where each starts among the nodes (the tiles at 0).
    let tiles = (params.point_count + tile - 1u) / tile;
    var level_start = array<u32, LEVELS_MAX>();
    level_start[0] = 0u;
    var level_size = tiles;
    var levels = 1u;
    var next_start = tiles;
    while (level_size > 1u && levels < LEVELS_MAX) {
        level_size = (level_size + FANOUT - 1u) / FANOUT;
        level_start[levels] = next_start;
        next_start += level_size;
        levels += 1u;
    }
    let rcv = Receiver(point.position, point.normal, t, b);
    // Stack entries: node index within its level (bits 0–25), level (26–29), whether it is
    // open for the diffuse light (30) and for the glossy one (31).
    var walk: Walk;
    walk.level_start = level_start;
    walk.top = 1u;
    // A light without power keeps nothing whatever hides it: it never opens a node (the CPU
    // twin walks it and scales it to 0 all the same).
    let lit_d = max(lights.diffuse.x, max(lights.diffuse.y, lights.diffuse.z)) > 0.0;
    let lit_s = glossy_on && max(lights.glossy.x, max(lights.glossy.y, lights.glossy.z)) > 0.0;
    walk.stack[0] = ((levels - 1u) << 26u) | (select(0u, 1u, lit_d) << 30u) | (select(0u, 1u, lit_s) << 31u);
    // Mesa's llvmpipe ends any loop after 65535 iterations per invocation (counted across
    // re-entries): four steps written out per iteration let the walk visit 262 140 nodes.
    // A walk ends early once neither light can change any more (`still_open`).
    while (walk.top > 0u
        && ((lit_d && still_open(shares.sum_d, shares.visible_d))
            || (lit_s && still_open(shares.sum_s, shares.visible_s)))) {
        walk_step(&walk, &shares, rcv, lights, tile);
        walk_step(&walk, &shares, rcv, lights, tile);
        walk_step(&walk, &shares, rcv, lights, tile);
        walk_step(&walk, &shares, rcv, lights, tile);
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
