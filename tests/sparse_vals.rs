//! The sparse VAL method on the software Vulkan device: RSM flux conservation, GPU kernels
//! against their CPU twins (`valgi::vals::math`), exact renormalization, dark points staying
//! exactly dark, brute force against a CPU sum, glossy lobes that follow the eye, occlusion
//! behind a blocker, and the sparse image against brute force.

mod common;

use glam::{Quat, Vec3, Vec4};
use valgi::gpu::GpuContext;
use valgi::light::rsm::VAL_WINDOW;
use valgi::light::val_windows::ValReads;
use valgi::light::GlossyGather;
use valgi::method::{Method, MethodOptions};
use valgi::peers::brute::BruteMethod;
use valgi::raster::FrameOutput;
use valgi::scene::builtin::{self, BuiltinParams};
use valgi::scene::mesh::MeshBuilder;
use valgi::scene::{
    Camera, CameraView, FovAxis, Instance, Light, LightKind, Material, Node, Scene, Trs,
};
use valgi::vals::math::{self, OcclusionMode, Receiver, Weights};
use valgi::vals::sparse::{
    GatherForm, PointsReadback, SparseOptions, VisibilityLookup, RASTER_GATHER_WIDTH,
};
use valgi::vals::{SparseMethod, SparseSettings, Stage};

use common::small_render_settings as settings;

fn sparse_settings(
    rsm: u32,
    points: usize,
    occlusion: OcclusionMode,
    glossy: bool,
) -> SparseSettings {
    SparseSettings {
        rsm,
        rsm_texels: None,
        sparse_points: points,
        seed: 3,
        options: SparseOptions {
            tile: 64,
            gather: Default::default(),
            glossy: if glossy {
                GlossyGather::On
            } else {
                GlossyGather::Off
            },
            occlusion,
            weights: Weights::Geometric,
            visibility_history: 0,
            adaptive_rays: false,
            gather_slices: 0,
            gather_points: 0,
            visibility_lookup: Default::default(),
            gather_vals: ValReads::Auto,
        },
        ..Default::default()
    }
}

fn camera(scene: &Scene, size: u32) -> CameraView {
    let _ = size;
    scene
        .camera_view(None, 1.0, &scene.world_from_node())
        .expect("camera")
}

/// Renders with the sparse method up to `last` and reads the per-point buffers.
fn run_sparse(
    ctx: &GpuContext,
    scene: &Scene,
    size: u32,
    s: SparseSettings,
    last: Stage,
) -> (SparseMethod, FrameOutput, PointsReadback) {
    let mut method = SparseMethod::new(ctx, scene, settings(size), s).expect("sparse method");
    method.last_stage = last;
    let world = scene.world_from_node();
    let frame = method
        .render(ctx, scene, &world, &camera(scene, size))
        .expect("render");
    let points = method
        .sparse
        .read_points(ctx, scene, &world)
        .expect("readback");
    (method, frame, points)
}

fn close(a: Vec3, b: Vec3, rel: f32, abs: f32) -> bool {
    (a - b).abs().max_element() <= rel * a.abs().max_element().max(b.abs().max_element()) + abs
}

/// Asserts [`close`] and names `what` with both values when it fails.
fn assert_close(a: Vec3, b: Vec3, rel: f32, abs: f32, what: std::fmt::Arguments) {
    assert!(close(a, b, rel, abs), "{what}: {a} vs {b}");
}

fn cornell_coarse() -> Scene {
    builtin::load("cornell", &BuiltinParams { max_edge: 0.1 }).expect("cornell")
}

#[test]
fn rsm_of_a_point_light_in_a_closed_box_reflects_rho_times_its_power() {
    let Some(ctx) = common::gpu() else { return };
    let scene = builtin::load("box-point", &BuiltinParams { max_edge: 0.5 }).unwrap();
    let (method, frame, _) = run_sparse(
        &ctx,
        &scene,
        32,
        sparse_settings(64, 64, OcclusionMode::Off, false),
        Stage::Gather,
    );
    let vals = method.rsm.read_vals(&ctx).unwrap();
    assert_eq!(vals.len(), 6 * 64 * 64, "every cube-map texel sees a wall");
    let total: Vec3 = vals.iter().map(|v| v.flux).sum();
    // Every direction of a 1 W/sr light hits a wall of albedo 0.5: Φ = 0.5·4π·1 W. The RSM's
    // texel solid angles are a midpoint rule over the cube, good to ~1e-4 at 64².
    let expected = 0.5 * 4.0 * std::f32::consts::PI;
    assert!(
        (total.x - expected).abs() < 1e-3 * expected,
        "reflected flux {total} vs {expected}"
    );
    // A_j = Ω_j·d_j² is the footprint had the wall faced the light, so ΣA = ∫d² dΩ =
    // ∫cos θ dA = 6·∫∫_[-1,1]² (1+x²+y²)^(-1/2) dx dy over the six unit-distance faces.
    let n = 2000;
    let face: f64 = (0..n * n)
        .map(|i| {
            let x = -1.0 + (2.0 * (i % n) as f64 + 1.0) / n as f64;
            let y = -1.0 + (2.0 * (i / n) as f64 + 1.0) / n as f64;
            (1.0 + x * x + y * y).powf(-0.5) * (2.0 / n as f64).powi(2)
        })
        .sum();
    let area: f32 = vals.iter().map(|v| v.area).sum();
    let expected_area = 6.0 * face as f32;
    assert!(
        (area - expected_area).abs() < 1e-3 * expected_area,
        "VAL area {area} vs {expected_area} m²"
    );
    assert_eq!(frame.direct.non_finite_count(), 0);
}

/// The VALs of `scene`'s RSMs at `rsm` per view under `max_vals`, and the RSM's packing.
fn rsm_vals(
    ctx: &GpuContext,
    scene: &Scene,
    rsm: u32,
    max_vals: u32,
) -> (Vec<valgi::light::Val>, u32, bool) {
    let render = valgi::raster::RenderSettings {
        max_vals,
        ..settings(8)
    };
    let raster = valgi::raster::Rasterizer::new(ctx, scene, render).unwrap();
    let rsm = valgi::light::rsm::Rsm::new(ctx, scene, &raster, rsm).unwrap();
    let mut passes = valgi::gpu::Passes::new(ctx);
    rsm.prepare(ctx, scene, &scene.world_from_node());
    rsm.record(&mut passes, &raster.scene_gpu).unwrap();
    passes.finish().unwrap();
    let packed = rsm.physical_layers < rsm.layer_count;
    (rsm.read_vals(ctx).unwrap(), rsm.resolution, packed)
}

/// More point lights than the device has array layers for their cube faces: the views share
/// physical layers as tiles. All lights sit where the box's one light sits, so every view
/// must produce exactly the VALs of the same face of the lone light (a tile read or
/// rendered at a wrong offset changes texel directions, solid angles and flux), and with
/// `--max-vals` below the views' texels the side shrinks but the reflected flux stays
/// ρ·4π·I per light.
#[test]
fn rsm_views_beyond_the_array_layers_pack_into_tiles_with_the_same_vals() {
    let Some(ctx) = common::gpu() else { return };
    let single = builtin::load("box-point", &BuiltinParams { max_edge: 0.5 }).unwrap();
    let (lone, _, lone_packed) = rsm_vals(&ctx, &single, 8, u32::MAX);
    assert_eq!((lone.len(), lone_packed), (6 * 64, false));
    let lights = ctx.device.limits().max_texture_array_layers / 6 + 40;
    let mut many = single.clone();
    many.lights = vec![single.lights[0].clone(); lights as usize];
    let (vals, side, packed) = rsm_vals(&ctx, &many, 8, u32::MAX);
    assert_eq!(side, 8);
    assert!(packed, "{} views were not packed", 6 * lights);
    assert_eq!(vals.len(), lone.len() * lights as usize);
    // Rasterized at another viewport offset, interpolants may differ in the last bit.
    for (i, val) in vals.iter().enumerate() {
        let twin = &lone[i % lone.len()];
        assert!(
            close(val.position, twin.position, 1e-5, 1e-6)
                && close(val.flux, twin.flux, 1e-5, 0.0)
                && (val.area - twin.area).abs() <= 1e-5 * twin.area,
            "VAL {i} (view {}): {val:?} vs {twin:?}",
            i / 64
        );
    }
    // A budget of 20 VALs per view: 4² each, and the same power reflected.
    let (budgeted, side, _) = rsm_vals(&ctx, &many, 8, 6 * lights * 20);
    assert_eq!((side, budgeted.len()), (4, 6 * 16 * lights as usize));
    let flux = |v: &[valgi::light::Val]| v.iter().map(|v| v.flux.x as f64).sum::<f64>();
    let expected = 0.5 * 4.0 * std::f64::consts::PI * lights as f64;
    for (label, total) in [("8²", flux(&vals)), ("4²", flux(&budgeted))] {
        assert!(
            (total - expected).abs() < 0.02 * expected,
            "{label}: reflected flux {total} vs {expected}"
        );
    }
}

/// Under `--max-vals` the lights share the VALs by power: three co-located point lights of
/// powers 1 : 4 : 16 get RSM sides 2 : 4 : 8 (VALs 1 : 4 : 16, so every VAL carries the same
/// flux), laid out in one array, and each light still reflects ρ·4π·I.
#[test]
fn lights_share_the_val_budget_by_power() {
    let Some(ctx) = common::gpu() else { return };
    let single = builtin::load("box-point", &BuiltinParams { max_edge: 0.5 }).unwrap();
    let base = single.lights[0].intensity;
    let mut scene = single.clone();
    scene.lights = [1.0, 4.0, 16.0]
        .iter()
        .map(|&scale| valgi::scene::Light {
            intensity: base * scale,
            ..single.lights[0].clone()
        })
        .collect();
    let render = valgi::raster::RenderSettings {
        max_vals: 520,
        ..settings(8)
    };
    let raster = valgi::raster::Rasterizer::new(&ctx, &scene, render).unwrap();
    let rsm = valgi::light::rsm::Rsm::new(&ctx, &scene, &raster, 8).unwrap();
    assert_eq!(rsm.light_sides, vec![2, 4, 8]);
    let mut passes = valgi::gpu::Passes::new(&ctx);
    rsm.prepare(&ctx, &scene, &scene.world_from_node());
    rsm.record(&mut passes, &raster.scene_gpu).unwrap();
    passes.finish().unwrap();
    let vals = rsm.read_vals(&ctx).unwrap();
    // The box surrounds the light: every texel is lit, in view order.
    assert_eq!(vals.len(), 6 * (4 + 16 + 64));
    let mut first = 0;
    for (light, side) in [(0usize, 2usize), (1, 4), (2, 8)] {
        let count = 6 * side * side;
        let own = &vals[first..first + count];
        first += count;
        let flux: f64 = own.iter().map(|v| v.flux.x as f64).sum();
        let expected = 0.5 * 4.0 * std::f64::consts::PI * scene.lights[light].intensity as f64;
        assert!(
            (flux - expected).abs() < 0.03 * expected,
            "light {light} at {side}²: reflected flux {flux} vs {expected}"
        );
        let mean = flux / count as f64;
        let bright_mean = 0.5 * 4.0 * std::f64::consts::PI * (base as f64 * 16.0) / (6.0 * 64.0);
        assert!(
            (mean - bright_mean).abs() < 0.05 * bright_mean,
            "light {light}: {mean} W per VAL vs {bright_mean} for the brightest"
        );
    }
}

/// A device that binds fewer VALs than the RSMs would make (here 200, the RSMs wanting 384):
/// the lights share what one binding holds by power, as under `--max-vals`, each keeping its
/// reflected power, and the method renders.
#[test]
fn the_val_buffer_shrinks_to_the_devices_binding_limit() {
    let val_bytes = std::mem::size_of::<valgi::light::rsm::GpuVal>() as u64;
    let Some(ctx) = common::gpu_with_limits(|limits| {
        limits.max_storage_buffer_binding_size = 200 * val_bytes;
    }) else {
        return;
    };
    let scene = builtin::load("box-point", &BuiltinParams { max_edge: 0.5 }).unwrap();
    let raster = valgi::raster::Rasterizer::new(&ctx, &scene, settings(8)).unwrap();
    let rsm = valgi::light::rsm::Rsm::new(&ctx, &scene, &raster, 8).unwrap();
    // 6·5² = 150 of the 200 fit; 6·6² = 216 would not.
    assert_eq!(rsm.light_sides, vec![5]);
    let mut passes = valgi::gpu::Passes::new(&ctx);
    rsm.prepare(&ctx, &scene, &scene.world_from_node());
    rsm.record(&mut passes, &raster.scene_gpu).unwrap();
    passes.finish().unwrap();
    let vals = rsm.read_vals(&ctx).unwrap();
    assert_eq!(vals.len(), 150);
    let flux: f64 = vals.iter().map(|v| v.flux.x as f64).sum();
    let expected = 0.5 * 4.0 * std::f64::consts::PI * scene.lights[0].intensity as f64;
    assert!(
        (flux - expected).abs() < 0.03 * expected,
        "reflected flux {flux} vs {expected}"
    );
    // A whole frame of brute force on the same device (its own RSM at 8²).
    let mut options = MethodOptions::default();
    options.set("rsm", 8);
    let mut method = BruteMethod::new(&ctx, &scene, settings(8), &options).unwrap();
    let frame = method
        .render(&ctx, &scene, &scene.world_from_node(), &camera(&scene, 8))
        .unwrap();
    assert!(frame.indirect.pixels.iter().any(|p| p[0] > 0.0));
}

/// Kernels longer than the device's workgroups per dimension wrap into another dimension:
/// with the limit lowered to 3 groups every per-point and per-vertex pass wraps, and the
/// image is the same to the bit (a thread skipped or run twice would change it).
#[test]
fn dispatches_past_the_workgroup_limit_wrap_without_changing_the_image() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let world = scene.world_from_node();
    for occlusion in [OcclusionMode::Sum, OcclusionMode::Rays] {
        let render = |max_groups: Option<u32>| {
            let s = sparse_settings(16, 600, occlusion, true);
            let mut method = SparseMethod::new(&ctx, &scene, settings(24), s).unwrap();
            if let Some(max) = max_groups {
                method.sparse.max_groups_per_dimension = max;
            }
            let points = method.sparse.point_count.div_ceil(64);
            let vertices = method.sparse.vertex_count.div_ceil(64);
            let frame = method
                .render(&ctx, &scene, &world, &camera(&scene, 27))
                .unwrap();
            (frame.indirect.pixels, points, vertices)
        };
        let (whole, point_groups, vertex_groups) = render(None);
        let (wrapped, _, _) = render(Some(3));
        assert!(
            point_groups > 3 && vertex_groups > 3,
            "{point_groups} point and {vertex_groups} vertex groups do not wrap"
        );
        assert!(
            whole.iter().any(|p| p[0] > 0.0),
            "{occlusion:?}: black image"
        );
        assert!(
            whole == wrapped,
            "{occlusion:?}: the wrapped dispatch changed the image"
        );
    }
}

#[test]
fn gpu_kernels_agree_with_their_cpu_twins() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let eye = camera(&scene, 32).position();
    for weights in [Weights::Geometric, Weights::Flux] {
        let mut s = sparse_settings(32, 400, OcclusionMode::Sum, true);
        s.options.weights = weights;
        // Gather.
        let (method, _, gathered) = run_sparse(&ctx, &scene, 32, s, Stage::Gather);
        let vals = method.rsm.read_vals(&ctx).unwrap();
        assert!(vals.len() > 500, "{} VALs", vals.len());
        let receivers: Vec<Receiver> = gathered
            .points
            .iter()
            .map(|p| Receiver {
                position: p.position,
                normal: p.normal,
                k: p.k,
            })
            .collect();
        let mut lit = 0;
        for (i, r) in receivers.iter().enumerate() {
            let cpu = math::gather(r, eye, &vals, weights, true);
            let gpu = &gathered.lights[i];
            assert_close(
                gpu.diffuse,
                cpu.diffuse,
                1e-3,
                1e-9,
                format_args!("point {i}: E_d"),
            );
            assert_close(
                gpu.glossy,
                cpu.glossy,
                1e-3,
                1e-9,
                format_args!("point {i}: E_s"),
            );
            // Positions are stored as f16 offsets from the point: 2⁻¹¹ relative.
            let reach = (cpu.diffuse_position - r.position).length();
            assert!(
                (gpu.diffuse_position - cpu.diffuse_position).length() <= 1e-3 * reach + 1e-5,
                "point {i}: l_d"
            );
            let reach_s = (cpu.glossy_position - r.position).length();
            assert!(
                (gpu.glossy_position - cpu.glossy_position).length() <= 1e-3 * reach_s + 1e-5,
                "point {i}: l_s"
            );
            let (sd, _) = gathered.spheres[i];
            assert!(
                (sd - cpu.diffuse_sphere).abs() <= 2e-3 * cpu.diffuse_sphere + 1e-5,
                "point {i}: sphere {sd} vs {}",
                cpu.diffuse_sphere
            );
            if cpu.diffuse.max_element() > 0.0 {
                lit += 1;
            }
        }
        assert!(lit > receivers.len() / 2, "only {lit} points lit");

        // Renormalize, fed the GPU's gathered sums.
        let (_, _, renormalized) = run_sparse(&ctx, &scene, 32, s, Stage::Renormalize);
        for (i, r) in receivers.iter().enumerate() {
            let g = &gathered.lights[i];
            let input = math::Gathered {
                diffuse: g.diffuse,
                glossy: g.glossy,
                diffuse_position: g.diffuse_position,
                glossy_position: g.glossy_position,
                ..Default::default()
            };
            let (cpu, _) = math::renormalize(r, eye, &input);
            let gpu = &renormalized.lights[i];
            assert!(
                close(gpu.diffuse, cpu.diffuse, 1e-3, 1e-9),
                "point {i}: I_d {} vs {}",
                gpu.diffuse,
                cpu.diffuse
            );
            assert!(
                close(gpu.glossy, cpu.glossy, 1e-3, 1e-9),
                "point {i}: I_s {} vs {}",
                gpu.glossy,
                cpu.glossy
            );
        }

        // Occlusion, both combinations, fed the GPU's renormalized lights.
        let discs: Vec<math::OccluderDisc> = renormalized
            .points
            .iter()
            .map(|p| math::OccluderDisc {
                center: p.position,
                normal: p.normal,
                radius: p.disc_radius,
            })
            .collect();
        // Tiles of 4 points make a tree of four levels, whose upper nodes the pass skips.
        for (mode, tile) in [(OcclusionMode::Sum, 64), (OcclusionMode::Union, 4)] {
            let mut so = s;
            so.options.occlusion = mode;
            so.options.tile = tile;
            let (occluding, _, occluded) = run_sparse(&ctx, &scene, 32, so, Stage::Occlusion);
            // The discs in the pass's walk order, and the tree it culls with against its
            // CPU twin.
            let tile = so.options.tile;
            let walked = math::in_walk_order(&discs, occluding.sparse.occluder_walk());
            let tree = math::occlusion_tree(&walked, tile as usize);
            let levels = occluding.sparse.read_occluder_bounds(&ctx, tile).unwrap();
            assert_eq!(levels.len(), tree.len());
            assert!(tile > 4 || tree.len() >= 4, "{} levels", tree.len());
            let nodes = levels.iter().flatten().zip(tree.iter().flatten());
            for (k, (gpu, cpu)) in nodes.enumerate() {
                assert!(
                    (gpu.center - cpu.center).length() < 1e-5
                        && (gpu.radius - cpu.radius).abs() < 1e-5
                        && (gpu.max_disc_radius - cpu.max_disc_radius).abs() < 1e-6
                        && (gpu.half_extent - cpu.half_extent).abs().max_element() < 1e-5,
                    "node {k}: {gpu:?} vs {cpu:?}"
                );
            }
            let mut darkened = 0;
            for (i, r) in receivers.iter().enumerate() {
                let before = &renormalized.lights[i];
                let (sd, _) = renormalized.spheres[i];
                let walk = math::OcclusionWalk {
                    mode,
                    tile: tile as usize,
                };
                let o = math::occlusion(r, before.diffuse_position, sd, &walked, &tree, walk);
                let cpu = before.diffuse * (1.0 - o);
                let gpu = occluded.lights[i].diffuse;
                assert!(
                    close(gpu, cpu, 1e-3, 1e-7 * before.diffuse.max_element()),
                    "{mode:?} point {i}: {gpu} vs {cpu} (o = {o})"
                );
                if o > 0.01 {
                    darkened += 1;
                }
            }
            assert!(
                darkened > 10,
                "{mode:?}: occlusion touched only {darkened} points"
            );
        }

        interpolation_against_cpu(&ctx, &scene, s);
    }
}

/// Interpolation, fed the GPU's final point lights and the quantized link weights, against
/// its CPU twin at every instance vertex. Returns how many vertices the blend cap changed.
fn interpolation_against_cpu(ctx: &GpuContext, scene: &Scene, s: SparseSettings) -> usize {
    let (method, _, final_points) = run_sparse(ctx, scene, 32, s, Stage::Interpolate);
    let vertex_lights = method.sparse.read_vertex_lights(ctx).unwrap();
    let mut v = 0usize;
    let mut point_offset = 0usize;
    let world = scene.world_from_node();
    let mut capped = 0;
    for instance in &scene.instances {
        let mesh = &scene.meshes[instance.mesh];
        let mesh_points = &method.points[instance.mesh];
        let world_from_model = world[instance.node];
        let normal_from_model = glam::Mat3::from_mat4(world_from_model)
            .inverse()
            .transpose();
        for (r, row) in mesh_points.links.iter().enumerate() {
            // A two-sided sheet's back rows light the vertex's other face.
            let i = r % mesh.positions.len();
            let side = if r < mesh.positions.len() { 1.0 } else { -1.0 };
            let position = world_from_model.transform_point3(mesh.positions[i]);
            // The GPU reads the normal octahedral-encoded: the same input here.
            let model_normal = side * mesh.normals[i];
            let quantized =
                valgi::vals::sparse::oct_decode(valgi::vals::sparse::oct_encode(model_normal));
            let normal = (normal_from_model * quantized).normalize();
            let links: Vec<(usize, f32)> = row
                .iter()
                .map(|l| {
                    let w = (l.weight.clamp(0.0, 1.0) * 65535.0).round() / 65535.0;
                    (point_offset + l.point as usize, w)
                })
                .filter(|(_, w)| *w > 0.0)
                .collect();
            let cpu = math::interpolate(position, normal, &links, &final_points.lights);
            let blended = math::interpolate(Vec3::ZERO, Vec3::ZERO, &links, &final_points.lights);
            if cpu.diffuse != blended.diffuse {
                capped += 1;
            }
            let gpu = &vertex_lights[v];
            assert!(
                close(gpu.diffuse, cpu.diffuse, 1e-3, 1e-9),
                "vertex {v}: {} vs {}",
                gpu.diffuse,
                cpu.diffuse
            );
            assert!(close(gpu.glossy, cpu.glossy, 1e-3, 1e-9), "vertex {v}");
            assert!(
                (gpu.diffuse_position - cpu.diffuse_position).length() < 1e-4,
                "vertex {v}"
            );
            v += 1;
        }
        point_offset += mesh_points.positions.len();
    }
    assert_eq!(v, vertex_lights.len());
    capped
}

/// The cap on a vertex's blended light (`math::BLEND_GAIN_MAX`) fires on a curved mesh, the
/// GPU where the CPU twin does.
#[test]
fn interpolation_caps_blended_lights_on_the_bunny_as_its_cpu_twin_does() {
    let Some(ctx) = common::gpu() else { return };
    let scene = builtin::load("bunny-box", &BuiltinParams::default()).unwrap();
    let s = sparse_settings(32, 2048, OcclusionMode::Off, true);
    let capped = interpolation_against_cpu(&ctx, &scene, s);
    assert!(capped > 0, "no vertex capped its diffuse light");
}

#[test]
fn renormalized_lights_reproduce_the_gathered_sums_at_each_point() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let eye = camera(&scene, 32).position();
    let s = sparse_settings(32, 300, OcclusionMode::Off, true);
    let (_, _, gathered) = run_sparse(&ctx, &scene, 32, s, Stage::Gather);
    let (method, _, renormalized) = run_sparse(&ctx, &scene, 32, s, Stage::Renormalize);
    let (clamp_d, clamp_s) = method.sparse.read_clamps(&ctx).unwrap();
    let mut checked = 0;
    for (i, p) in renormalized.points.iter().enumerate() {
        let (e, l) = (&gathered.lights[i], &renormalized.lights[i]);
        let r = math::mirror((eye - p.position).normalize(), p.normal);
        let d = math::diffuse_point(p.position, p.normal, l.diffuse_position, l.diffuse);
        let g = math::glossy_point(p.position, p.normal, r, p.k, l.glossy_position, l.glossy);
        // Skip the channels whose clamp fired (counted, and rare).
        let unclamped_d = math::diffuse_point_factor(p.position, p.normal, l.diffuse_position)
            >= math::COS_MIN / (l.diffuse_position - p.position).length_squared();
        if unclamped_d && e.diffuse.max_element() > 0.0 {
            assert!(
                close(d, e.diffuse, 1e-4, 0.0),
                "point {i}: {d} vs {}",
                e.diffuse
            );
            checked += 1;
        }
        let unclamped_s =
            math::glossy_point_factor(p.position, p.normal, r, p.k, l.glossy_position)
                >= math::COS_MIN / (l.glossy_position - p.position).length_squared();
        if unclamped_s && e.glossy.max_element() > 0.0 {
            assert!(
                close(g, e.glossy, 1e-4, 0.0),
                "point {i}: glossy {g} vs {}",
                e.glossy
            );
        }
    }
    assert!(
        checked > renormalized.points.len() / 2,
        "{checked} points checked"
    );
    assert!(
        (clamp_d as usize) < renormalized.points.len() / 10,
        "diffuse clamp fired {clamp_d}×"
    );
    eprintln!(
        "renormalize clamps: diffuse {clamp_d}, glossy {clamp_s} of {} points",
        renormalized.points.len()
    );
}

#[test]
fn points_that_receive_no_light_are_exactly_dark_and_nothing_is_nan() {
    let Some(ctx) = common::gpu() else { return };
    // On a lone plane every VAL is coplanar with every receiver: n·ω̂ = 0 exactly.
    let scene = builtin::load("plane-spot", &BuiltinParams { max_edge: 0.25 }).unwrap();
    let (method, frame, points) = run_sparse(
        &ctx,
        &scene,
        32,
        sparse_settings(32, 200, OcclusionMode::Sum, true),
        Stage::Apply,
    );
    assert!(method.rsm.read_count(&ctx).unwrap() > 100);
    for l in &points.lights {
        assert_eq!(l.diffuse, Vec3::ZERO);
        assert_eq!(l.glossy, Vec3::ZERO);
        assert!(l.diffuse_position.is_finite() && l.glossy_position.is_finite());
    }
    for v in method.sparse.read_vertex_lights(&ctx).unwrap() {
        assert!(v.diffuse_position.is_finite() && v.glossy_position.is_finite());
        assert_eq!(v.diffuse, Vec3::ZERO);
    }
    assert!(frame
        .indirect
        .pixels
        .iter()
        .all(|p| p[0] == 0.0 && p[1] == 0.0 && p[2] == 0.0));
    assert_eq!(frame.direct.non_finite_count(), 0);

    // Without any light there are no VALs at all.
    let mut dark = scene.clone();
    dark.lights.clear();
    let (method, frame, points) = run_sparse(
        &ctx,
        &dark,
        32,
        sparse_settings(32, 200, OcclusionMode::Union, true),
        Stage::Apply,
    );
    assert_eq!(method.rsm.read_count(&ctx).unwrap(), 0);
    assert!(points
        .lights
        .iter()
        .all(|l| l.diffuse == Vec3::ZERO && l.diffuse_position.is_finite()));
    assert_eq!(frame.indirect.non_finite_count(), 0);
    assert!(frame.indirect.pixels.iter().all(|p| p[..3] == [0.0; 3]));
}

/// Where the ray through pixel (x, y)'s centre meets the plane y = 0.
fn pixel_on_floor(camera: &CameraView, size: u32, x: u32, y: u32) -> Vec3 {
    let world_from_clip = camera.clip_from_world().inverse();
    let ndc = |v: u32| (v as f32 + 0.5) / size as f32 * 2.0 - 1.0;
    let unproject = |z: f32| {
        let p = world_from_clip * Vec4::new(ndc(x), -ndc(y), z, 1.0);
        p.truncate() / p.w
    };
    let (a, b) = (unproject(0.0), unproject(1.0));
    a + (b - a) * (a.y / (a.y - b.y))
}

#[test]
fn brute_force_matches_the_cpu_sum_over_every_val() {
    let Some(ctx) = common::gpu() else { return };
    brute_force_against_cpu(&ctx, 32, 64);
    // Past 65535 VALs: Mesa's llvmpipe stops any loop after 65535 iterations per invocation,
    // which once cut the sums short silently.
    brute_force_against_cpu(&ctx, 340, 32);
}

/// Brute force's two ways of reading the VAL list (`vals tiles|windows`) add each pixel's VALs
/// in the same order: the same image to the bit, glossy lobes included, over three windows and
/// part of a fourth. A window's sum carried wrongly would move the pixels by a quarter.
#[test]
fn brute_force_windows_write_the_tile_forms_image_to_the_bit() {
    let Some(ctx) = common::gpu() else { return };
    let scene = glossy_scene(0.3, 1.0);
    let run = |reads: &str| {
        let mut options = MethodOptions::default();
        options.set("rsm", 64);
        options.set("vals", reads);
        // 27 rows: the window form's last column of four pixels hangs past the image.
        let mut brute = BruteMethod::new(&ctx, &scene, settings(27), &options).unwrap();
        let world = scene.world_from_node();
        let frame = brute
            .render(&ctx, &scene, &world, &camera(&scene, 27))
            .unwrap();
        assert_eq!(Method::report(&brute)["vals_read"], reads);
        let count = brute.rsm.read_count(&ctx).unwrap() as u64;
        assert!(count > 3 * VAL_WINDOW, "{count} VALs");
        frame.indirect
    };
    let tiles = run("tiles");
    let windows = run("windows");
    let lit = tiles.pixels.iter().filter(|p| p[0] > 0.0).count();
    assert!(lit > tiles.pixels.len() / 4, "{lit} lit pixels");
    for (i, (t, w)) in tiles.pixels.iter().zip(&windows.pixels).enumerate() {
        assert_eq!(t, w, "pixel {i}");
    }
}

/// The raster gather (fragments over a point target, `--gather raster`) writes what the
/// compute gather writes: the same sums, positions and spheres at every point, with the
/// cluster visibility on and the points filling one and a half rows of the target.
#[test]
fn raster_gather_writes_what_the_compute_gather_writes() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let points = 3 * RASTER_GATHER_WIDTH as usize / 2;
    let run = |gather: GatherForm| {
        let mut s = sparse_settings(32, points, OcclusionMode::Rays, true);
        s.options.gather = gather;
        run_sparse(&ctx, &scene, 16, s, Stage::Gather).2
    };
    let compute = run(GatherForm::Compute);
    let raster = run(GatherForm::Raster);
    // Placement keeps about the count asked for: more than one row of the target either way.
    let placed = compute.points.len();
    assert!(
        placed > RASTER_GATHER_WIDTH as usize && placed < 2 * RASTER_GATHER_WIDTH as usize,
        "{placed} points"
    );
    assert_eq!(raster.points.len(), placed);
    let lit = compute
        .lights
        .iter()
        .filter(|l| l.diffuse.max_element() > 0.0)
        .count();
    assert!(lit > placed / 2, "{lit} of {placed} points gathered light");
    for (i, (c, r)) in compute.lights.iter().zip(&raster.lights).enumerate() {
        assert_close(
            c.diffuse,
            r.diffuse,
            1e-5,
            1e-12,
            format_args!("point {i}: diffuse"),
        );
        assert_close(
            c.glossy,
            r.glossy,
            1e-5,
            1e-12,
            format_args!("point {i}: glossy"),
        );
        assert_close(
            c.diffuse_position,
            r.diffuse_position,
            1e-3,
            1e-6,
            format_args!("point {i}: diffuse position"),
        );
        assert_close(
            c.glossy_position,
            r.glossy_position,
            1e-3,
            1e-6,
            format_args!("point {i}: glossy position"),
        );
    }
    for (i, (c, r)) in compute.spheres.iter().zip(&raster.spheres).enumerate() {
        assert!(
            (c.0 - r.0).abs() <= 1e-3 * c.0.abs() + 1e-6,
            "point {i}: diffuse sphere"
        );
        assert!(
            (c.1 - r.1).abs() <= 1e-3 * c.1.abs() + 1e-6,
            "point {i}: glossy sphere"
        );
    }
}

#[test]
fn both_visibility_lookups_gather_the_same_sums() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let run = |occlusion: OcclusionMode, lookup: VisibilityLookup, name: &str| {
        let mut s = sparse_settings(32, 700, occlusion, true);
        s.options.visibility_lookup = lookup;
        let (method, _, points) = run_sparse(&ctx, &scene, 16, s, Stage::Gather);
        assert_eq!(Method::report(&method)["visibility_lookup"], name);
        points
    };
    let tree = run(OcclusionMode::Rays, VisibilityLookup::Tree, "tree");
    let switch = run(OcclusionMode::Rays, VisibilityLookup::Switch, "switch");
    // The same word, hence the same f32 sums in the same order: equal to the bit.
    assert_same_points(&tree, &switch, "tree against switch");
    // And the lookup matters: the tall block hides some clusters from some points, so the
    // sums differ from those gathered without visibility.
    let off = run(OcclusionMode::Off, VisibilityLookup::Tree, "tree");
    let darker = tree
        .lights
        .iter()
        .zip(&off.lights)
        .filter(|(t, o)| t.diffuse.max_element() < 0.9 * o.diffuse.max_element())
        .count();
    assert!(
        darker > 10,
        "{darker} points lost a tenth of their light to visibility"
    );
}

/// Asserts that two gathers wrote the same bits at every point: sums, positions, spheres.
fn assert_same_points(a: &PointsReadback, b: &PointsReadback, what: &str) {
    assert_eq!(a.lights.len(), b.lights.len(), "{what}: point counts");
    for (i, (x, y)) in a.lights.iter().zip(&b.lights).enumerate() {
        assert_eq!(x.diffuse, y.diffuse, "{what}, point {i}: diffuse");
        assert_eq!(x.glossy, y.glossy, "{what}, point {i}: glossy");
        assert_eq!(
            x.diffuse_position, y.diffuse_position,
            "{what}, point {i}: position"
        );
        assert_eq!(
            x.glossy_position, y.glossy_position,
            "{what}, point {i}: glossy position"
        );
        assert_eq!(a.spheres[i], b.spheres[i], "{what}, point {i}: spheres");
    }
}

/// The two ways the compute gather reads the VAL list (`gather-vals`: tiles of workgroup
/// memory, or uniform windows of 1024 VALs with the running sums carried between windows in
/// the partial-sums buffer) add the same VALs in the same order: the same bits, with the
/// cluster visibility and with the disc occlusion's spheres. About 2500 VALs fill two windows
/// and part of a third; with the sums carried wrongly (dropped, added twice, or another
/// window's) they would lose or gain a sixth of their light or more.
#[test]
fn windowed_gather_writes_what_the_tiled_gather_writes_to_the_bit() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let run = |occlusion: OcclusionMode, vals: ValReads, name: &str| {
        let mut s = sparse_settings(64, 700, occlusion, true);
        s.options.gather_vals = vals;
        let (method, _, points) = run_sparse(&ctx, &scene, 16, s, Stage::Gather);
        let report = Method::report(&method);
        assert_eq!(report["gather_vals"], name);
        let count = method.rsm.read_count(&ctx).unwrap() as u64;
        assert!(
            count > 2 * VAL_WINDOW && !count.is_multiple_of(VAL_WINDOW),
            "{count} VALs"
        );
        points
    };
    for occlusion in [OcclusionMode::Rays, OcclusionMode::Sum] {
        let tiles = run(occlusion, ValReads::Tiles, "tiles");
        let windows = run(occlusion, ValReads::Windows, "windows");
        let lit = tiles
            .lights
            .iter()
            .filter(|l| l.diffuse.max_element() > 0.0)
            .count();
        assert!(lit > tiles.lights.len() / 2, "{lit} points gathered light");
        assert_same_points(&tiles, &windows, &format!("{occlusion:?}"));
    }
    // A CPU device reads windows unless the gather is split; a GPU reads tiles.
    let mut s = sparse_settings(64, 700, OcclusionMode::Rays, true);
    let (method, _, _) = run_sparse(&ctx, &scene, 16, s, Stage::Gather);
    let cpu = ctx.is_software();
    assert_eq!(method.sparse.gathers_in_windows(&s.options), cpu);
    s.options.gather_slices = 3;
    assert!(!method.sparse.gathers_in_windows(&s.options));
}

/// 4, 8 and 16 points per compute-gather invocation (`gather-points`; a CPU device picks 16
/// at 4096 points) gather the same f32 sums in the same order, so the same bits, with the
/// cluster visibility (each slot group's own words) and with the disc occlusion's spheres;
/// 1500 points fill one 16-slot workgroup and part of a second.
#[test]
fn every_points_per_invocation_gathers_the_same_sums() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let run = |occlusion: OcclusionMode, per_invocation: u32| {
        let mut s = sparse_settings(32, 1500, occlusion, true);
        s.options.gather_points = per_invocation;
        let (method, _, points) = run_sparse(&ctx, &scene, 16, s, Stage::Gather);
        assert_eq!(
            Method::report(&method)["gather_points_per_invocation"],
            per_invocation
        );
        points
    };
    for occlusion in [OcclusionMode::Rays, OcclusionMode::Sum] {
        let four = run(occlusion, 4);
        assert!(four.lights.len() > 1024, "{} points", four.lights.len());
        for per_invocation in [8, 16] {
            let other = run(occlusion, per_invocation);
            let what = format!("{occlusion:?}, {per_invocation} per invocation");
            assert_same_points(&four, &other, &what);
        }
        if occlusion == OcclusionMode::Sum {
            // The spheres are gathered for the disc occlusion.
            let sized = four.spheres.iter().filter(|(d, _)| *d > 0.0).count();
            assert!(sized > four.lights.len() / 2, "{sized} spheres");
        } else {
            // Visibility differs from point to point, so a slot reading another's words
            // would change its sums: the tall block hides clusters from some points.
            let off = run(OcclusionMode::Off, 16);
            let darker = four
                .lights
                .iter()
                .zip(&off.lights)
                .filter(|(t, o)| t.diffuse.max_element() < 0.9 * o.diffuse.max_element())
                .count();
            assert!(darker > 10, "{darker} points lost a tenth of their light");
            // Without the disc occlusion no sphere is written.
            assert!(four.spheres.iter().all(|&(d, s)| d == 0.0 && s == 0.0));
        }
    }
}

#[test]
fn split_gather_writes_what_the_whole_gather_writes() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let run = |slices: u32| {
        let mut s = sparse_settings(32, 700, OcclusionMode::Rays, true);
        s.options.gather_slices = slices;
        let (method, _, points) = run_sparse(&ctx, &scene, 16, s, Stage::Gather);
        // The split runs as asked (a CPU device would otherwise keep the gather whole).
        assert_eq!(method.sparse.gather_slices(&s.options), slices);
        points
    };
    let whole = run(1);
    let lit = whole
        .lights
        .iter()
        .filter(|l| l.diffuse.max_element() > 0.0)
        .count();
    assert!(lit > whole.lights.len() / 2, "{lit} points gathered light");
    // 6144 VALs in 7 slices: uneven chunks, none empty; in 200 slices most hold one tile's
    // worth or less. The sums differ only in the order of their f32 additions.
    for slices in [7, 200] {
        let split = run(slices);
        assert_eq!(split.points.len(), whole.points.len());
        for (i, (w, p)) in whole.lights.iter().zip(&split.lights).enumerate() {
            let what = |part: &str| format!("{slices} slices, point {i}: {part}");
            assert_close(
                w.diffuse,
                p.diffuse,
                1e-5,
                1e-12,
                format_args!("{}", what("diffuse")),
            );
            assert_close(
                w.glossy,
                p.glossy,
                1e-5,
                1e-12,
                format_args!("{}", what("glossy")),
            );
            assert_close(
                w.diffuse_position,
                p.diffuse_position,
                1e-3,
                1e-6,
                format_args!("{}", what("diffuse position")),
            );
            assert_close(
                w.glossy_position,
                p.glossy_position,
                1e-3,
                1e-6,
                format_args!("{}", what("glossy position")),
            );
        }
        // A sphere is 2σ from E[l²] − E[l]²: the rounding of the sums, which the slices
        // add in another order, is amplified by E[l²]/σ² (several hundred for a glossy lobe's
        // narrow set of VALs here) and then stored as f16. A missing or doubled slice would
        // move the sums above by a seventh, far past their 1e-5.
        for (i, (w, p)) in whole.spheres.iter().zip(&split.spheres).enumerate() {
            assert!(
                (w.0 - p.0).abs() <= 5e-3 * w.0.abs() + 1e-6
                    && (w.1 - p.1).abs() <= 5e-3 * w.1.abs() + 1e-6,
                "{slices} slices, point {i}: spheres {w:?} vs {p:?}"
            );
        }
    }
}

#[test]
fn gather_sums_more_than_65535_vals() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    let eye = camera(&scene, 16).position();
    for (gather, slices, vals) in [
        (GatherForm::Compute, 1, ValReads::Tiles),
        (GatherForm::Compute, 1, ValReads::Windows),
        (GatherForm::Compute, 5, ValReads::Tiles),
        (GatherForm::Raster, 1, ValReads::Auto),
    ] {
        let mut s = sparse_settings(340, 64, OcclusionMode::Off, true);
        s.options.gather = gather;
        s.options.gather_slices = slices;
        s.options.gather_vals = vals;
        gather_sums_against_cpu(&ctx, &scene, eye, s);
    }
}

fn gather_sums_against_cpu(ctx: &GpuContext, scene: &Scene, eye: Vec3, s: SparseSettings) {
    let gather = (
        s.options.gather,
        s.options.gather_slices,
        s.options.gather_vals,
    );
    let (method, _, gathered) = run_sparse(ctx, scene, 16, s, Stage::Gather);
    let vals = method.rsm.read_vals(ctx).unwrap();
    assert!(vals.len() > 65535, "{} VALs", vals.len());
    for (i, p) in gathered.points.iter().enumerate() {
        let r = Receiver {
            position: p.position,
            normal: p.normal,
            k: p.k,
        };
        let cpu = math::gather(&r, eye, &vals, Weights::Geometric, true);
        assert!(
            close(gathered.lights[i].diffuse, cpu.diffuse, 1e-3, 1e-9),
            "{gather:?} point {i}: {} vs {}",
            gathered.lights[i].diffuse,
            cpu.diffuse
        );
        assert!(
            close(gathered.lights[i].glossy, cpu.glossy, 1e-3, 1e-9),
            "{gather:?} point {i}: glossy"
        );
    }
}

fn brute_force_against_cpu(ctx: &GpuContext, rsm: u32, size: u32) {
    let scene = cornell_coarse();
    let mut options = MethodOptions::default();
    options.set("rsm", rsm);
    let mut brute = BruteMethod::new(ctx, &scene, settings(size), &options).unwrap();
    let world = scene.world_from_node();
    let cam = camera(&scene, size);
    let frame = brute.render(ctx, &scene, &world, &cam).unwrap();
    let vals = brute.rsm.read_vals(ctx).unwrap();
    let floor = scene.materials[scene
        .meshes
        .iter()
        .find(|m| m.name == "floor")
        .unwrap()
        .material]
        .clone();
    let rho_d = floor.base_color.truncate();
    // Pixels at the front of the floor, in front of both blocks (the short one starts at
    // z = 65 mm), spread across the image.
    let pixels: Vec<(u32, u32, Vec3)> = (0..size)
        .step_by(5)
        .flat_map(|x| (size * 50 / 64..size).map(move |y| (x, y)))
        .map(|(x, y)| (x, y, pixel_on_floor(&cam, size, x, y)))
        .filter(|(_, _, p)| p.x > 0.01 && p.x < 0.54 && p.z > 0.005 && p.z < 0.06)
        .collect();
    assert!(pixels.len() >= 4, "{} floor pixels", pixels.len());
    for (x, y, p) in pixels {
        let wo = (cam.position() - p).normalize();
        let cpu = math::brute_force(p, Vec3::Y, wo, rho_d, Vec3::ZERO, 1.0, &vals, true);
        let gpu = frame.indirect.get(x, y);
        let gpu = Vec3::new(gpu[0], gpu[1], gpu[2]);
        assert!(cpu.max_element() > 0.0);
        // The G-buffer position comes from a 32-bit depth: 1e-3 covers it.
        assert!(
            close(gpu, cpu, 2e-3, 0.0),
            "pixel ({x},{y}): {gpu} vs {cpu}"
        );
    }
}

// ---- small hand-built scenes -------------------------------------------------------------

struct Builder(Scene);

impl Builder {
    fn new(name: &str) -> Self {
        Self(Scene {
            name: name.into(),
            ..Scene::default()
        })
    }
    fn node(&mut self, name: &str, local: Trs) -> usize {
        self.0.nodes.push(Node {
            name: name.into(),
            parent: None,
            local,
        });
        self.0.nodes.len() - 1
    }
    fn quad(&mut self, name: &str, corners: [Vec3; 4], facing: Vec3, material: Material) {
        self.0.materials.push(material);
        let mut mesh = MeshBuilder::new(name, self.0.materials.len() - 1);
        let [p0, p1, p2, p3] = corners;
        mesh.add_quad(p0, p1, p2, p3, facing, 0.1);
        self.0.meshes.push(mesh.build());
        let node = self.node(name, Trs::default());
        self.0.instances.push(Instance {
            mesh: self.0.meshes.len() - 1,
            node,
        });
    }
    fn spot(&mut self, position: Vec3, direction: Vec3, outer: f32) {
        let node = self.node(
            "spot",
            Trs {
                translation: position,
                rotation: Quat::from_rotation_arc(Vec3::NEG_Z, direction.normalize()),
                ..Trs::default()
            },
        );
        self.0.lights.push(Light {
            name: "spot".into(),
            node,
            kind: LightKind::Spot {
                inner_cone_angle: 0.0,
                outer_cone_angle: outer,
            },
            color: Vec3::ONE,
            intensity: 2.0,
            range: None,
        });
    }
    fn camera(&mut self, eye: Vec3, target: Vec3) {
        let node = self.node(
            "camera",
            Trs {
                translation: eye,
                rotation: Quat::from_rotation_arc(Vec3::NEG_Z, (target - eye).normalize()),
                ..Trs::default()
            },
        );
        self.0.cameras.push(Camera {
            name: "camera".into(),
            node,
            yfov: 1.0,
            fov_axis: FovAxis::Vertical,
            aspect: None,
            znear: 0.01,
            zfar: None,
        });
    }
}

/// A horizontal square of half-size `half` at height y.
fn square(y: f32, half: f32) -> [Vec3; 4] {
    [
        Vec3::new(-half, y, -half),
        Vec3::new(half, y, -half),
        Vec3::new(half, y, half),
        Vec3::new(-half, y, half),
    ]
}

/// A glossy floor in front of a wall lit by a spot; the camera at `eye_x`.
fn glossy_scene(eye_x: f32, specular_factor: f32) -> Scene {
    let mut b = Builder::new("glossy-floor");
    b.quad(
        "floor",
        square(0.0, 1.0),
        Vec3::Y,
        Material {
            base_color: Vec4::new(0.8, 0.8, 0.8, 1.0),
            metallic: 0.5,
            roughness: 0.35,
            specular_factor,
            ..Material::lambert("floor", Vec3::splat(0.8))
        },
    );
    b.quad(
        "wall",
        [
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -1.0),
            Vec3::new(1.0, 1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
        ],
        Vec3::Z,
        Material::lambert("wall", Vec3::splat(0.8)),
    );
    b.spot(Vec3::new(0.0, 0.5, 0.2), Vec3::NEG_Z, 0.3);
    b.camera(Vec3::new(eye_x, 0.6, 1.2), Vec3::new(0.0, 0.0, -0.3));
    b.0
}

fn render_indirect(
    ctx: &GpuContext,
    scene: &Scene,
    size: u32,
    s: SparseSettings,
) -> (FrameOutput, CameraView) {
    let (_, frame, _) = run_sparse(ctx, scene, size, s, Stage::Apply);
    (frame, camera(scene, size))
}

#[test]
fn glossy_highlight_follows_the_eye_and_vanishes_when_glossy_is_off() {
    let Some(ctx) = common::gpu() else { return };
    let size = 48;
    let mut centroids = Vec::new();
    for eye_x in [-0.5f32, 0.5] {
        let scene = glossy_scene(eye_x, 1.0);
        let on = render_indirect(
            &ctx,
            &scene,
            size,
            sparse_settings(32, 600, OcclusionMode::Off, true),
        );
        let (off, cam) = render_indirect(
            &ctx,
            &scene,
            size,
            sparse_settings(32, 600, OcclusionMode::Off, false),
        );
        // Glossy off is exactly the floor without its specular lobe.
        let matte = glossy_scene(eye_x, 0.0);
        let (matte_frame, _) = render_indirect(
            &ctx,
            &matte,
            size,
            sparse_settings(32, 600, OcclusionMode::Off, true),
        );
        let mut weight = 0.0f32;
        let mut weighted_x = 0.0f32;
        let mut diffuse = 0.0f32;
        for y in 0..size {
            for x in 0..size {
                let a = on.0.indirect.get(x, y)[1];
                let b = off.indirect.get(x, y)[1];
                let m = matte_frame.indirect.get(x, y)[1];
                assert!(
                    (b - m).abs() <= 1e-4 * m.abs() + 1e-9,
                    "pixel ({x},{y}): glossy off {b} vs matte {m}"
                );
                let p = pixel_on_floor(&cam, size, x, y);
                if p.z > -0.95 && p.z < 1.0 && p.x.abs() < 1.0 && (a - b) > 0.0 {
                    weight += a - b;
                    weighted_x += (a - b) * p.x;
                }
                diffuse += b;
            }
        }
        assert!(
            weight > 0.05 * diffuse,
            "eye {eye_x}: glossy {weight} vs diffuse {diffuse}"
        );
        centroids.push(weighted_x / weight);
    }
    // The mirror image of the lit wall patch (x = 0) seen from x = ∓0.5 lies at ∓0.23 on the
    // floor; the highlight's centroid must move to the eye's side.
    assert!(
        centroids[0] < -0.05 && centroids[1] > 0.05,
        "highlight centroids {centroids:?}"
    );
}

#[test]
fn glossy_auto_gathers_only_where_a_material_reflects_glossily() {
    let Some(ctx) = common::gpu() else { return };
    let size = 32;
    let with = |glossy: GlossyGather| {
        let mut s = sparse_settings(32, 400, OcclusionMode::Off, true);
        s.options.glossy = glossy;
        s
    };
    // The Lambert floor (specular factor 0) and the glossy one.
    for (specular, gathers) in [(0.0f32, false), (1.0, true)] {
        let scene = glossy_scene(0.5, specular);
        let (auto, auto_frame, auto_points) =
            run_sparse(&ctx, &scene, size, with(GlossyGather::Auto), Stage::Apply);
        let (_, on_frame, on_points) =
            run_sparse(&ctx, &scene, size, with(GlossyGather::On), Stage::Apply);
        let report = valgi::frame::Method::report(&auto);
        assert_eq!(report["glossy"], "auto");
        assert_eq!(report["glossy_gathered"], gathers, "specular {specular}");
        // The same image either way: with no glossy material the glossy term is zero at
        // every pixel, gathered or not.
        for y in 0..size {
            for x in 0..size {
                assert_eq!(
                    auto_frame.indirect.get(x, y),
                    on_frame.indirect.get(x, y),
                    "specular {specular}, pixel ({x},{y})"
                );
            }
        }
        // The diffuse-only pipeline writes the full gather's diffuse lights and no glossy.
        for (a, o) in auto_points.lights.iter().zip(&on_points.lights) {
            assert_eq!(a.diffuse, o.diffuse);
            if gathers {
                assert_eq!(a.glossy, o.glossy);
            } else {
                assert_eq!(a.glossy, Vec3::ZERO);
            }
        }
        assert!(on_points
            .lights
            .iter()
            .any(|l| l.glossy.max_element() > 0.0));
        // Brute force decides the same way, with the same image either way.
        let brute = |glossy: &str| {
            let mut options = MethodOptions::default();
            options.set("rsm", 32);
            options.set("glossy", glossy);
            let mut brute = BruteMethod::new(&ctx, &scene, settings(size), &options).unwrap();
            let world = scene.world_from_node();
            let frame = brute
                .render(&ctx, &scene, &world, &camera(&scene, size))
                .unwrap();
            (valgi::frame::Method::report(&brute), frame.indirect)
        };
        let ((auto_report, auto_image), (_, on_image)) = (brute("auto"), brute("on"));
        assert_eq!(
            auto_report["glossy_gathered"], gathers,
            "specular {specular}"
        );
        assert_eq!(auto_image.pixels, on_image.pixels, "specular {specular}");
    }
}

/// Light from a lit ceiling patch reaches the floor through where a blocker hangs.
fn blocker_scene() -> Scene {
    let mut b = Builder::new("blocker");
    b.quad(
        "floor",
        square(0.0, 1.0),
        Vec3::Y,
        Material::lambert("floor", Vec3::splat(0.8)),
    );
    b.quad(
        "ceiling",
        square(1.0, 1.0),
        Vec3::NEG_Y,
        Material::lambert("ceiling", Vec3::splat(0.8)),
    );
    b.quad(
        "blocker",
        square(0.5, 0.3),
        Vec3::NEG_Y,
        Material::lambert("blocker", Vec3::splat(0.8)),
    );
    b.spot(Vec3::new(0.0, 0.9, 0.0), Vec3::Y, 1.2);
    b.camera(Vec3::new(0.0, 0.3, 2.0), Vec3::ZERO);
    b.0
}

#[test]
fn occlusion_darkens_receivers_behind_a_blocker_and_union_never_exceeds_sum() {
    let Some(ctx) = common::gpu() else { return };
    let scene = blocker_scene();
    let floor_mesh = scene.meshes.iter().position(|m| m.name == "floor").unwrap();
    let mut results = Vec::new();
    for mode in [OcclusionMode::Off, OcclusionMode::Sum, OcclusionMode::Union] {
        let (method, _, points) = run_sparse(
            &ctx,
            &scene,
            32,
            sparse_settings(32, 800, mode, false),
            Stage::Occlusion,
        );
        // The floor's points come first among the instances (the floor is instance 0).
        let floor_count = method.points[floor_mesh].positions.len();
        let under: Vec<f32> = points.points[..floor_count]
            .iter()
            .zip(&points.lights)
            .filter(|(p, _)| p.position.x.abs() < 0.15 && p.position.z.abs() < 0.15)
            .map(|(_, l)| l.diffuse.x)
            .collect();
        let open: Vec<f32> = points.points[..floor_count]
            .iter()
            .zip(&points.lights)
            .filter(|(p, _)| p.position.x.abs() > 0.7 || p.position.z.abs() > 0.7)
            .map(|(_, l)| l.diffuse.x)
            .collect();
        assert!(!under.is_empty() && !open.is_empty());
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        results.push((mode, mean(&under), mean(&open), points.lights.clone()));
    }
    let (_, off_under, _, _) = results[0];
    let (_, sum_under, _, ref sum_lights) = results[1];
    let (_, union_under, _, ref union_lights) = results[2];
    assert!(
        sum_under < 0.7 * off_under,
        "sum {sum_under} vs off {off_under}"
    );
    assert!(
        union_under < 0.9 * off_under,
        "union {union_under} vs off {off_under}"
    );
    assert!(
        union_under >= sum_under,
        "union {union_under} < sum {sum_under}"
    );
    for (s, u) in sum_lights.iter().zip(union_lights) {
        assert!(
            u.diffuse.x >= s.diffuse.x * (1.0 - 1e-5) - 1e-12,
            "union occluded more than sum at a point"
        );
    }
    eprintln!(
        "under the blocker: off {off_under:.4e}, sum {sum_under:.4e}, union {union_under:.4e}"
    );
}

/// Mean FLIP between two images tone-mapped at `exposure` stops.
fn mean_flip(a: &valgi::image_io::Image, b: &valgi::image_io::Image, exposure: f32) -> f32 {
    let (ta, tb) = (a.tone_map(exposure), b.tone_map(exposure));
    let (w, h) = ta.dimensions();
    let map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, ta.as_raw()),
        nv_flip::FlipImageRgb8::with_data(w, h, tb.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    nv_flip::FlipPool::from_image(&map).mean()
}

#[test]
fn sparse_indirect_on_cornell_is_close_to_brute_force() {
    let Some(ctx) = common::gpu() else { return };
    let scene = builtin::load("cornell", &BuiltinParams::default()).unwrap();
    let size = 256;
    let world = scene.world_from_node();
    let cam = camera(&scene, size);
    let mut brute_options = MethodOptions::default();
    brute_options.set("rsm", 64);
    let mut brute = BruteMethod::new(&ctx, &scene, settings(size), &brute_options).unwrap();
    let reference = brute.render(&ctx, &scene, &world, &cam).unwrap().indirect;
    // Exposure that puts the brute-force image's mean at 18% grey, so FLIP sees the indirect
    // light at the brightness a viewer of the indirect-only image would.
    let mean = (reference.mean_rgb().iter().sum::<f64>() / 3.0) as f32;
    let exposure = (0.18 / mean).log2();
    let mut flips = Vec::new();
    for (points, occlusion) in [
        (4096, OcclusionMode::Off),
        (1024, OcclusionMode::Off),
        (4096, OcclusionMode::Sum),
    ] {
        let s = SparseSettings {
            rsm: 64,
            sparse_points: points,
            ..SparseSettings::default()
        };
        let s = SparseSettings {
            options: SparseOptions {
                occlusion,
                ..s.options
            },
            ..s
        };
        let (_, frame, _) = run_sparse(&ctx, &scene, size, s, Stage::Apply);
        flips.push(mean_flip(&reference, &frame.indirect, exposure));
    }
    eprintln!("mean FLIP against brute force (exposure {exposure:.2}): 4096 points {:.4}, 1024 points {:.4}, 4096 points + occlusion {:.4}", flips[0], flips[1], flips[2]);
    assert_eq!(mean_flip(&reference, &reference, exposure), 0.0);
    // Measured on lavapipe: 0.040 (4096 points), 0.069 (1024), 0.174 (4096 with the paper's
    // occlusion, which brute force does not model). Without occlusion the only difference is
    // interpolation from the points, so the error must fall as points are added, and 4096
    // points must stay under 0.05: a quarter above the measured value leaves room for other
    // drivers' float rounding (transcendentals, fused multiply-adds), not for a change in the
    // method.
    assert!(
        flips[0] < flips[1],
        "more points must be closer to brute force: {flips:?}"
    );
    assert!(
        flips[0] < 0.05,
        "sparse (4096 points) vs brute force: mean FLIP {}",
        flips[0]
    );
    // Occlusion only ever darkens: it must move the image away from the unoccluded baseline.
    assert!(flips[2] > flips[0]);
}

#[test]
fn brute_force_agrees_with_the_one_bounce_reference_on_a_diffuse_scene() {
    let Some(ctx) = common::gpu() else { return };
    // A matte floor lit only by a spot-lit wall: nothing stands between any VAL and any
    // receiver, so brute force leaves out no visibility, and the difference to the path tracer
    // is the VALs' discretization (RSM texels as discs) and the shadow maps' filtering.
    let scene = glossy_scene(0.0, 0.0);
    let size = 48;
    let world = scene.world_from_node();
    let cam = camera(&scene, size);
    let mut options = MethodOptions::default();
    options.set("rsm", 64);
    let mut brute = BruteMethod::new(&ctx, &scene, settings(size), &options).unwrap();
    let vals_image = brute.render(&ctx, &scene, &world, &cam).unwrap().indirect;
    let mut ref_options = MethodOptions::default();
    ref_options.set("bounces", 1);
    ref_options.set("spp", 256);
    let mut reference =
        valgi::method::create("reference", &ctx, &scene, settings(size), &ref_options).unwrap();
    let truth = reference
        .render(&ctx, &scene, &world, &cam)
        .unwrap()
        .indirect;
    // Mean indirect radiance over the floor in front of the wall (away from the corner, where
    // a disc light is least like the surface it stands for).
    let mut sums = (0.0f64, 0.0f64);
    let mut count = 0;
    for y in 0..size {
        for x in 0..size {
            let p = pixel_on_floor(&cam, size, x, y);
            if p.z > -0.7 && p.z < 0.6 && p.x.abs() < 0.8 {
                sums.0 += vals_image.get(x, y)[1] as f64;
                sums.1 += truth.get(x, y)[1] as f64;
                count += 1;
            }
        }
    }
    assert!(count > 200, "{count} floor pixels");
    let relative = (sums.0 - sums.1).abs() / sums.1;
    eprintln!(
        "floor indirect: VALs {:.4e}, reference {:.4e} ({:.2}% apart)",
        sums.0 / count as f64,
        sums.1 / count as f64,
        100.0 * relative
    );
    assert!(
        relative < 0.05,
        "brute-force VALs {} vs reference {} ({:.1}%)",
        sums.0,
        sums.1,
        100.0 * relative
    );
}

#[test]
fn preprocessing_is_cached_per_mesh_and_points_ride_with_rigid_motion() {
    let Some(ctx) = common::gpu() else { return };
    let scene = builtin::load("cornell-moving", &BuiltinParams { max_edge: 0.1 }).unwrap();
    let s = sparse_settings(32, 333, OcclusionMode::Off, true);
    let first = SparseMethod::new(&ctx, &scene, settings(32), s).unwrap();
    let second = SparseMethod::new(&ctx, &scene, settings(32), s).unwrap();
    assert!(first.meshes_computed > 0);
    assert_eq!(
        second.meshes_computed, 0,
        "the second method recomputed points"
    );
    // Points are placed once in model space: moving the scene moves them rigidly.
    let (t0, t1) = (scene.world_from_node_at(0.0), scene.world_from_node_at(1.0));
    let (a, b) = (
        first.sparse.decoded_points(&scene, &t0),
        first.sparse.decoded_points(&scene, &t1),
    );
    let moved = a
        .iter()
        .zip(&b)
        .filter(|(p, q)| (p.position - q.position).length() > 1e-4)
        .count();
    assert!(
        moved > 0 && moved < a.len(),
        "{moved} of {} points moved",
        a.len()
    );
    for (p, q) in a.iter().zip(&b) {
        assert_eq!(p.disc_radius, q.disc_radius);
    }
}

#[test]
fn the_same_frame_renders_bit_identically() {
    let Some(ctx) = common::gpu() else { return };
    // VALs are compacted in texel order, not in the order atomics happen to run, so every sum
    // over them — and the image — repeats exactly: no flicker from summation order.
    let scene = cornell_coarse();
    let s = sparse_settings(48, 300, OcclusionMode::Union, true);
    let (a_method, a, _) = run_sparse(&ctx, &scene, 32, s, Stage::Apply);
    let (b_method, b, _) = run_sparse(&ctx, &scene, 32, s, Stage::Apply);
    assert_eq!(
        a_method.rsm.read_vals(&ctx).unwrap(),
        b_method.rsm.read_vals(&ctx).unwrap()
    );
    assert_eq!(a.indirect.pixels, b.indirect.pixels);
    assert!(a.indirect.pixels.iter().any(|p| p[0] > 0.0));
}

#[test]
fn solutions_on_one_device_share_its_pipelines_and_render_as_on_their_own() {
    // The sparse passes' pipelines are compiled once per device: a second scene's solution
    // binds its own buffers to the pipelines the first one compiled, and must render exactly
    // what it renders on a device of its own.
    let (Some(shared), Some(own)) = (common::gpu(), common::gpu()) else {
        return;
    };
    let corridor = builtin::load("corridor", &BuiltinParams { max_edge: 0.2 }).expect("corridor");
    let s = sparse_settings(32, 300, OcclusionMode::Rays, true);
    let (first, _, _) = run_sparse(&shared, &cornell_coarse(), 32, s, Stage::Apply);
    let (second, after_cornell, _) = run_sparse(&shared, &corridor, 32, s, Stage::Apply);
    let (apart, alone, _) = run_sparse(&own, &corridor, 32, s, Stage::Apply);
    assert!(second.sparse.shares_pipelines_with(&first.sparse));
    assert!(!apart.sparse.shares_pipelines_with(&first.sparse));
    assert!(alone.indirect.pixels.iter().any(|p| p[0] > 0.0));
    assert_eq!(after_cornell.indirect.pixels, alone.indirect.pixels);
    assert_eq!(after_cornell.direct.pixels, alone.direct.pixels);
}

/// Budget mode's pilots build the method many times over one scene through a `SceneCache`:
/// those builds share the scene's upload, its meshes' BVHs and each point count's cut links.
/// Builds through caches of their own (the viewer's rebuilds, a benchmark's warm-up instance)
/// share the upload and the BVHs while a build over the same content lives, and nothing holds
/// them once none does; an edited scene gets its own. Every build renders what a build on its
/// own renders, to the bit.
#[test]
fn builds_over_one_scene_share_its_parts_and_render_what_a_build_alone_renders() {
    use std::sync::Arc;
    let Some(ctx) = common::gpu() else { return };
    let scene = builtin::load("door-room", &BuiltinParams { max_edge: 0.25 }).expect("door room");
    let world = scene.world_from_node();
    let view = camera(&scene, 24);
    let rays = sparse_settings(32, 256, OcclusionMode::Rays, true);
    assert!(rays.link_test);
    let fewer = SparseSettings {
        sparse_points: 128,
        ..rays
    };
    let indirect = |m: &mut SparseMethod| {
        m.render(&ctx, &scene, &world, &view)
            .expect("render")
            .indirect
            .pixels
    };

    let mut alone = SparseMethod::new(&ctx, &scene, settings(24), rays).expect("build alone");
    let expected = indirect(&mut alone);
    assert!(expected.iter().any(|p| p[0] > 0.0), "an indirect image");
    let alone_upload = Arc::downgrade(&alone.raster.scene_gpu);
    let alone_bvhs = Arc::downgrade(&alone.sparse.bvh().bottom);
    drop(alone);
    assert!(alone_upload.upgrade().is_none() && alone_bvhs.upgrade().is_none());

    let cache = valgi::vals::SceneCache::new(&scene);
    let build = |s: SparseSettings| {
        SparseMethod::from_cache(&ctx, &cache, settings(24), s, None).expect("cached build")
    };
    let (mut first, mut other, mut again) = (build(rays), build(fewer), build(rays));
    let mut own_cache = SparseMethod::new(&ctx, &scene, settings(24), rays).expect("build");
    let mut edited_scene = scene.clone();
    edited_scene.meshes[0].positions[0].y += 1e-3;
    let edited = SparseMethod::new(&ctx, &edited_scene, settings(24), rays).expect("edited build");

    for shares in [&other, &again, &own_cache] {
        assert!(Arc::ptr_eq(
            &first.raster.scene_gpu,
            &shares.raster.scene_gpu
        ));
        assert!(Arc::ptr_eq(
            &first.sparse.bvh().bottom,
            &shares.sparse.bvh().bottom
        ));
    }
    assert!(!Arc::ptr_eq(
        &first.raster.scene_gpu,
        &edited.raster.scene_gpu
    ));
    assert!(!Arc::ptr_eq(
        &first.sparse.bvh().bottom,
        &edited.sparse.bvh().bottom
    ));
    // The partition cuts links, and a cut mesh's points are new on every cut (not the
    // placement's): the same allocation in `again` is the first build's cut, from the cache.
    assert!(first.link_cut.links > 0, "{:?}", first.link_cut);
    let (placed, _) = valgi::vals::points::scene_points(&scene, rays.sparse_points, rays.seed);
    let cut_mesh = (0..scene.meshes.len())
        .find(|&m| !Arc::ptr_eq(&first.points[m], &placed[m]))
        .expect("a mesh whose links were cut");
    assert!(Arc::ptr_eq(
        &first.points[cut_mesh],
        &again.points[cut_mesh]
    ));
    assert_eq!((again.link_cut, again.meshes_computed), (first.link_cut, 0));

    assert!(indirect(&mut first) == expected);
    assert!(indirect(&mut again) == expected);
    assert!(indirect(&mut own_cache) == expected);
    assert!(
        indirect(&mut other) != expected,
        "fewer points, another image"
    );
}

/// A layer that counts the views it records and leaves the sparse light under it as it is.
struct CountingLayer(std::sync::Arc<std::sync::atomic::AtomicUsize>);

impl valgi::frame::IndirectLayer for CountingLayer {
    fn method_name(&self) -> &'static str {
        "sparse+counting"
    }

    fn update(&mut self, _: &GpuContext, _: &valgi::frame::FrameInput, _: &[&valgi::frame::View]) {}

    fn record_view(
        &mut self,
        _: &GpuContext,
        view: &valgi::frame::View,
        passes: &mut valgi::gpu::Passes,
        draw_under: &mut dyn FnMut(
            &mut valgi::gpu::Passes,
            &wgpu::TextureView,
        ) -> Result<(), valgi::gpu::GpuError>,
    ) -> Result<(), valgi::raster::RenderError> {
        self.0.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        draw_under(passes, &view.targets.radiance_indirect)?;
        Ok(())
    }

    fn gpu_bytes(&self) -> u64 {
        0
    }
}

/// Under a time budget the frame to fit is the composed method's (`sparse+atlas` adds the
/// atlas's passes to every view): each timing pilot renders with the layer, through as many
/// views as the render's frames, and the layer comes back to the method chosen.
#[test]
fn timing_pilots_render_the_composed_methods_layer_through_every_view() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    // One candidate (every knob given): one timing pilot.
    let (_, options) = MethodOptions::parse_spec(
        "sparse:quality=auto,budget-ms=1e7,sparse-points=1024,rsm=32,occlusion=off",
    )
    .unwrap();
    let render = valgi::raster::RenderSettings {
        views_per_frame: 2,
        ..settings(24)
    };
    let recorded = std::sync::Arc::new(AtomicUsize::new(0));
    let layer = Box::new(CountingLayer(recorded.clone()));
    let mut method =
        SparseMethod::from_options_with_layer(&ctx, &scene, render, &options, Some(layer))
            .expect("budget mode");
    let budget = method.budget.clone().expect("a budget report");
    let pilots = budget["timing_pilots"]["measured"]
        .as_array()
        .map_or(0, Vec::len);
    assert_eq!(pilots, 1, "{budget}");
    assert_eq!(budget["timing_pilots"]["views"], 2, "{budget}");
    let frames = valgi::vals::budget::timed::TIMING_FRAMES;
    assert_eq!(recorded.load(Ordering::Relaxed), pilots * frames * 2);
    // The method chosen records through the layer.
    let world = scene.world_from_node();
    method
        .render(&ctx, &scene, &world, &camera(&scene, 24))
        .expect("render");
    assert_eq!(recorded.load(Ordering::Relaxed), pilots * frames * 2 + 1);
}

/// A method in budget mode says how to build its choice again without the search
/// (`Method::resolved_options`, what `valgi eval` builds its warm-up instance with): the
/// chosen knobs written in, the budget's own options gone, the others kept; built from
/// them, the method has the same settings, renders the same image, and searches nothing.
#[test]
fn a_budget_choice_builds_again_from_its_resolved_options_without_a_search() {
    let Some(ctx) = common::gpu() else { return };
    let scene = cornell_coarse();
    // A budget no frame fits: the cheapest candidate, whose knobs are none of the defaults.
    let (_, options) =
        MethodOptions::parse_spec("sparse:quality=auto,budget-ms=0.001,seed=7,glossy=off").unwrap();
    let mut searched =
        SparseMethod::from_options(&ctx, &scene, settings(24), &options).expect("budget mode");
    assert!(searched.budget.is_some());
    let pairs = searched
        .resolved_options()
        .expect("a budget choice resolves");
    let resolved = MethodOptions::from_pairs(pairs);
    for key in ["quality", "budget-ms", "target-flip", "budget-pilots"] {
        assert!(!resolved.given(key), "{key} in {resolved}");
    }
    let defaults = SparseSettings::default();
    let chosen = searched.settings;
    assert_ne!(
        (chosen.sparse_points, chosen.rsm, chosen.options.occlusion),
        (
            defaults.sparse_points,
            defaults.rsm,
            defaults.options.occlusion
        ),
        "the choice differs from the defaults, so the knobs must be written in"
    );
    valgi::method::check_options("sparse", &resolved).expect("options sparse takes");
    let mut rebuilt =
        SparseMethod::from_options(&ctx, &scene, settings(24), &resolved).expect("rebuilt");
    let again = rebuilt.settings;
    assert_eq!(
        (again.sparse_points, again.rsm, again.rsm_texels, again.seed),
        (chosen.sparse_points, chosen.rsm, chosen.rsm_texels, 7)
    );
    assert_eq!(
        (
            again.options.occlusion,
            again.options.adaptive_rays,
            again.options.glossy
        ),
        (
            chosen.options.occlusion,
            chosen.options.adaptive_rays,
            GlossyGather::Off
        )
    );
    assert!(rebuilt.budget.is_none() && rebuilt.resolved_options().is_none());
    let world = scene.world_from_node();
    let view = camera(&scene, 24);
    let indirect = |m: &mut SparseMethod| {
        m.render(&ctx, &scene, &world, &view)
            .expect("render")
            .indirect
            .pixels
    };
    let expected = indirect(&mut searched);
    assert!(expected.iter().any(|p| p[0] > 0.0), "an indirect image");
    assert!(indirect(&mut rebuilt) == expected);
}
