//! A frame is one view-free *update* (lights, shadow maps, RSM → VALs, the lighting solution)
//! followed by one *record* per [`View`]. A view owns its camera, its render targets and its
//! frame uniform; methods never see a window or a file. [`record_frame`] runs a method over a
//! list of views in one submission; [`View::read`] reads a view back only when a caller wants
//! the pixels (files, tests), so a window or a second view costs no CPU readback.

pub mod memory;
pub mod rig;

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::{Mat4, Vec3};

use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{FrameTimings, GpuBytes, GpuContext, GpuError, Passes, Scope};
use crate::image_io::Image;
use crate::raster::types::{FrameUniforms, ResolveParams};
use crate::raster::{
    compute_pipeline, RenderError, DEPTH_FORMAT, GBUFFER_MATERIAL_FORMAT, GBUFFER_NORMAL_FORMAT,
    RADIANCE_FORMAT,
};
use crate::scene::{CameraView, Scene};
pub use rig::ViewRig;

/// Render targets of one view at the supersampled resolution, plus the resolved outputs.
pub struct FrameTargets {
    pub render_width: u32,
    pub render_height: u32,
    pub depth: wgpu::TextureView,
    pub normal: wgpu::TextureView,
    pub diffuse: wgpu::TextureView,
    pub specular: wgpu::TextureView,
    pub emissive: wgpu::TextureView,
    pub radiance_direct: wgpu::TextureView,
    /// Indirect methods write their radiance here (render resolution).
    pub radiance_indirect: wgpu::TextureView,
    pub output_direct: wgpu::Texture,
    pub output_indirect: wgpu::Texture,
    pub bytes: GpuBytes,
}

impl FrameTargets {
    /// Bytes [`FrameTargets::new`] allocates: depth and four G-buffer layers, two radiance
    /// targets at the render size, two outputs at the output size.
    pub fn bytes(width: u32, height: u32, ssaa: u32) -> u64 {
        let texel = crate::gpu::resources::block_bytes;
        let render = width as u64 * ssaa as u64 * height as u64 * ssaa as u64;
        let output = width as u64 * height as u64;
        render
            * (texel(DEPTH_FORMAT)
                + texel(GBUFFER_NORMAL_FORMAT)
                + 3 * texel(GBUFFER_MATERIAL_FORMAT)
                + 2 * texel(RADIANCE_FORMAT))
            + output * 2 * texel(RADIANCE_FORMAT)
    }

    fn new(device: &wgpu::Device, width: u32, height: u32, ssaa: u32) -> Self {
        let mut bytes = GpuBytes::default();
        let (rw, rh) = (width * ssaa, height * ssaa);
        let mut target = |label: &str, w: u32, h: u32, format, usage| {
            bytes.texture_2d(device, label, (w, h), format, usage)
        };
        let attachment =
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let storage = wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING;
        // COPY_DST: CPU methods (the path tracer) write their image straight into the outputs.
        let output = wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST
            | wgpu::TextureUsages::TEXTURE_BINDING;
        let view = |t: wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        let gbuffer =
            |target: &mut dyn FnMut(&str, u32, u32, _, _) -> wgpu::Texture, label: &str, format| {
                view(target(label, rw, rh, format, attachment))
            };
        Self {
            render_width: rw,
            render_height: rh,
            depth: gbuffer(&mut target, "gbuffer depth", DEPTH_FORMAT),
            normal: gbuffer(&mut target, "gbuffer normal", GBUFFER_NORMAL_FORMAT),
            diffuse: gbuffer(&mut target, "gbuffer diffuse", GBUFFER_MATERIAL_FORMAT),
            specular: gbuffer(&mut target, "gbuffer specular", GBUFFER_MATERIAL_FORMAT),
            emissive: gbuffer(&mut target, "gbuffer emissive", GBUFFER_MATERIAL_FORMAT),
            radiance_direct: view(target("radiance direct", rw, rh, RADIANCE_FORMAT, storage)),
            // Compute passes (brute force) store into it; raster passes (sparse apply) draw.
            radiance_indirect: view(target(
                "radiance indirect",
                rw,
                rh,
                RADIANCE_FORMAT,
                storage | wgpu::TextureUsages::RENDER_ATTACHMENT,
            )),
            output_direct: target("output direct", width, height, RADIANCE_FORMAT, output),
            output_indirect: target("output indirect", width, height, RADIANCE_FORMAT, output),
            bytes,
        }
    }
}

static NEXT_VIEW_ID: AtomicU64 = AtomicU64::new(1);

/// Side of the square workgroup of every per-pixel compute pass (`@workgroup_size(8, 8, 1)`
/// in their WGSL; `tests/shader_layout.rs` checks each entry point against it with naga).
pub const PIXEL_TILE: u32 = 8;

/// The SSAA resolve kernel, one per device (see [`GpuContext::shared`]): views differ only in
/// the resources they bind.
pub struct ResolveKernel {
    layout: GroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl ResolveKernel {
    fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let layout = GroupLayout::new(
            device,
            "resolve",
            wgpu::ShaderStages::COMPUTE,
            RESOLVE_BINDINGS,
        );
        let pipeline = ctx.scoped(
            "the resolve pipeline",
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                compute_pipeline(
                    device,
                    "resolve",
                    &ctx.shader("resolve.wgsl"),
                    &layout.layout,
                )
            },
        )?;
        Ok(Self { layout, pipeline })
    }
}

impl View {
    /// Whether this view and `other` record their resolve with the same pipeline (they do
    /// on one device: it is compiled once).
    pub fn shares_resolve_with(&self, other: &View) -> bool {
        std::sync::Arc::ptr_eq(&self.resolve, &other.resolve)
    }
}

/// `resolve.wgsl`: its parameters, the SSAA radiance (direct, indirect) it box-filters, and the
/// output-size targets it writes.
const RESOLVE_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
    Slot::StorageTexture(RADIANCE_FORMAT),
];

/// One camera's share of a frame: its camera, targets and frame uniform.
pub struct View {
    id: u64,
    /// `main` for a mono render; `left`/`right`, a CAVE wall's name, or `grid<i>`.
    pub name: String,
    pub camera: CameraView,
    pub width: u32,
    pub height: u32,
    pub ssaa: u32,
    pub targets: FrameTargets,
    /// The `Frame` uniform (camera, render size) every per-view pass binds.
    pub frame_buffer: wgpu::Buffer,
    resolve_params: wgpu::Buffer,
    /// The device's one resolve pipeline and layout.
    resolve: std::sync::Arc<ResolveKernel>,
    resolve_group: wgpu::BindGroup,
    bytes: GpuBytes,
}

impl View {
    pub fn new(
        ctx: &GpuContext,
        name: &str,
        camera: CameraView,
        (width, height): (u32, u32),
        ssaa: u32,
    ) -> Result<Self, RenderError> {
        check_size(ctx, width, height, ssaa)?;
        let device = &ctx.device;
        let (rw, rh) = (width * ssaa, height * ssaa);
        let targets = ctx.scoped(
            &format!("the render targets of view '{name}' ({rw}×{rh} after {ssaa}×{ssaa} SSAA)"),
            Some(FrameTargets::bytes(width, height, ssaa)),
            "Lower --width/--height or --ssaa",
            || FrameTargets::new(device, width, height, ssaa),
        )?;
        let mut bytes = GpuBytes::default();
        let frame_buffer = bytes.uniform::<FrameUniforms>(device, "frame uniforms");
        let resolve_params = bytes.uniform::<ResolveParams>(device, "resolve params");
        let resolve = ctx.shared(|| ResolveKernel::new(ctx))?;
        let out_direct = targets.output_direct.create_view(&Default::default());
        let out_indirect = targets.output_indirect.create_view(&Default::default());
        let resolve_group = resolve.layout.bind(
            device,
            &[
                &resolve_params,
                &targets.radiance_direct,
                &targets.radiance_indirect,
                &out_direct,
                &out_indirect,
            ],
        );
        Ok(Self {
            id: NEXT_VIEW_ID.fetch_add(1, Ordering::Relaxed),
            name: name.to_string(),
            camera,
            width,
            height,
            ssaa,
            targets,
            frame_buffer,
            resolve_params,
            resolve,
            resolve_group,
            bytes,
        })
    }

    /// Unique for the life of the process: a view made anew (a resize) gets a new id, so
    /// per-view state a method caches can never outlive the targets it binds.
    pub fn id(&self) -> u64 {
        self.id
    }

    pub fn render_size(&self) -> (u32, u32) {
        (self.targets.render_width, self.targets.render_height)
    }

    /// GPU bytes of the view's targets and uniforms.
    pub fn gpu_bytes(&self) -> u64 {
        self.targets.bytes.0 + self.bytes.0
    }

    /// Writes this frame's camera into the view's frame uniform.
    pub fn upload(&self, ctx: &GpuContext, light_count: u32, shadow_pcf_radius: u32) {
        let clip_from_world = self.camera.clip_from_world();
        let frame = FrameUniforms {
            clip_from_world: clip_from_world.to_cols_array_2d(),
            world_from_clip: clip_from_world.inverse().to_cols_array_2d(),
            camera_position: self.camera.position().extend(1.0).to_array(),
            render_size: [self.targets.render_width, self.targets.render_height],
            light_count,
            shadow_pcf_radius,
        };
        ctx.queue
            .write_buffer(&self.frame_buffer, 0, bytemuck::bytes_of(&frame));
    }

    /// SSAA box filter of direct and indirect radiance to the output size (pass "resolve").
    pub fn record_resolve(
        &self,
        ctx: &GpuContext,
        passes: &mut Passes,
        has_indirect: bool,
    ) -> Result<(), GpuError> {
        let params = ResolveParams {
            output_size: [self.width, self.height],
            ssaa: self.ssaa,
            has_indirect: has_indirect as u32,
        };
        ctx.queue
            .write_buffer(&self.resolve_params, 0, bytemuck::bytes_of(&params));
        let (w, h) = (self.width, self.height);
        passes.compute("resolve", |pass| {
            pass.set_pipeline(&self.resolve.pipeline);
            pass.set_bind_group(0, &self.resolve_group, &[]);
            pass.dispatch_workgroups(w.div_ceil(PIXEL_TILE), h.div_ceil(PIXEL_TILE), 1);
        })
    }

    /// A compute pass with one 8×8 workgroup per render-target tile (per-pixel methods).
    pub fn record_per_pixel(
        &self,
        passes: &mut Passes,
        label: &str,
        pipeline: &wgpu::ComputePipeline,
        group: &wgpu::BindGroup,
    ) -> Result<(), GpuError> {
        let (w, h) = self.render_size();
        passes.compute(label, |pass| {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(w.div_ceil(PIXEL_TILE), h.div_ceil(PIXEL_TILE), 1);
        })
    }

    /// Reads the resolved direct and indirect images back (the indirect one only when the
    /// method wrote it; otherwise it is black).
    pub fn read(&self, ctx: &GpuContext, has_indirect: bool) -> Result<(Image, Image), GpuError> {
        ctx.check_uncaptured()?;
        let (w, h) = (self.width, self.height);
        let direct = crate::gpu::read_texture_rgba32f(ctx, &self.targets.output_direct)?;
        let indirect = if has_indirect {
            Image::from_rgba(
                w,
                h,
                crate::gpu::read_texture_rgba32f(ctx, &self.targets.output_indirect)?,
            )
        } else {
            Image::new(w, h)
        };
        Ok((Image::from_rgba(w, h, direct), indirect))
    }

    /// Writes CPU-computed output images (the path tracer's) into the view's outputs.
    pub fn write_outputs(&self, ctx: &GpuContext, direct: &Image, indirect: &Image) {
        for (texture, image) in [
            (&self.targets.output_direct, direct),
            (&self.targets.output_indirect, indirect),
        ] {
            let texels: Vec<[f32; 4]> = image
                .pixels
                .iter()
                .map(|p| [p[0], p[1], p[2], 1.0])
                .collect();
            ctx.write_texture_2d(
                texture,
                0,
                bytemuck::cast_slice(&texels),
                (image.width, image.height),
                16,
            );
        }
    }
}

/// Output × SSAA must fit the device's textures.
pub fn check_size(ctx: &GpuContext, width: u32, height: u32, ssaa: u32) -> Result<(), RenderError> {
    if width == 0 || height == 0 || ssaa == 0 {
        return Err(RenderError::Settings(
            "width, height and ssaa must be at least 1".into(),
        ));
    }
    let limit = ctx.device.limits().max_texture_dimension_2d;
    let (rw, rh) = (width as u64 * ssaa as u64, height as u64 * ssaa as u64);
    if rw > limit as u64 || rh > limit as u64 {
        return Err(RenderError::Settings(format!(
            "{rw}×{rh} render targets (output × SSAA) exceed the device's limit of {limit} texels per side; lower --width/--height or --ssaa"
        )));
    }
    Ok(())
}

/// What a method is given for one frame: the scene at this frame's pose and the eye its
/// view-dependent solution terms (the glossy lobes) are computed for.
pub struct FrameInput<'a> {
    pub scene: &'a Scene,
    pub world_from_node: &'a [Mat4],
    /// The mid-eye of the frame's views (the camera itself with one view).
    pub solution_eye: Vec3,
}

/// What a view's record left in its targets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewResult {
    /// Direct light only; the resolve writes black indirect light.
    Direct,
    /// Direct and indirect radiance in the render targets.
    DirectAndIndirect,
    /// The method wrote the outputs itself (CPU methods); no resolve.
    Outputs,
}

impl ViewResult {
    pub fn has_indirect(self) -> bool {
        self != ViewResult::Direct
    }

    /// GPU bytes of the view that the method rendered with: its targets, or none for a
    /// method that wrote the outputs from the CPU.
    pub fn view_bytes(self, view: &View) -> u64 {
        match self {
            ViewResult::Outputs => 0,
            _ => view.gpu_bytes(),
        }
    }
}

/// Every rendering method: a view-free update, then one record per view. `Send`, so that a
/// method can be built on a worker thread (`valgi view` rebuilds off its UI thread).
pub trait Method: Send {
    /// The method's name as given to `--method`.
    fn name(&self) -> &'static str;

    /// Output size and quality the method was made with (the size of a mono view).
    fn settings(&self) -> crate::raster::RenderSettings;

    /// Everything that does not depend on a camera: lights, shadow maps, RSM → VALs, the
    /// gather at the sparse points (glossy for `frame.solution_eye`), occlusion,
    /// interpolation, LPV propagation. `views` are the frame's views, for per-view state
    /// the method keeps (and drops for views that are gone).
    fn update(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        views: &[&View],
        passes: &mut Passes,
    ) -> Result<(), RenderError>;

    /// One view: G-buffer, direct light, and the method's lookup of the solution into the
    /// view's `radiance_indirect`.
    fn record_view(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError>;

    /// False for a method that renders its frames on the CPU (the path tracer): it has no
    /// pipelines to compile, so a benchmark need not warm it up before timing it.
    fn renders_on_gpu(&self) -> bool {
        true
    }

    /// After the frame's submission: read back the counters the report shows.
    fn end_frame(&mut self, _ctx: &GpuContext, _timings: &FrameTimings) -> Result<(), RenderError> {
        Ok(())
    }

    /// GPU bytes the method owns (scene, shadow maps, solution), views excluded.
    fn gpu_bytes(&self) -> u64;

    /// The `key=value` options that build this method again as it is, without the search its
    /// own options asked for (budget mode's pilots): what a benchmark's untimed warm-up
    /// instance is built with. `None` when the options it was built with already do.
    fn resolved_options(&self) -> Option<Vec<(String, String)>> {
        None
    }

    /// Method-specific keys for the JSON report (empty by default).
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }

    /// The method's sparse points, for a viewer's debug view that draws them as splats on
    /// the GPU (`vals_debug_splats.wgsl`); `None` for methods without sparse points.
    fn debug_points(&self) -> Option<DebugPointSource<'_>> {
        None
    }

    /// The method's VALs, for a viewer's debug view that draws them as splats; `None` for
    /// methods without VALs.
    fn debug_vals(&self) -> Option<DebugValSource<'_>> {
        None
    }

    /// Draws the light atlas's debug colours (charts, texel grid, coverage holes, seams) in
    /// place of its indirect light while `on`; false for methods without an atlas (nothing
    /// changes).
    fn set_debug_atlas(&mut self, _on: bool) -> bool {
        false
    }

    /// What the method's solution does at the surface under a viewer's cursor (`pick`, in
    /// the scene placed by `world_from_node`, seen from `eye`): the picked vertex's links to
    /// the points it interpolates, and the point whose light the occluder view shows. `None`
    /// for methods without sparse points.
    fn debug_pick(
        &self,
        _scene: &crate::scene::Scene,
        _world_from_node: &[glam::Mat4],
        _pick: &crate::scene::pick::ScenePick,
        _eye: glam::Vec3,
    ) -> Option<DebugPick> {
        None
    }

    /// Estimated variance of each pixel of the last frame (full or indirect image), for
    /// Monte Carlo methods; `None` for deterministic ones.
    fn variance(&self, _indirect_only: bool) -> Option<Image> {
        None
    }

    /// One frame through one view of the method's own size, read back: the mono path that
    /// tests and the harness use.
    fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: &CameraView,
    ) -> Result<FrameOutput, RenderError> {
        let s = self.settings();
        let view = View::new(ctx, "main", *camera, (s.width, s.height), s.ssaa)?;
        let frame = record_frame(
            self,
            ctx,
            scene,
            world_from_node,
            std::slice::from_ref(&view),
        )?;
        let result = frame.results[0];
        let (direct, indirect) = view.read(ctx, result.has_indirect())?;
        Ok(FrameOutput {
            direct,
            indirect,
            timings: frame.timings.merged(),
            gpu_bytes: self.gpu_bytes() + result.view_bytes(&view),
        })
    }
}

/// The GPU buffers of a method's sparse points, in the layouts of `vals_common.wgsl`, for a
/// debug overlay to draw them without a CPU readback: a point's world position is its
/// model-space record placed by its instance's matrix, which only the GPU holds per frame.
pub struct DebugPointSource<'a> {
    /// `array<InstanceData>`: this frame's matrices.
    pub instances: &'a wgpu::Buffer,
    /// `array<vec4<u32>>`: model position (f32 bits) and octahedral normal.
    pub points_model: &'a wgpu::Buffer,
    /// `array<vec2<u32>>`: lobe exponent and disc radius (f16 pair), instance index.
    pub points_meta: &'a wgpu::Buffer,
    /// `array<vec4<u32>>`: the diffuse light's intensity (f32 bits) and position offset.
    pub point_diffuse: &'a wgpu::Buffer,
    /// `array<vec4<u32>>`: the glossy light's intensity and position offset.
    pub point_glossy: &'a wgpu::Buffer,
    /// `array<vec2<u32>>`: the rest of the lights' position offsets and the spheres.
    pub point_extra: &'a wgpu::Buffer,
    pub count: u32,
}

/// The sparse-point structure at a picked surface, in world space, for the viewer's links and
/// occluder views.
#[derive(Clone, Debug, PartialEq)]
pub struct DebugPick {
    /// The picked mesh vertex (world position).
    pub vertex: glam::Vec3,
    /// Its links: each linked point's world position and normalized interpolation weight
    /// (the weights sum to 1, or are all 0 when no linked point faces the vertex's way).
    pub links: Vec<(glam::Vec3, f32)>,
    /// The sparse point nearest the pick on the surface's side: its index in the method's
    /// point buffers (`DebugPointSource`) and its world position.
    pub point: Option<(u32, glam::Vec3)>,
}

/// The GPU buffers of a method's VALs (`array<Val>` of `vals_common.wgsl` and the count the
/// frame's passes wrote, `array<u32>` element 0), for a debug overlay: the count stays on the
/// GPU, so a drawer covers `capacity` slots and skips those past it.
pub struct DebugValSource<'a> {
    pub vals: &'a wgpu::Buffer,
    pub val_count: &'a wgpu::Buffer,
    pub capacity: u32,
}

/// Indirect light a composed method adds on top of another method's (`sparse+atlas`: the
/// atlas's bounces 2..B over the VAL bounce). Per view, the layer hands the underlying
/// method a target of its own to draw into, then writes the view's `radiance_indirect`
/// (that light plus its own).
pub trait IndirectLayer: Send {
    /// The composed method's name (as given to `--method`).
    fn method_name(&self) -> &'static str;
    /// Draws the layer's debug colours in place of the composed indirect light while `on`
    /// (`Method::set_debug_atlas`); false for layers that have none.
    fn set_debug_atlas(&mut self, _on: bool) -> bool {
        false
    }
    /// Per-frame uploads (transforms) and per-view state for this frame's views.
    fn update(&mut self, ctx: &GpuContext, frame: &FrameInput, views: &[&View]);
    /// Records the view's indirect light: `draw_under` draws the underlying method's light
    /// into the texture it is given (`RADIANCE_FORMAT`, the view's render resolution).
    fn record_view(
        &mut self,
        ctx: &GpuContext,
        view: &View,
        passes: &mut Passes,
        draw_under: &mut dyn FnMut(&mut Passes, &wgpu::TextureView) -> Result<(), GpuError>,
    ) -> Result<(), RenderError>;
    fn gpu_bytes(&self) -> u64;
    /// Extra keys for the method's JSON report.
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

/// One rendered frame of one view: direct and indirect radiance at the output resolution
/// (linear, W/(m²·sr)).
pub struct FrameOutput {
    pub direct: Image,
    pub indirect: Image,
    pub timings: crate::gpu::PassTimings,
    pub gpu_bytes: u64,
}

impl FrameOutput {
    /// Direct + indirect, or the indirect part alone.
    pub fn radiance(&self, indirect_only: bool) -> Image {
        if indirect_only {
            self.indirect.clone()
        } else {
            self.direct.add(&self.indirect)
        }
    }
}

/// A recorded and submitted frame: pass times by scope and what each view holds.
pub struct RecordedFrame {
    pub timings: FrameTimings,
    pub results: Vec<ViewResult>,
    /// Update passes per label, counted while recording (one update per frame, whatever the
    /// number of views).
    pub solution_pass_counts: Vec<(String, u32)>,
}

/// The mid-eye of a list of views.
pub fn mid_eye(views: &[View]) -> Vec3 {
    if views.is_empty() {
        return Vec3::ZERO;
    }
    views.iter().map(|v| v.camera.position()).sum::<Vec3>() / views.len() as f32
}

/// Runs the method's update once, then records every view, in one submission.
pub fn record_frame<M: Method + ?Sized>(
    method: &mut M,
    ctx: &GpuContext,
    scene: &Scene,
    world_from_node: &[Mat4],
    views: &[View],
) -> Result<RecordedFrame, RenderError> {
    let frame = FrameInput {
        scene,
        world_from_node,
        solution_eye: mid_eye(views),
    };
    let view_refs: Vec<&View> = views.iter().collect();
    let mut passes = Passes::new(ctx);
    passes.set_scope(Scope::Solution);
    method.update(ctx, &frame, &view_refs, &mut passes)?;
    let solution_pass_counts = passes.counts(Scope::Solution);
    let mut results = Vec::with_capacity(views.len());
    for (i, view) in views.iter().enumerate() {
        passes.set_scope(Scope::View(i));
        let result = method.record_view(ctx, &frame, view, &mut passes)?;
        if result != ViewResult::Outputs {
            view.record_resolve(ctx, &mut passes, result.has_indirect())?;
        }
        results.push(result);
    }
    let timings = passes.finish_scoped()?;
    ctx.check_uncaptured()?;
    method.end_frame(ctx, &timings)?;
    Ok(RecordedFrame {
        timings,
        results,
        solution_pass_counts,
    })
}

/// Per-view state a method keeps between frames (bind groups over a view's targets, extra
/// per-view textures), keyed by [`View::id`] and pruned to the views of the current frame so
/// that nothing accumulates while views come and go.
pub struct ViewCache<T> {
    entries: HashMap<u64, T>,
}

impl<T> Default for ViewCache<T> {
    fn default() -> Self {
        Self {
            entries: HashMap::new(),
        }
    }
}

impl<T> ViewCache<T> {
    /// Drops the state of views not in `views`.
    pub fn retain(&mut self, views: &[&View]) {
        self.entries
            .retain(|id, _| views.iter().any(|v| v.id() == *id));
    }

    pub fn get_or_try_insert(
        &mut self,
        view: &View,
        make: impl FnOnce() -> Result<T, RenderError>,
    ) -> Result<&T, RenderError> {
        match self.entries.entry(view.id()) {
            std::collections::hash_map::Entry::Occupied(e) => Ok(e.into_mut()),
            std::collections::hash_map::Entry::Vacant(e) => Ok(e.insert(make()?)),
        }
    }

    pub fn get(&self, view: &View) -> Option<&T> {
        self.entries.get(&view.id())
    }

    pub fn values_by_id(&self, id: u64) -> Option<&T> {
        self.entries.get(&id)
    }

    pub fn len(&self) -> usize {
        self.entries.len()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    pub fn values(&self) -> impl Iterator<Item = &T> {
        self.entries.values()
    }
}
