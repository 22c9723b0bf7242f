//! Every rendering method implements [`Method`]: scene, transforms and camera in; direct and
//! indirect radiance, per-pass GPU times and owned GPU bytes out. The CLI and (later) the
//! evaluation harness treat all methods alike through it.

use glam::Mat4;

use crate::gpu::GpuContext;
use crate::raster::{FrameOutput, Rasterizer, RenderError, RenderSettings};
use crate::scene::{CameraView, Scene};

pub trait Method {
    /// The method's name as given to `--method`.
    fn name(&self) -> &'static str;

    /// Renders one frame with the scene's nodes at `world_from_node`.
    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError>;

    /// Method-specific keys for the JSON report (empty by default).
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

/// Methods `valgi render --method` accepts, with a one-line description.
pub const METHODS: &[(&str, &str)] = &[(
    "direct",
    "direct light only: shadow-mapped punctual lights and emission (indirect is black)",
)];

/// Builds a method by name for one scene and output size.
pub fn create(
    name: &str,
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
) -> Result<Box<dyn Method>, RenderError> {
    match name {
        "direct" => Ok(Box::new(DirectMethod {
            raster: Rasterizer::new(ctx, scene, settings)?,
        })),
        other => Err(RenderError::Settings(format!(
            "unknown method '{other}' (available: {})",
            METHODS
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

/// Direct light only: the base every indirect method adds to.
pub struct DirectMethod {
    pub raster: Rasterizer,
}

impl Method for DirectMethod {
    fn name(&self) -> &'static str {
        "direct"
    }

    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError> {
        self.raster
            .render_direct(ctx, scene, world_from_node, camera)
    }
}
