//! The atlas as a layer on top of another method's indirect light (`sparse+atlas`: bounce 1
//! from the VALs, bounces 2..B from an atlas baked with `--from-bounce 2`). The underlying
//! method draws its bounce into a target of the layer's; the pass "atlas add" then writes
//! `radiance_indirect = that bounce + ρ_d/π·E_atlas`, so no bounce is counted twice as long as
//! the atlas starts at bounce 2 (see `src/atlas/README.md`).

use super::AtlasLayer;
use crate::frame::{FrameInput, IndirectLayer, View, ViewCache};
use crate::gpu::bindings::GroupLayout;
use crate::gpu::{GpuBytes, GpuContext, GpuError, Passes};
use crate::raster::{RenderError, RADIANCE_FORMAT};

/// The atlas on top of another method's bounce: an [`IndirectLayer`].
pub struct AtlasOnVals {
    pub layer: AtlasLayer,
    name: &'static str,
    add_pipeline: wgpu::ComputePipeline,
    add_bgl: GroupLayout,
    /// Per view: the texture the underlying method draws into, and its bytes.
    under: ViewCache<(wgpu::TextureView, GpuBytes)>,
}

impl AtlasOnVals {
    /// `name` is the composed method's name.
    pub fn new(ctx: &GpuContext, layer: AtlasLayer, name: &'static str) -> Self {
        let device = &ctx.device;
        let cs = wgpu::ShaderStages::COMPUTE;
        let add_bgl = GroupLayout::new(device, "atlas add", cs, super::ADD_BINDINGS);
        let add_pipeline = crate::gpu::compute_pipeline_groups(
            device,
            "atlas add",
            &ctx.shader("atlas_apply.wgsl"),
            &[&add_bgl.layout],
            "cs_add",
            &[],
        );
        Self {
            layer,
            name,
            add_pipeline,
            add_bgl,
            under: ViewCache::default(),
        }
    }
}

impl IndirectLayer for AtlasOnVals {
    fn method_name(&self) -> &'static str {
        self.name
    }

    fn set_debug_atlas(&mut self, on: bool) -> bool {
        self.layer.debug = on;
        true
    }

    fn update(&mut self, ctx: &GpuContext, frame: &FrameInput, views: &[&View]) {
        self.layer.update(ctx, frame.world_from_node, views);
        self.under.retain(views);
    }

    fn record_view(
        &mut self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
        draw_under: &mut dyn FnMut(&mut Passes, &wgpu::TextureView) -> Result<(), GpuError>,
    ) -> Result<(), RenderError> {
        let (under, _) = self.under.get_or_try_insert(view, || {
            let mut bytes = GpuBytes::default();
            let texture = bytes.texture_2d(
                &ctx.device,
                "vals indirect",
                view.render_size(),
                RADIANCE_FORMAT,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            );
            Ok((texture.create_view(&Default::default()), bytes))
        })?;
        draw_under(passes, under)?;
        let state = self.layer.record_lookup(ctx, view, passes)?;
        let group = self.add_bgl.bind(
            &ctx.device,
            &[
                &state.apply_buffer,
                &state.irradiance,
                &view.targets.diffuse,
                &view.targets.radiance_indirect,
                under,
            ],
        );
        view.record_per_pixel(passes, "atlas add", &self.add_pipeline, &group)?;
        Ok(())
    }

    fn gpu_bytes(&self) -> u64 {
        self.layer.gpu_bytes() + self.under.values().map(|(_, b)| b.0).sum::<u64>()
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
