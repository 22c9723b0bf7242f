//! Many views, one lighting solution: a frame is one update and one record per view.

mod common;

use valgi::frame::{record_frame, View, ViewRig};
use valgi::gpu::GpuContext;
use valgi::image_io::Image;
use valgi::method::{self, MethodOptions};
use valgi::scene::{builtin, CameraView, Scene};

use common::small_render_settings as settings;

const SIZE: u32 = 32;

fn cornell() -> Scene {
    builtin::load("cornell", &builtin::BuiltinParams::default()).unwrap()
}

fn options(pairs: &[(&str, &str)]) -> MethodOptions {
    let mut o = MethodOptions::default();
    for (k, v) in pairs {
        o.set(k, v);
    }
    o
}

fn camera(scene: &Scene) -> CameraView {
    scene
        .camera_view(None, 1.0, &scene.world_from_node())
        .unwrap()
}

fn views(ctx: &GpuContext, scene: &Scene, rig: &ViewRig) -> Vec<View> {
    let cam = camera(scene);
    rig.views(&cam, (SIZE, SIZE), glam::Vec3::new(0.278, 0.274, 0.28))
        .into_iter()
        .map(|r| View::new(ctx, &r.name, r.camera, r.size, 1).unwrap())
        .collect()
}

fn max_abs_difference(a: &Image, b: &Image) -> f32 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(p, q)| (0..3).map(move |c| (p[c] - q[c]).abs()))
        .fold(0.0, f32::max)
}

fn mean(image: &Image) -> f32 {
    image.pixels.iter().map(|p| p[0] + p[1] + p[2]).sum::<f32>() / image.pixels.len() as f32
}

/// `grid:1` is the mono camera, and the frame code gives the mono render's pixels.
#[test]
fn grid_of_one_view_equals_the_mono_render() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell();
    let world = scene.world_from_node();
    let o = options(&[("rsm", "32"), ("sparse-points", "512")]);
    let mut mono = method::create("sparse", &ctx, &scene, settings(SIZE), &o).unwrap();
    let reference = mono.render(&ctx, &scene, &world, &camera(&scene)).unwrap();
    let mut m = method::create("sparse", &ctx, &scene, settings(SIZE), &o).unwrap();
    let grid = views(&ctx, &scene, &ViewRig::Grid { count: 1 });
    let frame = record_frame(m.as_mut(), &ctx, &scene, &world, &grid).unwrap();
    let (direct, indirect) = grid[0].read(&ctx, frame.results[0].has_indirect()).unwrap();
    assert!(mean(&reference.indirect) > 0.0);
    assert_eq!(max_abs_difference(&direct, &reference.direct), 0.0);
    assert_eq!(max_abs_difference(&indirect, &reference.indirect), 0.0);
}

/// Two eyes: the solution is updated once (one gather, one RSM per light layer), both views
/// read it, and each eye sees what a mono render from that eye sees.
#[test]
fn stereo_views_share_one_update_and_match_mono_renders_from_each_eye() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell();
    let world = scene.world_from_node();
    // Diffuse only: the solution then does not depend on any eye at all.
    let o = options(&[("rsm", "32"), ("sparse-points", "512"), ("glossy", "off")]);
    let mut m = method::create("sparse", &ctx, &scene, settings(SIZE), &o).unwrap();
    let eyes = views(&ctx, &scene, &ViewRig::Stereo { ipd: 0.05 });
    // The views differ in their targets only: one resolve pipeline serves both.
    assert!(eyes[0].shares_resolve_with(&eyes[1]));
    let frame = record_frame(m.as_mut(), &ctx, &scene, &world, &eyes).unwrap();
    let count = |label: &str| {
        frame
            .solution_pass_counts
            .iter()
            .find(|(l, _)| l == label)
            .map_or(0, |(_, n)| *n)
    };
    assert_eq!(count("gather"), 1, "{:?}", frame.solution_pass_counts);
    assert_eq!(count("interpolation"), 1);
    assert_eq!(count("gbuffer"), 0, "G-buffers are per view");
    assert_eq!(frame.timings.views.len(), 2);
    for view_timings in &frame.timings.views {
        assert!(view_timings.get("apply").is_some() && view_timings.get("gbuffer").is_some());
        assert!(view_timings.get("gather").is_none());
    }
    let mut images = vec![];
    for (view, result) in eyes.iter().zip(&frame.results) {
        let (_, indirect) = view.read(&ctx, result.has_indirect()).unwrap();
        let mut mono = method::create("sparse", &ctx, &scene, settings(SIZE), &o).unwrap();
        let alone = mono.render(&ctx, &scene, &world, &view.camera).unwrap();
        assert!(
            max_abs_difference(&indirect, &alone.indirect) < 1e-5 * mean(&alone.indirect).max(1.0),
            "view {}: stereo and mono renders of the same eye differ",
            view.name
        );
        images.push(indirect);
    }
    // The eyes are 5 cm apart, so their images differ, but not their light.
    assert!(max_abs_difference(&images[0], &images[1]) > 0.0);
    let (l, r) = (mean(&images[0]), mean(&images[1]));
    assert!((l - r).abs() < 0.05 * l, "mean indirect {l} vs {r}");
}

/// `glossy-eye per-view` re-gathers the glossy half for each eye and leaves the diffuse half
/// alone; each eye then sees what a mono render from it sees. Also with the gather split over
/// VAL slices (a GPU's default), whose reduction then writes the glossy half alone.
#[test]
fn per_view_glossy_changes_only_the_glossy_term() {
    let Some(ctx) = common::gpu() else { return };
    for slices in ["1", "3"] {
        per_view_glossy_with(&ctx, slices);
    }
}

fn per_view_glossy_with(ctx: &valgi::gpu::GpuContext, slices: &str) {
    // Spheres with Phong k = 1..1000: the glossy term shows in the image.
    let scene = builtin::load("glossy-row", &builtin::BuiltinParams::default()).unwrap();
    let world = scene.world_from_node();
    let run = |eye: &str| {
        let o = options(&[
            ("rsm", "32"),
            ("sparse-points", "512"),
            ("glossy-eye", eye),
            ("gather-slices", slices),
        ]);
        let mut m = valgi::vals::SparseMethod::new(
            ctx,
            &scene,
            settings(SIZE),
            valgi::vals::SparseSettings::from_options(&o).unwrap(),
        )
        .unwrap();
        let eyes = views(ctx, &scene, &ViewRig::Stereo { ipd: 0.2 });
        let frame = record_frame(&mut m, ctx, &scene, &world, &eyes).unwrap();
        let points = m.sparse.read_points(ctx, &scene, &world).unwrap();
        let (_, right) = eyes[1].read(ctx, frame.results[1].has_indirect()).unwrap();
        (points, right, eyes[1].camera)
    };
    let (mid, mid_right, right_camera) = run("mid");
    let (per_view, per_view_right, _) = run("per-view");
    let mut glossy_changed = 0;
    for (a, b) in mid.lights.iter().zip(&per_view.lights) {
        assert_eq!(
            a.diffuse, b.diffuse,
            "{slices} slices: diffuse intensities moved"
        );
        assert_eq!(a.diffuse_position, b.diffuse_position);
        if a.glossy != b.glossy {
            glossy_changed += 1;
        }
    }
    // The last view recorded is the right eye; its glossy solution is aimed at it.
    assert!(
        glossy_changed > mid.lights.len() / 10,
        "{glossy_changed} of {}",
        mid.lights.len()
    );
    let o = options(&[
        ("rsm", "32"),
        ("sparse-points", "512"),
        ("gather-slices", slices),
    ]);
    let mut mono = method::create("sparse", ctx, &scene, settings(SIZE), &o).unwrap();
    let alone = mono.render(ctx, &scene, &world, &right_camera).unwrap();
    let scale = mean(&alone.indirect).max(1e-6);
    assert!(max_abs_difference(&per_view_right, &alone.indirect) < 1e-4 * scale.max(1.0));
    assert!(max_abs_difference(&mid_right, &per_view_right) > 0.0);
}

/// Two CAVE walls that share an edge: the pixels on either side of the edge see the same
/// surfaces, so they agree far better than pixels on the walls' other edges do.
#[test]
fn adjacent_cave_walls_meet_without_a_seam() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell();
    let world = scene.world_from_node();
    let file =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/cave/cornell_4wall.json");
    let rig = ViewRig::parse(&format!("cave:{}", file.display())).unwrap();
    let walls = views(&ctx, &scene, &rig);
    let names: Vec<&str> = walls.iter().map(|w| w.name.as_str()).collect();
    assert_eq!(names, ["left", "front", "right", "floor"]);
    let mut m = method::create(
        "direct",
        &ctx,
        &scene,
        settings(SIZE),
        &MethodOptions::default(),
    )
    .unwrap();
    let frame = record_frame(m.as_mut(), &ctx, &scene, &world, &walls[..2]).unwrap();
    let read = |i: usize| {
        walls[i]
            .read(&ctx, frame.results[i].has_indirect())
            .unwrap()
            .0
    };
    let (left, front) = (read(0), read(1));
    let column = |image: &Image, x: u32| -> Vec<[f32; 4]> {
        (0..image.height)
            .map(|y| image.pixels[(y * image.width + x) as usize])
            .collect()
    };
    let difference = |a: &[[f32; 4]], b: &[[f32; 4]]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| (0..3).map(|c| (p[c] - q[c]).abs()).sum::<f32>())
            .sum::<f32>()
            / a.len() as f32
    };
    let seam = difference(&column(&left, SIZE - 1), &column(&front, 0));
    let far = difference(&column(&left, 0), &column(&front, SIZE - 1));
    let brightness = column(&front, 0)
        .iter()
        .map(|p| p[0] + p[1] + p[2])
        .sum::<f32>()
        / SIZE as f32;
    assert!(brightness > 0.0);
    assert!(
        seam < 0.1 * brightness,
        "seam {seam} against brightness {brightness}"
    );
    assert!(seam < 0.5 * far, "seam {seam}, far edges {far}");
}

/// Every registered method is listed by `valgi methods` with its options, has a render flag
/// for each option, and is accepted by `valgi eval`'s spec check.
#[test]
fn every_registered_method_is_listed_and_accepted() {
    let exe = env!("CARGO_BIN_EXE_valgi");
    let listed = std::process::Command::new(exe)
        .arg("methods")
        .output()
        .unwrap();
    common::assert_success(&listed);
    let listed = String::from_utf8_lossy(&listed.stdout);
    let help = std::process::Command::new(exe)
        .args(["render", "--help"])
        .output()
        .unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    assert!(!method::REGISTRY.is_empty());
    for entry in method::REGISTRY {
        assert!(
            listed
                .lines()
                .any(|l| l.split_whitespace().next() == Some(entry.name)),
            "'{}' missing from `valgi methods`:\n{listed}",
            entry.name
        );
        for o in entry.options {
            assert!(
                listed.contains(&format!("--{}", o.name)),
                "{}: {}",
                entry.name,
                o.name
            );
            assert!(
                help.contains(&format!("--{}", o.name)),
                "render --help lacks --{}",
                o.name
            );
        }
        assert!(method::entry(entry.name).is_ok());
    }
    // A spec naming an option the method does not take is refused before any rendering.
    let request = valgi::eval::EvalRequest {
        methods: vec!["direct:rsm=4".into()],
        ..Default::default()
    };
    let e = match valgi::eval::run(&request) {
        Ok(_) => panic!("eval accepted an option 'direct' does not take"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("no option(s) rsm"), "{e}");
}
