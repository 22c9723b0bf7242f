//! The viewer's debug views: a method's sparse points or VALs drawn as small splats over each
//! view's region (`vals_debug_splats.wgsl`), from the buffers the method lends through
//! [`Method::debug_points`] and [`Method::debug_vals`], with no CPU readback (each splat is
//! depth-tested in its vertex stage against the view's G-buffer depth at its centre); the
//! links of the vertex under the cursor as lines (`debug_lines.wgsl`, from
//! [`Method::debug_pick`]); and the occluder discs and light spheres of the point under the
//! cursor (`vals_debug_occluders.wgsl`, from the point buffers).

use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::frame::{DebugPick, Method, View};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::GpuContext;

pub use super::state::DebugViews;

/// The shader of the point and VAL splats.
pub const SHADER: &str = "vals_debug_splats.wgsl";
/// The links view's shader.
pub const LINES_SHADER: &str = "debug_lines.wgsl";
/// The occluder view's shader.
pub const OCCLUDERS_SHADER: &str = "vals_debug_occluders.wgsl";

/// Segments of each circle the occluder view draws.
pub const CIRCLE_SEGMENTS: u32 = 32;

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

/// `DebugOccluderParams` in `vals_debug_occluders.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct DebugOccluderParams {
    pub point: u32,
    pub point_count: u32,
    pub segments: u32,
    pub pad0: u32,
}

/// One vertex of the links view's line list (`LineVertex` in `debug_lines.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct LineVertex {
    pub position: [f32; 3],
    pub colour: [f32; 3],
}

/// The links of `pick` as a line list: a segment from the vertex to each linked point, whose
/// brightness is the link's share of the largest weight (a zero-weight link is drawn dim
/// blue: kept by the kd-tree, rejected by the normal test), and a small cross on the vertex.
pub fn link_lines(pick: &DebugPick) -> Vec<LineVertex> {
    let v = pick.vertex;
    let most = pick.links.iter().map(|l| l.1).fold(0.0f32, f32::max);
    let mut lines = vec![];
    for &(point, weight) in &pick.links {
        let colour = if weight > 0.0 && most > 0.0 {
            let s = 0.35 + 0.65 * weight / most;
            [s, s, 0.2 * s]
        } else {
            [0.15, 0.25, 0.8]
        };
        lines.push(LineVertex {
            position: v.to_array(),
            colour,
        });
        lines.push(LineVertex {
            position: point.to_array(),
            colour,
        });
    }
    // The cross: a tenth of the longest link per arm.
    let arm = 0.1
        * pick
            .links
            .iter()
            .map(|l| (l.0 - v).length())
            .fold(0.0f32, f32::max);
    for axis in [glam::Vec3::X, glam::Vec3::Y, glam::Vec3::Z] {
        for end in [v - arm * axis, v + arm * axis] {
            lines.push(LineVertex {
                position: end.to_array(),
                colour: [1.0, 0.2, 1.0],
            });
        }
    }
    lines
}

/// Group 0 (both stages): the view's frame uniform, the splat parameters, the G-buffer depth.
const VIEW_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Uniform, Slot::DepthTexture];
/// Group 1 (`vs_point`, and the occluder view): instances, points_model, points_meta,
/// point_diffuse, point_extra, point_glossy (the occluder view's only).
const POINT_BINDINGS: &[Slot] = &[
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
];
/// Group 0 of the occluder view: the view's frame uniform, its parameters.
const OCCLUDER_VIEW_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Uniform];
/// Group 0 of the links view: the view's frame uniform.
const LINE_VIEW_BINDINGS: &[Slot] = &[Slot::Uniform];
/// Group 2 (`vs_val`): the VALs and their count.
const VAL_BINDINGS: &[Slot] = &[Slot::Storage, Slot::Storage];

/// One debug draw of one view: its pipeline's kind, groups and counts.
pub enum DebugDraw {
    Splats {
        points: bool,
        view_group: wgpu::BindGroup,
        source_group: wgpu::BindGroup,
        instances: u32,
    },
    Lines {
        view_group: wgpu::BindGroup,
        vertices: wgpu::Buffer,
        count: u32,
    },
    Occluders {
        view_group: wgpu::BindGroup,
        point_group: wgpu::BindGroup,
        point_count: u32,
    },
}

/// The pipelines of the debug views, made once per window.
pub struct DebugOverlay {
    view_layout: GroupLayout,
    point_layout: GroupLayout,
    val_layout: GroupLayout,
    occluder_view_layout: GroupLayout,
    line_view_layout: GroupLayout,
    point_pipeline: wgpu::RenderPipeline,
    val_pipeline: wgpu::RenderPipeline,
    line_pipeline: wgpu::RenderPipeline,
    sphere_pipeline: wgpu::RenderPipeline,
    disc_pipeline: wgpu::RenderPipeline,
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
        let vertex_only = |label, slots| GroupLayout::new(device, label, vertex, slots);
        let occluder_view_layout = vertex_only("debug occluders view", OCCLUDER_VIEW_BINDINGS);
        let line_view_layout = vertex_only("debug lines view", LINE_VIEW_BINDINGS);
        let lines = |label, module: &wgpu::ShaderModule, entry, groups: &[_], buffers: &[_]| {
            crate::raster::overlay_pipeline(
                device,
                &crate::raster::OverlayPipeline {
                    label,
                    module,
                    vertex_entry: entry,
                    groups,
                    format,
                    write_mask: wgpu::ColorWrites::ALL,
                    topology: wgpu::PrimitiveTopology::LineList,
                    buffers,
                    blend: None,
                },
            )
        };
        let line_shader = ctx.shader(LINES_SHADER);
        let line_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
        let line_pipeline = lines(
            "debug lines",
            &line_shader,
            "vs_main",
            &[Some(&line_view_layout.layout)],
            &[Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<LineVertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &line_attributes,
            })],
        );
        let occluder_shader = ctx.shader(OCCLUDERS_SHADER);
        let occluder_groups = [
            Some(&occluder_view_layout.layout),
            Some(&point_layout.layout),
        ];
        let sphere_pipeline = lines(
            "debug occluders: spheres",
            &occluder_shader,
            "vs_sphere",
            &occluder_groups,
            &[],
        );
        let disc_pipeline = lines(
            "debug occluders: discs",
            &occluder_shader,
            "vs_disc",
            &occluder_groups,
            &[],
        );
        Self {
            view_layout,
            point_layout,
            val_layout,
            occluder_view_layout,
            line_view_layout,
            point_pipeline,
            val_pipeline,
            line_pipeline,
            sphere_pipeline,
            disc_pipeline,
        }
    }

    /// This frame's draws, per view of `views`, for the debug views that are on and that the
    /// method has (`pick`: what lies under the cursor, for the links and occluder views). The
    /// groups and the small parameter blocks are made per frame, only while a debug view is
    /// on; what no view changes (the point group, the occluder parameters, the link lines)
    /// once for all views.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        &self,
        ctx: &GpuContext,
        method: &dyn Method,
        views: &[View],
        on: DebugViews,
        pick: Option<&DebugPick>,
        exposure_scale: f32,
        encode_srgb: bool,
    ) -> Vec<Vec<DebugDraw>> {
        let device = &ctx.device;
        let uniform = |label, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let points = method.debug_points().filter(|p| p.count > 0);
        let point_group = points
            .as_ref()
            .filter(|_| on.points || on.occluders)
            .map(|p| {
                self.point_layout.bind(
                    device,
                    &[
                        p.instances,
                        p.points_model,
                        p.points_meta,
                        p.point_diffuse,
                        p.point_extra,
                        p.point_glossy,
                    ],
                )
            });
        let occluder_params = match (&points, pick.and_then(|k| k.point)) {
            (Some(p), Some((point, _))) if on.occluders => {
                let params = DebugOccluderParams {
                    point,
                    point_count: p.count,
                    segments: CIRCLE_SEGMENTS,
                    pad0: 0,
                };
                Some((
                    uniform("debug occluder params", bytemuck::bytes_of(&params)),
                    p.count,
                ))
            }
            _ => None,
        };
        let link_vertices = pick
            .filter(|k| on.links && !k.links.is_empty())
            .map(|pick| {
                let lines = link_lines(pick);
                let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("debug link lines"),
                    contents: bytemuck::cast_slice(&lines),
                    usage: wgpu::BufferUsages::VERTEX,
                });
                (buffer, lines.len() as u32)
            });
        let vals = method.debug_vals().filter(|v| on.vals && v.capacity > 0);
        let val_group = vals
            .as_ref()
            .map(|v| self.val_layout.bind(device, &[v.vals, v.val_count]));
        views
            .iter()
            .map(|view| {
                let splat_group = |instances: u32| {
                    let params = DebugSplatParams {
                        exposure_scale,
                        encode_srgb: encode_srgb as u32,
                        splat_pixels: SPLAT_PIXELS,
                        instance_count: instances,
                        size: [view.width, view.height],
                        pad0: [0; 2],
                    };
                    let buffer = uniform("debug splat params", bytemuck::bytes_of(&params));
                    self.view_layout
                        .bind(device, &[&view.frame_buffer, &buffer, &view.targets.depth])
                };
                let mut draws = vec![];
                if let (true, Some(p), Some(group)) = (on.points, &points, &point_group) {
                    draws.push(DebugDraw::Splats {
                        points: true,
                        view_group: splat_group(p.count),
                        source_group: group.clone(),
                        instances: p.count,
                    });
                }
                if let (Some((params, point_count)), Some(group)) = (&occluder_params, &point_group)
                {
                    draws.push(DebugDraw::Occluders {
                        view_group: self
                            .occluder_view_layout
                            .bind(device, &[&view.frame_buffer, params]),
                        point_group: group.clone(),
                        point_count: *point_count,
                    });
                }
                if let Some((vertices, count)) = &link_vertices {
                    draws.push(DebugDraw::Lines {
                        view_group: self.line_view_layout.bind(device, &[&view.frame_buffer]),
                        vertices: vertices.clone(),
                        count: *count,
                    });
                }
                if let (Some(v), Some(group)) = (&vals, &val_group) {
                    draws.push(DebugDraw::Splats {
                        points: false,
                        view_group: splat_group(v.capacity),
                        source_group: group.clone(),
                        instances: v.capacity,
                    });
                }
                draws
            })
            .collect()
    }

    /// Records `draws` into `pass`, whose viewport is the view's region.
    pub fn draw(&self, pass: &mut wgpu::RenderPass<'static>, draws: &[DebugDraw]) {
        for d in draws {
            match d {
                DebugDraw::Splats {
                    points,
                    view_group,
                    source_group,
                    instances,
                } => {
                    if *points {
                        pass.set_pipeline(&self.point_pipeline);
                        pass.set_bind_group(1, source_group, &[]);
                    } else {
                        pass.set_pipeline(&self.val_pipeline);
                        pass.set_bind_group(2, source_group, &[]);
                    }
                    pass.set_bind_group(0, view_group, &[]);
                    pass.draw(0..6, 0..*instances);
                }
                DebugDraw::Lines {
                    view_group,
                    vertices,
                    count,
                } => {
                    pass.set_pipeline(&self.line_pipeline);
                    pass.set_bind_group(0, view_group, &[]);
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    pass.draw(0..*count, 0..1);
                }
                DebugDraw::Occluders {
                    view_group,
                    point_group,
                    point_count,
                } => {
                    let vertices = 0..2 * CIRCLE_SEGMENTS;
                    pass.set_bind_group(0, view_group, &[]);
                    pass.set_bind_group(1, point_group, &[]);
                    pass.set_pipeline(&self.disc_pipeline);
                    pass.draw(vertices.clone(), 0..*point_count);
                    pass.set_pipeline(&self.sphere_pipeline);
                    pass.draw(vertices, 0..3);
                }
            }
        }
    }
}
