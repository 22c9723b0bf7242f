// Step 4 — apply: rasterize the scene again with each vertex's two point lights as varyings
// and shade every visible pixel with its own normal (normal maps), view direction and
// material from the G-buffer. Depth-tested Equal against the G-buffer (both vertex stages are
// @invariant), so each pixel is shaded once, by the surface the G-buffer holds.
#include "vals_common.wgsl"

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> ranges: array<InstanceRange>;
@group(0) @binding(3) var<storage, read> vertex_lights: array<vec4<f32>>;
@group(0) @binding(4) var gbuffer_normal: texture_2d<f32>;
@group(0) @binding(5) var gbuffer_diffuse: texture_2d<f32>;
@group(0) @binding(6) var gbuffer_specular: texture_2d<f32>;
@group(0) @binding(7) var<uniform> params: SparseParams;

struct VertexOut {
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) position_world: vec3<f32>,
    @location(1) diffuse_position: vec3<f32>,
    @location(2) diffuse: vec3<f32>,
    @location(3) glossy_position: vec3<f32>,
    @location(4) glossy: vec3<f32>,
    // A two-sided sheet's back-face lights (the front ones again for a one-sided mesh).
    @location(5) back_diffuse_position: vec3<f32>,
    @location(6) back_diffuse: vec3<f32>,
    @location(7) back_glossy_position: vec3<f32>,
    @location(8) back_glossy: vec3<f32>,
}

@vertex
fn vs_main(@location(0) position: vec3<f32>, @builtin(vertex_index) vertex: u32, @builtin(instance_index) instance: u32) -> VertexOut {
    let inst = instances[instance];
    let world = inst.world_from_model * vec4<f32>(position, 1.0);
    let range = ranges[instance];
    let v = range.vertex_offset + vertex;
    let a = vertex_lights[v * 3u];
    let b = vertex_lights[v * 3u + 1u];
    let c = vertex_lights[v * 3u + 2u];
    let vb = v + range.back_offset;
    let ba = vertex_lights[vb * 3u];
    let bb = vertex_lights[vb * 3u + 1u];
    let bc = vertex_lights[vb * 3u + 2u];
    var out: VertexOut;
    out.back_diffuse_position = ba.xyz;
    out.back_diffuse = vec3<f32>(ba.w, bb.xy);
    out.back_glossy_position = vec3<f32>(bb.zw, bc.x);
    out.back_glossy = bc.yzw;
    // The same expression as the G-buffer's, so @invariant gives the same depth.
    out.clip = frame.clip_from_world * (inst.world_from_model * vec4<f32>(position, 1.0));
    out.position_world = world.xyz;
    out.diffuse_position = a.xyz;
    out.diffuse = vec3<f32>(a.w, b.xy);
    out.glossy_position = vec3<f32>(b.zw, c.x);
    out.glossy = c.yzw;
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front_facing: bool) -> @location(0) vec4<f32> {
    // The G-buffer holds a back face's flipped normal; its lights are the back ones.
    let diffuse_position = select(in.back_diffuse_position, in.diffuse_position, front_facing);
    let diffuse = select(in.back_diffuse, in.diffuse, front_facing);
    let glossy_position = select(in.back_glossy_position, in.glossy_position, front_facing);
    let glossy = select(in.back_glossy, in.glossy, front_facing);
    let pixel = vec2<i32>(in.clip.xy);
    let n = normalize(textureLoad(gbuffer_normal, pixel, 0).xyz);
    let diffuse_tex = textureLoad(gbuffer_diffuse, pixel, 0);
    let rho_d = diffuse_tex.rgb;
    let k = diffuse_tex.a;
    let rho_s = textureLoad(gbuffer_specular, pixel, 0).rgb;
    let p = in.position_world;
    var radiance = rho_d / PI * diffuse * diffuse_point_factor(p, n, diffuse_position);
    if ((params.flags & FLAG_GLOSSY) != 0u) {
        let wo = normalize(frame.camera_position.xyz - p);
        let r = reflect(-wo, n);
        radiance += rho_s * ((k + 2.0) / (2.0 * PI)) * glossy * glossy_point_factor(p, n, r, k, glossy_position);
    }
    return vec4<f32>(radiance, 1.0);
}
