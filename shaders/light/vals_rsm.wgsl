// Reflective shadow map: per texel of one light's view, the surface it sees (position, normal)
// and the flux that surface reflects: Φ = ρ_d·I(ω)·Ω_texel for point and spot lights, with
// Ω_texel = Δ²/(1+u²+v²)^{3/2}; Φ = ρ_d·E·A_texel for directional lights. A = Ω·d² (or the
// texel's area). Texels whose surface faces away from the light reflect nothing.
#include "common.wgsl"

struct RsmView {
    clip_from_world: mat4x4<f32>,
    light_index: u32,
    resolution: u32,
    // tan(fov/2) of a perspective view; 0 for orthographic.
    tan_half_fov: f32,
    // World area of one texel of an orthographic view.
    texel_area: f32,
    // Top-left texel of this view's tile in its physical layer (views may share one).
    tile_origin: vec2<u32>,
}

@group(0) @binding(0) var<uniform> view: RsmView;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;
@group(0) @binding(2) var<storage, read> lights: array<Light>;

@group(1) @binding(0) var<uniform> material: MaterialParams;
@group(1) @binding(1) var material_sampler: sampler;
@group(1) @binding(2) var base_color_texture: texture_2d<f32>;
@group(1) @binding(3) var metallic_roughness_texture: texture_2d<f32>;
@group(1) @binding(4) var normal_texture: texture_2d<f32>;
@group(1) @binding(5) var emissive_texture: texture_2d<f32>;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv0: vec2<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) position_world: vec3<f32>,
    @location(1) normal_world: vec3<f32>,
    @location(2) uv0: vec2<f32>,
}

@vertex
fn vs_main(v: VertexIn, @builtin(instance_index) instance: u32) -> VertexOut {
    let inst = instances[instance];
    let normal_from_model = mat3x3<f32>(inst.normal_from_model[0].xyz, inst.normal_from_model[1].xyz, inst.normal_from_model[2].xyz);
    let world = inst.world_from_model * vec4<f32>(v.position, 1.0);
    var out: VertexOut;
    out.clip = view.clip_from_world * world;
    out.position_world = world.xyz;
    out.normal_world = normal_from_model * v.normal;
    out.uv0 = v.uv0;
    return out;
}

struct RsmOut {
    // xyz: world position; w: area A.
    @location(0) position_area: vec4<f32>,
    // xyz: unit normal, turned toward the light's side like the G-buffer turns it to the eye.
    @location(1) normal: vec4<f32>,
    // rgb: reflected flux; a: 1 where a surface reflects light.
    @location(2) flux: vec4<f32>,
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front_facing: bool) -> RsmOut {
    let light = lights[view.light_index];
    let base_tex = textureSample(base_color_texture, material_sampler, in.uv0);
    let mr_tex = textureSample(metallic_roughness_texture, material_sampler, in.uv0);
    let base = material.base_color.rgb * base_tex.rgb;
    let metallic = clamp(material.metallic * mr_tex.b, 0.0, 1.0);
    let rho_d = diffuse_albedo(base, metallic);
    let side = select(-1.0, 1.0, front_facing);
    let n = normalize(in.normal_world) * side;
    let p = in.position_world;

    var flux = vec3<f32>(0.0);
    var area = 0.0;
    var to_light: vec3<f32>;
    if (light.kind == LIGHT_DIRECTIONAL) {
        to_light = -light.direction.xyz;
        area = view.texel_area;
        flux = rho_d * light.intensity.rgb * area;
    } else {
        let d = p - light.position.xyz;
        let dist = length(d);
        to_light = -d / max(dist, 1e-30);
        // Image-plane coordinates of this texel's centre at unit distance.
        let local = in.clip.xy - vec2<f32>(view.tile_origin);
        let ndc = vec2<f32>(local.x / f32(view.resolution) * 2.0 - 1.0, 1.0 - local.y / f32(view.resolution) * 2.0);
        let uv = ndc * view.tan_half_fov;
        let delta = 2.0 * view.tan_half_fov / f32(view.resolution);
        let q = 1.0 + dot(uv, uv);
        let omega = delta * delta / (q * sqrt(q));
        var intensity = light.intensity.rgb * range_window(light.direction.w, dist);
        if (light.kind == LIGHT_SPOT) {
            intensity *= spot_attenuation(light, -to_light);
        } else if (light.kind == LIGHT_EMITTER) {
            intensity *= emitter_lobe(light, -to_light);
        }
        flux = rho_d * intensity * omega;
        area = omega * dist * dist;
    }
    var out: RsmOut;
    out.position_area = vec4<f32>(p, area);
    out.normal = vec4<f32>(n, 0.0);
    let lit = dot(n, to_light) > 0.0 && max(flux.r, max(flux.g, flux.b)) > 0.0;
    out.flux = select(vec4<f32>(0.0), vec4<f32>(flux, 1.0), lit);
    return out;
}
