//! `sparse+atlas`: direct light + bounce 1 from the VALs (the sparse method, dynamic) + the
//! bounces 2..B of an atlas baked with `--from-bounce 2` (static). The sparse apply pass draws
//! its bounce into a target of its own; the pass "atlas add" then writes
//! `radiance_indirect = VAL bounce + ρ_d/π·E_atlas`, so no bounce is counted twice as long as
//! the atlas starts at bounce 2 (see `src/atlas/README.md`).

use std::path::Path;

use glam::Mat4;

use super::{load_atlas, AtlasLayer};
use crate::gpu::{GpuContext, GpuError, Passes};
use crate::method::{Method, MethodOptions};
use crate::raster::{
    buffer_binding, storage_texture_entry, texture_entry, uniform_entry, view_binding, RenderError,
    RenderSettings, RADIANCE_FORMAT,
};
use crate::scene::{CameraView, Scene};
use crate::vals::{IndirectLayer, SparseMethod, SparseSettings};

/// The atlas on top of the VAL bounce: an [`IndirectLayer`] of the sparse method.
pub struct AtlasOnVals {
    pub layer: AtlasLayer,
    vals_view: wgpu::TextureView,
    add_pipeline: wgpu::ComputePipeline,
    add_group: wgpu::BindGroup,
    vals_bytes: u64,
}

impl AtlasOnVals {
    pub fn new(
        ctx: &GpuContext,
        sparse: &SparseMethod,
        layer: AtlasLayer,
    ) -> Result<Self, RenderError> {
        let device = &ctx.device;
        let targets = &sparse.raster.targets;
        let (w, h) = (targets.render_width, targets.render_height);
        let vals_texture = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("vals indirect"),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: RADIANCE_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let vals_bytes = w as u64 * h as u64 * 16;
        let vals_view = vals_texture.create_view(&Default::default());
        let cs = wgpu::ShaderStages::COMPUTE;
        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("atlas add"),
            entries: &[
                uniform_entry(0, cs),
                texture_entry(1, cs),
                texture_entry(2, cs),
                storage_texture_entry(3, cs),
                texture_entry(4, cs),
            ],
        });
        let add_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("atlas add"),
            layout: &bgl,
            entries: &[
                buffer_binding(0, &layer.apply_buffer),
                view_binding(1, &layer.irradiance),
                view_binding(2, &targets.diffuse),
                view_binding(3, &targets.radiance_indirect),
                view_binding(4, &vals_view),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("atlas add"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let add_pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("atlas add"),
            layout: Some(&pipeline_layout),
            module: &ctx.shader("atlas_apply.wgsl"),
            entry_point: Some("cs_add"),
            compilation_options: Default::default(),
            cache: None,
        });
        Ok(Self {
            layer,
            vals_view,
            add_pipeline,
            add_group,
            vals_bytes,
        })
    }
}

impl IndirectLayer for AtlasOnVals {
    fn method_name(&self) -> &'static str {
        "sparse+atlas"
    }

    fn prepare(&self, ctx: &GpuContext, world_from_node: &[Mat4], camera: &CameraView) {
        self.layer.prepare(ctx, world_from_node, camera);
    }

    fn vals_target(&self) -> &wgpu::TextureView {
        &self.vals_view
    }

    fn record(&self, passes: &mut Passes) -> Result<(), GpuError> {
        self.layer.record_lookup(passes)?;
        let [w, h] = self.layer.render_size;
        passes.compute("atlas add", |pass| {
            pass.set_pipeline(&self.add_pipeline);
            pass.set_bind_group(0, &self.add_group, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        })
    }

    fn gpu_bytes(&self) -> u64 {
        self.layer.bytes.0 + self.vals_bytes
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        map.insert(
            "atlas_missing_texels".into(),
            serde_json::json!(self.layer.missing_texels),
        );
        map
    }
}

/// `--method sparse+atlas --atlas FILE` (every sparse option, plus `atlas`). The atlas should
/// be baked with `--from-bounce 2`: bounce 1 comes from the VALs.
pub fn create_sparse_atlas(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(sparse_atlas(ctx, scene, render, options)?))
}

/// [`create_sparse_atlas`] as the concrete sparse method with its atlas layer (for tests).
pub fn sparse_atlas(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
) -> Result<SparseMethod, RenderError> {
    let path: String = options.get("atlas", String::new())?;
    if path.is_empty() {
        return Err(RenderError::Settings(
            "method 'sparse+atlas' needs --atlas FILE.exr (from `valgi bake --from-bounce 2`)"
                .into(),
        ));
    }
    let settings = SparseSettings::from_options(options)?;
    let atlas = load_atlas(Path::new(&path))?;
    let mut sparse = SparseMethod::new(ctx, scene, render, settings)?;
    let layer = AtlasLayer::new(ctx, scene, &sparse.raster, &atlas)?;
    let on_vals = AtlasOnVals::new(ctx, &sparse, layer)?;
    sparse.layer = Some(Box::new(on_vals));
    Ok(sparse)
}
