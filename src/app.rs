//! What `valgi render` does, as a library call: load the scene, pick the camera, build the
//! method, render, write the files, and report. The binary only parses arguments.

use std::path::PathBuf;
use std::time::Instant;

use crate::gpu::{GpuContext, GpuError};
use crate::image_io::{prepare_output, ImageError};
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
}

/// One `valgi render` invocation.
#[derive(Clone, Debug)]
pub struct RenderRequest {
    /// Built-in scene name or a `.gltf`/`.glb` path.
    pub scene: String,
    pub method: String,
    /// The method's knobs (`--rsm 64` becomes `rsm=64`).
    pub options: MethodOptions,
    pub settings: RenderSettings,
    /// Camera name or index; `None` = the scene's first camera (or a framing default).
    pub camera: Option<String>,
    /// Files to write; the extension picks EXR or PNG.
    pub outputs: Vec<PathBuf>,
    /// PNG exposure in stops.
    pub exposure: f32,
    pub indirect_only: bool,
    /// Built-in scenes' tessellation (maximum edge length, metres).
    pub max_edge: f32,
    /// Animation time, seconds (of the first frame with `frames`).
    pub time: f32,
    /// Render this many frames as `frame_NNNN.exr` into the single output folder.
    pub frames: Option<u32>,
    /// Frames per second for `frames`.
    pub fps: f32,
}

impl Default for RenderRequest {
    fn default() -> Self {
        Self {
            scene: "cornell".into(),
            method: "direct".into(),
            options: MethodOptions::default(),
            settings: RenderSettings::default(),
            camera: None,
            outputs: vec![],
            exposure: 0.0,
            indirect_only: false,
            max_edge: BuiltinParams::default().max_edge,
            time: 0.0,
            frames: None,
            fps: 30.0,
        }
    }
}

/// Renders and writes the request's outputs; returns the JSON report line.
pub fn render(request: &RenderRequest) -> Result<serde_json::Value, AppError> {
    let started = Instant::now();
    if let Some(frames) = request.frames {
        return render_frames(request, frames, started);
    }
    // Fail on an unwritable output before spending time on the scene and the GPU.
    for path in &request.outputs {
        prepare_output(path)?;
    }
    let scene = scene::load(
        &request.scene,
        &BuiltinParams {
            max_edge: request.max_edge,
        },
    )?;
    for warning in &scene.warnings {
        log::warn!("{warning}");
    }
    let ctx = GpuContext::new()?;
    let settings = request.settings;
    let world_from_node = scene.world_from_node_at(request.time);
    let camera = scene.camera_view(
        request.camera.as_deref(),
        settings.width as f32 / settings.height as f32,
        &world_from_node,
    )?;
    let mut method = method::create(&request.method, &ctx, &scene, settings, &request.options)?;
    let frame = method.render(&ctx, &scene, &world_from_node, &camera)?;
    if request.indirect_only && request.method == "direct" {
        log::warn!("--indirect-only with method 'direct': the image is black by definition");
    }
    let mut image = frame.radiance(request.indirect_only);
    let non_finite = image.sanitize();
    if non_finite > 0 {
        log::warn!("{non_finite} pixels had non-finite radiance; written as black");
    }
    for path in &request.outputs {
        image.write(path, request.exposure)?;
    }
    let variance_outputs = write_variance(method.as_ref(), request)?;
    let mut report = serde_json::json!({
        "scene": scene.name,
        "method": method.name(),
        "options": request.options.to_string(),
        "width": settings.width,
        "height": settings.height,
        "ssaa": settings.ssaa,
        "passes": frame.timings.to_json(),
        "total_ms": crate::gpu::timing::round3(frame.timings.total_ms()),
        "gpu_timestamps": frame.timings.gpu_timestamps,
        "gpu_bytes": frame.gpu_bytes,
        "adapter": ctx.adapter_label(),
        "lights": scene.lights.len(),
        "triangles": scene.triangle_count(),
        "indirect_only": request.indirect_only,
        "non_finite_pixels": non_finite,
        "warnings": scene.warnings.len(),
        "outputs": request.outputs.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    });
    if !variance_outputs.is_empty() {
        report["variance_outputs"] = serde_json::json!(variance_outputs);
    }
    if let Some(obj) = report.as_object_mut() {
        obj.extend(method.report());
        obj.insert(
            "wall_ms".into(),
            serde_json::json!(crate::gpu::timing::round3(
                started.elapsed().as_secs_f64() * 1000.0
            )),
        );
    }
    Ok(report)
}

/// `frame_NNNN.exr` for frame `index` in `dir`.
pub fn frame_path(dir: &std::path::Path, index: u32) -> PathBuf {
    dir.join(format!("frame_{index:04}.exr"))
}

/// Renders `frames` frames of the animation with one method instance (so preprocessing happens
/// once) and writes numbered EXRs into the request's single output folder.
fn render_frames(
    request: &RenderRequest,
    frames: u32,
    started: Instant,
) -> Result<serde_json::Value, AppError> {
    let dir = request
        .outputs
        .first()
        .cloned()
        .unwrap_or_else(|| PathBuf::from("out/frames"));
    if frames == 0 || !(request.fps.is_finite() && request.fps > 0.0) {
        return Err(
            RenderError::Settings("--frames must be at least 1 and --fps positive".into()).into(),
        );
    }
    prepare_output(&frame_path(&dir, 0))?;
    let scene = scene::load(
        &request.scene,
        &BuiltinParams {
            max_edge: request.max_edge,
        },
    )?;
    for warning in &scene.warnings {
        log::warn!("{warning}");
    }
    if scene.animations.is_empty() {
        log::warn!(
            "scene '{}' has no animation: every frame is the same",
            scene.name
        );
    }
    let ctx = GpuContext::new()?;
    let settings = request.settings;
    let mut method = method::create(&request.method, &ctx, &scene, settings, &request.options)?;
    let mut frame_ms = Vec::with_capacity(frames as usize);
    let mut non_finite = 0;
    let mut last_timings = None;
    for index in 0..frames {
        let time = request.time + index as f32 / request.fps;
        let world_from_node = scene.world_from_node_at(time);
        let camera = scene.camera_view(
            request.camera.as_deref(),
            settings.width as f32 / settings.height as f32,
            &world_from_node,
        )?;
        let frame = method.render(&ctx, &scene, &world_from_node, &camera)?;
        let mut image = frame.radiance(request.indirect_only);
        non_finite += image.sanitize();
        image.write(&frame_path(&dir, index), request.exposure)?;
        frame_ms.push(crate::gpu::timing::round3(frame.timings.total_ms()));
        last_timings = Some(frame.timings);
    }
    let mut report = serde_json::json!({
        "scene": scene.name,
        "method": method.name(),
        "options": request.options.to_string(),
        "width": settings.width,
        "height": settings.height,
        "frames": frames,
        "fps": request.fps,
        "frame_total_ms": frame_ms,
        "last_frame_passes": last_timings.map(|t| t.to_json()),
        "adapter": ctx.adapter_label(),
        "indirect_only": request.indirect_only,
        "non_finite_pixels": non_finite,
        "out_dir": dir.display().to_string(),
    });
    if let Some(obj) = report.as_object_mut() {
        obj.extend(method.report());
        obj.insert(
            "wall_ms".into(),
            serde_json::json!(crate::gpu::timing::round3(
                started.elapsed().as_secs_f64() * 1000.0
            )),
        );
    }
    Ok(report)
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
