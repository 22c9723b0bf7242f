// A depth-sensor frame → virtual area lights (seed 003 §5). Four passes over the frame:
// `bilateral` smooths the depth (holes skipped), `surfels` turns every pixel into a
// camera-facing Lambertian disc in world space, `reduce` merges the surfels of each block of a
// stratified grid into one VAL (footprint-weighted; 1×1 blocks keep every pixel) — or, with
// `--real-cut`, `cut` merges them into the coarsest quadtree blocks the receivers see small —
// and `samples_of_surfels` puts the surfels at the image tiles' sample candidates into the
// visibility rays' sample slots. `src/mixed_reality/math.rs` is the CPU twin of the first
// three and of `cut`, `light::sensor::surfel_samples` of the last.
#include "vals_common.wgsl"
#include "sensor_strata.wgsl"

struct DepthValParams {
    // The sensor's camera (OpenCV axes: x right, y down, +z forward) to world.
    world_from_camera: mat4x4<f32>,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: u32,
    height: u32,
    grid_width: u32,
    grid_height: u32,
    // Bilateral σ in pixels and in metres.
    sigma_spatial: f32,
    sigma_range: f32,
    // Radiance (W/(m²·sr)) of a decoded colour value of 1.
    real_scale: f32,
    // Neighbours farther than this fraction of the depth are across an edge.
    max_jump: f32,
    radius: u32,
    // 0: the VAL's area is the facing footprint; 1: the true (tilted) area.
    area_mode: u32,
    // Cluster tiles per image side: a candidate's `flux.w` is its block's tile.
    cluster_tiles: u32,
    pad1: u32,
    // `--real-cut`: the receivers' bounding sphere (w < 0: unknown, nothing merges) and the
    // largest radius-over-gap ratio of a merged block.
    receivers: vec4<f32>,
    cut_ratio: f32,
    pad2: u32,
    pad3: u32,
    pad4: u32,
}

@group(0) @binding(0) var<uniform> params: DepthValParams;
// Metres along the optical axis; 0 = hole.
@group(0) @binding(1) var<storage, read_write> depth_raw: array<f32>;
// rgb: sRGB-decoded colour.
@group(0) @binding(2) var<storage, read_write> color: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> depth_filtered: array<f32>;
// position_area.w: the VAL area (0 = no surfel); normal.w: the true area, the merge weight.
@group(0) @binding(4) var<storage, read_write> surfels: array<Val>;
@group(0) @binding(5) var<storage, read_write> candidates: array<Val>;
// The visibility rays' samples of the image's tiles (`light::sensor::sample_slot`).
@group(0) @binding(6) var<storage, read_write> samples: array<Val>;

const TRUE_AREA_MIN_COSINE: f32 = 0.2;

@compute @workgroup_size(8, 8, 1)
fn bilateral(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.width || id.y >= params.height) {
        return;
    }
    let i = id.y * params.width + id.x;
    let z = depth_raw[i];
    if (z <= 0.0) {
        depth_filtered[i] = 0.0;
        return;
    }
    let r = i32(params.radius);
    let inv_s = 1.0 / (2.0 * params.sigma_spatial * params.sigma_spatial);
    let inv_r = 1.0 / (2.0 * params.sigma_range * params.sigma_range);
    var sum = 0.0;
    var weights = 0.0;
    for (var dy = -r; dy <= r; dy++) {
        let y = i32(id.y) + dy;
        if (y < 0 || y >= i32(params.height)) {
            continue;
        }
        for (var dx = -r; dx <= r; dx++) {
            let x = i32(id.x) + dx;
            if (x < 0 || x >= i32(params.width)) {
                continue;
            }
            let zq = depth_raw[u32(y) * params.width + u32(x)];
            if (zq <= 0.0) {
                continue;
            }
            let dz = zq - z;
            let w = exp(-f32(dx * dx + dy * dy) * inv_s - dz * dz * inv_r);
            sum += w * zq;
            weights += w;
        }
    }
    depth_filtered[i] = sum / weights;
}

fn camera_point(x: u32, y: u32) -> vec3<f32> {
    let z = depth_filtered[y * params.width + x];
    return vec3<f32>((f32(x) - params.cx) / params.fx * z, (f32(y) - params.cy) / params.fy * z, z);
}

fn same_surface(zq: f32, z: f32) -> bool {
    return zq > 0.0 && abs(zq - z) <= params.max_jump * z;
}

// The tangent along one image axis: central where both neighbours are on the surface,
// one-sided where one is, none (zero) where neither is.
fn tangent(x: u32, y: u32, step: vec2<u32>, z: f32) -> vec3<f32> {
    let has_prev = (step.x == 1u && x > 0u) || (step.y == 1u && y > 0u);
    let has_next = (step.x == 1u && x + 1u < params.width) || (step.y == 1u && y + 1u < params.height);
    var prev_ok = false;
    var next_ok = false;
    if (has_prev) {
        prev_ok = same_surface(depth_filtered[(y - step.y) * params.width + x - step.x], z);
    }
    if (has_next) {
        next_ok = same_surface(depth_filtered[(y + step.y) * params.width + x + step.x], z);
    }
    let p = camera_point(x, y);
    if (prev_ok && next_ok) {
        return camera_point(x + step.x, y + step.y) - camera_point(x - step.x, y - step.y);
    }
    if (next_ok) {
        return camera_point(x + step.x, y + step.y) - p;
    }
    if (prev_ok) {
        return p - camera_point(x - step.x, y - step.y);
    }
    return vec3<f32>(0.0);
}

@compute @workgroup_size(8, 8, 1)
fn surfel(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= params.width || id.y >= params.height) {
        return;
    }
    let i = id.y * params.width + id.x;
    var s: Val;
    s.position_area = vec4<f32>(0.0);
    s.normal = vec4<f32>(0.0);
    s.flux = vec4<f32>(0.0);
    let z = depth_filtered[i];
    if (z <= 0.0) {
        surfels[i] = s;
        return;
    }
    let tx = tangent(id.x, id.y, vec2<u32>(1u, 0u), z);
    let ty = tangent(id.x, id.y, vec2<u32>(0u, 1u), z);
    let c = cross(tx, ty);
    let p = camera_point(id.x, id.y);
    if (dot(c, c) <= 1e-20 * z * z * z * z) {
        surfels[i] = s;
        return;
    }
    var n = normalize(c);
    if (dot(n, p) > 0.0) {
        n = -n;
    }
    let d = length(p);
    let cos_sensor = max(dot(n, -p / d), 0.0);
    // The pixel's solid angle cos³α/(fx·fy) times d² (cos α = z/d).
    let facing_area = z * z * (z / d) / (params.fx * params.fy);
    let true_area = facing_area / max(cos_sensor, TRUE_AREA_MIN_COSINE);
    let radiance = color[i].rgb * params.real_scale;
    let world = params.world_from_camera * vec4<f32>(p, 1.0);
    let world_normal = normalize((params.world_from_camera * vec4<f32>(n, 0.0)).xyz);
    s.position_area = vec4<f32>(world.xyz, select(facing_area, true_area, params.area_mode == 1u));
    s.normal = vec4<f32>(world_normal, true_area);
    s.flux = vec4<f32>(PI * radiance * true_area, 0.0);
    surfels[i] = s;
}

@compute @workgroup_size(64, 1, 1)
fn reduce(@builtin(global_invocation_id) id: vec3<u32>) {
    let block = id.x;
    if (block >= params.grid_width * params.grid_height) {
        return;
    }
    let bx = block % params.grid_width;
    let by = block / params.grid_width;
    let x0 = bx * params.width / params.grid_width;
    let x1 = (bx + 1u) * params.width / params.grid_width;
    let y0 = by * params.height / params.grid_height;
    let y1 = (by + 1u) * params.height / params.grid_height;
    var position = vec3<f32>(0.0);
    var normal = vec3<f32>(0.0);
    var flux = vec3<f32>(0.0);
    var area = 0.0;
    var weights = 0.0;
    for (var y = y0; y < y1; y++) {
        for (var x = x0; x < x1; x++) {
            let s = surfels[y * params.width + x];
            if (s.position_area.w <= 0.0) {
                continue;
            }
            let w = s.normal.w;
            position += w * s.position_area.xyz;
            normal += w * s.normal.xyz;
            flux += s.flux.rgb;
            area += s.position_area.w;
            weights += w;
        }
    }
    var out: Val;
    out.position_area = vec4<f32>(0.0);
    out.normal = vec4<f32>(0.0);
    out.flux = vec4<f32>(0.0);
    // The tile of the block's first pixel (`light::sensor::pixel_tile`).
    let tiles = params.cluster_tiles;
    let tile = (y0 * tiles / params.height) * tiles + x0 * tiles / params.width;
    if (weights > 0.0 && max(flux.r, max(flux.g, flux.b)) > 0.0 && length(normal) > 1e-6 * weights) {
        out.position_area = vec4<f32>(position / weights, area);
        out.normal = vec4<f32>(normalize(normal), 0.0);
        out.flux = vec4<f32>(flux, f32(tile));
    }
    candidates[block] = out;
}

// One invocation per sample slot: the surfel at the slot's candidate pixel (area 0: none).
@compute @workgroup_size(64, 1, 1)
fn samples_of_surfels(@builtin(global_invocation_id) id: vec3<u32>) {
    let tiles = params.cluster_tiles;
    let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE * SAMPLE_CANDIDATES;
    let slot = id.x;
    if (slot >= tiles * tiles * per_tile) {
        return;
    }
    let k = slot % SAMPLE_CANDIDATES;
    let s = (slot / SAMPLE_CANDIDATES) % (CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE);
    let tile = slot / per_tile;
    let pixel = stratum_candidate_pixel(vec2<u32>(params.width, params.height), tiles, tile, s, k);
    var sample = surfels[pixel.y * params.width + pixel.x];
    if (!(sample.position_area.w > 0.0)) {
        sample.position_area = vec4<f32>(0.0);
    }
    samples[slot] = sample;
}

// `cut` (`--real-cut`; CPU twin `math::cut`, where the criterion is explained): each
// workgroup takes a CUT_BLOCK² block of pixels and builds its quadtree bottom-up (levels 1 and
// 2 in registers, 3–5 through workgroup memory), then every invocation writes its 4×4 pixels'
// candidate slots top-down: a block's VAL at its first pixel where the block is the coarsest
// accepted one, empty slots elsewhere. Sums are merged in the twin's order.
const CUT_BLOCK: u32 = 32u;
const CUT_NORMAL_AGREEMENT: f32 = 0.7;

struct CutNode {
    weighted_position: vec3<f32>,
    area: f32,
    weighted_normal: vec3<f32>,
    weight: f32,
    flux: vec3<f32>,
    radius: f32,
}

// Level 2 (8×8 nodes) at 0, level 3 (4×4) at 64, level 4 (2×2) at 80, level 5 at 84.
var<workgroup> cut_nodes: array<CutNode, 85>;

fn cut_slot(level: u32, i: u32, j: u32) -> u32 {
    switch level {
        case 2u: { return j * 8u + i; }
        case 3u: { return 64u + j * 4u + i; }
        case 4u: { return 80u + j * 2u + i; }
        default: { return 84u; }
    }
}

fn cut_surfel_node(x: u32, y: u32) -> CutNode {
    var n: CutNode;
    if (x >= params.width || y >= params.height) {
        return n;
    }
    let s = surfels[y * params.width + x];
    // Weighted by flux (`math::CutNode`); what does not emit is empty.
    let w = (s.flux.r + s.flux.g + s.flux.b) / 3.0;
    if (s.position_area.w <= 0.0 || !(w > 0.0)) {
        return n;
    }
    n.weighted_position = w * s.position_area.xyz;
    n.area = s.position_area.w;
    n.weighted_normal = w * s.normal.xyz;
    n.weight = w;
    n.flux = s.flux.rgb;
    return n;
}

// How far a child's surfels reach from the parent's mean.
fn cut_reach(c: CutNode, mean: vec3<f32>) -> f32 {
    if (c.weight <= 0.0) {
        return 0.0;
    }
    return length(c.weighted_position / c.weight - mean) + c.radius;
}

// Children (0,0), (1,0), (0,1), (1,1).
fn cut_merge(a: CutNode, b: CutNode, c: CutNode, d: CutNode) -> CutNode {
    var n: CutNode;
    n.weighted_position = ((a.weighted_position + b.weighted_position) + c.weighted_position) + d.weighted_position;
    n.area = ((a.area + b.area) + c.area) + d.area;
    n.weighted_normal = ((a.weighted_normal + b.weighted_normal) + c.weighted_normal) + d.weighted_normal;
    n.weight = ((a.weight + b.weight) + c.weight) + d.weight;
    n.flux = ((a.flux + b.flux) + c.flux) + d.flux;
    if (n.weight > 0.0) {
        let mean = n.weighted_position / n.weight;
        n.radius = max(max(cut_reach(a, mean), cut_reach(b, mean)), max(cut_reach(c, mean), cut_reach(d, mean)));
    }
    return n;
}

fn cut_pixel_tile(x: u32, y: u32) -> u32 {
    let tiles = params.cluster_tiles;
    return (y * tiles / params.height) * tiles + x * tiles / params.width;
}

// The block of pixels [x0, x1) × [y0, y1) may be one VAL (`math::cut_accepts`).
fn cut_accepts(n: CutNode, x0: u32, y0: u32, x1: u32, y1: u32) -> bool {
    if (n.weight <= 0.0) {
        return true;
    }
    if (params.receivers.w < 0.0) {
        return false;
    }
    if (cut_pixel_tile(x0, y0) != cut_pixel_tile(x1 - 1u, y1 - 1u)) {
        return false;
    }
    if (length(n.weighted_normal) < CUT_NORMAL_AGREEMENT * n.weight) {
        return false;
    }
    let gap = length(n.weighted_position / n.weight - params.receivers.xyz) - params.receivers.w - n.radius;
    return n.radius < params.cut_ratio * gap;
}

// The node's VAL for the slot of pixel (x, y), its first (`reduce`'s test and tile).
fn cut_val(n: CutNode, x: u32, y: u32) -> Val {
    var out: Val;
    if (n.weight > 0.0 && max(n.flux.r, max(n.flux.g, n.flux.b)) > 0.0 && length(n.weighted_normal) > 1e-6 * n.weight) {
        out.position_area = vec4<f32>(n.weighted_position / n.weight, n.area);
        out.normal = vec4<f32>(normalize(n.weighted_normal), 0.0);
        out.flux = vec4<f32>(n.flux, f32(cut_pixel_tile(x, y)));
    }
    return out;
}

fn cut_write(x: u32, y: u32, val: Val) {
    if (x < params.width && y < params.height) {
        candidates[y * params.width + x] = val;
    }
}

@compute @workgroup_size(64, 1, 1)
fn cut(@builtin(workgroup_id) group: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let block = group.xy * CUT_BLOCK;
    // This invocation's 4×4 pixels are level-2 node (lid % 8, lid / 8) of the block.
    let origin = block + vec2<u32>(lid % 8u, lid / 8u) * 4u;
    var level1: array<CutNode, 4>;
    for (var c = 0u; c < 4u; c++) {
        let o = origin + vec2<u32>(c % 2u, c / 2u) * 2u;
        level1[c] = cut_merge(
            cut_surfel_node(o.x, o.y),
            cut_surfel_node(o.x + 1u, o.y),
            cut_surfel_node(o.x, o.y + 1u),
            cut_surfel_node(o.x + 1u, o.y + 1u),
        );
    }
    cut_nodes[lid] = cut_merge(level1[0], level1[1], level1[2], level1[3]);
    workgroupBarrier();
    for (var level = 3u; level <= 5u; level++) {
        let side = CUT_BLOCK >> level;
        if (lid < side * side) {
            let i = 2u * (lid % side);
            let j = 2u * (lid / side);
            let below = level - 1u;
            let merged = cut_merge(
                cut_nodes[cut_slot(below, i, j)],
                cut_nodes[cut_slot(below, i + 1u, j)],
                cut_nodes[cut_slot(below, i, j + 1u)],
                cut_nodes[cut_slot(below, i + 1u, j + 1u)],
            );
            cut_nodes[cut_slot(level, lid % side, lid / side)] = merged;
        }
        workgroupBarrier();
    }
    let dims = vec2<u32>(params.width, params.height);
    if (any(origin >= dims)) {
        return;
    }
    // The coarsest accepted ancestor among levels 5 … 2, if any.
    for (var k = 0u; k < 4u; k++) {
        let level = 5u - k;
        let size = 1u << level;
        let ij = (origin - block) / size;
        let first = block + ij * size;
        let last = min(first + size, dims);
        let node = cut_nodes[cut_slot(level, ij.x, ij.y)];
        if (cut_accepts(node, first.x, first.y, last.x, last.y)) {
            for (var p = 0u; p < 16u; p++) {
                let xy = origin + vec2<u32>(p % 4u, p / 4u);
                var val: Val;
                if (all(xy == first)) {
                    val = cut_val(node, xy.x, xy.y);
                }
                cut_write(xy.x, xy.y, val);
            }
            return;
        }
    }
    for (var c = 0u; c < 4u; c++) {
        let o = origin + vec2<u32>(c % 2u, c / 2u) * 2u;
        if (any(o >= dims)) {
            continue;
        }
        let last = min(o + 2u, dims);
        let whole = cut_accepts(level1[c], o.x, o.y, last.x, last.y);
        for (var p = 0u; p < 4u; p++) {
            let xy = o + vec2<u32>(p % 2u, p / 2u);
            var val: Val;
            if (whole) {
                if (p == 0u) {
                    val = cut_val(level1[c], xy.x, xy.y);
                }
            } else {
                val = cut_val(cut_surfel_node(xy.x, xy.y), xy.x, xy.y);
            }
            cut_write(xy.x, xy.y, val);
        }
    }
}
