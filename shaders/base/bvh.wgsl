// Shadow rays against the scene's two-level BVH (`src/light/bvh.rs`, whose `SceneBvh::occluded`
// is the CPU twin): the top level over the instances' world boxes, each instance at its leaves
// tested against its box, then the ray in the instance's model space through its mesh's
// binary BVH. The BVH is bind group 1 of every
// includer (`SceneBvh::bind_group_layout`).

struct BvhNode {
    min: vec3<f32>,
    // > 0: a leaf with this many triangles from `first`; 0: children `first`, `first + 1`.
    prim_count: u32,
    max: vec3<f32>,
    first: u32,
}

struct BvhTriangle {
    v0: vec4<f32>,
    e1: vec4<f32>,
    e2: vec4<f32>,
}

struct BvhInstance {
    model_from_world: mat4x4<f32>,
    // w: bits of the mesh's first node.
    world_min: vec4<f32>,
    // w: bits of the mesh's first triangle.
    world_max: vec4<f32>,
}

@group(1) @binding(0) var<storage, read> bvh_nodes: array<BvhNode>;
@group(1) @binding(1) var<storage, read> bvh_triangles: array<BvhTriangle>;
@group(1) @binding(2) var<storage, read> bvh_instances: array<BvhInstance>;
// The top level: leaves hold `prim_count` instances from `first` (in `bvh_instances`).
@group(1) @binding(3) var<storage, read> bvh_top: array<BvhNode>;

const BVH_STACK_DEPTH: u32 = 64u;

fn bvh_safe_inverse(d: vec3<f32>) -> vec3<f32> {
    let tiny = abs(d) < vec3<f32>(1e-20);
    let huge = select(vec3<f32>(-1e20), vec3<f32>(1e20), d >= vec3<f32>(0.0));
    return select(1.0 / d, huge, tiny);
}

fn bvh_ray_box(origin: vec3<f32>, inv_dir: vec3<f32>, t_max: f32, lo: vec3<f32>, hi: vec3<f32>) -> bool {
    return bvh_box_entry(origin, inv_dir, t_max, lo, hi) >= 0.0;
}

// Where the ray (t in [0, t_max]) enters a box, or −1 when it misses it.
fn bvh_box_entry(origin: vec3<f32>, inv_dir: vec3<f32>, t_max: f32, lo: vec3<f32>, hi: vec3<f32>) -> f32 {
    let t0 = (lo - origin) * inv_dir;
    let t1 = (hi - origin) * inv_dir;
    let a = min(t0, t1);
    let b = max(t0, t1);
    let near = max(max(max(a.x, a.y), a.z), 0.0);
    let far = min(min(min(b.x, b.y), b.z), t_max);
    return select(-1.0, near, near <= far);
}

// Möller–Trumbore, both faces: true for a hit at t in (0, t_max).
fn bvh_ray_triangle(origin: vec3<f32>, dir: vec3<f32>, t_max: f32, tri: BvhTriangle) -> bool {
    let e1 = tri.e1.xyz;
    let e2 = tri.e2.xyz;
    let p = cross(dir, e2);
    let det = dot(e1, p);
    if (abs(det) < 1e-12) {
        return false;
    }
    let inv = 1.0 / det;
    let s = origin - tri.v0.xyz;
    let u = dot(s, p) * inv;
    if (u < 0.0 || u > 1.0) {
        return false;
    }
    let q = cross(s, e1);
    let v = dot(dir, q) * inv;
    if (v < 0.0 || u + v > 1.0) {
        return false;
    }
    let t = dot(e2, q) * inv;
    return t > 0.0 && t < t_max;
}

fn bvh_mesh_hit(origin: vec3<f32>, dir: vec3<f32>, first_node: u32, first_triangle: u32) -> bool {
    let inv = bvh_safe_inverse(dir);
    var stack: array<u32, BVH_STACK_DEPTH>;
    var top = 1u;
    stack[0] = 0u;
    while (top > 0u) {
        top -= 1u;
        let node = bvh_nodes[first_node + stack[top]];
        if (!bvh_ray_box(origin, inv, 1.0, node.min, node.max)) {
            continue;
        }
        if (node.prim_count > 0u) {
            for (var i = 0u; i < node.prim_count; i++) {
                if (bvh_ray_triangle(origin, dir, 1.0, bvh_triangles[first_triangle + node.first + i])) {
                    return true;
                }
            }
        } else if (top + 2u <= BVH_STACK_DEPTH) {
            stack[top] = node.first;
            stack[top + 1u] = node.first + 1u;
            top += 2u;
        }
    }
    return false;
}

// Pushes the children `first` and `first + 1` the segment enters (entry ≥ 0), the nearer on
// top; returns the new top. A child that finds the stack full is dropped, as it always was
// (`SceneBvh` keeps trees within the stack's depth).
fn bvh_push_entered(stack: ptr<function, array<u32, BVH_STACK_DEPTH>>, top: u32, first: u32, entry_a: f32, entry_b: f32) -> u32 {
    var t = top;
    let a_first = entry_a <= entry_b;
    let far_entry = select(entry_a, entry_b, a_first);
    let near_entry = select(entry_b, entry_a, a_first);
    if (far_entry >= 0.0 && t < BVH_STACK_DEPTH) {
        (*stack)[t] = select(first, first + 1u, a_first);
        t += 1u;
    }
    if (near_entry >= 0.0 && t < BVH_STACK_DEPTH) {
        (*stack)[t] = select(first + 1u, first, a_first);
        t += 1u;
    }
    return t;
}

// True when a triangle lies on the segment from `start` to `end` (t in (0, 1)).
fn segment_occluded(start: vec3<f32>, end: vec3<f32>) -> bool {
    let d = end - start;
    let inv = bvh_safe_inverse(d);
    let root = bvh_top[0];
    if (bvh_box_entry(start, inv, 1.0, root.min, root.max) < 0.0) {
        return false;
    }
    var stack: array<u32, BVH_STACK_DEPTH>;
    var top = 1u;
    stack[0] = 0u;
    // Every node on the stack is one the segment enters; of two children, the one it enters
    // first comes off first, so that a blocked ray meets its nearest blocking instance before
    // it walks the meshes behind it. (Within a mesh the same order measured slower: short
    // unblocked rays pay for the sort and gain nothing.)
    while (top > 0u) {
        top -= 1u;
        let node = bvh_top[stack[top]];
        if (node.prim_count == 0u) {
            let a = bvh_top[node.first];
            let b = bvh_top[node.first + 1u];
            top = bvh_push_entered(&stack, top, node.first, bvh_box_entry(start, inv, 1.0, a.min, a.max), bvh_box_entry(start, inv, 1.0, b.min, b.max));
            continue;
        }
        for (var i = node.first; i < node.first + node.prim_count; i++) {
            let inst = bvh_instances[i];
            if (!bvh_ray_box(start, inv, 1.0, inst.world_min.xyz, inst.world_max.xyz)) {
                continue;
            }
            let origin = (inst.model_from_world * vec4<f32>(start, 1.0)).xyz;
            let dir = (inst.model_from_world * vec4<f32>(d, 0.0)).xyz;
            if (bvh_mesh_hit(origin, dir, bitcast<u32>(inst.world_min.w), bitcast<u32>(inst.world_max.w))) {
                return true;
            }
        }
    }
    return false;
}
