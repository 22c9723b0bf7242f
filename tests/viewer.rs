//! `valgi view` in a window on a virtual X server: a few frames, a screenshot, and the
//! screenshot's view regions against `valgi render` of the same camera. Runs under
//! `xvfb-run` when it is installed, else on `$DISPLAY`; without either it is skipped loudly,
//! and under `CI=true` it fails (`.ci/setup` installs Xvfb).

mod common;

use std::path::Path;
use std::process::Command;

/// How to reach an X server: through `xvfb-run`, on `$DISPLAY`, or not at all.
fn windowed(args: &[&str]) -> Option<Command> {
    let exe = env!("CARGO_BIN_EXE_valgi");
    let on_path = |tool: &str| {
        std::env::var_os("PATH")
            .is_some_and(|paths| std::env::split_paths(&paths).any(|dir| dir.join(tool).is_file()))
    };
    if on_path("xvfb-run") {
        let mut command = Command::new("xvfb-run");
        command
            .args(["-a", "-s", "-screen 0 1024x768x24", exe])
            .args(args);
        return Some(command);
    }
    if std::env::var_os("DISPLAY").is_some() {
        let mut command = Command::new(exe);
        command.args(args);
        return Some(command);
    }
    if std::env::var("CI").is_ok_and(|v| v == "true" || v == "1") {
        panic!("CI=true but neither xvfb-run nor DISPLAY: .ci/setup installs xvfb");
    }
    eprintln!(
        "SKIPPED: the viewer test needs an X server; install `xvfb` (xvfb-run) or set DISPLAY"
    );
    None
}

fn run(mut command: Command) -> String {
    let output = command.output().expect("run valgi");
    let stdout = String::from_utf8_lossy(&output.stdout).to_string();
    assert!(
        output.status.success(),
        "{command:?} failed\nstdout: {stdout}\nstderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

fn load(path: &Path) -> image::RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Largest per-channel difference and mean of `region` (of `shot` at x0) against `reference`.
fn compare(shot: &image::RgbImage, x0: u32, reference: &image::RgbImage) -> (u8, f64) {
    let mut max_diff = 0u8;
    let mut sum = 0.0;
    for (x, y, p) in reference.enumerate_pixels() {
        let q = shot.get_pixel(x0 + x, y);
        for c in 0..3 {
            max_diff = max_diff.max(p[c].abs_diff(q[c]));
            sum += q[c] as f64;
        }
    }
    (
        max_diff,
        sum / (reference.width() * reference.height() * 3) as f64,
    )
}

const SIZE: &str = "64";
/// 8-bit levels the window may differ from the PNG: the present shader's OETF is the CPU's in
/// f32 (measured 0 on lavapipe); one level covers a GPU `pow` and an sRGB target's hardware
/// encode.
const MAX_LEVELS: u8 = 1;

#[test]
fn view_screenshot_matches_render_in_each_view() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer");
    for rig in ["mono", "stereo"] {
        let shot = dir.join(format!("shot_{rig}.png"));
        let base = [
            "--scene",
            "cornell",
            "--method",
            "direct",
            "--width",
            SIZE,
            "--height",
            SIZE,
            "--shadow-res",
            "256",
            "--views",
            rig,
        ];
        let mut view_args = vec!["view"];
        view_args.extend(base);
        let shot_text = shot.to_str().unwrap();
        view_args.extend(["--frames", "3", "--screenshot", shot_text]);
        let Some(command) = windowed(&view_args) else {
            return;
        };
        let report = run(command);
        assert!(report.contains("\"frames\":3"), "report: {report}");

        let reference = dir.join(format!("render_{rig}.png"));
        let mut render = Command::new(env!("CARGO_BIN_EXE_valgi"));
        render
            .arg("render")
            .args(base)
            .args(["--out", reference.to_str().unwrap()]);
        run(render);

        let shot = load(&shot);
        let names: &[&str] = if rig == "mono" {
            &["render_mono.png"]
        } else {
            &["render_stereo_left.png", "render_stereo_right.png"]
        };
        let mut regions = vec![];
        for (i, name) in names.iter().enumerate() {
            let reference = load(&dir.join(name));
            let x0 = i as u32 * reference.width();
            let (max_diff, mean) = compare(&shot, x0, &reference);
            eprintln!("{rig} view {i}: max difference {max_diff} levels, mean {mean:.1}");
            assert!(mean > 10.0, "{rig} view {i} is black (mean {mean:.2})");
            assert!(
                max_diff <= MAX_LEVELS,
                "{rig} view {i} differs from `valgi render` by {max_diff} levels"
            );
            regions.push(reference);
        }
        if rig == "stereo" {
            assert_ne!(regions[0], regions[1], "the two eyes see the same image");
        }
    }
}
