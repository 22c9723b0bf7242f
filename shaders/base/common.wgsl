// Shared definitions: the structs every pass sees (mirrored by #[repr(C)] types in
// src/raster/types.rs, checked against naga's layout in tests) and the material model of
// DESIGN §3.

const PI: f32 = 3.14159265358979;

const LIGHT_POINT: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_DIRECTIONAL: u32 = 2u;
// A Lambertian emitter standing for emissive triangles: a point light whose intensity is
// I0·max(0, n̄·ω), n̄ = direction.xyz.
const LIGHT_EMITTER: u32 = 3u;

struct Frame {
    clip_from_world: mat4x4<f32>,
    world_from_clip: mat4x4<f32>,
    camera_position: vec4<f32>,
    // Size of the render targets (output size × SSAA factor).
    render_size: vec2<u32>,
    light_count: u32,
    shadow_pcf_radius: u32,
}

struct Light {
    // xyz: world position (point, spot, emitter).
    position: vec4<f32>,
    // xyz: unit direction the light points along (spot, directional; an emitter's n̄); w: range
    // (0 = none).
    direction: vec4<f32>,
    // rgb: W/sr (point, spot; I0 of an emitter) or W/m² (directional).
    intensity: vec4<f32>,
    kind: u32,
    // First shadow view; point lights and emitters use six consecutive views. NO_SHADOW: none.
    first_shadow_view: u32,
    // KHR_lights_punctual cone: attenuation = saturate(cos·scale + offset)².
    cone_scale: f32,
    cone_offset: f32,
}

struct ShadowView {
    clip_from_world: mat4x4<f32>,
    // xyz: the light's position (perspective) or zero (orthographic); w: 1 perspective, 0 ortho.
    origin: vec4<f32>,
    // x: world size of one texel at unit distance (perspective) or absolute (ortho);
    // y: the view's resolution (its tile's side); z: near plane; w: far plane.
    texel: vec4<f32>,
    // xyz: (u0, v0, size) of the view's tile in its layer's texture coordinates.
    atlas_rect: vec4<f32>,
    atlas_layer: u32,
}

const NO_SHADOW: u32 = 0xffffffffu;

struct InstanceData {
    world_from_model: mat4x4<f32>,
    // Inverse transpose of world_from_model's upper 3×3, as columns of a mat4 for alignment.
    normal_from_model: mat4x4<f32>,
}

struct MaterialParams {
    base_color: vec4<f32>,
    // rgb: emitted radiance W/(m²·sr) (factor × strength); a: unused.
    emissive: vec4<f32>,
    metallic: f32,
    roughness: f32,
    specular_factor: f32,
    normal_scale: f32,
}

// f_r = ρ_d/π + ρ_s·(k+2)/(2π)·max(0, r·ω_i)^k with r = reflect(−ω_o, n) (DESIGN §3).
fn brdf(rho_d: vec3<f32>, rho_s: vec3<f32>, k: f32, n: vec3<f32>, wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32> {
    let r = reflect(-wo, n);
    let lobe = pow(max(dot(r, wi), 0.0), k);
    return rho_d / PI + rho_s * ((k + 2.0) / (2.0 * PI)) * lobe;
}

// KHR_lights_punctual spot cone: saturate(cos·scale + offset)², squared linear ramp in cosine.
fn spot_attenuation(light: Light, to_surface: vec3<f32>) -> f32 {
    let cd = dot(light.direction.xyz, to_surface);
    let a = clamp(cd * light.cone_scale + light.cone_offset, 0.0, 1.0);
    return a * a;
}

// Lambertian emitter lobe max(0, n̄·ω) toward the unit direction to_surface.
fn emitter_lobe(light: Light, to_surface: vec3<f32>) -> f32 {
    return max(dot(light.direction.xyz, to_surface), 0.0);
}

// KHR_lights_punctual range window clamp(1 − (d/range)⁴, 0, 1), 1 when the glTF sets no range.
fn range_window(range: f32, distance: f32) -> f32 {
    if (range <= 0.0) {
        return 1.0;
    }
    let x = distance / range;
    let x2 = x * x;
    return clamp(1.0 - x2 * x2, 0.0, 1.0);
}

// ρ_d, ρ_s and k from glTF metallic-roughness values (DESIGN §3).
fn diffuse_albedo(base: vec3<f32>, metallic: f32) -> vec3<f32> {
    return base * (1.0 - metallic);
}

fn specular_albedo(base: vec3<f32>, metallic: f32, specular_factor: f32) -> vec3<f32> {
    return mix(vec3<f32>(0.04), base, metallic) * specular_factor;
}

fn phong_exponent(roughness: f32) -> f32 {
    let alpha = max(roughness * roughness, 1e-4);
    return clamp(2.0 / (alpha * alpha) - 2.0, 1.0, 10000.0);
}
