//! `--method direct`: shadow-mapped punctual lights and emission, no indirect light. The base
//! every indirect method adds to, and the smallest example of a registered method.

use crate::frame::{FrameInput, Method, View, ViewResult};
use crate::gpu::{GpuContext, Passes};
use crate::method::{Entry, MethodOptions};
use crate::raster::{Rasterizer, RenderError, RenderSettings};
use crate::scene::Scene;

pub static ENTRY: Entry = Entry {
    name: "direct",
    help: "direct light only: shadow-mapped punctual lights and emission (indirect is black)",
    options: &[],
    create,
};

fn create(
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    _options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(DirectMethod {
        raster: Rasterizer::new(ctx, scene, settings)?,
    }))
}

/// Direct light only.
pub struct DirectMethod {
    pub raster: Rasterizer,
}

impl Method for DirectMethod {
    fn name(&self) -> &'static str {
        "direct"
    }

    fn settings(&self) -> RenderSettings {
        self.raster.settings
    }

    fn update(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        _views: &[&View],
        passes: &mut Passes,
    ) -> Result<(), RenderError> {
        Ok(self
            .raster
            .update_and_record(ctx, frame.scene, frame.world_from_node, passes)?)
    }

    fn record_view(
        &mut self,
        ctx: &GpuContext,
        _frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError> {
        self.raster.record_view_base(ctx, view, passes)?;
        Ok(ViewResult::Direct)
    }

    fn gpu_bytes(&self) -> u64 {
        self.raster.gpu_bytes()
    }
}
