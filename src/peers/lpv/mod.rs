//! Light propagation volumes (`--method lpv`) and higher-order LPVs (`--method holpv`), seed
//! 004 / DESIGN §6. The RSM VALs of [`crate::light::rsm::Rsm`] are injected as clamped-cosine
//! lobes into an N³ grid fitted to the scene (`lpv_inject.wgsl`); a geometry volume of blocker
//! potentials from the RSM and the camera's G-buffer sits half a cell off (`lpv_geometry.wgsl`);
//! S gather steps propagate the light to 6 (LPV, 2-band SH) or 26 (HO-LPV, 3-band SH)
//! neighbours with ping-pong volumes (3D textures, `lpv_pack.wgsl` packs the injection into
//! the first) and an accumulation buffer (`lpv_propagate.wgsl`); every pixel reads the
//! accumulation, packed the same way (`lpv_lookup.wgsl`). Equations, units and choices:
//! README.md in this folder; CPU twins: [`math`].

pub mod face_code;
pub mod math;

use bytemuck::{Pod, Zeroable};
use glam::UVec3;

use crate::frame::{FrameInput, Method, View, ViewResult, PIXEL_TILE};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{FrameTimings, GpuBytes, GpuContext, GpuError, Passes};
use crate::light::rsm::Rsm;
use crate::method::{Entry, MethodOptions, OptionKind, OptionSpec};
use crate::raster::{Rasterizer, RenderError, RenderSettings, RADIANCE_FORMAT};
use crate::scene::Scene;

use math::{Face, Grid, Volume};

/// `lpv_inject.wgsl`: parameters, the VALs and their count, the radiance volume it adds to.
const INJECT_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Storage, Slot::Storage, Slot::StorageRw];

/// `lpv_geometry.wgsl`: parameters, the VALs and their count, the geometry volume it writes,
/// and the first view's frame uniform and G-buffer (depth, normal, specular) for its surfels.
const GEOMETRY_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::Storage,
    Slot::StorageRw,
    Slot::Uniform,
    Slot::DepthTexture,
    Slot::Texture,
    Slot::Texture,
];

/// `lpv_propagate.wgsl`: parameters, the source volume (a 3D texture), the destination (a
/// storage texture), the accumulated volume (a buffer) and the geometry volume. The faces are
/// written into the shader (`lpv_faces.wgsl`, [`face_code`]).
const PROPAGATE_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Texture3d,
    Slot::StorageTexture3d(STEP_FORMAT),
    Slot::StorageRw,
    Slot::Storage,
];

/// `lpv_pack.wgsl`: parameters, the injected volume (a buffer) and the texture it fills.
const PACK_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::StorageTexture3d(STEP_FORMAT),
];

/// Texel format of the volumes the propagation steps read and write: a cell is
/// [`cell_texels`] texels along x, its 3·SH floats in order (`lpv_cell_texels` in
/// `lpv_common.wgsl`).
const STEP_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// rgba32float texels a cell of a step volume takes (3 for LPV, 7 for HO-LPV).
pub fn cell_texels(sh_count: usize) -> u32 {
    (3 * sh_count as u32).div_ceil(4)
}

/// `lpv_lookup.wgsl`: frame and parameters, the accumulated volume, the G-buffer and the
/// indirect target.
const LOOKUP_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Uniform,
    Slot::Texture3d,
    Slot::DepthTexture,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
];

/// RSM texels per workgroup of injection and of the geometry volume's RSM surfels
/// (`cs_main` in `lpv_inject.wgsl`, `cs_rsm` in `lpv_geometry.wgsl`).
pub const TEXEL_GROUP: u32 = 64;

/// Cells per side of a propagation or pack workgroup (`@workgroup_size(4, 4, 4)` in
/// `lpv_propagate.wgsl` and `lpv_pack.wgsl`).
pub const PROPAGATE_BLOCK: u32 = 4;

/// `LpvParams` in `shaders/lpv/lpv_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LpvParams {
    pub origin_cell: [f32; 4],
    pub dims: [u32; 4],
    pub occlusion: u32,
    pub surfel_stride: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// LPV (2 bands, 6 directions) or HO-LPV (3 bands, 26 directions).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    Lpv,
    HoLpv,
}

impl Order {
    pub fn sh_count(self) -> usize {
        match self {
            Order::Lpv => 4,
            Order::HoLpv => 9,
        }
    }

    pub fn faces(self) -> Vec<Face> {
        match self {
            Order::Lpv => math::faces6(),
            Order::HoLpv => math::faces26(),
        }
    }

    fn name(self) -> &'static str {
        match self {
            Order::Lpv => "lpv",
            Order::HoLpv => "holpv",
        }
    }
}

/// The knobs of both methods.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LpvSettings {
    pub order: Order,
    /// Cells per axis (N³ grid).
    pub grid: u32,
    /// Propagation steps S.
    pub steps: u32,
    /// Geometry-volume occlusion from the second step on.
    pub occlusion: bool,
    /// RSM resolution per light layer.
    pub rsm: u32,
}

impl LpvSettings {
    /// From method options: `grid` (32), `steps` (= grid), `occlusion` (on|off; the sparse
    /// method's sum|union mean on), `rsm` (128).
    pub fn from_options(order: Order, options: &MethodOptions) -> Result<Self, RenderError> {
        let grid: u32 = options.get("grid", 32)?;
        if !(3..=256).contains(&grid) {
            return Err(RenderError::Settings(format!(
                "--grid {grid}: must be 3..=256"
            )));
        }
        let steps: u32 = options.get("steps", grid)?;
        let occlusion = options.choice("occlusion", &["on", "off", "sum", "union"])? != "off";
        let rsm: u32 = options.get("rsm", 128)?;
        Ok(Self {
            order,
            grid,
            steps,
            occlusion,
            rsm,
        })
    }
}

/// Which of the method's volumes to read back.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VolumeId {
    /// Injection's sums (a buffer), packed into `Even` before the first step.
    Injected,
    /// Target of steps 1, 3, … (a 3D texture).
    Odd,
    /// The packed injection, source of step 1 and target of steps 2, 4, … (a 3D texture;
    /// packed only when there is a step).
    Even,
    Accum,
}

pub struct LpvMethod {
    pub raster: Rasterizer,
    pub rsm: Rsm,
    pub settings: LpvSettings,
    pub grid: Grid,
    pub faces: Vec<Face>,
    params_off: wgpu::Buffer,
    params_on: wgpu::Buffer,
    /// [injected, accum], in [`Volume`]'s layout.
    volumes: [wgpu::Buffer; 2],
    /// The volumes the steps read and write, [even, odd] ([`VolumeId`]).
    step_volumes: [wgpu::Texture; 2],
    /// The accumulated volume packed as the steps' volumes are, which the lookup reads.
    accum_texels: wgpu::TextureView,
    pack_pipeline: wgpu::ComputePipeline,
    /// Packs the injected volume into the even step volume, and the accumulated one into
    /// `accum_texels`.
    pack_groups: [wgpu::BindGroup; 2],
    gv_buffer: wgpu::Buffer,
    bytes: GpuBytes,
    volume_bytes: u64,
    inject_pipeline: wgpu::ComputePipeline,
    inject_group: wgpu::BindGroup,
    geometry_rsm: wgpu::ComputePipeline,
    geometry_camera: wgpu::ComputePipeline,
    geometry_layout: GroupLayout,
    propagate_pipeline: wgpu::ComputePipeline,
    /// The steps after the first, where they read only the coefficients a step writes
    /// (HO-LPV, `STEP_SOURCES`, [`face_code::steps_read_fewer_coefficients`]); else the first
    /// step's pipeline serves them all.
    propagate_step_pipeline: Option<wgpu::ComputePipeline>,
    /// even→odd without occlusion (step 1), odd→even, even→odd (with occlusion when on).
    propagate_groups: [wgpu::BindGroup; 3],
    lookup_pipeline: wgpu::ComputePipeline,
    lookup_layout: GroupLayout,
    surfel_stride: u32,
    /// The view whose G-buffer gave this frame's camera surfels (its G-buffer is drawn in
    /// the update, before the propagation, and not again in its record).
    surfel_view: Option<u64>,
    vals: u32,
}

fn pipeline(
    ctx: &GpuContext,
    label: &str,
    shader: &str,
    entry: &str,
    layout: &wgpu::BindGroupLayout,
    sh_count: usize,
    extra_constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let mut constants = vec![("SH_COUNT", sh_count as f64)];
    constants.extend_from_slice(extra_constants);
    let pipeline_layout = ctx
        .device
        .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&pipeline_layout),
            module: &ctx.shader(shader),
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants: &constants,
                // No LPV pass keeps workgroup memory.
                zero_initialize_workgroup_memory: false,
            },
            cache: None,
        })
}

impl LpvMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        settings: LpvSettings,
    ) -> Result<Self, RenderError> {
        let device = &ctx.device;
        let raster = Rasterizer::new(ctx, scene, render)?;
        let rsm = Rsm::new(ctx, scene, &raster, settings.rsm)?;
        // Fitted once to the rest pose, so that animation does not move the grid (no flicker).
        let bounds = scene.world_bounds(&scene.world_from_node());
        let (lo, hi) = if bounds.is_empty() {
            (glam::Vec3::ZERO, glam::Vec3::ONE)
        } else {
            (bounds.min, bounds.max)
        };
        let grid = Grid::fit(lo, hi, settings.grid);
        let order = settings.order;
        let sh = order.sh_count();
        let faces = order.faces();
        let cells = (grid.dims.x * grid.dims.y * grid.dims.z) as u64;
        let volume_size = cells * 3 * sh as u64 * 4;
        let gv_cells = (grid.dims + UVec3::ONE).as_u64vec3();
        let gv_size = gv_cells.x * gv_cells.y * gv_cells.z * 16;
        let max_binding = device
            .limits()
            .max_storage_buffer_binding_size
            .min(device.limits().max_buffer_size);
        if volume_size > max_binding {
            return Err(RenderError::Settings(format!(
                "--grid {}: a volume needs {volume_size} bytes; the device binds at most {max_binding}",
                settings.grid
            )));
        }
        let texels = cell_texels(sh);
        let step_extent = wgpu::Extent3d {
            width: grid.dims.x * texels,
            height: grid.dims.y,
            depth_or_array_layers: grid.dims.z,
        };
        let max_3d = device.limits().max_texture_dimension_3d;
        if step_extent.width.max(grid.dims.y).max(grid.dims.z) > max_3d {
            return Err(RenderError::Settings(format!(
                "--grid {}: a step volume is {} × {} × {} texels ({texels} a cell along x); the \
                 device's 3D textures have at most {max_3d} a side: use a smaller --grid",
                settings.grid,
                step_extent.width,
                step_extent.height,
                step_extent.depth_or_array_layers
            )));
        }

        let mut bytes = GpuBytes::default();
        let storage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC;
        let mut volume = |label: &str, size: u64| {
            bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some(label),
                    size,
                    usage: storage,
                    mapped_at_creation: false,
                },
            )
        };
        let volumes = [
            volume("lpv injected", volume_size),
            volume("lpv accum", volume_size),
        ];
        let gv_buffer = volume("lpv geometry", gv_size);
        let step_desc = wgpu::TextureDescriptor {
            label: None,
            size: step_extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: STEP_FORMAT,
            usage: wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        };
        let step_bytes = crate::gpu::resources::texture_bytes(&step_desc);
        let mut step_volume = |label: &str| {
            bytes.texture(
                device,
                &wgpu::TextureDescriptor {
                    label: Some(label),
                    ..step_desc.clone()
                },
            )
        };
        let step_volumes = [step_volume("lpv even steps"), step_volume("lpv odd steps")];
        let step_views = step_volumes
            .each_ref()
            .map(|t| t.create_view(&wgpu::TextureViewDescriptor::default()));
        let accum_texels = step_volume("lpv accumulated texels")
            .create_view(&wgpu::TextureViewDescriptor::default());
        let volume_bytes = 2 * volume_size + 3 * step_bytes + gv_size;
        let uniform = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        let params_size = std::mem::size_of::<LpvParams>() as u64;
        let mut params = || {
            bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some("lpv params"),
                    size: params_size,
                    usage: uniform,
                    mapped_at_creation: false,
                },
            )
        };
        let params_off = params();
        let params_on = params();

        let cs = wgpu::ShaderStages::COMPUTE;
        // Injection.
        let inject_layout = GroupLayout::new(device, "lpv inject", cs, INJECT_BINDINGS);
        let inject_group = inject_layout.bind(
            device,
            &[
                &params_off,
                &rsm.vals_buffer,
                &rsm.val_count_buffer,
                &volumes[0],
            ],
        );
        let inject_pipeline = pipeline(
            ctx,
            "lpv inject",
            "lpv_inject.wgsl",
            "cs_main",
            &inject_layout.layout,
            sh,
            &[],
        );
        // Geometry volume.
        let geometry_layout = GroupLayout::new(device, "lpv geometry", cs, GEOMETRY_BINDINGS);
        let geometry_rsm = pipeline(
            ctx,
            "lpv geometry rsm",
            "lpv_geometry.wgsl",
            "cs_rsm",
            &geometry_layout.layout,
            sh,
            &[],
        );
        let geometry_camera = pipeline(
            ctx,
            "lpv geometry camera",
            "lpv_geometry.wgsl",
            "cs_camera",
            &geometry_layout.layout,
            sh,
            &[],
        );
        // Propagation.
        let propagate_layout = GroupLayout::new(device, "lpv propagate", cs, PROPAGATE_BINDINGS);
        let later = if settings.occlusion {
            &params_on
        } else {
            &params_off
        };
        let group = |params: &wgpu::Buffer, src: usize, dst: usize| {
            propagate_layout.bind(
                device,
                &[
                    params,
                    &step_views[src],
                    &step_views[dst],
                    &volumes[1],
                    &gv_buffer,
                ],
            )
        };
        let propagate_groups = [
            group(&params_off, 0, 1),
            group(later, 1, 0),
            group(later, 0, 1),
        ];
        let propagate_pipeline = pipeline(
            ctx,
            "lpv propagate",
            "lpv_propagate.wgsl",
            "cs_main",
            &propagate_layout.layout,
            sh,
            &[],
        );
        let propagate_step_pipeline = face_code::steps_read_fewer_coefficients(order).then(|| {
            pipeline(
                ctx,
                "lpv propagate steps",
                "lpv_propagate.wgsl",
                "cs_main",
                &propagate_layout.layout,
                sh,
                &[("STEP_SOURCES", 1.0)],
            )
        });
        let pack_layout = GroupLayout::new(device, "lpv pack", cs, PACK_BINDINGS);
        let pack_groups = [
            pack_layout.bind(device, &[&params_off, &volumes[0], &step_views[0]]),
            pack_layout.bind(device, &[&params_off, &volumes[1], &accum_texels]),
        ];
        let pack_pipeline = pipeline(
            ctx,
            "lpv pack",
            "lpv_pack.wgsl",
            "cs_main",
            &pack_layout.layout,
            sh,
            &[],
        );
        // Lookup.
        let lookup_layout = GroupLayout::new(device, "lpv lookup", cs, LOOKUP_BINDINGS);
        let lookup_pipeline = pipeline(
            ctx,
            "lpv lookup",
            "lpv_lookup.wgsl",
            "cs_main",
            &lookup_layout.layout,
            sh,
            &[],
        );
        Ok(Self {
            raster,
            rsm,
            settings,
            grid,
            faces,
            params_off,
            params_on,
            volumes,
            step_volumes,
            accum_texels,
            pack_pipeline,
            pack_groups,
            gv_buffer,
            bytes,
            volume_bytes,
            inject_pipeline,
            inject_group,
            geometry_rsm,
            geometry_camera,
            geometry_layout,
            propagate_pipeline,
            propagate_step_pipeline,
            propagate_groups,
            lookup_pipeline,
            lookup_layout,
            surfel_stride: 1,
            surfel_view: None,
            vals: 0,
        })
    }

    /// Bytes of the light volumes (injected and accumulated as buffers, two step volumes and
    /// the accumulated one as textures) and the geometry volume.
    pub fn volume_bytes(&self) -> u64 {
        self.volume_bytes
    }

    /// One of the light volumes of the last frame, in [`Volume`]'s layout.
    pub fn read_volume(&self, ctx: &GpuContext, which: VolumeId) -> Result<Volume, GpuError> {
        let sh = self.settings.order.sh_count();
        let data = match which {
            VolumeId::Injected => crate::gpu::read_buffer(ctx, &self.volumes[0])?,
            VolumeId::Accum => crate::gpu::read_buffer(ctx, &self.volumes[1])?,
            VolumeId::Even | VolumeId::Odd => {
                let texture = &self.step_volumes[usize::from(which == VolumeId::Odd)];
                let texels = crate::gpu::read_texture_rgba32f(ctx, texture)?;
                // A row holds `cell_texels` texels a cell. The packed injection (`Even` until
                // step 2 overwrites it) has every coefficient, [channel][coefficient]; a step's
                // output the floats of `face_code::step_layout`, in the first `step_texels` a
                // cell of the row.
                let order = self.settings.order;
                let written_by_step = match which {
                    VolumeId::Odd => true,
                    _ => self.settings.steps >= 2,
                };
                let (layout, per_cell): (Vec<(usize, usize)>, u32) = if written_by_step {
                    (face_code::step_layout(order), face_code::step_texels(order))
                } else {
                    (
                        (0..3)
                            .flat_map(|ch| (0..sh).map(move |k| (ch, k)))
                            .collect(),
                        cell_texels(sh),
                    )
                };
                let row = (self.grid.dims.x * cell_texels(sh)) as usize;
                let cells = (self.grid.dims.x * self.grid.dims.y * self.grid.dims.z) as usize;
                let mut data = Vec::with_capacity(cells * 3 * sh);
                for row_texels in texels.chunks_exact(row) {
                    for cell in row_texels
                        .chunks_exact(per_cell as usize)
                        .take(self.grid.dims.x as usize)
                    {
                        let mut out = vec![0.0; 3 * sh];
                        for (&(ch, k), value) in layout.iter().zip(cell.iter().flatten()) {
                            out[ch * sh + k] = *value;
                        }
                        data.extend(out);
                    }
                }
                data
            }
        };
        Ok(Volume {
            dims: self.grid.dims,
            sh,
            data,
        })
    }

    /// The geometry volume of the last frame ((N+1)³ × 4 floats).
    pub fn read_geometry(&self, ctx: &GpuContext) -> Result<Vec<f32>, GpuError> {
        crate::gpu::read_buffer(ctx, &self.gv_buffer)
    }

    fn write_params(&self, ctx: &GpuContext) {
        let g = &self.grid;
        let mut p = LpvParams {
            origin_cell: g.origin.extend(g.cell).to_array(),
            dims: [g.dims.x, g.dims.y, g.dims.z, g.dims.x * g.dims.y * g.dims.z],
            occlusion: 0,
            surfel_stride: self.surfel_stride,
            pad0: 0,
            pad1: 0,
        };
        ctx.queue
            .write_buffer(&self.params_off, 0, bytemuck::bytes_of(&p));
        p.occlusion = 1;
        ctx.queue
            .write_buffer(&self.params_on, 0, bytemuck::bytes_of(&p));
    }
}

impl Method for LpvMethod {
    fn name(&self) -> &'static str {
        self.settings.order.name()
    }

    fn settings(&self) -> RenderSettings {
        self.raster.settings
    }

    fn update(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        views: &[&View],
        passes: &mut Passes,
    ) -> Result<(), RenderError> {
        self.raster
            .update_and_record(ctx, frame.scene, frame.world_from_node, passes)?;
        self.rsm.prepare(ctx, frame.scene, frame.world_from_node);
        // The geometry volume also takes surfels from a camera's G-buffer, as the LPV paper
        // does: the first view's. That part of the solution depends on that view.
        let surfel_view = views
            .first()
            .filter(|_| self.settings.occlusion && self.settings.steps > 1);
        if let Some(view) = surfel_view {
            let (w, h) = view.render_size();
            // About 128² camera surfels whatever the resolution.
            self.surfel_stride = w.max(h).div_ceil(128).max(1);
        }
        self.surfel_view = surfel_view.map(|v| v.id());
        self.write_params(ctx);
        self.rsm.record(passes, &self.raster.scene_gpu)?;
        let encoder = passes.encoder();
        encoder.clear_buffer(&self.volumes[0], 0, None);
        encoder.clear_buffer(&self.gv_buffer, 0, None);
        // One invocation per RSM texel, in rows of at most 65535 workgroups.
        let groups = self.rsm.capacity.div_ceil(TEXEL_GROUP);
        let val_groups = (groups.min(65535), groups.div_ceil(65535));
        passes.compute("inject", |pass| {
            pass.set_pipeline(&self.inject_pipeline);
            pass.set_bind_group(0, &self.inject_group, &[]);
            pass.dispatch_workgroups(val_groups.0, val_groups.1, 1);
        })?;
        if let Some(view) = surfel_view {
            view.upload(
                ctx,
                frame.scene.lights.len() as u32,
                self.raster.settings.pcf_radius,
            );
            self.raster.record_gbuffer(ctx, view, passes)?;
            let t = &view.targets;
            let geometry_group = self.geometry_layout.bind(
                &ctx.device,
                &[
                    &self.params_off,
                    &self.rsm.vals_buffer,
                    &self.rsm.val_count_buffer,
                    &self.gv_buffer,
                    &view.frame_buffer,
                    &t.depth,
                    &t.normal,
                    &t.specular,
                ],
            );
            let s = self.surfel_stride;
            let (sx, sy) = (t.render_width.div_ceil(s), t.render_height.div_ceil(s));
            passes.compute("geometry", |pass| {
                pass.set_bind_group(0, &geometry_group, &[]);
                pass.set_pipeline(&self.geometry_rsm);
                pass.dispatch_workgroups(val_groups.0, val_groups.1, 1);
                pass.set_pipeline(&self.geometry_camera);
                pass.dispatch_workgroups(sx.div_ceil(PIXEL_TILE), sy.div_ceil(PIXEL_TILE), 1);
            })?;
        }
        let volume_size = self.volumes[0].size();
        passes.encoder().copy_buffer_to_buffer(
            &self.volumes[0],
            0,
            &self.volumes[1],
            0,
            volume_size,
        );
        // One invocation per cell, for packing and propagation.
        let cell_groups = self
            .grid
            .dims
            .to_array()
            .map(|n| n.div_ceil(PROPAGATE_BLOCK));
        let pack = |passes: &mut Passes, label: &str, group: &wgpu::BindGroup| {
            passes.compute(label, |pass| {
                pass.set_pipeline(&self.pack_pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(cell_groups[0], cell_groups[1], cell_groups[2]);
            })
        };
        if self.settings.steps > 0 {
            pack(passes, "pack", &self.pack_groups[0])?;
            passes.compute("propagate", |pass| {
                pass.set_pipeline(&self.propagate_pipeline);
                for step in 0..self.settings.steps {
                    if step == 1 {
                        if let Some(steps) = &self.propagate_step_pipeline {
                            pass.set_pipeline(steps);
                        }
                    }
                    let group = match step {
                        0 => &self.propagate_groups[0],
                        s if s % 2 == 1 => &self.propagate_groups[1],
                        _ => &self.propagate_groups[2],
                    };
                    pass.set_bind_group(0, group, &[]);
                    pass.dispatch_workgroups(cell_groups[0], cell_groups[1], cell_groups[2]);
                }
            })?;
        }
        pack(passes, "pack accumulated", &self.pack_groups[1])?;
        Ok(())
    }

    fn record_view(
        &mut self,
        ctx: &GpuContext,
        _frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError> {
        if self.surfel_view == Some(view.id()) {
            self.raster.record_direct(ctx, view, passes)?;
        } else {
            self.raster.record_view_base(ctx, view, passes)?;
        }
        let t = &view.targets;
        let lookup_group = self.lookup_layout.bind(
            &ctx.device,
            &[
                &view.frame_buffer,
                &self.params_off,
                &self.accum_texels,
                &t.depth,
                &t.normal,
                &t.diffuse,
                &t.specular,
                &t.radiance_indirect,
            ],
        );
        view.record_per_pixel(passes, "lookup", &self.lookup_pipeline, &lookup_group)?;
        Ok(ViewResult::DirectAndIndirect)
    }

    fn end_frame(&mut self, ctx: &GpuContext, _timings: &FrameTimings) -> Result<(), RenderError> {
        self.vals = self.rsm.read_count(ctx)?;
        Ok(())
    }

    fn debug_vals(&self) -> Option<crate::frame::DebugValSource<'_>> {
        Some(self.rsm.debug_vals())
    }

    fn gpu_bytes(&self) -> u64 {
        self.raster.gpu_bytes() + self.rsm.bytes.0 + self.bytes.0
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        let s = &self.settings;
        map.insert("grid".into(), s.grid.into());
        map.insert("steps".into(), s.steps.into());
        map.insert(
            "occlusion".into(),
            if s.occlusion { "on" } else { "off" }.into(),
        );
        map.insert("sh_coefficients".into(), s.order.sh_count().into());
        map.insert("propagation_faces".into(), self.faces.len().into());
        map.insert("cell_size_m".into(), self.grid.cell.into());
        map.insert("volume_gpu_bytes".into(), self.volume_bytes.into());
        map.insert("vals".into(), self.vals.into());
        map.insert("rsm".into(), self.rsm.resolution.into());
        map
    }
}

/// LPV's options (shared by `lpv` and `holpv`).
const OPTIONS: &[OptionSpec] = &[
    OptionSpec {
        name: "grid",
        kind: OptionKind::Int { min: 3, max: 256 },
        default: "32",
        help: "light propagation volume cells per axis",
    },
    OptionSpec {
        name: "steps",
        kind: OptionKind::Int { min: 0, max: 1024 },
        default: "",
        help: "light propagation steps (default: = grid)",
    },
    OptionSpec {
        name: "occlusion",
        kind: OptionKind::Choice(&["on", "off", "sum", "union"]),
        default: "on",
        help: "occlusion from the geometry volume (sum and union also mean on)",
    },
    OptionSpec {
        name: "rsm",
        kind: OptionKind::Int { min: 1, max: 2048 },
        default: "128",
        help: "RSM resolution per light layer",
    },
];

pub static LPV_ENTRY: Entry = Entry {
    name: "lpv",
    help: "direct + one diffuse bounce through a light propagation volume: 2-band SH, 6-direction propagation",
    options: OPTIONS,
    create: |ctx, scene, render, options| create(ctx, scene, render, Order::Lpv, options),
};

pub static HOLPV_ENTRY: Entry = Entry {
    name: "holpv",
    help: "direct + one diffuse bounce through a higher-order LPV: 3-band SH, 26-direction propagation",
    options: OPTIONS,
    create: |ctx, scene, render, options| create(ctx, scene, render, Order::HoLpv, options),
};

/// `method::create` for "lpv" and "holpv".
pub fn create(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    order: Order,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    let settings = LpvSettings::from_options(order, options)?;
    Ok(Box::new(LpvMethod::new(ctx, scene, render, settings)?))
}

/// LPV's structs shared with WGSL, for the layout test.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout as layout;
    vec![layout!(
        "LpvParams",
        "lpv_common.wgsl",
        LpvParams,
        [origin_cell, dims, occlusion, surfel_stride, pad0, pad1]
    )]
}
