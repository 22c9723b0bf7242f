// Light atlas lookup: rasterizes the light-map meshes from the camera and writes, per pixel,
// the atlas irradiance E (W/m²) at the surface's light-map UV. Bilinear filtering by hand
// (rgba32float is not filterable everywhere); texel centres sit at (i + 0.5) / R, the same
// as `atlas::bake::sample_bilinear` on the CPU.

struct AtlasFrame {
    clip_from_world: mat4x4<f32>,
    atlas_size: vec2<u32>,
    pad: vec2<u32>,
}

@group(0) @binding(0) var<uniform> frame: AtlasFrame;
@group(0) @binding(1) var<storage, read> world_from_model: array<mat4x4<f32>>;
@group(0) @binding(2) var atlas: texture_2d<f32>;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) uv: vec2<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

@vertex
fn vs_main(v: VertexIn, @builtin(instance_index) instance: u32) -> VertexOut {
    var out: VertexOut;
    let world = world_from_model[instance] * vec4<f32>(v.position, 1.0);
    out.clip = frame.clip_from_world * world;
    out.uv = v.uv;
    return out;
}

fn atlas_texel(p: vec2<i32>) -> vec3<f32> {
    let size = vec2<i32>(frame.atlas_size);
    return textureLoad(atlas, clamp(p, vec2<i32>(0), size - 1), 0).rgb;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let p = in.uv * vec2<f32>(frame.atlas_size) - 0.5;
    let base = floor(p);
    let f = p - base;
    let b = vec2<i32>(base);
    let e = atlas_texel(b) * (1.0 - f.x) * (1.0 - f.y)
        + atlas_texel(b + vec2<i32>(1, 0)) * f.x * (1.0 - f.y)
        + atlas_texel(b + vec2<i32>(0, 1)) * (1.0 - f.x) * f.y
        + atlas_texel(b + vec2<i32>(1, 1)) * f.x * f.y;
    return vec4<f32>(e, 1.0);
}
