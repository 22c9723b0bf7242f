//! Mixed reality: RGB-D decoding of the four sensor layouts with their documented median
//! depths, clear errors for bad frames, and the depth → VAL kernels against their CPU twins.

mod common;

use std::path::{Path, PathBuf};

use valgi::mixed_reality::rgbd::{self, DepthFormat, DepthRange, Intrinsics, RgbdError, RgbdFrame};

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/rgbd")
}

fn read(color: &str, depth: &str, format: DepthFormat) -> RgbdFrame {
    let d = data().join("RGBD");
    RgbdFrame::read(
        &d.join(color),
        &d.join(depth),
        format,
        DepthRange::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

fn assert_median(frame: &RgbdFrame, expected: f32) {
    let median = frame.median_depth();
    eprintln!(
        "median {median} m (expected {expected}), holes {:.3}",
        frame.hole_fraction()
    );
    assert!(
        (median - expected).abs() <= 0.02 * expected,
        "median depth {median} m, expected {expected} m ±2%"
    );
    assert!(frame.depth.iter().all(|z| z.is_finite() && *z >= 0.0));
    assert!(frame.hole_fraction() < 0.5, "{}", frame.hole_fraction());
}

#[test]
fn the_four_formats_decode_to_their_median_depths() {
    let f = read(
        "color/00000.jpg",
        "depth/00000.png",
        DepthFormat::PrimeSense,
    );
    assert_eq!((f.width, f.height), (640, 480));
    assert_median(&f, 1.86);
    let o = "other_formats";
    assert_median(
        &read(
            &format!("{o}/TUM_color.png"),
            &format!("{o}/TUM_depth.png"),
            DepthFormat::Tum,
        ),
        2.42,
    );
    assert_median(
        &read(
            &format!("{o}/NYU_color.ppm"),
            &format!("{o}/NYU_depth.pgm"),
            DepthFormat::Nyu,
        ),
        3.27,
    );
    assert_median(
        &read(
            &format!("{o}/SUN_color.jpg"),
            &format!("{o}/SUN_depth.png"),
            DepthFormat::Sun,
        ),
        2.72,
    );
}

#[test]
fn a_wrong_format_does_not_give_the_documented_median() {
    // The decoders are not interchangeable: SUN read as PrimeSense is 8× off.
    let o = "other_formats";
    let f = read(
        &format!("{o}/SUN_color.jpg"),
        &format!("{o}/SUN_depth.png"),
        DepthFormat::PrimeSense,
    );
    assert!((f.median_depth() - 2.72).abs() > 0.1);
}

#[test]
fn bad_frames_are_clear_errors() {
    let d = data().join("RGBD");
    let dir = common::temp_dir("mr-errors");
    let missing = dir.join("nope.png");
    let err = RgbdFrame::read(
        &d.join("color/00000.jpg"),
        &missing,
        DepthFormat::PrimeSense,
        DepthRange::default(),
    )
    .unwrap_err();
    assert!(matches!(err, RgbdError::Read { .. }), "{err}");
    assert!(err.to_string().contains("nope.png"), "{err}");

    // Colour 640×480 against a 32×24 depth.
    let small = dir.join("small_depth.png");
    image::ImageBuffer::<image::Luma<u16>, _>::from_pixel(32, 24, image::Luma([1000u16]))
        .save(&small)
        .unwrap();
    let err = RgbdFrame::read(
        &d.join("color/00000.jpg"),
        &small,
        DepthFormat::PrimeSense,
        DepthRange::default(),
    )
    .unwrap_err();
    assert!(matches!(err, RgbdError::SizeMismatch { .. }), "{err}");
    assert!(err.to_string().contains("small_depth.png"), "{err}");

    // An 8-bit depth PNG.
    let eight = dir.join("eight_bit.png");
    image::GrayImage::from_pixel(640, 480, image::Luma([100u8]))
        .save(&eight)
        .unwrap();
    let err = RgbdFrame::read(
        &d.join("color/00000.jpg"),
        &eight,
        DepthFormat::PrimeSense,
        DepthRange::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("16-bit"), "{err}");
    assert!(err.to_string().contains("eight_bit.png"), "{err}");

    let bad_json = dir.join("camera.json");
    std::fs::write(
        &bad_json,
        r#"{"width": 640, "height": 480, "intrinsic_matrix": [1, 2]}"#,
    )
    .unwrap();
    let err = Intrinsics::read(&bad_json).unwrap_err();
    assert!(err.to_string().contains("9 numbers"), "{err}");

    let bad_log = dir.join("trajectory.log");
    std::fs::write(&bad_log, "0 0 1\n1 0 0 0\n0 1 0 0\n").unwrap();
    assert!(rgbd::read_poses(&bad_log).is_err());
}

#[test]
fn holes_and_out_of_range_samples_are_zero() {
    // 0 is a hole in every format; the Kinect's 2047 is a hole in NYU.
    for f in [DepthFormat::PrimeSense, DepthFormat::Tum, DepthFormat::Sun] {
        assert_eq!(f.metres(0), 0.0);
    }
    assert_eq!(DepthFormat::Nyu.metres(2047u16.swap_bytes()), 0.0);
    assert!((DepthFormat::Sun.metres(1860u16.rotate_left(3)) - 1.86).abs() < 1e-6);
    assert!((DepthFormat::Tum.metres(12100) - 2.42).abs() < 1e-6);
}

#[test]
fn intrinsics_and_poses_read_from_the_open3d_files() {
    let k = Intrinsics::read(&data().join("camera_primesense.json")).unwrap();
    assert_eq!(k, Intrinsics::primesense_default());
    let poses = rgbd::read_poses(&data().join("RGBD/trajectory.log")).unwrap();
    assert_eq!(poses.len(), 5);
    // Row 1 of the first block: translation x = −0.3106.
    assert!((poses[0].w_axis.x + 0.31057997).abs() < 1e-5);
    assert!((poses[0].w_axis.z - 2.12648).abs() < 1e-4);
    // Rotations stay rotations.
    assert!((poses[0].determinant().abs() - 1.0).abs() < 1e-3);

    let dir = common::temp_dir("mr-tum");
    let tum = dir.join("groundtruth.txt");
    std::fs::write(
        &tum,
        "# t tx ty tz qx qy qz qw\n1.0 1 2 3 0 0 0.7071068 0.7071068\n",
    )
    .unwrap();
    let poses = rgbd::read_poses(&tum).unwrap();
    let x = poses[0].transform_vector3(glam::Vec3::X);
    assert!((x - glam::Vec3::Y).length() < 1e-5, "{x}");
    assert_eq!(poses[0].w_axis.truncate(), glam::Vec3::new(1.0, 2.0, 3.0));
}
