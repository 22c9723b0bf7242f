//! What `valgi render` does, as a library call: load the scene, pick the camera and its
//! views, build the method, render the frames, write the files, and report. The binary only
//! parses arguments.

use std::path::PathBuf;
use std::time::Instant;

use crate::frame::memory::{self, MemorySample};
use crate::frame::{record_frame, Method, View, ViewResult, ViewRig};
use crate::gpu::timing::round3;
use crate::gpu::{GpuContext, GpuError};
use crate::image_io::{prepare_output, Image, ImageError};
use crate::method::{self, MethodOptions};
use crate::raster::{RenderError, RenderSettings};
use crate::scene::{self, builtin::BuiltinParams, SceneError};

#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Cancelled(#[from] crate::progress::Cancelled),
}

/// Beyond ±64 stops (2^64) every pixel of a PNG is black or white.
pub const MAX_EXPOSURE_STOPS: f32 = 64.0;

/// One `valgi render` invocation.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    /// Built-in scene name or a `.gltf`/`.glb` path.
    pub scene: String,
    /// A registered method (`crate::method`); the default, [`DEFAULT_METHOD`], is the
    /// product's image.
    pub method: String,
    /// Rendered instead when `method` cannot bake its atlas in memory (`RenderError::AtlasBake`),
    /// with a warning: `sparse` for the default method; `None` (the CLI with `--method`): the
    /// refusal is the error.
    pub method_fallback: Option<String>,
    /// The method's knobs (`--rsm 64` becomes `rsm=64`).
    pub options: MethodOptions,
    pub settings: RenderSettings,
    /// Camera name or index; `None` = the scene's first camera (or a framing default).
    pub camera: Option<String>,
    /// Lights and a camera added to the scene (`--light`, `--camera-eye`, …).
    pub edits: scene::edits::SceneEdits,
    /// Files to write; the extension picks EXR or PNG.
    pub outputs: Vec<PathBuf>,
    /// PNG exposure in stops.
    pub exposure: f32,
    /// Choose the PNG exposure from the first frame's image ([`image_io::key_exposure`]),
    /// instead of `exposure`.
    pub auto_exposure: bool,
    pub indirect_only: bool,
    /// Longest triangle edge (metres); `None`: the built-in scenes' 5 cm, and for an imported
    /// scene the sparse points' spacing with the sparse methods (see [`load_scene`]).
    pub max_edge: Option<f32>,
    /// Animation time, seconds (of the first frame with `frames`).
    pub time: f32,
    /// Render this many frames as `frame_NNNN.exr` into the single output folder.
    pub frames: Option<u32>,
    /// Frames per second for `frames`.
    pub fps: f32,
    /// The views of each frame (mono, stereo, a CAVE, a grid).
    pub views: ViewRig,
    /// Let the scene file reference files outside its folder (absolute paths, `..`).
    pub allow_external_paths: bool,
    /// Most proxy lights the emissive surfaces become (0 = none; see `scene::emitters`).
    pub emitter_lights: u32,
    /// Write the images (false: render and time the frames only, as a soak run does).
    pub write_images: bool,
    /// Sample the resident set and the GPU bytes every this many frames (0: never).
    pub memory_every: u32,
}

/// What `valgi render` draws without `--method`: the product's image, direct light + the sparse
/// VALs' bounce 1 + bounces 2.. from an atlas baked in memory for the scene (`--atlas FILE`
/// takes a baked one). Against the all-bounce path tracer on the Cornell box (128², FLIP):
/// 0.075, against 0.376 for `sparse` alone and 0.630 for `direct` (README, "Rendering").
pub const DEFAULT_METHOD: &str = "sparse+atlas";

/// The default method without its atlas, for scenes whose atlas the in-memory bake refuses.
pub const DEFAULT_METHOD_FALLBACK: &str = "sparse";

impl Default for RenderRequest {
    fn default() -> Self {
        Self {
            scene: "cornell".into(),
            method: DEFAULT_METHOD.into(),
            method_fallback: Some(DEFAULT_METHOD_FALLBACK.into()),
            options: MethodOptions::default(),
            settings: RenderSettings::default(),
            camera: None,
            edits: Default::default(),
            outputs: vec![],
            exposure: 0.0,
            auto_exposure: false,
            indirect_only: false,
            max_edge: None,
            time: 0.0,
            frames: None,
            fps: 30.0,
            views: ViewRig::Mono,
            allow_external_paths: false,
            emitter_lights: scene::emitters::DEFAULT_EMITTER_LIGHTS,
            write_images: true,
            memory_every: 0,
        }
    }
}

/// Where frame `frame` of view `view` is written, for each requested output.
///
/// - One frame, one view: the outputs as given.
/// - One frame, several views: `<stem>_<view>.<ext>` beside each output.
/// - Several frames into a folder (an output without `.exr`/`.png`): `frame_NNNN.exr`, or
///   `frame_NNNN_<view>.exr` with several views.
/// - Several frames to a file name: numbered files beside it, `<stem>_NNNN[_<view>].<ext>`.
fn output_paths(request: &RenderRequest, frame: u32, view: &str, multi_view: bool) -> Vec<PathBuf> {
    let suffix = if multi_view {
        format!("_{view}")
    } else {
        String::new()
    };
    let Some(frames) = request.frames else {
        return request
            .outputs
            .iter()
            .map(|p| {
                if multi_view {
                    with_stem_suffix(p, &suffix)
                } else {
                    p.clone()
                }
            })
            .collect();
    };
    let _ = frames;
    let dir_or_file = request
        .outputs
        .first()
        .cloned()
        .unwrap_or_else(|| PathBuf::from("out/frames"));
    if is_image_path(&dir_or_file) {
        request
            .outputs
            .iter()
            .map(|p| with_stem_suffix(p, &format!("_{frame:04}{suffix}")))
            .collect()
    } else {
        vec![dir_or_file.join(format!("frame_{frame:04}{suffix}.exr"))]
    }
}

fn is_image_path(path: &std::path::Path) -> bool {
    matches!(
        path.extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref(),
        Some("exr") | Some("png")
    )
}

/// `dir/stem.ext` → `dir/stem<suffix>.ext`.
fn with_stem_suffix(path: &std::path::Path, suffix: &str) -> PathBuf {
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}{suffix}.{}", ext.to_string_lossy()),
        None => format!("{stem}{suffix}"),
    };
    path.with_file_name(name)
}

/// `frame_NNNN.exr` for frame `index` in `dir`.
pub fn frame_path(dir: &std::path::Path, index: u32) -> PathBuf {
    dir.join(format!("frame_{index:04}.exr"))
}

/// Warns when most of a PNG came out black, and says what exposure would show it.
fn warn_if_dark(path: &std::path::Path, image: &Image, exposure: f32, auto: bool) {
    let dark = crate::image_io::dark_fraction(image, exposure);
    if dark < 0.9 {
        return;
    }
    match crate::image_io::key_exposure(image) {
        None => log::warn!(
            "{}: the image is black (no light reaches the camera)",
            path.display()
        ),
        Some(key) if !auto => log::warn!(
            "{}: {:.0}% of the pixels are black at --exposure {exposure}; --auto-exposure \
             would use {key:+.1} stops",
            path.display(),
            dark * 100.0
        ),
        Some(_) => log::warn!(
            "{}: {:.0}% of the pixels are black even at the automatic exposure \
             ({exposure:+.1} stops): a few bright pixels, the rest unlit",
            path.display(),
            dark * 100.0
        ),
    }
}

/// The views of a request at one pose: the rig applied to the scene camera.
fn rig_views(
    request: &RenderRequest,
    scene: &scene::Scene,
    world_from_node: &[glam::Mat4],
) -> Result<Vec<crate::frame::rig::RigView>, AppError> {
    let settings = request.settings;
    let camera = scene.camera_view(
        request.camera.as_deref(),
        settings.width as f32 / settings.height as f32,
        world_from_node,
    )?;
    let bounds = scene.world_bounds(world_from_node);
    let pivot = if bounds.is_empty() {
        camera.position()
    } else {
        (bounds.min + bounds.max) * 0.5
    };
    Ok(request
        .views
        .views(&camera, (settings.width, settings.height), pivot))
}

/// Renders the request's frames through its views and writes the outputs; returns the JSON
/// report line. Each frame is one update of the method's lighting solution and one record
/// per view; the method is built once, so preprocessing happens once.
pub fn render(request: &RenderRequest) -> Result<serde_json::Value, AppError> {
    let started = Instant::now();
    let frames = request.frames.unwrap_or(1);
    if frames == 0 || !(request.fps.is_finite() && request.fps > 0.0) {
        return Err(
            RenderError::Settings("--frames must be at least 1 and --fps positive".into()).into(),
        );
    }
    if !request.time.is_finite() {
        return Err(
            RenderError::Settings("--time must be a finite number of seconds".into()).into(),
        );
    }
    if !request.exposure.is_finite() || request.exposure.abs() > MAX_EXPOSURE_STOPS {
        return Err(RenderError::Settings(format!(
            "--exposure {}: must be a finite number of stops within ±{MAX_EXPOSURE_STOPS}",
            request.exposure
        ))
        .into());
    }
    let multi_view = request.views != ViewRig::Mono;
    // Fail on an unwritable output before spending time on the scene and the GPU.
    if request.write_images {
        for path in &output_paths(request, 0, "main", false) {
            prepare_output(path)?;
        }
    }
    let loading = crate::progress::Step::new(true, 1, &format!("loading {}", request.scene));
    let load_started = Instant::now();
    let aspect = request.settings.width as f32 / request.settings.height as f32;
    let (mut scene, mut tessellation, camera) = load_scene_edited(
        &request.scene,
        &[(&request.method, &request.options)],
        request.max_edge,
        request.allow_external_paths,
        request.emitter_lights,
        (&request.edits, request.camera.as_deref(), aspect),
    )?;
    let mut load_ms = load_started.elapsed().as_secs_f64() * 1000.0;
    // The camera as the command line named it, for loading the scene again.
    let requested_camera = request.camera.clone();
    loading.inc(1);
    loading.finish();
    // From here on the request names the camera the edits chose.
    let request = &RenderRequest {
        camera,
        ..request.clone()
    };
    for warning in &scene.warnings {
        log::warn!("{warning}");
    }
    if request.frames.is_some() && scene.animations.is_empty() {
        log::warn!(
            "scene '{}' has no animation: every frame is the same",
            scene.name
        );
    }
    if request.indirect_only && request.method == "direct" {
        log::warn!("--indirect-only with method 'direct': the image is black by definition");
    }
    let setup_started = Instant::now();
    let ctx = GpuContext::new()?;
    let first_world = scene.world_from_node_at(request.time);
    let rig = rig_views(request, &scene, &first_world)?;
    let settings = crate::raster::RenderSettings {
        camera: scene.camera_index(request.camera.as_deref()),
        views_per_frame: rig.len() as u32,
        ..request.settings
    };
    let preparing = crate::progress::Step::new(true, 1, &format!("preparing {}", request.method));
    let mut method = method::create_or(
        &request.method,
        request.method_fallback.as_deref(),
        "rendering",
        &ctx,
        &scene,
        settings,
        &request.options,
    )?;
    preparing.inc(1);
    preparing.finish();
    crate::progress::check()?;
    // Under a time budget an imported scene was refined for the densest candidate, since the
    // point count is measured on the device; with the choice made, the scene is refined for
    // it and the choice built again over it, its budget report kept.
    let mut retessellation = None;
    if let Some(resolved) = refines_for_time_budget(request, &tessellation, method.as_ref()) {
        let reloading = Instant::now();
        let (refined, refined_tessellation, _) = load_scene_edited(
            &request.scene,
            &[(method.name(), &resolved)],
            None,
            request.allow_external_paths,
            request.emitter_lights,
            (&request.edits, requested_camera.as_deref(), aspect),
        )?;
        let reload_ms = reloading.elapsed().as_secs_f64() * 1000.0;
        load_ms += reload_ms;
        retessellation = Some(Retessellation {
            budget: method.report().remove("budget"),
            densest_edge: tessellation.max_edge,
            reload_ms,
        });
        let name = method.name();
        // The dense scene's method goes first: its GPU memory is not needed again.
        drop(method);
        method = method::create(name, &ctx, &refined, settings, &resolved)?;
        scene = refined;
        tessellation = refined_tessellation;
    }
    // The method's construction: GPU context, uploads, pipelines and its preprocessing (a
    // second load of the scene counts as loading).
    let reload_ms = retessellation.as_ref().map_or(0.0, |r| r.reload_ms);
    let setup_ms = setup_started.elapsed().as_secs_f64() * 1000.0 - reload_ms;
    log::info!(
        "scene loaded in {load_ms:.0} ms, method '{}' set up in {setup_ms:.0} ms",
        request.method
    );
    let mut views = Vec::new();
    for rig in rig {
        views.push(View::new(
            &ctx,
            &rig.name,
            rig.camera,
            rig.size,
            settings.ssaa,
        )?);
    }
    let view_bytes: u64 = views.iter().map(View::gpu_bytes).sum();
    settings.check_gpu_memory(
        &format!("method '{}' with its views", request.method),
        method.gpu_bytes() + view_bytes,
    )?;
    let mut frame_ms = Vec::with_capacity(frames as usize);
    let mut non_finite = 0;
    let mut last = None;
    let mut written = Vec::new();
    let mut last_images = Vec::new();
    let mut memory = Vec::new();
    let mut exposure: Option<f32> = None;
    let frames_step = crate::progress::Step::new(frames > 1, frames as u64, "frames");
    for index in 0..frames {
        // Ctrl-C stops between frames and before a frame's files are written; frames already
        // written are whole files.
        crate::progress::check()?;
        let time = request.time + index as f32 / request.fps;
        let world_from_node = scene.world_from_node_at(time);
        for (view, rig) in views
            .iter_mut()
            .zip(rig_views(request, &scene, &world_from_node)?)
        {
            view.camera = rig.camera;
        }
        let frame = record_frame(method.as_mut(), &ctx, &scene, &world_from_node, &views)?;
        if index == 0 {
            // Per-view state a method makes on its first frame counts too.
            settings.check_gpu_memory(
                &format!("method '{}' after its first frame", request.method),
                owned_gpu_bytes(method.as_ref(), &views, &frame.results),
            )?;
        }
        crate::progress::check()?;
        last_images.clear();
        let write = request.write_images;
        for (view, result) in views.iter().zip(&frame.results).filter(|_| write) {
            let (direct, indirect) = view.read(&ctx, result.has_indirect())?;
            let mut image = if request.indirect_only {
                indirect
            } else {
                direct.add(&indirect)
            };
            non_finite += image.sanitize();
            // One exposure for the whole run (from the first image), so frames do not flicker.
            let exposure = *exposure.get_or_insert_with(|| {
                if request.auto_exposure {
                    crate::image_io::key_exposure(&image).unwrap_or(0.0)
                } else {
                    request.exposure
                }
            });
            for path in output_paths(request, index, &view.name, multi_view) {
                if index > 0 || multi_view {
                    prepare_output(&path)?;
                }
                image.write(&path, exposure)?;
                let is_png = path
                    .extension()
                    .is_some_and(|e| e.eq_ignore_ascii_case("png"));
                if is_png && index == 0 {
                    warn_if_dark(&path, &image, exposure, request.auto_exposure);
                }
                written.push(path.display().to_string());
            }
            last_images.push(image);
        }
        frame_ms.push(round3(frame.timings.merged().total_ms()));
        let done = index + 1;
        if request.memory_every > 0 && (index == 0 || done % request.memory_every == 0) {
            memory.push(MemorySample {
                frame: done,
                resident_bytes: memory::resident_bytes(),
                gpu_bytes: owned_gpu_bytes(method.as_ref(), &views, &frame.results),
            });
        }
        last = Some(frame);
        frames_step.inc(1);
    }
    frames_step.finish();
    if non_finite > 0 {
        log::warn!("{non_finite} pixels had non-finite radiance; written as black");
    }
    let frame = last.expect("at least one frame");
    if multi_view && request.frames.is_none() && request.write_images {
        if let Some(first) = request.outputs.first() {
            let sheet = with_stem_suffix(first, "_views").with_extension("png");
            prepare_output(&sheet)?;
            side_by_side(&last_images).write(&sheet, exposure.unwrap_or(request.exposure))?;
            written.push(sheet.display().to_string());
        }
    }
    let variance_outputs = if multi_view || request.frames.is_some() || !request.write_images {
        vec![]
    } else {
        write_variance(method.as_ref(), request)?
    };
    let merged = frame.timings.merged();
    let gpu_bytes = owned_gpu_bytes(method.as_ref(), &views, &frame.results);
    let mut report = serde_json::json!({
        "scene": scene.name,
        "method": method.name(),
        "options": request.options.to_string(),
        "width": settings.width,
        "height": settings.height,
        "ssaa": settings.ssaa,
        "passes": merged.to_json(),
        "total_ms": round3(merged.total_ms()),
        "gpu_timestamps": merged.gpu_timestamps,
        "gpu_bytes": gpu_bytes,
        "adapter": ctx.adapter_label(),
        "lights": scene.lights.len(),
        "triangles": scene.triangle_count(),
        "indirect_only": request.indirect_only,
        "non_finite_pixels": non_finite,
        "exposure": exposure.map(|e| (e * 1000.0).round() / 1000.0),
        // Of the last frame's images (sanitized, so finite), per view: a black or blown-out
        // render shows here without opening the file.
        "mean_luminance": last_images
            .iter()
            .map(|image| crate::eval::metrics::mean_luminance(image) as f32)
            .collect::<Vec<_>>(),
        "dark_fraction": last_images
            .iter()
            .map(|image| round3(crate::image_io::dark_fraction(image, exposure.unwrap_or(0.0))))
            .collect::<Vec<_>>(),
        "warnings": scene.warnings.len(),
        "outputs": written,
        "views": views.iter().map(|v| v.name.clone()).collect::<Vec<_>>(),
        "view_rig": request.views.label(),
        // Same-size views are recorded one pass per view; wgpu's multiview layers are not
        // used.
        "view_recording": "one pass per view",
        "solution_ms": round3(frame.timings.solution.total_ms()),
        "solution_passes": frame.timings.solution.to_json(),
        "view_ms": frame.timings.views.iter().map(|t| round3(t.total_ms())).collect::<Vec<_>>(),
        "view_passes": frame.timings.views.iter().map(|t| t.to_json()).collect::<Vec<_>>(),
        "solution_pass_counts": frame
            .solution_pass_counts
            .iter()
            .map(|(l, n)| (l.clone(), serde_json::json!(n)))
            .collect::<serde_json::Map<_, _>>(),
    });
    if !variance_outputs.is_empty() {
        report["variance_outputs"] = serde_json::json!(variance_outputs);
    }
    if !memory.is_empty() {
        report["memory"] = memory.iter().map(MemorySample::to_json).collect();
        // Growth over the second half of the run: the first half is warm-up (pipelines,
        // caches, the allocator's arenas).
        if let Some(growth) = memory::growth_after(&memory, frames / 2) {
            report["memory_growth"] = serde_json::json!({
                "frames": growth.frames,
                "rss_bytes": growth.resident_bytes,
                "rss_fraction": growth.resident_fraction,
                "gpu_bytes": growth.gpu_bytes,
            });
        }
    }
    if let Some(frames) = request.frames {
        let dir = request
            .outputs
            .first()
            .cloned()
            .unwrap_or_else(|| PathBuf::from("out/frames"));
        report["frames"] = serde_json::json!(frames);
        report["fps"] = serde_json::json!(request.fps);
        report["frame_total_ms"] = serde_json::json!(frame_ms);
        report["last_frame_passes"] = merged.to_json();
        report["out_dir"] = serde_json::json!(if is_image_path(&dir) {
            dir.parent()
                .unwrap_or(std::path::Path::new("."))
                .display()
                .to_string()
        } else {
            dir.display().to_string()
        });
    }
    if let Some(obj) = report.as_object_mut() {
        obj.extend(tessellation.to_json());
        obj.insert("load_ms".into(), serde_json::json!(round3(load_ms)));
        obj.insert("setup_ms".into(), serde_json::json!(round3(setup_ms)));
        obj.extend(method.report());
        if let Some(budget) = retessellation.as_ref().and_then(|r| r.budget.clone()) {
            obj.insert("budget".into(), budget);
        }
        // Budget mode says what it chose and why a line per knob; an imported scene's
        // tessellation is one of them, chosen as the scene was loaded (or loaded again).
        if let Some(budget) = obj.get_mut("budget").and_then(|b| b.as_object_mut()) {
            let mut why = match tessellation.source {
                "option" => "given".to_string(),
                _ => tessellation.why.clone(),
            };
            if let Some(again) = &retessellation {
                why = format!(
                    "{why}: the scene was refined again for the choice, which the budget made \
                     on it refined for the densest candidate ({:.3e} m); loading it again took \
                     {:.0} ms",
                    again.densest_edge, again.reload_ms
                );
            }
            budget.insert(
                "max_edge".into(),
                serde_json::json!({ "value": tessellation.max_edge, "why": why }),
            );
        }
        obj.insert(
            "wall_ms".into(),
            serde_json::json!(round3(started.elapsed().as_secs_f64() * 1000.0)),
        );
    }
    Ok(report)
}

/// A scene loaded again for a time budget's choice ([`refines_for_time_budget`]).
struct Retessellation {
    /// The budget's report, from the method built over the scene as first refined.
    budget: Option<serde_json::Value>,
    /// The edge the scene was first refined to, for the densest candidate, metres.
    densest_edge: f32,
    /// What loading it again took, ms.
    reload_ms: f64,
}

/// The options that build `method`'s time-budget choice again over the scene refined for it,
/// when the scene was refined for the densest candidate instead: an imported scene (a built-in
/// one is never refined past its own tessellation) whose tessellation followed the sparse
/// points' spacing, under `--budget-ms` with the point count left to the budget, which chose
/// fewer points. `sparse` only: `sparse+atlas` would bake its atlas a second time, which costs
/// more than the coarser mesh saves (Sponza at 8192 points: 1377 against 1488 ms a frame at
/// 1280×720 on lavapipe).
fn refines_for_time_budget(
    request: &RenderRequest,
    tessellation: &Tessellation,
    method: &dyn Method,
) -> Option<MethodOptions> {
    let imported =
        scene::resolve_alias(&request.scene).is_ok_and(|spec| scene::is_file_spec(&spec));
    let time_budget = matches!(
        crate::vals::budget_target(&request.options),
        Ok(Some(crate::vals::budget::BudgetTarget::Ms(_)))
    );
    // A `--max-edge` given makes the source `option`.
    if tessellation.source != "sparse spacing"
        || !imported
        || !time_budget
        || request.options.given("sparse-points")
        || method.name() != "sparse"
    {
        return None;
    }
    let resolved = MethodOptions::from_pairs(method.resolved_options()?);
    let chosen: usize = resolved.get("sparse-points", 0).ok()?;
    let densest = *crate::vals::budget::CANDIDATE_POINTS.last()?;
    (chosen > 0 && chosen < densest).then_some(resolved)
}

/// The tessellation a scene was loaded with and why.
#[derive(Clone, Debug, PartialEq)]
pub struct Tessellation {
    /// Longest triangle edge asked for, metres.
    pub max_edge: f32,
    /// `"option"` (given), `"sparse spacing"` (for a sparse method: an imported scene, or a
    /// built-in one's meshes built coarser than its 5 cm) or `"default"` (the built-in
    /// scenes' 5 cm).
    pub source: &'static str,
    /// The edge the meshes were refined to: `max_edge` unless the triangle budget raised it
    /// (the scene's warnings say so); `None` when nothing was refined.
    pub used_max_edge: Option<f32>,
    /// Why `max_edge` is what it is, in words.
    pub why: String,
}

impl Tessellation {
    pub fn to_json(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        map.insert("max_edge".into(), serde_json::json!(self.max_edge));
        map.insert("max_edge_source".into(), serde_json::json!(self.source));
        map.insert("max_edge_why".into(), serde_json::json!(self.why));
        map.insert(
            "max_edge_used".into(),
            serde_json::json!(self.used_max_edge),
        );
        map
    }
}

/// Loads `spec` for the given methods. An explicit `max_edge` wins; without one, built-in
/// scenes keep their 5 cm tessellation (stored reference images depend on it), and an
/// imported scene rendered by a method that gathers at sparse points is refined to those
/// points' spacing ([`crate::vals::default_max_edge`]; with several such methods the
/// finest), instead of 5 cm: Sponza at 5 cm is the 2-million-triangle budget, at its 4096
/// points' spacing (≈1 m) it keeps its 262k triangles plus the splits of its large floors.
/// Other methods keep 5 cm.
pub fn load_scene(
    spec: &str,
    methods: &[(&str, &MethodOptions)],
    max_edge: Option<f32>,
    allow_external_paths: bool,
    emitter_lights: u32,
) -> Result<(scene::Scene, Tessellation), AppError> {
    let none = crate::scene::edits::SceneEdits::default();
    let (scene, tessellation, _) = load_scene_edited(
        spec,
        methods,
        max_edge,
        allow_external_paths,
        emitter_lights,
        (&none, None, 1.0),
    )?;
    Ok((scene, tessellation))
}

/// [`load_scene`] with the command line's lights and camera applied (`edits`, the camera
/// selector and the image's aspect): the tessellation's choice sees them too (budget mode
/// surveys the lit scene from that camera). Returns the camera the edits leave it with.
pub fn load_scene_edited(
    spec: &str,
    methods: &[(&str, &MethodOptions)],
    max_edge: Option<f32>,
    allow_external_paths: bool,
    emitter_lights: u32,
    (edits, camera, aspect): (&crate::scene::edits::SceneEdits, Option<&str>, f32),
) -> Result<(scene::Scene, Tessellation, Option<String>), AppError> {
    let fallback = BuiltinParams::default().max_edge;
    let params = scene::LoadParams {
        max_edge: max_edge.unwrap_or(fallback),
        allow_external_paths,
        emitter_lights,
    };
    let mut failure: Option<AppError> = None;
    // The finest sparse method's edge and why.
    let mut finest: Option<(f32, String)> = None;
    let (mut scene, edges) = scene::load_choosing_max_edge(spec, &params, |raw| {
        if max_edge.is_some() {
            return None;
        }
        // The raw scene with the edits, when a method will survey it.
        let mut edited = None;
        for (method, options) in methods {
            if crate::vals::uses_sparse_points(method)
                && crate::vals::surveys_for_tessellation(options).unwrap_or(false)
                && edited.is_none()
            {
                let mut copy = raw.clone();
                match edits.apply(&mut copy, camera, aspect) {
                    Ok(selector) => edited = Some((copy, selector)),
                    Err(e) => failure = Some(e.into()),
                }
            }
        }
        for (method, options) in methods {
            if !crate::vals::uses_sparse_points(method) {
                continue;
            }
            let view = edited
                .as_ref()
                .map(|(s, selector)| (s, selector.as_deref(), aspect));
            match crate::vals::default_max_edge(raw, options, view) {
                Ok(Some((edge, why))) => {
                    if finest.as_ref().is_none_or(|(f, _)| edge < *f) {
                        finest = Some((edge, why));
                    }
                }
                Ok(None) => {}
                Err(e) => failure = Some(e.into()),
            }
        }
        finest.as_ref().map(|(edge, _)| *edge)
    })?;
    if let Some(e) = failure {
        return Err(e);
    }
    let camera = edits.apply(&mut scene, camera, aspect)?;
    let (max_edge, source, why) = match (max_edge, edges.chosen) {
        (Some(given), _) => (given, "option", "given (--max-edge)".to_string()),
        (None, Some(chosen)) => {
            let (edge, mut why) = finest.unwrap_or((chosen, String::new()));
            // A built-in scene is never refined past the tessellation it was built with.
            if chosen > edge {
                why = format!("{why}; no finer than the built-in scene's {fallback} m");
            }
            (chosen, "sparse spacing", why)
        }
        (None, None) => (
            fallback,
            "default",
            format!("{fallback} m, the default without a method that gathers at sparse points"),
        ),
    };
    Ok((
        scene,
        Tessellation {
            max_edge,
            source,
            used_max_edge: edges.used,
            why,
        },
        camera,
    ))
}

/// GPU bytes the method and its views' targets own.
fn owned_gpu_bytes(method: &dyn Method, views: &[View], results: &[ViewResult]) -> u64 {
    method.gpu_bytes()
        + views
            .iter()
            .zip(results)
            .map(|(v, r)| r.view_bytes(v))
            .sum::<u64>()
}

/// The views' images next to each other, top-aligned, for people to look at.
fn side_by_side(images: &[crate::image_io::Image]) -> crate::image_io::Image {
    let width: u32 = images.iter().map(|i| i.width).sum();
    let height = images.iter().map(|i| i.height).max().unwrap_or(1);
    let mut sheet = crate::image_io::Image::new(width.max(1), height);
    let mut x0 = 0;
    for image in images {
        for y in 0..image.height {
            for x in 0..image.width {
                sheet.pixels[(y * sheet.width + x0 + x) as usize] =
                    image.pixels[(y * image.width + x) as usize];
            }
        }
        x0 += image.width;
    }
    sheet
}

/// `<stem>.variance.exr` beside every EXR output of a method that estimates its own per-pixel
/// variance (the reference): the variance of each pixel's mean, per channel.
fn write_variance(
    method: &dyn method::Method,
    request: &RenderRequest,
) -> Result<Vec<String>, AppError> {
    let Some(variance) = method.variance(request.indirect_only) else {
        return Ok(vec![]);
    };
    let mut written = vec![];
    for path in &request.outputs {
        if path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            == Some("exr".into())
        {
            let out = path.with_extension("variance.exr");
            variance.write_exr(&out)?;
            written.push(out.display().to_string());
        }
    }
    Ok(written)
}
