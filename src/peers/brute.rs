//! Brute-force VALs: every pixel sums every VAL from the same RSMs with the same disc
//! irradiance and BRDF as the sparse method, without interpolation or occlusion
//! (`shaders/brute_vals.wgsl`; CPU twin [`crate::vals::math::brute_force`]). Its image is what
//! the sparse method would give with a receiver point at every pixel, so the difference between
//! the two is the sparse method's interpolation error alone.

use glam::Mat4;

use crate::gpu::{GpuContext, Passes};
use crate::method::{Method, MethodOptions};
use crate::raster::{
    buffer_binding, compute_pipeline, depth_texture_entry, storage_entry, storage_texture_entry,
    texture_entry, uniform_entry, view_binding, FrameOutput, Rasterizer, RenderError,
    RenderSettings,
};
use crate::scene::{CameraView, Scene};
use crate::vals::rsm::Rsm;
use crate::vals::sparse::{SparseParams, FLAG_GLOSSY};

pub struct BruteMethod {
    pub raster: Rasterizer,
    pub rsm: Rsm,
    glossy: bool,
    tile: u32,
    params_buffer: wgpu::Buffer,
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    vals: u32,
}

impl BruteMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        options: &MethodOptions,
    ) -> Result<Self, RenderError> {
        let rsm_resolution: u32 = options.get("rsm", 128)?;
        let glossy = options.choice("glossy", &["on", "off"])? == "on";
        let tile: u32 = options.get("tile", 128)?;
        if !(1..=256).contains(&tile) {
            return Err(RenderError::Settings(format!(
                "--tile {tile}: must be 1..=256"
            )));
        }
        let raster = Rasterizer::new(ctx, scene, render)?;
        let rsm = Rsm::new(ctx, scene, &raster.scene_gpu, rsm_resolution)?;
        let device = &ctx.device;
        let params_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brute params"),
            size: std::mem::size_of::<SparseParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let cs = wgpu::ShaderStages::COMPUTE;
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("brute"),
            entries: &[
                uniform_entry(0, cs),
                uniform_entry(1, cs),
                storage_entry(2, cs),
                storage_entry(3, cs),
                depth_texture_entry(4, cs),
                texture_entry(5, cs),
                texture_entry(6, cs),
                texture_entry(7, cs),
                storage_texture_entry(8, cs),
            ],
        });
        let t = &raster.targets;
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("brute"),
            layout: &layout,
            entries: &[
                buffer_binding(0, &raster.frame_buffer),
                buffer_binding(1, &params_buffer),
                buffer_binding(2, &rsm.vals_buffer),
                buffer_binding(3, &rsm.val_count_buffer),
                view_binding(4, &t.depth),
                view_binding(5, &t.normal),
                view_binding(6, &t.diffuse),
                view_binding(7, &t.specular),
                view_binding(8, &t.radiance_indirect),
            ],
        });
        let pipeline = compute_pipeline(device, "brute", &ctx.shader("brute_vals.wgsl"), &layout);
        Ok(Self {
            raster,
            rsm,
            glossy,
            tile,
            params_buffer,
            pipeline,
            group,
            vals: 0,
        })
    }
}

impl Method for BruteMethod {
    fn name(&self) -> &'static str {
        "brute"
    }

    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError> {
        self.raster.prepare(ctx, scene, world_from_node, camera);
        self.rsm.prepare(ctx, scene, world_from_node);
        let params = SparseParams {
            eye: camera.position().extend(1.0).to_array(),
            flags: if self.glossy { FLAG_GLOSSY } else { 0 },
            tile: self.tile,
            ..Default::default()
        };
        ctx.queue
            .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
        let mut passes = Passes::new(ctx, self.rsm.layer_count + 16);
        self.raster.record_base(&mut passes)?;
        self.rsm.record(&mut passes, &self.raster.scene_gpu)?;
        self.raster
            .record_per_pixel(&mut passes, "brute", &self.pipeline, &self.group)?;
        let frame = self
            .raster
            .finish_frame(ctx, passes, true, self.rsm.bytes.0)?;
        self.vals = self.rsm.read_count(ctx)?;
        Ok(frame)
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        map.insert("vals".into(), self.vals.into());
        map.insert("rsm".into(), self.rsm.resolution.into());
        map.insert(
            "glossy".into(),
            if self.glossy { "on" } else { "off" }.into(),
        );
        map
    }
}
