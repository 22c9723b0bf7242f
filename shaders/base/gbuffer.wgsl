// G-buffer: per pixel the shading normal (normal map applied) and the material reduced to
// ρ_d, ρ_s, k and emission. Position comes from the depth buffer.
#include "common.wgsl"

@group(0) @binding(0) var<uniform> frame: Frame;
@group(0) @binding(1) var<storage, read> instances: array<InstanceData>;

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
    @location(3) tangent: vec4<f32>,
}

struct VertexOut {
    // Invariant so that later passes drawing the same geometry (the sparse VAL apply pass)
    // can depth-test with Equal against this depth.
    @builtin(position) @invariant clip: vec4<f32>,
    @location(0) normal_world: vec3<f32>,
    @location(1) uv0: vec2<f32>,
    @location(2) tangent_world: vec4<f32>,
}

@vertex
fn vs_main(v: VertexIn, @builtin(instance_index) instance: u32) -> VertexOut {
    let inst = instances[instance];
    let normal_from_model = mat3x3<f32>(inst.normal_from_model[0].xyz, inst.normal_from_model[1].xyz, inst.normal_from_model[2].xyz);
    let world_from_model3 = mat3x3<f32>(inst.world_from_model[0].xyz, inst.world_from_model[1].xyz, inst.world_from_model[2].xyz);
    var out: VertexOut;
    out.clip = frame.clip_from_world * (inst.world_from_model * vec4<f32>(v.position, 1.0));
    out.normal_world = normal_from_model * v.normal;
    out.uv0 = v.uv0;
    out.tangent_world = vec4<f32>(world_from_model3 * v.tangent.xyz, v.tangent.w);
    return out;
}

struct GBufferOut {
    // xyz: unit shading normal, world space.
    @location(0) normal: vec4<f32>,
    // rgb: ρ_d; a: Phong exponent k.
    @location(1) diffuse: vec4<f32>,
    // rgb: ρ_s; a: 1 where a surface was drawn.
    @location(2) specular: vec4<f32>,
    // rgb: emitted radiance.
    @location(3) emissive: vec4<f32>,
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front_facing: bool) -> GBufferOut {
    let base_tex = textureSample(base_color_texture, material_sampler, in.uv0);
    let mr_tex = textureSample(metallic_roughness_texture, material_sampler, in.uv0);
    let normal_tex = textureSample(normal_texture, material_sampler, in.uv0).xyz;
    let emissive_tex = textureSample(emissive_texture, material_sampler, in.uv0).rgb;

    let base = material.base_color.rgb * base_tex.rgb;
    // glTF packs roughness in G and metallic in B.
    let roughness = clamp(material.roughness * mr_tex.g, 0.0, 1.0);
    let metallic = clamp(material.metallic * mr_tex.b, 0.0, 1.0);

    // Back faces of double-sided (or open) geometry shade with the normal facing the viewer.
    let side = select(-1.0, 1.0, front_facing);
    var n = normalize(in.normal_world) * side;
    let t_len = length(in.tangent_world.xyz);
    if (t_len > 0.0) {
        let t = normalize(in.tangent_world.xyz - n * dot(n, in.tangent_world.xyz));
        let b = cross(n, t) * in.tangent_world.w;
        var tn = normal_tex * 2.0 - 1.0;
        tn = vec3<f32>(tn.xy * material.normal_scale, tn.z);
        let mapped = t * tn.x + b * tn.y + n * tn.z;
        if (dot(mapped, mapped) > 1e-12) {
            n = normalize(mapped);
        }
    }

    var out: GBufferOut;
    out.normal = vec4<f32>(n, 0.0);
    out.diffuse = vec4<f32>(diffuse_albedo(base, metallic), phong_exponent(roughness));
    out.specular = vec4<f32>(specular_albedo(base, metallic, material.specular_factor), 1.0);
    out.emissive = vec4<f32>(material.emissive.rgb * emissive_tex, 0.0);
    return out;
}
