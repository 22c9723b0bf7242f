// `valgi view`'s debug views: the sparse points and the VALs drawn as small square splats
// over a view's region of the window, straight from the sparse method's GPU buffers (no CPU
// readback). One instance per point or VAL slot, six vertices (two triangles) each. A splat is
// hidden when the view's G-buffer holds a surface nearer the eye at its centre, so the splats
// sit on the surfaces they belong to. Colours are radiances, tone-mapped like `present.wgsl`
// (radiance · 2^exposure, clamped, sRGB OETF), so the panel's exposure suits them as it suits
// the image:
// - a point: the irradiance E = I·max(0, n·ω)/d² its renormalized diffuse light (intensity I
//   at its averaged position) gives it, over π: the radiance a white diffuse surface there
//   reflects from the first bounce;
// - a VAL: its disc's radiance Φ/(π·A), flux Φ over the disc's area A, as the gather models
//   it. A is the footprint the RSM texel's surface would have facing the light, so this is
//   the surface's own radiance divided by the cosine at the light (equal where it faces it).
#include "vals_common.wgsl"

struct DebugSplatParams {
    // 2^exposure.
    exposure_scale: f32,
    // 1 when the target stores encoded values (a non-sRGB format), as in `present.wgsl`.
    encode_srgb: u32,
    // Side of a splat, output pixels.
    splat_pixels: f32,
    // Points: the point count; VALs: the VAL buffer's slots (the count read on the GPU).
    instance_count: u32,
    // The view's output size (the viewport the splats are drawn in), pixels.
    size: vec2<u32>,
    pad0: vec2<u32>,
}

// The relative distance a splat's centre may lie behind the G-buffer's surface and still be
// drawn: points and VALs lie on surfaces, up to the depth buffer's precision and the
// tessellation's flat facets.
const DEPTH_TOLERANCE: f32 = 0.02;

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<uniform> params: DebugSplatParams;
@group(0) @binding(2) var gbuffer_depth: texture_depth_2d;

// Points (`vs_point`): the buffers `SparseGpu` gathers into.
@group(1) @binding(0) var<storage, read> instances: array<InstanceData>;
@group(1) @binding(1) var<storage, read> points_model: array<vec4<u32>>;
@group(1) @binding(2) var<storage, read> points_meta: array<vec2<u32>>;
@group(1) @binding(3) var<storage, read> point_diffuse: array<vec4<u32>>;
@group(1) @binding(4) var<storage, read> point_extra: array<vec2<u32>>;

// VALs (`vs_val`): the RSM's VAL buffer and its count.
@group(2) @binding(0) var<storage, read> vals: array<Val>;
@group(2) @binding(1) var<storage, read> val_count: array<u32>;

struct SplatOut {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) radiance: vec3<f32>,
}

// A position outside the clip volume: all six vertices there make a splat that draws nothing.
fn culled() -> SplatOut {
    var out: SplatOut;
    out.position = vec4<f32>(2.0, 2.0, 2.0, 1.0);
    out.radiance = vec3<f32>(0.0);
    return out;
}

fn splat_corner(corner_index: u32) -> vec2<f32> {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(-1.0, 1.0),
        vec2<f32>(-1.0, 1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
    );
    return corners[corner_index % 6u];
}

// Corner `corner_index` of the splat at world position `world`, or a culled one when the centre is
// off screen or behind the G-buffer's surface.
fn splat(world: vec3<f32>, radiance: vec3<f32>, corner_index: u32) -> SplatOut {
    let clip = frame.clip_from_world * vec4<f32>(world, 1.0);
    if (clip.w <= 0.0) {
        return culled();
    }
    let ndc = clip.xyz / clip.w;
    if (any(abs(ndc.xy) > vec2<f32>(1.0)) || ndc.z < 0.0 || ndc.z > 1.0) {
        return culled();
    }
    // The G-buffer texel under the centre (render resolution, y down).
    let render = vec2<f32>(frame.render_size);
    let uv = vec2<f32>(ndc.x * 0.5 + 0.5, 0.5 - ndc.y * 0.5);
    let texel = vec2<u32>(clamp(uv * render, vec2<f32>(0.0), render - vec2<f32>(1.0)));
    let depth = textureLoad(gbuffer_depth, texel, 0);
    let surface_h = frame.world_from_clip * vec4<f32>(ndc.xy, depth, 1.0);
    let eye = frame.camera_position.xyz;
    let surface_distance = length(surface_h.xyz / surface_h.w - eye);
    if (length(world - eye) > surface_distance * (1.0 + DEPTH_TOLERANCE)) {
        return culled();
    }
    // NDC spans the viewport's size in pixels over 2 units: a half side of S/2 pixels is S/size.
    let half_side = vec2<f32>(params.splat_pixels) / vec2<f32>(params.size);
    var out: SplatOut;
    out.position = vec4<f32>((ndc.xy + splat_corner(corner_index) * half_side) * clip.w, clip.z, clip.w);
    out.radiance = radiance;
    return out;
}

@vertex
fn vs_point(@builtin(vertex_index) corner_index: u32, @builtin(instance_index) index: u32) -> SplatOut {
    if (index >= params.instance_count) {
        return culled();
    }
    let point_meta = points_meta[index];
    let point = world_point(points_model[index], point_meta, instances[point_meta.y]);
    let lights = decode_lights(point.position, point_diffuse[index], vec4<u32>(0u), point_extra[index]);
    let irradiance = lights.diffuse * diffuse_point_factor(point.position, point.normal, lights.diffuse_position);
    return splat(point.position, irradiance / PI, corner_index);
}

@vertex
fn vs_val(@builtin(vertex_index) corner_index: u32, @builtin(instance_index) index: u32) -> SplatOut {
    // Slots past the frame's count hold stale or no VALs.
    if (index >= min(min(val_count[0], arrayLength(&vals)), params.instance_count)) {
        return culled();
    }
    let val = vals[index];
    let area = val.position_area.w;
    if (!(area > 0.0)) {
        return culled();
    }
    return splat(val.position_area.xyz, val.flux.rgb / (PI * area), corner_index);
}

fn srgb_oetf(x: f32) -> f32 {
    if (x <= 0.0031308) {
        return 12.92 * x;
    }
    return 1.055 * pow(x, 1.0 / 2.4) - 0.055;
}

@fragment
fn fs_main(in: SplatOut) -> @location(0) vec4<f32> {
    let finite = (in.radiance == in.radiance) & (abs(in.radiance) <= vec3<f32>(3.0e38));
    let sanitized = select(vec3<f32>(0.0), in.radiance, finite);
    var mapped = clamp(sanitized * params.exposure_scale, vec3<f32>(0.0), vec3<f32>(1.0));
    if (params.encode_srgb != 0u) {
        mapped = vec3<f32>(srgb_oetf(mapped.r), srgb_oetf(mapped.g), srgb_oetf(mapped.b));
    }
    return vec4<f32>(mapped, 1.0);
}
