//! The atlas on the GPU: the lookup pass against its CPU twin, no black texel in view, and an
//! atlas baked for another scene rejected.

mod common;

use std::sync::atomic::AtomicBool;

use glam::{Vec2, Vec3, Vec4Swizzles};
use valgi::atlas::cuts::{lookup, ContactCuts};
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
    valgi::atlas::bake::write_atlas_exr(
        &result.atlas(1, settings.bounces),
        &path,
        1..=settings.bounces,
    )
    .unwrap();
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

/// Light-map UV of the surface point a camera ray sees: the path tracer's hit, then the layout
/// triangle that contains it (for a sheet's two faces, the one facing the ray, as the lookup
/// culls back faces).
fn uv_seen(
    layout: &valgi::atlas::layout::AtlasLayout,
    tracer: &valgi::reference::Tracer,
    eye: Vec3,
    dir: Vec3,
) -> Option<Vec2> {
    let p = tracer.intersect(eye, dir, 1e4)?.position;
    for cm in &layout.meshes {
        for tri in cm.indices.chunks_exact(3) {
            let [a, b, c] = [0, 1, 2].map(|k| cm.world_positions[tri[k] as usize]);
            let (lo, hi) = (a.min(b).min(c), a.max(b).max(c));
            if (p.cmplt(lo - 1e-4)).any() || (p.cmpgt(hi + 1e-4)).any() {
                continue;
            }
            let n = (b - a).cross(c - a);
            if n.length() < 1e-12 || n.normalize().dot(p - a).abs() > 1e-4 {
                continue;
            }
            if cm.sheet_face && n.dot(dir) > 0.0 {
                continue;
            }
            let area = n.length_squared();
            let w1 = (p - a).cross(c - a).dot(n) / area;
            let w2 = (b - a).cross(p - a).dot(n) / area;
            let w0 = 1.0 - w1 - w2;
            if w0.min(w1).min(w2) >= -1e-5 {
                let [ua, ub, uc] = [0, 1, 2].map(|k| cm.uvs[tri[k] as usize]);
                return Some(ua * w0 + ub * w1 + uc * w2);
            }
        }
    }
    None
}

/// Per pixel: the GPU lookup's irradiance, the CPU twin's at the UV the pixel sees (with the
/// layout's cuts, and without them), and the indirect radiance the method wrote. Pixels whose
/// surface has no UV are skipped.
fn gpu_and_cpu_lookups(
    ctx: &valgi::gpu::GpuContext,
    scene: &Scene,
    result: &valgi::atlas::Bake,
    atlas_file: &std::path::Path,
    size: u32,
) -> Vec<(f32, f32, f32, f32)> {
    let atlas = result.atlas(1, result.settings.bounces);
    let mut m = method(ctx, scene, size, atlas_file).unwrap();
    let wfn = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &wfn).unwrap();
    let frame = m.render(ctx, scene, &wfn, &camera).unwrap();
    let gpu = m.layer().read_irradiance(ctx).unwrap();
    let tracer = valgi::reference::Tracer::new(scene, &wfn);
    let no_cuts = ContactCuts::default();
    let tan = (camera.yfov * 0.5).tan();
    let mut out = Vec::new();
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
            let Some(uv) = uv_seen(&result.layout, &tracer, camera.position(), dir) else {
                continue;
            };
            out.push((
                gpu.get(x, y)[1],
                lookup(&atlas, &result.layout.cuts, uv)[1],
                lookup(&atlas, &no_cuts, uv)[1],
                frame.indirect.get(x, y)[1],
            ));
        }
    }
    out
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 0.02 * b.abs() + 1e-6
}

/// Every pixel of box-point's atlas irradiance equals the CPU lookup of the atlas at the
/// light-map UV of the surface point the pixel sees (found by ray casting), and its indirect
/// radiance is ρ_d/π times that (ρ_d = 0.5). A closed box has no contact cuts: the lookup is
/// plain bilinear.
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
    assert!(result.layout.cuts.texels.is_empty());
    let size = 48;
    let pixels = gpu_and_cpu_lookups(&ctx, &scene, &result, &path, size);
    let bad = pixels.iter().filter(|p| !close(p.0, p.1)).count();
    eprintln!(
        "{} pixels checked, {bad} off by more than 2 %",
        pixels.len()
    );
    let radiance_off = pixels
        .iter()
        .filter(|p| !close(p.3, 0.5 / std::f32::consts::PI * p.0))
        .count();
    assert_eq!(radiance_off, 0);
    assert!(pixels.len() > size as usize * size as usize * 9 / 10);
    // Pixels on a wall edge may pick the other wall's triangle: allow a thin line of them.
    assert!(
        bad * 50 < pixels.len(),
        "{bad} of {} pixels differ from the CPU lookup",
        pixels.len()
    );
}

/// The corridor's partition stands on the floor and meets the walls and the ceiling: the
/// layout cuts the texels along those lines, and the GPU lookup (which leaves out taps across
/// a cut) equals the CPU twin with cuts, also on the pixels where the cuts change the result.
#[test]
fn gpu_lookup_matches_the_cpu_twin_across_contact_cuts() {
    let Some(ctx) = common::gpu() else { return };
    let scene = scene::load("corridor", &BuiltinParams { max_edge: 0.1 }).unwrap();
    let settings = BakeSettings {
        vpls: 200,
        bounces: 2,
        atlas_res: 128,
        near_rays: 16,
        ..Default::default()
    };
    let (result, path) = bake_to(&scene, &settings, "corridor");
    let cuts = &result.layout.cuts;
    // The partition's foot on the floor runs along x = 2.1 on both sides of the doorway.
    let floor_cut = result
        .layout
        .texels
        .iter()
        .filter(|t| t.normal.y > 0.9 && (t.position.x - 2.1).abs() < 0.08)
        .filter(|t| cuts.texels.contains_key(&t.index))
        .count();
    eprintln!(
        "{} cut texels ({} contact segments); {floor_cut} along the partition's foot",
        cuts.texels.len(),
        cuts.segments
    );
    assert!(floor_cut >= 10 && cuts.dropped == 0);
    let size = 64;
    let pixels = gpu_and_cpu_lookups(&ctx, &scene, &result, &path, size);
    let bad = pixels.iter().filter(|p| !close(p.0, p.1)).count();
    let changed: Vec<_> = pixels.iter().filter(|p| !close(p.1, p.2)).collect();
    let changed_bad = changed.iter().filter(|p| !close(p.0, p.1)).count();
    eprintln!(
        "{} pixels checked, {bad} off by more than 2 %; cuts change {} of them ({changed_bad} off)",
        pixels.len(),
        changed.len()
    );
    assert!(pixels.len() > size as usize * size as usize * 9 / 10);
    assert!(
        changed.len() >= 10,
        "the cuts change only {} pixels",
        changed.len()
    );
    assert!(bad * 50 < pixels.len(), "{bad} of {} pixels", pixels.len());
    assert!(
        changed_bad * 5 < changed.len(),
        "{changed_bad} of {}",
        changed.len()
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
