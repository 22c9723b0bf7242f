//! Rendered images against stored references (mean FLIP on the documented tone map): they
//! catch regressions that the analytic tests cannot see, such as texture, normal-map or
//! shadow-filter changes. The threshold allows for rasterization differences between drivers
//! (a few pixels along edges), not for changes in shading: a wrong albedo, a missing normal
//! map or a shadow moved by a texel across the image raises mean FLIP well above it.

mod common;

use glam::{Quat, Vec3};
use valgi::raster::{Rasterizer, RenderSettings};
use valgi::scene::builtin::{self, BuiltinParams};
use valgi::scene::{Light, LightKind, Node, Scene, Trs};

const MAX_MEAN_FLIP: f32 = 0.02;

fn render(scene: &Scene) -> Option<valgi::image_io::Image> {
    let ctx = common::gpu()?;
    let settings = RenderSettings {
        width: 128,
        height: 128,
        ssaa: 2,
        shadow_resolution: 512,
        ..RenderSettings::default()
    };
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).expect("camera");
    let raster = Rasterizer::new(&ctx, scene, settings).expect("rasterizer");
    let frame = raster
        .render_direct(&ctx, scene, &world, &camera)
        .expect("render");
    Some(frame.radiance(false))
}

#[test]
fn cornell_direct_matches_reference() {
    let scene = builtin::load("cornell", &BuiltinParams::default()).unwrap();
    if let Some(image) = render(&scene) {
        common::assert_matches_reference("cornell_direct", &image, 0.0, MAX_MEAN_FLIP);
    }
}

/// Textures (sRGB base colour, metallic-roughness, emissive), the normal map and the glossy
/// lobe of a textured PBR model under a point light.
#[test]
fn damaged_helmet_under_a_point_light_matches_reference() {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/gltf-samples/DamagedHelmet/DamagedHelmet.glb");
    if !path.exists() {
        assert!(
            std::env::var("CI").is_err(),
            "{} missing under CI",
            path.display()
        );
        eprintln!("SKIPPED: {} not present", path.display());
        return;
    }
    let mut scene = valgi::scene::gltf_import::load(&path).unwrap();
    scene.nodes.push(Node {
        name: "key light".into(),
        parent: None,
        local: Trs {
            translation: Vec3::new(1.0, 1.5, 2.5),
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        },
    });
    scene.lights.push(Light {
        name: "key".into(),
        node: scene.nodes.len() - 1,
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity: 100.0,
        range: None,
    });
    if let Some(image) = render(&scene) {
        common::assert_matches_reference("damaged_helmet_point", &image, 0.0, MAX_MEAN_FLIP);
    }
}
