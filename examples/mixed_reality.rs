//! Mixed reality as a library call: the Stanford bunny stands on the floor of the Open3D RGB-D
//! frames (`../shared/data/rgbd/RGBD`), lit by the room's pixels as virtual area lights plus one
//! virtual point light, over the five frames with the last five fused (`--accumulate 5`).
//! Writes composite, object (RGBA) and indirect images per frame into the output folder and
//! prints each frame's pass times and the flicker at the bunny's sparse points.
//!
//! `cargo run --release --example mixed_reality [-- RGBD_DIR [OUT_DIR]]`

use std::path::PathBuf;

use valgi::mixed_reality::depth_vals::DepthValSettings;
use valgi::mixed_reality::rgbd::DepthFormat;
use valgi::mixed_reality::run::{self, FrameSource, MrRequest};
use valgi::mixed_reality::session::MrSettings;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let rgbd = PathBuf::from(
        args.next()
            .unwrap_or_else(|| "../shared/data/rgbd/RGBD".into()),
    );
    let out = PathBuf::from(args.next().unwrap_or_else(|| "out/mixed_reality".into()));
    let request = MrRequest {
        source: FrameSource::Folder(rgbd),
        format: DepthFormat::parse("primesense")?,
        // PrimeSense intrinsics and the folder's trajectory.log.
        intrinsics: None,
        trajectory: None,
        frames: 0..5,
        object: "bunny".into(),
        // On the horizontal surface nearest the lower middle of the first frame: the table.
        place: None,
        yaw: 0.0,
        scale: 1.0,
        // A warm virtual point light above and in front of the table (W/sr).
        lights: vec![(
            glam::Vec3::new(-1.5, 1.2, 1.8),
            glam::Vec3::new(2.0, 1.8, 1.5),
        )],
        settings: MrSettings {
            depth: DepthValSettings {
                accumulate: 5,
                ..DepthValSettings::default()
            },
            ..MrSettings::default()
        },
        out: out.clone(),
    };
    let report = run::run(&request)?;
    for frame in report["frames"].as_array().into_iter().flatten() {
        println!(
            "frame {}: {} VALs, passes {}",
            frame["frame"], frame["real_and_rsm_vals"], frame["passes_ms"]
        );
    }
    println!(
        "flicker at the bunny's sparse points over the frames: {}",
        report["point_flicker"]
    );
    println!("images in {}", out.display());
    Ok(())
}
