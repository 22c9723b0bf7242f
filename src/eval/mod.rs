//! The evaluation harness (`valgi eval`): every method and setting on every scene, measured
//! against cached path-traced references: error (RMSE, relative MSE, FLIP; full and indirect),
//! time per pass, GPU bytes, and temporal stability; written as a CSV, a speed/accuracy chart
//! per scene, and image sheets with error maps. See README.md beside this file.

pub mod metrics;
pub mod plot;
pub mod sweep;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::gpu::{GpuContext, GpuError};
use crate::image_io::{Image, ImageError};
use crate::method::{self, MethodOptions};
use crate::raster::{RenderError, RenderSettings};
use crate::reference::{self, Bounces, ReferenceSettings};
use crate::scene::{self, builtin::BuiltinParams, Scene, SceneError};

#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
    #[error("{0}")]
    Settings(String),
    #[error(transparent)]
    Cancelled(#[from] crate::progress::Cancelled),
    #[error(transparent)]
    App(#[from] crate::app::AppError),
}

/// One `valgi eval` invocation.
#[derive(Clone, Debug)]
pub struct EvalRequest {
    /// Built-in scene names or glTF paths.
    pub scenes: Vec<String>,
    /// Method specs `name[:key=value,...]`.
    pub methods: Vec<String>,
    pub out: PathBuf,
    pub width: u32,
    pub height: u32,
    /// Camera name or index (`None` = the scene's first).
    pub camera: Option<String>,
    /// Lights and a camera added to every scene (`--light`, `--camera-eye`, …).
    pub edits: scene::edits::SceneEdits,
    /// Reference paths per pixel.
    pub ref_spp: u32,
    /// Reference bounce count (1 compares single-bounce methods).
    pub ref_bounces: Bounces,
    pub ref_seed: u64,
    /// The reference keeps the materials' specular lobes (`--ref-specular`); `false` compares
    /// the diffuse-only methods (atlas, the VALs' bounce) with the light they model.
    pub ref_specular: bool,
    /// Frames rendered per method; ≥ 3 gives the flicker metric. Frame f is at `f·frame_dt` s.
    pub frames: u32,
    pub frame_dt: f32,
    pub max_edge: f32,
    /// Tessellate an imported scene for the listed sparse methods' point spacing, as `render`
    /// does without `--max-edge` (`max_edge` then applies to built-in scenes only).
    pub sparse_spacing: bool,
    /// Most proxy lights the emissive surfaces become (0 = none); the reference ignores it.
    pub emitter_lights: u32,
    /// Tone-map exposure (stops) for FLIP and sheets of full images; `None` = automatic.
    pub exposure: Option<f32>,
    /// Also render the sparse method over this grid of its budget knobs (`--sweep`) and write
    /// `sweep.csv`.
    pub sweep: Option<sweep::SweepGrid>,
    pub progress: bool,
}

impl Default for EvalRequest {
    fn default() -> Self {
        Self {
            scenes: vec!["cornell".into()],
            methods: vec!["direct".into()],
            out: PathBuf::from("out/eval"),
            width: 256,
            height: 256,
            camera: None,
            edits: Default::default(),
            ref_spp: 256,
            ref_bounces: Bounces::Limited(1),
            ref_seed: 0x5EED,
            ref_specular: true,
            frames: 1,
            frame_dt: 1.0 / 30.0,
            max_edge: BuiltinParams::default().max_edge,
            sparse_spacing: false,
            emitter_lights: scene::emitters::DEFAULT_EMITTER_LIGHTS,
            exposure: None,
            sweep: None,
            progress: true,
        }
    }
}

/// One row of `results.csv`.
#[derive(Clone, Debug)]
pub struct EvalRow {
    pub scene: String,
    pub method: String,
    pub settings: String,
    pub width: u32,
    pub height: u32,
    /// Mean ms per frame of every pass.
    pub passes: Vec<(String, f64)>,
    pub total_ms: f64,
    pub gpu_bytes: u64,
    pub rmse: f64,
    pub relmse: f64,
    pub flip: f64,
    pub rmse_indirect: f64,
    pub relmse_indirect: f64,
    pub flip_indirect: f64,
    pub flicker: Option<f64>,
    /// [`metrics::flicker_where`] over the pixels whose surface stands still in every frame
    /// (no moving object's silhouette; `None` when the camera moves or nothing stands still).
    pub flicker_static: Option<f64>,
    pub exposure: f32,
    pub exposure_indirect: f32,
}

/// The pixels whose first surface stands still over the frames (`metrics::static_pixels`,
/// within 1e-5 of the scene's diagonal): frame f's camera rays traced at time `f·frame_dt`.
pub fn static_pixels(
    scene: &Scene,
    camera: Option<&str>,
    (width, height): (u32, u32),
    frames: u32,
    frame_dt: f32,
) -> Result<Vec<bool>, EvalError> {
    if scene.animations.is_empty() {
        // Nothing moves, the camera included: every pixel stands still.
        return Ok(vec![true; (width * height) as usize]);
    }
    let aspect = width as f32 / height as f32;
    let mut hits = Vec::with_capacity(frames as usize);
    let mut diagonal = 0.0f32;
    for f in 0..frames {
        let world = scene.world_from_node_at(f as f32 * frame_dt);
        let view = scene.camera_view(camera, aspect, &world)?;
        let bounds = scene.world_bounds(&world);
        diagonal = diagonal.max((bounds.max - bounds.min).length());
        let tracer = crate::trace::Tracer::new(scene, &world);
        hits.push(
            crate::reference::first_hits(&tracer, &view, width, height)
                .into_iter()
                .map(|hit| hit.map(|h| (h.position, h.normal)))
                .collect::<Vec<_>>(),
        );
    }
    Ok(metrics::static_pixels(&hits, 1e-5 * diagonal.max(1e-6)))
}

/// What a run wrote.
#[derive(Clone, Debug)]
pub struct EvalSummary {
    pub rows: Vec<EvalRow>,
    pub csv: PathBuf,
    pub charts: Vec<PathBuf>,
    pub sheets: Vec<PathBuf>,
    /// References rendered this run (the rest came from the cache).
    pub references_rendered: usize,
    pub references_cached: usize,
    /// The `--sweep` grid's rows, every scene, and where they were written.
    pub sweep: Vec<sweep::SweepRow>,
    pub sweep_csv: Option<PathBuf>,
    /// Budget-mode rows checked against the grid (`sweep_check.csv`).
    pub sweep_checks: Vec<sweep::AutoCheck>,
}

pub const CSV_HEADER: &str = "scene,method,settings,width,height,passes_ms,total_ms,gpu_bytes,rmse,relmse,flip,rmse_indirect,relmse_indirect,flip_indirect,flicker,flicker_static,exposure,exposure_indirect";

/// Splits `--methods` text into specs: commas separate methods, except that a `key=value`
/// item without a `:` continues the previous method's options, so
/// `sparse:rsm=64,tile=128,direct` is `sparse:rsm=64,tile=128` and `direct`.
pub fn split_method_specs(text: &str) -> Vec<String> {
    let mut specs: Vec<String> = Vec::new();
    for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let continues = item.contains('=') && !item.contains(':');
        match specs.last_mut() {
            Some(last) if continues => {
                last.push(',');
                last.push_str(item);
            }
            _ => specs.push(item.to_string()),
        }
    }
    specs
}

/// Text → comma-separated list (scenes).
pub fn split_list(text: &str) -> Vec<String> {
    text.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(String::from)
        .collect()
}

/// FNV-1a, 64 bits: a stable hash for cache keys (std's hasher may change between releases).
pub fn fnv1a(text: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// A reference frame, from the cache or rendered.
pub struct CachedReference {
    pub direct: Image,
    pub indirect: Image,
    pub rendered: bool,
    pub key: String,
}

impl CachedReference {
    pub fn full(&self) -> Image {
        self.direct.add(&self.indirect)
    }
}

/// The version of the path tracer's output in every reference cache key: raised when a fix
/// changes its pixels, so that no cache keeps an image of the old one. 3: shadow rays along
/// a direction with a −0.0 component (a negated axis-plane sun direction) found no blocker
/// (`trace::obvhs_ray`).
pub const REFERENCE_VERSION: u32 = 3;

/// The reference's cache key: everything that changes its pixels.
#[allow(clippy::too_many_arguments)]
pub fn reference_key(
    scene: &str,
    camera: Option<&str>,
    width: u32,
    height: u32,
    bounces: Bounces,
    spp: u32,
    seed: u64,
    max_edge: f32,
    time: f32,
    specular: bool,
) -> String {
    // Keys of references with specular light (the default) are as they were before the
    // option existed, so caches stay valid.
    format!(
        "v{REFERENCE_VERSION} scene={scene} camera={} size={width}x{height} bounces={bounces} spp={spp} seed={seed} max_edge={max_edge} time={time}{}",
        camera.unwrap_or("-"),
        if specular { "" } else { " specular=off" }
    )
}

/// The scene part of a reference's cache key: the scene as named on the command line, and
/// the edits made to it (a reference cached for the bare scene must not serve the edited one).
pub fn reference_scene_key(scene_spec: &str, edits: &scene::edits::SceneEdits) -> String {
    if edits.is_empty() {
        scene_spec.to_string()
    } else {
        format!("{scene_spec} {edits:?}")
    }
}

/// A reference in the cache that [`find_cached_reference`] chose.
#[derive(Clone, Debug, PartialEq)]
pub struct CachedMatch {
    pub key: String,
    pub direct: PathBuf,
    pub indirect: PathBuf,
    pub spp: u32,
}

/// The reference `valgi eval` cached in `dir` (an eval output folder or its `cache`) for the
/// view of `scene_key` (see [`reference_scene_key`]) from `camera` at `width`×`height` and
/// `time`: of those, the one with the most samples per pixel (ties: the first key in order).
/// Its bounces, seed, tessellation and specular setting are whatever eval used; the key says.
pub fn find_cached_reference(
    dir: &Path,
    scene_key: &str,
    camera: Option<&str>,
    (width, height): (u32, u32),
    time: f32,
) -> Option<CachedMatch> {
    let cache_dir = if dir.join("cache").is_dir() {
        dir.join("cache")
    } else {
        dir.to_path_buf()
    };
    let prefix = format!(
        "v{REFERENCE_VERSION} scene={scene_key} camera={} size={width}x{height} ",
        camera.unwrap_or("-")
    );
    let time_field = format!("time={time}");
    let mut found: Vec<CachedMatch> = std::fs::read_dir(&cache_dir)
        .ok()?
        .filter_map(|entry| {
            let path = entry.ok()?.path();
            let stem = path
                .file_name()?
                .to_str()?
                .strip_suffix(".txt")?
                .to_string();
            let key = std::fs::read_to_string(&path).ok()?.trim().to_string();
            let rest = key.strip_prefix(&prefix)?;
            let fields: Vec<&str> = rest.split(' ').collect();
            if !fields.contains(&time_field.as_str()) {
                return None;
            }
            let spp = fields
                .iter()
                .find_map(|f| f.strip_prefix("spp=")?.parse().ok())?;
            let direct = cache_dir.join(format!("{stem}.direct.exr"));
            let indirect = cache_dir.join(format!("{stem}.indirect.exr"));
            (direct.is_file() && indirect.is_file()).then_some(CachedMatch {
                key,
                direct,
                indirect,
                spp,
            })
        })
        .collect();
    found.sort_by(|a, b| b.spp.cmp(&a.spp).then_with(|| a.key.cmp(&b.key)));
    found.into_iter().next()
}

/// Loads the reference for `key` from `cache_dir`, or renders it with `render` and stores it
/// (`ref-<hash>.direct.exr`, `.indirect.exr`, `.variance.exr` and the key in `.txt`).
pub fn cached_reference(
    cache_dir: &Path,
    key: &str,
    render: impl FnOnce() -> reference::ReferenceImage,
) -> Result<CachedReference, EvalError> {
    let stem = format!("ref-{:016x}", fnv1a(key));
    let direct_path = cache_dir.join(format!("{stem}.direct.exr"));
    let indirect_path = cache_dir.join(format!("{stem}.indirect.exr"));
    let key_path = cache_dir.join(format!("{stem}.txt"));
    let stored_key = std::fs::read_to_string(&key_path).unwrap_or_default();
    if stored_key.trim() == key && direct_path.is_file() && indirect_path.is_file() {
        match (
            Image::read_exr(&direct_path),
            Image::read_exr(&indirect_path),
        ) {
            (Ok(direct), Ok(indirect)) => {
                return Ok(CachedReference {
                    direct,
                    indirect,
                    rendered: false,
                    key: key.to_string(),
                })
            }
            (Err(e), _) | (_, Err(e)) => {
                log::warn!("reference cache unreadable, rendering again: {e}");
            }
        }
    }
    let image = render();
    // A reference stopped by Ctrl-C is incomplete: it must never enter the cache.
    crate::progress::check()?;
    image.direct.write_exr(&direct_path)?;
    image.indirect.write_exr(&indirect_path)?;
    image
        .variance
        .write_exr(&cache_dir.join(format!("{stem}.variance.exr")))?;
    std::fs::write(&key_path, format!("{key}\n")).map_err(|e| EvalError::Output {
        path: key_path.clone(),
        message: e.to_string(),
    })?;
    Ok(CachedReference {
        direct: image.direct,
        indirect: image.indirect,
        rendered: true,
        key: key.to_string(),
    })
}

/// File-name-safe version of a label.
pub fn slug(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn csv_field(text: &str) -> String {
    if text.contains(',') || text.contains('"') || text.contains('\n') {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.6e}")
    } else {
        String::new()
    }
}

impl EvalRow {
    pub fn csv_line(&self) -> String {
        let passes: Vec<String> = self
            .passes
            .iter()
            .map(|(p, ms)| format!("{p}={ms:.3}"))
            .collect();
        [
            csv_field(&self.scene),
            csv_field(&self.method),
            csv_field(&self.settings),
            self.width.to_string(),
            self.height.to_string(),
            csv_field(&passes.join(";")),
            format!("{:.3}", self.total_ms),
            self.gpu_bytes.to_string(),
            num(self.rmse),
            num(self.relmse),
            num(self.flip),
            num(self.rmse_indirect),
            num(self.relmse_indirect),
            num(self.flip_indirect),
            self.flicker.map(num).unwrap_or_default(),
            self.flicker_static.map(num).unwrap_or_default(),
            format!("{:.3}", self.exposure),
            format!("{:.3}", self.exposure_indirect),
        ]
        .join(",")
    }
}

/// Runs the evaluation and writes its files under `request.out`.
pub fn run(request: &EvalRequest) -> Result<EvalSummary, EvalError> {
    if request.scenes.is_empty() || (request.methods.is_empty() && request.sweep.is_none()) {
        return Err(EvalError::Settings(
            "eval needs at least one scene and one method (or --sweep)".into(),
        ));
    }
    if let Some(grid) = &request.sweep {
        grid.check()?;
    }
    if request.width == 0 || request.height == 0 || request.ref_spp == 0 || request.frames == 0 {
        return Err(EvalError::Settings(
            "width, height, ref-spp and frames must be at least 1".into(),
        ));
    }
    if let Some(exposure) = request.exposure.filter(|e| !e.is_finite()) {
        return Err(EvalError::Settings(format!(
            "--exposure {exposure}: must be a finite number of stops"
        )));
    }
    let reference_paths = request.width as u64 * request.height as u64 * request.ref_spp as u64;
    if reference_paths > crate::reference::ReferenceMethod::MAX_PATHS {
        return Err(EvalError::Settings(format!(
            "--ref-spp {}: {reference_paths} reference paths at {}×{}, beyond the budget of {}; \
             lower --ref-spp or the image size",
            request.ref_spp,
            request.width,
            request.height,
            crate::reference::ReferenceMethod::MAX_PATHS
        )));
    }
    // The grid's settings follow the listed methods; `grid_of[i]` is spec i's grid setting.
    let grid_settings = request
        .sweep
        .as_ref()
        .map(sweep::SweepGrid::settings)
        .unwrap_or_default();
    let mut grid_of: Vec<Option<sweep::GridSetting>> = vec![None; request.methods.len()];
    grid_of.extend(grid_settings.iter().copied().map(Some));
    let spec_texts = request
        .methods
        .iter()
        .cloned()
        .chain(grid_settings.iter().map(sweep::GridSetting::spec));
    // Parse every spec before any rendering, so a typo fails at once.
    let specs: Vec<(String, MethodOptions)> = spec_texts
        .map(|s| MethodOptions::parse_spec(&s))
        .collect::<Result<_, _>>()?;
    for (name, options) in &specs {
        method::check_options(name, options).map_err(|e| EvalError::Settings(e.to_string()))?;
    }
    let out = &request.out;
    let cache_dir = out.join("cache");
    std::fs::create_dir_all(&cache_dir).map_err(|e| EvalError::Output {
        path: cache_dir.clone(),
        message: e.to_string(),
    })?;
    let params = scene::LoadParams {
        max_edge: request.max_edge,
        emitter_lights: request.emitter_lights,
        ..scene::LoadParams::default()
    };
    let aspect = request.width as f32 / request.height as f32;
    // Each scene with the command line's edits, and the camera they leave it with.
    let mut scenes: Vec<(Scene, Option<String>, f32)> = Vec::with_capacity(request.scenes.len());
    let method_pairs: Vec<(&str, &MethodOptions)> =
        specs.iter().map(|(n, o)| (n.as_str(), o)).collect();
    for spec in &request.scenes {
        let edits = (&request.edits, request.camera.as_deref(), aspect);
        let (scene, camera, max_edge) = if request.sparse_spacing {
            let (scene, tessellation, camera) = crate::app::load_scene_edited(
                spec,
                &method_pairs,
                None,
                false,
                request.emitter_lights,
                edits,
            )?;
            (scene, camera, tessellation.max_edge)
        } else {
            let mut scene = scene::load_with(spec, &params)?;
            let camera = request.edits.apply(&mut scene, edits.1, aspect)?;
            (scene, camera, request.max_edge)
        };
        scenes.push((scene, camera, max_edge));
    }
    let ctx = GpuContext::new()?;
    let settings = RenderSettings {
        width: request.width,
        height: request.height,
        ..RenderSettings::default()
    };
    let mut summary = EvalSummary {
        rows: vec![],
        csv: out.join("results.csv"),
        charts: vec![],
        sheets: vec![],
        references_rendered: 0,
        references_cached: 0,
        sweep: vec![],
        sweep_csv: None,
        sweep_checks: vec![],
    };
    for (scene_spec, (scene, camera, max_edge)) in request.scenes.iter().zip(&scenes) {
        let scene_key = reference_scene_key(scene_spec, &request.edits);
        for warning in &scene.warnings {
            log::warn!("{warning}");
        }
        let scene_label = slug(&scene.name);
        // Methods that look at the scene when they are built (budget mode) see it from the
        // camera the images are drawn from.
        let settings = RenderSettings {
            camera: scene.camera_index(camera.as_deref()),
            ..settings
        };
        // The listed methods are built first, so that a bad option fails before the reference
        // renders; the sweep's (options checked above) are built one at a time as they render,
        // so a grid of dozens never holds more than one method's GPU memory.
        let mut methods: Vec<Option<Box<dyn method::Method>>> = Vec::with_capacity(specs.len());
        for ((name, options), grid) in specs.iter().zip(&grid_of) {
            methods.push(match grid {
                None => Some(method::create(name, &ctx, scene, settings, options)?),
                Some(_) => None,
            });
        }
        let world0 = scene.world_from_node_at(0.0);
        let camera0 = scene.camera_view(camera.as_deref(), aspect, &world0)?;
        let static_mask = if request.frames >= 3 {
            Some(static_pixels(
                scene,
                camera.as_deref(),
                (request.width, request.height),
                request.frames,
                request.frame_dt,
            )?)
        } else {
            None
        };
        let key = reference_key(
            &scene_key,
            camera.as_deref(),
            request.width,
            request.height,
            request.ref_bounces,
            request.ref_spp,
            request.ref_seed,
            *max_edge,
            0.0,
            request.ref_specular,
        );
        let reference = cached_reference(&cache_dir, &key, || {
            log::info!("rendering reference: {key}");
            reference::render(
                scene,
                &world0,
                &camera0,
                &ReferenceSettings {
                    width: request.width,
                    height: request.height,
                    spp: request.ref_spp,
                    bounces: request.ref_bounces,
                    seed: request.ref_seed,
                    progress: request.progress,
                    specular: request.ref_specular,
                },
            )
        })?;
        if reference.rendered {
            summary.references_rendered += 1;
        } else {
            summary.references_cached += 1;
        }
        let ref_full = reference.full();
        let ref_indirect = &reference.indirect;
        let exposure = request
            .exposure
            .unwrap_or_else(|| metrics::auto_exposure(&ref_full));
        let exposure_indirect = metrics::auto_exposure(ref_indirect);
        let mut sheet_rows = vec![plot::SheetRow {
            label: format!(
                "reference ({} spp, {} bounce(s){}); exposure {exposure:.1} / indirect {exposure_indirect:.1} stops",
                request.ref_spp,
                request.ref_bounces,
                if request.ref_specular { "" } else { ", no specular" }
            ),
            tiles: vec![
                ref_full.tone_map(exposure),
                ref_full.tone_map(exposure),
                image::RgbImage::new(request.width, request.height),
                ref_indirect.tone_map(exposure_indirect),
                ref_indirect.tone_map(exposure_indirect),
                image::RgbImage::new(request.width, request.height),
            ],
        }];
        let mut points = vec![];
        let methods_step = crate::progress::Step::new(
            request.progress,
            specs.len() as u64,
            &format!("{scene_label}: methods"),
        );
        let mut grid_rows: Vec<(sweep::GridSetting, usize, Image)> = vec![];
        // Rows of methods in budget mode: (row, their `budget` report, indirect image).
        let mut auto_rows: Vec<(usize, serde_json::Value, Image)> = vec![];
        for (((name, options), slot), grid) in specs.iter().zip(methods.iter_mut()).zip(&grid_of) {
            methods_step.inc(1);
            let method = match slot {
                Some(method) => method,
                None => slot.insert(method::create(name, &ctx, scene, settings, options)?),
            };
            if method.renders_on_gpu() {
                // One untimed frame first, on an instance of its own, so that the timed
                // frames' temporal state (the visibility history) starts as without it: a
                // pipeline's first dispatch compiles it, and on lavapipe with a cold shader
                // cache that took 6.5 s of a 0.16 s frame (glossy-row's budget-mode gather),
                // which the mean over three frames made a 14× slower row.
                // A method in budget mode is built there with its choice written in, so
                // that its pilots run once, on the timed instance.
                let warm_options = method
                    .resolved_options()
                    .map_or_else(|| options.clone(), MethodOptions::from_pairs);
                let mut warm = method::create(name, &ctx, scene, settings, &warm_options)?;
                warm.render(&ctx, scene, &world0, &camera0)?;
            }
            let settings_text = options.to_string();
            let label = if settings_text.is_empty() {
                name.clone()
            } else {
                format!("{name}:{settings_text}")
            };
            let mut passes: Vec<(String, f64)> = vec![];
            let mut indirect_frames = vec![];
            let mut first = None;
            let mut gpu_bytes = 0;
            for f in 0..request.frames {
                crate::progress::check()?;
                let time = f as f32 * request.frame_dt;
                let world = scene.world_from_node_at(time);
                let camera = scene.camera_view(camera.as_deref(), aspect, &world)?;
                let mut frame = method.render(&ctx, scene, &world, &camera)?;
                frame.direct.sanitize();
                frame.indirect.sanitize();
                for (pass, ms) in &frame.timings.passes {
                    match passes.iter_mut().find(|(p, _)| p == pass) {
                        Some((_, total)) => *total += ms,
                        None => passes.push((pass.clone(), *ms)),
                    }
                }
                gpu_bytes = gpu_bytes.max(frame.gpu_bytes);
                if request.frames >= 3 {
                    indirect_frames.push(frame.indirect.clone());
                }
                if f == 0 {
                    first = Some(frame);
                }
            }
            for (_, ms) in &mut passes {
                *ms /= request.frames as f64;
            }
            let total_ms = passes.iter().map(|(_, ms)| ms).sum();
            let frame = first.expect("at least one frame");
            let full = frame.direct.add(&frame.indirect);
            let (flip, flip_map) = metrics::flip_with_map(&full, &ref_full, exposure);
            let (flip_indirect, flip_map_indirect) =
                metrics::flip_with_map(&frame.indirect, ref_indirect, exposure_indirect);
            let row = EvalRow {
                scene: scene.name.clone(),
                method: name.clone(),
                settings: settings_text.clone(),
                width: request.width,
                height: request.height,
                passes,
                total_ms,
                gpu_bytes,
                rmse: metrics::rmse(&full, &ref_full),
                relmse: metrics::relmse(&full, &ref_full),
                flip,
                rmse_indirect: metrics::rmse(&frame.indirect, ref_indirect),
                relmse_indirect: metrics::relmse(&frame.indirect, ref_indirect),
                flip_indirect,
                flicker: metrics::flicker(&indirect_frames),
                flicker_static: static_mask
                    .as_deref()
                    .and_then(|mask| metrics::flicker_where(&indirect_frames, Some(mask))),
                exposure,
                exposure_indirect,
            };
            let images = out.join("images").join(&scene_label);
            full.write_exr(&images.join(format!("{}.exr", slug(&label))))?;
            frame
                .indirect
                .write_exr(&images.join(format!("{}.indirect.exr", slug(&label))))?;
            if request.sweep.is_some() && grid.is_none() {
                if let Some(budget) = method.report().get("budget") {
                    auto_rows.push((summary.rows.len(), budget.clone(), frame.indirect.clone()));
                }
            }
            if let Some(setting) = grid {
                // A grid row is one unlabelled point of its own series, not a sheet row; its
                // method is dropped at once.
                *slot = None;
                points.push(plot::ParetoPoint {
                    series: "sparse grid (--sweep)".into(),
                    label: String::new(),
                    ms: row.total_ms,
                    error: row.flip_indirect,
                });
                grid_rows.push((*setting, summary.rows.len(), frame.indirect));
                summary.rows.push(row);
                continue;
            }
            sheet_rows.push(plot::SheetRow {
                label: format!(
                    "{label}: {:.1} ms, FLIP {:.3}, indirect FLIP {:.3}",
                    row.total_ms, row.flip, row.flip_indirect
                ),
                tiles: vec![
                    full.tone_map(exposure),
                    ref_full.tone_map(exposure),
                    flip_map,
                    frame.indirect.tone_map(exposure_indirect),
                    ref_indirect.tone_map(exposure_indirect),
                    flip_map_indirect,
                ],
            });
            points.push(plot::ParetoPoint {
                series: name.clone(),
                label: settings_text,
                ms: row.total_ms,
                error: row.flip_indirect,
            });
            summary.rows.push(row);
        }
        if let Some(grid) = &request.sweep {
            let settings: Vec<sweep::GridSetting> = grid_rows.iter().map(|g| g.0).collect();
            let rows: Vec<&EvalRow> = grid_rows.iter().map(|g| &summary.rows[g.1]).collect();
            let images: Vec<Image> = grid_rows.iter().map(|g| g.2.clone()).collect();
            let scene_rows = sweep::scene_rows(grid, &settings, &rows, &images, exposure_indirect);
            for (row, budget, image) in &auto_rows {
                summary.sweep_checks.push(sweep::check_auto(
                    &summary.rows[*row],
                    budget,
                    image,
                    grid,
                    &settings,
                    &images,
                    &scene_rows,
                    exposure_indirect,
                ));
            }
            summary.sweep.extend(scene_rows);
        }
        let chart = out.join(format!("{scene_label}_pareto.png"));
        plot::pareto_chart(
            &chart,
            &format!(
                "{}: time vs indirect error ({}x{}, reference {} spp)",
                scene.name, request.width, request.height, request.ref_spp
            ),
            &points,
        )?;
        summary.charts.push(chart);
        let sheet = out.join(format!("{scene_label}_sheet.png"));
        plot::image_sheet(
            &sheet,
            &[
                "image",
                "reference",
                "FLIP",
                "indirect",
                "ref. indirect",
                "FLIP indirect",
            ],
            &sheet_rows,
        )?;
        summary.sheets.push(sheet);
    }
    let mut csv = String::new();
    let _ = writeln!(csv, "{CSV_HEADER}");
    for row in &summary.rows {
        let _ = writeln!(csv, "{}", row.csv_line());
    }
    std::fs::write(&summary.csv, csv).map_err(|e| EvalError::Output {
        path: summary.csv.clone(),
        message: e.to_string(),
    })?;
    if request.sweep.is_some() {
        let path = out.join("sweep.csv");
        sweep::write_csv(&path, &summary.sweep)?;
        summary.sweep_csv = Some(path);
        if !summary.sweep_checks.is_empty() {
            sweep::write_checks(&out.join("sweep_check.csv"), &summary.sweep_checks)?;
        }
    }
    Ok(summary)
}

/// Wall time helper for the CLI report.
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let value = f();
    (value, start.elapsed().as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_viewer_finds_the_cached_reference_of_its_view_with_the_most_samples() {
        let dir = std::env::temp_dir().join(format!("valgi-refcache-{}", std::process::id()));
        let cache = dir.join("cache");
        std::fs::create_dir_all(&cache).unwrap();
        let key = |spp: u32, size: u32, time: f32, scene: &str| {
            reference_key(
                scene,
                None,
                size,
                size,
                Bounces::Limited(1),
                spp,
                1,
                0.05,
                time,
                true,
            )
        };
        let store = |key: &str, files: bool| {
            let stem = format!("ref-{:016x}", fnv1a(key));
            std::fs::write(cache.join(format!("{stem}.txt")), format!("{key}\n")).unwrap();
            if files {
                for part in ["direct", "indirect"] {
                    std::fs::write(cache.join(format!("{stem}.{part}.exr")), b"").unwrap();
                }
            }
        };
        // Candidates: the right view at 16 and 64 spp, one whose images are gone, and wrong
        // sizes, times and scenes (a scene name that only starts like the right one too).
        store(&key(16, 32, 0.0, "cornell"), true);
        store(&key(64, 32, 0.0, "cornell"), true);
        store(&key(256, 32, 0.0, "cornell"), false);
        store(&key(512, 48, 0.0, "cornell"), true);
        store(&key(512, 32, 0.5, "cornell"), true);
        store(&key(512, 32, 0.0, "cornell-point"), true);
        let found = find_cached_reference(&dir, "cornell", None, (32, 32), 0.0).unwrap();
        assert_eq!(found.key, key(64, 32, 0.0, "cornell"));
        assert_eq!(found.spp, 64);
        assert!(found.direct.is_file() && found.indirect.is_file());
        // The cache folder itself works as well as the eval folder above it.
        assert_eq!(
            find_cached_reference(&cache, "cornell", None, (32, 32), 0.0),
            Some(found)
        );
        assert_eq!(
            find_cached_reference(&dir, "cornell", None, (32, 32), 0.5)
                .unwrap()
                .spp,
            512
        );
        assert_eq!(
            find_cached_reference(&dir, "cornell", Some("top"), (32, 32), 0.0),
            None
        );
        assert_eq!(
            find_cached_reference(&dir, "cornell", None, (16, 16), 0.0),
            None
        );
        assert_eq!(
            find_cached_reference(&dir.join("none"), "cornell", None, (32, 32), 0.0),
            None
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
