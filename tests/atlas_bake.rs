//! The light-atlas baker on the CPU: the closed box against the geometric series, the energy
//! account, cancellation, bad input, and the EXR round trip.

use std::sync::atomic::AtomicBool;

use valgi::atlas::{bake, BakeError, BakeSettings};
use valgi::scene::{self, builtin::BuiltinParams};

fn no_progress(_: &str, _: usize, _: usize) {}

/// Bakes the scene at rest, without progress output or cancellation.
fn bake_now(
    scene: &valgi::scene::Scene,
    settings: &BakeSettings,
) -> Result<valgi::atlas::Bake, valgi::atlas::BakeError> {
    bake(
        scene,
        &scene.world_from_node(),
        settings,
        &no_progress,
        &AtomicBool::new(false),
    )
}

fn box_scene() -> valgi::scene::Scene {
    scene::load("box-point", &BuiltinParams { max_edge: 0.25 }).unwrap()
}

/// Closed 2×2×2 box, albedo ρ = 0.5 everywhere, point light of I = 1 W/sr at the centre.
/// Every watt the light emits (Φ = 4π·I) lands on the walls (A = 24 m²); each reflection keeps
/// the fraction ρ and, the box being closed, all reflected light lands on the walls again. So
/// the area-mean irradiance of bounce b is Ē_b = ρ^b·Φ/A and the B-bounce indirect mean is
/// Φ/A · Σ_{b=1..B} ρ^b = Φ/A · ρ(1 − ρ^B)/(1 − ρ) (0.5236·0.9375 = 0.4909 W/m² for B = 4).
#[test]
fn closed_box_matches_the_geometric_series() {
    let scene = box_scene();
    let settings = BakeSettings {
        vpls: 600,
        bounces: 4,
        atlas_res: 128,
        ..Default::default()
    };
    let result = bake_now(&scene, &settings).unwrap();
    let rho = 0.5f64;
    let phi_over_a = 4.0 * std::f64::consts::PI / 24.0;
    let centre: Vec<u32> = result
        .layout
        .texels
        .iter()
        .filter(|t| t.centre)
        .map(|t| t.index)
        .collect();
    let mut total = 0.0;
    for b in 1..=4u32 {
        let mean = centre
            .iter()
            .map(|&i| result.irradiance[b as usize - 1][i as usize][1] as f64)
            .sum::<f64>()
            / centre.len() as f64;
        let expected = phi_over_a * rho.powi(b as i32);
        eprintln!("bounce {b}: mean {mean:.4}, expected {expected:.4}");
        assert!(
            (mean / expected - 1.0).abs() < 0.06,
            "bounce {b}: mean {mean} vs {expected}"
        );
        total += mean;
    }
    let expected = phi_over_a * rho * (1.0 - rho.powi(4)) / (1.0 - rho);
    eprintln!("B = 4: mean {total:.4}, expected {expected:.4}");
    assert!(
        (total / expected - 1.0).abs() < 0.04,
        "{total} vs {expected}"
    );
    eprintln!("{}", result.summary());
    let e = result.energy;
    assert!(e.relative_residual() < 1e-6, "{e:?}");
    // Closed box: light leaves only through the form factors' discretization.
    assert!(e.escaped[1] / e.emitted[1] < 0.08, "{e:?}");
}

fn small(vpls: usize) -> BakeSettings {
    BakeSettings {
        vpls,
        bounces: 3,
        atlas_res: 64,
        ..Default::default()
    }
}

#[test]
fn the_energy_account_closes_on_an_open_box() {
    // The Cornell box is open at the front: light escapes, and the account still closes.
    let scene = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let result = bake(
        &scene,
        &scene.world_from_node(),
        &small(300),
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let e = result.energy;
    eprintln!("{}", result.summary());
    assert!(e.relative_residual() < 1e-6, "{e:?}");
    for c in 0..3 {
        assert!(e.emitted[c] > 0.0 && e.absorbed[c] > 0.0 && e.unshot[c] >= 0.0);
        let escaped = e.escaped[c] / e.emitted[c];
        assert!(
            (0.05..0.6).contains(&escaped),
            "channel {c}: escaped {escaped}"
        );
    }
    // The spot light's power is 2π·I·∫ ramp: every channel emits the same (white light).
    assert!((e.emitted[0] - e.emitted[2]).abs() < 1e-9 * e.emitted[0]);
    // Irradiance per bounce falls off (ρ < 1).
    let mean = |b: usize| {
        result.irradiance[b]
            .iter()
            .map(|e| e[1] as f64)
            .sum::<f64>()
    };
    assert!(mean(0) > mean(1) && mean(1) > mean(2) && mean(2) > 0.0);
}

#[test]
fn from_bounce_writes_the_later_bounces_only() {
    let scene = box_scene();
    let result = bake(
        &scene,
        &scene.world_from_node(),
        &small(200),
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let all = result.atlas(1, 3);
    let later = result.atlas(2, 3);
    let first = result.atlas(1, 1);
    for t in &result.layout.texels {
        let i = t.index as usize;
        for c in 0..3 {
            let sum = first.pixels[i][c] + later.pixels[i][c];
            assert!((sum - all.pixels[i][c]).abs() <= 1e-5 * all.pixels[i][c].max(1e-6));
        }
        assert_eq!(all.pixels[i][3], 1.0);
    }
}

#[test]
fn atlas_exr_round_trips() {
    let scene = box_scene();
    let result = bake(
        &scene,
        &scene.world_from_node(),
        &small(100),
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let image = result.atlas(1, 3);
    let dir = std::env::temp_dir().join(format!("valgi-atlas-rt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("box.exr");
    valgi::atlas::bake::write_atlas_exr(&image, &path).unwrap();
    let back = valgi::image_io::Image::read_exr(&path).unwrap();
    assert_eq!((back.width, back.height), (image.width, image.height));
    assert_eq!(back.pixels, image.pixels, "32-bit float EXR is lossless");
    let leftovers: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(leftovers.len(), 1, "no temporary file left: {leftovers:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn cancelling_stops_the_bake_and_leaves_no_file() {
    let dir = std::env::temp_dir().join(format!("valgi-atlas-cancel-{}", std::process::id()));
    let out = dir.join("cancelled.exr");
    let cancel = AtomicBool::new(false);
    // Cancel as soon as the bake reports the visibility stage (as Ctrl-C would).
    let progress = |stage: &str, _: usize, _: usize| {
        if stage == "visibility" || stage == "fill" {
            cancel.store(true, std::sync::atomic::Ordering::Relaxed);
        }
    };
    let request = valgi::atlas::BakeRequest {
        scene: "box-point".into(),
        max_edge: 0.25,
        settings: small(200),
        from_bounce: 1,
        out: out.clone(),
    };
    let err = valgi::atlas::bake_to_file(&request, &progress, &cancel).unwrap_err();
    assert!(matches!(err, BakeError::Cancelled), "{err}");
    assert!(!out.exists(), "no atlas after a cancelled bake");
    let left: Vec<_> = std::fs::read_dir(&dir)
        .map(|d| d.map(|e| e.unwrap().file_name()).collect())
        .unwrap_or_default();
    assert!(left.is_empty(), "nothing left behind: {left:?}");
}

#[test]
fn bad_input_fails_with_a_clear_error() {
    let mut scene = box_scene();
    scene.lights.clear();
    let err = bake(
        &scene,
        &scene.world_from_node(),
        &small(10),
        &no_progress,
        &AtomicBool::new(false),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("no punctual lights"), "{err}");

    let request = |out: &str, from_bounce: u32| valgi::atlas::BakeRequest {
        scene: "box-point".into(),
        max_edge: 0.25,
        settings: small(10),
        from_bounce,
        out: out.into(),
    };
    let cancel = AtomicBool::new(false);
    let err =
        valgi::atlas::bake_to_file(&request("/proc/valgi-none/a.exr", 1), &no_progress, &cancel)
            .unwrap_err()
            .to_string();
    assert!(err.contains("/proc/valgi-none/a.exr"), "{err}");
    let err = valgi::atlas::bake_to_file(&request("/tmp/a.png", 1), &no_progress, &cancel)
        .unwrap_err()
        .to_string();
    assert!(err.contains(".exr"), "{err}");
    let dir = std::env::temp_dir().join(format!("valgi-atlas-bad-{}", std::process::id()));
    let path = dir.join("x.exr");
    let err =
        valgi::atlas::bake_to_file(&request(path.to_str().unwrap(), 4), &no_progress, &cancel)
            .unwrap_err()
            .to_string();
    assert!(err.contains("--from-bounce"), "{err}");
    assert!(!path.exists());
    let err = bake(
        &box_scene(),
        &box_scene().world_from_node(),
        &BakeSettings {
            vpls: 0,
            ..small(1)
        },
        &no_progress,
        &cancel,
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("--vpls"), "{err}");
}

/// Across a chart seam the irradiance stays continuous. In the box the seams are the edges
/// between walls; the box is symmetric under the reflection that swaps two walls, so texels of
/// different charts at the same distance from their common edge (mirror images) hold the same
/// irradiance up to the bake's own texel-to-texel variation there (VPL sampling noise near a
/// corner). The test bounds the jump across seams by the jump between neighbouring texels of
/// one chart at the same distance from the edge, and both by a fraction of the mean.
#[test]
fn irradiance_is_continuous_across_chart_seams() {
    let scene = box_scene();
    let settings = BakeSettings {
        vpls: 400,
        bounces: 3,
        atlas_res: 128,
        ..Default::default()
    };
    let result = bake_now(&scene, &settings).unwrap();
    let image = result.atlas(1, 3);
    let texels = &result.layout.texels;
    let res = settings.atlas_res;
    // World size of one texel: area per centre texel.
    let texel_size = (24.0 / texels.iter().filter(|t| t.centre).count() as f32).sqrt();
    let mean = texels
        .iter()
        .map(|t| image.pixels[t.index as usize][1])
        .sum::<f32>()
        / texels.len() as f32;
    let axis = |n: glam::Vec3| n.abs().max_position();
    // Distance of a texel on the wall with normal axis i to its edge with the wall of axis j.
    let edge_distance = |p: glam::Vec3, j: usize| 1.0 - p[j].abs();
    let (mut seam, mut inside) = (Vec::new(), Vec::new());
    for a in texels {
        let i = axis(a.normal);
        for b in texels {
            if a.index >= b.index || a.position.distance(b.position) > 1.5 * texel_size {
                continue;
            }
            let (ax, ay) = (a.index % res, a.index / res);
            let (bx, by) = (b.index % res, b.index / res);
            let uv_far = ax.abs_diff(bx) + ay.abs_diff(by) > 4;
            let j = axis(b.normal);
            let jump = (image.pixels[a.index as usize][1] - image.pixels[b.index as usize][1])
                .abs()
                / mean;
            if uv_far && i != j {
                if (edge_distance(a.position, j) - edge_distance(b.position, i)).abs()
                    < 0.3 * texel_size
                {
                    seam.push(jump);
                }
            } else if !uv_far && i == j {
                // Neighbours along an edge of the same wall, both next to that edge.
                for k in (0..3).filter(|&k| k != i) {
                    let (da, db) = (edge_distance(a.position, k), edge_distance(b.position, k));
                    if da < 1.5 * texel_size && (da - db).abs() < 0.3 * texel_size {
                        inside.push(jump);
                    }
                }
            }
        }
    }
    let rms = |v: &[f32]| (v.iter().map(|x| x * x).sum::<f32>() / v.len() as f32).sqrt();
    let (rs, ri) = (rms(&seam), rms(&inside));
    eprintln!(
        "{} mirror pairs across seams: rms jump {rs:.3} of the mean; {} same-chart pairs along edges: {ri:.3}",
        seam.len(),
        inside.len()
    );
    assert!(seam.len() > 100 && inside.len() > 100);
    assert!(
        rs < 1.5 * ri,
        "seams add a jump: {rs} vs {ri} inside the charts"
    );
    assert!(
        rs < 0.25,
        "rms jump across seams {rs} of the mean irradiance"
    );
}

/// A mesh with TEXCOORD_1 keeps it: the layout uses the given UVs (here the plane's [0, 1]
/// UVs), and every texel of the page stands for a point of the plane.
#[test]
fn texcoord1_is_used_when_present() {
    let mut scene = scene::load("plane-point", &BuiltinParams { max_edge: 0.5 }).unwrap();
    assert_eq!(scene.instances.len(), 1, "plane-point has one placed mesh");
    let mesh = &mut scene.meshes[scene.instances[0].mesh];
    let (lo, hi) = mesh.uv0.iter().fold(
        (glam::Vec2::splat(f32::MAX), glam::Vec2::splat(f32::MIN)),
        |(lo, hi), uv| (lo.min(*uv), hi.max(*uv)),
    );
    mesh.uv1 = Some(mesh.uv0.iter().map(|uv| (*uv - lo) / (hi - lo)).collect());
    let result = bake(
        &scene,
        &scene.world_from_node(),
        &small(50),
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    assert_eq!(result.layout.source, "texcoord1");
    assert_eq!(result.layout.texels.len(), 64 * 64);
    assert!(result.layout.texels.iter().all(|t| t.centre));
}
