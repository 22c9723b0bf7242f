//! Metrics on image pairs with known answers, the method-spec splitter, the reference cache,
//! and `valgi eval` end to end on two tiny animated scenes.

mod common;

use valgi::eval::{self, metrics};
use valgi::image_io::Image;

fn constant(w: u32, h: u32, v: f32) -> Image {
    Image::from_rgba(w, h, vec![[v, v, v, 1.0]; (w * h) as usize])
}

fn ramp(w: u32, h: u32) -> Image {
    let pixels = (0..w * h)
        .map(|i| {
            let v = (i % w) as f32 / w as f32;
            [v, 0.5 * v, 0.25, 1.0]
        })
        .collect();
    Image::from_rgba(w, h, pixels)
}

#[test]
fn identical_images_have_zero_error() {
    let a = ramp(32, 24);
    assert_eq!(metrics::rmse(&a, &a), 0.0);
    assert_eq!(metrics::relmse(&a, &a), 0.0);
    assert_eq!(metrics::flip(&a, &a, 0.0), 0.0);
}

#[test]
fn a_known_offset_gives_its_known_error() {
    let r = constant(16, 16, 0.5);
    let a = constant(16, 16, 0.6);
    assert!((metrics::rmse(&a, &r) - 0.1).abs() < 1e-6);
    // (0.1)² / (0.5² + 0.01) = 0.01 / 0.26.
    assert!((metrics::relmse(&a, &r) - 0.01 / 0.26).abs() < 1e-6);
    // An offset in one channel of a quarter of the pixels: RMSE = sqrt(0.2²/(3·4)).
    let mut b = r.clone();
    for p in b.pixels.iter_mut().step_by(4) {
        p[1] += 0.2;
    }
    let expected = (0.04f64 / 12.0).sqrt();
    assert!((metrics::rmse(&b, &r) - expected).abs() < 1e-6);
    // FLIP grows with the difference and stays in (0, 1].
    let small = metrics::flip(&constant(16, 16, 0.52), &r, 0.0);
    let large = metrics::flip(&constant(16, 16, 0.9), &r, 0.0);
    assert!(
        0.0 < small && small < large && large <= 1.0,
        "{small} {large}"
    );
    // White against black is the largest difference FLIP knows.
    let extreme = metrics::flip(&constant(16, 16, 1.0), &constant(16, 16, 0.0), 0.0);
    assert!(extreme > 0.9, "{extreme}");
}

#[test]
fn flicker_is_zero_for_linear_motion_and_known_for_alternation() {
    // Linear in time: second differences vanish.
    let linear: Vec<Image> = (0..5)
        .map(|t| constant(8, 8, 1.0 + 0.1 * t as f32))
        .collect();
    assert!(metrics::flicker(&linear).unwrap() < 1e-10);
    // I_t = m + d·(−1)^t: second difference ±4d, so flicker = 16 d² / m².
    let (m, d) = (2.0f32, 0.1f32);
    let alternating: Vec<Image> = (0..6)
        .map(|t| constant(8, 8, m + if t % 2 == 0 { d } else { -d }))
        .collect();
    let expected = 16.0 * (d * d) as f64 / (m * m) as f64;
    let got = metrics::flicker(&alternating).unwrap();
    assert!(
        (got - expected).abs() < 1e-6 * expected.max(1.0),
        "{got} vs {expected}"
    );
    assert!(metrics::flicker(&linear[..2]).is_none());
    assert_eq!(metrics::flicker(&vec![constant(4, 4, 0.0); 3]), Some(0.0));
}

#[test]
fn static_flicker_leaves_out_the_pixels_a_moving_surface_crosses() {
    use glam::Vec3;
    // Pixel 0 keeps its surface; pixel 1 sees a moving one; pixel 2 misses in every frame;
    // pixel 3 turns; pixel 4 hits, then misses.
    let frames = 4;
    let hit = |x: f32, n: Vec3| Some((Vec3::new(x, 0.0, 1.0), n));
    let hits: Vec<Vec<Option<(Vec3, Vec3)>>> = (0..frames)
        .map(|f| {
            let t = f as f32;
            vec![
                hit(0.0, Vec3::Z),
                hit(0.1 * t, Vec3::Z),
                None,
                hit(0.0, Vec3::new(0.0, 0.1 * t, 1.0).normalize()),
                if f == 0 { hit(0.0, Vec3::Z) } else { None },
            ]
        })
        .collect();
    let mask = metrics::static_pixels(&hits, 1e-4);
    assert_eq!(mask, vec![true, false, true, false, false]);
    // Pixel 0 brightens linearly, pixel 1 (the moving surface) alternates: the static flicker
    // is 0, the flicker of all pixels is not.
    let images: Vec<Image> = (0..frames)
        .map(|t| {
            let mut image = constant(5, 1, 1.0);
            let v = 1.0 + 0.1 * t as f32;
            image.pixels[0] = [v, v, v, 1.0];
            let v = if t % 2 == 0 { 2.0 } else { 0.0 };
            image.pixels[1] = [v, v, v, 1.0];
            image
        })
        .collect();
    assert!(metrics::flicker(&images).unwrap() > 0.1);
    assert!(metrics::flicker_where(&images, Some(&mask)).unwrap() < 1e-10);
    assert!(metrics::flicker_where(&images, Some(&[false; 5])).is_none());
}

#[test]
fn auto_exposure_maps_the_mean_to_mid_grey() {
    let e = metrics::auto_exposure(&constant(4, 4, 0.045));
    assert!((e - 2.0).abs() < 1e-4, "{e}");
    assert_eq!(metrics::auto_exposure(&constant(4, 4, 0.0)), 0.0);
}

#[test]
fn method_specs_split_at_method_boundaries() {
    assert_eq!(
        eval::split_method_specs("direct,sparse:rsm=64,tile=128,brute,reference:spp=4"),
        vec![
            "direct",
            "sparse:rsm=64,tile=128",
            "brute",
            "reference:spp=4"
        ]
    );
    assert_eq!(eval::split_method_specs(" direct , "), vec!["direct"]);
    assert_eq!(
        eval::split_list("cornell, corridor"),
        vec!["cornell", "corridor"]
    );
}

#[test]
fn references_are_cached_by_key() {
    let dir = common::temp_dir("eval-cache");
    let make = || valgi::reference::ReferenceImage {
        direct: constant(4, 2, 0.5),
        indirect: constant(4, 2, 0.25),
        variance: constant(4, 2, 0.0),
        variance_indirect: constant(4, 2, 0.0),
        paths: 8,
        seconds: 0.0,
    };
    let key_with = |specular| {
        eval::reference_key(
            "cornell",
            None,
            4,
            2,
            valgi::reference::Bounces::Limited(1),
            16,
            1,
            0.05,
            0.0,
            specular,
        )
    };
    let key = key_with(true);
    // Keys of references with specular light read as they did before the switch existed
    // (caches stay valid); without it the key differs.
    assert!(!key.contains("specular"), "{key}");
    let diffuse_key = key_with(false);
    assert!(
        diffuse_key.starts_with(&key) && diffuse_key != key,
        "{diffuse_key}"
    );
    let first = eval::cached_reference(&dir, &key, make).unwrap();
    assert!(first.rendered);
    let second = eval::cached_reference(&dir, &key, || panic!("must come from the cache")).unwrap();
    assert!(!second.rendered);
    assert_eq!(second.indirect, first.indirect);
    assert_eq!(second.full().get(0, 0)[0], 0.75);
    let other_key = key.replace("spp=16", "spp=32");
    assert!(
        eval::cached_reference(&dir, &other_key, make)
            .unwrap()
            .rendered
    );
}

#[test]
fn eval_end_to_end_on_two_tiny_scenes() {
    if common::gpu().is_none() {
        return;
    }
    let dir = common::temp_dir("eval-e2e");
    let run = |methods: &str| {
        std::process::Command::new(env!("CARGO_BIN_EXE_valgi"))
            .args(["eval", "--scenes", "cornell-moving,corridor-moving"])
            .args(["--methods", methods])
            .args([
                "--width",
                "24",
                "--height",
                "16",
                "--ref-spp",
                "4",
                "--frames",
                "3",
            ])
            .args(["--max-edge", "0.3", "--out"])
            .arg(&dir)
            .output()
            .expect("run valgi eval")
    };
    let output = run("direct,reference:spp=2,bounces=1");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "eval failed: {stderr}");
    let stdout = String::from_utf8_lossy(&output.stdout);
    let report: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(report["references_rendered"], 2);
    assert_eq!(report["rows"], 4);

    let csv = std::fs::read_to_string(dir.join("results.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines[0], eval::CSV_HEADER);
    assert_eq!(lines.len(), 5, "{csv}");
    let header: Vec<&str> = lines[0].split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    for line in &lines[1..] {
        // Settings may be quoted (they contain commas); split the quoted field out first.
        let fields = split_csv(line);
        assert_eq!(fields.len(), header.len(), "{line}");
        for metric in [
            "rmse",
            "relmse",
            "flip",
            "flip_indirect",
            "flicker",
            "flicker_static",
            "total_ms",
        ] {
            let v: f64 = fields[col(metric)]
                .parse()
                .unwrap_or_else(|_| panic!("{metric} is not a number in {line}"));
            assert!(v.is_finite() && v >= 0.0, "{metric} = {v} in {line}");
        }
    }
    let direct = lines
        .iter()
        .find(|l| l.starts_with("cornell-moving,direct"))
        .unwrap();
    let direct = split_csv(direct);
    assert!(direct[col("passes_ms")].contains("shadow="), "{direct:?}");
    assert!(direct[col("gpu_bytes")].parse::<u64>().unwrap() > 0);
    let reference = lines
        .iter()
        .find(|l| l.starts_with("corridor-moving,reference"))
        .unwrap();
    let reference = split_csv(reference);
    assert_eq!(reference[col("settings")], "bounces=1,spp=2");
    assert!(reference[col("passes_ms")].starts_with("path_trace="));
    assert_eq!(reference[col("gpu_bytes")], "0");

    for scene in ["cornell-moving", "corridor-moving"] {
        for file in [format!("{scene}_pareto.png"), format!("{scene}_sheet.png")] {
            let img = image::open(dir.join(&file)).unwrap_or_else(|e| panic!("{file}: {e}"));
            assert!(img.width() >= 100 && img.height() >= 50, "{file}");
        }
    }

    // A second run takes the references from the cache.
    let output = run("direct");
    assert!(output.status.success());
    let report: serde_json::Value = serde_json::from_str(
        String::from_utf8_lossy(&output.stdout)
            .lines()
            .last()
            .unwrap(),
    )
    .unwrap();
    assert_eq!(report["references_cached"], 2);
    assert_eq!(report["references_rendered"], 0);

    // Unknown methods and options are named before anything renders.
    for (methods, needle) in [("nope", "nope"), ("reference:colour=red", "colour")] {
        let output = run(methods);
        assert!(!output.status.success());
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(stderr.contains(needle), "{stderr}");
    }
}

/// Splits one CSV line with RFC 4180 quoting.
fn split_csv(line: &str) -> Vec<String> {
    let mut fields = vec![];
    let mut field = String::new();
    let mut quoted = false;
    let mut chars = line.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '"' if quoted && chars.peek() == Some(&'"') => {
                field.push('"');
                chars.next();
            }
            '"' => quoted = !quoted,
            ',' if !quoted => fields.push(std::mem::take(&mut field)),
            _ => field.push(c),
        }
    }
    fields.push(field);
    fields
}

#[test]
fn failure_case_scenes_and_their_moving_variants() {
    use valgi::scene::builtin::{self, procedural, BuiltinParams};
    let params = BuiltinParams { max_edge: 0.2 };
    for base in [
        "cornell",
        "corridor",
        "coarse-wall",
        "aligned-occluders",
        "thin-wall",
        "glossy-row",
        "cornell-bunny",
    ] {
        let moving = format!("{base}-moving");
        assert!(
            builtin::names().iter().any(|(n, _)| *n == moving),
            "{moving} listed"
        );
        let scene = builtin::load(&moving, &params).unwrap();
        assert_eq!(scene.name, moving);
        assert!(scene.animation_duration() > 0.0, "{moving} is animated");
        let (a, b) = (scene.world_from_node_at(0.0), scene.world_from_node_at(1.0));
        assert!(a != b, "{moving} moves");
        let still = builtin::load(base, &params).unwrap();
        assert!(still.animations.is_empty(), "{base} is still");
    }
    // The door angle is a parameter; closed shuts the doorway.
    let closed = builtin::load("corridor-door0", &params).unwrap();
    let open = builtin::load("corridor-door90", &params).unwrap();
    let door = |s: &valgi::scene::Scene| {
        let node = s.nodes.iter().position(|n| n.name == "door").unwrap();
        s.world_from_node()[node].transform_vector3(glam::Vec3::Z)
    };
    assert!((door(&closed) - glam::Vec3::Z).length() < 1e-5);
    assert!((door(&open) - glam::Vec3::X).length() < 1e-5);
    assert!(builtin::load("corridor-door400", &params).is_err());
    // The coarse wall is two triangles.
    let coarse = builtin::load("coarse-wall", &params).unwrap();
    let wall = coarse
        .meshes
        .iter()
        .find(|m| m.name == procedural::COARSE_WALL_MESH)
        .unwrap();
    assert_eq!(wall.triangle_count(), 2);
    // glossy-row's exponents come out of the material mapping.
    let glossy = builtin::load("glossy-row", &params).unwrap();
    for k in procedural::GLOSSY_ROW_EXPONENTS {
        let m = glossy
            .materials
            .iter()
            .find(|m| m.name == format!("phong k={k}"))
            .unwrap();
        let got = valgi::scene::Material::phong_exponent(m.roughness);
        assert!((got - k).abs() < 1e-2 * k, "k {k}: {got}");
    }
}

#[test]
fn bunny_from_ply_or_a_named_stand_in() {
    use valgi::scene::builtin::procedural::{bunny_mesh, load_ply};
    let dir = common::temp_dir("bunny");
    // Missing: the stand-in, named as such, with a warning naming where it looked.
    let missing = dir.join("none.ply");
    let (mesh, warning) = bunny_mesh(std::slice::from_ref(&missing)).unwrap();
    assert!(mesh.name.contains("stand-in"), "{}", mesh.name);
    assert!(mesh.triangle_count() > 100);
    assert!(warning.unwrap().contains("none.ply"));
    // A small valid ASCII PLY with an extra vertex property and a quad.
    let good = dir.join("quad.ply");
    std::fs::write(
        &good,
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nproperty float confidence\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0 1\n1 0 0 1\n1 1 0 1\n0 1 0 1\n4 0 1 2 3\n",
    )
    .unwrap();
    let mesh = load_ply(&good).unwrap();
    assert_eq!(mesh.triangle_count(), 2);
    let (mesh, warning) = bunny_mesh(&[missing.clone(), good.clone()]).unwrap();
    assert_eq!(mesh.name, "bunny");
    assert!(warning.is_none());
    // Malformed files are errors that name the file and the problem.
    for (name, text, needle) in [
        ("magic.ply", "plx\n", "not a PLY"),
        ("binary.ply", "ply\nformat binary_little_endian 1.0\nend_header\n", "no vertex element"),
        (
            "short.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n",
            "ends at vertex 2",
        ),
        (
            "index.ply",
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n",
            "out of range",
        ),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let err = load_ply(&path).unwrap_err().to_string();
        assert!(err.contains(name) && err.contains(needle), "{err}");
        let err = bunny_mesh(&[path]).unwrap_err().to_string();
        assert!(err.contains(needle), "{err}");
    }
    // The shared data's bunny, when present, loads as the real thing.
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/bunny/bun_zipper_res2.ply");
    if shared.is_file() {
        let mesh = load_ply(&shared).unwrap();
        assert!(mesh.triangle_count() > 10_000, "{}", mesh.triangle_count());
    }
}
