//! The Stanford bunny on the floor of the Open3D living-room frames (five PrimeSense frames
//! with their trajectory), lit by the room's pixels as virtual area lights and by one virtual
//! point light, composited into the photos with its shadow and bounce on the real floor.
//! Writes composite, object (RGBA) and indirect images per frame into `out/mixed-reality/`
//! and prints the JSON report (per-pass times, VAL counts, the flicker of the light on the
//! bunny across the frames).
//!
//! cargo run --release --example mixed_reality [-- --accumulate]

use std::path::Path;

use glam::Vec3;
use valgi::mixed_reality::depth_vals::DepthValSettings;
use valgi::mixed_reality::rgbd::DepthFormat;
use valgi::mixed_reality::run::{self, FrameSource, MrRequest};
use valgi::mixed_reality::session::MrSettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let data = Path::new("../shared/data/rgbd");
    let accumulate = std::env::args().any(|a| a == "--accumulate");
    let request = MrRequest {
        source: FrameSource::Folder(data.join("RGBD")),
        format: DepthFormat::PrimeSense,
        intrinsics: Some(data.join("camera_primesense.json")),
        trajectory: None,
        frames: 0..5,
        object: "bunny".into(),
        // On the floor in front of the rocking chair, 2.5× the scanned size (≈ 40 cm).
        place: None,
        yaw: 0.0,
        scale: 2.5,
        lights: vec![(Vec3::new(-1.5, 1.2, 2.0), Vec3::splat(1.5))],
        settings: MrSettings {
            depth: DepthValSettings {
                accumulate: if accumulate { 5 } else { 1 },
                ..Default::default()
            },
            ..Default::default()
        },
        out: "out/mixed-reality".into(),
    };
    println!("{}", run::run(&request)?);
    Ok(())
}
