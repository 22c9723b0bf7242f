//! `#[repr(C)]` mirrors of the WGSL structs in `shaders/base/common.wgsl` and `shaders/base/resolve.wgsl`.
//! `tests/shader_layout.rs` checks every size and field offset against naga's reflection.

use bytemuck::{Pod, Zeroable};

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FrameUniforms {
    pub clip_from_world: [[f32; 4]; 4],
    pub world_from_clip: [[f32; 4]; 4],
    pub camera_position: [f32; 4],
    pub render_size: [u32; 2],
    pub light_count: u32,
    pub shadow_pcf_radius: u32,
}

pub const LIGHT_POINT: u32 = 0;
pub const LIGHT_SPOT: u32 = 1;
pub const LIGHT_DIRECTIONAL: u32 = 2;
/// A Lambertian emitter (proxy of emissive triangles): a point light with the lobe
/// `max(0, n̄·ω)`, n̄ = `direction.xyz`.
pub const LIGHT_EMITTER: u32 = 3;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct GpuLight {
    pub position: [f32; 4],
    pub direction: [f32; 4],
    pub intensity: [f32; 4],
    pub kind: u32,
    pub first_shadow_view: u32,
    pub cone_scale: f32,
    pub cone_offset: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ShadowView {
    pub clip_from_world: [[f32; 4]; 4],
    pub origin: [f32; 4],
    pub texel: [f32; 4],
    /// `(u0, v0, size)` of the view's tile in its layer's texture coordinates (`w` unused).
    pub atlas_rect: [f32; 4],
    pub atlas_layer: u32,
    pub _pad: [u32; 3],
}

/// `GpuLight::first_shadow_view` of a light without a shadow map (over the shadow budget).
pub const NO_SHADOW: u32 = u32::MAX;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct InstanceData {
    pub world_from_model: [[f32; 4]; 4],
    pub normal_from_model: [[f32; 4]; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct MaterialParams {
    pub base_color: [f32; 4],
    pub emissive: [f32; 4],
    pub metallic: f32,
    pub roughness: f32,
    pub specular_factor: f32,
    pub normal_scale: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ResolveParams {
    pub output_size: [u32; 2],
    pub ssaa: u32,
    pub has_indirect: u32,
}

/// Interleaved vertex as uploaded for rasterization.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub uv0: [f32; 2],
    pub tangent: [f32; 4],
}

impl Vertex {
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 4] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2, 3 => Float32x4];

    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &Self::ATTRIBUTES,
        }
    }
}

/// A Rust struct's layout as the layout test compares it with naga's reflection.
pub struct SharedLayout {
    pub wgsl_name: &'static str,
    /// Shader file (includes resolved) that declares the struct.
    pub file: &'static str,
    pub size: usize,
    /// Field names and byte offsets, in declaration order.
    pub fields: Vec<(&'static str, usize)>,
}

/// `SharedLayout` of a `#[repr(C)]` struct: `shared_layout!("WgslName", "file.wgsl", RustType,
/// [fields in declaration order])`.
macro_rules! shared_layout {
    ($wgsl:literal, $file:literal, $ty:ty, [$($field:ident),*]) => {
        $crate::raster::types::SharedLayout {
            wgsl_name: $wgsl,
            file: $file,
            size: std::mem::size_of::<$ty>(),
            fields: vec![$((stringify!($field), std::mem::offset_of!($ty, $field))),*],
        }
    };
}
pub(crate) use shared_layout;

/// The base layer's structs shared with WGSL (each technique lists its own; the registry
/// collects them all for the layout test).
pub fn shared_layouts() -> Vec<SharedLayout> {
    use shared_layout as layout;
    vec![
        layout!(
            "Frame",
            "common.wgsl",
            FrameUniforms,
            [
                clip_from_world,
                world_from_clip,
                camera_position,
                render_size,
                light_count,
                shadow_pcf_radius
            ]
        ),
        layout!(
            "Light",
            "common.wgsl",
            GpuLight,
            [
                position,
                direction,
                intensity,
                kind,
                first_shadow_view,
                cone_scale,
                cone_offset
            ]
        ),
        layout!(
            "ShadowView",
            "common.wgsl",
            ShadowView,
            [clip_from_world, origin, texel, atlas_rect, atlas_layer]
        ),
        layout!(
            "InstanceData",
            "common.wgsl",
            InstanceData,
            [world_from_model, normal_from_model]
        ),
        layout!(
            "MaterialParams",
            "common.wgsl",
            MaterialParams,
            [
                base_color,
                emissive,
                metallic,
                roughness,
                specular_factor,
                normal_scale
            ]
        ),
        layout!(
            "ResolveParams",
            "resolve.wgsl",
            ResolveParams,
            [output_size, ssaa, has_indirect]
        ),
    ]
}
