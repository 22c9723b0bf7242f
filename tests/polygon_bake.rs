//! The polygon-light baker (seed 001) end to end: the closed box against the geometric
//! series, power conservation from the lights to the VPLs to the virtual lights, the texel
//! coverage invariant, and per-bounce against joint clustering.

mod common;

use std::sync::atomic::AtomicBool;

use valgi::atlas::bake::PolygonSettings;
use valgi::atlas::{bake, Bake, BakeSettings, Lights};
use valgi::scene::{self, builtin::BuiltinParams, Scene};

fn no_progress(_: &str, _: usize, _: usize) {}

fn bake_now(scene: &Scene, settings: &BakeSettings) -> Bake {
    bake(
        scene,
        &scene.world_from_node(),
        settings,
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap()
}

fn polygons(paths: usize, bounces: u32, atlas_res: u32) -> BakeSettings {
    BakeSettings {
        lights: Lights::Polygons,
        vpls: paths,
        bounces,
        atlas_res,
        ..Default::default()
    }
}

/// Closed 2 m box of albedo 0.5 with a 1 W/sr point light at its centre: the area-mean
/// irradiance of bounce b is ρ^b·Φ/A (see tests/atlas_bake.rs). Nothing stands inside, so
/// the shadows must not darken anything either.
#[test]
fn closed_box_matches_the_geometric_series() {
    let scene = scene::load("box-point", &BuiltinParams { max_edge: 0.25 }).unwrap();
    for shadows in [false, true] {
        let mut settings = polygons(20_000, 3, 64);
        settings.polygon.shadows = shadows;
        let result = bake_now(&scene, &settings);
        eprintln!("{}", result.summary());
        for b in 1..=3u32 {
            let mean = common::centre_bounce_mean(&result, b);
            let expected = common::BOX_PHI_OVER_A * 0.5f64.powi(b as i32);
            eprintln!("shadows {shadows}, bounce {b}: mean {mean:.4}, expected {expected:.4}");
            assert!(
                (mean / expected - 1.0).abs() < 0.05,
                "shadows {shadows}, bounce {b}: {mean} vs {expected}"
            );
        }
        assert!(
            result.energy.relative_residual() < 1e-9,
            "{:?}",
            result.energy
        );
    }
}

/// Σ light power = Σ photon power; per light and bounce, Σ VPL power = Σ virtual-light power
/// (every VPL lands in exactly one cluster); the photons' account closes.
#[test]
fn power_is_conserved_from_lights_to_vpls_to_virtual_lights() {
    use valgi::atlas::bake::light_power;
    use valgi::atlas::polygon::{cluster_lights, photons};
    let scene = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let world = scene.world_from_node();
    let tracer = valgi::reference::Tracer::new(&scene, &world);
    let lights = valgi::shading::WorldLight::from_scene(&scene, &world);
    let p = photons::trace(
        &tracer,
        &lights,
        (glam::Vec3::ZERO, 10.0),
        20_000,
        3,
        5,
        &AtomicBool::new(false),
    );
    let emitted = light_power(&lights[0]).unwrap().as_dvec3();
    for c in 0..3 {
        assert!((p.energy.emitted[c] - emitted[c]).abs() <= 1e-12 * emitted[c]);
    }
    assert!(p.energy.relative_residual() < 1e-12, "{:?}", p.energy);
    let settings = PolygonSettings::default();
    for (b, vpls) in p.vpls[0].iter().enumerate() {
        let tags = vec![b; vpls.len()];
        let (virtual_lights, planes) = cluster_lights(vpls, &tags, 3, &settings, 5.5, 9);
        for c in 0..3 {
            let vpl_sum: f64 = vpls.iter().map(|v| v.power[c]).sum();
            let light_sum: f64 = virtual_lights.iter().map(|l| l.power[b][c]).sum();
            assert!(
                (vpl_sum - light_sum).abs() <= 1e-12 * vpl_sum,
                "bounce {}: {vpl_sum} vs {light_sum}",
                b + 1
            );
        }
        let polygons = virtual_lights
            .iter()
            .filter(|l| matches!(l.shape, valgi::atlas::polygon::Shape::Polygon(_)))
            .count();
        eprintln!(
            "bounce {}: {} VPLs, {planes} planes, {} lights ({polygons} polygons)",
            b + 1,
            vpls.len(),
            virtual_lights.len()
        );
        // Cornell's VPLs lie on its walls and blocks: nearly all clusters are planar.
        assert!(planes >= 5 && polygons * 10 >= virtual_lights.len() * 9);
    }
}

/// The paper's invariant on the conservative coverage: every texel that a uv triangle
/// overlaps gets a (finite) value.
#[test]
fn every_texel_a_uv_triangle_overlaps_gets_a_value() {
    use valgi::atlas::layout::triangle_overlaps_square;
    let scene = scene::load("cornell", &BuiltinParams { max_edge: 0.1 }).unwrap();
    let result = bake_now(&scene, &polygons(3000, 1, 64));
    let res = result.layout.resolution;
    let mut overlapped = 0usize;
    for m in &result.layout.meshes {
        for t in m.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.uvs[i as usize] * res as f32);
            let lo = a.min(b).min(c).floor().max(glam::Vec2::ZERO);
            let hi = a.max(b).max(c).ceil().min(glam::Vec2::splat(res as f32));
            for y in lo.y as u32..hi.y as u32 {
                for x in lo.x as u32..hi.x as u32 {
                    let q = glam::Vec2::new(x as f32, y as f32);
                    if triangle_overlaps_square(a, b, c, q, q + glam::Vec2::ONE) {
                        overlapped += 1;
                        let i = (y * res + x) as usize;
                        assert!(
                            result.covered[i],
                            "texel ({x}, {y}) is overlapped but empty"
                        );
                        assert!(result.irradiance[0][i].iter().all(|v| v.is_finite()));
                    }
                }
            }
        }
    }
    assert!(overlapped > 0);
}

/// Relative RMS error of bounces 1 + 2 at every `step`-th covered texel centre against the
/// path tracer's irradiance (green channel), baked with polygon lights clustered per bounce
/// or jointly (all bounces of a light together), and the error over the texels `region`
/// picks. 20k photon paths, 2 bounces.
fn clustering_error(
    scene: &Scene,
    per_bounce: bool,
    atlas_res: u32,
    step: usize,
    seed: u64,
    region: impl Fn(glam::Vec3) -> bool,
) -> (f64, f64) {
    let mut settings = polygons(20_000, 2, atlas_res);
    settings.polygon.per_bounce = per_bounce;
    settings.seed = seed;
    let result = bake_now(scene, &settings);
    let texels: Vec<_> = result
        .layout
        .texels
        .iter()
        .filter(|t| t.centre)
        .step_by(step)
        .copied()
        .collect();
    let picked: Vec<_> = texels.iter().collect();
    let reference = common::texel_reference(scene, &picked, 2, 1024, 3);
    let rel = |pick: &dyn Fn(glam::Vec3) -> bool| {
        let (mut sq, mut sum, mut n) = (0.0f64, 0.0f64, 0usize);
        for (t, r) in texels.iter().zip(&reference) {
            if !pick(t.position) {
                continue;
            }
            let baked: f64 = (0..2)
                .map(|b| result.irradiance[b][t.index as usize][1] as f64)
                .sum();
            sq += (baked - r.y as f64).powi(2);
            sum += r.y as f64;
            n += 1;
        }
        assert!(n > 0, "no texel in the region");
        (sq / n as f64).sqrt() / (sum / n as f64)
    };
    let (all, picked) = (rel(&|_| true), rel(&region));
    eprintln!(
        "per bounce {per_bounce}, seed {seed}: {} lights, relative RMS error {all:.4} over {} texels, {picked:.4} in the region",
        result.virtual_lights.len(),
        texels.len()
    );
    (all, picked)
}

/// Where bounces 1 and 2 lie on the same walls (Cornell; `VALGI_JOINT_SCENE=door-room` for
/// the door room) clustering them jointly costs nothing: both stay accurate (Cornell: 0.076
/// joint against 0.082 per bounce; door-room 0.141 against 0.140).
#[test]
fn per_bounce_and_joint_clustering_are_both_accurate_where_bounces_share_surfaces() {
    let name = std::env::var("VALGI_JOINT_SCENE").unwrap_or("cornell".into());
    let scene = scene::load(&name, &BuiltinParams { max_edge: 0.1 }).unwrap();
    let error = |per_bounce| clustering_error(&scene, per_bounce, 64, 7, 0, |_| true).0;
    let (separate, joint) = (error(true), error(false));
    let bound = if name == "cornell" { 0.10 } else { 0.2 };
    assert!(
        separate < bound && joint < bound,
        "per bounce {separate}, joint {joint}"
    );
}

/// Seed 001's Fig. 9: under the arcade's gallery the sun's first bounce lies in stripes
/// between the pillars' shadows and the second bounce fills the gaps. Clustered together,
/// the clusters straddle the shadows and their polygons spread the first bounce's power over
/// them; clustered per bounce, the gaps split the first bounce's clusters. So per bounce is
/// the more accurate, over the whole scene and under the roof, for every seed.
#[test]
fn per_bounce_clustering_beats_joint_clustering_under_the_arcade() {
    let scene = scene::load("arcade", &BuiltinParams { max_edge: 0.1 }).unwrap();
    let under_roof = |p: glam::Vec3| p.z < 2.5 && p.y < 3.0;
    for seed in [0, 1, 2] {
        let error = |per_bounce| clustering_error(&scene, per_bounce, 96, 5, seed, under_roof);
        let ((separate, separate_gallery), (joint, joint_gallery)) = (error(true), error(false));
        assert!(
            separate < joint && separate_gallery < joint_gallery,
            "seed {seed}: per bounce {separate} ({separate_gallery} under the roof), \
             joint {joint} ({joint_gallery})"
        );
    }
}
