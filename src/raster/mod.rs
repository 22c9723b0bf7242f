//! Rasterization shared by every method: shadow maps (view-free), and per view the G-buffer
//! and direct lighting. Indirect methods render into [`FrameTargets::radiance_indirect`]
//! between the direct pass and the view's resolve, so direct and indirect light stay separate
//! to the end.

pub mod scene_gpu;
pub mod shadow_atlas;
pub mod shadows;
pub mod types;

use std::sync::Arc;

use glam::Mat4;

use crate::frame::View;
pub use crate::frame::{FrameOutput, FrameTargets};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{GpuBytes, GpuContext, GpuError, Passes};
use crate::scene::{Aabb, CameraView, Scene};
use scene_gpu::{SceneGpu, SceneTooLarge};
use types::{ShadowView, Vertex};

/// Size and quality knobs shared by every method.
#[derive(Clone, Copy, Debug)]
pub struct RenderSettings {
    pub width: u32,
    pub height: u32,
    /// N×N supersampling per output pixel (1 = none).
    pub ssaa: u32,
    /// Shadow-map resolution per layer.
    pub shadow_resolution: u32,
    /// PCF kernel radius in texels ((2r+1)² bilinear comparison taps).
    pub pcf_radius: u32,
    /// Budget of the shadow maps in MiB: lights share it by power ([`shadow_atlas`]).
    pub shadow_memory_mib: u32,
    /// Most VALs the RSMs of all lights may make together: beyond it the lights share them
    /// by power ([`crate::light::rsm::share_sides`]).
    pub max_vals: u32,
    /// Cap on the GPU memory a method may own, in MiB (`--gpu-memory`; `None`: the device's
    /// own limits). Shadow maps and RSMs each get at most a quarter of it, and a method whose
    /// buffers and textures exceed it is refused before it renders.
    pub gpu_memory_mib: Option<u32>,
    /// The scene camera (index into `Scene::cameras`) the frames are drawn from, for what a
    /// method builds from the camera's view before any frame (budget mode's survey); `None`:
    /// the scene's first camera, or the framing default without one.
    pub camera: Option<usize>,
    /// Views each frame records (`--views`: two for stereo, one per CAVE wall), for what a
    /// method times before any frame: budget mode's timing pilots record as many, each of
    /// `width` × `height`, through the scene camera.
    pub views_per_frame: u32,
}

impl RenderSettings {
    /// The shadow maps' budget in bytes: `--shadow-memory`, within a quarter of `--gpu-memory`.
    pub fn shadow_budget_bytes(&self) -> u64 {
        let own = self.shadow_memory_mib as u64 * (1 << 20);
        self.gpu_memory_mib
            .map_or(own, |gpu| own.min(gpu as u64 * (1 << 20) / 4))
    }

    /// Most VALs the RSMs may make: `--max-vals`, within a quarter of `--gpu-memory` at
    /// [`crate::light::rsm::BYTES_PER_VAL`] each.
    pub fn val_budget(&self) -> u32 {
        self.gpu_memory_mib.map_or(self.max_vals, |gpu| {
            let fit = gpu as u64 * (1 << 20) / 4 / crate::light::rsm::BYTES_PER_VAL;
            self.max_vals.min(fit.min(u32::MAX as u64) as u32)
        })
    }

    /// How a message names a budget: the option itself (`option`, e.g. "--max-vals 5"), or,
    /// under `--gpu-memory`, the `amount` in force and where it comes from.
    pub fn budget_name(&self, option: &str, amount: &str) -> String {
        match self.gpu_memory_mib {
            None => option.to_string(),
            Some(gpu) => format!("{amount} ({option} within a quarter of --gpu-memory {gpu})"),
        }
    }

    /// An error when `owned` bytes exceed `--gpu-memory`, naming what holds them.
    pub fn check_gpu_memory(&self, what: &str, owned: u64) -> Result<(), RenderError> {
        match self.gpu_memory_mib {
            Some(gpu) if owned > gpu as u64 * (1 << 20) => Err(RenderError::Settings(format!(
                "{what} needs {} of GPU memory, over --gpu-memory {gpu} MiB: lower the image \
                 size, --rsm, --sparse-points, --shadow-memory or --max-vals, or raise \
                 --gpu-memory to at least {} MiB",
                crate::gpu::format_bytes(owned),
                owned.div_ceil(1 << 20),
            ))),
            _ => Ok(()),
        }
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            ssaa: 1,
            shadow_resolution: 1024,
            pcf_radius: 1,
            shadow_memory_mib: DEFAULT_SHADOW_MEMORY_MIB,
            max_vals: crate::light::rsm::DEFAULT_MAX_VALS,
            gpu_memory_mib: None,
            camera: None,
            views_per_frame: 1,
        }
    }
}

/// What to try when wgpu refuses a pipeline: it exceeds a limit of this adapter.
pub const PIPELINE_REMEDY: &str =
    "The adapter's limits are below what the pipeline needs; try another adapter (WGPU_ADAPTER_NAME)";

/// Smallest `--shadow-res`: below it PCF kernels span the whole map.
pub const MIN_SHADOW_RESOLUTION: u32 = shadow_atlas::MIN_TILE_SIDE;

/// Default `--shadow-memory`: 64 full layers at the default 1024² (ten point lights and four
/// spots at full resolution; a thousand point lights at 64² to 128²).
pub const DEFAULT_SHADOW_MEMORY_MIB: u32 = 256;

#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    SceneTooLarge(#[from] SceneTooLarge),
    #[error("{0}")]
    Settings(String),
    /// An atlas method given no `--atlas` could not bake one in memory (its charts need a
    /// larger atlas than the default bake's, …): `valgi render`'s default method then
    /// renders without the atlas.
    #[error("{0}")]
    AtlasBake(String),
    #[error(transparent)]
    Cancelled(#[from] crate::progress::Cancelled),
}

pub const GBUFFER_NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const GBUFFER_MATERIAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
pub const RADIANCE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// `shadow.wgsl` and the G-buffer's frame group: a camera (the shadow layer's view or the
/// frame uniform) and the instance transforms.
const CAMERA_AND_INSTANCES: &[Slot] = &[Slot::Uniform, Slot::Storage];

/// `direct_light.wgsl`: frame, lights, shadow views, the shadow-map array and its comparison
/// sampler, the G-buffer (depth, normal, diffuse, specular, emissive) and the direct target.
const DIRECT_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::Storage,
    Slot::DepthTextureArray,
    Slot::ComparisonSampler,
    Slot::DepthTexture,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
    Slot::Uniform,
    Slot::Uniform,
];
/// Lights and shadow views in `direct_light.wgsl`'s uniform blocks (`LIGHT_BLOCK`,
/// `VIEW_BLOCK` there): 16 and 32 KiB.
pub const LIGHT_BLOCK: u32 = 256;
pub const VIEW_BLOCK: u32 = 256;

/// Shadow maps, G-buffer and direct light for one scene: the view-free part (scene upload,
/// lights, shadow maps) is updated once per frame; the G-buffer and direct light are recorded
/// per [`View`].
pub struct Rasterizer {
    pub settings: RenderSettings,
    /// The scene's upload, shared with other rasterizers over the same scene
    /// ([`Rasterizer::over`]).
    pub scene_gpu: Arc<SceneGpu>,
    lights_buffer: wgpu::Buffer,
    shadow_views_buffer: wgpu::Buffer,
    /// The lights and views again as the uniform blocks the direct pass reads when they fit
    /// (`lights_in_block`).
    lights_block: wgpu::Buffer,
    shadow_views_block: wgpu::Buffer,
    lights_in_block: bool,
    /// Where each light's views live in the shadow-map array.
    atlas: shadow_atlas::ShadowAtlas,
    /// One uniform buffer and bind group per shadowed view, in view order (`None`: the
    /// light is unshadowed).
    shadow_view_groups: Vec<Option<(wgpu::Buffer, wgpu::BindGroup)>>,
    /// Per array layer: its render target and the views drawn into it with their tiles.
    shadow_layers: Vec<(wgpu::TextureView, Vec<(usize, shadow_atlas::Tile)>)>,
    shadow_pipeline: wgpu::RenderPipeline,
    gbuffer_pipeline: wgpu::RenderPipeline,
    gbuffer_bgl: GroupLayout,
    direct_pipeline: wgpu::ComputePipeline,
    direct_bgl: GroupLayout,
    shadow_array_view: wgpu::TextureView,
    comparison_sampler: wgpu::Sampler,
    light_count: u32,
    shadow_bytes: GpuBytes,
    /// Model-space bounds of every mesh, for per-frame shadow-frustum fitting.
    mesh_bounds: Vec<Aabb>,
}

impl Rasterizer {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        settings: RenderSettings,
    ) -> Result<Self, RenderError> {
        // The mono view's size is checked here so that a bad size fails before any upload.
        crate::frame::check_size(ctx, settings.width, settings.height, settings.ssaa)?;
        let scene_gpu = SceneGpu::shared(ctx, scene, scene.content_key())?;
        Self::over(ctx, scene, settings, scene_gpu)
    }

    /// The rasterizer over `scene_gpu`, an upload of `scene` that other rasterizers may share
    /// (budget mode's pilots build a method per candidate over one scene).
    pub fn over(
        ctx: &GpuContext,
        scene: &Scene,
        settings: RenderSettings,
        scene_gpu: Arc<SceneGpu>,
    ) -> Result<Self, RenderError> {
        let device = &ctx.device;
        let limits = device.limits();
        crate::frame::check_size(ctx, settings.width, settings.height, settings.ssaa)?;
        let shadow_resolution = settings.shadow_resolution;
        let max_shadow_resolution = limits.max_texture_dimension_2d;
        if !(MIN_SHADOW_RESOLUTION..=max_shadow_resolution).contains(&shadow_resolution) {
            return Err(RenderError::Settings(format!(
                "--shadow-res {shadow_resolution}: must be {MIN_SHADOW_RESOLUTION}..={max_shadow_resolution} \
                 (the device's largest 2D texture side)"
            )));
        }
        let atlas = plan_shadow_atlas(scene, &settings, limits.max_texture_array_layers)?;
        let mut shadow_bytes = GpuBytes::default();

        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let lights_buffer = shadow_bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("lights"),
                size: (scene.lights.len().max(1) * std::mem::size_of::<types::GpuLight>()) as u64,
                usage: storage,
                mapped_at_creation: false,
            },
        );
        let first_view: Vec<u32> = scene
            .lights
            .iter()
            .scan(0, |next, light| {
                let first = *next;
                *next += light.kind.shadow_layers();
                Some(first)
            })
            .collect();
        let view_count: u32 = scene.lights.iter().map(|l| l.kind.shadow_layers()).sum();
        let layers = atlas.layers.max(1);
        let shadow_views_buffer = shadow_bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("shadow views"),
                size: view_count.max(1) as u64 * std::mem::size_of::<ShadowView>() as u64,
                usage: storage,
                mapped_at_creation: false,
            },
        );
        let lights_in_block =
            scene.lights.len() <= LIGHT_BLOCK as usize && view_count <= VIEW_BLOCK;
        let mut block = |label: &str, count: u32, size: usize| {
            shadow_bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some(label),
                    size: u64::from(count) * size as u64,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                },
            )
        };
        let lights_block = block(
            "lights block",
            LIGHT_BLOCK,
            std::mem::size_of::<types::GpuLight>(),
        );
        let shadow_views_block = block(
            "shadow views block",
            VIEW_BLOCK,
            std::mem::size_of::<ShadowView>(),
        );
        let shadow_desc = wgpu::TextureDescriptor {
            label: Some("shadow maps"),
            size: wgpu::Extent3d {
                width: shadow_resolution,
                height: shadow_resolution,
                depth_or_array_layers: layers,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: DEPTH_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        };
        let shadow_texture = ctx.scoped(
            &format!(
                "the shadow maps of scene '{}' ({}: {layers} layers of \
                 {shadow_resolution}×{shadow_resolution})",
                scene.name,
                crate::gpu::count_of(scene.lights.len(), "light")
            ),
            Some(crate::gpu::resources::texture_bytes(&shadow_desc)),
            "Lower --shadow-res (a point light takes six layers) or use fewer lights",
            || shadow_bytes.texture(device, &shadow_desc),
        )?;
        let shadow_array_view = shadow_texture.create_view(&wgpu::TextureViewDescriptor {
            label: Some("shadow maps array"),
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let mut shadow_layers: Vec<(wgpu::TextureView, Vec<(usize, shadow_atlas::Tile)>)> = (0
            ..atlas.layers)
            .map(|layer| {
                let view = shadow_texture.create_view(&wgpu::TextureViewDescriptor {
                    label: Some("shadow layer"),
                    dimension: Some(wgpu::TextureViewDimension::D2),
                    base_array_layer: layer,
                    array_layer_count: Some(1),
                    ..Default::default()
                });
                (view, Vec::new())
            })
            .collect();
        for (light, tiles) in atlas.tiles.iter().enumerate() {
            for (face, tile) in tiles.iter().flatten().enumerate() {
                let view_index = first_view[light] as usize + face;
                shadow_layers[tile.layer as usize]
                    .1
                    .push((view_index, *tile));
            }
        }

        // Shadow pipeline: depth only, slope-scaled bias against acne on sloped receivers.
        let shadow_module = ctx.shader("shadow_depth.wgsl");
        let shadow_bgl = GroupLayout::new(
            device,
            "shadow layer",
            wgpu::ShaderStages::VERTEX,
            CAMERA_AND_INSTANCES,
        );
        let mut shadow_view_groups: Vec<Option<(wgpu::Buffer, wgpu::BindGroup)>> =
            (0..view_count).map(|_| None).collect();
        for (_, tiles) in &shadow_layers {
            for &(view_index, _) in tiles {
                let buffer = shadow_bytes.uniform::<ShadowView>(device, "shadow view");
                let group = shadow_bgl.bind(device, &[&buffer, &scene_gpu.instance_buffer]);
                shadow_view_groups[view_index] = Some((buffer, group));
            }
        }
        let shadow_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("shadow"),
            bind_group_layouts: &[Some(&shadow_bgl.layout)],
            immediate_size: 0,
        });
        let shadow_pipeline = ctx.scoped("the shadow pipeline", None, PIPELINE_REMEDY, || {
            ScenePipeline {
                label: "shadow",
                module: &shadow_module,
                layout: &shadow_layout,
                vertex: POSITION_ONLY,
                depth_write: true,
                depth_compare: wgpu::CompareFunction::Less,
                depth_bias: wgpu::DepthBiasState {
                    constant: 2,
                    slope_scale: 1.5,
                    clamp: 0.0,
                },
                targets: &[],
            }
            .build(device)
        })?;

        // G-buffer pipeline.
        let gbuffer_module = ctx.shader("gbuffer.wgsl");
        let frame_bgl = GroupLayout::new(
            device,
            "gbuffer frame",
            wgpu::ShaderStages::VERTEX,
            CAMERA_AND_INSTANCES,
        );
        let gbuffer_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gbuffer"),
            bind_group_layouts: &[
                Some(&frame_bgl.layout),
                Some(&scene_gpu.material_layout.layout),
            ],
            immediate_size: 0,
        });
        let gbuffer_pipeline = ctx.scoped("the gbuffer pipeline", None, PIPELINE_REMEDY, || {
            ScenePipeline {
                label: "gbuffer",
                module: &gbuffer_module,
                layout: &gbuffer_layout,
                vertex: Vertex::layout(),
                depth_write: true,
                depth_compare: wgpu::CompareFunction::Less,
                depth_bias: wgpu::DepthBiasState::default(),
                targets: &[
                    GBUFFER_NORMAL_FORMAT,
                    GBUFFER_MATERIAL_FORMAT,
                    GBUFFER_MATERIAL_FORMAT,
                    GBUFFER_MATERIAL_FORMAT,
                ],
            }
            .build(device)
        })?;

        // Direct lighting.
        let direct_module = ctx.shader("direct_light.wgsl");
        let cs = wgpu::ShaderStages::COMPUTE;
        let direct_bgl = GroupLayout::new(device, "direct light", cs, DIRECT_BINDINGS);
        let comparison_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("shadow comparison"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        });
        let direct_pipeline =
            ctx.scoped("the direct-light pipeline", None, PIPELINE_REMEDY, || {
                let in_block = [("LIGHTS_IN_BLOCK", f64::from(u8::from(lights_in_block)))];
                crate::gpu::compute_pipeline_groups(
                    device,
                    "direct light",
                    &direct_module,
                    &[&direct_bgl.layout],
                    "cs_main",
                    &in_block,
                )
            })?;

        report_shadow_atlas(scene, &atlas);
        if scene.lights.is_empty() {
            log::warn!(
                "scene '{}' has no lights: direct light is black (emission only); add one with \
                 --light point:X,Y,Z,INTENSITY | spot:… | sun:DX,DY,DZ,IRRADIANCE | \
                 headlight:INTENSITY",
                scene.name
            );
        }

        Ok(Self {
            settings: RenderSettings {
                shadow_resolution,
                ..settings
            },
            scene_gpu,
            lights_buffer,
            shadow_views_buffer,
            lights_block,
            shadow_views_block,
            lights_in_block,
            atlas,
            shadow_view_groups,
            shadow_layers,
            shadow_pipeline,
            gbuffer_pipeline,
            gbuffer_bgl: frame_bgl,
            direct_pipeline,
            direct_bgl,
            shadow_array_view,
            comparison_sampler,
            light_count: scene.lights.len() as u32,
            shadow_bytes,
            mesh_bounds: scene.meshes.iter().map(|m| m.model_bounds()).collect(),
        })
    }

    /// GPU bytes of everything the rasterizer owns: scene, shadow maps, uniforms.
    pub fn gpu_bytes(&self) -> u64 {
        self.scene_gpu.bytes.0 + self.shadow_bytes.0
    }

    /// Uploads this frame's transforms, lights and shadow views (no camera: views have
    /// their own).
    pub fn update(&self, ctx: &GpuContext, scene: &Scene, world_from_node: &[Mat4]) {
        let queue = &ctx.queue;
        self.scene_gpu
            .update_transforms(ctx, scene, world_from_node);
        let bounds = scene.instance_bounds(&self.mesh_bounds, world_from_node);
        let sides: Vec<u32> = self
            .atlas
            .tiles
            .iter()
            .map(|tiles| tiles.as_ref().map_or(self.atlas.layer_side, |t| t[0].side))
            .collect();
        let mut setup = shadows::setup_lights(
            scene,
            world_from_node,
            &bounds,
            &sides,
            self.settings.pcf_radius as f32 + 1.0,
        );
        for (light, tiles) in setup.lights.iter_mut().zip(&self.atlas.tiles) {
            let Some(tiles) = tiles else {
                light.first_shadow_view = types::NO_SHADOW;
                continue;
            };
            for (face, tile) in tiles.iter().enumerate() {
                let view = &mut setup.views[light.first_shadow_view as usize + face];
                let [u0, v0, size] = tile.uv_rect(self.atlas.layer_side);
                view.atlas_rect = [u0, v0, size, 0.0];
                view.atlas_layer = tile.layer;
            }
        }
        if !setup.lights.is_empty() {
            // Only the direct pass reads these, from the blocks or from the storage buffers.
            let (lights, views) = if self.lights_in_block {
                (&self.lights_block, &self.shadow_views_block)
            } else {
                (&self.lights_buffer, &self.shadow_views_buffer)
            };
            queue.write_buffer(lights, 0, bytemuck::cast_slice(&setup.lights));
            queue.write_buffer(views, 0, bytemuck::cast_slice(&setup.views));
        }
        for (group, view) in self.shadow_view_groups.iter().zip(&setup.views) {
            if let Some((buffer, _)) = group {
                queue.write_buffer(buffer, 0, bytemuck::bytes_of(view));
            }
        }
    }

    /// The view-free half of every frame: uploads and shadow maps.
    pub fn update_and_record(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        passes: &mut Passes,
    ) -> Result<(), GpuError> {
        self.update(ctx, scene, world_from_node);
        self.record_shadows(passes)
    }

    /// Shadow maps of every shadowed light (pass "shadow"): one pass per array layer, one
    /// viewport per tile in it.
    pub fn record_shadows(&self, passes: &mut Passes) -> Result<(), GpuError> {
        for (view, tiles) in &self.shadow_layers {
            passes.render(
                "shadow",
                &[],
                Some(wgpu::RenderPassDepthStencilAttachment {
                    view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                |pass| {
                    pass.set_pipeline(&self.shadow_pipeline);
                    for &(view_index, tile) in tiles {
                        let (_, group) = self.shadow_view_groups[view_index]
                            .as_ref()
                            .expect("every tiled view has its uniforms");
                        let (x, y, side) = (tile.x as f32, tile.y as f32, tile.side as f32);
                        pass.set_viewport(x, y, side, side, 0.0, 1.0);
                        pass.set_scissor_rect(tile.x, tile.y, tile.side, tile.side);
                        pass.set_bind_group(0, group, &[]);
                        self.scene_gpu.draw(pass, None);
                    }
                },
            )?;
        }
        Ok(())
    }

    /// Uploads the view's camera and records its G-buffer and direct light: what every
    /// method draws first in a view.
    pub fn record_view_base(
        &self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
    ) -> Result<(), GpuError> {
        view.upload(ctx, self.light_count, self.settings.pcf_radius);
        self.record_gbuffer(ctx, view, passes)?;
        self.record_direct(ctx, view, passes)
    }

    /// Normals and materials of the visible surfaces (pass "gbuffer").
    pub fn record_gbuffer(
        &self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
    ) -> Result<(), GpuError> {
        let group = self.gbuffer_bgl.bind(
            &ctx.device,
            &[&view.frame_buffer, &self.scene_gpu.instance_buffer],
        );
        let t = &view.targets;
        passes.render(
            "gbuffer",
            &[
                cleared(&t.normal),
                cleared(&t.diffuse),
                cleared(&t.specular),
                cleared(&t.emissive),
            ],
            Some(wgpu::RenderPassDepthStencilAttachment {
                view: &t.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            |pass| {
                pass.set_pipeline(&self.gbuffer_pipeline);
                pass.set_bind_group(0, &group, &[]);
                self.scene_gpu.draw(pass, Some(1));
            },
        )
    }

    /// Whether the direct pass reads the lights and shadow views from their uniform blocks
    /// (both fit one), not from the storage buffers.
    pub fn lights_in_block(&self) -> bool {
        self.lights_in_block
    }

    /// Direct light and emission per pixel (pass "direct").
    pub fn record_direct(
        &self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
    ) -> Result<(), GpuError> {
        let t = &view.targets;
        let group = self.direct_bgl.bind(
            &ctx.device,
            &[
                &view.frame_buffer,
                &self.lights_buffer,
                &self.shadow_views_buffer,
                &self.shadow_array_view,
                &self.comparison_sampler,
                &t.depth,
                &t.normal,
                &t.diffuse,
                &t.specular,
                &t.emissive,
                &t.radiance_direct,
                &self.lights_block,
                &self.shadow_views_block,
            ],
        );
        view.record_per_pixel(passes, "direct", &self.direct_pipeline, &group)
    }

    /// Shadows, G-buffer, direct light and resolve of one camera, read back: the whole
    /// direct-only frame (what `--method direct` renders).
    pub fn render_direct(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError> {
        let s = self.settings;
        let view = View::new(ctx, "main", *camera, (s.width, s.height), s.ssaa)?;
        let mut passes = Passes::new(ctx);
        self.update_and_record(ctx, scene, world_from_node, &mut passes)?;
        passes.set_scope(crate::gpu::Scope::View(0));
        self.record_view_base(ctx, &view, &mut passes)?;
        view.record_resolve(ctx, &mut passes, false)?;
        let timings = passes.finish()?;
        let (direct, indirect) = view.read(ctx, false)?;
        Ok(FrameOutput {
            direct,
            indirect,
            timings,
            gpu_bytes: self.gpu_bytes() + view.gpu_bytes(),
        })
    }
}

/// Power of a light in watts (luminance-weighted), what its shadow-map and RSM shares
/// follow; a directional light's is infinite (it covers the whole scene).
pub fn light_power(light: &crate::scene::Light) -> f32 {
    use crate::scene::LightKind;
    let luminance = crate::shading::luminance(light.radiometric()).max(0.0);
    let solid_angle = match light.kind {
        LightKind::Point => 4.0 * std::f32::consts::PI,
        LightKind::Emitter => std::f32::consts::PI,
        LightKind::Spot {
            outer_cone_angle, ..
        } => 2.0 * std::f32::consts::PI * (1.0 - outer_cone_angle.clamp(0.0, 1.6).cos()),
        LightKind::Directional => return f32::INFINITY,
    };
    luminance * solid_angle
}

/// The shadow-map layout of a scene's lights under `--shadow-memory`.
fn plan_shadow_atlas(
    scene: &Scene,
    settings: &RenderSettings,
    max_layers: u32,
) -> Result<shadow_atlas::ShadowAtlas, RenderError> {
    let requests: Vec<shadow_atlas::TileRequest> = scene
        .lights
        .iter()
        .map(|light| shadow_atlas::TileRequest {
            views: light.kind.shadow_layers(),
            importance: light_power(light),
        })
        .collect();
    let bytes_per_texel = crate::gpu::resources::block_bytes(DEPTH_FORMAT);
    let budget_bytes = settings.shadow_budget_bytes();
    shadow_atlas::allocate(
        &requests,
        settings.shadow_resolution,
        bytes_per_texel,
        budget_bytes,
        max_layers,
    )
    .map_err(
        |shadow_atlas::AtlasError::LayerOverBudget { layer_bytes, .. }| {
            RenderError::Settings(format!(
                "--shadow-res {res}: one {res}×{res} shadow layer takes {} MiB, more than \
             {}; lower --shadow-res or raise --shadow-memory to at least {}",
                layer_bytes.div_ceil(1 << 20),
                settings.budget_name(
                    &format!("--shadow-memory {}", settings.shadow_memory_mib),
                    &format!("{} MiB", settings.shadow_budget_bytes() >> 20)
                ),
                layer_bytes.div_ceil(1 << 20),
                res = settings.shadow_resolution,
            ))
        },
    )
}

/// Says which lights lost shadow resolution or their shadows to the budget.
fn report_shadow_atlas(scene: &Scene, atlas: &shadow_atlas::ShadowAtlas) {
    let unshadowed = atlas.unshadowed();
    if unshadowed > 0 {
        log::warn!(
            "scene '{}': {unshadowed} of {} are unshadowed (they still light the scene): \
             their shadow maps do not fit --shadow-memory even at {}²; raise --shadow-memory \
             or lower --shadow-res",
            scene.name,
            crate::gpu::count_of(scene.lights.len(), "light"),
            shadow_atlas::MIN_TILE_SIDE,
        );
    }
    let reduced = atlas.reduced();
    if reduced > 0 {
        log::info!(
            "scene '{}': {reduced} of {} have shadow maps below --shadow-res {} (down to {}²) \
             to fit --shadow-memory, the dimmest smallest",
            scene.name,
            crate::gpu::count_of(scene.lights.len(), "light"),
            atlas.layer_side,
            atlas.smallest_side(),
        );
    }
}

/// A render pipeline that draws the scene's meshes. No culling: open and single-sided geometry
/// shades its back faces with a flipped normal rather than showing holes.
pub struct ScenePipeline<'a> {
    pub label: &'a str,
    pub module: &'a wgpu::ShaderModule,
    pub layout: &'a wgpu::PipelineLayout,
    pub vertex: wgpu::VertexBufferLayout<'a>,
    pub depth_write: bool,
    pub depth_compare: wgpu::CompareFunction,
    pub depth_bias: wgpu::DepthBiasState,
    /// Colour target formats; empty for a depth-only pipeline (no fragment stage).
    pub targets: &'a [wgpu::TextureFormat],
}

impl ScenePipeline<'_> {
    pub fn build(self, device: &wgpu::Device) -> wgpu::RenderPipeline {
        let targets: Vec<Option<wgpu::ColorTargetState>> = self
            .targets
            .iter()
            .map(|&format| {
                Some(wgpu::ColorTargetState {
                    format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })
            })
            .collect();
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(self.label),
            layout: Some(self.layout),
            vertex: wgpu::VertexState {
                module: self.module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(self.vertex)],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(self.depth_write),
                depth_compare: Some(self.depth_compare),
                stencil: wgpu::StencilState::default(),
                bias: self.depth_bias,
            }),
            multisample: wgpu::MultisampleState::default(),
            fragment: (!targets.is_empty()).then(|| wgpu::FragmentState {
                module: self.module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        })
    }
}

/// A colour attachment cleared to transparent black and stored.
pub fn cleared(view: &wgpu::TextureView) -> Option<wgpu::RenderPassColorAttachment<'_>> {
    Some(wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations {
            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
            store: wgpu::StoreOp::Store,
        },
    })
}

/// Vertex buffers of [`Vertex`] read for their position only (shadow maps, depth-equal
/// passes).
pub const POSITION_ONLY: wgpu::VertexBufferLayout<'static> = wgpu::VertexBufferLayout {
    array_stride: std::mem::size_of::<Vertex>() as u64,
    step_mode: wgpu::VertexStepMode::Vertex,
    attributes: &[wgpu::VertexAttribute {
        format: wgpu::VertexFormat::Float32x3,
        offset: 0,
        shader_location: 0,
    }],
};

pub fn buffer_binding(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry {
        binding,
        resource: buffer.as_entire_binding(),
    }
}

pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
) -> wgpu::ComputePipeline {
    compute_pipeline_at(device, label, module, layout, "cs_main")
}

/// A render pipeline that draws one full-target triangle: `vs_main` (no vertex buffers) and
/// `fs_main` of `module` into one colour target of `format`, no depth, no blending.
pub fn fullscreen_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
    write_mask: wgpu::ColorWrites,
) -> wgpu::RenderPipeline {
    unbuffered_pipeline(
        device,
        label,
        module,
        "vs_main",
        &[Some(layout)],
        format,
        write_mask,
    )
}

/// A render pipeline whose vertex entry `vertex_entry` makes its own vertices (no vertex
/// buffers), with `fs_main` of the same module into one colour target of `format`: no depth,
/// no blending, triangle lists.
pub fn unbuffered_pipeline(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    vertex_entry: &str,
    groups: &[Option<&wgpu::BindGroupLayout>],
    format: wgpu::TextureFormat,
    write_mask: wgpu::ColorWrites,
) -> wgpu::RenderPipeline {
    overlay_pipeline(
        device,
        &OverlayPipeline {
            label,
            module,
            vertex_entry,
            groups,
            format,
            write_mask,
            topology: wgpu::PrimitiveTopology::TriangleList,
            buffers: &[],
            blend: None,
        },
    )
}

/// What [`overlay_pipeline`] builds: `vertex_entry` and `fs_main` of `module`, drawing
/// `topology` from `buffers` (none: the vertex stage makes its vertices) into one colour
/// target of `format`, with no depth, blended by `blend` (`None`: written as is).
pub struct OverlayPipeline<'a> {
    pub label: &'a str,
    pub module: &'a wgpu::ShaderModule,
    pub vertex_entry: &'a str,
    pub groups: &'a [Option<&'a wgpu::BindGroupLayout>],
    pub format: wgpu::TextureFormat,
    pub write_mask: wgpu::ColorWrites,
    pub topology: wgpu::PrimitiveTopology,
    pub buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    pub blend: Option<wgpu::BlendState>,
}

/// The render pipeline `desc` describes (full-target passes, the viewer's overlays).
pub fn overlay_pipeline(device: &wgpu::Device, desc: &OverlayPipeline) -> wgpu::RenderPipeline {
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(desc.label),
        bind_group_layouts: desc.groups,
        immediate_size: 0,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some(desc.label),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: desc.module,
            entry_point: Some(desc.vertex_entry),
            compilation_options: Default::default(),
            buffers: desc.buffers,
        },
        primitive: wgpu::PrimitiveState {
            topology: desc.topology,
            ..Default::default()
        },
        depth_stencil: None,
        multisample: wgpu::MultisampleState::default(),
        fragment: Some(wgpu::FragmentState {
            module: desc.module,
            entry_point: Some("fs_main"),
            compilation_options: Default::default(),
            targets: &[Some(wgpu::ColorTargetState {
                format: desc.format,
                blend: desc.blend,
                write_mask: desc.write_mask,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// A compute pipeline for the entry point `entry` of a module with several.
pub fn compute_pipeline_at(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    layout: &wgpu::BindGroupLayout,
    entry: &str,
) -> wgpu::ComputePipeline {
    crate::gpu::compute_pipeline_groups(device, label, module, &[layout], entry, &[])
}
