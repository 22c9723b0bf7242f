// `valgi view`'s occluder debug view: for one sparse point (the one under the cursor), its
// renormalized lights' spheres and every other point's occluder disc that takes a share of the
// diffuse sphere, drawn as outlines (line lists) straight from the sparse method's buffers after
// the frame ran (no readback). The shares are `occluder_share`, the function the occlusion pass
// evaluates (`vals_occluder_share.wgsl`), so the discs drawn are exactly those that darken the
// point in `--occlusion sum|union`; whether that mode is on does not matter here.
// - `vs_sphere`, instance 0: the diffuse sphere (yellow), instance 1: the glossy sphere (cyan),
//   each a circle facing the eye; instance 2: the segment from the point to its diffuse light.
// - `vs_disc`, one instance per point: its disc (centre, normal, radius as the occlusion pass
//   builds it), red, brighter with a larger share; discs with no share are culled.
#include "vals_occluder_share.wgsl"

struct DebugOccluderParams {
    // The picked point's index in the point buffers.
    point: u32,
    point_count: u32,
    // Segments per circle; each vertex stage draws 2·segments vertices per instance.
    segments: u32,
    pad0: u32,
}

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: DebugOccluderParams;

@group(1) @binding(0) var<storage, read> instances: array<InstanceData>;
@group(1) @binding(1) var<storage, read> points_model: array<vec4<u32>>;
@group(1) @binding(2) var<storage, read> points_meta: array<vec2<u32>>;
@group(1) @binding(3) var<storage, read> point_diffuse: array<vec4<u32>>;
@group(1) @binding(4) var<storage, read> point_extra: array<vec2<u32>>;
@group(1) @binding(5) var<storage, read> point_glossy: array<vec4<u32>>;

struct LineOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) colour: vec3<f32>,
}

fn culled() -> LineOut {
    var out: LineOut;
    out.position = vec4<f32>(2.0, 2.0, 2.0, 1.0);
    out.colour = vec3<f32>(0.0);
    return out;
}

fn line_vertex(world: vec3<f32>, colour: vec3<f32>) -> LineOut {
    var out: LineOut;
    out.position = frame.clip_from_world * vec4<f32>(world, 1.0);
    out.colour = colour;
    return out;
}

// Vertex `vertex_index` of a circle drawn as a line list: segment k runs from angle k to k + 1.
fn circle_point(centre: vec3<f32>, axis: vec3<f32>, radius: f32, vertex_index: u32) -> vec3<f32> {
    let k = vertex_index / 2u + vertex_index % 2u;
    let angle = 2.0 * PI * f32(k) / f32(max(params.segments, 3u));
    let t = tangent_frame_t(axis);
    let b = tangent_frame_b(axis);
    return centre + radius * (cos(angle) * t + sin(angle) * b);
}

struct Picked {
    point: WorldPoint,
    lights: PointLights,
}

fn picked() -> Picked {
    let i = params.point;
    let point_meta = points_meta[i];
    let point = world_point(points_model[i], point_meta, instances[point_meta.y]);
    return Picked(point, decode_lights(point.position, point_diffuse[i], point_glossy[i], point_extra[i]));
}

@vertex
fn vs_sphere(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) which: u32) -> LineOut {
    if (params.point >= params.point_count) {
        return culled();
    }
    let p = picked();
    if (which == 2u) {
        if (vertex_index > 1u || !(p.lights.diffuse_sphere > 0.0)) {
            return culled();
        }
        return line_vertex(select(p.point.position, p.lights.diffuse_position, vertex_index == 1u), vec3<f32>(1.0, 1.0, 0.3));
    }
    var centre = p.lights.diffuse_position;
    var radius = p.lights.diffuse_sphere;
    var colour = vec3<f32>(1.0, 0.9, 0.1);
    if (which == 1u) {
        centre = p.lights.glossy_position;
        radius = p.lights.glossy_sphere;
        colour = vec3<f32>(0.1, 0.9, 1.0);
    }
    if (!(radius > 0.0)) {
        return culled();
    }
    let axis = normalize(centre - frame.camera_position.xyz);
    return line_vertex(circle_point(centre, axis, radius, vertex_index), colour);
}

@vertex
fn vs_disc(@builtin(vertex_index) vertex_index: u32, @builtin(instance_index) j: u32) -> LineOut {
    if (params.point >= params.point_count || j >= params.point_count || j == params.point) {
        return culled();
    }
    let p = picked();
    let disc_meta = points_meta[j];
    let d = world_point(points_model[j], disc_meta, instances[disc_meta.y]);
    let disc = Disc(vec4<f32>(d.position, d.disc_radius), vec4<f32>(d.normal, 0.0));
    let x = p.point.position;
    let n = p.point.normal;
    let share = occluder_share(x, n, tangent_frame_t(n), tangent_frame_b(n), p.lights.diffuse_position, p.lights.diffuse_sphere, disc);
    if (!(share > 0.0)) {
        return culled();
    }
    let colour = vec3<f32>(0.3 + 0.7 * min(share, 1.0), 0.05, 0.05);
    return line_vertex(circle_point(d.position, d.normal, d.disc_radius, vertex_index), colour);
}

@fragment
fn fs_main(in: LineOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.colour, 1.0);
}
