//! The atlas against the path tracer, and `sparse+atlas` (VAL bounce 1 + atlas bounces 2..B):
//! exact composition, closer to the B-bounce reference than `sparse` alone without exceeding
//! it (no bounce counted twice), the atlas within a measured FLIP of the B-bounce reference,
//! and no black texel in view on `corridor`.

mod common;

use std::sync::atomic::AtomicBool;

use valgi::atlas::{bake, AtlasMethod, BakeSettings};
use valgi::eval::metrics;
use valgi::gpu::GpuContext;
use valgi::image_io::Image;
use valgi::method::{self, MethodOptions};
use valgi::raster::RenderSettings;
use valgi::reference::{self, Bounces, ReferenceSettings};
use valgi::scene::{self, builtin::BuiltinParams, Scene};

fn no_progress(_: &str, _: usize, _: usize) {}

/// Output size of every image here.
const SIZE: u32 = 64;
/// Bounces of the bake and of the reference.
const BOUNCES: u32 = 4;

/// Bakes `scene` once and writes bounces `from..=BOUNCES` to one EXR per `from`.
fn bake_files(scene: &Scene, settings: &BakeSettings, name: &str, from: &[u32]) -> Vec<String> {
    let result = bake(
        scene,
        &scene.world_from_node(),
        settings,
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let dir = common::temp_dir("atlas-compose");
    from.iter()
        .map(|&f| {
            let path = dir.join(format!("{name}-from{f}.exr"));
            valgi::atlas::bake::write_atlas_exr(
                &result.atlas(f, settings.bounces),
                &path,
                f..=settings.bounces,
            )
            .unwrap();
            path.display().to_string()
        })
        .collect()
}

fn render_settings() -> RenderSettings {
    RenderSettings {
        width: SIZE,
        height: SIZE,
        ..Default::default()
    }
}

/// The indirect image of `spec` (`name[:key=value,...]`) through the scene's camera.
fn indirect(ctx: &GpuContext, scene: &Scene, spec: &str) -> Image {
    let (name, options) = MethodOptions::parse_spec(spec).unwrap();
    let mut m = method::create(&name, ctx, scene, render_settings(), &options).unwrap();
    let wfn = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &wfn).unwrap();
    let mut frame = m.render(ctx, scene, &wfn, &camera).unwrap();
    frame.indirect.sanitize();
    frame.indirect
}

/// The path tracer's indirect image with `bounces` bounces.
fn reference_indirect(scene: &Scene, bounces: u32, spp: u32, seed: u64) -> Image {
    let wfn = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &wfn).unwrap();
    reference::render(
        scene,
        &wfn,
        &camera,
        &ReferenceSettings {
            width: SIZE,
            height: SIZE,
            spp,
            bounces: Bounces::Limited(bounces),
            seed,
            progress: false,
            specular: true,
        },
    )
    .indirect
}

fn cornell_bake() -> BakeSettings {
    BakeSettings {
        vpls: 400,
        bounces: BOUNCES,
        atlas_res: 128,
        ..Default::default()
    }
}

/// `sparse+atlas` = `sparse` + `atlas` (with the same from-bounce-2 file) pixel for pixel:
/// the composition adds the two layers and changes nothing else; and the spec with '+' in the
/// name parses as the harness passes it.
#[test]
fn sparse_plus_atlas_is_the_sum_of_its_layers() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let files = bake_files(
        &scene,
        &BakeSettings {
            vpls: 200,
            bounces: 3,
            atlas_res: 64,
            ..Default::default()
        },
        "sum",
        &[2],
    );
    let spec = format!("sparse+atlas:atlas={},rsm=64", files[0]);
    let (name, options) = MethodOptions::parse_spec(&spec).unwrap();
    assert_eq!(name, "sparse+atlas");
    let m = method::create(&name, &ctx, &scene, render_settings(), &options).unwrap();
    assert_eq!(m.name(), "sparse+atlas");
    let both = indirect(&ctx, &scene, &spec);
    let vals = indirect(&ctx, &scene, "sparse:rsm=64");
    let atlas = indirect(&ctx, &scene, &format!("atlas:atlas={}", files[0]));
    let mut worst = 0.0f32;
    for ((b, v), a) in both.pixels.iter().zip(&vals.pixels).zip(&atlas.pixels) {
        for c in 0..3 {
            let expected = v[c] + a[c];
            worst = worst.max((b[c] - expected).abs() / (expected.abs() + 1e-3));
        }
    }
    eprintln!("largest relative difference {worst:.2e}");
    assert!(
        worst < 1e-4,
        "sparse+atlas differs from sparse + atlas by {worst}"
    );
    assert!(atlas.mean_rgb()[0] > 0.0 && vals.mean_rgb()[0] > 0.0);
    // A missing file is an error naming it (no `atlas` option at all bakes one in memory).
    let mut missing = MethodOptions::default();
    missing.set("atlas", "/tmp/valgi-no-such-atlas.exr");
    let err = method::create("sparse+atlas", &ctx, &scene, render_settings(), &missing)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("--atlas") && err.contains("valgi-no-such-atlas.exr"),
        "{err}"
    );
}

/// On `cornell`, against the 4-bounce reference: `sparse+atlas` (bounce 1 from the VALs,
/// 2..4 from an atlas baked with --from-bounce 2) is much closer than `sparse` (bounce 1 only)
/// and its mean does not exceed the reference's. The negative control adds the full atlas
/// (bounces 1..4) to the VAL bounce, counting bounce 1 twice; that mean clearly exceeds the
/// reference, so the mean check does catch double counting. Measured (64×64, 256 spp): mean
/// luminance reference 0.1653, sparse 0.0926, sparse+atlas 0.1685 (+1.9 %), double-counted
/// 0.2596; RMSE sparse 0.117, sparse+atlas 0.033. The +1.9 % is the two layers' own small
/// biases, not a bounce counted twice: against the 1-bounce reference (0.0906) `sparse` is
/// +2.2 %, and the atlas's bounces 2..4 (≈0.076) are ≈+1.7 % against the reference's (0.0747).
#[test]
fn sparse_plus_atlas_approaches_the_b_bounce_reference_without_double_counting() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let files = bake_files(&scene, &cornell_bake(), "cornell", &[1, 2]);
    let reference = reference_indirect(&scene, BOUNCES, 256, 7);
    let sparse = indirect(&ctx, &scene, "sparse");
    let composed = indirect(&ctx, &scene, &format!("sparse+atlas:atlas={}", files[1]));
    let full_atlas = indirect(&ctx, &scene, &format!("atlas:atlas={}", files[0]));
    let mean = |i: &Image| metrics::mean_luminance(i);
    let (m_ref, m_sparse, m_comp) = (mean(&reference), mean(&sparse), mean(&composed));
    let m_double = m_sparse + mean(&full_atlas);
    let (e_sparse, e_comp) = (
        metrics::rmse(&sparse, &reference),
        metrics::rmse(&composed, &reference),
    );
    eprintln!(
        "mean luminance: reference {m_ref:.4}, sparse {m_sparse:.4}, sparse+atlas {m_comp:.4}, \
         double-counted {m_double:.4}; RMSE sparse {e_sparse:.4}, sparse+atlas {e_comp:.4}"
    );
    assert!(
        e_comp < 0.6 * e_sparse,
        "sparse+atlas RMSE {e_comp} not well below sparse's {e_sparse}"
    );
    // 2 % above the mean allows for the 256-spp reference's noise in the mean (< 0.5 %).
    assert!(
        m_comp <= 1.02 * m_ref,
        "sparse+atlas mean {m_comp} exceeds the reference's {m_ref}"
    );
    assert!(m_comp > m_sparse, "the atlas added nothing");
    assert!(
        m_double > 1.1 * m_ref,
        "negative control: double counting should exceed the reference ({m_double} vs {m_ref})"
    );
}

/// The atlas's indirect image (all 4 bounces, 400 VPLs, 128² texels) against the 4-bounce
/// reference's indirect image (512 spp), by mean FLIP at the reference's automatic exposure,
/// 64×64 pixels.
///
/// Measured (lavapipe, this commit): atlas 0.079 (0.117 before the near-field gather and the
/// ray-confirmed visibility); noise floor (a second 512-spp reference with another seed)
/// 0.054; the same atlas scaled ×1.25 0.292 and ×0.8 0.247; one bounce where four are expected
/// 0.52. The threshold 0.10 leaves the atlas ~30 % headroom (VPL and seed changes move it by a
/// few hundredths) and sits well below a ±20 % error in the level of indirect light, the
/// smallest plainly wrong answer here; the controls are asserted too, so the threshold keeps
/// meaning something if the metric or the sizes change.
#[test]
fn cornell_atlas_matches_the_b_bounce_reference_within_flip() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let files = bake_files(&scene, &cornell_bake(), "cornell-flip", &[1]);
    let reference = reference_indirect(&scene, BOUNCES, 512, 11);
    let exposure = metrics::auto_exposure(&reference);
    let atlas = indirect(&ctx, &scene, &format!("atlas:atlas={}", files[0]));
    let flip = metrics::flip(&atlas, &reference, exposure);
    // Noise floor: another reference with the same settings and another seed.
    let other = reference_indirect(&scene, BOUNCES, 512, 12);
    let noise = metrics::flip(&other, &reference, exposure);
    // Wrong answers: one bounce where four are expected; the atlas 25 % too bright or dark.
    let one_bounce = reference_indirect(&scene, 1, 512, 13);
    let flip_one = metrics::flip(&one_bounce, &reference, exposure);
    let scaled = |k: f32| {
        let mut image = atlas.clone();
        for p in &mut image.pixels {
            for c in p.iter_mut().take(3) {
                *c *= k;
            }
        }
        metrics::flip(&image, &reference, exposure)
    };
    let (bright, dark) = (scaled(1.25), scaled(0.8));
    eprintln!(
        "indirect FLIP against the {BOUNCES}-bounce reference: atlas {flip:.4}, noise floor \
         {noise:.4}, atlas ×1.25 {bright:.4}, ×0.8 {dark:.4}, one bounce only {flip_one:.4}"
    );
    assert!(
        flip < FLIP_THRESHOLD,
        "atlas FLIP {flip} ≥ {FLIP_THRESHOLD}"
    );
    assert!(noise < FLIP_THRESHOLD, "noise floor {noise}");
    for (what, f) in [("×1.25", bright), ("×0.8", dark), ("one bounce", flip_one)] {
        assert!(f > FLIP_THRESHOLD, "control {what} passes: {f}");
    }
}

/// See `cornell_atlas_matches_the_b_bounce_reference_within_flip`.
const FLIP_THRESHOLD: f64 = 0.10;

/// The atlas-only view of `corridor` (two rooms, the second lit only by bounces) has no black
/// surface pixel.
#[test]
fn no_black_texels_in_view_on_corridor() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("corridor", &BuiltinParams::default()).unwrap();
    let files = bake_files(
        &scene,
        &BakeSettings {
            vpls: 300,
            bounces: 2,
            atlas_res: 256,
            ..Default::default()
        },
        "corridor",
        &[1],
    );
    let size = 128;
    let mut options = MethodOptions::default();
    options.set("atlas", &files[0]);
    let mut m = AtlasMethod::new(
        &ctx,
        &scene,
        RenderSettings {
            width: size,
            height: size,
            ..Default::default()
        },
        &options,
    )
    .unwrap();
    common::assert_no_black_texels_in_view(&ctx, &scene, &mut m, size);
}

/// Zero-thickness sheets get charts for both faces: on `corridor` the partition and the door
/// are sheets (nothing else), on `cornell` nothing is; and the corridor's atlas no longer
/// carries the lit room's light through the partition into the dark room (before the back
/// faces had their own texels its mean indirect luminance was 2.2× the reference's).
#[test]
fn corridor_sheets_have_two_faces_and_do_not_leak() {
    let names = |scene: &Scene| -> Vec<String> {
        let layout = valgi::atlas::layout::layout(scene, &scene.world_from_node(), 128).unwrap();
        let mut names: Vec<String> = layout
            .meshes
            .iter()
            .filter(|m| m.sheet_face)
            .map(|m| scene.meshes[scene.instances[m.instance].mesh].name.clone())
            .collect();
        names.sort();
        names
    };
    let cornell = scene::load("cornell", &BuiltinParams::default()).unwrap();
    assert!(names(&cornell).is_empty(), "{:?}", names(&cornell));
    let scene = scene::load("corridor", &BuiltinParams::default()).unwrap();
    assert_eq!(
        names(&scene),
        ["door", "door", "partition", "partition"],
        "both faces of the door and the partition"
    );

    let Some(ctx) = common::gpu() else { return };
    let bounces = 2;
    let files = bake_files(
        &scene,
        &BakeSettings {
            vpls: 400,
            bounces,
            atlas_res: 256,
            ..Default::default()
        },
        "corridor-leak",
        &[1],
    );
    let atlas = indirect(&ctx, &scene, &format!("atlas:atlas={}", files[0]));
    let reference = reference_indirect(&scene, bounces, 128, 21);
    let ratio = metrics::mean_luminance(&atlas) / metrics::mean_luminance(&reference);
    let flip = metrics::flip(&atlas, &reference, metrics::auto_exposure(&reference));
    eprintln!("corridor, {bounces} bounces: mean ratio {ratio:.3}, indirect FLIP {flip:.4}");
    assert!((0.75..1.25).contains(&ratio), "mean ratio {ratio}");
}
