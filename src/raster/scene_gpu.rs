//! The scene as GPU resources: one vertex and index buffer per mesh, a bind group per material
//! (textures with mip chains, default 1×1 textures where a material has none), and a storage
//! buffer of per-instance transforms refreshed every frame so rigid motion costs one upload.

use std::sync::Arc;

use glam::{Mat3, Mat4, Vec4};
use rayon::prelude::*;

use super::types::{InstanceData, MaterialParams, Vertex};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{GpuBytes, GpuContext};
use crate::scene::{ColorSpace, Scene, Texture};

/// The scene does not fit the device (a mesh larger than the biggest buffer, say).
#[derive(Debug, thiserror::Error)]
#[error("scene '{scene}' does not fit the GPU: {message}")]
pub struct SceneTooLarge {
    pub scene: String,
    pub message: String,
}

pub struct GpuMesh {
    pub vertex_buffer: wgpu::Buffer,
    pub index_buffer: wgpu::Buffer,
    pub index_count: u32,
    pub material: usize,
}

pub struct SceneGpu {
    pub meshes: Vec<GpuMesh>,
    pub material_layout: GroupLayout,
    pub material_bind_groups: Vec<wgpu::BindGroup>,
    /// `InstanceData` per scene instance, indexed by `@builtin(instance_index)`.
    pub instance_buffer: wgpu::Buffer,
    /// Mesh index of each instance, in the order of `instance_buffer`.
    pub instance_meshes: Vec<usize>,
    pub bytes: GpuBytes,
}

impl SceneGpu {
    /// `scene`'s upload, the one a live user of the same content (`content_key`,
    /// [`Scene::content_key`]) holds on this device or else a new one
    /// ([`GpuContext::live_by_key`]). Its per-frame state, the instances' transforms, is
    /// written by each user before its own submission.
    pub fn shared(
        ctx: &GpuContext,
        scene: &Scene,
        content_key: u64,
    ) -> Result<Arc<Self>, SceneTooLarge> {
        ctx.live_by_key(content_key, || Self::upload(ctx, scene))
    }

    pub fn upload(ctx: &GpuContext, scene: &Scene) -> Result<Self, SceneTooLarge> {
        let device = &ctx.device;
        let limits = device.limits();
        let mut bytes = GpuBytes::default();
        let too_large = |message: String| SceneTooLarge {
            scene: scene.name.clone(),
            message,
        };

        let mut meshes = Vec::with_capacity(scene.meshes.len());
        for mesh in &scene.meshes {
            let vertices: Vec<Vertex> = (0..mesh.positions.len())
                .map(|i| Vertex {
                    position: mesh.positions[i].to_array(),
                    normal: mesh
                        .normals
                        .get(i)
                        .copied()
                        .unwrap_or(glam::Vec3::Y)
                        .to_array(),
                    uv0: mesh.uv0.get(i).copied().unwrap_or_default().to_array(),
                    // A zero tangent tells the shader to skip normal mapping.
                    tangent: mesh
                        .tangents
                        .get(i)
                        .copied()
                        .unwrap_or(Vec4::ZERO)
                        .to_array(),
                })
                .collect();
            let vertex_bytes = std::mem::size_of_val(vertices.as_slice()) as u64;
            if vertex_bytes > limits.max_buffer_size {
                return Err(too_large(format!(
                    "mesh '{}' needs a {vertex_bytes}-byte vertex buffer; the device allows {}",
                    mesh.name, limits.max_buffer_size
                )));
            }
            let vertex_buffer = bytes.buffer_init(
                device,
                &format!("{} vertices", mesh.name),
                bytemuck::cast_slice(&vertices),
                wgpu::BufferUsages::VERTEX,
            );
            let index_buffer = bytes.buffer_init(
                device,
                &format!("{} indices", mesh.name),
                bytemuck::cast_slice(&mesh.indices),
                wgpu::BufferUsages::INDEX,
            );
            meshes.push(GpuMesh {
                vertex_buffer,
                index_buffer,
                index_count: mesh.indices.len() as u32,
                material: mesh.material,
            });
        }

        let material_layout = material_bind_group_layout(device);
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("material sampler"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            mipmap_filter: wgpu::MipmapFilterMode::Linear,
            anisotropy_clamp: 1,
            ..Default::default()
        });
        let max_dim = limits.max_texture_dimension_2d;
        let textures: Vec<wgpu::TextureView> = scene
            .textures
            .iter()
            .map(|t| upload_texture(ctx, &mut bytes, t, max_dim))
            .collect();
        let white = upload_texture(
            ctx,
            &mut bytes,
            &Texture {
                name: "white".into(),
                width: 1,
                height: 1,
                rgba8: vec![255; 4],
                color_space: ColorSpace::Linear,
            },
            max_dim,
        );
        let flat_normal = upload_texture(
            ctx,
            &mut bytes,
            &Texture {
                name: "flat normal".into(),
                width: 1,
                height: 1,
                rgba8: vec![128, 128, 255, 255],
                color_space: ColorSpace::Linear,
            },
            max_dim,
        );
        let pick = |index: Option<usize>, fallback: &wgpu::TextureView| -> wgpu::TextureView {
            index
                .and_then(|i| textures.get(i))
                .unwrap_or(fallback)
                .clone()
        };
        let material_bind_groups = scene
            .materials
            .iter()
            .map(|m| {
                let params = MaterialParams {
                    base_color: m.base_color.to_array(),
                    emissive: m.emissive.extend(0.0).to_array(),
                    metallic: m.metallic,
                    roughness: m.roughness,
                    specular_factor: m.specular_factor,
                    normal_scale: m.normal_scale,
                };
                let uniform = bytes.buffer_init(
                    device,
                    &format!("material {}", m.name),
                    bytemuck::bytes_of(&params),
                    wgpu::BufferUsages::UNIFORM,
                );
                let views = [
                    pick(m.base_color_texture, &white),
                    pick(m.metallic_roughness_texture, &white),
                    pick(m.normal_texture, &flat_normal),
                    pick(m.emissive_texture, &white),
                ];
                material_layout.bind(
                    device,
                    &[
                        &uniform, &sampler, &views[0], &views[1], &views[2], &views[3],
                    ],
                )
            })
            .collect();

        let instance_count = scene.instances.len().max(1);
        let instance_buffer = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("instances"),
                size: (instance_count * std::mem::size_of::<InstanceData>()) as u64,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            },
        );
        let gpu = Self {
            meshes,
            material_layout,
            material_bind_groups,
            instance_buffer,
            instance_meshes: scene.instances.iter().map(|i| i.mesh).collect(),
            bytes,
        };
        gpu.update_transforms(ctx, scene, &scene.world_from_node());
        Ok(gpu)
    }

    /// Uploads the instances' world transforms (one small write per frame).
    pub fn update_transforms(&self, ctx: &GpuContext, scene: &Scene, world_from_node: &[Mat4]) {
        let data: Vec<InstanceData> = scene
            .instances
            .iter()
            .map(|inst| instance_data(world_from_node[inst.node]))
            .collect();
        if !data.is_empty() {
            ctx.queue
                .write_buffer(&self.instance_buffer, 0, bytemuck::cast_slice(&data));
        }
    }

    /// Draws every instance; `material_group` is the bind group slot for materials, if the
    /// pipeline has one.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'_>, material_group: Option<u32>) {
        for (instance, &mesh_index) in self.instance_meshes.iter().enumerate() {
            let mesh = &self.meshes[mesh_index];
            if mesh.index_count == 0 {
                continue;
            }
            if let Some(group) = material_group {
                pass.set_bind_group(group, &self.material_bind_groups[mesh.material], &[]);
            }
            pass.set_vertex_buffer(0, mesh.vertex_buffer.slice(..));
            pass.set_index_buffer(mesh.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
            let i = instance as u32;
            pass.draw_indexed(0..mesh.index_count, 0, i..i + 1);
        }
    }
}

/// Transforms for one instance. Normals use the inverse transpose so non-uniform scale keeps
/// them perpendicular to the surface.
pub fn instance_data(world_from_model: Mat4) -> InstanceData {
    let m3 = Mat3::from_mat4(world_from_model);
    let det = m3.determinant();
    let normal3 = if det.abs() > 1e-20 {
        m3.inverse().transpose()
    } else {
        Mat3::IDENTITY
    };
    InstanceData {
        world_from_model: world_from_model.to_cols_array_2d(),
        normal_from_model: Mat4::from_mat3(normal3).to_cols_array_2d(),
    }
}

/// The material group of `gbuffer.wgsl` and `vals_rsm.wgsl` (fragment stage): the material
/// parameters, the filtering sampler, and the base-colour, metallic-roughness, normal and
/// emissive textures.
const MATERIAL_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::FilteringSampler,
    Slot::FilterableTexture,
    Slot::FilterableTexture,
    Slot::FilterableTexture,
    Slot::FilterableTexture,
];

fn material_bind_group_layout(device: &wgpu::Device) -> GroupLayout {
    GroupLayout::new(
        device,
        "material",
        wgpu::ShaderStages::FRAGMENT,
        MATERIAL_BINDINGS,
    )
}

/// Uploads an RGBA8 texture with a full mip chain (box-filtered in linear space, so sRGB
/// textures do not darken in the distance). Textures beyond the device's limit are halved
/// until they fit.
fn upload_texture(
    ctx: &GpuContext,
    bytes: &mut GpuBytes,
    texture: &Texture,
    max_dim: u32,
) -> wgpu::TextureView {
    let srgb = texture.color_space == ColorSpace::Srgb;
    let mut level = MipLevel::from_texture(texture, srgb);
    while level.width > max_dim || level.height > max_dim {
        log::warn!(
            "texture '{}' ({}×{}) exceeds the device limit {max_dim}; halving it",
            texture.name,
            level.width,
            level.height
        );
        level = level.half(srgb);
    }
    let mip_count = 32 - level.width.max(level.height).leading_zeros();
    let format = if srgb {
        wgpu::TextureFormat::Rgba8UnormSrgb
    } else {
        wgpu::TextureFormat::Rgba8Unorm
    };
    let gpu_texture = bytes.texture(
        &ctx.device,
        &wgpu::TextureDescriptor {
            label: Some(&texture.name),
            size: wgpu::Extent3d {
                width: level.width,
                height: level.height,
                depth_or_array_layers: 1,
            },
            mip_level_count: mip_count,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        },
    );
    for mip in 0..mip_count {
        ctx.write_texture_2d(
            &gpu_texture,
            mip,
            &level.rgba8,
            (level.width, level.height),
            4,
        );
        if mip + 1 < mip_count {
            level = level.half(srgb);
        }
    }
    gpu_texture.create_view(&wgpu::TextureViewDescriptor::default())
}

struct MipLevel {
    width: u32,
    height: u32,
    rgba8: Vec<u8>,
}

impl MipLevel {
    fn from_texture(texture: &Texture, _srgb: bool) -> Self {
        let expected = (texture.width * texture.height * 4) as usize;
        let mut rgba8 = texture.rgba8.clone();
        // A short or long pixel array (bad source data) is padded or cut, never read past.
        rgba8.resize(expected, 255);
        Self {
            width: texture.width.max(1),
            height: texture.height.max(1),
            rgba8,
        }
    }

    /// The next mip level: each texel averages the 2×2 (or fewer, at odd edges) texels above.
    fn half(&self, srgb: bool) -> Self {
        let width = (self.width / 2).max(1);
        let height = (self.height / 2).max(1);
        let lut = srgb_decode_table();
        let to_linear = |v: u8, channel: usize| -> f32 {
            if srgb && channel < 3 {
                lut[v as usize]
            } else {
                v as f32 / 255.0
            }
        };
        let to_byte = |x: f32, channel: usize| -> u8 {
            let y = if srgb && channel < 3 {
                linear_to_srgb(x)
            } else {
                x
            };
            (y * 255.0 + 0.5).clamp(0.0, 255.0) as u8
        };
        let mut rgba8 = vec![0u8; (width * height * 4) as usize];
        // Rows in parallel: a large scene's textures (Sponza's) made this the rasterizer's
        // largest set-up cost on one thread. Each texel is computed as before, so the chain
        // is the same to the bit.
        rgba8
            .par_chunks_mut((width * 4) as usize)
            .enumerate()
            .for_each(|(y, row)| {
                let y = y as u32;
                for x in 0..width {
                    for c in 0..4 {
                        let mut sum = 0.0;
                        let mut n = 0.0;
                        for sy in 0..2 {
                            for sx in 0..2 {
                                let px = (2 * x + sx).min(self.width - 1);
                                let py = (2 * y + sy).min(self.height - 1);
                                let v = self.rgba8[((py * self.width + px) * 4) as usize + c];
                                sum += to_linear(v, c);
                                n += 1.0;
                            }
                        }
                        row[(x * 4) as usize + c] = to_byte(sum / n, c);
                    }
                }
            });
        Self {
            width,
            height,
            rgba8,
        }
    }
}

/// sRGB-encoded byte → linear value, computed once.
fn srgb_decode_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}

pub fn srgb_to_linear(x: f32) -> f32 {
    if x <= 0.04045 {
        x / 12.92
    } else {
        ((x + 0.055) / 1.055).powf(2.4)
    }
}

pub fn linear_to_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.0031308 {
        x * 12.92
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The parallel mip step against the 2×2 box average written out per texel, on an odd
    /// size (edge texels repeat) and with sRGB decoding on the colour channels only.
    #[test]
    fn half_averages_each_two_by_two_block_in_linear_space() {
        let (width, height) = (7u32, 5u32);
        let rgba8: Vec<u8> = (0..width * height * 4)
            .map(|i| (i * 37 % 251) as u8)
            .collect();
        let level = MipLevel {
            width,
            height,
            rgba8: rgba8.clone(),
        };
        for srgb in [false, true] {
            let half = level.half(srgb);
            assert_eq!((half.width, half.height), (3, 2));
            for y in 0..half.height {
                for x in 0..half.width {
                    for c in 0..4usize {
                        let decode = |v: u8| {
                            if srgb && c < 3 {
                                srgb_to_linear(v as f32 / 255.0)
                            } else {
                                v as f32 / 255.0
                            }
                        };
                        let mut sum = 0.0;
                        for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                            let px = (2 * x + sx).min(width - 1);
                            let py = (2 * y + sy).min(height - 1);
                            sum += decode(rgba8[((py * width + px) * 4) as usize + c]);
                        }
                        let mean = sum / 4.0;
                        let encoded = if srgb && c < 3 {
                            linear_to_srgb(mean)
                        } else {
                            mean
                        };
                        let want = (encoded * 255.0 + 0.5).clamp(0.0, 255.0) as u8;
                        let got = half.rgba8[((y * half.width + x) * 4) as usize + c];
                        assert!(
                            (got as i32 - want as i32).abs() <= 1,
                            "texel ({x}, {y}) channel {c} srgb {srgb}: {got} vs {want}"
                        );
                    }
                }
            }
        }
    }
}
