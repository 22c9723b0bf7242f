//! `valgi view`: a window on the frame code of `valgi render`. Each redraw is one
//! [`record_frame`] over the rig's views (one lighting update, one record per view) on the
//! window's device; each view's resolved output is then drawn into its region of the window
//! by a small render pass (`present.wgsl`, the PNG tone map), and the egui panel on top, with
//! no CPU readback. `--screenshot` (and the F12 key) reads back one frame drawn into an
//! offscreen texture by the same passes. Method rebuilds run on a worker thread while the
//! running method keeps drawing; the state the panel and input change lives in
//! [`state::ViewerState`], testable without a window.

pub mod debug;
pub mod panel_layer;
pub mod reference;
pub mod state;

use std::collections::{BTreeMap, HashSet};
use std::path::PathBuf;
use std::sync::{mpsc, Arc};
use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};
use winit::application::ApplicationHandler;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::keyboard::{KeyCode, PhysicalKey};
use winit::window::{Window, WindowId};

use crate::app::AppError;
use crate::frame::{record_frame, DebugPick, Method, View, ViewResult, ViewRig};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::timing::round3;
use crate::gpu::{FrameTimings, GpuContext};
use crate::method::{self, MethodOptions, OptionKind};
use crate::raster::types::{shared_layout, SharedLayout};
use crate::raster::{RenderError, RenderSettings};
use crate::scene::{CameraView, Scene};

pub use state::{
    CameraControl, Components, DebugViews, DragMode, FlyCamera, OrbitCamera, StereoDisplay,
};
use state::{ViewerState, FOV_RANGE_DEGREES};

/// `present.wgsl` (fragment): the tone map's parameters, the view's direct and indirect
/// radiance, and the reference's (the reference debug view).
const PRESENT_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
];

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
    /// Built instead at start-up when `method` cannot bake its atlas in memory (as
    /// `RenderRequest::method_fallback`): `sparse` for the default `sparse+atlas`.
    pub method_fallback: Option<String>,
    pub options: MethodOptions,
    /// Size of each view's region and the method's quality settings.
    pub settings: RenderSettings,
    pub camera: Option<String>,
    /// Lights and a camera added to the scene (`--light`, `--camera-eye`, …).
    pub edits: crate::scene::edits::SceneEdits,
    pub views: ViewRig,
    /// Longest triangle edge; `None`: as `valgi render` chooses it for the starting method
    /// (an imported scene viewed with a sparse method is refined to its point spacing, any
    /// other scene to 5 cm). A method switched to in the panel keeps the scene as loaded.
    pub max_edge: Option<f32>,
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
    /// Show a two-view rig as a red/cyan anaglyph instead of side by side.
    pub anaglyph: bool,
    /// Scripted runs: after the first frame, change this method option (key, value; the key
    /// `method` switches the method) as the panel would, and run on until the rebuild is in
    /// (the report gives its figures).
    pub change_option: Option<(String, String)>,
    /// Debug views on from the start (`--debug`).
    pub debug: DebugViews,
    /// The window pixel whose surface the links and occluder views show in a scripted run
    /// (`--pick X,Y`); interactively, the cursor's.
    pub pick: Option<(u32, u32)>,
    /// Where `valgi eval` cached its references (its output folder or the `cache` in it):
    /// the reference debug view draws the difference to the one of the view on screen.
    pub reference: Option<PathBuf>,
    /// `--preview`: the material preview room instead of `scene`, its ball's material edited
    /// live in the panel.
    pub preview: Option<ViewerPreview>,
}

/// The material preview of `valgi view --preview`: the room of `valgi preview` with one ball.
#[derive(Clone, Debug)]
pub struct ViewerPreview {
    pub material: crate::preview::PreviewMaterial,
    pub ball: crate::preview::BallShape,
}

/// Longest triangle edge of the preview room and ball unless `--max-edge` is given, metres
/// (`valgi preview`'s).
pub const PREVIEW_MAX_EDGE: f32 = 0.05;

/// The live preview: the ball's mesh (made once) and the material on it now.
struct PreviewLive {
    ball: crate::scene::Mesh,
    material: crate::preview::PreviewMaterial,
    max_edge: f32,
}

impl PreviewLive {
    fn scene(&self) -> Scene {
        crate::preview::preview_scene("preview", &self.material, &self.ball, self.max_edge)
    }
}

/// The preview material with `key` (`roughness`, `metallic`, `specular`, `base`) set to
/// `value` as `valgi preview --sweep` reads it (a number in 0..=1; `base`: R/G/B or a grey).
pub fn edit_preview_material(
    material: &crate::scene::Material,
    key: &str,
    value: &str,
) -> Result<crate::scene::Material, String> {
    let sweep = crate::preview::Sweep::parse(&format!("{key}={value}"))
        .map_err(|e| format!("material.{key}={value}: {e}"))?;
    let base = crate::preview::PreviewMaterial::plain("preview", material.clone());
    match sweep.materials(&base).as_slice() {
        [one] => Ok(one.material.clone()),
        many => Err(format!(
            "material.{key}={value}: one value expected, got {}",
            many.len()
        )),
    }
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PresentParams {
    pub exposure_scale: f32,
    pub components: u32,
    pub encode_srgb: u32,
    pub difference: u32,
    pub origin: [u32; 2],
    pub size: [u32; 2],
}

/// The viewer's structs shared with WGSL.
pub fn shared_layouts() -> Vec<SharedLayout> {
    vec![
        shared_layout!(
            "PresentParams",
            "present.wgsl",
            PresentParams,
            [
                exposure_scale,
                components,
                encode_srgb,
                difference,
                origin,
                size
            ]
        ),
        shared_layout!(
            "DebugOccluderParams",
            "vals_debug_occluders.wgsl",
            debug::DebugOccluderParams,
            [point, point_count, segments, pad0]
        ),
        shared_layout!(
            "DebugSplatParams",
            "vals_debug_splats.wgsl",
            debug::DebugSplatParams,
            [
                exposure_scale,
                encode_srgb,
                splat_pixels,
                instance_count,
                size,
                pad0
            ]
        ),
    ]
}

/// What the panel changes; applied after the UI pass.
enum Action {
    SetMethod(&'static str),
    /// The preview ball's new material.
    SetMaterial(crate::scene::Material),
    SetOption(&'static str, String),
    /// Back to a scene camera (`None`: the first).
    ResetCamera(Option<String>),
    SetDragMode(DragMode),
    Screenshot,
}

/// A method built on a worker thread with the scene it was built for, or why it could not be.
type Built = Result<(Box<dyn Method>, Arc<Scene>), String>;

/// The worker of the rebuild in flight: its generation and where its method arrives.
struct Worker {
    generation: u64,
    receiver: mpsc::Receiver<Built>,
}

/// How often the panel's changing readouts (frame times, pass timings, figures) are
/// refreshed: between refreshes an idle panel draws the same shapes, and its cached layer
/// ([`panel_layer::PanelLayer`]) is reused.
const READOUT_INTERVAL: std::time::Duration = std::time::Duration::from_millis(250);

/// The readouts the panel shows, as of their last refresh.
#[derive(Clone, Debug, Default)]
struct Readout {
    history: std::collections::VecDeque<f32>,
    frame_ms: f64,
    timings: FrameTimings,
    figures: Figures,
    taken: Option<Instant>,
}

impl Readout {
    fn is_due(&self, now: Instant) -> bool {
        self.taken
            .is_none_or(|taken| now.duration_since(taken) >= READOUT_INTERVAL)
    }
}

/// The numbers of the render JSON line that the panel shows, from the last frame.
#[derive(Clone, Debug, Default, PartialEq)]
struct Figures {
    /// GPU bytes the method and the views' targets own (`gpu_bytes`).
    gpu_bytes: u64,
    /// VALs of the last update (`vals`), sparse points (`sparse_points`) and the points that
    /// clamped their (diffuse, glossy) renormalization (`renormalize_clamped`), for methods
    /// that have them.
    vals: Option<u64>,
    sparse_points: Option<u64>,
    renormalize_clamped: Option<(u64, u64)>,
}

impl Figures {
    fn of(method: &dyn Method, views: &[View], results: &[ViewResult]) -> Self {
        let report = method.report();
        let count = |key: &str| report.get(key).and_then(|v| v.as_u64());
        let clamps = report.get("renormalize_clamped").and_then(|v| {
            let pair = v.as_array()?;
            Some((pair.first()?.as_u64()?, pair.get(1)?.as_u64()?))
        });
        Self {
            // As `render`'s report counts it: the method's own bytes and each view's.
            gpu_bytes: method.gpu_bytes()
                + views
                    .iter()
                    .zip(results)
                    .map(|(v, r)| r.view_bytes(v))
                    .sum::<u64>(),
            vals: count("vals"),
            sparse_points: count("sparse_points"),
            renormalize_clamped: clamps,
        }
    }
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
    if request.anaglyph
        && request
            .views
            .views(&dummy_camera(), (1, 1), Vec3::ZERO)
            .len()
            != 2
    {
        return Err(RenderError::Settings(
            "--anaglyph needs a two-view rig (--views stereo[:IPD])".into(),
        )
        .into());
    }
    if let Some(path) = &request.screenshot {
        crate::image_io::prepare_output(path).map_err(AppError::from)?;
    }
    let aspect = request.settings.width as f32 / request.settings.height as f32;
    let (scene, tessellation, camera, preview) = match &request.preview {
        Some(p) => {
            if !request.edits.is_empty() {
                return Err(RenderError::Settings(
                    "--preview builds its own room: --light, --camera-eye and the other scene edits do not apply".into(),
                )
                .into());
            }
            let max_edge = request.max_edge.unwrap_or(PREVIEW_MAX_EDGE);
            let live = PreviewLive {
                ball: crate::preview::ball_mesh(p.ball, max_edge)
                    .map_err(|e| ViewerError::App(e.into()))?,
                material: p.material.clone(),
                max_edge,
            };
            let tessellation = crate::app::Tessellation {
                max_edge,
                source: if request.max_edge.is_some() {
                    "option"
                } else {
                    "default"
                },
                used_max_edge: Some(max_edge),
                why: match request.max_edge {
                    Some(_) => "given (--max-edge)".to_string(),
                    None => format!("{max_edge} m, the preview ball's tessellation"),
                },
            };
            (
                live.scene(),
                tessellation,
                request.camera.clone(),
                Some(live),
            )
        }
        None => {
            let (scene, tessellation, camera) = crate::app::load_scene_edited(
                &request.scene,
                &[(request.method.as_str(), &request.options)],
                request.max_edge,
                request.allow_external_paths,
                request.emitter_lights,
                (&request.edits, request.camera.as_deref(), aspect),
            )
            .map_err(ViewerError::App)?;
            (scene, tessellation, camera, None)
        }
    };
    // From here on the request names the camera the edits chose; the preview's methods get
    // `valgi preview`'s defaults (RSM 32², adaptive visibility rays) unless given.
    let request = &ViewerRequest {
        camera,
        options: match &preview {
            Some(_) => crate::preview::preview_options(&request.method, &request.options),
            None => request.options.clone(),
        },
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
        scene: Arc::new(scene),
        preview,
        tessellation,
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
    /// Shared with the rebuild workers; a preview's material edit replaces it when the
    /// method built for the edited scene lands.
    scene: Arc<Scene>,
    /// `--preview`: handed to the window's state when it opens.
    preview: Option<PreviewLive>,
    /// How the scene was tessellated when it was loaded (reported as `render` reports it).
    tessellation: crate::app::Tessellation,
    running: Option<Running>,
    error: Option<ViewerError>,
    report: Option<serde_json::Value>,
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.running.is_some() {
            return;
        }
        match Running::new(event_loop, &self.request, &self.scene, self.preview.take()) {
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
                self.report = Some(running.report(&self.scene, &self.tessellation));
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
                        if code == KeyCode::F12 && !event.repeat {
                            running.pending_actions.push(Action::Screenshot);
                        }
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
            WindowEvent::MouseWheel { delta, .. } if !consumed => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    // Pixel deltas (touchpads): about 50 pixels per line.
                    MouseScrollDelta::PixelDelta(p) => p.y as f32 / 50.0,
                };
                let (current, pivot) = (running.camera_now, running.pivot);
                running.state.wheel(&current, pivot, lines);
            }
            WindowEvent::CursorMoved { position, .. } => {
                let now = (position.x as f32, position.y as f32);
                if let (true, Some(last)) = (running.dragging, running.cursor) {
                    let (current, pivot) = (running.camera_now, running.pivot);
                    running
                        .state
                        .drag(&current, pivot, now.0 - last.0, now.1 - last.1);
                }
                running.cursor = Some(now);
            }
            WindowEvent::RedrawRequested => match running.redraw(&mut self.scene) {
                Ok(done) => {
                    if done {
                        self.report = Some(running.report(&self.scene, &self.tessellation));
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

/// The present pass's pipelines: all channels, and the two eyes of an anaglyph (red from the
/// left eye, green and blue from the right, by the colour target's write mask).
struct PresentPipelines {
    full: wgpu::RenderPipeline,
    red: wgpu::RenderPipeline,
    cyan: wgpu::RenderPipeline,
}

struct Running {
    request: ViewerRequest,
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    /// Shared with the rebuild workers (wgpu's device and queue are `Send + Sync`).
    ctx: Arc<GpuContext>,
    method_name: &'static str,
    options: MethodOptions,
    edits: BTreeMap<&'static str, String>,
    method_error: Option<String>,
    /// `None` until the first build is in.
    method: Option<Box<dyn Method>>,
    worker: Option<Worker>,
    views: Vec<View>,
    results: Vec<ViewResult>,
    present_layout: GroupLayout,
    present: PresentPipelines,
    present_targets: Vec<PresentTarget>,
    debug_overlay: debug::DebugOverlay,
    /// This frame's debug draws, per view.
    debug_draws: Vec<Vec<debug::DebugDraw>>,
    /// What lies under the cursor (the links and occluder views), and the pixel, camera and
    /// time it was picked for.
    pick: Option<DebugPick>,
    pick_for: Option<(u32, u32, [u32; 16], u32)>,
    reference: reference::ReferenceOverlay,
    /// `--preview`: the ball and the material on screen (or on its way, with a rebuild).
    preview: Option<PreviewLive>,
    /// Whether the first view draws its difference to the reference this frame.
    reference_on: bool,
    /// Whether the running method has a light atlas, and draws its debug view this frame.
    atlas_available: bool,
    atlas_on: bool,
    egui_ctx: egui::Context,
    egui_state: egui_winit::State,
    egui_renderer: egui_wgpu::Renderer,
    panel: panel_layer::PanelLayer,
    readout: Readout,
    state: ViewerState,
    /// The rig's camera of the last frame (before the rig offsets its views) and the scene
    /// centre: where drags and the wheel start from.
    camera_now: Mat4,
    yfov_now: f32,
    pivot: Vec3,
    keys_down: HashSet<KeyCode>,
    dragging: bool,
    cursor: Option<(f32, f32)>,
    /// Input handled between redraws (the screenshot key).
    pending_actions: Vec<Action>,
    timings: FrameTimings,
    figures: Figures,
    /// CPU wall time of the last frame's record and submit, ms.
    frame_ms: f64,
    /// Interval between the starts of the last two redraws, ms.
    frame_interval_ms: f64,
    frames_done: u32,
    /// Sum over the frames drawn of the passes' total (the `frame_total_ms` that `render
    /// --frames` lists), ms: the window path's overhead is the frame interval beyond it.
    pass_total_sum_ms: f64,
    last_redraw: Instant,
    screenshots_written: Vec<PathBuf>,
}

impl Running {
    fn new(
        event_loop: &ActiveEventLoop,
        request: &ViewerRequest,
        scene: &Arc<Scene>,
        preview: Option<PreviewLive>,
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
        let ctx = Arc::new(GpuContext::for_surface(&instance, &surface)?);
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
        let present = PresentPipelines {
            full: present_pipeline(&ctx, &present_layout.layout, format, wgpu::ColorWrites::ALL),
            red: present_pipeline(
                &ctx,
                &present_layout.layout,
                format,
                wgpu::ColorWrites::RED | wgpu::ColorWrites::ALPHA,
            ),
            cyan: present_pipeline(
                &ctx,
                &present_layout.layout,
                format,
                wgpu::ColorWrites::GREEN | wgpu::ColorWrites::BLUE,
            ),
        };
        let debug_overlay = debug::DebugOverlay::new(&ctx, format);
        let reference = reference::ReferenceOverlay::new(&ctx, request.reference.as_deref());
        let method_entry = method::entry(&request.method)?;

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
        let panel = panel_layer::PanelLayer::new(&ctx, format);
        let mut state = ViewerState::new(
            request.camera.clone(),
            request.time,
            request.exposure,
            scene.animation_duration(),
        );
        if request.anaglyph {
            state.stereo_display = StereoDisplay::Anaglyph;
        }
        state.debug = request.debug;
        state.material = preview.as_ref().map(|p| p.material.material.clone());
        let mut running = Self {
            request: request.clone(),
            window,
            surface,
            config,
            ctx,
            method_name: method_entry.name,
            options: request.options.clone(),
            edits: BTreeMap::new(),
            method_error: None,
            method: None,
            worker: None,
            views: vec![],
            results: vec![],
            present_layout,
            present,
            present_targets: vec![],
            debug_overlay,
            debug_draws: vec![],
            pick: None,
            pick_for: None,
            reference,
            preview,
            reference_on: false,
            atlas_available: false,
            atlas_on: false,
            egui_ctx,
            egui_state,
            egui_renderer,
            panel,
            readout: Readout::default(),
            state,
            camera_now: Mat4::IDENTITY,
            yfov_now: 1.0,
            pivot: Vec3::ZERO,
            keys_down: HashSet::new(),
            dragging: false,
            cursor: None,
            pending_actions: vec![],
            timings: FrameTimings::default(),
            figures: Figures::default(),
            frame_ms: 0.0,
            frame_interval_ms: 0.0,
            frames_done: 0,
            pass_total_sum_ms: 0.0,
            last_redraw: Instant::now(),
            screenshots_written: vec![],
        };
        running.reset_edits();
        running.make_views((s.width, s.height), scene)?;
        // The first build runs on the worker too: the window opens (and redraws its panel)
        // while the scene is preprocessed.
        let fallback = match &request.method_fallback {
            Some(name) => Some(method::entry(name)?.name),
            None => None,
        };
        running.start_rebuild_or(method_entry.name, fallback, request.options.clone(), scene);
        Ok(running)
    }

    /// Views of the rig at `size` each, side by side from the window's top-left corner.
    fn make_views(&mut self, size: (u32, u32), scene: &Scene) -> Result<(), ViewerError> {
        let world_from_node = scene.world_from_node_at(self.state.time);
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
            let group = self.present_group(&params, &view, self.present_targets.is_empty());
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

    /// The present pass's group of a view: its parameters, outputs, and (for the first view,
    /// the only one a reference can match) the reference textures.
    fn present_group(&self, params: &wgpu::Buffer, view: &View, first: bool) -> wgpu::BindGroup {
        let direct = view.targets.output_direct.create_view(&Default::default());
        let indirect = view
            .targets
            .output_indirect
            .create_view(&Default::default());
        let (ref_direct, ref_indirect) = match first {
            true => self.reference.textures(),
            false => (self.reference.empty(), self.reference.empty()),
        };
        self.present_layout.bind(
            &self.ctx.device,
            &[params, &direct, &indirect, ref_direct, ref_indirect],
        )
    }

    /// The view on screen as the reference lookup sees it.
    fn reference_view(&self, scene_time: f32) -> reference::ReferenceView {
        let size = self.views.first().map_or((0, 0), |v| (v.width, v.height));
        let unmatchable = if self.views.len() != 1 {
            Some("a cached reference is a mono image: use --views mono")
        } else if self.state.world_from_view().is_some() {
            Some("the camera was moved: reset to the scene camera for the reference")
        } else if self.state.yfov_degrees.is_some() {
            Some("the field of view is overridden: reset to the scene camera for the reference")
        } else {
            None
        };
        reference::ReferenceView {
            scene_key: crate::eval::reference_scene_key(&self.request.scene, &self.request.edits),
            camera: self.request.camera.clone(),
            size,
            time: scene_time,
            unmatchable,
        }
    }

    /// Picks the surface under the cursor (or `--pick`) in the view it lies in and asks the
    /// method what its solution does there; again only when the pixel, camera or time changed.
    fn update_pick(&mut self, scene: &Scene, world_from_node: &[Mat4]) {
        let Some((x, y)) = self.request.pick.or_else(|| {
            self.cursor
                .map(|(x, y)| (x.max(0.0) as u32, y.max(0.0) as u32))
        }) else {
            self.pick = None;
            return;
        };
        let region = self.present_targets.iter().position(|t| {
            (t.origin.0..t.origin.0 + t.size.0).contains(&x)
                && (t.origin.1..t.origin.1 + t.size.1).contains(&y)
        });
        let (Some(i), Some(method)) = (region, self.method.as_ref()) else {
            self.pick = None;
            self.pick_for = None;
            return;
        };
        let view = &self.views[i];
        let key = (
            x,
            y,
            view.camera
                .world_from_view
                .to_cols_array()
                .map(f32::to_bits),
            self.state.time.to_bits(),
        );
        if self.pick_for == Some(key) {
            return;
        }
        self.pick_for = Some(key);
        let t = &self.present_targets[i];
        let (origin, dir) = crate::reference::camera_ray(
            &view.camera,
            view.width,
            view.height,
            (x - t.origin.0) as f32 + 0.5,
            (y - t.origin.1) as f32 + 0.5,
        );
        self.pick = crate::scene::pick::pick(scene, world_from_node, origin, dir).and_then(|hit| {
            method.debug_pick(scene, world_from_node, &hit, view.camera.position())
        });
    }

    /// The scene's camera at this frame, or the flown or orbited one, with the field of
    /// view of the slider.
    fn base_camera(
        &self,
        scene: &Scene,
        size: (u32, u32),
        world_from_node: &[Mat4],
    ) -> Result<CameraView, ViewerError> {
        let mut camera = scene
            .camera_view(
                self.state.scene_camera.as_deref(),
                size.0 as f32 / size.1 as f32,
                world_from_node,
            )
            .map_err(AppError::from)?;
        if let Some(world_from_view) = self.state.world_from_view() {
            camera.world_from_view = world_from_view;
        }
        self.state.apply_fov(&mut camera);
        Ok(camera)
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

    /// Builds method `name` with `options` on a worker thread; the running method keeps
    /// drawing until it is in. A newer request supersedes this one (its method is dropped).
    fn start_rebuild(&mut self, name: &'static str, options: MethodOptions, scene: &Arc<Scene>) {
        self.start_rebuild_or(name, None, options, scene);
    }

    /// [`Self::start_rebuild`], building `fallback` instead when `name` cannot bake its atlas
    /// in memory (`RenderError::AtlasBake`, with a warning).
    fn start_rebuild_or(
        &mut self,
        name: &'static str,
        fallback: Option<&'static str>,
        options: MethodOptions,
        scene: &Arc<Scene>,
    ) {
        let size = self.views.first().map_or(
            (self.request.settings.width, self.request.settings.height),
            |v| (v.width, v.height),
        );
        let settings = RenderSettings {
            width: size.0,
            height: size.1,
            views_per_frame: self.views.len().max(1) as u32,
            ..self.request.settings
        };
        let generation = self.state.rebuilds.request(name, options.clone());
        let (sender, receiver) = mpsc::channel();
        let (ctx, scene) = (self.ctx.clone(), scene.clone());
        let spawned = std::thread::Builder::new()
            .name("valgi-rebuild".into())
            .spawn(move || {
                let built =
                    method::create_or(name, fallback, "viewing", &ctx, &scene, settings, &options)
                        .map(|m| (m, scene))
                        .map_err(|e| e.to_string());
                // The window may have closed, or a newer rebuild superseded this one.
                let _ = sender.send(built);
            });
        match spawned {
            Ok(_) => {
                self.worker = Some(Worker {
                    generation,
                    receiver,
                })
            }
            Err(e) => {
                self.state.rebuilds.finish(generation, false);
                self.method_error = Some(format!("cannot start the rebuild: {e}"));
            }
        }
    }

    /// Installs the worker's method when it is in, and returns the scene it was built for;
    /// on failure the running method stays and the panel shows why.
    fn poll_rebuild(&mut self) -> Option<Arc<Scene>> {
        let worker = self.worker.as_ref()?;
        let built = match worker.receiver.try_recv() {
            Ok(built) => built,
            Err(mpsc::TryRecvError::Empty) => return None,
            Err(mpsc::TryRecvError::Disconnected) => {
                Err("the rebuild stopped without a result (see the log)".to_string())
            }
        };
        let generation = worker.generation;
        self.worker = None;
        let done = self.state.rebuilds.finish(generation, built.is_ok())?;
        let landed = match built {
            Ok((m, scene)) => {
                // The method built: the request's, or its fallback.
                self.method_name = m.name();
                self.method = Some(m);
                self.options = done.options;
                self.method_error = None;
                Some(scene)
            }
            Err(e) => {
                self.method_error = Some(e);
                None
            }
        };
        self.reset_edits();
        landed
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
    fn redraw(&mut self, scene: &mut Arc<Scene>) -> Result<bool, ViewerError> {
        let now = Instant::now();
        let scripted = self.request.frames.is_some();
        self.frame_interval_ms = (now - self.last_redraw).as_secs_f64() * 1000.0;
        let dt = if scripted {
            SCRIPTED_FRAME_S
        } else {
            (self.frame_interval_ms as f32 / 1000.0).min(0.25)
        };
        let previous = std::mem::replace(&mut self.last_redraw, now);
        // Charged before the poll: the interval in which the rebuild landed was waited
        // through while it ran. The first build counts too (the panel is drawn meanwhile).
        self.state.rebuilds.note_frame(previous, now);
        if let Some(landed) = self.poll_rebuild() {
            // The method was built for this scene (a preview's edited material).
            *scene = landed;
        }
        let scene: &Arc<Scene> = scene;
        // A scripted run whose method never built has nothing to draw: it would wait forever.
        if scripted && self.method.is_none() && self.state.rebuilds.pending().is_none() {
            if let Some(e) = &self.method_error {
                return Err(
                    RenderError::Settings(format!("method {}: {e}", self.method_name)).into(),
                );
            }
        }
        self.walk(dt);
        if self.frames_done > 0 {
            self.state.advance(dt, !scripted);
        }
        let world_from_node = scene.world_from_node_at(self.state.time);
        let size = self.views.first().map_or((1, 1), |v| (v.width, v.height));
        let camera = self.base_camera(scene, size, &world_from_node)?;
        self.pivot = scene_pivot(scene, &world_from_node, &camera);
        self.camera_now = camera.world_from_view;
        self.yfov_now = camera.yfov;
        let rig = self.request.views.views(&camera, size, self.pivot);
        for (view, r) in self.views.iter_mut().zip(rig) {
            view.camera = r.camera;
        }
        let started = Instant::now();
        let drawing = self.method.is_some();
        if let Some(method) = self.method.as_mut() {
            // Set every frame: a rebuilt method starts with it off.
            self.atlas_available = method.set_debug_atlas(self.state.debug.atlas);
            self.atlas_on = self.atlas_available && self.state.debug.atlas;
            let frame = record_frame(
                method.as_mut(),
                &self.ctx,
                scene,
                &world_from_node,
                &self.views,
            )?;
            self.results = frame.results;
            self.timings = frame.timings;
            self.pass_total_sum_ms += self.timings.merged().total_ms();
            self.figures = Figures::of(method.as_ref(), &self.views, &self.results);
        }
        if self.state.debug.needs_pick() {
            self.update_pick(scene, &world_from_node);
        } else {
            (self.pick, self.pick_for) = (None, None);
        }
        self.reference_on = false;
        if self.state.debug.reference {
            let wanted = self.reference_view(self.state.time);
            if self.reference.update(&self.ctx, &wanted) {
                if let (Some(target), Some(view)) =
                    (self.present_targets.first(), self.views.first())
                {
                    let group = self.present_group(&target.params, view, true);
                    self.present_targets[0].group = group;
                }
            }
            // An unmatchable view has nothing loaded (`ReferenceOverlay::update`).
            self.reference_on = self.reference.key().is_some();
        }

        let raw_input = self.egui_state.take_egui_input(&self.window);
        let mut actions = std::mem::take(&mut self.pending_actions);
        if self.readout.is_due(now) {
            self.readout = Readout {
                history: self.state.frame_ms_history.clone(),
                frame_ms: self.frame_ms,
                timings: self.timings.clone(),
                figures: self.figures.clone(),
                taken: Some(now),
            };
        }
        let mut full = {
            let mut panel = PanelData {
                method_name: self.method_name,
                edits: &mut self.edits,
                method_error: self.method_error.as_deref(),
                state: &mut self.state,
                readout: &self.readout,
                cameras: scene
                    .cameras
                    .iter()
                    .enumerate()
                    .map(|(i, c)| format!("{i}: {}", c.name))
                    .collect(),
                yfov_degrees: self.yfov_now.to_degrees(),
                two_views: self.views.len() == 2,
                view_names: self.views.iter().map(|v| v.name.clone()).collect(),
                screenshots: &self.screenshots_written,
                debug_available: self.method.as_ref().map_or_else(DebugViews::default, |m| {
                    let points = m.debug_points().is_some();
                    DebugViews {
                        points,
                        vals: m.debug_vals().is_some(),
                        links: points,
                        occluders: points,
                        reference: self.request.reference.is_some(),
                        atlas: self.atlas_available,
                    }
                }),
                reference_note: if self.reference_on {
                    format!("reference: {}", self.reference.key().unwrap_or_default())
                } else {
                    self.reference.note().to_string()
                },
                pick: self.pick.as_ref(),
            };
            self.egui_ctx
                .run_ui(raw_input, |ui| panel.show(ui, &mut actions))
        };
        // Keep redrawing while a rebuild runs, so the spinner turns and the result lands.
        self.egui_state
            .handle_platform_output(&self.window, full.platform_output);
        let pixels_per_point = full.pixels_per_point;
        let size = (self.config.width, self.config.height);
        let panel_stale = self.panel.is_stale(
            &full.shapes,
            !full.textures_delta.set.is_empty(),
            size,
            pixels_per_point,
        );
        let panel_shapes = std::mem::take(&mut full.shapes);
        let jobs = if panel_stale {
            self.egui_ctx
                .tessellate(panel_shapes.clone(), pixels_per_point)
        } else {
            self.panel.reuse();
            vec![]
        };
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
        self.debug_draws = match &self.method {
            Some(method) if self.state.debug.any_overlay() && !self.anaglyph() => {
                self.debug_overlay.prepare(
                    &self.ctx,
                    method.as_ref(),
                    &self.views,
                    self.state.debug,
                    self.pick.as_ref(),
                    2f32.powf(self.state.exposure),
                    !self.config.format.is_srgb(),
                )
            }
            _ => vec![],
        };

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
        if panel_stale {
            self.egui_renderer.update_buffers(
                &self.ctx.device,
                &self.ctx.queue,
                &mut encoder,
                &jobs,
                &screen,
            );
            self.panel.redraw(
                &self.ctx,
                &mut encoder,
                &self.egui_renderer,
                &jobs,
                &screen,
                panel_shapes,
            );
        }
        if let Some(output) = &output {
            let target = output.texture.create_view(&Default::default());
            self.draw(&mut encoder, &target);
        }
        // A scripted run ends after its frames once no rebuild is in flight.
        let last = drawing
            && self.state.rebuilds.pending().is_none()
            && self
                .request
                .frames
                .is_some_and(|n| self.frames_done + 1 >= n);
        let key_shot = actions.iter().any(|a| matches!(a, Action::Screenshot));
        let shot_path = match (&self.request.screenshot, last) {
            (Some(path), true) => Some(path.clone()),
            _ if key_shot => {
                let dir = std::env::current_dir().unwrap_or_else(|_| PathBuf::from("."));
                Some(self.state.next_screenshot_path(&dir))
            }
            _ => None,
        };
        let shot = shot_path.as_ref().map(|_| self.offscreen_target());
        if let Some(texture) = &shot {
            let target = texture.create_view(&Default::default());
            self.draw(&mut encoder, &target);
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
        if drawing {
            self.state.push_frame_ms(self.frame_interval_ms as f32);
            self.frames_done += 1;
        }
        if let (Some(texture), Some(path)) = (shot, shot_path) {
            self.write_screenshot(&texture, &path)?;
            self.screenshots_written.push(path);
        }
        if scripted && self.frames_done == 1 && drawing {
            if let Some((key, value)) = self.request.change_option.clone() {
                if key == "method" {
                    // The panel's method menu: a new method with its default options.
                    actions.push(Action::SetMethod(method::entry(&value)?.name));
                } else if let Some(field) = key.strip_prefix("material.") {
                    // The preview panel's material knobs.
                    let preview = self.preview.as_ref().ok_or_else(|| {
                        RenderError::Settings(format!("--change-option {key}: needs --preview"))
                    })?;
                    let material = edit_preview_material(&preview.material.material, field, &value)
                        .map_err(RenderError::Settings)?;
                    actions.push(Action::SetMaterial(material));
                } else {
                    let spec = method::entry(self.method_name)?
                        .options
                        .iter()
                        .find(|o| o.name == key)
                        .ok_or_else(|| {
                            RenderError::Settings(format!(
                                "--change-option: method '{}' has no option '{key}'",
                                self.method_name
                            ))
                        })?;
                    actions.push(Action::SetOption(spec.name, value));
                }
            }
        }
        for action in actions {
            self.apply(action, scene);
        }
        Ok(last)
    }

    fn apply(&mut self, action: Action, scene: &Arc<Scene>) {
        // A preview builds every method for its newest material, which a rebuild in flight
        // may not have landed yet.
        let scene = match &self.preview {
            Some(p) => &Arc::new(p.scene()),
            None => scene,
        };
        // Options of the newest request, so quick successive edits accumulate.
        let (newest_method, newest_options) = match self.state.rebuilds.pending() {
            Some(p) => (p.method, p.options.clone()),
            None => (self.method_name, self.options.clone()),
        };
        match action {
            Action::SetMethod(name) => {
                let options = match self.preview {
                    Some(_) => crate::preview::preview_options(name, &MethodOptions::default()),
                    None => MethodOptions::default(),
                };
                self.start_rebuild(name, options, scene)
            }
            Action::SetOption(key, value) => {
                let mut options = newest_options;
                options.set(key, value);
                self.start_rebuild(newest_method, options, scene);
            }
            Action::SetMaterial(material) => {
                if let Some(p) = &mut self.preview {
                    self.state.material = Some(material.clone());
                    p.material.material = material;
                    let edited = Arc::new(p.scene());
                    self.start_rebuild(newest_method, newest_options, &edited);
                }
            }
            Action::ResetCamera(selector) => self.state.reset_to(selector),
            Action::SetDragMode(mode) => {
                let (current, pivot) = (self.camera_now, self.pivot);
                self.state.set_drag_mode(mode, &current, pivot);
            }
            // Taken in `redraw`, which draws the offscreen copy.
            Action::Screenshot => {}
        }
    }

    /// WASD (and Q/E down/up) at the speed knob, metres per second.
    fn walk(&mut self, dt: f32) {
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
        let (current, pivot) = (self.camera_now, self.pivot);
        self.state.walk(&current, pivot, local, dt);
    }

    /// Whether the two views are drawn as one anaglyph.
    fn anaglyph(&self) -> bool {
        self.state.stereo_display == StereoDisplay::Anaglyph && self.present_targets.len() == 2
    }

    fn write_present_params(&self) {
        let encode_srgb = !self.config.format.is_srgb() as u32;
        let anaglyph = self.anaglyph();
        for (i, target) in self.present_targets.iter().enumerate() {
            // An anaglyph draws both eyes into the first region.
            let origin = if anaglyph {
                self.present_targets[0].origin
            } else {
                target.origin
            };
            let params = PresentParams {
                // The atlas view's colours are display values in the indirect image.
                exposure_scale: if self.atlas_on {
                    1.0
                } else {
                    2f32.powf(self.state.exposure)
                },
                components: if self.atlas_on {
                    Components::Indirect.bits()
                } else {
                    self.state.components.bits()
                },
                encode_srgb,
                difference: (i == 0 && self.reference_on) as u32,
                origin: [origin.0, origin.1],
                size: [target.size.0, target.size.1],
            };
            self.ctx
                .queue
                .write_buffer(&target.params, 0, bytemuck::bytes_of(&params));
        }
    }

    /// The views into their regions, then the panel's layer, into `target` (the window's
    /// format).
    fn draw(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView) {
        let mut pass = colour_pass(
            encoder,
            "present",
            wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            },
        );
        let (w, h) = (self.config.width, self.config.height);
        let anaglyph = self.anaglyph();
        for (i, t) in self.present_targets.iter().enumerate() {
            let (origin, pipeline) = match (anaglyph, i) {
                (false, _) => (t.origin, &self.present.full),
                (true, 0) => (t.origin, &self.present.red),
                (true, _) => (self.present_targets[0].origin, &self.present.cyan),
            };
            // Regions that the window no longer covers (mid-resize) are skipped.
            if origin.0 + t.size.0 > w || origin.1 + t.size.1 > h {
                continue;
            }
            pass.set_viewport(
                origin.0 as f32,
                origin.1 as f32,
                t.size.0 as f32,
                t.size.1 as f32,
                0.0,
                1.0,
            );
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, &t.group, &[]);
            pass.draw(0..3, 0..1);
            // Debug splats over the view, clipped to its region by the viewport.
            if let Some(draws) = self.debug_draws.get(i) {
                self.debug_overlay.draw(&mut pass, draws);
            }
        }
        self.panel.composite(&mut pass);
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

    /// The JSON report: the last frame's passes and figures, as `valgi render` prints them.
    fn report(&self, scene: &Scene, tessellation: &crate::app::Tessellation) -> serde_json::Value {
        let merged = self.timings.merged();
        let mut report = serde_json::json!({
            "scene": scene.name,
            "method": self.method.as_ref().map(|m| m.name()),
            "options": self.options.to_string(),
            "views": self.views.iter().map(|v| v.name.clone()).collect::<Vec<_>>(),
            "view_size": self.views.first().map(|v| [v.width, v.height]),
            "stereo_display": if self.anaglyph() { "anaglyph" } else { "side-by-side" },
            // Debug views on, the overlay draws the last frame recorded (over all views), what
            // was picked for the links and occluder views, and the reference on screen.
            "debug": {
                "points": self.state.debug.points,
                "vals": self.state.debug.vals,
                "links": self.state.debug.links,
                "occluders": self.state.debug.occluders,
                "reference": self.state.debug.reference,
                "atlas": self.atlas_on,
                "draws": self.debug_draws.iter().map(Vec::len).sum::<usize>(),
                "pick": self.pick.as_ref().map(|p| serde_json::json!({
                    "vertex": p.vertex.to_array(),
                    "links": p.links.iter().map(|(q, w)| serde_json::json!({
                        "point": q.to_array(),
                        "weight": w,
                    })).collect::<Vec<_>>(),
                    "point": p.point.map(|(i, q)| serde_json::json!({
                        "index": i,
                        "position": q.to_array(),
                    })),
                })),
                "reference_key": if self.reference_on { self.reference.key() } else { None },
                "reference_note": self.reference.note(),
            },
            "frames": self.frames_done,
            "surface_format": format!("{:?}", self.config.format),
            "adapter": self.ctx.adapter_label(),
            "passes": merged.to_json(),
            "total_ms": round3(merged.total_ms()),
            "solution_ms": round3(self.timings.solution.total_ms()),
            "view_ms": self.timings.views.iter().map(|t| round3(t.total_ms())).collect::<Vec<_>>(),
            "gpu_bytes": self.figures.gpu_bytes,
            // Interval between the starts of successive redraws (the window's frame time):
            // the mean over the history and the longest.
            "frame_interval_ms": {
                "frames": self.state.frame_ms_history.len(),
                "mean": round3(mean(self.state.frame_ms_history.iter().map(|&v| v as f64))),
                "max": round3(self.state.frame_ms_history.iter().fold(0.0f32, |a, &b| a.max(b)) as f64),
            },
            "pass_total_ms_mean": round3(self.pass_total_sum_ms / self.frames_done.max(1) as f64),
            // Frames that drew the panel's layer, and frames that composited it as it was.
            "panel_layer": {"redraws": self.panel.redraws, "reuses": self.panel.reuses},
            "screenshot": self.request.screenshot.as_ref().map(|p| p.display().to_string()),
        });
        if let Some(r) = &self.state.rebuilds.last {
            report["rebuild"] = serde_json::json!({
                "method": r.method,
                "ok": r.ok,
                "ms": round3(r.ms),
                "ui_frames": r.frames,
                "longest_ui_frame_ms": round3(r.longest_frame_ms),
            });
        }
        if let Some(obj) = report.as_object_mut() {
            obj.extend(tessellation.to_json());
        }
        if let (Some(obj), Some(method)) = (report.as_object_mut(), &self.method) {
            for (key, value) in method.report() {
                obj.entry(key).or_insert(value);
            }
        }
        report
    }
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 {
        0.0
    } else {
        sum / n as f64
    }
}

/// A render pass into one colour attachment, free of the encoder's borrow (egui's renderer
/// takes a `'static` pass).
fn colour_pass(
    encoder: &mut wgpu::CommandEncoder,
    label: &str,
    attachment: wgpu::RenderPassColorAttachment<'_>,
) -> wgpu::RenderPass<'static> {
    encoder
        .begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(attachment)],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
        .forget_lifetime()
}

/// What the panel shows and edits.
struct PanelData<'a> {
    method_name: &'static str,
    edits: &'a mut BTreeMap<&'static str, String>,
    method_error: Option<&'a str>,
    state: &'a mut ViewerState,
    /// Frame times, pass timings and figures as of their last refresh.
    readout: &'a Readout,
    /// The scene's cameras, "index: name".
    cameras: Vec<String>,
    /// The field of view on screen, degrees.
    yfov_degrees: f32,
    two_views: bool,
    view_names: Vec<String>,
    screenshots: &'a [PathBuf],
    /// The debug views the running method can draw.
    debug_available: DebugViews,
    /// The reference on screen, or why there is none.
    reference_note: String,
    /// What the links and occluder views show.
    pick: Option<&'a DebugPick>,
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
        self.figures_ui(ui);
        ui.separator();
        self.method_ui(ui, actions);
        ui.separator();
        self.material_ui(ui, actions);
        ui.add(egui::Slider::new(&mut self.state.exposure, -8.0..=8.0).text("exposure (stops)"));
        ui.horizontal(|ui| {
            let c = &mut self.state.components;
            ui.radio_value(c, Components::Direct, "direct");
            ui.radio_value(c, Components::Indirect, "indirect");
            ui.radio_value(c, Components::Both, "both");
        });
        self.debug_ui(ui);
        if self.two_views {
            ui.horizontal(|ui| {
                let d = &mut self.state.stereo_display;
                ui.radio_value(d, StereoDisplay::SideBySide, "side by side");
                ui.radio_value(d, StereoDisplay::Anaglyph, "anaglyph");
            });
        }
        ui.separator();
        self.camera_ui(ui, actions);
        ui.separator();
        self.passes_ui(ui);
    }

    /// The debug views' toggles; a method without points or VALs greys its box out.
    fn debug_ui(&mut self, ui: &mut egui::Ui) {
        let available = self.debug_available;
        let debug = &mut self.state.debug;
        ui.horizontal(|ui| {
            ui.label("debug:");
            ui.add_enabled(
                available.points,
                egui::Checkbox::new(&mut debug.points, "sparse points"),
            )
            .on_hover_text(
                "splats coloured by the first-bounce radiance E/π of the point's diffuse light",
            );
            ui.add_enabled(available.vals, egui::Checkbox::new(&mut debug.vals, "VALs"))
                .on_hover_text("splats coloured by the disc radiance Φ/(π·A)");
        });
        ui.horizontal(|ui| {
            ui.add_enabled(available.links, egui::Checkbox::new(&mut debug.links, "links"))
                .on_hover_text(
                    "the vertex under the cursor and its 8 links, brighter with more weight (blue: weight 0)",
                );
            ui.add_enabled(
                available.occluders,
                egui::Checkbox::new(&mut debug.occluders, "occluders"),
            )
            .on_hover_text(
                "the light spheres of the point under the cursor (yellow diffuse, cyan glossy) and the occluder discs that cover the diffuse one (redder: larger share)",
            );
            ui.add_enabled(
                available.reference,
                egui::Checkbox::new(&mut debug.reference, "reference diff"),
            )
            .on_hover_text(
                "luminance of the image minus the cached path-traced reference's: red brighter, blue darker (--reference DIR)",
            );
        });
        ui.add_enabled(available.atlas, egui::Checkbox::new(&mut debug.atlas, "atlas"))
            .on_hover_text(
                "the light atlas in place of its light: a hue per chart, a checkerboard of its texels, magenta where the texel holds no surface, paler where the lookup crosses a seam or cut",
            );
        if debug.needs_pick() {
            match self.pick {
                Some(p) => ui.label(format!(
                    "vertex {:.2?}: {} links{}",
                    p.vertex.to_array(),
                    p.links.len(),
                    p.point
                        .map_or(String::new(), |(i, _)| format!(", point {i}"))
                )),
                None => ui.label("point at a surface of a view"),
            };
        }
        if debug.reference && !self.reference_note.is_empty() {
            ui.label(egui::RichText::new(&self.reference_note).small());
        }
    }

    /// Frame time with its history plot and the counts of the render JSON line.
    fn figures_ui(&self, ui: &mut egui::Ui) {
        let history = &self.readout.history;
        ui.label(format!(
            "frame {:.1} ms (interval), record + submit {:.1} ms",
            history.back().copied().unwrap_or(0.0),
            self.readout.frame_ms
        ));
        frame_plot(ui, history);
        let f = &self.readout.figures;
        ui.label(format!(
            "GPU bytes {:.1} MiB",
            f.gpu_bytes as f64 / 1048576.0
        ));
        if let Some(vals) = f.vals {
            ui.label(format!("VALs {vals}"));
        }
        if let Some(points) = f.sparse_points {
            ui.label(format!("sparse points {points}"));
        }
        if let Some((d, s)) = f.renormalize_clamped {
            ui.label(format!("renormalize clamps {d} diffuse, {s} glossy"));
        }
        if let Some(last) = self.screenshots.last() {
            ui.label(format!("F12 wrote {}", last.display()));
        } else {
            ui.label("F12: screenshot");
        }
    }

    /// `--preview`: the ball's base colour, roughness, metallic and specular factor. A knob
    /// let go (or changed by a click or the keyboard) rebuilds the method for the edited
    /// material off the UI thread; dragging only moves the knob.
    fn material_ui(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        let Some(material) = &mut self.state.material else {
            return;
        };
        ui.label("material");
        let mut commit = false;
        let mut knob = |ui: &mut egui::Ui, value: &mut f32, label: &str| {
            let r = ui.add(egui::Slider::new(value, 0.0..=1.0).text(label));
            commit |= r.drag_stopped() || (r.changed() && !r.dragged());
        };
        let base = &mut material.base_color;
        let mut rgb = [base.x, base.y, base.z];
        for (value, label) in rgb.iter_mut().zip(["base red", "base green", "base blue"]) {
            knob(ui, value, label);
        }
        (base.x, base.y, base.z) = (rgb[0], rgb[1], rgb[2]);
        knob(ui, &mut material.roughness, "roughness");
        knob(ui, &mut material.metallic, "metallic");
        knob(ui, &mut material.specular_factor, "specular");
        if commit {
            actions.push(Action::SetMaterial(material.clone()));
        }
        ui.separator();
    }

    fn method_ui(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
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
        if let Some(p) = self.state.rebuilds.pending() {
            ui.horizontal(|ui| {
                ui.spinner();
                ui.label(format!(
                    "building {} … {:.1} s",
                    p.method,
                    p.started.elapsed().as_secs_f32()
                ));
            });
            // The worker's own step, where it reports one (an atlas bake's stages): how much
            // of it is done.
            if let Some(step) = crate::progress::latest() {
                ui.add(
                    egui::ProgressBar::new(step.fraction())
                        .text(format!("{} {}/{}", step.message, step.done, step.len)),
                );
            }
        } else if let Some(r) = &self.state.rebuilds.last {
            ui.label(format!(
                "last build {:.0} ms, longest UI frame meanwhile {:.0} ms",
                r.ms, r.longest_frame_ms
            ));
        }
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
    }

    fn camera_ui(&mut self, ui: &mut egui::Ui, actions: &mut Vec<Action>) {
        ui.horizontal(|ui| {
            let mut mode = self.state.drag_mode;
            ui.radio_value(&mut mode, DragMode::Fly, "fly");
            ui.radio_value(&mut mode, DragMode::Orbit, "orbit");
            if mode != self.state.drag_mode {
                actions.push(Action::SetDragMode(mode));
            }
        });
        ui.label(match self.state.drag_mode {
            DragMode::Fly => "WASD, Q/E down/up, drag to turn, wheel: speed",
            DragMode::Orbit => "drag to orbit the centre, wheel to zoom, WASD/QE pan",
        });
        ui.add(
            egui::Slider::new(&mut self.state.speed, 0.01..=100.0)
                .logarithmic(true)
                .text("speed (m/s)"),
        );
        let mut fov = self.yfov_degrees;
        if ui
            .add(egui::Slider::new(&mut fov, FOV_RANGE_DEGREES).text("field of view (°)"))
            .changed()
        {
            self.state.yfov_degrees = Some(fov);
        }
        let current = self.state.scene_camera.clone();
        let selected = match &current {
            None => "first".to_string(),
            Some(s) => s.clone(),
        };
        egui::ComboBox::from_label("reset to camera")
            .selected_text(selected)
            .show_ui(ui, |ui| {
                if self.cameras.is_empty() && ui.selectable_label(false, "default").clicked() {
                    actions.push(Action::ResetCamera(None));
                }
                for (i, label) in self.cameras.iter().enumerate() {
                    if ui.selectable_label(false, label).clicked() {
                        actions.push(Action::ResetCamera(Some(i.to_string())));
                    }
                }
            });
        if self.state.duration > 0.0 {
            ui.horizontal(|ui| {
                let label = if self.state.playing { "pause" } else { "play" };
                if ui.button(label).clicked() {
                    self.state.playing = !self.state.playing;
                }
                let mut t = self.state.time.min(self.state.duration);
                if ui
                    .add(egui::Slider::new(&mut t, 0.0..=self.state.duration).text("t (s)"))
                    .changed()
                {
                    self.state.scrub(t);
                }
            });
        }
    }

    fn passes_ui(&self, ui: &mut egui::Ui) {
        let timings = &self.readout.timings;
        let gpu = if timings.solution.gpu_timestamps {
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
        scope(ui, "solution", &timings.solution);
        for (name, timings) in self.view_names.iter().zip(&timings.views) {
            scope(ui, &format!("view {name}"), timings);
        }
    }
}

/// The frame-interval history as a line over a strip of the panel, scaled to its maximum.
fn frame_plot(ui: &mut egui::Ui, history: &std::collections::VecDeque<f32>) {
    let size = egui::vec2(ui.available_width(), 48.0);
    let (rect, _) = ui.allocate_exact_size(size, egui::Sense::hover());
    let painter = ui.painter_at(rect);
    painter.rect_filled(rect, 2.0, egui::Color32::from_gray(24));
    let top = history.iter().fold(1.0f32, |a, &b| a.max(b));
    let n = state::HISTORY_FRAMES.max(2) as f32;
    let points: Vec<egui::Pos2> = history
        .iter()
        .enumerate()
        .map(|(i, &ms)| {
            egui::pos2(
                rect.left() + rect.width() * i as f32 / (n - 1.0),
                rect.bottom() - rect.height() * (ms / top).clamp(0.0, 1.0),
            )
        })
        .collect();
    painter.add(egui::Shape::line(
        points,
        egui::Stroke::new(1.0, egui::Color32::LIGHT_GREEN),
    ));
    painter.text(
        rect.left_top() + egui::vec2(3.0, 1.0),
        egui::Align2::LEFT_TOP,
        format!("{top:.0} ms"),
        egui::FontId::monospace(10.0),
        egui::Color32::GRAY,
    );
}

fn present_pipeline(
    ctx: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
    write_mask: wgpu::ColorWrites,
) -> wgpu::RenderPipeline {
    let shader = ctx.shader("present.wgsl");
    crate::raster::fullscreen_pipeline(&ctx.device, "present", &shader, layout, format, write_mask)
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
    fn a_preview_knob_edits_one_field_of_the_material() {
        let start = crate::preview::default_material();
        let rough = edit_preview_material(&start, "roughness", "0.2").unwrap();
        assert_eq!(rough.roughness, 0.2);
        assert_eq!(
            (rough.metallic, rough.base_color),
            (start.metallic, start.base_color)
        );
        let base = edit_preview_material(&start, "base", "0.1/0.2/0.3").unwrap();
        assert_eq!(
            base.base_color,
            glam::Vec4::new(0.1, 0.2, 0.3, start.base_color.w)
        );
        assert_eq!(base.roughness, start.roughness);
        for (key, value) in [
            ("gloss", "0.3"),
            ("roughness", "1.5"),
            ("roughness", "0..1:3"),
        ] {
            let error = edit_preview_material(&start, key, value).unwrap_err();
            assert!(
                error.contains(&format!("material.{key}={value}")),
                "{error}"
            );
        }
    }
}
