//! The egui panel as a cached layer. egui lays the panel out every frame (that is how it
//! sees input), but its output only changes when the panel does. So the viewer tessellates
//! and draws that output into a layer of the window's size only when egui's shapes, its
//! textures, the window's size or its scale changed. Every frame composites the layer over
//! the views (`shaders/base/panel_layer.wgsl`), within the pixels the panel's primitives
//! cover. On a software adapter, drawing the panel was the largest part of the window's cost.
//! The readouts that change every frame (frame times, pass timings) are refreshed a few
//! times a second (`mod.rs`, `Readout`), so that an idle panel stays unchanged.

use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::GpuContext;

/// The layer at one window size.
struct Target {
    size: (u32, u32),
    view: wgpu::TextureView,
    group: wgpu::BindGroup,
}

pub struct PanelLayer {
    pipeline: wgpu::RenderPipeline,
    layout: GroupLayout,
    format: wgpu::TextureFormat,
    target: Option<Target>,
    /// What the layer holds: egui's shapes and scale when it was drawn.
    shapes: Vec<egui::epaint::ClippedShape>,
    pixels_per_point: f32,
    /// The pixels the drawn primitives cover (x, y, width, height); `None`: nothing drawn.
    covered: Option<[u32; 4]>,
    /// Frames the layer was drawn in, and frames that reused it.
    pub redraws: u64,
    pub reuses: u64,
}

impl PanelLayer {
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat) -> Self {
        let layout = GroupLayout::new(
            &ctx.device,
            "panel layer",
            wgpu::ShaderStages::FRAGMENT,
            &[Slot::Texture],
        );
        let pipeline = crate::raster::overlay_pipeline(
            &ctx.device,
            &crate::raster::OverlayPipeline {
                label: "panel layer",
                module: &ctx.shader("panel_layer.wgsl"),
                vertex_entry: "vs_main",
                groups: &[Some(&layout.layout)],
                format,
                write_mask: wgpu::ColorWrites::ALL,
                topology: wgpu::PrimitiveTopology::TriangleList,
                buffers: &[],
                blend: Some(wgpu::BlendState::PREMULTIPLIED_ALPHA_BLENDING),
            },
        );
        Self {
            pipeline,
            layout,
            format,
            target: None,
            shapes: Vec::new(),
            pixels_per_point: 0.0,
            covered: None,
            redraws: 0,
            reuses: 0,
        }
    }

    /// Whether egui's output `shapes` at this size and scale differ from what the layer holds
    /// (or egui changed a texture they may use).
    pub fn is_stale(
        &self,
        shapes: &[egui::epaint::ClippedShape],
        textures_changed: bool,
        size: (u32, u32),
        pixels_per_point: f32,
    ) -> bool {
        textures_changed
            || self.target.as_ref().is_none_or(|t| t.size != size)
            || self.pixels_per_point != pixels_per_point
            || self.shapes != shapes
    }

    /// Draws the tessellated panel `jobs` into the layer (onto transparent black) with
    /// `renderer`, whose buffers the caller has updated for them; `shapes` is what they were
    /// tessellated from.
    pub fn redraw(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        renderer: &egui_wgpu::Renderer,
        jobs: &[egui::ClippedPrimitive],
        screen: &egui_wgpu::ScreenDescriptor,
        shapes: Vec<egui::epaint::ClippedShape>,
    ) {
        let size = (screen.size_in_pixels[0], screen.size_in_pixels[1]);
        if self.target.as_ref().is_none_or(|t| t.size != size) {
            self.target = Some(self.make_target(ctx, size));
        }
        let Some(target) = &self.target else {
            return;
        };
        let Some(attachment) = crate::raster::cleared(&target.view) else {
            return;
        };
        let mut pass = super::colour_pass(encoder, "panel", attachment);
        renderer.render(&mut pass, jobs, screen);
        drop(pass);
        self.covered = covered_pixels(jobs, screen);
        self.shapes = shapes;
        self.pixels_per_point = screen.pixels_per_point;
        self.redraws += 1;
    }

    /// Notes a frame that composites the layer as it is.
    pub fn reuse(&mut self) {
        self.reuses += 1;
    }

    /// Composites the layer over what `pass` (the window's size) holds.
    pub fn composite(&self, pass: &mut wgpu::RenderPass<'_>) {
        let (Some(target), Some([x, y, w, h])) = (&self.target, self.covered) else {
            return;
        };
        pass.set_viewport(
            0.0,
            0.0,
            target.size.0 as f32,
            target.size.1 as f32,
            0.0,
            1.0,
        );
        pass.set_scissor_rect(x, y, w, h);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &target.group, &[]);
        pass.draw(0..3, 0..1);
        pass.set_scissor_rect(0, 0, target.size.0, target.size.1);
    }

    fn make_target(&self, ctx: &GpuContext, size: (u32, u32)) -> Target {
        let texture = ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("panel layer"),
            size: wgpu::Extent3d {
                width: size.0.max(1),
                height: size.1.max(1),
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: self.format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let view = texture.create_view(&Default::default());
        let group = self.layout.bind(&ctx.device, &[&view]);
        Target { size, view, group }
    }
}

/// The pixel rectangle (x, y, width, height) inside the screen that covers every primitive's
/// clip rectangle, or `None` when there is no primitive.
fn covered_pixels(
    jobs: &[egui::ClippedPrimitive],
    screen: &egui_wgpu::ScreenDescriptor,
) -> Option<[u32; 4]> {
    let [width, height] = screen.size_in_pixels;
    let scale = screen.pixels_per_point;
    let rect = jobs
        .iter()
        .map(|job| job.clip_rect)
        .reduce(|a, b| a.union(b))?;
    let x0 = (rect.min.x * scale).floor().clamp(0.0, width as f32) as u32;
    let y0 = (rect.min.y * scale).floor().clamp(0.0, height as f32) as u32;
    let x1 = (rect.max.x * scale).ceil().clamp(0.0, width as f32) as u32;
    let y1 = (rect.max.y * scale).ceil().clamp(0.0, height as f32) as u32;
    (x1 > x0 && y1 > y0).then_some([x0, y0, x1 - x0, y1 - y0])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(min: (f32, f32), max: (f32, f32)) -> egui::ClippedPrimitive {
        egui::ClippedPrimitive {
            clip_rect: egui::Rect::from_min_max(egui::pos2(min.0, min.1), egui::pos2(max.0, max.1)),
            primitive: egui::epaint::Primitive::Mesh(Default::default()),
        }
    }

    #[test]
    fn the_composite_covers_every_clip_rectangle_in_pixels_within_the_screen() {
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [800, 600],
            pixels_per_point: 2.0,
        };
        assert_eq!(covered_pixels(&[], &screen), None);
        // A panel on the right and a popup left of it, in points; the union in pixels.
        let jobs = [
            job((300.0, 0.0), (400.0, 300.0)),
            job((250.5, 40.0), (310.0, 80.2)),
        ];
        assert_eq!(covered_pixels(&jobs, &screen), Some([501, 0, 299, 600]));
        // Clip rectangles past the screen are cut to it.
        let off = [job((-10.0, -10.0), (1000.0, 1000.0))];
        assert_eq!(covered_pixels(&off, &screen), Some([0, 0, 800, 600]));
    }
}
