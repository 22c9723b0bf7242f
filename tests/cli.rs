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
    // Without --method, render draws the product's image: direct + the sparse VALs' bounce
    // + the later bounces of an atlas baked in memory.
    assert_eq!(report["method"], "sparse+atlas");
    assert_eq!(report["width"], 48);
    for pass in [
        "shadow",
        "gbuffer",
        "direct",
        "resolve",
        "rsm",
        "gather",
        "apply",
        "atlas add",
    ] {
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
    let report = common::success_report(&output);
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

/// Runs `valgi ARGS` and asserts it exits non-zero without a panic and that its error
/// names every one of `needles`.
fn assert_refused(args: &[&str], needles: &[&str]) {
    let output = valgi().args(args).output().expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        !output.status.success(),
        "valgi {args:?} succeeded; stderr: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "valgi {args:?}: {stderr}");
    for needle in needles {
        assert!(
            stderr.contains(needle),
            "valgi {args:?}: error does not name '{needle}': {stderr}"
        );
    }
}

/// `NAME` in a fresh folder of its own for `test`.
fn temp_out(test: &str, name: &str) -> String {
    common::temp_dir(test).join(name).display().to_string()
}

fn tiny_render<'a>(out: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "render",
        "--scene",
        "plane-point",
        "--width",
        "8",
        "--height",
        "8",
        "--out",
        out,
    ];
    args.extend_from_slice(extra);
    args
}

#[test]
fn non_finite_times_and_exposures_are_refused_before_work_starts() {
    let out = temp_out("cli-finite", "x.exr");
    let out = out.as_str();
    for value in ["NaN", "inf", "-inf"] {
        // `=`: clap reads a separate `-inf` as a flag.
        let time = format!("--time={value}");
        assert_refused(&tiny_render(out, &[&time]), &["--time"]);
        let exposure = format!("--exposure={value}");
        assert_refused(&tiny_render(out, &[&exposure]), &["--exposure", value]);
    }
    assert_refused(
        &tiny_render(out, &["--exposure", "1000"]),
        &["--exposure", "1000"],
    );
    assert!(!std::path::Path::new(out).exists(), "an image was written");
}

#[test]
fn a_max_edge_that_would_blow_up_the_mesh_is_refused_with_its_triangle_count() {
    let out = temp_out("cli-max-edge", "x.exr");
    // Cornell at 1 µm edges would be ~10¹³ triangles; the check must answer at once, without
    // building them (the test would run out of memory otherwise).
    for command in ["render", "bake"] {
        assert_refused(
            &[
                command,
                "--scene",
                "cornell",
                "--max-edge",
                "0.000001",
                "--out",
                &out,
            ],
            &["--max-edge", "triangles", "budget"],
        );
    }
}

#[test]
fn bake_refuses_absurd_vpl_counts() {
    let out = temp_out("cli-vpls", "atlas.exr");
    let out = out.as_str();
    assert_refused(
        &[
            "bake", "--scene", "cornell", "--vpls", "100000", "--out", out,
        ],
        &["--vpls", "100000"],
    );
    assert_refused(
        &[
            "bake",
            "--scene",
            "cornell",
            "--bounces",
            "1000",
            "--out",
            out,
        ],
        &["--bounces", "1000"],
    );
}

/// `--gpu-memory` caps what the method owns: a point light's six 1024² shadow layers (24 MiB)
/// shrink to fit a quarter of 16 MiB, the whole method stays within 16 MiB, and views that
/// alone exceed it are refused with the size and the option named.
#[test]
fn the_gpu_memory_cap_shrinks_budgets_and_refuses_what_cannot_fit() {
    if common::gpu().is_none() {
        return;
    }
    let out = temp_out("cli-gpu-memory", "x.exr");
    let out = out.as_str();
    let gpu_bytes = |extra: &[&str]| {
        let output = valgi()
            .args(tiny_render(out, &[&["--method", "sparse"], extra].concat()))
            .output()
            .expect("run valgi");
        let stdout = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "{extra:?}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
        let report: serde_json::Value =
            serde_json::from_str(stdout.lines().last().expect("a JSON line")).expect("JSON");
        report["gpu_bytes"].as_u64().expect("gpu_bytes")
    };
    let free = gpu_bytes(&[]);
    let capped = gpu_bytes(&["--gpu-memory", "16"]);
    assert!(free > 24 << 20, "uncapped: {free} bytes");
    assert!(capped <= 16 << 20, "capped at 16 MiB: {capped} bytes");
    let large = [
        "render",
        "--scene",
        "plane-point",
        "--width",
        "2048",
        "--height",
        "2048",
        "--gpu-memory",
        "16",
        "--out",
        out,
    ];
    assert_refused(&large, &["--gpu-memory 16", "MiB", "raise --gpu-memory"]);
    assert_refused(
        &tiny_render(out, &["--gpu-memory", "8"]),
        &["--gpu-memory", "8"],
    );
}

/// A scene without one triangle has no sparse points and no vertices: the sparse method
/// renders it (black, with a warning) instead of dispatching kernels over placeholder buffers,
/// and a point count one mesh cannot hold is refused before placement (which would take
/// minutes).
#[test]
fn sparse_handles_a_scene_without_faces_and_refuses_oversized_meshes_early() {
    if common::gpu().is_none() {
        return;
    }
    let out = temp_out("cli-no-faces", "x.png");
    let corpus = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/corpus/obj/ok-missing-faces.obj"
    );
    let output = valgi()
        .args([
            "render", "--scene", corpus, "--method", "sparse", "--width", "16", "--height", "16",
            "--rsm", "8", "--out", &out,
        ])
        .output()
        .expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(std::path::Path::new(&out).exists());
    let started = std::time::Instant::now();
    assert_refused(
        &[
            "render",
            "--scene",
            "cornell",
            "--method",
            "sparse",
            "--width",
            "8",
            "--height",
            "8",
            "--sparse-points",
            "1048576",
            "--out",
            &out,
        ],
        &["--sparse-points 1048576", "mesh 'floor'", "65536"],
    );
    // Refused before placement: far below the minutes placement takes.
    assert!(started.elapsed().as_secs() < 60, "{:?}", started.elapsed());
}

/// `valgi mr` with `option value` and frames that do not exist is refused for the option,
/// before any file is read.
fn assert_mr_refuses(name: &str, option: &str, value: &str, expected: &[&str]) {
    assert_mr_refuses_all(name, &[option, value], expected);
}

/// The same with any options.
fn assert_mr_refuses_all(name: &str, options: &[&str], expected: &[&str]) {
    let dir = common::temp_dir(name);
    let mut args = vec!["mr", "--color", "no-color.png", "--depth", "no-depth.png"];
    args.extend_from_slice(options);
    args.extend_from_slice(&["--out", dir.to_str().unwrap()]);
    assert_refused(&args, expected);
}

#[test]
fn mr_refuses_a_sparse_point_count_out_of_range() {
    for count in ["0", "10000000"] {
        assert_mr_refuses(
            "cli-mr-points",
            "--sparse-points",
            count,
            &["--sparse-points", count],
        );
    }
}

#[test]
fn mr_refuses_a_real_cut_that_is_not_a_ratio_or_meets_another_reduction() {
    for ratio in ["-0.1", "NaN", "inf", "2"] {
        assert_mr_refuses("cli-mr-cut", "--real-cut", ratio, &["--real-cut", "ratio"]);
    }
    for other in [["--real-vals", "4096"], ["--accumulate", "3"]] {
        assert_mr_refuses_all(
            "cli-mr-cut-vals",
            &["--real-cut", "0.1", other[0], other[1]],
            &["--real-cut", other[0], "give one"],
        );
    }
}

#[test]
fn mr_refuses_a_real_thickness_that_is_not_a_length() {
    for thickness in ["0", "-1", "NaN", "inf", "1e9"] {
        assert_mr_refuses(
            "cli-mr-thickness",
            "--real-thickness",
            thickness,
            &["--real-thickness", "metres"],
        );
    }
}

#[test]
fn shadow_budgets_val_budgets_spp_and_sparse_points_out_of_range_are_refused() {
    if common::gpu().is_none() {
        return;
    }
    let out = temp_out("cli-ranges", "x.exr");
    let out = out.as_str();
    for res in ["0", "8", "1000000"] {
        assert_refused(
            &tiny_render(out, &["--shadow-res", res]),
            &["--shadow-res", res],
        );
    }
    for budget in ["0", "100000"] {
        assert_refused(
            &tiny_render(out, &["--shadow-memory", budget]),
            &["--shadow-memory", budget],
        );
    }
    // One 4096² layer is 64 MiB: a 16 MiB budget cannot hold even one.
    assert_refused(
        &tiny_render(out, &["--shadow-res", "4096", "--shadow-memory", "16"]),
        &["--shadow-res 4096", "64 MiB", "--shadow-memory 16"],
    );
    assert_refused(
        &tiny_render(out, &["--max-vals", "0"]),
        &["--max-vals", "0"],
    );
    for slices in ["0", "257", "half", "-1"] {
        let flag = format!("--gather-slices={slices}");
        assert_refused(
            &tiny_render(out, &["--method", "sparse", &flag]),
            &["--gather-slices", slices, "1..=256"],
        );
    }
    // plane-point's point light has six RSM views: five VALs cannot give each one.
    assert_refused(
        &tiny_render(out, &["--method", "sparse", "--max-vals", "5"]),
        &["--max-vals 5", "6 light views"],
    );
    assert_refused(
        &tiny_render(out, &["--method", "reference", "--spp", "1000000000"]),
        &["spp", "1000000000"],
    );
    // In range per pixel, but 2⁴⁴ paths over the whole image.
    assert_refused(
        &[
            "render",
            "--scene",
            "plane-point",
            "--method",
            "reference",
            "--width",
            "4096",
            "--height",
            "4096",
            "--spp",
            "1048576",
            "--out",
            out,
        ],
        &["spp", "paths", "budget"],
    );
    assert_refused(
        &tiny_render(out, &["--method", "sparse", "--sparse-points", "10000000"]),
        &["sparse-points", "10000000"],
    );
    assert!(!std::path::Path::new(out).exists(), "an image was written");
}

#[test]
fn bad_lights_and_cameras_are_refused_naming_the_value() {
    let out = temp_out("cli-edits", "x.exr");
    let out = out.as_str();
    assert_refused(
        &tiny_render(out, &["--light", "lamp:1,2,3,4"]),
        &["--light", "lamp:1,2,3,4", "unknown light kind"],
    );
    assert_refused(
        &tiny_render(out, &["--light", "point:-1,2,3"]),
        &["point:-1,2,3", "point takes 4 numbers"],
    );
    assert_refused(
        &tiny_render(out, &["--camera-eye", "-1,2"]),
        &["--camera-eye", "-1,2", "X,Y,Z"],
    );
    assert_refused(&tiny_render(out, &["--fov", "0"]), &["--fov 0"]);
    assert_refused(
        &tiny_render(out, &["--camera-eye", "0,1,0", "--camera-target", "0,1,0"]),
        &["coincide"],
    );
    assert!(!std::path::Path::new(out).exists(), "an image was written");
}

#[test]
fn a_light_and_camera_from_the_command_line_light_an_unlit_scene() {
    if common::gpu().is_none() {
        return;
    }
    // `plane-point` lit by a second light below the camera, seen from another eye: negative
    // numbers pass as values, and the report counts the added light.
    let out = temp_out("cli-edits-render", "lit.exr");
    let output = valgi()
        .args(tiny_render(
            &out,
            &[
                "--light",
                "spot:-0.5,1.5,0.5,0.2,-1,-0.2,10,40,3,1,0.8,0.6",
                "--light",
                "headlight:1",
                "--camera-eye",
                "-1.5,2,1.5",
                "--fov",
                "50",
            ],
        ))
        .output()
        .expect("run valgi");
    let report = common::success_report(&output);
    assert_eq!(report["lights"], 3, "{report}");
}

/// The measured Cornell box of the shared data (Mitsuba 3: `$` parameters, inline spectra, an
/// emitter nested in its shape; millimetres) renders with its documented command: every pixel
/// finite, the room lit by its luminaire alone (nothing from the command line).
#[test]
fn the_measured_cornell_box_renders_from_its_mitsuba_3_file() {
    let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/cornell-measured/cbox.xml");
    if !scene.is_file() {
        eprintln!("skipped: ../shared/data/cornell-measured is not present");
        return;
    }
    if common::gpu().is_none() {
        return;
    }
    let out = temp_out("cli-cornell-measured", "cbox.exr");
    let output = valgi()
        .args(["render", "--scene"])
        .arg(&scene)
        // 50 mm edges: the file is in millimetres (README, "Mitsuba 3").
        .args(["--method", "direct", "--max-edge", "50"])
        .args(["--width", "16", "--height", "16"])
        .args(["--out", &out])
        .output()
        .expect("run valgi");
    let report = common::success_report(&output);
    assert!(report["lights"].as_u64().unwrap_or(0) >= 1, "{report}");
    let image = valgi::image_io::Image::read_exr(std::path::Path::new(&out)).unwrap();
    assert!(
        image
            .pixels
            .iter()
            .all(|p| p.iter().all(|c| c.is_finite() && *c >= 0.0)),
        "non-finite or negative pixels"
    );
    // Floor, walls and blocks face the luminaire; only the ceiling around it is unlit at one
    // bounce (about a fifth of the frame).
    let lit = image
        .pixels
        .iter()
        .filter(|p| p[0] + p[1] + p[2] > 1e-3)
        .count() as f64
        / image.pixels.len() as f64;
    assert!(lit > 0.6, "lit fraction {lit}");
}

#[test]
fn the_opengl_backend_is_refused_at_start_up_with_the_remedy() {
    // Whether or not this machine has an OpenGL adapter, the answer is one clear error that
    // names the remedy, never a panic on the first float render target.
    let out = temp_out("cli-gl", "x.exr");
    let output = valgi()
        .args(tiny_render(&out, &[]))
        .env("WGPU_BACKEND", "gl")
        .output()
        .expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "rendered on OpenGL: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("cannot run valgi") || stderr.contains("no GPU adapter found"),
        "{stderr}"
    );
    assert!(stderr.contains("mesa-vulkan-drivers"), "{stderr}");
    assert!(!std::path::Path::new(&out).exists());
}

#[test]
fn ctrl_c_stops_a_reference_render_cleanly_without_a_file() {
    if common::gpu().is_none() {
        return;
    }
    let out = temp_out("cli-ctrl-c", "long.exr");
    // Far more paths than can finish before the interrupt.
    let mut child = valgi()
        .args([
            "render",
            "--scene",
            "cornell",
            "--method",
            "reference",
            "--spp",
            "200000",
            "--width",
            "48",
            "--height",
            "48",
            "--out",
            &out,
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start valgi");
    std::thread::sleep(std::time::Duration::from_secs(3));
    let killed = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("run kill");
    assert!(killed.success());
    let started = std::time::Instant::now();
    let output = loop {
        if child.try_wait().expect("wait").is_some() {
            break child.wait_with_output().expect("output");
        }
        assert!(
            started.elapsed().as_secs() < 60,
            "still running 60 s after Ctrl-C"
        );
        std::thread::sleep(std::time::Duration::from_millis(100));
    };
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("cancelled"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(!std::path::Path::new(&out).exists(), "an image was written");
    assert!(
        !std::path::Path::new(&format!("{out}.partial")).exists(),
        "a partial file was left"
    );
}

#[test]
fn auto_exposure_is_reported_and_a_black_png_is_named() {
    if common::gpu().is_none() {
        return;
    }
    let out = temp_out("cli-exposure", "x.png");
    let run = |extra: &[&str]| {
        let output = valgi()
            .args(tiny_render(&out, extra))
            .output()
            .expect("run valgi");
        common::assert_success(&output);
        let stdout = String::from_utf8_lossy(&output.stdout).to_string();
        let report: serde_json::Value =
            serde_json::from_str(stdout.lines().last().expect("JSON")).expect("JSON");
        (report, String::from_utf8_lossy(&output.stderr).to_string())
    };
    let (auto, auto_err) = run(&["--auto-exposure"]);
    let stops = auto["exposure"].as_f64().expect("exposure in the report");
    assert!(stops.is_finite() && stops != 0.0, "{auto}");
    assert!(!auto_err.contains("are black"), "{auto_err}");
    let (dark, dark_err) = run(&["--exposure", "-20"]);
    assert_eq!(dark["exposure"], -20.0);
    assert!(
        dark_err.contains("are black at --exposure -20") && dark_err.contains("--auto-exposure"),
        "{dark_err}"
    );
    // The mean is of the linear image, before exposure: the same scene gives the same lit
    // mean at both; the dark fraction is at the run's exposure.
    let mean = |r: &serde_json::Value| r["mean_luminance"][0].as_f64().expect("mean_luminance");
    let dark_fraction = |r: &serde_json::Value| r["dark_fraction"][0].as_f64().expect("dark");
    assert!(mean(&auto) > 0.0, "{auto}");
    assert!(
        (mean(&auto) - mean(&dark)).abs() <= 1e-6 * mean(&auto),
        "{auto}\n{dark}"
    );
    assert_eq!(dark_fraction(&dark), 1.0, "{dark}");
    assert!(dark_fraction(&auto) < 0.9, "{auto}");
}

/// `valgi render --method sparse --quality auto` at 32² and its JSON line.
fn budget_render(scene: &str, extra: &[&str]) -> serde_json::Value {
    budget_render_as(Some("sparse"), scene, extra)
}

/// [`budget_render`] with `method` (`None`: `render`'s default).
fn budget_render_as(method: Option<&str>, scene: &str, extra: &[&str]) -> serde_json::Value {
    let name = method.unwrap_or("default").replace('+', "-");
    let out = temp_out("cli-budget", &format!("{scene}-{name}.exr"));
    let mut command = valgi();
    command.args(["render", "--scene", scene]);
    if let Some(method) = method {
        command.args(["--method", method]);
    }
    let output = command
        .args(["--width", "32", "--height", "32", "--quality", "auto"])
        .args(extra)
        .args(["--out", &out])
        .output()
        .expect("run valgi");
    common::success_report(&output)
}

#[test]
fn budget_mode_says_what_it_chose_and_why_and_keeps_what_was_given() {
    if common::gpu().is_none() {
        return;
    }
    // The Cornell box's blocks hide part of the lit floor from the walls: rays.
    let cornell = budget_render("cornell", &["--target-flip", "0.1"]);
    let budget = &cornell["budget"];
    assert_eq!(budget["occlusion"]["value"], "rays", "{budget}");
    assert_eq!(cornell["occlusion"], "rays");
    for knob in [
        "sparse_points",
        "rsm",
        "occlusion",
        "visibility_rays",
        "max_edge",
    ] {
        let why = budget[knob]["why"].as_str().unwrap_or_default();
        assert!(why.len() > 20, "{knob}: {budget}");
    }
    // The tessellation's line is the scene's: Cornell's 5 cm, coarser than its survey's
    // points would ask for (every candidate's are closer than 7 cm).
    assert_eq!(budget["max_edge"]["value"], cornell["max_edge"], "{budget}");
    assert!(
        budget["max_edge"]["why"]
            .as_str()
            .unwrap()
            .contains("no finer than the built-in scene's"),
        "{budget}"
    );
    // The placed points are the chosen count, give or take the rounding of each mesh's share.
    let chosen = budget["sparse_points"]["value"].as_u64().unwrap() as f64;
    let placed = cornell["sparse_points"].as_u64().unwrap() as f64;
    assert!((placed / chosen - 1.0).abs() < 0.02, "{placed} vs {chosen}");
    // Pilot frames measured the candidates: the choice is the cheapest one they measured
    // meeting the target, or the converged one.
    let pilots = &budget["pilots"];
    assert_eq!(pilots["size"], serde_json::json!([32, 32]), "{budget}");
    assert_eq!(budget["met"], true, "{budget}");
    let measured = pilots["measured"].as_array().expect("measured pilots");
    let max_pilots = valgi::vals::budget::DEFAULT_PILOTS;
    assert!(
        !measured.is_empty() && measured.len() <= max_pilots,
        "{pilots}"
    );
    let key = |c: &serde_json::Value| {
        (
            c["points"].as_u64(),
            c["rsm"].as_u64(),
            c["visibility"].as_str().map(str::to_owned),
        )
    };
    let cheapest_met = measured
        .iter()
        .filter(|p| p["measured_flip"].as_f64().unwrap() <= 0.1)
        .min_by(|a, b| {
            a["predicted_ms"]
                .as_f64()
                .unwrap()
                .total_cmp(&b["predicted_ms"].as_f64().unwrap())
        })
        .unwrap_or(&pilots["converged"]);
    let chosen = (
        budget["sparse_points"]["value"].as_u64(),
        budget["rsm"]["value"].as_u64(),
        Some(
            match (
                budget["occlusion"]["value"].as_str(),
                budget["visibility_rays"]["value"].as_str(),
            ) {
                (Some("off"), _) => "off".to_owned(),
                (_, Some("adaptive")) => "rays adaptive".to_owned(),
                _ => "rays".to_owned(),
            },
        ),
    );
    assert_eq!(key(cheapest_met), chosen, "{budget}");
    assert!(
        pilots["chosen_measured_flip"].as_f64().unwrap() <= 0.1,
        "{budget}"
    );
    // Without pilots the survey's prediction decides, and is what the report gives.
    let unmeasured = budget_render("cornell", &["--target-flip", "0.1", "--budget-pilots", "0"]);
    let unmeasured = &unmeasured["budget"];
    assert!(unmeasured["pilots"].is_null(), "{unmeasured}");
    assert!(
        unmeasured["predicted_flip"].as_f64().unwrap() <= 0.1,
        "{unmeasured}"
    );
    // Its walls are Lambert: the gather is diffuse only and priced so; `glossy on` prices the
    // lobes.
    assert_eq!(cornell["glossy_gathered"], false);
    let gather_cost = valgi::vals::budget::model::gather_cost;
    assert_eq!(budget["gather_cost"], gather_cost(false, true));
    let glossy = budget_render("cornell", &["--target-flip", "0.1", "--glossy", "on"]);
    assert_eq!(glossy["budget"]["occlusion"]["value"], "rays");
    assert_eq!(glossy["budget"]["gather_cost"], gather_cost(true, true));
    assert!(gather_cost(false, true) < gather_cost(true, true));
    // The survey looks from the camera the image is drawn from: the scene's own by default,
    // the command line's when it gives one.
    let own = budget["surveyed_from"].as_array().expect("surveyed_from");
    let eye = [0.1, 0.9, 0.2];
    let moved = budget_render(
        "cornell",
        &["--camera-eye", "0.1,0.9,0.2", "--camera-target", "0,0.5,-1"],
    );
    let from = moved["budget"]["surveyed_from"]
        .as_array()
        .expect("surveyed_from");
    for (axis, (f, e)) in from.iter().zip(eye).enumerate() {
        assert!(
            (f.as_f64().unwrap() - e).abs() < 1e-4,
            "axis {axis}: {from:?}"
        );
    }
    assert_ne!(own, from, "cornell's own camera stands elsewhere");
    // In a convex empty box nothing is in the way: no occlusion. A point count given on the
    // command line stays, and says so.
    let empty = budget_render("bunny-box-empty", &["--sparse-points", "300"]);
    assert_eq!(empty["budget"]["occlusion"]["value"], "off", "{empty}");
    assert_eq!(empty["sparse_points"].as_u64(), Some(300));
    assert_eq!(empty["budget"]["sparse_points"]["why"], "given");
    // A target without budget mode, two targets, and nonsense values are refused.
    let out = temp_out("cli-budget", "x.exr");
    let out = out.as_str();
    let sparse = ["--method", "sparse"];
    assert_refused(
        &[tiny_render(out, &sparse), vec!["--target-flip", "0.1"]].concat(),
        &["--quality auto"],
    );
    for extra in [
        vec![
            "--quality",
            "auto",
            "--target-flip",
            "0.1",
            "--budget-ms",
            "100",
        ],
        vec!["--quality", "auto", "--target-flip", "1.5"],
        vec!["--quality", "auto", "--budget-ms", "-3"],
    ] {
        assert_refused(&[tiny_render(out, &sparse), extra].concat(), &["--"]);
    }
    for pilots in ["-1", "many", "33"] {
        let extra = vec!["--quality", "auto", "--budget-pilots", pilots];
        assert_refused(
            &[tiny_render(out, &sparse), extra].concat(),
            &["budget-pilots", pilots],
        );
    }
}

/// Under `--budget-ms` the candidates are timed at the render's size: a budget every frame
/// fits takes the most accurate candidate, one no frame fits the cheapest (said to miss),
/// and one between them the most accurate candidate a pilot measured within it (by
/// prediction, or by the pilot frames that rank those within it).
#[test]
fn a_time_budget_is_spent_by_timed_frames() {
    if common::gpu().is_none() {
        return;
    }
    let key = |c: &serde_json::Value| {
        (
            c["points"].as_u64(),
            c["rsm"].as_u64(),
            c["visibility"].as_str().map(str::to_owned),
        )
    };
    let chosen = |budget: &serde_json::Value| {
        let visibility = match (
            budget["occlusion"]["value"].as_str(),
            budget["visibility_rays"]["value"].as_str(),
        ) {
            (Some("off"), _) => "off",
            (_, Some("adaptive")) => "rays adaptive",
            _ => "rays",
        };
        (
            budget["sparse_points"]["value"].as_u64(),
            budget["rsm"]["value"].as_u64(),
            Some(visibility.to_owned()),
        )
    };
    let max_pilots = valgi::vals::budget::DEFAULT_PILOTS;
    let timed = |ms: f64| {
        let report = budget_render("cornell", &["--budget-ms", &ms.to_string()]);
        let budget = report["budget"].clone();
        let pilots = budget["timing_pilots"].clone();
        assert_eq!(pilots["size"], serde_json::json!([32, 32]), "{budget}");
        let measured = pilots["measured"].as_array().expect("timed pilots").clone();
        assert!(
            !measured.is_empty() && measured.len() <= max_pilots,
            "{budget}"
        );
        (budget, measured)
    };
    let time = |c: &serde_json::Value| c["measured_ms"].as_f64().unwrap_or(f64::INFINITY);
    // Every candidate fits: the most accurate (the richest) is timed once, and taken.
    let (roomy, measured) = timed(1e7);
    assert_eq!(roomy["met"], true, "{roomy}");
    assert_eq!(measured.len(), 1, "{roomy}");
    assert_eq!(key(&measured[0]), chosen(&roomy), "{roomy}");
    assert_eq!(roomy["sparse_points"]["value"], 16384, "{roomy}");
    let rich_ms = time(&measured[0]);
    // None fits: the cheapest, timed to be sure, and the budget said to be missed.
    let (tight, measured) = timed(1e-3);
    assert_eq!(tight["met"], false, "{tight}");
    assert_eq!(measured.len(), 1, "{tight}");
    assert_eq!(key(&measured[0]), chosen(&tight), "{tight}");
    assert!(tight["choice"]
        .as_str()
        .unwrap()
        .contains("no candidate fits"));
    let cheap_ms = time(&measured[0]);
    assert!(cheap_ms < rich_ms, "{cheap_ms} against {rich_ms}");
    // Between them: the most accurate candidate measured within the budget.
    let between = (cheap_ms * rich_ms).sqrt();
    let (budget, measured) = timed(between);
    let best = measured
        .iter()
        .filter(|p| time(p) <= between)
        .min_by(|a, b| {
            let flip = |c: &serde_json::Value| c["predicted_flip"].as_f64().unwrap();
            flip(a).total_cmp(&flip(b))
        });
    // (The cheapest, timed within it above, is there to be found, unless the pilots run out
    // first.)
    assert!(best.is_some() || measured.len() == max_pilots, "{budget}");
    if let Some(best) = best {
        assert_eq!(budget["met"], true, "{budget}");
        assert!(
            budget["timing_pilots"]["chosen_measured_ms"]
                .as_f64()
                .unwrap()
                <= between
        );
        // Unless pilot frames measured another candidate more accurate (and it was timed
        // within the budget too), the most accurate by prediction among those timed within.
        let accuracy = &budget["timing_pilots"]["accuracy"];
        if accuracy["changed_choice"] == true {
            let flip = |c: &serde_json::Value| c["measured_flip"].as_f64().unwrap_or(f64::INFINITY);
            let most_accurate = accuracy["measured"]
                .as_array()
                .expect("accuracy pilots")
                .iter()
                .min_by(|a, b| flip(a).total_cmp(&flip(b)))
                .expect("an accuracy pilot");
            assert_eq!(key(most_accurate), chosen(&budget), "{budget}");
            assert!(measured
                .iter()
                .any(|p| key(p) == chosen(&budget) && time(p) <= between));
        } else {
            assert_eq!(key(best), chosen(&budget), "{budget}");
        }
    } // Without pilots the survey's prediction decides.
    let alone = budget_render("cornell", &["--budget-ms", "100", "--budget-pilots", "0"]);
    assert!(alone["budget"]["timing_pilots"].is_null(), "{alone}");
}

/// A frame through a rig records the per-view passes (G-buffer, direct light, apply) once per
/// view, so `render` tells budget mode how many views its frames record, and the timing
/// pilots record as many (`timing_pilots_render_the_composed_methods_layer_through_every_view`
/// counts them).
#[test]
fn a_time_budget_is_timed_through_as_many_views_as_the_rig() {
    if common::gpu().is_none() {
        return;
    }
    let cheapest = [
        "--sparse-points",
        "1024",
        "--rsm",
        "32",
        "--occlusion",
        "off",
    ];
    for (views, count) in [("mono", 1), ("stereo", 2), ("grid:8", 8)] {
        let mut args = vec!["--budget-ms", "1e7", "--views", views];
        args.extend(cheapest);
        let report = budget_render("cornell", &args);
        let budget = &report["budget"];
        assert_eq!(budget["timing_pilots"]["views"], count, "{budget}");
        assert_eq!(
            report["views"].as_array().map(Vec::len),
            Some(count),
            "{report}"
        );
        let target = budget["target"].as_str().unwrap();
        assert_eq!(
            target.contains(&format!("through {count} views")),
            count > 1,
            "{target}"
        );
    }
}

/// `render`'s default method (`sparse+atlas`) under a time budget keeps its atlas layer: the
/// timing pilots borrow it and hand it back.
#[test]
fn the_default_method_under_a_time_budget_keeps_its_atlas() {
    if common::gpu().is_none() {
        return;
    }
    let report = budget_render_as(
        None,
        "cornell",
        &[
            "--budget-ms",
            "1e7",
            "--sparse-points",
            "1024",
            "--rsm",
            "32",
            "--occlusion",
            "off",
        ],
    );
    assert_eq!(report["method"], "sparse+atlas", "{report}");
    assert!(
        report["passes"]["atlas lookup"].as_f64().is_some(),
        "{report}"
    );
    let pilots = &report["budget"]["timing_pilots"]["measured"];
    assert_eq!(pilots.as_array().map(Vec::len), Some(1), "{report}");
}

/// An imported scene's tessellation is budget mode's fifth knob. Under a time budget the
/// scene is first refined for the densest candidate (the point count is measured on the
/// device after the scene is refined); once the budget has chosen fewer points, the scene is
/// refined again for them and the choice built over it. The budget's `max_edge` line says
/// which.
#[test]
fn a_time_budget_refines_an_imported_scene_for_the_points_it_chose_and_says_why() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-budget-max-edge");
    let scene = dir.join("corner.obj");
    // A 2 m × 2 m floor and a 2 m × 2 m wall behind it, two triangles each: a single plane
    // sends no light to itself, and budget mode has nothing to budget there.
    std::fs::write(
        &scene,
        "v -1 0 -1\nv 1 0 -1\nv 1 0 1\nv -1 0 1\nv -1 2 -1\nv 1 2 -1\n\
         f 1 3 2\nf 1 4 3\nf 1 2 6\nf 1 6 5\n",
    )
    .unwrap();
    let render = |budget_ms: &str| {
        let output = valgi()
            .args(["render", "--scene"])
            .arg(&scene)
            .args(["--light", "point:0,1,0.5,5", "--method", "sparse"])
            .args(["--width", "16", "--height", "16", "--no-write"])
            .args(["--quality", "auto", "--budget-ms", budget_ms])
            .args(["--budget-pilots", "0"])
            .output()
            .expect("run valgi");
        common::success_report(&output)
    };
    // The edge for `points` on the 8 m² corner, and the report's line.
    let expected = |points: usize| (8.0 / points as f64).sqrt() * std::f64::consts::FRAC_1_SQRT_2;
    let check_edge = |report: &serde_json::Value, points: usize| {
        assert_eq!(report["max_edge_source"], "sparse spacing", "{report}");
        let line = &report["budget"]["max_edge"];
        assert_eq!(line["value"], report["max_edge"], "{report}");
        let edge = line["value"].as_f64().unwrap();
        assert!(
            (edge / expected(points) - 1.0).abs() < 1e-3,
            "{edge} against {} for {points} points",
            expected(points)
        );
        line["why"].as_str().unwrap().to_string()
    };

    // Every candidate fits: the densest is chosen, and the scene stays as first refined.
    let densest = *valgi::vals::budget::CANDIDATE_POINTS.last().unwrap();
    let rich = render("1e7");
    assert_eq!(rich["budget"]["sparse_points"]["value"], densest, "{rich}");
    let why = check_edge(&rich, densest);
    assert!(
        why.contains("densest candidate") && !why.contains("again"),
        "{why}"
    );

    // None fits: the cheapest candidate, and the corner refined again for its points, four
    // times coarser along an edge.
    let fewest = valgi::vals::budget::CANDIDATE_POINTS[0];
    let cheap = render("0.001");
    assert_eq!(cheap["budget"]["sparse_points"]["value"], fewest, "{cheap}");
    assert_eq!(cheap["budget"]["met"], false, "{cheap}");
    let why = check_edge(&cheap, fewest);
    assert!(why.contains("refined again for the choice"), "{why}");
    let triangles = |r: &serde_json::Value| r["triangles"].as_u64().unwrap();
    assert!(
        triangles(&cheap) * 8 < triangles(&rich),
        "{} triangles against {}",
        triangles(&cheap),
        triangles(&rich)
    );
    // The method rendered is the choice, over the coarser corner: the same points as the
    // choice built over the scene as first refined would place (two-sided OBJ sheets get
    // their points on both sides).
    let placed = |r: &serde_json::Value| r["sparse_points"].as_u64().unwrap() as f64;
    assert!(
        (placed(&cheap) / placed(&rich) - fewest as f64 / densest as f64).abs() < 0.01,
        "{} points against {}",
        placed(&cheap),
        placed(&rich)
    );
}

/// The default method's atlas is baked in memory; a scene whose charts the default bake
/// cannot fit (3000 separate triangles need a 274² atlas, the bake's is 256²) renders the
/// sparse method alone with a warning, while `--method sparse+atlas` asked for by name is
/// refused with the size the bake needs.
#[test]
fn the_default_renders_without_the_atlas_where_the_bake_refuses_it() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-default-fallback");
    let scene = common::separate_triangles_obj(&dir, 3000);
    let render = |method: Option<&str>| {
        let mut command = valgi();
        command
            .args(["render", "--scene"])
            .arg(&scene)
            .args([
                "--light",
                "point:1.5,1,1.25,1",
                "--width",
                "16",
                "--height",
                "16",
            ])
            .args(["--sparse-points", "256", "--rsm", "16", "--out"])
            .arg(dir.join("out.exr"));
        if let Some(m) = method {
            command.args(["--method", m]);
        }
        command.output().expect("run valgi")
    };
    let output = render(None);
    common::assert_success(&output);
    let stderr = String::from_utf8_lossy(&output.stderr);
    let stdout = String::from_utf8_lossy(&output.stdout);
    let report: serde_json::Value =
        serde_json::from_str(stdout.lines().last().expect("a JSON line")).expect("JSON");
    assert_eq!(report["method"], "sparse", "{stderr}");
    assert!(
        stderr.contains("rendering 'sparse' without the atlas"),
        "{stderr}"
    );
    let output = render(Some("sparse+atlas"));
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("--atlas-res"), "{stderr}");
}

/// `render`'s default method takes every option of the sparse method it is built on: the
/// occlusion and budget flags as well as the atlas.
#[test]
fn the_default_method_takes_the_sparse_options() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-default-options");
    let flags = "--occlusion off --quality auto --target-flip 0.1 --width 16 --height 16";
    let output = valgi()
        .args(["render", "--scene", "plane-spot"])
        .args(flags.split(' '))
        .arg("--out")
        .arg(dir.join("x.exr"))
        .output()
        .expect("run valgi");
    let report = common::success_report(&output);
    assert_eq!(
        (&report["method"], &report["occlusion"]),
        (&"sparse+atlas".into(), &"off".into())
    );
    // Budget mode ran (manual settings report no `budget`).
    assert!(report["budget"]["met"].is_boolean(), "{report}");
}
