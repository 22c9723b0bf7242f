//! `valgi bake` and `valgi render --method atlas` end to end.

mod common;

use std::process::Command;

fn valgi() -> Command {
    Command::new(env!("CARGO_BIN_EXE_valgi"))
}

fn json_line(stdout: &[u8]) -> serde_json::Value {
    let stdout = String::from_utf8_lossy(stdout);
    let line = stdout.lines().last().expect("a JSON line");
    serde_json::from_str(line).expect("valid JSON")
}

#[test]
fn bake_writes_an_atlas_and_render_uses_it() {
    let dir = common::temp_dir("cli-bake");
    let atlas = dir.join("box.exr");
    let output = valgi()
        .args(["bake", "--scene", "box-point", "--max-edge", "0.25"])
        .args([
            "--vpls",
            "100",
            "--bounces",
            "3",
            "--atlas-res",
            "64",
            "--from-bounce",
            "2",
            "--out",
        ])
        .arg(&atlas)
        .output()
        .expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "bake failed: {stderr}");
    let report = json_line(&output.stdout);
    for key in [
        "vpls",
        "samples",
        "texels",
        "stages_ms",
        "energy",
        "wall_ms",
        "shots",
    ] {
        assert!(report.get(key).is_some(), "missing {key}: {report}");
    }
    for stage in [
        "unwrap",
        "discretize",
        "direct",
        "sites",
        "visibility",
        "shoot",
        "fill",
        "write",
    ] {
        assert!(
            report["stages_ms"].get(stage).is_some(),
            "stage {stage}: {report}"
        );
    }
    assert!(report["energy"]["relative_residual"].as_f64().unwrap() < 1e-6);
    assert_eq!(report["from_bounce"], 2);
    // The light-map pre-pass figures of seed 001 §4.
    let prepass = &report["prepass"];
    let count = |key: &str| prepass[key].as_u64().unwrap_or_else(|| panic!("{report}"));
    assert_eq!(count("used_texels"), report["texels"].as_u64().unwrap());
    assert!(
        0 < count("t_uv") && count("t_uv") <= count("triangles"),
        "{prepass}"
    );
    assert!(count("p_uv") < count("used_texels"), "{prepass}");
    assert!(atlas.is_file());
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    names.sort();
    assert_eq!(
        names,
        ["box.exr", "box.exr.layout"],
        "only the atlas and its light-map layout"
    );

    if common::gpu().is_none() {
        return;
    }
    let image = dir.join("render.exr");
    let output = valgi()
        .args(["render", "--scene", "box-point", "--max-edge", "0.25"])
        .args(["--method", "atlas", "--width", "32", "--height", "32"])
        .args(["--indirect-only", "--atlas"])
        .arg(&atlas)
        .arg("--out")
        .arg(&image)
        .output()
        .expect("run valgi");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "render failed: {stderr}");
    let report = json_line(&output.stdout);
    assert_eq!(report["method"], "atlas");
    assert_eq!(report["atlas_missing_texels"], 0);
    assert_eq!(report["atlas_layout"], "stored", "{report}");
    let indirect = valgi::image_io::Image::read_exr(&image).unwrap();
    assert!(indirect.mean_rgb()[1] > 0.0);
}

/// `bake --no-scene-lights` bakes with the `--light` options alone, as `render` and `eval`
/// light with them: the emitted power is the added point light's 4π·I, and the scene's own
/// light's power is what the added light adds to it.
#[test]
fn bake_without_the_scene_s_lights_emits_the_added_light_alone() {
    let dir = common::temp_dir("cli-bake-lights");
    let emitted = |extra: &[&str]| {
        let output = valgi()
            .args([
                "bake",
                "--scene",
                "box-point",
                "--max-edge",
                "0.25",
                "--vpls",
                "50",
            ])
            .args(["--bounces", "1", "--atlas-res", "32", "--out"])
            .arg(dir.join("lights.exr"))
            .args(extra)
            .output()
            .expect("run valgi");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(output.status.success(), "bake {extra:?} failed: {stderr}");
        json_line(&output.stdout)["energy"]["emitted"][0]
            .as_f64()
            .unwrap()
    };
    let added = ["--light", "point:0.1,0.5,0.1,2"];
    let scene_only = emitted(&[]);
    let both = emitted(&added);
    let added_only = emitted(&["--light", "point:0.1,0.5,0.1,2", "--no-scene-lights"]);
    let point_power = 4.0 * std::f64::consts::PI * 2.0;
    assert!(
        (added_only - point_power).abs() < 1e-3 * point_power,
        "{added_only} W emitted, the point light has {point_power}"
    );
    assert!(
        (both - scene_only - added_only).abs() < 1e-3 * both,
        "{both} W with both, {scene_only} + {added_only} apart"
    );
    let output = valgi()
        .args(["bake", "--scene", "box-point", "--no-scene-lights", "--out"])
        .arg(dir.join("dark.exr"))
        .output()
        .expect("run valgi");
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("has no lights"), "{stderr}");
}

#[test]
fn bake_and_atlas_errors_are_clear() {
    let output = valgi()
        .args([
            "bake",
            "--scene",
            "box-point",
            "--out",
            "/proc/valgi-none/a.exr",
        ])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(stderr.contains("/proc/valgi-none/a.exr"), "{stderr}");

    let output = valgi()
        .args(["bake", "--scene", "no-such-scene", "--out", "/tmp/x.exr"])
        .output()
        .unwrap();
    assert!(!output.status.success());

    if common::gpu().is_none() {
        return;
    }
    // A missing atlas file is an error naming it (no --atlas at all bakes one in memory).
    let output = valgi()
        .args(["render", "--scene", "box-point", "--method", "atlas"])
        .args(["--atlas", "/tmp/valgi-no-such-atlas.exr"])
        .args([
            "--width",
            "16",
            "--height",
            "16",
            "--out",
            "/tmp/valgi-x.png",
        ])
        .output()
        .unwrap();
    assert!(!output.status.success());
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("--atlas") && stderr.contains("valgi-no-such-atlas.exr"),
        "{stderr}"
    );
}

/// Ctrl-C (SIGINT) during a long bake stops it with exit code 130 and leaves no file.
#[test]
fn interrupt_stops_the_bake_cleanly() {
    let dir = common::temp_dir("cli-bake-int");
    let atlas = dir.join("big.exr");
    let child = valgi()
        .args(["bake", "--scene", "cornell", "--vpls", "6400", "--out"])
        .arg(&atlas)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("cancelled"), "{stderr}");
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(names.is_empty(), "nothing written: {names:?}");
}

/// `--method sparse+atlas` from `valgi render` and as a `valgi eval` spec (with '+' in the
/// name and the atlas as an option), and `valgi bake-bench` writing its CSVs and chart.
#[test]
fn sparse_atlas_renders_evaluates_and_bake_bench_writes_its_files() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-sparse-atlas");
    let atlas = dir.join("box2.exr");
    let output = valgi()
        .args(["bake", "--scene", "box-point", "--max-edge", "0.25"])
        .args(["--vpls", "100", "--bounces", "3", "--atlas-res", "64"])
        .args(["--from-bounce", "2", "--out"])
        .arg(&atlas)
        .output()
        .expect("run valgi");
    common::assert_success(&output);
    let output = valgi()
        .args(["render", "--scene", "box-point", "--max-edge", "0.25"])
        .args([
            "--method",
            "sparse+atlas",
            "--width",
            "32",
            "--height",
            "32",
        ])
        .args(["--rsm", "32", "--indirect-only", "--atlas"])
        .arg(&atlas)
        .arg("--out")
        .arg(dir.join("render.exr"))
        .output()
        .expect("run valgi");
    common::assert_success(&output);
    let report = json_line(&output.stdout);
    assert_eq!(report["method"], "sparse+atlas");
    assert_eq!(report["atlas_missing_texels"], 0);
    assert!(report["passes"].get("atlas add").is_some(), "{report}");

    let eval = dir.join("eval");
    let output = valgi()
        .args(["eval", "--scenes", "box-point", "--max-edge", "0.25"])
        .arg("--methods")
        .arg(format!(
            "sparse:rsm=32,sparse+atlas:atlas={},rsm=32",
            atlas.display()
        ))
        .args(["--width", "24", "--height", "24", "--ref-spp", "4"])
        .args(["--ref-bounces", "3", "--out"])
        .arg(&eval)
        .output()
        .expect("run valgi");
    common::assert_success(&output);
    let csv = std::fs::read_to_string(eval.join("results.csv")).unwrap();
    assert!(csv.contains("\nbox-point,sparse+atlas,"), "{csv}");

    let bench = dir.join("bench");
    let output = valgi()
        .args(["bake-bench", "--scenes", "box-point", "--max-edge", "0.25"])
        .args(["--vpls", "30,60", "--bounces", "2", "--atlas-res", "64"])
        .args(["--width", "24", "--height", "24", "--ref-spp", "8"])
        .args(["--pt-spp", "1,4", "--out"])
        .arg(&bench)
        .output()
        .expect("run valgi");
    common::assert_success(&output);
    let csv = std::fs::read_to_string(bench.join("bake.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    assert!(csv.starts_with("scene,vpls,"));
    let curve = std::fs::read_to_string(bench.join("reference_convergence.csv")).unwrap();
    assert_eq!(curve.lines().count(), 3, "{curve}");
    assert!(bench.join("bake_box-point.png").is_file());
}

/// Without `--atlas`, `atlas` and `sparse+atlas` bake the scene's atlas in memory with
/// `valgi bake`'s defaults: the image is the one rendered with the file `valgi bake` writes
/// with its defaults (bounces from 1 for `atlas`, from 2 for `sparse+atlas`), bit for bit.
#[test]
fn atlas_methods_without_a_file_bake_the_default_atlas_in_memory() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("cli-atlas-in-memory");
    let read = |path: &std::path::Path| valgi::image_io::Image::read_exr(path).expect("EXR");
    for (method, from_bounce) in [("atlas", "1"), ("sparse+atlas", "2")] {
        let file = dir.join(format!("baked-{from_bounce}.exr"));
        let output = valgi()
            .args(["bake", "--scene", "box-point", "--max-edge", "0.25"])
            .args(["--from-bounce", from_bounce, "--out"])
            .arg(&file)
            .output()
            .expect("run valgi");
        common::assert_success(&output);
        let render = |atlas: Option<&std::path::Path>, out: &str| {
            let mut command = valgi();
            command
                .args(["render", "--scene", "box-point", "--max-edge", "0.25"])
                .args(["--method", method, "--width", "32", "--height", "32"]);
            if method == "sparse+atlas" {
                command.args(["--rsm", "32", "--sparse-points", "256"]);
            }
            if let Some(atlas) = atlas {
                command.arg("--atlas").arg(atlas);
            }
            let output = command
                .arg("--out")
                .arg(dir.join(out))
                .output()
                .expect("run valgi");
            common::assert_success(&output);
            let stderr = String::from_utf8_lossy(&output.stderr).to_string();
            (read(&dir.join(out)), stderr)
        };
        let (from_file, _) = render(Some(&file), &format!("{method}-file.exr"));
        let (in_memory, stderr) = render(None, &format!("{method}-memory.exr"));
        assert!(
            stderr.contains("atlas bake (no --atlas given)"),
            "{method}: the in-memory bake reports its stages: {stderr}"
        );
        assert!(from_file.mean_rgb()[0] > 0.0);
        assert_eq!(
            from_file.pixels, in_memory.pixels,
            "{method}: the in-memory atlas renders as the default bake's file does"
        );
    }
}
