//! The viewer's debug views: a method's sparse points or VALs drawn as small splats over each
//! view's region (`vals_debug_splats.wgsl`), from the buffers the method lends through
//! [`Method::debug_points`] and [`Method::debug_vals`], with no CPU readback. Each splat is
//! depth-tested in its vertex stage against the view's G-buffer depth at its centre.

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::frame::{Method, View};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::GpuContext;

pub use super::state::DebugViews;

/// The shader of both views.
pub const SHADER: &str = "vals_debug_splats.wgsl";

/// Side of a splat, output pixels.
pub const SPLAT_PIXELS: f32 = 4.0;

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct DebugSplatParams {
    pub exposure_scale: f32,
    pub encode_srgb: u32,
    pub splat_pixels: f32,
    pub instance_count: u32,
    pub size: [u32; 2],
    pub pad0: [u32; 2],
}

/// Group 0 (both stages): the view's frame uniform, the splat parameters, the G-buffer depth.
const VIEW_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Uniform, Slot::DepthTexture];
/// Group 1 (`vs_point`): instances, points_model, points_meta, point_diffuse, point_extra.
const POINT_BINDINGS: &[Slot] = &[
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
];
/// Group 2 (`vs_val`): the VALs and their count.
const VAL_BINDINGS: &[Slot] = &[Slot::Storage, Slot::Storage];

/// One splat draw of one view: its pipeline, groups and instance count.
pub struct SplatDraw {
    points: bool,
    view_group: wgpu::BindGroup,
    source_group: wgpu::BindGroup,
    instances: u32,
}

/// The pipelines of the two views, made once per window.
pub struct DebugOverlay {
    view_layout: GroupLayout,
    point_layout: GroupLayout,
    val_layout: GroupLayout,
    point_pipeline: wgpu::RenderPipeline,
    val_pipeline: wgpu::RenderPipeline,
}

impl DebugOverlay {
    pub fn new(ctx: &GpuContext, format: wgpu::TextureFormat) -> Self {
        let device = &ctx.device;
        let both = wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT;
        let vertex = wgpu::ShaderStages::VERTEX;
        let view_layout = GroupLayout::new(device, "debug splats view", both, VIEW_BINDINGS);
        let point_layout = GroupLayout::new(device, "debug splats points", vertex, POINT_BINDINGS);
        let val_layout = GroupLayout::new(device, "debug splats vals", vertex, VAL_BINDINGS);
        let shader = ctx.shader(SHADER);
        let pipeline = |label, entry, groups: &[Option<&wgpu::BindGroupLayout>]| {
            crate::raster::unbuffered_pipeline(
                device,
                label,
                &shader,
                entry,
                groups,
                format,
                wgpu::ColorWrites::ALL,
            )
        };
        let point_pipeline = pipeline(
            "debug splats: points",
            "vs_point",
            &[Some(&view_layout.layout), Some(&point_layout.layout)],
        );
        // `vs_val` reads group 2 only; group 1 (the points) stays unbound.
        let val_pipeline = pipeline(
            "debug splats: vals",
            "vs_val",
            &[Some(&view_layout.layout), None, Some(&val_layout.layout)],
        );
        Self {
            view_layout,
            point_layout,
            val_layout,
            point_pipeline,
            val_pipeline,
        }
    }

    /// This frame's draws of `view` for the views that are on and that the method has.
    /// The groups and the 32-byte parameter blocks are made per frame, only while a debug
    /// view is on.
    pub fn prepare(
        &self,
        ctx: &GpuContext,
        method: &dyn Method,
        view: &View,
        on: DebugViews,
        exposure_scale: f32,
        encode_srgb: bool,
    ) -> Vec<SplatDraw> {
        let device = &ctx.device;
        let view_group = |instances: u32| {
            let params = DebugSplatParams {
                exposure_scale,
                encode_srgb: encode_srgb as u32,
                splat_pixels: SPLAT_PIXELS,
                instance_count: instances,
                size: [view.width, view.height],
                pad0: [0; 2],
            };
            let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("debug splat params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
            self.view_layout
                .bind(device, &[&view.frame_buffer, &buffer, &view.targets.depth])
        };
        let mut draws = vec![];
        if on.points {
            if let Some(p) = method.debug_points().filter(|p| p.count > 0) {
                draws.push(SplatDraw {
                    points: true,
                    view_group: view_group(p.count),
                    source_group: self.point_layout.bind(
                        device,
                        &[
                            p.instances,
                            p.points_model,
                            p.points_meta,
                            p.point_diffuse,
                            p.point_extra,
                        ],
                    ),
                    instances: p.count,
                });
            }
        }
        if on.vals {
            if let Some(v) = method.debug_vals().filter(|v| v.capacity > 0) {
                draws.push(SplatDraw {
                    points: false,
                    view_group: view_group(v.capacity),
                    source_group: self.val_layout.bind(device, &[v.vals, v.val_count]),
                    instances: v.capacity,
                });
            }
        }
        draws
    }

    /// Records `draws` into `pass`, whose viewport is the view's region.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'static>, draws: &[SplatDraw]) {
        for d in draws {
            if d.points {
                pass.set_pipeline(&self.point_pipeline);
                pass.set_bind_group(1, &d.source_group, &[]);
            } else {
                pass.set_pipeline(&self.val_pipeline);
                pass.set_bind_group(2, &d.source_group, &[]);
            }
            pass.set_bind_group(0, &d.view_group, &[]);
            pass.draw(0..6, 0..d.instances);
        }
    }
}
