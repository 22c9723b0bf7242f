// Shadow rays against the scene's two-level BVH (`src/light/bvh.rs`, whose `SceneBvh::occluded`
// is the CPU twin): the top level over the instances' world boxes, each instance at its leaves
// tested against its box, then the ray in the instance's model space through its mesh's
// binary BVH. Both levels are threaded (`bvh::threaded`): preorder, an inner node's left child
// next to it and its `first` the index past its subtree, so the walk keeps no stack (a private
// array is zero-filled on every call, which on the software driver cost half the pass). The
// BVH is bind group 1 of every includer (`SceneBvh::bind_group_layout`).

struct BvhNode {
    min: vec3<f32>,
    // > 0: a leaf with this many triangles (instances) from `first`; 0: an inner node whose
    // left child is the next node and whose subtree ends before node `first`.
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

// Every record as rgba32uint texels, 2^BVH_ROW_SHIFT a row (`BVH_ROW_TEXELS` in
// `src/light/bvh.rs`, which says why textures: on a CPU device a texel fetch at a per-lane
// address is one gathered load, a storage read a loop over lanes): the mesh nodes (2 texels
// each), the triangles (3), the instances (6) and the top level's nodes (2), whose leaves
// hold `prim_count` instances from `first`.
const BVH_ROW_SHIFT: u32 = 12u;
@group(1) @binding(0) var bvh_node_texels: texture_2d<u32>;
@group(1) @binding(1) var bvh_triangle_texels: texture_2d<u32>;
@group(1) @binding(2) var bvh_instance_texels: texture_2d<u32>;
@group(1) @binding(3) var bvh_top_texels: texture_2d<u32>;

fn bvh_texel(texels: texture_2d<u32>, t: u32) -> vec4<u32> {
    let row_mask = (1u << BVH_ROW_SHIFT) - 1u;
    return textureLoad(texels, vec2<u32>(t & row_mask, t >> BVH_ROW_SHIFT), 0);
}

fn bvh_node_of(texels: texture_2d<u32>, i: u32) -> BvhNode {
    let a = bvh_texel(texels, 2u * i);
    let b = bvh_texel(texels, 2u * i + 1u);
    return BvhNode(bitcast<vec3<f32>>(a.xyz), a.w, bitcast<vec3<f32>>(b.xyz), b.w);
}

fn bvh_node(i: u32) -> BvhNode {
    return bvh_node_of(bvh_node_texels, i);
}

fn bvh_top_node(i: u32) -> BvhNode {
    return bvh_node_of(bvh_top_texels, i);
}

fn bvh_instance(i: u32) -> BvhInstance {
    let t = 6u * i;
    let m = mat4x4<f32>(
        bitcast<vec4<f32>>(bvh_texel(bvh_instance_texels, t)),
        bitcast<vec4<f32>>(bvh_texel(bvh_instance_texels, t + 1u)),
        bitcast<vec4<f32>>(bvh_texel(bvh_instance_texels, t + 2u)),
        bitcast<vec4<f32>>(bvh_texel(bvh_instance_texels, t + 3u)),
    );
    return BvhInstance(
        m,
        bitcast<vec4<f32>>(bvh_texel(bvh_instance_texels, t + 4u)),
        bitcast<vec4<f32>>(bvh_texel(bvh_instance_texels, t + 5u)),
    );
}

fn bvh_triangle(i: u32) -> BvhTriangle {
    return BvhTriangle(
        bitcast<vec4<f32>>(bvh_texel(bvh_triangle_texels, 3u * i)),
        bitcast<vec4<f32>>(bvh_texel(bvh_triangle_texels, 3u * i + 1u)),
        bitcast<vec4<f32>>(bvh_texel(bvh_triangle_texels, 3u * i + 2u)),
    );
}

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

// Where the walk over a threaded tree whose root is `root` ends.
fn bvh_walk_end(root: BvhNode) -> u32 {
    return select(root.first, 1u, root.prim_count > 0u);
}

// The threaded walk's next node after node `i`: the next one after a leaf or into an inner
// node the segment enters, else past the inner node's subtree.
fn bvh_next(i: u32, node: BvhNode, entered: bool) -> u32 {
    return select(node.first, i + 1u, entered || node.prim_count > 0u);
}

fn bvh_mesh_hit(origin: vec3<f32>, dir: vec3<f32>, first_node: u32, first_triangle: u32) -> bool {
    let inv = bvh_safe_inverse(dir);
    let end = bvh_walk_end(bvh_node(first_node));
    var i = 0u;
    while (i < end) {
        let node = bvh_node(first_node + i);
        let entered = bvh_ray_box(origin, inv, 1.0, node.min, node.max);
        if (entered) {
            for (var k = 0u; k < node.prim_count; k++) {
                if (bvh_ray_triangle(origin, dir, 1.0, bvh_triangle(first_triangle + node.first + k))) {
                    return true;
                }
            }
        }
        i = bvh_next(i, node, entered);
    }
    return false;
}

// True when a triangle lies on the segment from `start` to `end` (t in (0, 1)).
fn segment_occluded(start: vec3<f32>, end: vec3<f32>) -> bool {
    let d = end - start;
    let inv = bvh_safe_inverse(d);
    let last = bvh_walk_end(bvh_top_node(0u));
    var i = 0u;
    while (i < last) {
        let node = bvh_top_node(i);
        let entered = bvh_ray_box(start, inv, 1.0, node.min, node.max);
        if (entered) {
            for (var k = node.first; k < node.first + node.prim_count; k++) {
                let inst = bvh_instance(k);
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
        i = bvh_next(i, node, entered);
    }
    return false;
}
