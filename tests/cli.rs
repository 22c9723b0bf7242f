//! The `valgi` binary end to end: its JSON report, its files, and clear errors for bad input.

mod common;

use std::process::Command;

fn valgi() -> Command {
    Command::new(env!("CARGO_BIN_EXE_valgi"))
}

#[test]
fn render_writes_exr_and_png_and_reports_json() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-render");
    let exr = dir.join("nested/plane.exr");
    let png = dir.join("plane.png");
    let output = valgi()
        .args([
            "render",
            "--scene",
            "plane-spot",
            "--width",
            "48",
            "--height",
            "32",
        ])
        .args(["--ssaa", "2", "--out"])
        .arg(&exr)
        .arg("--out")
        .arg(&png)
        .output()
        .expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "valgi failed: {stderr}");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let line = stdout.lines().last().expect("a JSON line");
    let report: serde_json::Value = serde_json::from_str(line).expect("valid JSON");
    for key in [
        "scene",
        "method",
        "width",
        "height",
        "passes",
        "total_ms",
        "gpu_bytes",
        "adapter",
    ] {
        assert!(report.get(key).is_some(), "missing key {key} in {line}");
    }
    assert_eq!(report["scene"], "plane-spot");
    assert_eq!(report["method"], "direct");
    assert_eq!(report["width"], 48);
    for pass in ["shadow", "gbuffer", "direct", "resolve"] {
        assert!(
            report["passes"][pass].as_f64().is_some(),
            "no time for pass {pass}"
        );
    }
    assert!(report["gpu_bytes"].as_u64().unwrap() > 48 * 32 * 16);
    let img = valgi::image_io::Image::read_exr(&exr).expect("EXR written");
    assert_eq!((img.width, img.height), (48, 32));
    let decoded = image::open(&png).expect("PNG written").to_rgb8();
    assert_eq!(decoded.dimensions(), (48, 32));
}

#[test]
fn unwritable_output_fails_before_rendering_and_names_the_path() {
    let output = valgi()
        .args([
            "render",
            "--scene",
            "plane-point",
            "--out",
            "/proc/valgi-no/x.exr",
        ])
        .output()
        .expect("run valgi");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("/proc/valgi-no/x.exr"), "{stderr}");
}

#[test]
fn bad_extension_and_bad_scene_are_clear_errors() {
    let dir = common::temp_dir("cli-bad");
    let output = valgi()
        .args(["render", "--scene", "plane-point", "--out"])
        .arg(dir.join("x.jpg"))
        .output()
        .expect("run valgi");
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("x.jpg"));

    let truncated = dir.join("broken.gltf");
    std::fs::write(
        &truncated,
        br#"{"asset": {"version": "2.0"}, "scenes": [{"no"#,
    )
    .unwrap();
    let output = valgi()
        .args(["render", "--scene"])
        .arg(&truncated)
        .arg("--out")
        .arg(dir.join("x.exr"))
        .output()
        .expect("run valgi");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("broken.gltf"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");

    let output = valgi()
        .args(["render", "--scene", "no-such-scene"])
        .arg("--out")
        .arg(dir.join("x.exr"))
        .output()
        .expect("run valgi");
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("no-such-scene"));
}

#[test]
fn scenes_lists_the_built_ins() {
    let output = valgi().arg("scenes").output().expect("run valgi");
    assert!(output.status.success());
    let stdout = String::from_utf8_lossy(&output.stdout);
    for name in ["cornell", "cornell-point", "plane-point", "plane-spot"] {
        assert!(
            stdout.lines().any(|l| l.starts_with(name)),
            "{name} missing: {stdout}"
        );
    }
}

#[test]
fn sparse_renders_numbered_frames_of_an_animation_with_table2_timings() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-frames");
    let output = valgi()
        .args([
            "render",
            "--scene",
            "cornell-moving",
            "--method",
            "sparse",
            "--width",
            "32",
            "--height",
            "32",
        ])
        .args([
            "--rsm",
            "32",
            "--sparse-points",
            "300",
            "--occlusion",
            "union",
            "--glossy",
            "on",
        ])
        .args([
            "--max-edge",
            "0.15",
            "--indirect-only",
            "--frames",
            "3",
            "--out",
        ])
        .arg(&dir)
        .output()
        .expect("run valgi");
    common::assert_success(&output);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let report: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    for key in [
        "rsm",
        "direct",
        "gather",
        "renormalize",
        "occlusion",
        "interpolation",
        "apply",
        "total",
    ] {
        assert!(
            report["table2"][key].as_f64().is_some(),
            "table2.{key} missing: {report}"
        );
    }
    assert!(report["vals"].as_u64().unwrap() > 100);
    assert_eq!(report["sparse_points"].as_u64(), Some(300));
    assert_eq!(report["frames"].as_u64(), Some(3));
    let frames: Vec<valgi::image_io::Image> = (0..3)
        .map(|i| {
            valgi::image_io::Image::read_exr(&dir.join(format!("frame_{i:04}.exr"))).expect("frame")
        })
        .collect();
    // The light sweeps: consecutive frames differ.
    assert_ne!(frames[0].pixels, frames[2].pixels);

    // --frames without a single output folder, and an option the method lacks, are errors.
    let output = valgi()
        .args(["render", "--method", "direct", "--rsm", "64"])
        .output()
        .unwrap();
    assert!(!output.status.success());
    assert!(String::from_utf8_lossy(&output.stderr).contains("has no option(s) rsm"));
}
