//! The atlas on the GPU: the lookup pass against its CPU twin, no black texel in view, and an
//! atlas baked for another scene rejected.

mod common;

use std::sync::atomic::AtomicBool;

use glam::{Vec2, Vec3, Vec4Swizzles};
use valgi::atlas::bake::sample_bilinear;
use valgi::atlas::{bake, AtlasMethod, BakeSettings};
use valgi::method::{Method, MethodOptions};
use valgi::raster::RenderSettings;
use valgi::scene::{self, builtin::BuiltinParams, Scene};

fn no_progress(_: &str, _: usize, _: usize) {}

fn bake_to(
    scene: &Scene,
    settings: &BakeSettings,
    name: &str,
) -> (valgi::atlas::Bake, std::path::PathBuf) {
    let result = bake(
        scene,
        &scene.world_from_node(),
        settings,
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let path = common::temp_dir("atlas-render").join(format!("{name}.exr"));
    valgi::atlas::bake::write_atlas_exr(&result.atlas(1, settings.bounces), &path).unwrap();
    (result, path)
}

fn method(
    ctx: &valgi::gpu::GpuContext,
    scene: &Scene,
    size: u32,
    atlas: &std::path::Path,
) -> Result<AtlasMethod, valgi::raster::RenderError> {
    let mut options = MethodOptions::default();
    options.set("atlas", atlas.display());
    AtlasMethod::new(
        ctx,
        scene,
        RenderSettings {
            width: size,
            height: size,
            ..Default::default()
        },
        &options,
    )
}

/// Every pixel of box-point's indirect image equals ρ_d/π times the CPU bilinear lookup of the
/// atlas at the light-map UV of the surface point the pixel sees (found by ray casting).
#[test]
fn gpu_lookup_matches_the_cpu_twin() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("box-point", &BuiltinParams { max_edge: 0.25 }).unwrap();
    let settings = BakeSettings {
        vpls: 200,
        bounces: 2,
        atlas_res: 64,
        ..Default::default()
    };
    let (result, path) = bake_to(&scene, &settings, "box");
    let atlas = result.atlas(1, 2);
    let size = 48;
    let mut m = method(&ctx, &scene, size, &path).unwrap();
    let wfn = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &wfn).unwrap();
    let frame = m.render(&ctx, &scene, &wfn, &camera).unwrap();
    let tan = (camera.yfov * 0.5).tan();
    let eye = camera.position();
    let mut checked = 0;
    let mut bad = 0;
    for y in 0..size {
        for x in 0..size {
            let ndc = Vec2::new(
                (x as f32 + 0.5) / size as f32 * 2.0 - 1.0,
                1.0 - (y as f32 + 0.5) / size as f32 * 2.0,
            );
            let dir_view = Vec3::new(ndc.x * tan * camera.aspect, ndc.y * tan, -1.0);
            let dir = (camera.world_from_view * dir_view.extend(0.0))
                .xyz()
                .normalize();
            // Inside the box [-1, 1]³: the nearest wall along the ray.
            let t = (0..3)
                .filter(|&k| dir[k].abs() > 1e-6)
                .map(|k| (dir[k].signum() - eye[k]) / dir[k])
                .fold(f32::INFINITY, f32::min);
            let p = eye + dir * t;
            // Light-map UV at p: the layout triangle containing it.
            let mut uv = None;
            for cm in &result.layout.meshes {
                for tri in cm.indices.chunks_exact(3) {
                    let [a, b, c] = [0, 1, 2].map(|k| cm.world_positions[tri[k] as usize]);
                    let n = (b - a).cross(c - a);
                    if n.length() < 1e-12 || n.normalize().dot(p - a).abs() > 1e-4 {
                        continue;
                    }
                    let area = n.length_squared();
                    let w1 = (p - a).cross(c - a).dot(n) / area;
                    let w2 = (b - a).cross(p - a).dot(n) / area;
                    let w0 = 1.0 - w1 - w2;
                    if w0.min(w1).min(w2) >= -1e-5 {
                        let [ua, ub, uc] = [0, 1, 2].map(|k| cm.uvs[tri[k] as usize]);
                        uv = Some(ua * w0 + ub * w1 + uc * w2);
                    }
                }
            }
            let Some(uv) = uv else { continue };
            let e = sample_bilinear(&atlas, uv);
            let expected = 0.5 / std::f32::consts::PI * e[1];
            let got = frame.indirect.get(x, y)[1];
            checked += 1;
            if (got - expected).abs() > 0.02 * expected + 1e-6 {
                bad += 1;
            }
        }
    }
    eprintln!("{checked} pixels checked, {bad} off by more than 2 %");
    assert!(checked > size as usize * size as usize * 9 / 10);
    // Pixels on a wall edge may pick the other wall's triangle: allow a thin line of them.
    assert!(
        bad * 50 < checked,
        "{bad} of {checked} pixels differ from the CPU lookup"
    );
}

/// The atlas-only view of the Cornell box through its camera has no black surface pixel: every
/// texel a pixel samples holds light (texel coverage plus dilation across chart borders).
#[test]
fn no_black_texels_in_view_on_cornell() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let settings = BakeSettings {
        vpls: 300,
        bounces: 2,
        atlas_res: 128,
        ..Default::default()
    };
    let (_, path) = bake_to(&scene, &settings, "cornell");
    let size = 128;
    let mut m = method(&ctx, &scene, size, &path).unwrap();
    let frame = common::assert_no_black_texels_in_view(&ctx, &scene, &mut m, size);
    // Regression guard on the whole pipeline (bake + lookup), tone-mapped at +2 stops.
    common::assert_matches_reference("atlas_cornell_indirect", &frame.indirect, 2.0, 0.05);
}

#[test]
fn an_atlas_for_another_scene_is_rejected() {
    let Some(ctx) = common::gpu() else { return };
    let small = scene::load("box-point", &BuiltinParams { max_edge: 0.25 }).unwrap();
    let (_, path) = bake_to(
        &small,
        &BakeSettings {
            vpls: 50,
            bounces: 1,
            atlas_res: 64,
            ..Default::default()
        },
        "other",
    );
    let cornell = scene::load("cornell", &BuiltinParams::default()).unwrap();
    let err = method(&ctx, &cornell, 32, &path).err().unwrap().to_string();
    assert!(err.contains("does not match"), "{err}");
    let err = method(
        &ctx,
        &cornell,
        32,
        std::path::Path::new("/nonexistent/a.exr"),
    )
    .err()
    .unwrap()
    .to_string();
    assert!(err.contains("--atlas"), "{err}");
}

/// The atlas's Rust mirrors of WGSL structs have the layout naga reflects.
#[test]
fn atlas_structs_match_naga_layout() {
    for layout in valgi::atlas::shared_layouts() {
        let module = valgi::shaders::validate(layout.file).unwrap_or_else(|e| panic!("{e}"));
        let ty = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(layout.wgsl_name))
            .unwrap_or_else(|| panic!("struct {} not found", layout.wgsl_name))
            .1;
        let naga::TypeInner::Struct { members, span } = &ty.inner else {
            panic!("{} is not a struct", layout.wgsl_name);
        };
        assert_eq!(*span as usize, layout.size, "{}", layout.wgsl_name);
        assert_eq!(members.len(), layout.fields.len(), "{}", layout.wgsl_name);
        for (member, (name, offset)) in members.iter().zip(&layout.fields) {
            assert_eq!(member.name.as_deref(), Some(*name));
            assert_eq!(
                member.offset as usize, *offset,
                "{}.{name}",
                layout.wgsl_name
            );
        }
    }
}
