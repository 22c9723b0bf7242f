// Reflective shadow map: per texel of one light's view, the surface it sees (position, normal)
// and the flux that surface reflects: Φ = ρ_d·I(ω)·Ω_texel for point and spot lights, with
// Ω_texel = ∫ (1+u²+v²)^{-3/2} over the texel's image-plane square; Φ = ρ_d·E·A_texel for directional lights. A = Ω·d² (or the
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

// Solid angle of texel `texel` of a side² perspective view with tan(fov/2) = t: the integral
// of (1+u²+v²)^{-3/2} over the texel's square on the unit image plane. Small views (a light
// that --max-vals shrank) take the exact corner formula, where the centre rule would
// overestimate a 2² face by 4 % and a 1² face by 91 %; larger ones 2×2 Gauss points, where
// the corner formula's differences would cancel in f32. The CPU twin is
// `light::rsm::texel_solid_angle`.
fn texel_solid_angle(texel: vec2<u32>, side: u32, t: f32) -> f32 {
    let delta = 2.0 * t / f32(side);
    let lo = vec2<f32>(-t + f32(texel.x) * delta, t - f32(texel.y + 1u) * delta);
    let hi = lo + vec2<f32>(delta);
    if (side <= EXACT_SOLID_ANGLE_SIDE) {
        return abs(corner_solid_angle(hi.x, hi.y) - corner_solid_angle(lo.x, hi.y)
            - corner_solid_angle(hi.x, lo.y) + corner_solid_angle(lo.x, lo.y));
    }
    let centre = 0.5 * (lo + hi);
    let g = delta / (2.0 * sqrt(3.0));
    var sum = 0.0;
    for (var i = 0u; i < 4u; i++) {
        let uv = centre + g * vec2<f32>(select(-1.0, 1.0, (i & 1u) != 0u), select(-1.0, 1.0, i >= 2u));
        let q = 1.0 + dot(uv, uv);
        sum += 1.0 / (q * sqrt(q));
    }
    return 0.25 * sum * delta * delta;
}

const EXACT_SOLID_ANGLE_SIDE: u32 = 16u;

// Solid angle of the image-plane rectangle [0,u]×[0,v] at unit distance (signed).
fn corner_solid_angle(u: f32, v: f32) -> f32 {
    return atan(u * v / sqrt(1.0 + u * u + v * v));
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
        let texel = vec2<u32>(in.clip.xy - vec2<f32>(view.tile_origin));
        let omega = texel_solid_angle(texel, view.resolution, view.tan_half_fov);
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
