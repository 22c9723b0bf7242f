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
    extra: &[&str],
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
    args.extend(extra);
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
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_debug");
    let Some((plain, plain_report)) = sparse_view(&dir, "plain", &[], &[]) else {
        return;
    };
    assert_eq!(plain_report["debug"]["draws"], 0, "{plain_report}");
    let (points_shot, points_report) = sparse_view(&dir, "points", &["points"], &[]).unwrap();
    assert_eq!(points_report["debug"]["draws"], 1, "{points_report}");
    let size: u32 = DEBUG_SIZE.parse().unwrap();

    // The points' projections through the viewer's camera (the scene's first, frame 0).
    let (scene, world_from_node, camera) = cornell_at_rest();
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

    let (vals_shot, vals_report) = sparse_view(&dir, "vals", &["vals"], &[]).unwrap();
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

/// The scene, placed at frame 0, and the camera of the viewer's debug tests, as the viewer
/// loads them.
fn cornell_at_rest() -> (
    valgi::scene::Scene,
    Vec<glam::Mat4>,
    valgi::scene::CameraView,
) {
    use valgi::scene::{builtin::BuiltinParams, LoadParams};
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
    (scene, world_from_node, camera)
}

fn vec3_of(value: &serde_json::Value) -> glam::Vec3 {
    let a: Vec<f32> = value
        .as_array()
        .unwrap_or_else(|| panic!("not an array: {value}"))
        .iter()
        .map(|v| v.as_f64().unwrap() as f32)
        .collect();
    glam::Vec3::new(a[0], a[1], a[2])
}

/// The pixels of the top-left `size`² (the first view's region) that have exactly colour `rgb`.
fn pixels_of(image: &image::RgbImage, size: u32, rgb: [u8; 3]) -> Vec<(u32, u32)> {
    (0..size)
        .flat_map(|y| (0..size).map(move |x| (x, y)))
        .filter(|&(x, y)| image.get_pixel(x, y).0 == rgb)
        .collect()
}

/// `--debug links,occluders --pick X,Y`: the viewer picks the surface under the pixel and the
/// sparse method answers with the vertex's links and the nearest point, exactly as the
/// library computes them from the same camera ray, scene and point set; the screenshot shows
/// the overlays' colours (the magenta cross on the vertex, the yellow diffuse sphere), which
/// the plain view has nowhere.
#[test]
fn the_links_and_occluder_views_show_the_picked_vertex_and_point() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_pick");
    let size: u32 = DEBUG_SIZE.parse().unwrap();
    // On the tall block's front face.
    let pixel = (size / 2, size * 9 / 16);
    let pick_arg = format!("{},{}", pixel.0, pixel.1);
    let Some((plain, _)) = sparse_view(&dir, "plain", &[], &[]) else {
        return;
    };
    let (shot, report) = sparse_view(
        &dir,
        "pick",
        &["links", "occluders"],
        &["--pick", &pick_arg, "--opt", "occlusion=sum"],
    )
    .unwrap();
    let shown = &report["debug"]["pick"];
    assert_eq!(report["debug"]["draws"], 2, "{report}");

    let (scene, world_from_node, camera) = cornell_at_rest();
    let (origin, dir_ray) = valgi::reference::camera_ray(
        &camera,
        size,
        size,
        pixel.0 as f32 + 0.5,
        pixel.1 as f32 + 0.5,
    );
    let hit = valgi::scene::pick::pick(&scene, &world_from_node, origin, dir_ray)
        .expect("the pixel shows a surface");
    let (points, _) = valgi::vals::points::scene_points(&scene, 200, 1);
    let expected =
        valgi::vals::points::debug_pick(&scene, &world_from_node, &points, &hit, camera.position())
            .unwrap();
    let close = |a: glam::Vec3, b: glam::Vec3| (a - b).length() < 1e-6;
    assert!(
        close(vec3_of(&shown["vertex"]), expected.vertex),
        "viewer's vertex {} against {:?}",
        shown["vertex"],
        expected.vertex
    );
    let links = shown["links"].as_array().unwrap();
    assert_eq!(links.len(), expected.links.len());
    for (link, (point, weight)) in links.iter().zip(&expected.links) {
        assert!(
            close(vec3_of(&link["point"]), *point),
            "{link} against {point:?}"
        );
        assert!((link["weight"].as_f64().unwrap() as f32 - weight).abs() < 1e-6);
    }
    let total: f32 = expected.links.iter().map(|l| l.1).sum();
    assert!(
        (total - 1.0).abs() < 1e-5,
        "the picked vertex's weights sum to {total}"
    );
    let (index, position) = expected.point.unwrap();
    assert_eq!(shown["point"]["index"], index, "{shown}");
    assert!(close(vec3_of(&shown["point"]["position"]), position));

    // The overlay colours (display values, written as they are into the non-sRGB window):
    // the vertex cross (1, 0.2, 1) and the diffuse sphere (1, 0.9, 0.1).
    let count = |image: &image::RgbImage, rgb: [u8; 3]| pixels_of(image, size, rgb).len();
    let cross = [255, 51, 255];
    let sphere = [255, 230, 26];
    eprintln!(
        "pick: {} cross pixels, {} sphere pixels",
        count(&shot, cross),
        count(&shot, sphere)
    );
    assert_eq!(count(&plain, cross) + count(&plain, sphere), 0);
    assert!(count(&shot, cross) > 0, "no vertex cross drawn");
    assert!(count(&shot, sphere) > 0, "no light sphere drawn");
    // The cross is drawn around the vertex's projection.
    let ndc = camera.clip_from_world().project_point3(expected.vertex);
    let at = (
        (ndc.x * 0.5 + 0.5) * size as f32,
        (0.5 - ndc.y * 0.5) * size as f32,
    );
    let far_cross = pixels_of(&shot, size, cross)
        .into_iter()
        .filter(|&(x, y)| {
            (x as f32 + 0.5 - at.0).abs() > 8.0 || (y as f32 + 0.5 - at.1).abs() > 8.0
        })
        .count();
    assert_eq!(far_cross, 0, "cross pixels away from the vertex at {at:?}");
}

/// `--debug reference --reference DIR`: the view draws, per pixel, the luminance of its image
/// minus that of the reference `valgi eval` cached for it (red brighter, blue darker, the PNG
/// tone map), to the level of the same difference computed here from `valgi render`'s image
/// and the cached EXRs; a view eval never rendered shows the plain image and says why.
#[test]
fn the_reference_view_draws_the_difference_to_the_cached_reference() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_reference");
    let eval_dir = dir.join("eval");
    let exe = env!("CARGO_BIN_EXE_valgi");
    let size = "32";
    let common_args = [
        "--scene", "cornell", "--method", "direct", "--width", size, "--height", size,
    ];
    let mut eval = std::process::Command::new(exe);
    eval.args([
        "eval",
        "--scenes",
        "cornell",
        "--methods",
        "direct",
        "--width",
        size,
        "--height",
        size,
    ])
    .args(["--ref-spp", "4", "--out", eval_dir.to_str().unwrap()]);
    run(eval);
    let rendered = dir.join("render.exr");
    let mut render = std::process::Command::new(exe);
    render
        .arg("render")
        .args(common_args)
        .args(["--out", rendered.to_str().unwrap()]);
    run(render);
    let shot = dir.join("difference.png");
    let mut args = vec!["view"];
    args.extend(common_args);
    args.extend(["--frames", "1", "--screenshot", shot.to_str().unwrap()]);
    args.extend([
        "--debug",
        "reference",
        "--reference",
        eval_dir.to_str().unwrap(),
    ]);
    let Some(command) = windowed(&args) else {
        return;
    };
    let report = report_of(&run(command));
    let key = report["debug"]["reference_key"]
        .as_str()
        .unwrap_or_else(|| panic!("{report}"));
    assert!(
        key.starts_with(&format!(
            "v{} scene=cornell camera=- size=32x32 ",
            valgi::eval::REFERENCE_VERSION
        )),
        "{key}"
    );

    let cache = eval_dir.join("cache");
    let stem = format!("ref-{:016x}", valgi::eval::fnv1a(key));
    let read = |path: &Path| valgi::image_io::Image::read_exr(path).unwrap();
    let reference_direct = read(&cache.join(format!("{stem}.direct.exr")));
    let reference_indirect = read(&cache.join(format!("{stem}.indirect.exr")));
    let image = read(&rendered);
    let luminance = |p: &[f32; 4]| 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
    let level = |v: f32| (valgi::image_io::srgb_oetf(v.clamp(0.0, 1.0)) * 255.0).round() as i32;
    let shot_image = load(&shot);
    let (mut worst, mut brighter, mut darker) = (0, 0, 0);
    for y in 0..32u32 {
        for x in 0..32u32 {
            let i = (y * 32 + x) as usize;
            let d = luminance(&image.pixels[i])
                - luminance(&reference_direct.pixels[i])
                - luminance(&reference_indirect.pixels[i]);
            let expected = [level(d.max(0.0)), 0, level((-d).max(0.0))];
            let got = shot_image.get_pixel(x, y).0;
            for c in 0..3 {
                worst = worst.max((got[c] as i32 - expected[c]).abs());
            }
            brighter += (expected[0] > 0) as u32;
            darker += (expected[2] > 0) as u32;
        }
    }
    eprintln!(
        "reference difference: {brighter} pixels brighter, {darker} darker, worst level {worst}"
    );
    assert!(worst <= 1, "the difference is {worst} levels off the CPU's");
    // A 4-spp reference is noisy: both signs show.
    assert!(brighter > 0 && darker > 0);

    // Another size: no cached reference, the plain image, and the note says why.
    let mut args = vec!["view", "--scene", "cornell", "--method", "direct"];
    args.extend(["--width", "40", "--height", "32", "--frames", "1"]);
    args.extend([
        "--debug",
        "reference",
        "--reference",
        eval_dir.to_str().unwrap(),
    ]);
    let report = report_of(&run(windowed(&args).unwrap()));
    assert!(report["debug"]["reference_key"].is_null(), "{report}");
    let note = report["debug"]["reference_note"].as_str().unwrap();
    assert!(
        note.contains("holds no reference") && note.contains("40x32"),
        "{note}"
    );
}

/// `--debug atlas`: the atlas method draws its light-map texels as a checkerboard on each
/// chart mesh's hue, so twice the atlas resolution gives about twice the checker squares
/// across a wall; a clean bake has no coverage hole, and texels whose coverage flag is cleared
/// (alpha 0) show magenta, as many as the view sees of them.
#[test]
fn the_atlas_view_shows_its_texels_and_coverage_holes() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_atlas");
    let exe = env!("CARGO_BIN_EXE_valgi");
    let bake = |res: u32| {
        let out = dir.join(format!("atlas{res}.exr"));
        let mut command = std::process::Command::new(exe);
        command
            .args([
                "bake",
                "--scene",
                "cornell",
                "--vpls",
                "50",
                "--bounces",
                "1",
            ])
            .args([
                "--atlas-res",
                &res.to_string(),
                "--out",
                out.to_str().unwrap(),
            ]);
        run(command);
        out
    };
    let size = 128u32;
    let view = |atlas: &Path, name: &str| {
        let shot = dir.join(format!("{name}.png"));
        let option = format!("atlas={}", atlas.display());
        let args = [
            "view",
            "--scene",
            "cornell",
            "--method",
            "atlas",
            "--opt",
            &option,
            "--width",
            "128",
            "--height",
            "128",
            "--frames",
            "1",
            "--screenshot",
            shot.to_str().unwrap(),
            "--debug",
            "atlas",
        ];
        let report = report_of(&run(windowed(&args)?));
        assert_eq!(report["debug"]["atlas"], true, "{report}");
        Some(load(&shot))
    };
    let coarse = bake(64);
    let fine = bake(128);
    let Some(coarse_shot) = view(&coarse, "coarse") else {
        return;
    };
    let fine_shot = view(&fine, "fine").unwrap();
    // Colour changes along a row across the back wall, above the blocks.
    let changes = |image: &image::RgbImage| {
        let y = size * 3 / 10;
        (size * 3 / 10..size * 7 / 10 - 1)
            .filter(|&x| image.get_pixel(x, y) != image.get_pixel(x + 1, y))
            .count()
    };
    let (c, f) = (changes(&coarse_shot), changes(&fine_shot));
    eprintln!("atlas view: {c} checker edges across the wall at 64², {f} at 128²");
    assert!(c >= 4, "{c} checker edges at 64²");
    let ratio = f as f64 / c as f64;
    assert!(
        (1.5..=2.6).contains(&ratio),
        "128² gives {f} edges, 64² {c}"
    );
    let magenta = |image: &image::RgbImage| pixels_of(image, size, [255, 0, 255]).len();
    assert_eq!(magenta(&fine_shot), 0, "a clean bake has no coverage hole");

    // Clear the coverage flag of every 150th covered texel (under the 1 % the renderer
    // accepts as missing), with the layout the bake stored beside it.
    let mut holed = valgi::image_io::Image::read_exr(&fine).unwrap();
    let mut cleared = 0;
    for (i, p) in holed.pixels.iter_mut().filter(|p| p[3] > 0.0).enumerate() {
        if i % 150 == 0 {
            p[3] = 0.0;
            cleared += 1;
        }
    }
    let holed_path = dir.join("holed.exr");
    holed.write_exr(&holed_path).unwrap();
    std::fs::copy(
        fine.with_extension("exr.layout"),
        holed_path.with_extension("exr.layout"),
    )
    .unwrap();
    let holed_shot = view(&holed_path, "holed").unwrap();
    let holes = magenta(&holed_shot);
    eprintln!("atlas view: {cleared} texels cleared, {holes} magenta pixels");
    assert!(holes > 0, "no coverage hole shown");
}

/// `valgi view --preview`: the material preview room with `valgi preview`'s method defaults;
/// a material knob (`--change-option material.roughness=0.2`, as the panel's slider does)
/// rebuilds the method for the edited material, and the window then shows exactly what
/// `valgi render` shows of the built-in scene with that roughness, not the starting one.
#[test]
fn the_preview_material_knobs_rebuild_for_the_edited_material() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_preview");
    let exe = env!("CARGO_BIN_EXE_valgi");
    let shot = dir.join("preview.png");
    let args = [
        "view",
        "--preview",
        "--width",
        "48",
        "--height",
        "48",
        "--frames",
        "2",
        "--screenshot",
        shot.to_str().unwrap(),
        "--change-option",
        "material.roughness=0.2",
    ];
    let Some(command) = windowed(&args) else {
        return;
    };
    let report = report_of(&run(command));
    assert_eq!(report["method"], "sparse", "{report}");
    assert_eq!(
        report["options"], "rsm=32,visibility-rays=adaptive",
        "{report}"
    );
    assert_eq!(report["rebuild"]["ok"], true, "{report}");
    let render = |scene: &str| {
        let out = dir.join(format!("{scene}.png"));
        let mut command = std::process::Command::new(exe);
        command
            .args([
                "render", "--scene", scene, "--method", "sparse", "--opt", "rsm=32",
            ])
            .args([
                "--opt",
                "visibility-rays=adaptive",
                "--width",
                "48",
                "--height",
                "48",
            ])
            .args(["--out", out.to_str().unwrap()]);
        run(command);
        load(&out)
    };
    let window = load(&shot);
    let (edited, _) = compare(&window, 0, &render("preview-r20"));
    let (starting, _) = compare(&window, 0, &render("preview"));
    eprintln!("preview: {edited} levels from roughness 0.2, {starting} from 0.5");
    assert!(
        edited <= 1,
        "the edited material's view is {edited} levels off render"
    );
    assert!(
        starting > 8,
        "roughness 0.5 differs by only {starting} levels"
    );

    // A material knob needs the preview.
    let args = [
        "view",
        "--frames",
        "2",
        "--width",
        "32",
        "--height",
        "32",
        "--change-option",
        "material.roughness=0.2",
    ];
    let output = windowed(&args).unwrap().output().unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("needs --preview"), "{stderr}");
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

/// Arguments that cannot work together are refused before any window opens: the preview
/// builds its own room (no `--scene`), a material needs the preview, a pick is two pixel
/// coordinates.
#[test]
fn view_arguments_that_cannot_work_together_are_refused() {
    let exe = env!("CARGO_BIN_EXE_valgi");
    for (args, expected) in [
        (
            vec!["--preview", "--scene", "sponza"],
            "cannot be used with",
        ),
        (vec!["--material", "x.glb"], "--preview"),
        (
            vec!["--pick", "1,2,3"],
            "--pick 1,2,3: expected two whole pixel coordinates",
        ),
        (vec!["--pick=-1,2"], "expected two whole pixel coordinates"),
        (vec!["--debug", "normals"], "unknown debug view"),
    ] {
        let output = std::process::Command::new(exe)
            .arg("view")
            .args(&args)
            .args(["--frames", "1"])
            .output()
            .expect("run valgi");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} was accepted");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

/// The panel is drawn into a cached layer only when egui's output changes (its readouts
/// refresh four times a second), and composited every frame: an idle panel is reused, and
/// the screenshot shows it beside the view.
#[test]
fn the_panel_layer_is_reused_while_the_panel_is_unchanged_and_shown_every_frame() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_panel");
    let shot = dir.join("panel.png");
    let mut args = vec!["view"];
    args.extend(direct_cornell("mono"));
    args.extend(["--frames", "150", "--screenshot", shot.to_str().unwrap()]);
    let Some(command) = windowed(&args) else {
        return;
    };
    let report = report_of(&run(command));
    let layer = &report["panel_layer"];
    let (redraws, reuses) = (
        layer["redraws"].as_u64().unwrap(),
        layer["reuses"].as_u64().unwrap(),
    );
    eprintln!("panel layer: {redraws} redraws, {reuses} reuses");
    assert!(redraws >= 1, "{layer}");
    // Measured 40 redraws (the first build and egui's start-up) and 111 reuses.
    assert!(
        reuses * 2 >= redraws + reuses,
        "the idle panel was drawn again in most frames: {layer}"
    );
    // Every frame composites the layer: the panel beside the view has its dark fill and
    // bright text.
    let image = load(&shot);
    let size: u32 = SIZE.parse().unwrap();
    let panel: Vec<u8> = (0..image.height())
        .flat_map(|y| (size..image.width()).map(move |x| (x, y)))
        .map(|(x, y)| image.get_pixel(x, y).0[1])
        .collect();
    assert!(!panel.is_empty());
    let mean = panel.iter().map(|&g| g as f64).sum::<f64>() / panel.len() as f64;
    let bright = panel.iter().filter(|&&g| g > 110).count();
    eprintln!("panel region: mean green {mean:.1}, {bright} bright pixels");
    assert!(mean > 15.0, "the panel region is black (mean {mean:.1})");
    assert!(bright > 100, "no panel text ({bright} bright pixels)");
}

/// Without `--method` the viewer opens on `render`'s default, `sparse+atlas` (its atlas baked
/// in memory on the worker), and on a scene whose atlas the bake refuses (3000 separate
/// triangles need a 274² atlas) on `sparse`, with a warning.
#[test]
fn the_viewer_opens_on_renders_default_method() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("viewer_default_method");
    let pieces = common::separate_triangles_obj(&dir, 3000);
    let pieces = pieces.to_str().unwrap();
    for (scene, expected) in [("cornell", "sparse+atlas"), (pieces, "sparse")] {
        let args = [
            "view",
            "--scene",
            scene,
            "--light",
            "point:1.5,1,1.25,1",
            "--sparse-points",
            "256",
            "--rsm",
            "16",
            "--width",
            "32",
            "--height",
            "32",
            "--frames",
            "2",
        ];
        let Some(mut command) = windowed(&args) else {
            return;
        };
        let output = command.output().expect("run valgi");
        let stdout = String::from_utf8_lossy(&output.stdout);
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "{scene}: {stderr}");
        let report = report_of(&stdout);
        assert_eq!(report["method"], expected, "{scene}: {stderr}");
        if expected == "sparse" {
            assert!(
                stderr.contains("viewing 'sparse' without the atlas"),
                "{stderr}"
            );
        }
    }
}
