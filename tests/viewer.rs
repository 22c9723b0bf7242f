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

/// The last JSON line a run printed: its report.
fn report_of(stdout: &str) -> serde_json::Value {
    let line = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with('{'))
        .unwrap_or_else(|| panic!("no JSON line in {stdout}"));
    serde_json::from_str(line).expect("JSON report")
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

/// The arguments `view` and `render` share in the screenshot tests: the Cornell box, direct
/// light only, at SIZE², with `views`.
fn direct_cornell(views: &str) -> [&str; 12] {
    [
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
    ]
}

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
        let base = direct_cornell(views);
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
    let base = direct_cornell("stereo");
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
    let report = report_of(&run(command));
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

/// Runs `valgi view` of the sparse method on the Cornell box with `debug` views on (none when
/// empty) and returns the screenshot and the JSON report.
fn sparse_view(
    dir: &Path,
    name: &str,
    debug: &[&str],
) -> Option<(image::RgbImage, serde_json::Value)> {
    let shot = dir.join(format!("{name}.png"));
    let mut args = vec![
        "view",
        "--scene",
        "cornell",
        "--method",
        "sparse",
        "--width",
        DEBUG_SIZE,
        "--height",
        DEBUG_SIZE,
        "--shadow-res",
        "128",
        "--opt",
        "rsm=16",
        "--opt",
        "sparse-points=200",
        "--frames",
        "1",
        "--screenshot",
        shot.to_str().unwrap(),
    ];
    for view in debug {
        args.extend(["--debug", view]);
    }
    let report = report_of(&run(windowed(&args)?));
    Some((load(&shot), report))
}

const DEBUG_SIZE: &str = "96";

/// Pixels of the view's region (the window's top-left `size`²) that differ between two shots.
fn changed_in_view(plain: &image::RgbImage, debug: &image::RgbImage, size: u32) -> Vec<(u32, u32)> {
    let mut changed = vec![];
    for y in 0..size {
        for x in 0..size {
            if plain.get_pixel(x, y) != debug.get_pixel(x, y) {
                changed.push((x, y));
            }
        }
    }
    changed
}

/// With `--debug points` the view differs from the plain one only in squares around the
/// sparse points' projections, computed here on the CPU from the same point set
/// (`vals::points::scene_points`) and camera; with `--debug vals`, in at most one 4×4 splat
/// per VAL.
#[test]
fn debug_views_draw_splats_at_the_points_and_vals() {
    use valgi::scene::{builtin::BuiltinParams, LoadParams};
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_debug");
    let Some((plain, plain_report)) = sparse_view(&dir, "plain", &[]) else {
        return;
    };
    assert_eq!(plain_report["debug"]["draws"], 0, "{plain_report}");
    let (points_shot, points_report) = sparse_view(&dir, "points", &["points"]).unwrap();
    assert_eq!(points_report["debug"]["draws"], 1, "{points_report}");
    let size: u32 = DEBUG_SIZE.parse().unwrap();

    // The points' projections through the viewer's camera (the scene's first, frame 0).
    let scene = valgi::scene::load_with(
        "cornell",
        &LoadParams {
            max_edge: BuiltinParams::default().max_edge,
            allow_external_paths: false,
            emitter_lights: valgi::scene::emitters::DEFAULT_EMITTER_LIGHTS,
        },
    )
    .unwrap();
    let world_from_node = scene.world_from_node_at(0.0);
    let camera = scene.camera_view(None, 1.0, &world_from_node).unwrap();
    let clip_from_world = camera.clip_from_world();
    let (points, _) = valgi::vals::points::scene_points(&scene, 200, 1);
    let mut projected = vec![];
    for instance in &scene.instances {
        let world_from_model = world_from_node[instance.node];
        for p in &points[instance.mesh].positions {
            let clip = clip_from_world * world_from_model.transform_point3(*p).extend(1.0);
            if clip.w <= 0.0 {
                continue;
            }
            let ndc = clip.truncate() / clip.w;
            if ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0 {
                let s = size as f32;
                projected.push(((ndc.x * 0.5 + 0.5) * s, (0.5 - ndc.y * 0.5) * s));
            }
        }
    }
    let changed = changed_in_view(&plain, &points_shot, size);
    eprintln!(
        "points: {} projected into the view, {} pixels changed",
        projected.len(),
        changed.len()
    );
    // A 4-pixel splat covers the pixel centres within 2 px of its own; one more pixel for
    // rounding at the square's edges.
    let near = |&(x, y): &(u32, u32), &(px, py): &(f32, f32)| {
        (x as f32 + 0.5 - px).abs() <= 3.0 && (y as f32 + 0.5 - py).abs() <= 3.0
    };
    let stray: Vec<_> = changed
        .iter()
        .filter(|c| !projected.iter().any(|p| near(c, p)))
        .collect();
    assert!(
        stray.is_empty(),
        "{} changed pixels lie away from every point's projection, e.g. {:?}",
        stray.len(),
        &stray[..stray.len().min(5)]
    );
    // Most points are in front (the depth test hides those behind the boxes).
    let shown = projected
        .iter()
        .filter(|p| changed.iter().any(|c| near(c, p)))
        .count();
    eprintln!(
        "points: {shown} of {} projections have a splat",
        projected.len()
    );
    assert!(
        shown * 2 > projected.len(),
        "only {shown} of {} points are drawn",
        projected.len()
    );

    let (vals_shot, vals_report) = sparse_view(&dir, "vals", &["vals"]).unwrap();
    assert_eq!(vals_report["debug"]["draws"], 1, "{vals_report}");
    let vals = vals_report["vals"].as_u64().unwrap() as usize;
    let changed = changed_in_view(&plain, &vals_shot, size);
    eprintln!("vals: {vals} VALs, {} pixels changed", changed.len());
    assert!(!changed.is_empty(), "no VAL splat drawn");
    assert!(
        changed.len() <= 16 * vals,
        "{} pixels changed by {vals} VAL splats of 4×4",
        changed.len()
    );
}

/// A scripted run whose method cannot be built exits with the build's error instead of
/// waiting for a method that never comes.
#[test]
fn a_scripted_run_whose_method_fails_to_build_exits_with_its_error() {
    if common::gpu().is_none() {
        return;
    }
    let args = [
        "view", "--scene", "cornell", "--method", "direct", "--width", "32", "--height", "32",
        "--opt", "rsm=16", "--frames", "1",
    ];
    let Some(mut command) = windowed(&args) else {
        return;
    };
    let output = command.output().expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "the run succeeded: {stderr}");
    assert!(stderr.contains("has no option(s) rsm"), "stderr: {stderr}");
}

/// The viewer tessellates an imported scene as `valgi render` does for the method it starts
/// with: refined to the sparse points' spacing for `sparse` (the same edge as `render`), the
/// built-in 5 cm for a method without points.
#[test]
fn the_viewer_tessellates_an_imported_scene_as_render_does() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer-tessellation");
    // A 4 × 3 m floor and a 4 × 2.5 m wall, two triangles each.
    let obj = dir.join("room.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 4 0 0\nv 4 0 3\nv 0 0 3\nv 0 2.5 0\nv 4 2.5 0\n\
         vn 0 1 0\nvn 0 0 1\nf 1//1 4//1 3//1 2//1\nf 1//2 2//2 6//2 5//2\n",
    )
    .unwrap();
    let scene = obj.to_str().unwrap();
    let common_args = [
        "--scene",
        scene,
        "--width",
        "32",
        "--height",
        "32",
        "--light",
        "point:2,2,2,5",
    ];
    let sparse_args = ["--opt", "rsm=16", "--opt", "sparse-points=64"];
    let view = |method: &str, options: &[&str]| {
        let mut args = vec!["view", "--method", method, "--frames", "1"];
        args.extend(common_args);
        args.extend(options);
        windowed(&args).map(|command| report_of(&run(command)))
    };
    let Some(sparse) = view("sparse", &sparse_args) else {
        return;
    };
    assert_eq!(sparse["max_edge_source"], "sparse spacing", "{sparse}");
    let mut render = Command::new(env!("CARGO_BIN_EXE_valgi"));
    render
        .args(["render", "--method", "sparse", "--out"])
        .arg(dir.join("room.png"))
        .args(common_args)
        .args(sparse_args);
    let rendered = report_of(&run(render));
    assert_eq!(
        sparse["max_edge"], rendered["max_edge"],
        "view {sparse}, render {rendered}"
    );
    assert!(sparse["max_edge"].as_f64().unwrap() > 0.05);
    let direct = view("direct", &[]).unwrap();
    assert_eq!(direct["max_edge_source"], "default", "{direct}");
    assert!((direct["max_edge"].as_f64().unwrap() - 0.05).abs() < 1e-6);
}
