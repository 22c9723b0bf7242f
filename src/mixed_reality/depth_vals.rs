//! The GPU passes that turn a depth-sensor frame into VALs (`depth_vals.wgsl`): bilateral
//! filter → surfels → stratified reduction. [`DepthVals`] is a [`ValSource`]: the sparse
//! method appends its VALs to the RSM's. Frames arrive through a [`FrameSlot`] (the latest
//! one wins, as from a live sensor) and are uploaded when the next frame is recorded.

use std::sync::{Arc, Mutex};

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

use super::math::{self, KernelParams, Receivers, Surfel};
use super::rgbd::{Intrinsics, RgbdFrame};
use crate::frame::PIXEL_TILE;
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{GpuBytes, GpuContext, GpuError, Passes};
use crate::light::rsm::GpuVal;
use crate::light::sensor::{
    projected_samples, world_tile, SensorBuffers, SensorParams, SENSOR_TILES,
};
use crate::light::{ExternalVals, Val, ValSource};
use crate::raster::RenderError;

/// `depth_vals.wgsl`: its parameters, then the raw depth, colour, filtered depth, surfels,
/// per-block candidates and the visibility rays' sample slots its four passes read and write.
const BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
];

/// Blocks per workgroup of the `reduce` pass (`@workgroup_size(64, 1, 1)`).
pub const REDUCE_GROUP: u32 = 64;

/// Invocations of a `cut` workgroup (`@workgroup_size(64, 1, 1)`): one per 4×4 pixels of
/// its `CUT_BLOCK`² block, which the dispatch counts.
pub const CUT_GROUP: u32 = (math::CUT_BLOCK / 4) * (math::CUT_BLOCK / 4);

/// Sample slots per workgroup of the `samples_of_surfels` pass (`@workgroup_size(64, 1, 1)`).
pub const SAMPLES_GROUP: u32 = 64;

/// `DepthValParams` in `shaders/mixed_reality/depth_vals.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DepthValParams {
    pub world_from_camera: [[f32; 4]; 4],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    pub grid_width: u32,
    pub grid_height: u32,
    pub sigma_spatial: f32,
    pub sigma_range: f32,
    pub real_scale: f32,
    pub max_jump: f32,
    pub radius: u32,
    pub area_mode: u32,
    pub cluster_tiles: u32,
    pub pad1: u32,
    pub receivers: [f32; 4],
    pub cut_ratio: f32,
    pub pad2: u32,
    pub pad3: u32,
    pub pad4: u32,
}

impl From<&KernelParams> for DepthValParams {
    fn from(p: &KernelParams) -> Self {
        Self {
            world_from_camera: p.world_from_camera.to_cols_array_2d(),
            fx: p.fx,
            fy: p.fy,
            cx: p.cx,
            cy: p.cy,
            width: p.width,
            height: p.height,
            grid_width: p.grid_width,
            grid_height: p.grid_height,
            sigma_spatial: p.sigma_spatial,
            sigma_range: p.sigma_range,
            real_scale: p.real_scale,
            max_jump: p.max_jump,
            radius: p.radius,
            area_mode: p.true_area as u32,
            cluster_tiles: SENSOR_TILES,
            pad1: 0,
            receivers: NO_RECEIVERS,
            cut_ratio: 0.0,
            pad2: 0,
            pad3: 0,
            pad4: 0,
        }
    }
}

/// `DepthValParams::receivers` when no receivers are known: `--real-cut` merges nothing.
const NO_RECEIVERS: [f32; 4] = [0.0, 0.0, 0.0, -1.0];

/// How a depth frame becomes VALs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthValSettings {
    /// Bilateral half-width in pixels (0: no filter).
    pub radius: u32,
    pub sigma_spatial: f32,
    /// Metres.
    pub sigma_range: f32,
    /// Radiance of a decoded colour of 1 (`--real-scale`, W/(m²·sr)).
    pub real_scale: f32,
    pub max_jump: f32,
    /// The VAL's area is the true tilted area rather than the facing footprint.
    pub true_area: bool,
    /// At most this many VALs (`--real-vals`); `None` keeps one per pixel.
    pub real_vals: Option<u32>,
    /// `--real-cut θ`: merge pixels into the coarsest blocks the receivers see smaller than
    /// θ (radius over gap, `math::cut`); `None` (the default here) keeps one VAL per pixel.
    pub real_cut: Option<f32>,
    /// Fuse the last this-many frames in a voxel hash (`--accumulate`; 1: latest frame only).
    pub accumulate: u32,
    /// Voxel edge of the fusion, metres.
    pub voxel: f32,
    /// The filtered depth blocks the virtual object's shadow rays (`--real-occluders`).
    pub real_occluders: bool,
    /// Metres of matter assumed behind every seen surface (`--real-thickness`).
    pub real_thickness: f32,
}

impl Default for DepthValSettings {
    /// 5×5 kernel, σ_s = 2 px, σ_r = 30 mm (methods note C.2).
    fn default() -> Self {
        Self {
            radius: 2,
            sigma_spatial: 2.0,
            sigma_range: 0.03,
            real_scale: 1.0,
            max_jump: 0.05,
            true_area: false,
            real_vals: None,
            real_cut: None,
            accumulate: 1,
            voxel: 0.02,
            real_occluders: true,
            real_thickness: DEFAULT_REAL_THICKNESS,
        }
    }
}

impl DepthValSettings {
    pub fn check(&self) -> Result<(), RenderError> {
        let bad = |why: &str| Err(RenderError::Settings(why.to_string()));
        if self.radius > 16 {
            return bad("--bilateral-radius must be 0..=16 pixels");
        }
        let positive = |x: f32| x > 0.0 && x.is_finite();
        if !positive(self.sigma_spatial) || !positive(self.sigma_range) {
            return bad("--sigma-spatial and --sigma-range must be positive");
        }
        if !(self.real_scale >= 0.0 && self.real_scale.is_finite()) {
            return bad("--real-scale must be a finite number ≥ 0");
        }
        if !(self.max_jump > 0.0 && self.max_jump.is_finite()) {
            return bad("the depth-jump threshold must be positive");
        }
        if self.accumulate == 0 || self.accumulate > 64 {
            return bad("--accumulate must be 1..=64 frames");
        }
        if !(self.voxel > 0.0 && self.voxel.is_finite()) {
            return bad("--voxel must be a positive length in metres");
        }
        if self.real_vals == Some(0) {
            return bad("--real-vals must be at least 1");
        }
        if let Some(ratio) = self.real_cut {
            if !(ratio > 0.0 && ratio <= 1.0) {
                return bad(
                    "--real-cut must be a ratio in (0, 1] (0.1: blocks seen within about 0.1 rad)",
                );
            }
            if self.real_vals.is_some() {
                return bad("--real-cut and --real-vals both reduce the sensor's VALs: give one");
            }
            if self.accumulate > 1 {
                return bad("--real-cut merges the latest frame's pixels; --accumulate fuses voxels instead: give one");
            }
        }
        if !(self.real_thickness > 0.0 && self.real_thickness <= 100.0) {
            return bad("--real-thickness must be a length in metres in (0, 100]");
        }
        Ok(())
    }

    /// What the visibility pass is told of a frame of `intrinsics` seen from
    /// `world_from_camera` (`light::sensor`).
    pub fn sensor_params(&self, k: &Intrinsics, world_from_camera: Mat4) -> SensorParams {
        SensorParams {
            camera_from_world: world_from_camera.inverse().to_cols_array_2d(),
            fx: k.fx,
            fy: k.fy,
            cx: k.cx,
            cy: k.cy,
            width: k.width,
            height: k.height,
            tiles: SENSOR_TILES,
            occludes: self.real_occluders as u32,
            thickness: self.real_thickness,
            has_frame: 1,
            pad: [0; 2],
        }
    }

    /// The kernels' parameters for a frame of `intrinsics` seen from `world_from_camera`.
    pub fn kernel_params(&self, intrinsics: &Intrinsics, world_from_camera: Mat4) -> KernelParams {
        let (grid_width, grid_height) =
            math::grid_for(intrinsics.width, intrinsics.height, self.real_vals);
        KernelParams {
            world_from_camera,
            fx: intrinsics.fx,
            fy: intrinsics.fy,
            cx: intrinsics.cx,
            cy: intrinsics.cy,
            width: intrinsics.width,
            height: intrinsics.height,
            grid_width,
            grid_height,
            sigma_spatial: self.sigma_spatial,
            sigma_range: self.sigma_range,
            real_scale: self.real_scale,
            max_jump: self.max_jump,
            radius: self.radius,
            true_area: self.true_area,
        }
    }
}

/// CPU twin of the three passes together: the candidates [`DepthVals`] leaves.
pub fn depth_vals_cpu(frame: &RgbdFrame, p: &KernelParams) -> Vec<Val> {
    let filtered = math::bilateral(&frame.depth, p);
    math::reduce(&math::surfels(&filtered, &frame.color, p), p)
}

/// The same with `--real-cut ratio` and these receivers: one candidate slot per pixel.
pub fn depth_vals_cut_cpu(
    frame: &RgbdFrame,
    p: &KernelParams,
    ratio: f32,
    receivers: Option<Receivers>,
) -> Vec<Val> {
    let filtered = math::bilateral(&frame.depth, p);
    let surfels = math::surfels(&filtered, &frame.color, p);
    math::cut(&surfels, p, SENSOR_TILES, ratio, receivers)
}

/// `valgi mr`'s `--real-cut` when neither `--real-vals` nor `--accumulate` is given. On the
/// Open3D frames with the bunny it keeps 12k of 267k VALs, within 1.2 % (mean absolute) of
/// the full set's irradiance at the sparse points (src/mixed_reality/README.md).
/// [`DepthValSettings::default`] keeps every pixel.
pub const DEFAULT_REAL_CUT: f32 = 0.1;

/// `--real-thickness`: metres of matter assumed behind a seen surface. A thick prior blocks
/// the rays that pass just behind a thin thing (a partition, a chair's back seen edge-on); a
/// thin one lets rays through a bulky thing seen at a grazing angle. Against exact visibility
/// of the same VALs, on a bulky block and on a thin partition (`tests/mixed_reality.rs`,
/// table in `src/mixed_reality/README.md`), the summed error was smallest at 0.15 m.
pub const DEFAULT_REAL_THICKNESS: f32 = 0.15;

/// The latest sensor frame and its camera-to-world pose, waiting for upload.
pub type FrameSlot = Arc<Mutex<Option<(RgbdFrame, Mat4)>>>;

pub struct DepthVals {
    pub intrinsics: Intrinsics,
    pub settings: DepthValSettings,
    pub slot: FrameSlot,
    /// The virtual receivers `--real-cut` measures blocks from, set by whoever places the
    /// virtual objects (`session::MixedReality::new`); `None`: nothing merges.
    pub receivers: Option<Receivers>,
    external: ExternalVals,
    params_buffer: wgpu::Buffer,
    depth_raw: wgpu::Buffer,
    color: wgpu::Buffer,
    depth_filtered: wgpu::Buffer,
    surfels: wgpu::Buffer,
    /// The latest frame's `SensorParams` for the visibility pass (also in `external.sensor`).
    sensor_params: wgpu::Buffer,
    /// The visibility rays' samples of the image's tiles (also in `external.sensor`).
    samples: wgpu::Buffer,
    /// `--accumulate`: the camera the fused VALs are tiled and sampled in, the first frame's
    /// (fixed, so a fused VAL keeps its cluster and the samples stay put while the camera
    /// moves).
    tiling_camera: Option<Mat4>,
    /// bilateral, surfel, reduce, samples, cut.
    pipelines: [wgpu::ComputePipeline; 5],
    group: wgpu::BindGroup,
    bytes: GpuBytes,
    /// A frame has been uploaded (until then the candidates are all empty).
    has_frame: bool,
    last_valid_pixels: usize,
    /// `accumulate > 1`: the fusion, whose VALs are uploaded as the candidates.
    fusion: Option<math::VoxelFusion>,
    last_fused: usize,
}

impl DepthVals {
    pub fn new(
        ctx: &GpuContext,
        intrinsics: Intrinsics,
        settings: DepthValSettings,
    ) -> Result<Self, RenderError> {
        settings.check()?;
        let device = &ctx.device;
        let pixels = intrinsics.width as u64 * intrinsics.height as u64;
        let p = settings.kernel_params(&intrinsics, Mat4::IDENTITY);
        let blocks = p.grid_width as u64 * p.grid_height as u64;
        let limits = device.limits();
        let largest = pixels * std::mem::size_of::<GpuVal>() as u64;
        if largest
            > limits
                .max_storage_buffer_binding_size
                .min(limits.max_buffer_size)
            || blocks.div_ceil(REDUCE_GROUP as u64)
                > limits.max_compute_workgroups_per_dimension as u64
        {
            return Err(RenderError::Settings(format!(
                "a {}×{} depth frame is too large for this device",
                intrinsics.width, intrinsics.height
            )));
        }
        let mut bytes = GpuBytes::default();
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC;
        let mut storage = |label: &str, size: u64| {
            bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some(label),
                    size: size.max(16),
                    usage,
                    mapped_at_creation: false,
                },
            )
        };
        let val = std::mem::size_of::<GpuVal>() as u64;
        let depth_raw = storage("mr depth", pixels * 4);
        let color = storage("mr colour", pixels * 16);
        let depth_filtered = storage("mr filtered depth", pixels * 4);
        let surfels = storage("mr surfels", pixels * val);
        let candidates = storage("mr candidates", blocks * val);
        let samples = storage(
            "mr sensor samples",
            crate::light::sensor::sample_slots(SENSOR_TILES) as u64 * val,
        );
        let params_buffer = bytes.uniform::<DepthValParams>(device, "mr params");
        let sensor_params = bytes.uniform::<SensorParams>(device, "mr sensor");
        let cs = wgpu::ShaderStages::COMPUTE;
        let bgl = GroupLayout::new(device, "depth vals", cs, BINDINGS);
        let group = bgl.bind(
            device,
            &[
                &params_buffer,
                &depth_raw,
                &color,
                &depth_filtered,
                &surfels,
                &candidates,
                &samples,
            ],
        );
        let module = ctx.shader("depth_vals.wgsl");
        let pipelines =
            ["bilateral", "surfel", "reduce", "samples_of_surfels", "cut"].map(|entry| {
                crate::raster::compute_pipeline_at(device, entry, &module, &bgl.layout, entry)
            });
        Ok(Self {
            intrinsics,
            settings,
            slot: FrameSlot::default(),
            receivers: None,
            external: ExternalVals {
                candidates,
                rows: p.grid_height,
                row_length: p.grid_width,
                sensor: Some(SensorBuffers {
                    params: sensor_params.clone(),
                    depth: depth_filtered.clone(),
                    samples: samples.clone(),
                    tiles: SENSOR_TILES,
                }),
            },
            params_buffer,
            depth_raw,
            color,
            depth_filtered,
            surfels,
            sensor_params,
            samples,
            tiling_camera: None,
            pipelines,
            group,
            bytes,
            has_frame: false,
            last_valid_pixels: 0,
            fusion: (settings.accumulate > 1)
                .then(|| math::VoxelFusion::new(settings.accumulate as usize, settings.voxel)),
            last_fused: 0,
        })
    }

    /// Uploads a frame now (the slot's frame, if any, is uploaded at the next record).
    pub fn upload(
        &mut self,
        ctx: &GpuContext,
        frame: &RgbdFrame,
        world_from_camera: Mat4,
    ) -> Result<(), RenderError> {
        let k = &self.intrinsics;
        if (frame.width, frame.height) != (k.width, k.height) {
            return Err(RenderError::Settings(format!(
                "the RGB-D frame is {}×{} but the intrinsics are for {}×{}",
                frame.width, frame.height, k.width, k.height
            )));
        }
        if !world_from_camera.is_finite() {
            return Err(RenderError::Settings(
                "the camera pose is not finite".into(),
            ));
        }
        let p = self.kernel_params(world_from_camera);
        let q = &ctx.queue;
        let sensor = self.sensor_params(world_from_camera);
        q.write_buffer(&self.sensor_params, 0, bytemuck::bytes_of(&sensor));
        self.has_frame = true;
        self.last_valid_pixels = frame.depth.iter().filter(|&&z| z > 0.0).count();
        let Some(fusion) = &mut self.fusion else {
            // The GPU passes filter, back-project and reduce this frame.
            let color: Vec<[f32; 4]> = frame
                .color
                .iter()
                .map(|c| [c[0], c[1], c[2], 0.0])
                .collect();
            let mut params = DepthValParams::from(&p);
            if let Some(ratio) = self.settings.real_cut {
                params.cut_ratio = ratio;
                let usable = |r: &Receivers| r.centre.is_finite() && r.radius >= 0.0;
                if let Some(r) = self.receivers.filter(usable) {
                    params.receivers = [r.centre.x, r.centre.y, r.centre.z, r.radius];
                }
            }
            q.write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
            q.write_buffer(&self.depth_raw, 0, bytemuck::cast_slice(&frame.depth));
            q.write_buffer(&self.color, 0, bytemuck::cast_slice(&color));
            return Ok(());
        };
        // The fusion runs on the CPU over the filter's and the surfel pass's CPU twins; its
        // VALs replace the reduction's candidates, and the filtered depth goes up as it is
        // for the visibility rays' march (no GPU pass runs for this frame).
        let filtered = math::bilateral(&frame.depth, &p);
        q.write_buffer(&self.depth_filtered, 0, bytemuck::cast_slice(&filtered));
        let surfels = math::surfels(&filtered, &frame.color, &p);
        let capacity = (self.external.rows * self.external.row_length) as usize;
        let fused = fusion.push(surfels, capacity);
        self.last_fused = fused.len();
        // Each fused VAL's cluster is the tile it projects to in the first frame's camera,
        // and each sample slot holds the fused VAL that projects nearest its candidate
        // pixel there: both stay put while the camera moves.
        let tiling = SensorParams {
            camera_from_world: self
                .tiling_camera
                .get_or_insert(world_from_camera)
                .inverse()
                .to_cols_array_2d(),
            ..sensor
        };
        let mut records: Vec<GpuVal> = fused
            .iter()
            .map(|val| {
                let mut record = GpuVal::from_val(val);
                record.flux[3] = world_tile(&tiling, val.position) as f32;
                record
            })
            .collect();
        records.resize(capacity, GpuVal::default());
        q.write_buffer(&self.external.candidates, 0, bytemuck::cast_slice(&records));
        let samples: Vec<GpuVal> = projected_samples(&tiling, &fused)
            .iter()
            .map(GpuVal::from_val)
            .collect();
        q.write_buffer(&self.samples, 0, bytemuck::cast_slice(&samples));
        Ok(())
    }

    pub fn kernel_params(&self, world_from_camera: Mat4) -> KernelParams {
        self.settings
            .kernel_params(&self.intrinsics, world_from_camera)
    }

    /// What the visibility pass is told of a frame seen from `world_from_camera`.
    pub fn sensor_params(&self, world_from_camera: Mat4) -> SensorParams {
        self.settings
            .sensor_params(&self.intrinsics, world_from_camera)
    }

    /// The four passes ("mr bilateral", "mr surfels", "mr reduce" or with `--real-cut` "mr
    /// cut", "mr samples") of a frame that is not fused (with `--accumulate` the CPU makes all
    /// they would).
    pub fn record_passes(&self, passes: &mut Passes) -> Result<(), GpuError> {
        let (w, h) = (self.intrinsics.width, self.intrinsics.height);
        let blocks = self.external.rows * self.external.row_length;
        let tiles = (w.div_ceil(PIXEL_TILE), h.div_ceil(PIXEL_TILE), 1);
        let slots = crate::light::sensor::sample_slots(SENSOR_TILES) as u32;
        let [bilateral, surfel, reduce, samples, cut] = &self.pipelines;
        let reduction = match self.settings.real_cut {
            Some(_) => (
                "mr cut",
                cut,
                (w.div_ceil(math::CUT_BLOCK), h.div_ceil(math::CUT_BLOCK), 1),
            ),
            None => ("mr reduce", reduce, (blocks.div_ceil(REDUCE_GROUP), 1, 1)),
        };
        let steps = [
            ("mr bilateral", bilateral, tiles),
            ("mr surfels", surfel, tiles),
            reduction,
            ("mr samples", samples, (slots.div_ceil(SAMPLES_GROUP), 1, 1)),
        ];
        for (label, pipeline, (x, y, z)) in steps {
            passes.compute(label, |pass| {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &self.group, &[]);
                pass.dispatch_workgroups(x, y, z);
            })?;
        }
        Ok(())
    }

    pub fn read_filtered(&self, ctx: &GpuContext) -> Result<Vec<f32>, GpuError> {
        crate::gpu::read_buffer(ctx, &self.depth_filtered)
    }

    pub fn read_surfels(&self, ctx: &GpuContext) -> Result<Vec<Surfel>, GpuError> {
        let raw: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.surfels)?;
        Ok(raw
            .iter()
            .map(|g| Surfel {
                val: g.to_val(),
                true_area: g.normal[3],
            })
            .collect())
    }

    /// Each candidate's cluster tile (`flux.w`).
    pub fn read_candidate_tiles(&self, ctx: &GpuContext) -> Result<Vec<u32>, GpuError> {
        let raw: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.external.candidates)?;
        Ok(raw.iter().map(GpuVal::cluster).collect())
    }

    /// The visibility rays' sample slots (`light::sensor::sample_slot`).
    pub fn read_samples(&self, ctx: &GpuContext) -> Result<Vec<Val>, GpuError> {
        let raw: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.samples)?;
        Ok(raw.iter().map(GpuVal::to_val).collect())
    }

    pub fn read_candidates(&self, ctx: &GpuContext) -> Result<Vec<Val>, GpuError> {
        let raw: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.external.candidates)?;
        Ok(raw.iter().map(GpuVal::to_val).collect())
    }
}

impl ValSource for DepthVals {
    fn external(&self) -> &ExternalVals {
        &self.external
    }

    fn record(&mut self, ctx: &GpuContext, passes: &mut Passes) -> Result<(), RenderError> {
        let pending = self
            .slot
            .lock()
            .map_err(|_| RenderError::Settings("the RGB-D frame slot was poisoned".into()))?
            .take();
        if let Some((frame, pose)) = pending {
            self.upload(ctx, &frame, pose)?;
        }
        match (self.has_frame, self.fusion.is_some()) {
            (true, false) => self.record_passes(passes)?,
            // `upload` wrote the fused VALs, their samples and the filtered depth.
            (true, true) => {}
            (false, _) => passes
                .encoder()
                .clear_buffer(&self.external.candidates, 0, None),
        }
        Ok(())
    }

    fn gpu_bytes(&self) -> u64 {
        self.bytes.0
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let p = self.kernel_params(Mat4::IDENTITY);
        serde_json::json!({
            "real_vals_grid": [p.grid_width, p.grid_height],
            "real_cut": self.settings.real_cut,
            "real_valid_pixels": self.last_valid_pixels,
            "real_scale": self.settings.real_scale,
            "accumulate": self.settings.accumulate,
            "fused_vals": self.last_fused,
        })
        .as_object()
        .cloned()
        .unwrap_or_default()
    }
}
