//! Long runs stay flat: every method renders 300 animated frames at 16² and neither the
//! process's resident set (its floor, from third to third of the run after warm-up) nor the GPU bytes the
//! method owns may grow after warm-up. The
//! sparse method once grew ~1.8 MB a frame here (a software driver specialised its kernels
//! on per-frame uniform values and kept every variant).

mod common;

use std::sync::atomic::AtomicBool;

use valgi::app::{self, RenderRequest};
use valgi::atlas::{bake, BakeSettings};
use valgi::frame::ViewRig;
use valgi::method::MethodOptions;
use valgi::scene::{self, builtin::BuiltinParams};

const FRAMES: u32 = 300;
const WARMUP: u32 = 100;
const SAMPLE_EVERY: u32 = 20;
/// Resident growth allowed from each third of the run after warm-up to the next, floor to
/// floor, as a fraction of the resident set (`frame::memory::sustained_resident_growth`). A
/// leak lifts every floor; an allocator arena or a driver pool that steps up once lifts one,
/// and a transient peak (seen here at +1.9% and +2.6% in single runs) lifts none. A leak of
/// 20 kB a frame lifts the ~130 MB set's floor about 1% per 67-frame third.
const RESIDENT_SLACK_PER_THIRD: f64 = 0.005;

fn atlas_for(scene_name: &str, from_bounce: u32) -> std::path::PathBuf {
    let scene = scene::load(scene_name, &BuiltinParams::default()).unwrap();
    let settings = BakeSettings {
        vpls: 60,
        bounces: 2,
        atlas_res: 64,
        ..BakeSettings::default()
    };
    let result = bake(
        &scene,
        &scene.world_from_node(),
        &settings,
        &|_: &str, _: usize, _: usize| {},
        &AtomicBool::new(false),
    )
    .unwrap();
    let path = common::temp_dir("soak").join(format!("{scene_name}-{from_bounce}.exr"));
    valgi::atlas::bake::write_atlas_exr(
        &result.atlas(from_bounce, settings.bounces),
        &path,
        from_bounce..=settings.bounces,
    )
    .unwrap();
    path
}

/// A method, its options and the views of each frame.
type Run<'a> = (&'a str, Vec<(&'a str, &'a str)>, ViewRig);

#[test]
fn no_method_grows_over_a_long_run() {
    if common::gpu().is_none() {
        return;
    }
    let scene_name = "cornell-moving";
    let atlas = atlas_for(scene_name, 1);
    let later_bounces = atlas_for(scene_name, 2);
    let atlas = atlas.display().to_string();
    let later_bounces = later_bounces.display().to_string();
    let runs: Vec<Run> = vec![
        ("direct", vec![], ViewRig::Mono),
        (
            "sparse",
            vec![("rsm", "16"), ("sparse-points", "256")],
            ViewRig::Mono,
        ),
        (
            "sparse",
            vec![
                ("rsm", "16"),
                ("sparse-points", "256"),
                ("glossy-eye", "per-view"),
            ],
            ViewRig::Stereo { ipd: 0.064 },
        ),
        ("brute", vec![("rsm", "16")], ViewRig::Mono),
        ("lpv", vec![("rsm", "16"), ("grid", "8")], ViewRig::Mono),
        ("holpv", vec![("rsm", "16"), ("grid", "8")], ViewRig::Mono),
        ("atlas", vec![("atlas", &atlas)], ViewRig::Mono),
        (
            "sparse+atlas",
            vec![
                ("rsm", "16"),
                ("sparse-points", "256"),
                ("atlas", &later_bounces),
            ],
            ViewRig::Stereo { ipd: 0.064 },
        ),
    ];
    let mut failures = vec![];
    for (method, pairs, views) in runs {
        let mut options = MethodOptions::default();
        for (k, v) in &pairs {
            options.set(k, v);
        }
        let label = format!("{method} {} views={}", options, views.label());
        let request = RenderRequest {
            scene: scene_name.into(),
            method: method.into(),
            method_fallback: None,
            options,
            settings: common::small_render_settings(16),
            frames: Some(FRAMES),
            views,
            write_images: false,
            memory_every: SAMPLE_EVERY,
            ..RenderRequest::default()
        };
        let report = app::render(&request).unwrap_or_else(|e| panic!("{label}: {e}"));
        let samples: Vec<valgi::frame::memory::MemorySample> = report["memory"]
            .as_array()
            .expect("memory samples")
            .iter()
            .map(|s| valgi::frame::memory::MemorySample {
                frame: s["frame"].as_u64().unwrap() as u32,
                resident_bytes: s["rss_bytes"].as_u64(),
                gpu_bytes: s["gpu_bytes"].as_u64().unwrap(),
            })
            .collect();
        let growth = valgi::frame::memory::growth_after(&samples, WARMUP).expect("samples");
        assert_eq!(growth.frames, FRAMES - WARMUP, "{label}");
        let fraction = growth.resident_fraction.expect("Linux reports VmRSS");
        let sustained = valgi::frame::memory::sustained_resident_growth(&samples, WARMUP)
            .expect("resident samples in all three thirds");
        eprintln!(
            "{label}: resident {:+} bytes ({:+.2}%, floors {:+.2}% a third), gpu {:+} bytes over \
             frames {WARMUP}..{FRAMES}",
            growth.resident_bytes.unwrap_or(0),
            fraction * 100.0,
            sustained * 100.0,
            growth.gpu_bytes
        );
        if sustained > RESIDENT_SLACK_PER_THIRD || growth.gpu_bytes != 0 {
            failures.push(format!(
                "{label}: resident {:+.2}% (floors {:+.2}% a third), gpu {:+} bytes after warm-up",
                fraction * 100.0,
                sustained * 100.0,
                growth.gpu_bytes
            ));
        }
    }
    assert!(failures.is_empty(), "memory grew:\n{}", failures.join("\n"));
}
