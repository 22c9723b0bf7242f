// A depth-sensor frame → virtual area lights (seed 003 §5). Four passes over the frame:
// `bilateral` smooths the depth (holes skipped), `surfels` turns every pixel into a
// camera-facing Lambertian disc in world space, `reduce` merges the surfels of each block of a
// stratified grid into one VAL (footprint-weighted; 1×1 blocks keep every pixel), and
// `samples_of_surfels` puts the surfels at the image tiles' sample candidates into the
// visibility rays' sample slots. `src/mixed_reality/math.rs` is the CPU twin of the first
// three, `light::sensor::surfel_samples` of the last.
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
