//! `valgi view`: a window on the frame code of `valgi render`. Each redraw is one
//! [`record_frame`] over the rig's views (one lighting update, one record per view) on the
//! window's device; each view's resolved output is then drawn into its region of the window
//! by a small render pass (`present.wgsl`, the PNG tone map), and the egui panel on top, with
//! no CPU readback. `--screenshot` reads back one frame, the last, drawn into an offscreen
//! texture by the same passes.

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{EulerRot, Mat4, Quat, Vec3};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::app::AppError;
use crate::frame::{record_frame, Method, View, ViewResult, ViewRig};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::timing::round3;
use crate::gpu::{FrameTimings, GpuContext};
use crate::method::{self, MethodOptions, OptionKind};
use crate::raster::types::{shared_layout, SharedLayout};
use crate::raster::{RenderError, RenderSettings};
use crate::scene::{self, CameraView, Scene};

/// `present.wgsl` (fragment): the tone map's parameters and the view's direct and indirect
/// radiance.
const PRESENT_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Texture, Slot::Texture];

/// Width of the control panel, logical pixels.
const PANEL_WIDTH: f32 = 280.0;
/// Animation step per frame of a scripted run (`--frames`), seconds: `valgi render`'s 30 fps.
const SCRIPTED_FRAME_S: f32 = 1.0 / 30.0;

#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    #[error(transparent)]
    App(#[from] AppError),
    #[error("window: {0}")]
    Window(String),
    #[error("screenshot {path}: {message}")]
    Screenshot { path: PathBuf, message: String },
}

impl From<RenderError> for ViewerError {
    fn from(e: RenderError) -> Self {
        ViewerError::App(e.into())
    }
}

impl From<crate::gpu::GpuError> for ViewerError {
    fn from(e: crate::gpu::GpuError) -> Self {
        ViewerError::App(e.into())
    }
}

/// One `valgi view` invocation.
#[derive(Clone, Debug)]
pub struct ViewerRequest {
    pub scene: String,
    pub method: String,
    pub options: MethodOptions,
    /// Size of each view's region and the method's quality settings.
    pub settings: RenderSettings,
    pub camera: Option<String>,
    /// Lights and a camera added to the scene (`--light`, `--camera-eye`, …).
    pub edits: crate::scene::edits::SceneEdits,
    pub views: ViewRig,
    pub max_edge: f32,
    pub allow_external_paths: bool,
    /// Most proxy lights the emissive surfaces become (0 = none).
    pub emitter_lights: u32,
    /// Animation time of the first frame, seconds.
    pub time: f32,
    pub exposure: f32,
    /// Render this many frames, then exit (scripted runs and tests).
    pub frames: Option<u32>,
    /// Write the last frame's window contents here (PNG).
    pub screenshot: Option<PathBuf>,
}

/// Which radiance the window shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Components {
    Direct,
    Indirect,
    Both,
}

impl Components {
    fn bits(self) -> u32 {
        match self {
            Components::Direct => 1,
            Components::Indirect => 2,
            Components::Both => 3,
        }
    }
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PresentParams {
    pub exposure_scale: f32,
    pub components: u32,
    pub encode_srgb: u32,
    pub pad0: u32,
    pub origin: [u32; 2],
    pub size: [u32; 2],
}

/// The viewer's structs shared with WGSL.
pub fn shared_layouts() -> Vec<SharedLayout> {
    vec![shared_layout!(
        "PresentParams",
        "present.wgsl",
        PresentParams,
        [exposure_scale, components, encode_srgb, pad0, origin, size]
    )]
}

/// A camera flown by WASD and mouse drags: a position, a heading about world +y and a pitch.
#[derive(Clone, Copy, Debug)]
pub struct FlyCamera {
    pub position: Vec3,
    pub yaw: f32,
    pub pitch: f32,
}

impl FlyCamera {
    /// The heading and pitch of `camera`'s view direction (its roll is dropped).
    pub fn from_view(camera: &CameraView) -> Self {
        let forward = -camera
            .world_from_view
            .z_axis
            .truncate()
            .normalize_or(Vec3::NEG_Z);
        Self {
            position: camera.position(),
            yaw: (-forward.x).atan2(-forward.z),
            pitch: forward.y.clamp(-1.0, 1.0).asin(),
        }
    }

    pub fn world_from_view(&self) -> Mat4 {
        let rotation = Quat::from_euler(EulerRot::YXZ, self.yaw, self.pitch, 0.0);
        Mat4::from_rotation_translation(rotation, self.position)
    }

    /// Moves by `local` (view-space x right, y up, z backwards) metres.
    pub fn translate_local(&mut self, local: Vec3) {
        let rotation = Quat::from_euler(EulerRot::YXZ, self.yaw, self.pitch, 0.0);
        self.position += rotation * local;
    }

    /// Turns by a drag of `dx`, `dy` radians (right and down positive).
    pub fn turn(&mut self, dx: f32, dy: f32) {
        self.yaw -= dx;
        let limit = std::f32::consts::FRAC_PI_2 - 1e-3;
        self.pitch = (self.pitch - dy).clamp(-limit, limit);
    }
}

/// What the panel changes; applied after the UI pass.
enum Action {
    SetMethod(&'static str),
    SetOption(&'static str, String),
    ResetCamera,
}

/// The knobs that take effect in the next frame without rebuilding anything.
struct Knobs {
    exposure: f32,
    components: Components,
    playing: bool,
    time: f32,
    speed: f32,
}

/// Loads the scene, opens the window and runs until it is closed (or `frames` are done).
/// Returns the JSON report of the last frame.
pub fn run(request: &ViewerRequest) -> Result<serde_json::Value, ViewerError> {
    if request.frames == Some(0) {
        return Err(RenderError::Settings("--frames must be at least 1".into()).into());
    }
    if !request.time.is_finite() || !request.exposure.is_finite() {
        return Err(RenderError::Settings("--time and --exposure must be finite".into()).into());
    }
    if let Some(path) = &request.screenshot {
        crate::image_io::prepare_output(path).map_err(AppError::from)?;
    }
    let mut scene = scene::load_with(
        &request.scene,
        &scene::LoadParams {
            max_edge: request.max_edge,
            allow_external_paths: request.allow_external_paths,
            emitter_lights: request.emitter_lights,
        },
    )
    .map_err(AppError::from)?;
    let aspect = request.settings.width as f32 / request.settings.height as f32;
    let camera = request
        .edits
        .apply(&mut scene, request.camera.as_deref(), aspect)
        .map_err(AppError::from)?;
    // From here on the request names the camera the edits chose.
    let request = &ViewerRequest {
        camera,
        ..request.clone()
    };
    for warning in &scene.warnings {
        log::warn!("{warning}");
    }
    let event_loop = EventLoop::new().map_err(|e| {
        ViewerError::Window(format!(
            "cannot open a display ({e}); set DISPLAY to an X server, or run under `xvfb-run`"
        ))
    })?;
    let mut app = App {
        request: request.clone(),
        scene,
        running: None,
        error: None,
        report: None,
    };
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewerError::Window(e.to_string()))?;
    if let Some(e) = app.error {
        return Err(e);
    }
    Ok(app.report.unwrap_or_else(|| serde_json::json!({})))
}

struct App {
    request: ViewerRequest,
    scene: Scene,
    running: Option<Running>,
    error: Option<ViewerError>,
    report: Option<serde_json::Value>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_some() {
            return;
        }
        match Running::new(event_loop, &self.request, &self.scene) {
            Ok(running) => {
                running.window.request_redraw();
                self.running = Some(running);
            }
            Err(e) => {
                self.error = Some(e);
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        let Some(running) = self.running.as_mut() else {
            return;
        };
        let consumed = running
            .egui_state
            .on_window_event(&running.window, &event)
            .consumed;
        match event {
            WindowEvent::CloseRequested => {
                self.report = Some(running.report(&self.scene));
                event_loop.exit();
            }
            WindowEvent::Resized(size) => {
                if let Err(e) = running.resize(size.width, size.height, &self.scene) {
                    self.error = Some(e);
                    event_loop.exit();
                }
            }
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    if event.state == ElementState::Pressed && !consumed {
                        running.keys_down.insert(code);
                    } else if event.state == ElementState::Released {
                        running.keys_down.remove(&code);
                    }
                }
            }
            WindowEvent::MouseInput {
                state,
                button: MouseButton::Left,
                ..
            } => {
                running.dragging = state == ElementState::Pressed && !consumed;
            }
            WindowEvent::CursorMoved { position, .. } => {
                let now = (position.x as f32, position.y as f32);
                if let (true, Some(last)) = (running.dragging, running.cursor) {
                    let radians_per_pixel = 0.005;
                    let mut fly = running.fly_or_scene_camera();
                    fly.turn(
                        (now.0 - last.0) * radians_per_pixel,
                        (now.1 - last.1) * radians_per_pixel,
                    );
                    running.fly = Some(fly);
                }
                running.cursor = Some(now);
            }
            WindowEvent::RedrawRequested => match running.redraw(&self.scene) {
                Ok(done) => {
                    if done {
                        self.report = Some(running.report(&self.scene));
                        event_loop.exit();
                    } else {
                        running.window.request_redraw();
                    }
                }
                Err(e) => {
                    self.error = Some(e);
                    event_loop.exit();
                }
            },
            _ => {}
        }
    }
}

/// A view's present pass state: its uniform and a bind group over its outputs.
struct PresentTarget {
    params: wgpu::Buffer,
    group: wgpu::BindGroup,
    origin: (u32, u32),
    size: (u32, u32),
}

struct Running {
    request: ViewerRequest,
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ctx: GpuContext,
    method_name: &'static str,
    options: MethodOptions,
    edits: BTreeMap<&'static str, String>,
    method_error: Option<String>,
    method: Box<dyn Method>,
    views: Vec<View>,
    results: Vec<ViewResult>,
    present_layout: GroupLayout,
    present_pipeline: wgpu::RenderPipeline,
    present_targets: Vec<PresentTarget>,
    egui_ctx: egui::Context,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
    knobs: Knobs,
    /// `None` until the user moves: the scene's (possibly animated) camera is used as is.
    fly: Option<FlyCamera>,
    keys_down: HashSet<KeyCode>,
    dragging: bool,
    cursor: Option<(f32, f32)>,
    timings: FrameTimings,
    frame_ms: f64,
    frames_done: u32,
    last_redraw: Instant,
}

impl Running {
    fn new(
        event_loop: &ActiveEventLoop,
        request: &ViewerRequest,
        scene: &Scene,
    ) -> Result<Self, ViewerError> {
        let s = request.settings;
        let view_count = request
            .views
            .views(&dummy_camera(), (s.width, s.height), Vec3::ZERO);
        let total_width: u32 = view_count.iter().map(|v| v.size.0).sum();
        let height = view_count
            .iter()
            .map(|v| v.size.1)
            .max()
            .unwrap_or(s.height);
        let attributes = Window::default_attributes()
            .with_title(format!("valgi view: {}", scene.name))
            .with_inner_size(winit::dpi::PhysicalSize::new(
                total_width + PANEL_WIDTH as u32,
                height,
            ));
        let window = Arc::new(
            event_loop
                .create_window(attributes)
                .map_err(|e| ViewerError::Window(e.to_string()))?,
        );
        let instance = GpuContext::window_instance(Box::new(event_loop.owned_display_handle()));
        let surface = instance
            .create_surface(window.clone())
            .map_err(|e| ViewerError::Window(format!("cannot draw into the window: {e}")))?;
        let ctx = GpuContext::for_surface(&instance, &surface)?;
        let caps = surface.get_capabilities(&ctx.adapter);
        // egui blends in gamma space, so it wants a non-sRGB target; the present pass then
        // applies the OETF itself.
        let format = [
            wgpu::TextureFormat::Bgra8Unorm,
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureFormat::Bgra8UnormSrgb,
            wgpu::TextureFormat::Rgba8UnormSrgb,
        ]
        .into_iter()
        .find(|f| caps.formats.contains(f))
        .ok_or_else(|| {
            ViewerError::Window(format!(
                "the window offers no 8-bit RGBA format (it offers {:?})",
                caps.formats
            ))
        })?;
        let size = window.inner_size();
        let config = wgpu::SurfaceConfiguration {
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            present_mode: wgpu::PresentMode::AutoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&ctx.device, &config);

        let fs = wgpu::ShaderStages::FRAGMENT;
        let present_layout = GroupLayout::new(&ctx.device, "present", fs, PRESENT_BINDINGS);
        let present_pipeline = present_pipeline(&ctx, &present_layout.layout, format);

        let method_entry = method::entry(&request.method)?;
        let mut edits = BTreeMap::new();
        for spec in method_entry.options {
            let given = request.options.entries().find(|(k, _)| *k == spec.name);
            edits.insert(
                spec.name,
                given.map_or(spec.default.to_string(), |(_, v)| v.to_string()),
            );
        }
        let method = method::create(&request.method, &ctx, scene, s, &request.options)?;

        let egui_ctx = egui::Context::default();
        let egui_state = egui_winit::State::new(
            egui_ctx.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            Some(ctx.device.limits().max_texture_dimension_2d as usize),
        );
        let egui_renderer =
            egui_wgpu::Renderer::new(&ctx.device, format, egui_wgpu::RendererOptions::default());
        let mut running = Self {
            request: request.clone(),
            window,
            surface,
            config,
            ctx,
            method_name: method_entry.name,
            options: request.options.clone(),
            edits,
            method_error: None,
            method,
            views: vec![],
            results: vec![],
            present_layout,
            present_pipeline,
            present_targets: vec![],
            egui_ctx,
            egui_state,
            egui_renderer,
            knobs: Knobs {
                exposure: request.exposure,
                components: Components::Both,
                playing: !scene.animations.is_empty(),
                time: request.time,
                speed: 1.0,
            },
            fly: None,
            keys_down: HashSet::new(),
            dragging: false,
            cursor: None,
            timings: FrameTimings::default(),
            frame_ms: 0.0,
            frames_done: 0,
            last_redraw: Instant::now(),
        };
        running.make_views((s.width, s.height), scene)?;
        Ok(running)
    }

    /// Views of the rig at `size` each, side by side from the window's top-left corner.
    fn make_views(&mut self, size: (u32, u32), scene: &Scene) -> Result<(), ViewerError> {
        let world_from_node = scene.world_from_node_at(self.knobs.time);
        let camera = self.base_camera(scene, size, &world_from_node)?;
        let rig =
            self.request
                .views
                .views(&camera, size, scene_pivot(scene, &world_from_node, &camera));
        self.views.clear();
        self.present_targets.clear();
        let mut x = 0;
        for r in rig {
            let view = View::new(
                &self.ctx,
                &r.name,
                r.camera,
                r.size,
                self.request.settings.ssaa,
            )?;
            let params = self.ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("present params"),
                size: std::mem::size_of::<PresentParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let direct = view.targets.output_direct.create_view(&Default::default());
            let indirect = view
                .targets
                .output_indirect
                .create_view(&Default::default());
            let group = self
                .present_layout
                .bind(&self.ctx.device, &[&params, &direct, &indirect]);
            self.present_targets.push(PresentTarget {
                params,
                group,
                origin: (x, 0),
                size: r.size,
            });
            x += r.size.0;
            self.views.push(view);
        }
        Ok(())
    }

    /// The scene's camera at this frame, or the flown one.
    fn base_camera(
        &self,
        scene: &Scene,
        size: (u32, u32),
        world_from_node: &[Mat4],
    ) -> Result<CameraView, ViewerError> {
        let mut camera = scene
            .camera_view(
                self.request.camera.as_deref(),
                size.0 as f32 / size.1 as f32,
                world_from_node,
            )
            .map_err(AppError::from)?;
        if let Some(fly) = &self.fly {
            camera.world_from_view = fly.world_from_view();
        }
        Ok(camera)
    }

    fn fly_or_scene_camera(&self) -> FlyCamera {
        self.fly
            .unwrap_or_else(|| FlyCamera::from_view(&self.views[0].camera))
    }

    fn resize(&mut self, width: u32, height: u32, scene: &Scene) -> Result<(), ViewerError> {
        if width == 0 || height == 0 {
            return Ok(());
        }
        self.config.width = width;
        self.config.height = height;
        self.surface.configure(&self.ctx.device, &self.config);
        let panel = (PANEL_WIDTH * self.window.scale_factor() as f32) as u32;
        let count = self.views.len().max(1) as u32;
        let size = ((width.saturating_sub(panel) / count).max(1), height);
        if self.views.first().map(|v| (v.width, v.height)) != Some(size) {
            self.make_views(size, scene)?;
        }
        Ok(())
    }

    /// Rebuilds the method with `options`; on failure the running method stays and the
    /// panel shows why.
    fn rebuild_method(&mut self, name: &'static str, options: MethodOptions, scene: &Scene) {
        let size = self.views.first().map_or(
            (self.request.settings.width, self.request.settings.height),
            |v| (v.width, v.height),
        );
        let settings = RenderSettings {
            width: size.0,
            height: size.1,
            ..self.request.settings
        };
        match method::create(name, &self.ctx, scene, settings, &options) {
            Ok(m) => {
                self.method = m;
                self.method_name = name;
                self.options = options;
                self.method_error = None;
            }
            Err(e) => self.method_error = Some(e.to_string()),
        }
        self.reset_edits();
    }

    /// The panel's option texts: the explicit options, else the registry's defaults.
    fn reset_edits(&mut self) {
        self.edits.clear();
        if let Ok(entry) = method::entry(self.method_name) {
            for spec in entry.options {
                let given = self.options.entries().find(|(k, _)| *k == spec.name);
                self.edits.insert(
                    spec.name,
                    given.map_or(spec.default.to_string(), |(_, v)| v.to_string()),
                );
            }
        }
    }

    /// One frame: camera and animation step, the frame's record, the present and panel
    /// passes. Returns true when a scripted run is done.
    fn redraw(&mut self, scene: &Scene) -> Result<bool, ViewerError> {
        let now = Instant::now();
        let scripted = self.request.frames.is_some();
        let dt = if scripted {
            SCRIPTED_FRAME_S
        } else {
            (now - self.last_redraw).as_secs_f32().min(0.25)
        };
        self.last_redraw = now;
        self.fly_step(dt);
        if self.knobs.playing && self.frames_done > 0 {
            self.knobs.time += dt;
            let duration = scene.animation_duration();
            if duration > 0.0 && !scripted {
                self.knobs.time %= duration;
            }
        }
        let world_from_node = scene.world_from_node_at(self.knobs.time);
        let size = self.views.first().map_or((1, 1), |v| (v.width, v.height));
        let camera = self.base_camera(scene, size, &world_from_node)?;
        let rig =
            self.request
                .views
                .views(&camera, size, scene_pivot(scene, &world_from_node, &camera));
        for (view, r) in self.views.iter_mut().zip(rig) {
            view.camera = r.camera;
        }
        let started = Instant::now();
        let frame = record_frame(
            self.method.as_mut(),
            &self.ctx,
            scene,
            &world_from_node,
            &self.views,
        )?;
        self.results = frame.results;
        self.timings = frame.timings;

        let raw_input = self.egui_state.take_egui_input(&self.window);
        let mut actions = vec![];
        let mut full = {
            let panel = PanelData {
                method_name: self.method_name,
                edits: &mut self.edits,
                method_error: self.method_error.as_deref(),
                knobs: &mut self.knobs,
                timings: &self.timings,
                frame_ms: self.frame_ms,
                has_animation: !scene.animations.is_empty(),
                flying: self.fly.is_some(),
                view_names: self.views.iter().map(|v| v.name.clone()).collect(),
            };
            let mut panel = panel;
            self.egui_ctx
                .run_ui(raw_input, |ui| panel.show(ui, &mut actions))
        };
        self.egui_state
            .handle_platform_output(&self.window, full.platform_output);
        let pixels_per_point = full.pixels_per_point;
        let jobs = self.egui_ctx.tessellate(full.shapes, pixels_per_point);
        for (id, deltas) in full.textures_delta.set.drain() {
            for delta in deltas {
                self.egui_renderer
                    .update_texture(&self.ctx.device, &self.ctx.queue, id, &delta);
            }
        }
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [self.config.width, self.config.height],
            pixels_per_point,
        };
        self.write_present_params();

        let output = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => Some(t),
            _ => {
                self.surface.configure(&self.ctx.device, &self.config);
                None
            }
        };
        let mut encoder = self
            .ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("present"),
            });
        self.egui_renderer.update_buffers(
            &self.ctx.device,
            &self.ctx.queue,
            &mut encoder,
            &jobs,
            &screen,
        );
        if let Some(output) = &output {
            let target = output.texture.create_view(&Default::default());
            self.draw(&mut encoder, &target, &jobs, &screen);
        }
        let last = self
            .request
            .frames
            .is_some_and(|n| self.frames_done + 1 >= n);
        let shot = match (&self.request.screenshot, last) {
            (Some(_), true) => Some(self.offscreen_target()),
            _ => None,
        };
        if let Some(texture) = &shot {
            let target = texture.create_view(&Default::default());
            self.draw(&mut encoder, &target, &jobs, &screen);
        }
        self.ctx.queue.submit([encoder.finish()]);
        if let Some(output) = output {
            self.window.pre_present_notify();
            self.ctx.queue.present(output);
        }
        for id in std::mem::take(&mut full.textures_delta.free) {
            self.egui_renderer.free_texture(&id);
        }
        self.frame_ms = started.elapsed().as_secs_f64() * 1000.0;
        self.frames_done += 1;
        if let (Some(texture), Some(path)) = (shot, self.request.screenshot.clone()) {
            self.write_screenshot(&texture, &path)?;
        }
        for action in actions {
            self.apply(action, scene);
        }
        Ok(last)
    }

    fn apply(&mut self, action: Action, scene: &Scene) {
        match action {
            Action::SetMethod(name) => self.rebuild_method(name, MethodOptions::default(), scene),
            Action::SetOption(key, value) => {
                let mut options = self.options.clone();
                options.set(key, value);
                let name = self.method_name;
                self.rebuild_method(name, options, scene);
            }
            Action::ResetCamera => self.fly = None,
        }
    }

    /// WASD (and Q/E down/up) at the speed knob, metres per second.
    fn fly_step(&mut self, dt: f32) {
        let mut local = Vec3::ZERO;
        for (key, direction) in [
            (KeyCode::KeyW, Vec3::NEG_Z),
            (KeyCode::KeyS, Vec3::Z),
            (KeyCode::KeyA, Vec3::NEG_X),
            (KeyCode::KeyD, Vec3::X),
            (KeyCode::KeyE, Vec3::Y),
            (KeyCode::KeyQ, Vec3::NEG_Y),
        ] {
            if self.keys_down.contains(&key) {
                local += direction;
            }
        }
        if local != Vec3::ZERO && !self.views.is_empty() {
            let mut fly = self.fly_or_scene_camera();
            fly.translate_local(local.normalize() * self.knobs.speed * dt);
            self.fly = Some(fly);
        }
    }

    fn write_present_params(&self) {
        let encode_srgb = !self.config.format.is_srgb() as u32;
        for target in &self.present_targets {
            let params = PresentParams {
                exposure_scale: 2f32.powf(self.knobs.exposure),
                components: self.knobs.components.bits(),
                encode_srgb,
                pad0: 0,
                origin: [target.origin.0, target.origin.1],
                size: [target.size.0, target.size.1],
            };
            self.ctx
                .queue
                .write_buffer(&target.params, 0, bytemuck::bytes_of(&params));
        }
    }

    /// The views into their regions, then the panel, into `target` (the window's format).
    fn draw(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        jobs: &[egui::ClippedPrimitive],
        screen: &egui_wgpu::ScreenDescriptor,
    ) {
        let pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("present"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        let mut pass = pass.forget_lifetime();
        let (w, h) = (self.config.width, self.config.height);
        for t in &self.present_targets {
            // Regions that the window no longer covers (mid-resize) are skipped.
            if t.origin.0 + t.size.0 > w || t.origin.1 + t.size.1 > h {
                continue;
            }
            pass.set_viewport(
                t.origin.0 as f32,
                t.origin.1 as f32,
                t.size.0 as f32,
                t.size.1 as f32,
                0.0,
                1.0,
            );
            pass.set_pipeline(&self.present_pipeline);
            pass.set_bind_group(0, &t.group, &[]);
            pass.draw(0..3, 0..1);
        }
        pass.set_viewport(0.0, 0.0, w as f32, h as f32, 0.0, 1.0);
        self.egui_renderer.render(&mut pass, jobs, screen);
    }

    fn offscreen_target(&self) -> wgpu::Texture {
        self.ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("screenshot"),
            size: wgpu::Extent3d {
                width: self.config.width,
                height: self.config.height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: self.config.format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        })
    }

    fn write_screenshot(
        &self,
        texture: &wgpu::Texture,
        path: &std::path::Path,
    ) -> Result<(), ViewerError> {
        let bytes = crate::gpu::read_texture_bytes(&self.ctx, texture, 4)?;
        let bgra = matches!(
            self.config.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        );
        let rgb: Vec<u8> = bytes
            .chunks_exact(4)
            .flat_map(|p| {
                if bgra {
                    [p[2], p[1], p[0]]
                } else {
                    [p[0], p[1], p[2]]
                }
            })
            .collect();
        let image = image::RgbImage::from_raw(texture.width(), texture.height(), rgb)
            .expect("texel count matches the texture");
        image.save(path).map_err(|e| ViewerError::Screenshot {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    }

    /// The JSON report: the last frame's passes, as `valgi render` prints them.
    fn report(&self, scene: &Scene) -> serde_json::Value {
        let merged = self.timings.merged();
        serde_json::json!({
            "scene": scene.name,
            "method": self.method.name(),
            "options": self.options.to_string(),
            "views": self.views.iter().map(|v| v.name.clone()).collect::<Vec<_>>(),
            "view_size": self.views.first().map(|v| [v.width, v.height]),
            "frames": self.frames_done,
            "surface_format": format!("{:?}", self.config.format),
            "adapter": self.ctx.adapter_label(),
            "passes": merged.to_json(),
            "total_ms": round3(merged.total_ms()),
            "solution_ms": round3(self.timings.solution.total_ms()),
            "view_ms": self.timings.views.iter().map(|t| round3(t.total_ms())).collect::<Vec<_>>(),
            "screenshot": self.request.screenshot.as_ref().map(|p| p.display().to_string()),
        })
    }
}

/// What the panel shows and edits.
struct PanelData<'a> {
    method_name: &'static str,
    edits: &'a mut BTreeMap<&'static str, String>,
    method_error: Option<&'a str>,
    knobs: &'a mut Knobs,
    timings: &'a FrameTimings,
    frame_ms: f64,
    has_animation: bool,
    flying: bool,
    view_names: Vec<String>,
}

impl PanelData<'_> {
    fn show(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        egui::Panel::right("controls")
            .exact_size(PANEL_WIDTH)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| self.contents(ui, actions));
            });
    }

    fn contents(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        ui.heading("valgi");
        ui.label(format!(
            "frame {:.1} ms (CPU wall, record + submit)",
            self.frame_ms
        ));
        ui.separator();
        egui::ComboBox::from_label("method")
            .selected_text(self.method_name)
            .show_ui(ui, |ui| {
                for entry in method::REGISTRY {
                    if ui
                        .selectable_label(entry.name == self.method_name, entry.name)
                        .clicked()
                        && entry.name != self.method_name
                    {
                        actions.push(Action::SetMethod(entry.name));
                    }
                }
            });
        if let Ok(entry) = method::entry(self.method_name) {
            for spec in entry.options {
                let Some(text) = self.edits.get_mut(spec.name) else {
                    continue;
                };
                ui.horizontal(|ui| {
                    ui.label(spec.name).on_hover_text(spec.help);
                    match spec.kind {
                        OptionKind::Int { min, max } => {
                            let mut value: i64 = text.parse().unwrap_or(min);
                            let response =
                                ui.add(egui::DragValue::new(&mut value).range(min..=max));
                            if response.changed() {
                                *text = value.to_string();
                            }
                            if response.drag_stopped()
                                || (response.changed() && !response.dragged())
                            {
                                actions.push(Action::SetOption(spec.name, text.clone()));
                            }
                        }
                        OptionKind::Choice(choices) => {
                            egui::ComboBox::from_id_salt(spec.name)
                                .selected_text(text.as_str())
                                .show_ui(ui, |ui| {
                                    for choice in choices {
                                        if ui.selectable_label(text == choice, *choice).clicked()
                                            && text != choice
                                        {
                                            actions.push(Action::SetOption(
                                                spec.name,
                                                choice.to_string(),
                                            ));
                                        }
                                    }
                                });
                        }
                        OptionKind::Path | OptionKind::Text => {
                            let response = ui.text_edit_singleline(text);
                            if response.lost_focus()
                                && ui.input(|i| i.key_pressed(egui::Key::Enter))
                            {
                                actions.push(Action::SetOption(spec.name, text.clone()));
                            }
                        }
                    }
                });
            }
        }
        if let Some(error) = self.method_error {
            ui.colored_label(egui::Color32::LIGHT_RED, error);
        }
        ui.separator();
        ui.add(egui::Slider::new(&mut self.knobs.exposure, -8.0..=8.0).text("exposure (stops)"));
        ui.horizontal(|ui| {
            ui.radio_value(&mut self.knobs.components, Components::Direct, "direct");
            ui.radio_value(&mut self.knobs.components, Components::Indirect, "indirect");
            ui.radio_value(&mut self.knobs.components, Components::Both, "both");
        });
        ui.separator();
        ui.label("camera: WASD, Q/E down/up, drag to turn");
        ui.add(
            egui::Slider::new(&mut self.knobs.speed, 0.01..=100.0)
                .logarithmic(true)
                .text("speed (m/s)"),
        );
        if ui
            .add_enabled(self.flying, egui::Button::new("reset to the scene camera"))
            .clicked()
        {
            actions.push(Action::ResetCamera);
        }
        if self.has_animation {
            ui.horizontal(|ui| {
                let label = if self.knobs.playing { "pause" } else { "play" };
                if ui.button(label).clicked() {
                    self.knobs.playing = !self.knobs.playing;
                }
                ui.label(format!("t = {:.2} s", self.knobs.time));
            });
        }
        ui.separator();
        let gpu = if self.timings.solution.gpu_timestamps {
            "GPU timestamps"
        } else {
            "wall clock"
        };
        ui.label(format!("passes, ms ({gpu})"));
        let scope = |ui: &mut egui::Ui, title: &str, timings: &crate::gpu::PassTimings| {
            ui.label(format!("{title}: {:.2}", timings.total_ms()));
            for (label, ms) in &timings.passes {
                ui.label(format!("    {label:<20} {ms:8.2}"));
            }
        };
        scope(ui, "solution", &self.timings.solution);
        for (name, timings) in self.view_names.iter().zip(&self.timings.views) {
            scope(ui, &format!("view {name}"), timings);
        }
    }
}

fn present_pipeline(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
) -> wgpu::RenderPipeline {
    let shader = ctx.shader("present.wgsl");
    let pipeline_layout = ctx
        .device
        .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("present"),
            bind_group_layouts: &[Some(layout)],
            immediate_size: 0,
        });
    ctx.device
        .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("present"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format,
                    blend: None,
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        })
}

/// The point a `grid` rig turns about: the scene's centre.
fn scene_pivot(scene: &Scene, world_from_node: &[Mat4], camera: &CameraView) -> Vec3 {
    let bounds = scene.world_bounds(world_from_node);
    if bounds.is_empty() {
        camera.position()
    } else {
        (bounds.min + bounds.max) * 0.5
    }
}

/// A camera for counting a rig's views and their sizes before the scene camera is known.
fn dummy_camera() -> CameraView {
    CameraView {
        world_from_view: Mat4::IDENTITY,
        yfov: 1.0,
        aspect: 1.0,
        znear: 0.1,
        zfar: 10.0,
        off_axis: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fly_camera_round_trips_a_view_direction() {
        let camera = CameraView {
            world_from_view: glam::camera::rh::view::look_at_mat4(
                Vec3::new(1.0, 2.0, 3.0),
                Vec3::new(0.0, 0.5, 0.0),
                Vec3::Y,
            )
            .inverse(),
            ..dummy_camera()
        };
        let fly = FlyCamera::from_view(&camera);
        let rebuilt = fly.world_from_view();
        let forward = |m: Mat4| -m.z_axis.truncate();
        assert!((forward(rebuilt) - forward(camera.world_from_view)).length() < 1e-5);
        assert!((rebuilt.w_axis.truncate() - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
        // Without roll the rebuilt right vector stays horizontal.
        assert!(rebuilt.x_axis.y.abs() < 1e-6);
    }

    #[test]
    fn fly_camera_moves_along_its_view() {
        let mut fly = FlyCamera {
            position: Vec3::ZERO,
            yaw: std::f32::consts::FRAC_PI_2,
            pitch: 0.0,
        };
        // Heading +90° about +y looks down −x.
        fly.translate_local(Vec3::NEG_Z);
        assert!(
            (fly.position - Vec3::NEG_X).length() < 1e-6,
            "{:?}",
            fly.position
        );
    }
}
