//! Emissive surfaces are lights in every method: the proxy lights of `scene::emitters` in the
//! GPU methods against the reference's sampling of the emissive triangles themselves, closed
//! forms for a small emitter, and the Khronos EmissiveStrengthTest.

mod common;

use glam::Vec3;
use valgi::gpu::GpuContext;
use valgi::image_io::Image;
use valgi::method::MethodOptions;
use valgi::reference::{self, Hit, Tracer};
use valgi::sampling::Rng;
use valgi::scene::emitters::{self, emissive_triangles};
use valgi::scene::{self, Instance, LightKind, LoadParams, Material, Mesh, Node, Scene, Trs};
use valgi::shading::WorldLight;

const PI: f32 = std::f32::consts::PI;

fn load(spec: &str, emitter_lights: u32) -> Scene {
    load_coarse(spec, emitter_lights, LoadParams::default().max_edge)
}

/// [`load`] tessellated to `max_edge` metres.
fn load_coarse(spec: &str, emitter_lights: u32, max_edge: f32) -> Scene {
    scene::load_with(
        spec,
        &LoadParams {
            emitter_lights,
            max_edge,
            ..LoadParams::default()
        },
    )
    .unwrap_or_else(|e| panic!("{spec}: {e}"))
}

/// The direct image (emission included) of `method` from the scene's first camera.
fn direct_image(
    ctx: &GpuContext,
    scene: &Scene,
    method: &str,
    size: u32,
    options: &[(&str, &str)],
) -> Image {
    let mut opts = MethodOptions::default();
    for (k, v) in options {
        opts.set(k, v);
    }
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).expect("camera");
    let mut m = valgi::method::create(
        method,
        ctx,
        scene,
        common::small_render_settings(size),
        &opts,
    )
    .unwrap_or_else(|e| panic!("{method}: {e}"));
    let frame = m.render(ctx, scene, &world, &camera).expect("render");
    assert_eq!(frame.direct.non_finite_count(), 0, "{method}: NaN or inf");
    frame.direct
}

/// The reference's direct image (emission, punctual lights and emitters sampled), no bounce.
fn reference_direct(ctx: &GpuContext, scene: &Scene, size: u32, spp: u32) -> Image {
    let spp = spp.to_string();
    direct_image(
        ctx,
        scene,
        "reference",
        size,
        &[("bounces", "0"), ("spp", &spp)],
    )
}

fn mean_flip(image: &Image, reference: &Image, exposure: f32) -> f64 {
    valgi::eval::metrics::flip(image, reference, exposure)
}

/// A one-sided emissive square of side `side` centred at `centre`, emitting toward −y.
fn emissive_square_scene(side: f32, centre: Vec3, radiance: Vec3) -> Scene {
    let h = side * 0.5;
    let c = centre;
    // Counter-clockwise seen from below: the winding's front faces −y.
    let positions = vec![
        c + Vec3::new(-h, 0.0, -h),
        c + Vec3::new(h, 0.0, -h),
        c + Vec3::new(h, 0.0, h),
        c + Vec3::new(-h, 0.0, h),
    ];
    let mesh = Mesh {
        name: "square".into(),
        normals: vec![Vec3::NEG_Y; 4],
        positions,
        indices: vec![0, 1, 2, 0, 2, 3],
        material: 0,
        ..Mesh::default()
    };
    let mut scene = Scene {
        name: "square".into(),
        nodes: vec![Node {
            name: "square".into(),
            parent: None,
            local: Trs::default(),
        }],
        meshes: vec![mesh],
        materials: vec![Material {
            emissive: radiance,
            ..Material::lambert("lamp", Vec3::ZERO)
        }],
        instances: vec![Instance { mesh: 0, node: 0 }],
        ..Scene::default()
    };
    emitters::add_emitter_lights(&mut scene, 1);
    scene
}

/// Irradiance at the origin of a receiver facing +y from a Lambertian emitter of radiance `l`
/// filling the rectangle [x0, x1] × [z0, z1] at height `height`, parallel to the receiver:
/// `E = L ∫∫ h² / (x² + z² + h²)² dx dz`, by the closed form of the corner rectangles.
fn parallel_rectangle_irradiance(l: f32, height: f32, x: [f32; 2], z: [f32; 2]) -> f64 {
    // π·L·F for the rectangle [0, a] × [0, b] with a corner above the receiver.
    let corner = |a: f64, b: f64| -> f64 {
        let s = a.signum() * b.signum();
        let (xa, yb) = (a.abs() / height as f64, b.abs() / height as f64);
        let (sx, sy) = ((1.0 + xa * xa).sqrt(), (1.0 + yb * yb).sqrt());
        s * 0.5 * (xa / sx * (yb / sx).atan() + yb / sy * (xa / sy).atan())
    };
    let f = corner(x[1] as f64, z[1] as f64)
        - corner(x[0] as f64, z[1] as f64)
        - corner(x[1] as f64, z[0] as f64)
        + corner(x[0] as f64, z[0] as f64);
    l as f64 * f
}

#[test]
fn a_small_emitters_proxy_gives_the_form_factor_irradiance_and_its_power() {
    let (side, height, radiance) = (0.2f32, 1.0f32, Vec3::new(1.0, 2.0, 0.5));
    let scene = emissive_square_scene(side, Vec3::new(0.0, height, 0.0), radiance);
    assert_eq!(scene.lights.len(), 1);
    let world = scene.world_from_node();
    let lights = WorldLight::from_scene(&scene, &world);
    let light = lights[0];
    assert_eq!(light.kind, LightKind::Emitter);
    // Power: π·I0 = π·Σ L_e·A.
    let emitted: Vec3 = emissive_triangles(&scene, &world)
        .iter()
        .map(|t| t.intensity())
        .sum::<Vec3>()
        * PI;
    let expected = radiance * side * side * PI;
    assert!((emitted - expected).abs().max_element() < 1e-5 * expected.max_element());
    let power = valgi::atlas::bake::light_power(&light).expect("an emitter has a power");
    assert!(
        (power - expected).abs().max_element() < 1e-4 * expected.max_element(),
        "{power} vs {expected}"
    );
    // Irradiance at receivers on the floor y = 0 facing up, below the centre and off to the
    // side (45° and about 63° off the axis), against the closed form for the square.
    for offset in [0.0f32, 1.0, 2.0] {
        let p = Vec3::new(offset, 0.0, 0.0);
        let (wi, e_normal) = light.incident(p);
        let e_proxy = e_normal * Vec3::Y.dot(wi).max(0.0);
        let h = side * 0.5;
        let exact = parallel_rectangle_irradiance(1.0, height, [-h - offset, h - offset], [-h, h]);
        for c in 0..3 {
            let exact_c = exact * radiance[c] as f64;
            let ratio = e_proxy[c] as f64 / exact_c;
            eprintln!(
                "offset {offset}: proxy {:.5e} exact {exact_c:.5e} ratio {ratio:.4}",
                e_proxy[c]
            );
            assert!(
                (ratio - 1.0).abs() < 0.03,
                "offset {offset} channel {c}: ratio {ratio}"
            );
        }
    }
    // A budget out of range is an error naming the option.
    let err = scene::load_with(
        "emissive-quad",
        &LoadParams {
            emitter_lights: emitters::MAX_EMITTER_LIGHTS + 1,
            ..LoadParams::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("--emitter-lights 65"), "{err}");
    // No light behind the emitter (its lobe).
    let (_, above) = light.incident(Vec3::new(0.0, 2.0 * height, 0.0));
    assert_eq!(above, Vec3::ZERO);
}

#[test]
fn the_reference_samples_emitters_to_the_form_factor_irradiance() {
    // A white Lambertian receiver: the reflected radiance is E/π.
    let (side, height, radiance) = (0.4f32, 0.5f32, Vec3::splat(3.0));
    let scene = emissive_square_scene(side, Vec3::new(0.0, height, 0.0), radiance);
    let world = scene.world_from_node();
    let tracer = Tracer::new(&scene, &world);
    let h = side * 0.5;
    for offset in [0.0f32, 0.3] {
        let p = Vec3::new(offset, 0.0, 0.0);
        let hit = Hit {
            t: 1.0,
            position: p,
            geometric_normal: Vec3::Y,
            normal: Vec3::Y,
            rho_d: Vec3::ONE,
            rho_s: Vec3::ZERO,
            k: 1.0,
            emission: Vec3::ZERO,
        };
        let n = 20000;
        let mut sum = 0.0f64;
        for s in 0..n {
            let mut rng = Rng::new(7, 0, s);
            sum += reference::emitter_light(&tracer, &hit, Vec3::Y, &mut rng).x as f64;
        }
        let e = sum / n as f64 * PI as f64;
        let exact =
            parallel_rectangle_irradiance(radiance.x, height, [-h - offset, h - offset], [-h, h]);
        eprintln!("offset {offset}: reference {e:.5} exact {exact:.5}");
        assert!(
            (e / exact - 1.0).abs() < 0.01,
            "offset {offset}: {e} vs {exact}"
        );
        // The proxy light is not counted again by the reference's punctual lights.
        assert_eq!(reference::direct_light(&tracer, &hit, Vec3::Y), Vec3::ZERO);
        // The methods' view of the same light keeps the proxy.
        assert!(tracer.direct_irradiance(p, Vec3::Y).x > 0.0);
    }
}

/// Luminance of a pixel.
fn lum(p: [f32; 4]) -> f64 {
    0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64
}

#[test]
fn an_emissive_quad_lights_direct_sparse_and_reference_alike() {
    let Some(ctx) = common::gpu() else { return };
    let size = 48;
    let scene = load("emissive-quad", emitters::DEFAULT_EMITTER_LIGHTS);
    assert!(scene.lights.iter().all(|l| l.kind == LightKind::Emitter));
    assert_eq!(
        scene.lights.len(),
        emitters::DEFAULT_EMITTER_LIGHTS as usize
    );
    let truth = reference_direct(&ctx, &scene, size, 256);
    let exposure = valgi::eval::metrics::auto_exposure(&truth);
    let direct = direct_image(&ctx, &scene, "direct", size, &[]);
    let sparse = direct_image(
        &ctx,
        &scene,
        "sparse",
        size,
        &[("rsm", "16"), ("sparse-points", "256")],
    );
    let flip_direct = mean_flip(&direct, &truth, exposure);
    let flip_sparse = mean_flip(&sparse, &truth, exposure);
    // The same scene without the cosine lobe (each proxy an isotropic point light of I0), and
    // with the proxies off.
    let mut no_lobe = scene.clone();
    for l in &mut no_lobe.lights {
        l.kind = LightKind::Point;
    }
    let flip_no_lobe = mean_flip(
        &direct_image(&ctx, &no_lobe, "direct", size, &[]),
        &truth,
        exposure,
    );
    let off = load("emissive-quad", 0);
    assert!(off.lights.is_empty());
    let flip_off = mean_flip(
        &direct_image(&ctx, &off, "direct", size, &[]),
        &truth,
        exposure,
    );
    // A second reference with another seed: the floor under which no method can get.
    let noise = {
        let mut m = valgi::method::create(
            "reference",
            &ctx,
            &scene,
            common::small_render_settings(size),
            &{
                let mut o = MethodOptions::default();
                o.set("bounces", "0");
                o.set("spp", "256");
                o.set("seed", "2");
                o
            },
        )
        .unwrap();
        let world = scene.world_from_node();
        let camera = scene.camera_view(None, 1.0, &world).unwrap();
        mean_flip(
            &m.render(&ctx, &scene, &world, &camera).unwrap().direct,
            &truth,
            exposure,
        )
    };
    eprintln!(
        "mean FLIP vs reference direct (exposure {exposure:.2}): direct {flip_direct:.4}, sparse \
         {flip_sparse:.4}, no lobe {flip_no_lobe:.4}, proxies off {flip_off:.4}, reference seed 2 \
         {noise:.4}"
    );
    // The walls are lit: the mean of the direct image is the reference's within 10%.
    let (m_direct, m_truth) = (
        valgi::eval::metrics::mean_luminance(&direct),
        valgi::eval::metrics::mean_luminance(&truth),
    );
    eprintln!("mean luminance: direct {m_direct:.4}, reference {m_truth:.4}");
    assert!(
        (m_direct / m_truth - 1.0).abs() < 0.1,
        "{m_direct} vs {m_truth}"
    );
    assert!(flip_direct < MAX_FLIP, "direct: {flip_direct}");
    assert!(flip_sparse < MAX_FLIP, "sparse: {flip_sparse}");
    assert!(flip_no_lobe > MAX_FLIP, "without the lobe: {flip_no_lobe}");
    assert!(flip_off > MAX_FLIP, "proxies off: {flip_off}");
}

/// Mean FLIP the direct images of `emissive-quad` may differ from the reference's by. Measured
/// on lavapipe (48², reference 256 spp, exposure 1.21): direct 0.0637, sparse 0.0637 (the same
/// direct pass), against 0.0105 between two reference seeds; without the cosine lobe 0.337,
/// with the proxies off 0.602.
const MAX_FLIP: f64 = 0.075;

#[test]
fn emissive_strength_test_lights_its_backdrop() {
    let Some(ctx) = common::gpu() else { return };
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/gltf-samples/EmissiveStrengthTest/EmissiveStrengthTest.glb"
    );
    if !std::path::Path::new(path).is_file() {
        eprintln!("SKIPPED: {path} not found");
        return;
    }
    let size = 48;
    // The 16 m backdrop at the default 5 cm edges is 128k triangles in 48 cube shadow-map
    // layers; 25 cm keeps the test short and changes nothing the test looks at.
    let max_edge = 0.25;
    let load = |budget| load_coarse(path, budget, max_edge);
    let scene = load(emitters::DEFAULT_EMITTER_LIGHTS);
    assert_eq!(
        scene.lights.len(),
        emitters::DEFAULT_EMITTER_LIGHTS as usize
    );
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).unwrap();
    // The backdrop's pixels: those wholly on the plane z = −2 (rays through their corners and
    // centre land there), so that the reference's anti-aliasing mixes no cube into them.
    let tracer = Tracer::new(&scene, &world);
    let backdrop: Vec<usize> = (0..size * size)
        .filter(|&i| {
            let (x, y) = ((i % size) as f32, (i / size) as f32);
            [
                (0.01, 0.01),
                (0.99, 0.01),
                (0.5, 0.5),
                (0.01, 0.99),
                (0.99, 0.99),
            ]
            .iter()
            .all(|(jx, jy)| {
                let (o, d) = reference::camera_ray(&camera, size, size, x + jx, y + jy);
                tracer
                    .intersect(o, d, f32::INFINITY)
                    .is_some_and(|h| (h.position.z + 2.0).abs() < 1e-3)
            })
        })
        .map(|i| i as usize)
        .collect();
    assert!(
        backdrop.len() > (size * size / 16) as usize,
        "{} backdrop pixels",
        backdrop.len()
    );
    let mean_over = |image: &Image| -> f64 {
        backdrop.iter().map(|&i| lum(image.pixels[i])).sum::<f64>() / backdrop.len() as f64
    };
    let truth = mean_over(&reference_direct(&ctx, &scene, size, 64));
    let direct = mean_over(&direct_image(&ctx, &scene, "direct", size, &[]));
    let sparse = mean_over(&direct_image(
        &ctx,
        &scene,
        "sparse",
        size,
        &[("rsm", "16"), ("sparse-points", "256")],
    ));
    let off = mean_over(&direct_image(&ctx, &load(0), "direct", size, &[]));
    // Five cubes of six faces: a light per face.
    let every_face = mean_over(&direct_image(&ctx, &load(30), "direct", size, &[]));
    eprintln!(
        "backdrop mean direct luminance: reference {truth:.4}, direct {direct:.4} ({:.3}), \
         sparse {sparse:.4} ({:.3}), a light per face {every_face:.4} ({:.3}), proxies off {off:.4}",
        direct / truth,
        sparse / truth,
        every_face / truth
    );
    assert!(truth > 0.0);
    assert_eq!(off, 0.0, "nothing but the emitters lights the backdrop");
    for (name, value) in [("direct", direct), ("sparse", sparse)] {
        let share = value / truth;
        assert!(
            BACKDROP_SHARE.contains(&share),
            "{name}: {value} vs reference {truth} ({share:.3} of it)"
        );
    }
    // With a light per face the lobes are the faces' own: closer to the reference.
    let share = every_face / truth;
    assert!(
        (share - 1.0).abs() < EVERY_FACE_TOLERANCE,
        "a light per face: {every_face} vs reference {truth} ({share:.3} of it)"
    );
}

/// The share of the reference's mean backdrop light the GPU methods give EmissiveStrengthTest
/// with the default 8 lights for its 30 emissive faces. Measured on lavapipe: 1.313 (direct
/// and sparse alike): merged faces' lobes aim some of the side faces' power at the backdrop.
/// Without the proxies the backdrop is black (0).
const BACKDROP_SHARE: std::ops::Range<f64> = 0.9..1.45;

/// How far from the reference a light per face may be. Measured: 1.090 of it (the faces are
/// 1 m squares 1.5 m from the backdrop, where a point emitter is a fair but not exact stand-in).
const EVERY_FACE_TOLERANCE: f64 = 0.15;

#[test]
fn the_direct_pass_lights_with_emitters_as_its_cpu_twin_does() {
    let Some(ctx) = common::gpu() else { return };
    let size = 32;
    let scene = load_coarse("emissive-quad", emitters::DEFAULT_EMITTER_LIGHTS, 0.25);
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).unwrap();
    let image = direct_image(&ctx, &scene, "direct", size, &[]);
    let tracer = Tracer::new(&scene, &world);
    let (mut compared, mut close) = (0, 0);
    for y in 0..size {
        for x in 0..size {
            let (o, d) = reference::camera_ray(&camera, size, size, x as f32 + 0.5, y as f32 + 0.5);
            let Some(hit) = tracer.intersect(o, d, f32::INFINITY) else {
                continue;
            };
            if hit.emission != Vec3::ZERO {
                continue;
            }
            // `shading::WorldLight::reflected` with ray-traced visibility: the shadow maps
            // are the GPU's only other ingredient.
            let mut twin = Vec3::ZERO;
            for light in &tracer.lights {
                let (wi, _) = light.incident(hit.position);
                let origin = tracer.spawn(&hit, wi);
                let t_max = (light.position - origin).length() - tracer.epsilon;
                if tracer.unoccluded(origin, wi, t_max) {
                    twin +=
                        light.reflected(hit.position, hit.normal, o, hit.rho_d, hit.rho_s, hit.k);
                }
            }
            let gpu = Vec3::from_slice(&image.get(x, y)[..3]);
            compared += 1;
            if (gpu - twin).abs().max_element() <= 0.01 * twin.max_element() + 1e-5 {
                close += 1;
            }
        }
    }
    eprintln!("{close} of {compared} pixels within 1% of the CPU twin");
    assert!(compared > (size * size / 2) as usize);
    // Pixels straddling a wall edge see another surface at the pixel centre than the ray.
    assert!(
        close as f64 > 0.95 * compared as f64,
        "{close} of {compared}"
    );
}

#[test]
fn an_emitters_rsm_reflects_rho_times_pi_i0_in_a_closed_box() {
    let Some(ctx) = common::gpu() else { return };
    // box-point's 1 W/sr point light made an emitter facing down: every direction of its lobe
    // hits a wall of albedo 0.5, so the RSM holds Φ = 0.5·π·1 W (a point light's is 0.5·4π).
    let mut scene = valgi::scene::builtin::load(
        "box-point",
        &valgi::scene::builtin::BuiltinParams { max_edge: 0.5 },
    )
    .unwrap();
    let node = scene.lights[0].node;
    scene.nodes[node].local.rotation = glam::Quat::from_rotation_arc(Vec3::NEG_Z, Vec3::NEG_Y);
    scene.lights[0].kind = LightKind::Emitter;
    let settings = valgi::vals::SparseSettings {
        rsm: 64,
        sparse_points: 64,
        ..Default::default()
    };
    let mut method =
        valgi::vals::SparseMethod::new(&ctx, &scene, common::small_render_settings(32), settings)
            .unwrap();
    method.last_stage = valgi::vals::Stage::Gather;
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).unwrap();
    use valgi::method::Method;
    method.render(&ctx, &scene, &world, &camera).unwrap();
    let vals = method.rsm.read_vals(&ctx).unwrap();
    let total: Vec3 = vals.iter().map(|v| v.flux).sum();
    let expected = 0.5 * PI;
    eprintln!("emitter RSM flux {total} vs {expected}");
    assert!(
        (total.x - expected).abs() < 2e-3 * expected,
        "reflected flux {total} vs {expected}"
    );
    // Nothing comes from behind the lobe: the upper half of the box holds no flux.
    let above: f32 = vals
        .iter()
        .filter(|v| v.position.y > 1e-3)
        .map(|v| v.flux.x)
        .sum();
    assert_eq!(above, 0.0);
}

/// `method` with the options `pairs` at `size`² (the tests' small render settings).
fn create_method(
    ctx: &GpuContext,
    scene: &Scene,
    method: &str,
    size: u32,
    pairs: &[(&str, &str)],
) -> Box<dyn valgi::method::Method> {
    let mut options = MethodOptions::default();
    for (k, v) in pairs {
        options.set(k, v);
    }
    valgi::method::create(
        method,
        ctx,
        scene,
        common::small_render_settings(size),
        &options,
    )
    .unwrap_or_else(|e| panic!("{method}: {e}"))
}

/// Every GPU method takes the emitter proxies: they share `direct`'s direct pass (same
/// pixels), and their indirect light, which exists only through the proxies' RSMs in a scene
/// lit by nothing else, is there and of the reference's one-bounce order.
#[test]
fn every_gpu_method_is_lit_by_the_emitter_proxies() {
    let Some(ctx) = common::gpu() else { return };
    let size = 24;
    let scene = load("emissive-quad", emitters::DEFAULT_EMITTER_LIGHTS);
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).expect("camera");
    let direct = direct_image(&ctx, &scene, "direct", size, &[]);
    let reference = reference::render(
        &scene,
        &world,
        &camera,
        &reference::ReferenceSettings {
            width: size,
            height: size,
            spp: 64,
            progress: false,
            ..Default::default()
        },
    );
    let reference_indirect = reference.indirect.mean_rgb()[0];
    assert!(reference_indirect > 0.0);
    // Measured on lavapipe: brute 0.999, negative 1.050 (both gather the same VALs the
    // reference's one bounce integrates); LPV 0.276 and HO-LPV 0.443 at a 16³ grid, the
    // propagation's known energy loss in a small box. Without the proxies all four are 0.
    let vals = 0.85..1.15;
    let volumes = 0.2..1.5;
    for (method, options, range) in [
        ("brute", vec![("rsm", "16")], &vals),
        (
            "lpv",
            vec![("rsm", "16"), ("grid", "16"), ("steps", "8")],
            &volumes,
        ),
        (
            "holpv",
            vec![("rsm", "16"), ("grid", "16"), ("steps", "8")],
            &volumes,
        ),
        ("negative", vec![("rsm", "16")], &vals),
    ] {
        let mut m = create_method(&ctx, &scene, method, size, &options);
        let frame = m.render(&ctx, &scene, &world, &camera).expect("render");
        let worst = frame
            .direct
            .pixels
            .iter()
            .zip(&direct.pixels)
            .map(|(a, b)| (a[0] - b[0]).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst < 1e-5,
            "{method}: direct differs from 'direct' by {worst}"
        );
        assert_eq!(frame.indirect.non_finite_count(), 0, "{method}");
        let ratio = frame.indirect.mean_rgb()[0] / reference_indirect;
        eprintln!("{method}: indirect mean / reference {ratio:.3}");
        assert!(
            range.contains(&ratio),
            "{method}: indirect mean is {ratio:.3} of the reference's, outside {range:?}"
        );
    }
}

/// Without `--rsm`, a scene's lights share one point light's RSM texels by power
/// (`light::rsm::DEFAULT_SHARED_TEXELS`): the eight proxies of the emissive quad make a
/// fraction of the VALs they make at 128² each, and the indirect light keeps its power (each
/// VAL carries its share of the flux). Sparse and brute force gather the same VALs.
#[test]
fn lights_share_the_default_rsm_texels_and_keep_their_power() {
    let Some(ctx) = common::gpu() else { return };
    let size = 24;
    let scene = load("emissive-quad", emitters::DEFAULT_EMITTER_LIGHTS);
    assert!(scene.lights.len() > 1);
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world).expect("camera");
    let render = |method: &str, pairs: &[(&str, &str)]| {
        let mut m = create_method(&ctx, &scene, method, size, pairs);
        let frame = m.render(&ctx, &scene, &world, &camera).expect("render");
        let vals = m.report()["vals"].as_u64().expect("vals");
        (frame.indirect.mean_rgb()[0], vals, m.report())
    };
    let points = [("sparse-points", "256")];
    let (shared, shared_vals, report) = render("sparse", &points);
    let (full, full_vals, _) = render("sparse", &[points[0], ("rsm", "128")]);
    let (brute, brute_vals, _) = render("brute", &[]);
    let sides: Vec<u64> = report["rsm_light_sides"]
        .as_array()
        .expect("rsm_light_sides")
        .iter()
        .map(|s| s.as_u64().unwrap())
        .collect();
    eprintln!(
        "shared: {shared_vals} VALs, sides {sides:?}, indirect {shared:.4e}; rsm 128: \
         {full_vals} VALs, {full:.4e}; brute {brute_vals} VALs, {brute:.4e}"
    );
    let texels: u64 = sides.iter().map(|s| 6 * s * s).sum();
    assert!(texels <= valgi::light::rsm::DEFAULT_SHARED_TEXELS as u64);
    assert!(sides.iter().all(|&s| s < 128), "{sides:?}");
    assert!(
        full_vals > 2 * shared_vals,
        "{full_vals} VALs at 128² against {shared_vals} shared"
    );
    assert_eq!(brute_vals, shared_vals, "brute force shares the same way");
    assert!(
        (shared / full - 1.0).abs() < 0.05,
        "indirect mean shared {shared:.4e} against {full:.4e} at 128²"
    );
}
