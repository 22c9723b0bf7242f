// A depth sensor's image for the visibility pass: the clusters its VALs form (tiles of the
// image, with ray samples per stratum that its producer fills) and its depth as an
// occluder of shadow rays (a height field with a thickness prior). Bind group 2 of its
// includer (`light::sensor::SensorBuffers`); `src/light/sensor.rs` is the CPU twin and
// explains the rules.
#include "vals_common.wgsl"

#include "sensor_strata.wgsl"

struct SensorParams {
    camera_from_world: mat4x4<f32>,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    width: u32,
    height: u32,
    // Tiles per image side (0: no sensor).
    tiles: u32,
    // 1: the depth blocks shadow rays.
    occludes: u32,
    // Metres of matter assumed behind every seen surface.
    thickness: f32,
    // 1: a frame has been uploaded.
    has_frame: u32,
    pad: vec2<u32>,
}

@group(2) @binding(0) var<uniform> sensor: SensorParams;
// Filtered depth per pixel (m along the optical axis, 0 a hole).
@group(2) @binding(1) var<storage, read> sensor_depth: array<f32>;
// Per tile, stratum and candidate (`(tile·16 + s)·SAMPLE_CANDIDATES + k`) the VAL the rays
// go to (area ≤ 0: none), filled by the sensor's producer.
@group(2) @binding(2) var<storage, read> sensor_samples: array<Val>;

const SENSOR_MAX_STEPS: u32 = 48u;
const SENSOR_NEAR: f32 = 0.05;
const SENSOR_TOLERANCE_ABS: f32 = 0.02;
const SENSOR_TOLERANCE_REL: f32 = 0.02;

fn sensor_tile_count() -> u32 {
    return sensor.tiles * sensor.tiles;
}

fn sensor_project(p: vec3<f32>) -> vec2<f32> {
    return vec2<f32>(sensor.fx * p.x / p.z + sensor.cx, sensor.fy * p.y / p.z + sensor.cy);
}

// Candidate `k` of stratum `s` of sensor tile `tile` (area 0: none).
fn sensor_stratum_sample(tile: u32, s: u32, k: u32) -> Val {
    let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
    var sample = sensor_samples[(tile * per_tile + s) * SAMPLE_CANDIDATES + k];
    if (!(sample.position_area.w > 0.0)) {
        sample.position_area.w = 0.0;
    }
    return sample;
}

// Whether the seen surfaces block the world segment from `start` to `end`: a run of samples
// inside matter with free space on both sides.
fn sensor_blocks(start: vec3<f32>, end: vec3<f32>) -> bool {
    if (sensor.occludes == 0u || sensor.has_frame == 0u) {
        return false;
    }
    var a = (sensor.camera_from_world * vec4<f32>(start, 1.0)).xyz;
    var b = (sensor.camera_from_world * vec4<f32>(end, 1.0)).xyz;
    if (a.z <= SENSOR_NEAR && b.z <= SENSOR_NEAR) {
        return false;
    }
    if (a.z < SENSOR_NEAR) {
        a = mix(a, b, (SENSOR_NEAR - a.z) / (b.z - a.z));
    } else if (b.z < SENSOR_NEAR) {
        b = mix(b, a, (SENSOR_NEAR - b.z) / (a.z - b.z));
    }
    let ua = sensor_project(a);
    let ub = sensor_project(b);
    let pixels = max(abs(ub.x - ua.x), abs(ub.y - ua.y));
    var steps = SENSOR_MAX_STEPS;
    // `pixels` is finite here unless the projection overflowed.
    if (pixels < f32(SENSOR_MAX_STEPS)) {
        steps = max(u32(ceil(pixels)), 1u);
    }
    var left_start = false;
    var inside_run = false;
    for (var i = 0u; i < steps; i++) {
        let t = (f32(i) + 0.5) / f32(steps);
        let p = mix(a, b, t);
        let uv = floor(sensor_project(p) + vec2<f32>(0.5));
        var inside = false;
        if (uv.x >= 0.0 && uv.y >= 0.0 && uv.x < f32(sensor.width) && uv.y < f32(sensor.height)) {
            let d = sensor_depth[u32(uv.y) * sensor.width + u32(uv.x)];
            if (d > 0.0) {
                let tolerance = max(SENSOR_TOLERANCE_ABS, SENSOR_TOLERANCE_REL * d);
                inside = p.z > d + tolerance && p.z < d + sensor.thickness;
            }
        }
        if (!inside) {
            if (inside_run) {
                return true;
            }
            left_start = true;
        } else if (left_start) {
            inside_run = true;
        }
    }
    return false;
}
