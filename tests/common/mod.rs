//! Shared test helpers.
#![allow(dead_code)]

use valgi::gpu::GpuContext;
use valgi::raster::RenderSettings;

/// A square image of `size` pixels with 256² shadow maps: small enough for tests.
pub fn small_render_settings(size: u32) -> RenderSettings {
    RenderSettings {
        width: size,
        height: size,
        shadow_resolution: 256,
        ..RenderSettings::default()
    }
}

/// The GPU device, or `None` (with a loud message) when there is none. Under CI
/// (`CI=true`) a missing adapter fails the test: CI must never pass while testing nothing.
pub fn gpu() -> Option<GpuContext> {
    gpu_with_limits(|_| {})
}

/// [`gpu`] on a device asked for the adapter's limits as changed by `adjust`.
pub fn gpu_with_limits(adjust: impl Fn(&mut wgpu::Limits)) -> Option<GpuContext> {
    match GpuContext::with_limits(adjust) {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            if std::env::var("CI")
                .map(|v| v == "true" || v == "1")
                .unwrap_or(false)
            {
                panic!("CI=true but no GPU adapter: {e}");
            }
            eprintln!("SKIPPED (no GPU adapter; set up Mesa's lavapipe to run it): {e}");
            None
        }
    }
}

/// A fresh folder for one test's files.
pub fn temp_dir(test: &str) -> std::path::PathBuf {
    static MADE: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());
    let dir = std::env::temp_dir().join(format!("valgi-{test}-{}", std::process::id()));
    // The first call in this process finds any folder of this name left over from an earlier
    // run whose process had the same id, and starts it empty, so listings see only this run's
    // files; later calls (a test asking again for its folder) keep what it wrote.
    let mut made = MADE.lock().unwrap_or_else(|e| e.into_inner());
    if !made.iter().any(|m| m == test) {
        made.push(test.to_string());
        if dir.exists() {
            std::fs::remove_dir_all(&dir).expect("clear a leftover temp dir");
        }
    }
    std::fs::create_dir_all(&dir).expect("create temp dir");
    dir
}

/// Compares a rendered image, tone-mapped at `exposure`, with the stored reference
/// `data/references/<name>.png` by mean FLIP. On failure it writes the actual image and the
/// FLIP error map to `target/image-test-failures/`. `VALGI_UPDATE_REFERENCES=1` rewrites the
/// reference instead (review the new image before committing it).
pub fn assert_matches_reference(
    name: &str,
    image: &valgi::image_io::Image,
    exposure: f32,
    max_mean_flip: f32,
) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let reference_path = root.join("data/references").join(format!("{name}.png"));
    let actual = image.tone_map(exposure);
    if std::env::var("VALGI_UPDATE_REFERENCES").is_ok_and(|v| v == "1") {
        std::fs::create_dir_all(reference_path.parent().unwrap()).unwrap();
        actual.save(&reference_path).expect("write reference");
        eprintln!("updated {}", reference_path.display());
        return;
    }
    let reference = image::open(&reference_path)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (create it with VALGI_UPDATE_REFERENCES=1)",
                reference_path.display()
            )
        })
        .to_rgb8();
    assert_eq!(
        reference.dimensions(),
        actual.dimensions(),
        "{name}: size differs from the reference"
    );
    let (w, h) = actual.dimensions();
    let error_map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, reference.as_raw()),
        nv_flip::FlipImageRgb8::with_data(w, h, actual.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mean = nv_flip::FlipPool::from_image(&error_map).mean();
    if mean > max_mean_flip {
        let out = root.join("target/image-test-failures");
        std::fs::create_dir_all(&out).unwrap();
        actual.save(out.join(format!("{name}.actual.png"))).unwrap();
        let diff = error_map.apply_color_lut(&nv_flip::magma_lut());
        image::RgbImage::from_raw(w, h, diff.to_vec())
            .unwrap()
            .save(out.join(format!("{name}.flip.png")))
            .unwrap();
        panic!(
            "{name}: mean FLIP {mean:.4} > {max_mean_flip} against {}; actual and error map in {}",
            reference_path.display(),
            out.display()
        );
    }
}

/// Renders `method` (an `atlas` method) from the scene's camera and asserts that no surface in
/// view samples a black atlas texel and that no surface pixel's indirect light is black.
/// Returns the frame.
pub fn assert_no_black_texels_in_view(
    ctx: &GpuContext,
    scene: &valgi::scene::Scene,
    method: &mut valgi::atlas::AtlasMethod,
    size: u32,
) -> valgi::raster::FrameOutput {
    use valgi::method::Method;
    let wfn = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &wfn).unwrap();
    let frame = method.render(ctx, scene, &wfn, &camera).unwrap();
    let e = method.layer().read_irradiance(ctx).unwrap();
    let surface = e.pixels.iter().filter(|p| p[3] > 0.0).count();
    let black = e
        .pixels
        .iter()
        .filter(|p| p[3] > 0.0 && p[0] + p[1] + p[2] <= 0.0)
        .count();
    eprintln!("{surface} surface pixels, {black} black");
    assert!(surface > (size * size) as usize / 2);
    assert_eq!(black, 0, "black atlas texels in view");
    let indirect_black = frame
        .indirect
        .pixels
        .iter()
        .zip(&e.pixels)
        .filter(|(l, p)| p[3] > 0.0 && l[0] + l[1] + l[2] <= 0.0)
        .count();
    assert_eq!(indirect_black, 0, "indirect radiance black on a surface");
    assert!(method.report()["atlas_missing_texels"] == 0);
    frame
}

/// Runs a command and asserts it succeeded, showing its stderr otherwise.
pub fn assert_success(output: &std::process::Output) {
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// Φ/A of `box-point`: its 1 W/sr point light (4π W) over the closed box's 24 m², the mean
/// direct irradiance; bounce b of the closed box adds ρ^b·Φ/A.
pub const BOX_PHI_OVER_A: f64 = 4.0 * std::f64::consts::PI / 24.0;

/// Mean irradiance (green) of bounce `bounce` (1-based) of a bake over the texels at chart
/// centres (away from seams and padding).
pub fn centre_bounce_mean(result: &valgi::atlas::Bake, bounce: u32) -> f64 {
    let irradiance = &result.irradiance[bounce as usize - 1];
    let (sum, count) = result
        .layout
        .texels
        .iter()
        .filter(|t| t.centre)
        .fold((0.0f64, 0usize), |(sum, count), t| {
            (sum + irradiance[t.index as usize][1] as f64, count + 1)
        });
    sum / count.max(1) as f64
}

/// The path tracer's indirect irradiance (`bounces` bounces, diffuse only, `samples` paths
/// each) at atlas texels, the reference the bake tests compare texels with.
pub fn texel_reference(
    scene: &valgi::scene::Scene,
    texels: &[&valgi::atlas::layout::Texel],
    bounces: u32,
    samples: u32,
    seed: u64,
) -> Vec<glam::Vec3> {
    use valgi::reference::{irradiance_at, Bounces, IrradianceSettings};
    let points: Vec<_> = texels.iter().map(|t| (t.position, t.normal)).collect();
    irradiance_at(
        scene,
        &scene.world_from_node(),
        &points,
        &IrradianceSettings {
            direct: false,
            bounces: Bounces::Limited(bounces),
            samples,
            seed,
            specular: false,
        },
    )
}

/// An OBJ of `count` separate 4 cm triangles on the floor (y = 0, facing up) in rows of 60, 5 cm
/// apart, written into `dir`: each is a light-map chart of its own, so 3000 of them need a
/// 274² atlas (`atlas::layout::min_resolution_for_charts`), more than the default bake's 256².
pub fn separate_triangles_obj(dir: &std::path::Path, count: usize) -> std::path::PathBuf {
    let mut obj = String::new();
    for k in 0..count {
        let (x, z) = ((k % 60) as f32 * 0.05, (k / 60) as f32 * 0.05);
        obj += &format!("v {x} 0 {z}\nv {} 0 {z}\nv {x} 0 {}\n", x + 0.04, z + 0.04);
    }
    for k in 0..count {
        let v = 3 * k + 1;
        obj += &format!("f {v} {} {}\n", v + 2, v + 1);
    }
    let path = dir.join("pieces.obj");
    std::fs::write(&path, obj).expect("write the OBJ");
    path
}

/// The JSON report of a `valgi` run that must have succeeded (its last stdout line).
pub fn success_report(output: &std::process::Output) -> serde_json::Value {
    assert_success(output);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().last().expect("a JSON line");
    serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"))
}
