//! Sparse virtual-area-light shading, the core method (DESIGN §4, seed 003). See README.md in
//! this folder for the equations and the pass list.
//!
//! - [`rsm`]: reflective shadow maps → one buffer of VALs for all lights.
//! - [`points`]: the preprocessing — sparse points per mesh, vertex links, disc radii.
//! - [`sparse`]: the GPU passes gather → renormalize → occlusion → interpolation → apply.
//! - [`math`]: the CPU twin of every kernel, and the documentation of the math.

pub mod math;
pub mod points;
pub mod rsm;
pub mod sparse;

use std::sync::Arc;
use std::time::Instant;

use glam::Mat4;

use crate::gpu::{GpuContext, GpuError, Passes};
use crate::method::{Method, MethodOptions};
use crate::raster::{FrameOutput, Rasterizer, RenderError, RenderSettings};
use crate::scene::{CameraView, Scene};
use math::{OcclusionMode, Weights};
use points::MeshPoints;
use rsm::Rsm;
pub use sparse::Stage;
use sparse::{SparseGpu, SparseOptions};

/// Everything `--method sparse` can be told.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseSettings {
    /// RSM resolution per light layer.
    pub rsm: u32,
    /// Sparse points for the whole scene.
    pub sparse_points: usize,
    /// Placement seed.
    pub seed: u64,
    pub options: SparseOptions,
}

impl Default for SparseSettings {
    fn default() -> Self {
        Self {
            rsm: 128,
            sparse_points: 4096,
            seed: 1,
            options: SparseOptions {
                tile: 128,
                glossy: true,
                occlusion: OcclusionMode::Sum,
                weights: Weights::Geometric,
            },
        }
    }
}

impl SparseSettings {
    /// Reads the options `rsm`, `sparse-points`, `seed`, `tile`, `glossy`, `occlusion` and
    /// `weights` (those not given keep their defaults).
    pub fn from_options(options: &MethodOptions) -> Result<Self, RenderError> {
        let d = Self::default();
        let tile: u32 = options.get("tile", d.options.tile)?;
        if !(1..=256).contains(&tile) {
            return Err(RenderError::Settings(format!(
                "--tile {tile}: must be 1..=256 (workgroup memory holds at most 256 VALs)"
            )));
        }
        let sparse_points: usize = options.get("sparse-points", d.sparse_points)?;
        if sparse_points == 0 {
            return Err(RenderError::Settings(
                "--sparse-points must be at least 1".into(),
            ));
        }
        Ok(Self {
            rsm: options.get("rsm", d.rsm)?,
            sparse_points,
            seed: options.get("seed", d.seed)?,
            options: SparseOptions {
                tile,
                glossy: options.choice("glossy", &["on", "off"])? == "on",
                occlusion: match options.choice("occlusion", &["sum", "union", "off"])? {
                    "off" => OcclusionMode::Off,
                    "union" => OcclusionMode::Union,
                    _ => OcclusionMode::Sum,
                },
                weights: match options.choice("weights", &["geometric", "flux"])? {
                    "flux" => Weights::Flux,
                    _ => Weights::Geometric,
                },
            },
        })
    }
}

/// The sparse method's structs shared with WGSL, for the layout test.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout;
    vec![
        shared_layout!(
            "Val",
            "vals_common.wgsl",
            rsm::GpuVal,
            [position_area, normal, flux]
        ),
        shared_layout!(
            "SparseParams",
            "vals_common.wgsl",
            sparse::SparseParams,
            [
                eye,
                point_count,
                instance_count,
                flags,
                occlusion_mode,
                tile,
                vertex_count,
                pad0,
                pad1
            ]
        ),
        shared_layout!(
            "InstanceRange",
            "vals_common.wgsl",
            sparse::InstanceRange,
            [vertex_offset, vertex_count, point_offset, link_offset]
        ),
        shared_layout!(
            "RsmView",
            "vals_rsm.wgsl",
            rsm::RsmView,
            [
                clip_from_world,
                light_index,
                resolution,
                tan_half_fov,
                texel_area
            ]
        ),
        shared_layout!(
            "RsmSize",
            "vals_from_rsm.wgsl",
            rsm::RsmSize,
            [resolution, layers, capacity, pad]
        ),
        shared_layout!(
            "FmaParams",
            "bench_fma.wgsl",
            crate::bench::FmaParams,
            [iterations, pad0, pad1, pad2]
        ),
    ]
}

/// Table 2 of the paper: per-pass milliseconds grouped as its rows.
pub fn table2(timings: &crate::gpu::PassTimings) -> serde_json::Value {
    let get = |l: &str| timings.get(l).unwrap_or(0.0);
    let round = crate::gpu::timing::round3;
    serde_json::json!({
        "rsm": round(get("rsm")),
        "direct": round(get("shadow") + get("gbuffer") + get("direct")),
        "gather": round(get("gather")),
        "renormalize": round(get("renormalize")),
        "occlusion": round(get("occlusion")),
        "interpolation": round(get("interpolation")),
        "apply": round(get("apply")),
        "total": round(timings.total_ms()),
    })
}

/// Indirect light that a composed method adds on top of the VAL bounce (`sparse+atlas`: the
/// atlas's bounces 2..B). With a layer set, the sparse apply pass draws the VAL bounce into
/// [`IndirectLayer::vals_target`] and the layer's `record` then writes `radiance_indirect`
/// (VAL bounce + its own light) after it. The layer reads the same G-buffer.
pub trait IndirectLayer {
    /// The composed method's name (as given to `--method`).
    fn method_name(&self) -> &'static str;
    /// Per-frame uploads (camera, transforms).
    fn prepare(&self, ctx: &GpuContext, world_from_node: &[Mat4], camera: &CameraView);
    /// Where the sparse apply pass draws (`RADIANCE_FORMAT`, render resolution).
    fn vals_target(&self) -> &wgpu::TextureView;
    /// Writes `radiance_indirect` from the VAL bounce in `vals_target` plus the layer's light.
    fn record(&self, passes: &mut Passes) -> Result<(), GpuError>;
    fn gpu_bytes(&self) -> u64;
    /// Extra keys for the method's JSON report.
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

pub struct SparseMethod {
    pub settings: SparseSettings,
    pub raster: Rasterizer,
    pub rsm: Rsm,
    pub sparse: SparseGpu,
    pub points: Vec<Arc<MeshPoints>>,
    /// Run the frame only up to this pass (tests read intermediate buffers).
    pub last_stage: Stage,
    pub preprocess_ms: f64,
    /// Meshes whose points were computed rather than taken from the cache.
    pub meshes_computed: usize,
    /// Further indirect light added after the apply pass (`None` for `--method sparse`).
    pub layer: Option<Box<dyn IndirectLayer>>,
    report: serde_json::Map<String, serde_json::Value>,
}

impl SparseMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        settings: SparseSettings,
    ) -> Result<Self, RenderError> {
        let raster = Rasterizer::new(ctx, scene, render)?;
        let rsm = Rsm::new(ctx, scene, &raster.scene_gpu, settings.rsm)?;
        let started = Instant::now();
        let (points, meshes_computed) =
            points::scene_points(scene, settings.sparse_points, settings.seed);
        let preprocess_ms = started.elapsed().as_secs_f64() * 1000.0;
        let sparse = SparseGpu::new(
            ctx,
            scene,
            &raster.scene_gpu,
            &raster.targets,
            &raster.frame_buffer,
            &points,
            &rsm.vals_buffer,
            &rsm.val_count_buffer,
        )?;
        Ok(Self {
            settings,
            raster,
            rsm,
            sparse,
            points,
            last_stage: Stage::Apply,
            preprocess_ms,
            meshes_computed,
            layer: None,
            report: Default::default(),
        })
    }

    /// GPU bytes of the sparse solution alone (points, links, vertex lights).
    pub fn solution_bytes(&self) -> u64 {
        self.sparse.bytes.0
    }
}

impl Method for SparseMethod {
    fn name(&self) -> &'static str {
        self.layer.as_ref().map_or("sparse", |l| l.method_name())
    }

    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError> {
        let opts = self.settings.options;
        self.raster.prepare(ctx, scene, world_from_node, camera);
        self.rsm.prepare(ctx, scene, world_from_node);
        self.sparse.prepare(ctx, camera.position(), &opts);
        if let Some(layer) = &self.layer {
            layer.prepare(ctx, world_from_node, camera);
        }
        let mut passes = Passes::new(ctx, self.rsm.layer_count + 36);
        self.raster.record_base(&mut passes)?;
        self.rsm.record(&mut passes, &self.raster.scene_gpu)?;
        let has_indirect = self.last_stage == Stage::Apply;
        match self.layer.as_ref().filter(|_| has_indirect) {
            None => self.sparse.record(
                &mut passes,
                &self.raster.scene_gpu,
                &self.raster.targets,
                &opts,
                self.last_stage,
            )?,
            Some(layer) => {
                self.sparse.record_into(
                    &mut passes,
                    &self.raster.scene_gpu,
                    &self.raster.targets,
                    &opts,
                    self.last_stage,
                    layer.vals_target(),
                )?;
                layer.record(&mut passes)?;
            }
        }
        let solution = self.solution_bytes();
        let layer_bytes = self.layer.as_ref().map_or(0, |l| l.gpu_bytes());
        let frame = self.raster.finish_frame(
            ctx,
            passes,
            has_indirect,
            self.rsm.bytes.0 + solution + layer_bytes,
        )?;
        let vals = self.rsm.read_count(ctx)?;
        let (clamped_d, clamped_s) = self.sparse.read_clamps(ctx)?;
        let points = self.sparse.point_count.max(1) as f64;
        let per_point = (self.sparse.point_bytes as f64) / points;
        let vertices = self.sparse.vertex_count.max(1) as f64;
        self.report = serde_json::json!({
            "table2": table2(&frame.timings),
            "vals": vals,
            "rsm": self.settings.rsm,
            "sparse_points": self.sparse.point_count,
            "instance_vertices": self.sparse.vertex_count,
            "tile": opts.tile,
            "glossy": if opts.glossy { "on" } else { "off" },
            "occlusion": format!("{:?}", opts.occlusion).to_lowercase(),
            "weights": format!("{:?}", opts.weights).to_lowercase(),
            "preprocess_ms": crate::gpu::timing::round3(self.preprocess_ms),
            "preprocess_meshes_computed": self.meshes_computed,
            "renormalize_clamped": [clamped_d, clamped_s],
            "solution_gpu_bytes": solution,
            "bytes_per_point": per_point,
            "vertex_light_bytes_per_vertex": self.sparse.vertex_light_bytes as f64 / vertices,
            "link_bytes": self.sparse.link_bytes,
        })
        .as_object()
        .cloned()
        .unwrap_or_default();
        if let Some(layer) = &self.layer {
            self.report.extend(layer.report());
        }
        Ok(frame)
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        self.report.clone()
    }
}

pub fn create(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    let settings = SparseSettings::from_options(options)?;
    Ok(Box::new(SparseMethod::new(ctx, scene, render, settings)?))
}
