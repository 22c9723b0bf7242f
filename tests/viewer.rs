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
    let cave = format!(
        "cave:{}",
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("data/cave/cornell_4wall.json")
            .display()
    );
    for (rig, views) in [
        ("mono", "mono"),
        ("stereo", "stereo"),
        ("cave", cave.as_str()),
    ] {
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
            views,
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
        // A CAVE rig is shown as its walls side by side, in the file's order.
        let names: &[&str] = match rig {
            "mono" => &["render_mono.png"],
            "stereo" => &["render_stereo_left.png", "render_stereo_right.png"],
            _ => &[
                "render_cave_left.png",
                "render_cave_front.png",
                "render_cave_right.png",
                "render_cave_floor.png",
            ],
        };
        let mut regions = vec![];
        let mut x0 = 0;
        for (i, name) in names.iter().enumerate() {
            let reference = load(&dir.join(name));
            let (max_diff, mean) = compare(&shot, x0, &reference);
            eprintln!("{rig} view {i}: max difference {max_diff} levels, mean {mean:.1}");
            assert!(mean > 10.0, "{rig} view {i} is black (mean {mean:.2})");
            assert!(
                max_diff <= MAX_LEVELS,
                "{rig} view {i} differs from `valgi render` by {max_diff} levels"
            );
            x0 += reference.width();
            regions.push(reference);
        }
        if rig == "stereo" {
            assert_ne!(regions[0], regions[1], "the two eyes see the same image");
        }
    }
}

#[test]
fn anaglyph_takes_red_from_the_left_eye_and_cyan_from_the_right() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_anaglyph");
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
        "stereo",
    ];
    let shot = dir.join("shot.png");
    let mut view_args = vec!["view"];
    view_args.extend(base);
    view_args.extend(["--anaglyph", "--frames", "2", "--screenshot"]);
    view_args.push(shot.to_str().unwrap());
    let Some(command) = windowed(&view_args) else {
        return;
    };
    let report = run(command);
    assert!(
        report.contains("\"stereo_display\":\"anaglyph\""),
        "report: {report}"
    );
    let reference = dir.join("render.png");
    let mut render = Command::new(env!("CARGO_BIN_EXE_valgi"));
    render
        .arg("render")
        .args(base)
        .args(["--out", reference.to_str().unwrap()]);
    run(render);
    let shot = load(&shot);
    let left = load(&dir.join("render_left.png"));
    let right = load(&dir.join("render_right.png"));
    assert_ne!(left, right, "the two eyes see the same image");
    let mut max_diff = 0u8;
    let mut second_region_sum = 0u64;
    for (x, y, l) in left.enumerate_pixels() {
        let r = right.get_pixel(x, y);
        let q = shot.get_pixel(x, y);
        let expected = [l[0], r[1], r[2]];
        for c in 0..3 {
            max_diff = max_diff.max(expected[c].abs_diff(q[c]));
        }
        let beside = shot.get_pixel(x + left.width(), y);
        second_region_sum += beside.0.iter().map(|&v| v as u64).sum::<u64>();
    }
    eprintln!("anaglyph: max difference {max_diff} levels");
    assert!(
        max_diff <= MAX_LEVELS,
        "the anaglyph differs from (left red, right green/blue) by {max_diff} levels"
    );
    // Both eyes land in the first region; the second stays clear.
    assert_eq!(
        second_region_sum, 0,
        "the right eye's region was drawn into"
    );
}

#[test]
fn an_option_change_rebuilds_off_the_ui_thread_and_reports_its_figures() {
    if common::gpu().is_none() {
        return;
    }
    let args = [
        "view",
        "--scene",
        "cornell",
        "--method",
        "sparse",
        "--width",
        "32",
        "--height",
        "32",
        "--shadow-res",
        "128",
        "--opt",
        "rsm=16",
        "--opt",
        "sparse-points=64",
        "--frames",
        "2",
        "--change-option",
        "sparse-points=96",
    ];
    let Some(command) = windowed(&args) else {
        return;
    };
    let stdout = run(command);
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON line in {stdout}"));
    let report: serde_json::Value = serde_json::from_str(line).expect("JSON report");
    eprintln!("{}", report["rebuild"]);
    assert_eq!(report["rebuild"]["ok"], true, "report: {report}");
    assert_eq!(report["rebuild"]["method"], "sparse");
    // The rebuilt method is the one drawing: its own figures, as `render` reports them.
    assert_eq!(report["sparse_points"], 96, "report: {report}");
    assert!(report["options"]
        .as_str()
        .unwrap()
        .contains("sparse-points=96"));
    assert!(report["vals"].as_u64().unwrap() > 0, "report: {report}");
    assert!(report["gpu_bytes"].as_u64().unwrap() > 0);
    assert!(report["frame_interval_ms"]["frames"].as_u64().unwrap() >= 2);
}
