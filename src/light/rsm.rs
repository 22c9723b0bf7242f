//! Reflective shadow maps → virtual area lights (DESIGN §4). Every light renders an R×R RSM
//! (a spot light one perspective layer, a point light six cube faces that tile the sphere
//! exactly, a directional light an orthographic layer fitted to the scene); a compute pass then
//! compacts every lit texel of every layer, in texel order, into one storage buffer of
//! [`GpuVal`] records (deterministic: the same VAL list every run).
//! Later passes (the sparse gather, brute force, LPV injection) read `vals_buffer` and the
//! count in `val_count_buffer`.

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{GpuBytes, GpuContext, GpuError, Passes};
use crate::raster::scene_gpu::SceneGpu;
use crate::raster::shadows::setup_lights;
use crate::raster::types::{GpuLight, Vertex};
use crate::raster::{cleared, Rasterizer, RenderError, ScenePipeline, DEPTH_FORMAT};
use crate::scene::{Aabb, Scene};

use super::{ExternalVals, Val};

/// One VAL as the shaders store it (`Val` in `shaders/vals/vals_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuVal {
    /// xyz: world position; w: area A (m²).
    pub position_area: [f32; 4],
    pub normal: [f32; 4],
    /// rgb: reflected flux Φ (W).
    pub flux: [f32; 4],
}

impl GpuVal {
    pub fn from_val(val: &Val) -> Self {
        Self {
            position_area: val.position.extend(val.area).to_array(),
            normal: val.normal.extend(0.0).to_array(),
            flux: val.flux.extend(0.0).to_array(),
        }
    }

    pub fn to_val(&self) -> Val {
        Val {
            position: glam::Vec4::from(self.position_area).truncate(),
            normal: glam::Vec4::from(self.normal).truncate(),
            flux: glam::Vec4::from(self.flux).truncate(),
            area: self.position_area[3],
        }
    }

    /// The VAL's cluster (`flux.w`, see [`texel_cluster`]).
    pub fn cluster(&self) -> u32 {
        self.flux[3] as u32
    }
}

/// `RsmView` in `shaders/light/vals_rsm.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RsmView {
    pub clip_from_world: [[f32; 4]; 4],
    pub light_index: u32,
    pub resolution: u32,
    /// tan(fov/2) of a perspective view; 0 for orthographic.
    pub tan_half_fov: f32,
    /// World area of one texel of an orthographic view.
    pub texel_area: f32,
    /// Top-left texel of the view's tile in its physical layer ([`Rsm::physical_texel`]).
    pub tile_origin: [u32; 2],
    pub _pad: [u32; 2],
}

/// `RsmSize` in `shaders/light/vals_from_rsm.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RsmSize {
    pub resolution: u32,
    pub layers: u32,
    pub capacity: u32,
    /// Cluster tiles per layer side ([`cluster_tiles`]).
    pub tiles: u32,
    /// Views per physical layer side ([`Rsm::pack`]).
    pub pack: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// The most VAL clusters a frame has: visibility is kept per (sparse point, cluster), one
/// byte each.
pub const MAX_CLUSTERS: u32 = 32;

/// The cluster id (`flux.w`) of VALs from no RSM tile (appended external VALs): the gather
/// gives them no cluster visibility.
pub const UNCLUSTERED: u32 = MAX_CLUSTERS;

/// Clusters the tiling aims at (at most [`MAX_CLUSTERS`]). 16 clusters of 8×8 samples
/// (2.6× the rays) measured the same error and the same flicker on `cornell-moving` as 25
/// of 4×4, at several times the cost.
pub const CLUSTER_BUDGET: u32 = 32;

/// Samples per cluster tile side: each tile has `CLUSTER_SAMPLE_SIDE²` strata whose centre
/// texels are the VALs visibility rays are shot at.
pub const CLUSTER_SAMPLE_SIDE: u32 = 4;

/// Cluster tiles per layer side: as many as [`MAX_CLUSTERS`] allows over all layers (a spot
/// light's one layer is cut 5×5, a point light's six layers 2×2), and at least one sample
/// stratum a texel wide.
pub fn cluster_tiles(resolution: u32, layers: u32) -> u32 {
    let by_budget = ((CLUSTER_BUDGET / layers.max(1)) as f32).sqrt().floor() as u32;
    by_budget.clamp(1, (resolution / CLUSTER_SAMPLE_SIDE).max(1))
}

/// The cluster of a texel: its tile over all layers, folded into [`MAX_CLUSTERS`] when the
/// lights have more layers than that (then one cluster holds several whole layers).
pub fn texel_cluster(resolution: u32, tiles: u32, layer: u32, x: u32, y: u32) -> u32 {
    (layer_tile(resolution, tiles, layer, x, y)) % MAX_CLUSTERS
}

/// A texel's tile over all layers: `layer·T² + ty·T + tx`.
pub fn layer_tile(resolution: u32, tiles: u32, layer: u32, x: u32, y: u32) -> u32 {
    let tx = x * tiles / resolution;
    let ty = y * tiles / resolution;
    layer * tiles * tiles + ty * tiles + tx
}

/// The RSM side every view gets under `max_vals`: the requested one, or the largest whose
/// `views · side²` texels fit (`None` when not even one texel per view does).
pub fn budget_resolution(requested: u32, views: u32, max_vals: u32) -> Option<u32> {
    if views == 0 {
        return Some(requested);
    }
    let fit = ((max_vals as f64 / views as f64).sqrt().floor() as u32).min(requested);
    // The float root can land one off near perfect squares; settle it in integers.
    let fits = |side: u32| views as u64 * side as u64 * side as u64 <= max_vals as u64;
    let side = (fit.saturating_sub(1)..=(fit + 1).min(requested))
        .rev()
        .find(|&side| fits(side))?;
    (side > 0).then_some(side)
}

/// [`Rsm::physical_texel`] for a given packing.
pub fn physical_texel(pack: u32, resolution: u32, layer: u32, x: u32, y: u32) -> (u32, u32, u32) {
    let per_layer = pack * pack;
    let slot = layer % per_layer;
    (
        layer / per_layer,
        (slot % pack) * resolution + x,
        (slot / pack) * resolution + y,
    )
}

/// Views per physical layer side: 1 while the views fit the array layers, else the smallest
/// `k` whose `k²` views per layer do, with `k·resolution` within the texture side.
pub fn pack_factor(views: u32, resolution: u32, max_layers: u32, max_side: u32) -> Option<u32> {
    (1..=max_side / resolution.max(1)).find(|&k| views.div_ceil(k * k) <= max_layers)
}

/// The stratum of a texel in its tile (one axis), if the texel is that stratum's sample:
/// strata split the tile's span `[t·R/T, (t+1)·R/T)` into `CLUSTER_SAMPLE_SIDE` parts, and a
/// stratum's sample is its centre texel.
pub fn sample_stratum(resolution: u32, tiles: u32, x: u32) -> Option<u32> {
    let t = x * tiles / resolution;
    let x0 = t * resolution / tiles;
    let x1 = (t + 1) * resolution / tiles;
    let width = (x1 - x0).max(1);
    let stratum = (x - x0) * CLUSTER_SAMPLE_SIDE / width;
    let centre = x0 + (2 * stratum + 1) * width / (2 * CLUSTER_SAMPLE_SIDE);
    (centre == x).then_some(stratum)
}

const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
const FLUX_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// Default `--max-vals`: a million VALs (about 90 MB of RSM and VAL storage); every scene
/// built in fits at the methods' default `rsm`.
pub const DEFAULT_MAX_VALS: u32 = 1 << 20;

/// The RSMs of every light and the VAL buffer made from them.
///
/// A *layer* here is one light view of `resolution`² texels (six per point light). When the
/// views outnumber the device's array layers, `pack`² of them share one physical layer of
/// `pack·resolution` texels a side, as tiles in row-major order; every texture read goes
/// through [`Rsm::physical_texel`] (and its WGSL twin), so consumers still think in views.
pub struct Rsm {
    pub resolution: u32,
    pub layer_count: u32,
    /// Views per physical layer side (1: one view per array layer).
    pub pack: u32,
    /// Capacity in RSM VALs (every texel of every layer).
    pub capacity: u32,
    /// Further slots after the RSM's for [`ExternalVals`] (0 without).
    pub external_capacity: u32,
    pub vals_buffer: wgpu::Buffer,
    /// One u32: how many VALs this frame produced.
    pub val_count_buffer: wgpu::Buffer,
    /// Cluster tiles per layer side ([`cluster_tiles`]); every VAL's `flux.w` holds its
    /// cluster.
    pub tiles: u32,
    /// Per tile over all layers, `CLUSTER_SAMPLE_SIDE²` slots: 1 + the index of the VAL at
    /// the stratum's centre texel, or 0 where that texel is unlit.
    pub cluster_samples: wgpu::Buffer,
    pub bytes: GpuBytes,
    lights_buffer: wgpu::Buffer,
    layer_buffers: Vec<wgpu::Buffer>,
    layer_groups: Vec<wgpu::BindGroup>,
    /// Per layer: position, normal and flux attachment views.
    layer_views: Vec<[wgpu::TextureView; 3]>,
    depth_view: wgpu::TextureView,
    pipeline: wgpu::RenderPipeline,
    /// count_rows, scan_rows, write_rows of `vals_from_rsm.wgsl`.
    compact_pipelines: [wgpu::ComputePipeline; 3],
    compact_group: wgpu::BindGroup,
    mesh_bounds: Vec<Aabb>,
    /// Position/area, normal and flux of every layer, as 2-D arrays (read by techniques that
    /// sample the RSM itself rather than its VAL list).
    pub array_views: [wgpu::TextureView; 3],
    append: Option<Append>,
}

/// The passes of `vals_append.wgsl` bound to one [`ExternalVals`].
struct Append {
    /// count_rows, append_rows.
    pipelines: [wgpu::ComputePipeline; 2],
    group: wgpu::BindGroup,
    rows: u32,
}

/// Rows per workgroup of the append passes (`@workgroup_size(64, 1, 1)`).
pub const APPEND_GROUP: u32 = 64;

/// `vals_rsm.wgsl`: the layer's view, the instance transforms and the lights.
const VIEW_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Storage, Slot::Storage];

/// `vals_from_rsm.wgsl`: the RSM size, its position, normal and flux arrays, and the VALs,
/// their count, the row offsets and the cluster samples it writes.
const COMPACT_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::TextureArray,
    Slot::TextureArray,
    Slot::TextureArray,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
];

/// `vals_append.wgsl`: its size block, the external candidates, and the VALs, their count and
/// the per-row counts it writes.
const APPEND_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
];

/// RSM rows per workgroup of the compaction's count and write passes (`count_rows`,
/// `write_rows` in `vals_from_rsm.wgsl`).
pub const ROW_GROUP: u32 = 64;

/// Threads of the compaction's single scan workgroup (`scan_rows`; its `SCAN_GROUP`).
pub const SCAN_GROUP: u32 = 256;

/// `AppendSize` in `shaders/light/vals_append.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct AppendSize {
    pub rows: u32,
    pub row_length: u32,
    pub capacity: u32,
    pub pad: u32,
}

impl Rsm {
    /// The RSMs of `scene`'s lights at `resolution` per view, drawn from `raster`'s scene
    /// upload and within its `max_vals`.
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        raster: &Rasterizer,
        resolution: u32,
    ) -> Result<Self, RenderError> {
        Self::with_external(ctx, scene, raster, resolution, None)
    }

    /// The RSMs, with room after their VALs for `external`'s valid candidates, which
    /// [`Rsm::record`] appends every frame (see [`ExternalVals`]).
    pub fn with_external(
        ctx: &GpuContext,
        scene: &Scene,
        raster: &Rasterizer,
        requested_resolution: u32,
        external: Option<&ExternalVals>,
    ) -> Result<Self, RenderError> {
        let scene_gpu = &raster.scene_gpu;
        let max_vals = raster.settings.max_vals;
        let device = &ctx.device;
        let limits = device.limits();
        if requested_resolution == 0 || requested_resolution > limits.max_texture_dimension_2d {
            return Err(RenderError::Settings(format!(
                "--rsm {requested_resolution}: the RSM resolution must be 1..={}",
                limits.max_texture_dimension_2d
            )));
        }
        let layer_count: u32 = scene.lights.iter().map(|l| l.kind.shadow_layers()).sum();
        let resolution = budget_resolution(requested_resolution, layer_count, max_vals)
            .ok_or_else(|| {
                RenderError::Settings(format!(
                    "--max-vals {max_vals}: scene '{}' has {layer_count} light views ({}), \
                     so not even one VAL per view fits; raise --max-vals to at least {layer_count}",
                    scene.name,
                    crate::gpu::count_of(scene.lights.len(), "light"),
                ))
            })?;
        if resolution < requested_resolution {
            log::warn!(
                "scene '{}': {layer_count} RSM views at --rsm {requested_resolution} would make \
                 {} VALs, over --max-vals {max_vals}; every view uses {resolution}² instead \
                 (each VAL carries its share of the flux, so the light's power is unchanged)",
                scene.name,
                layer_count as u64 * requested_resolution as u64 * requested_resolution as u64,
            );
        }
        let pack = pack_factor(
            layer_count,
            resolution,
            limits.max_texture_array_layers,
            limits.max_texture_dimension_2d,
        )
        .ok_or_else(|| {
            RenderError::Settings(format!(
                "scene '{}' needs {layer_count} RSM views of {resolution}²; the device's {} \
                 array layers of at most {}² cannot hold them: lower --rsm or --max-vals",
                scene.name, limits.max_texture_array_layers, limits.max_texture_dimension_2d
            ))
        })?;
        let physical_side = pack * resolution;
        let physical_layers = layer_count.div_ceil(pack * pack);
        let texels = layer_count as u64 * resolution as u64 * resolution as u64;
        let external_slots = external.map_or(0, |e| e.rows as u64 * e.row_length as u64);
        let slots = texels + external_slots;
        if slots > u32::MAX as u64 {
            return Err(RenderError::Settings(format!(
                "{texels} RSM VALs and {external_slots} external VALs exceed the 2³² VAL indices"
            )));
        }
        let val_bytes = slots.max(1) * std::mem::size_of::<GpuVal>() as u64;
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        if val_bytes > max_binding {
            return Err(RenderError::Settings(format!(
                "--rsm {resolution} with {layer_count} layers and {external_slots} external VALs needs {val_bytes} bytes of VALs; the device binds at most {max_binding} bytes: lower --rsm or the external VALs"
            )));
        }
        let mut bytes = GpuBytes::default();
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let vals_buffer = ctx.scoped(
            &format!("the VAL buffer ({slots} VALs)"),
            Some(val_bytes),
            "Lower --rsm, or use fewer lights or external VALs",
            || {
                bytes.buffer(
                    device,
                    &wgpu::BufferDescriptor {
                        label: Some("vals"),
                        size: val_bytes,
                        usage: storage | wgpu::BufferUsages::COPY_SRC,
                        mapped_at_creation: false,
                    },
                )
            },
        )?;
        let val_count_buffer = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("val count"),
                size: 4,
                usage: storage | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            },
        );
        let lights_buffer = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("rsm lights"),
                size: (scene.lights.len().max(1) * std::mem::size_of::<GpuLight>()) as u64,
                usage: storage,
                mapped_at_creation: false,
            },
        );
        let layers = layer_count.max(1);
        let physical = physical_layers.max(1);
        let side = physical_side as u64 * physical_side as u64;
        let rsm_bytes = side
            * (physical as u64
                * [POSITION_FORMAT, NORMAL_FORMAT, FLUX_FORMAT]
                    .map(crate::gpu::resources::block_bytes)
                    .iter()
                    .sum::<u64>()
                + crate::gpu::resources::block_bytes(DEPTH_FORMAT));
        let (textures, depth) = ctx.scoped(
            &format!(
                "the RSMs of scene '{}' ({}: {layers} layers of {resolution}×{resolution})",
                scene.name,
                crate::gpu::count_of(scene.lights.len(), "light")
            ),
            Some(rsm_bytes),
            "Lower --rsm or --max-vals (a point light takes six views) or use fewer lights",
            || {
                let mut array = |label: &str, format| {
                    bytes.texture(
                        device,
                        &wgpu::TextureDescriptor {
                            label: Some(label),
                            size: wgpu::Extent3d {
                                width: physical_side,
                                height: physical_side,
                                depth_or_array_layers: physical,
                            },
                            mip_level_count: 1,
                            sample_count: 1,
                            dimension: wgpu::TextureDimension::D2,
                            format,
                            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                                | wgpu::TextureUsages::TEXTURE_BINDING,
                            view_formats: &[],
                        },
                    )
                };
                let textures = [
                    array("rsm position", POSITION_FORMAT),
                    array("rsm normal", NORMAL_FORMAT),
                    array("rsm flux", FLUX_FORMAT),
                ];
                let depth = bytes.texture_2d(
                    device,
                    "rsm depth",
                    (physical_side, physical_side),
                    DEPTH_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT,
                );
                (textures, depth)
            },
        )?;
        let depth_view = depth.create_view(&Default::default());
        let layer_views: Vec<[wgpu::TextureView; 3]> = (0..physical_layers)
            .map(|layer| {
                textures.each_ref().map(|t| {
                    t.create_view(&wgpu::TextureViewDescriptor {
                        label: Some("rsm layer"),
                        dimension: Some(wgpu::TextureViewDimension::D2),
                        base_array_layer: layer,
                        array_layer_count: Some(1),
                        ..Default::default()
                    })
                })
            })
            .collect();
        let array_views = textures.each_ref().map(|t| {
            t.create_view(&wgpu::TextureViewDescriptor {
                label: Some("rsm array"),
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        });

        let vs_fs = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let view_bgl = GroupLayout::new(device, "rsm view", vs_fs, VIEW_BINDINGS);
        let layer_buffers: Vec<wgpu::Buffer> = (0..layer_count)
            .map(|_| bytes.uniform::<RsmView>(device, "rsm view"))
            .collect();
        let layer_groups = layer_buffers
            .iter()
            .map(|buffer| {
                view_bgl.bind(
                    device,
                    &[buffer, &scene_gpu.instance_buffer, &lights_buffer],
                )
            })
            .collect();
        let module = ctx.shader("vals_rsm.wgsl");
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("rsm"),
            bind_group_layouts: &[
                Some(&view_bgl.layout),
                Some(&scene_gpu.material_layout.layout),
            ],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2];
        let pipeline = ctx.scoped(
            "the RSM pipeline",
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                ScenePipeline {
                    label: "rsm",
                    module: &module,
                    layout: &layout,
                    vertex: wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<Vertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &attributes,
                    },
                    depth_write: true,
                    depth_compare: wgpu::CompareFunction::Less,
                    depth_bias: wgpu::DepthBiasState::default(),
                    targets: &[POSITION_FORMAT, NORMAL_FORMAT, FLUX_FORMAT],
                }
                .build(device)
            },
        )?;

        let cs = wgpu::ShaderStages::COMPUTE;
        let compact_bgl = GroupLayout::new(device, "vals from rsm", cs, COMPACT_BINDINGS);
        let tiles = cluster_tiles(resolution, layer_count);
        let cluster_samples = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("rsm cluster samples"),
                size: (layers as u64
                    * (tiles * tiles * CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE) as u64
                    * 4)
                .max(4),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            },
        );
        let capacity = texels.min(u32::MAX as u64) as u32;
        let size_buffer = bytes.buffer_init(
            device,
            "rsm size",
            bytemuck::bytes_of(&RsmSize {
                resolution,
                layers: layer_count,
                capacity,
                tiles,
                pack,
                pad0: 0,
                pad1: 0,
                pad2: 0,
            }),
            wgpu::BufferUsages::UNIFORM,
        );
        let row_offsets = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("rsm row offsets"),
                size: layers as u64 * resolution as u64 * 4,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            },
        );
        let compact_group = compact_bgl.bind(
            device,
            &[
                &size_buffer,
                &array_views[0],
                &array_views[1],
                &array_views[2],
                &vals_buffer,
                &val_count_buffer,
                &row_offsets,
                &cluster_samples,
            ],
        );
        let module = ctx.shader("vals_from_rsm.wgsl");
        let compact_pipelines = ctx.scoped(
            "the VAL compaction pipelines",
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                ["count_rows", "scan_rows", "write_rows"].map(|entry| {
                    crate::raster::compute_pipeline_at(
                        device,
                        entry,
                        &module,
                        &compact_bgl.layout,
                        entry,
                    )
                })
            },
        )?;
        let append = external.map(|e| {
            let bgl = GroupLayout::new(device, "vals append", cs, APPEND_BINDINGS);
            let size = bytes.buffer_init(
                device,
                "vals append size",
                bytemuck::bytes_of(&AppendSize {
                    rows: e.rows,
                    row_length: e.row_length,
                    capacity: slots as u32,
                    pad: 0,
                }),
                wgpu::BufferUsages::UNIFORM,
            );
            let row_counts = bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some("vals append rows"),
                    size: (e.rows as u64 + 1) * 4,
                    usage: wgpu::BufferUsages::STORAGE,
                    mapped_at_creation: false,
                },
            );
            let group = bgl.bind(
                device,
                &[
                    &size,
                    &e.candidates,
                    &vals_buffer,
                    &val_count_buffer,
                    &row_counts,
                ],
            );
            let module = ctx.shader("vals_append.wgsl");
            Append {
                pipelines: ["count_rows", "append_rows"].map(|entry| {
                    crate::raster::compute_pipeline_at(device, entry, &module, &bgl.layout, entry)
                }),
                group,
                rows: e.rows,
            }
        });
        Ok(Self {
            resolution,
            layer_count,
            pack,
            capacity,
            external_capacity: external_slots as u32,
            vals_buffer,
            val_count_buffer,
            tiles,
            cluster_samples,
            bytes,
            lights_buffer,
            layer_buffers,
            layer_groups,
            layer_views,
            depth_view,
            pipeline,
            compact_pipelines,
            compact_group,
            mesh_bounds: scene.meshes.iter().map(|m| m.model_bounds()).collect(),
            array_views,
            append,
        })
    }

    /// Uploads this frame's light records and RSM views.
    pub fn prepare(&self, ctx: &GpuContext, scene: &Scene, world_from_node: &[Mat4]) {
        let setup = self.light_setup(scene, world_from_node);
        if !setup.lights.is_empty() {
            ctx.queue
                .write_buffer(&self.lights_buffer, 0, bytemuck::cast_slice(&setup.lights));
        }
        let mut layer = 0usize;
        for (light_index, light) in setup.lights.iter().enumerate() {
            let layers = if matches!(
                light.kind,
                crate::raster::types::LIGHT_POINT | crate::raster::types::LIGHT_EMITTER
            ) {
                6
            } else {
                1
            };
            for _ in 0..layers {
                let view = &setup.views[layer];
                let perspective = view.origin[3] > 0.5;
                let rsm_view = RsmView {
                    clip_from_world: view.clip_from_world,
                    light_index: light_index as u32,
                    resolution: self.resolution,
                    tan_half_fov: if perspective {
                        0.5 * view.texel[0] * self.resolution as f32
                    } else {
                        0.0
                    },
                    texel_area: if perspective {
                        0.0
                    } else {
                        view.texel[0] * view.texel[0]
                    },
                    tile_origin: {
                        let (_, x, y) = self.physical_texel(layer as u32, 0, 0);
                        [x, y]
                    },
                    _pad: [0; 2],
                };
                ctx.queue.write_buffer(
                    &self.layer_buffers[layer],
                    0,
                    bytemuck::bytes_of(&rsm_view),
                );
                layer += 1;
            }
        }
    }

    /// This frame's light records and RSM layer views (layers in light order, six per point
    /// light), exactly as [`Rsm::prepare`] uploads them.
    pub fn light_setup(
        &self,
        scene: &Scene,
        world_from_node: &[Mat4],
    ) -> crate::raster::shadows::LightSetup {
        let bounds = scene.instance_bounds(&self.mesh_bounds, world_from_node);
        // No margin: cube faces must meet exactly so that no direction is counted twice.
        setup_lights(
            scene,
            world_from_node,
            &bounds,
            &vec![self.resolution; scene.lights.len()],
            0.0,
        )
    }

    /// Renders every RSM layer and compacts the lit texels into VALs (passes "rsm"), then
    /// appends the external VALs' valid candidates (pass "vals append"); their producer must
    /// have recorded its passes before this.
    pub fn record(&self, passes: &mut Passes, scene_gpu: &SceneGpu) -> Result<(), GpuError> {
        let per_physical = (self.pack * self.pack) as usize;
        for (physical, views) in self.layer_views.iter().enumerate() {
            let first = physical * per_physical;
            let last = (first + per_physical).min(self.layer_groups.len());
            passes.render(
                "rsm",
                &[cleared(&views[0]), cleared(&views[1]), cleared(&views[2])],
                Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                |pass| {
                    pass.set_pipeline(&self.pipeline);
                    for (layer, group) in (first..last).zip(&self.layer_groups[first..last]) {
                        let (_, x, y) = self.physical_texel(layer as u32, 0, 0);
                        let r = self.resolution;
                        pass.set_viewport(x as f32, y as f32, r as f32, r as f32, 0.0, 1.0);
                        pass.set_scissor_rect(x, y, r, r);
                        pass.set_bind_group(0, group, &[]);
                        scene_gpu.draw(pass, Some(1));
                    }
                },
            )?;
        }
        if self.layer_count > 0 {
            // One thread per row; rows past 65535 workgroups wrap into a second dimension.
            let groups = (self.resolution * self.layer_count).div_ceil(ROW_GROUP);
            let (gx, gy) = if groups <= 65535 {
                (groups, 1)
            } else {
                (65535, groups.div_ceil(65535))
            };
            passes
                .encoder()
                .clear_buffer(&self.cluster_samples, 0, None);
            let [count, scan, write] = &self.compact_pipelines;
            for (pipeline, (x, y)) in [(count, (gx, gy)), (scan, (1, 1)), (write, (gx, gy))] {
                passes.compute("rsm", |pass| {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, &self.compact_group, &[]);
                    pass.dispatch_workgroups(x, y, 1);
                })?;
            }
        } else {
            passes
                .encoder()
                .clear_buffer(&self.val_count_buffer, 0, None);
        }
        if let Some(append) = self.append.as_ref().filter(|a| a.rows > 0) {
            for pipeline in &append.pipelines {
                passes.compute("vals append", |pass| {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, &append.group, &[]);
                    pass.dispatch_workgroups(append.rows.div_ceil(APPEND_GROUP), 1, 1);
                })?;
            }
        }
        Ok(())
    }

    /// The VALs of the last recorded frame.
    pub fn read_vals(&self, ctx: &GpuContext) -> Result<Vec<Val>, GpuError> {
        let count = self
            .read_count(ctx)?
            .min(self.capacity.saturating_add(self.external_capacity)) as usize;
        let all: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.vals_buffer)?;
        Ok(all[..count.min(all.len())]
            .iter()
            .map(GpuVal::to_val)
            .collect())
    }

    /// The VALs of the last recorded frame as the GPU holds them (with their clusters).
    pub fn read_gpu_vals(&self, ctx: &GpuContext) -> Result<Vec<GpuVal>, GpuError> {
        let count = self.read_count(ctx)?.min(self.capacity) as usize;
        let mut all: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.vals_buffer)?;
        all.truncate(count);
        Ok(all)
    }

    /// The cluster sample slots of the last recorded frame (see [`Rsm::cluster_samples`]).
    pub fn read_cluster_samples(&self, ctx: &GpuContext) -> Result<Vec<u32>, GpuError> {
        crate::gpu::read_buffer(ctx, &self.cluster_samples)
    }

    /// Where texel (x, y) of view `layer` lives: (physical layer, x, y). Views fill their
    /// physical layer `pack` to a row (`rsm_texel` in `vals_from_rsm.wgsl` is the WGSL twin).
    pub fn physical_texel(&self, layer: u32, x: u32, y: u32) -> (u32, u32, u32) {
        physical_texel(self.pack, self.resolution, layer, x, y)
    }

    /// Tiles over all layers (each with `CLUSTER_SAMPLE_SIDE²` sample slots).
    pub fn tile_count(&self) -> u32 {
        self.layer_count * self.tiles * self.tiles
    }

    pub fn read_count(&self, ctx: &GpuContext) -> Result<u32, GpuError> {
        let count: Vec<u32> = crate::gpu::read_buffer(ctx, &self.val_count_buffer)?;
        Ok(count.first().copied().unwrap_or(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_val_budget_shrinks_every_view_to_the_largest_side_that_fits() {
        assert_eq!(budget_resolution(64, 6, u32::MAX), Some(64));
        assert_eq!(budget_resolution(64, 6000, 1 << 20), Some(13)); // 6000·13² ≤ 2²⁰ < 6000·14²
        assert_eq!(budget_resolution(64, 6, 6 * 49), Some(7));
        assert_eq!(budget_resolution(64, 6, 6 * 49 - 1), Some(6));
        assert_eq!(budget_resolution(64, 6, 5), None);
        assert_eq!(budget_resolution(64, 0, 1), Some(64));
    }

    #[test]
    fn views_pack_only_when_the_array_layers_run_out() {
        assert_eq!(pack_factor(2048, 64, 2048, 16384), Some(1));
        assert_eq!(pack_factor(2049, 64, 2048, 16384), Some(2));
        assert_eq!(pack_factor(6000, 64, 2048, 16384), Some(2));
        assert_eq!(pack_factor(10_000, 64, 2048, 16384), Some(3));
        // 4·4096 > 16384 would be needed.
        assert_eq!(pack_factor(100_000, 4096, 2048, 16384), None);
    }

    #[test]
    fn packed_views_tile_their_layers_without_overlap() {
        let (pack, side) = (3, 5);
        let mut seen = std::collections::HashSet::new();
        for layer in 0..20 {
            for y in 0..side {
                for x in 0..side {
                    let (l, px, py) = physical_texel(pack, side, layer, x, y);
                    assert!(px < pack * side && py < pack * side);
                    assert!(
                        seen.insert((l, px, py)),
                        "view {layer} texel {x},{y} reused"
                    );
                }
            }
        }
        assert_eq!(physical_texel(1, 8, 7, 3, 4), (7, 3, 4));
    }
}
