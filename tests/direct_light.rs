//! Direct lighting against closed-form answers on the software Vulkan device: a point light
//! over a plane, the KHR spot cone, a blocker's shadow, the Cornell box's orientation, SSAA,
//! and a scene without lights.

mod common;

use glam::{Vec3, Vec4};
use valgi::gpu::GpuContext;
use valgi::image_io::Image;
use valgi::raster::{FrameOutput, Rasterizer, RenderSettings};
use valgi::scene::builtin::{self, BuiltinParams};
use valgi::scene::{CameraView, LightKind, Scene};

const ALBEDO: f32 = 0.8;

fn load(name: &str) -> Scene {
    builtin::load(name, &BuiltinParams::default()).expect("built-in scene")
}

fn render(ctx: &GpuContext, scene: &Scene, settings: RenderSettings) -> (FrameOutput, CameraView) {
    let world = scene.world_from_node();
    let camera = scene
        .camera_view(None, settings.width as f32 / settings.height as f32, &world)
        .expect("camera");
    let raster = Rasterizer::new(ctx, scene, settings).expect("rasterizer");
    // The direct pass reads lights and shadow views from uniform blocks when they fit, else
    // from the storage buffers; each path is checked by the tests that reach it.
    let views: u32 = scene.lights.iter().map(|l| l.kind.shadow_layers()).sum();
    assert_eq!(
        raster.lights_in_block(),
        scene.lights.len() <= valgi::raster::LIGHT_BLOCK as usize
            && views <= valgi::raster::VIEW_BLOCK
    );
    let frame = raster
        .render_direct(ctx, scene, &world, &camera)
        .expect("render");
    assert_eq!(
        frame.direct.non_finite_count(),
        0,
        "NaN or inf in the image"
    );
    (frame, camera)
}

fn small(width: u32, height: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        shadow_resolution: 512,
        ..RenderSettings::default()
    }
}

/// Where the ray through pixel (x, y)'s centre meets the plane y = 0.
fn pixel_on_ground(camera: &CameraView, image: &Image, x: u32, y: u32) -> Option<Vec3> {
    let clip_from_world = camera.clip_from_world();
    let world_from_clip = clip_from_world.inverse();
    let ndc_x = (x as f32 + 0.5) / image.width as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - (y as f32 + 0.5) / image.height as f32 * 2.0;
    let unproject = |z: f32| {
        let p = world_from_clip * Vec4::new(ndc_x, ndc_y, z, 1.0);
        p.truncate() / p.w
    };
    let (a, b) = (unproject(0.0), unproject(1.0));
    let t = a.y / (a.y - b.y);
    (t > 0.0 && t < 1.0).then(|| a + (b - a) * t)
}

fn light_position(scene: &Scene) -> Vec3 {
    let world = scene.world_from_node();
    world[scene.lights[0].node].transform_point3(Vec3::ZERO)
}

#[test]
fn point_light_over_plane_matches_inverse_square_cosine_law() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("plane-point");
    let (frame, camera) = render(&ctx, &scene, small(96, 96));
    let light = light_position(&scene);
    let intensity = scene.lights[0].radiometric().x;
    let mut checked = 0;
    let mut worst: f32 = 0.0;
    for y in (4..96).step_by(7) {
        for x in (4..96).step_by(7) {
            let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) else {
                continue;
            };
            if p.x.abs() > 1.9 || p.z.abs() > 1.9 {
                continue; // off the 4 m plane
            }
            let to_light = light - p;
            let d = to_light.length();
            let cos = to_light.y / d;
            let expected = ALBEDO / std::f32::consts::PI * intensity * cos / (d * d);
            let got = frame.direct.get(x, y)[0];
            let rel = (got - expected).abs() / expected;
            worst = worst.max(rel);
            checked += 1;
        }
    }
    assert!(checked > 100, "only {checked} pixels landed on the plane");
    assert!(worst < 0.01, "worst relative error {worst} ≥ 1%");
}

/// A thousand point lights over the plane within the default shadow budget (6000 cube faces:
/// 24 GB at full resolution): every light's shadow map is a small tile, none may shadow the
/// open plane, and the sum is the inverse-square cosine law over all of them. With a budget
/// too small for all of them, the dimmest go unshadowed and the plane is lit the same.
#[test]
fn a_thousand_point_lights_render_within_the_shadow_budget() {
    let Some(ctx) = common::gpu() else { return };
    let mut scene = load("plane-point");
    let template = scene.lights[0].clone();
    scene.lights.clear();
    // A 10×10×10 lattice 0.5–1.5 m above the 4 m plane, powers spread over 10×.
    for i in 0..1000 {
        let (a, b, c) = (i % 10, (i / 10) % 10, i / 100);
        scene.nodes.push(valgi::scene::Node {
            name: format!("light {i}"),
            parent: None,
            local: valgi::scene::Trs {
                translation: Vec3::new(
                    -1.35 + 0.3 * a as f32,
                    0.5 + 0.1 * c as f32,
                    -1.35 + 0.3 * b as f32,
                ),
                ..Default::default()
            },
        });
        let mut light = template.clone();
        light.node = scene.nodes.len() - 1;
        light.intensity = template.intensity * (0.1 + 0.9 * ((i * 7) % 10) as f32 / 9.0) / 100.0;
        scene.lights.push(light);
    }
    let lights: Vec<(Vec3, f32)> = {
        let world = scene.world_from_node();
        scene
            .lights
            .iter()
            .map(|l| {
                (
                    world[l.node].transform_point3(Vec3::ZERO),
                    l.radiometric().x,
                )
            })
            .collect()
    };
    let settings = RenderSettings {
        shadow_resolution: 1024,
        ..small(48, 48)
    };
    // 1 MiB holds 1024 views of 16²: 170 lights keep shadows, the other 830 go without.
    let partly_shadowed = RenderSettings {
        shadow_resolution: 16,
        shadow_memory_mib: 1,
        ..settings
    };
    for settings in [settings, partly_shadowed] {
        let (frame, camera) = render(&ctx, &scene, settings);
        let (mut checked, mut worst) = (0, 0.0f32);
        for y in (2..48).step_by(5) {
            for x in (2..48).step_by(5) {
                let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) else {
                    continue;
                };
                if p.x.abs() > 1.9 || p.z.abs() > 1.9 {
                    continue;
                }
                let expected: f32 = lights
                    .iter()
                    .map(|&(light, intensity)| {
                        let to_light = light - p;
                        let d2 = to_light.length_squared();
                        ALBEDO / std::f32::consts::PI * intensity * to_light.y / (d2 * d2.sqrt())
                    })
                    .sum();
                let got = frame.direct.get(x, y)[0];
                worst = worst.max((got - expected).abs() / expected);
                checked += 1;
            }
        }
        assert!(checked > 30, "only {checked} pixels on the plane");
        assert!(
            worst < 0.01,
            "shadow memory {} MiB: worst relative error {worst}",
            settings.shadow_memory_mib
        );
    }
}

#[test]
fn spot_cone_follows_khr_falloff() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("plane-spot");
    let LightKind::Spot {
        inner_cone_angle,
        outer_cone_angle,
    } = scene.lights[0].kind
    else {
        panic!("plane-spot must have a spot light");
    };
    let (frame, camera) = render(&ctx, &scene, small(128, 128));
    let light = light_position(&scene);
    let intensity = scene.lights[0].radiometric().x;
    let scale = 1.0 / (inner_cone_angle.cos() - outer_cone_angle.cos()).max(0.001);
    let offset = -outer_cone_angle.cos() * scale;
    let peak = ALBEDO / std::f32::consts::PI * intensity / (light.y * light.y);
    let (mut inside, mut ramp, mut outside) = (0, 0, 0);
    let mut worst: f32 = 0.0;
    for y in 0..128 {
        for x in 0..128 {
            let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) else {
                continue;
            };
            let to_light = light - p;
            let d = to_light.length();
            let cos_spot = to_light.y / d; // the spot points straight down
            let angle = cos_spot.acos();
            let attenuation = (cos_spot * scale + offset).clamp(0.0, 1.0).powi(2);
            let expected =
                ALBEDO / std::f32::consts::PI * intensity * attenuation * cos_spot / (d * d);
            let got = frame.direct.get(x, y)[0];
            // Error relative to the peak: the ramp goes to zero at the outer edge.
            worst = worst.max((got - expected).abs() / peak);
            if angle < inner_cone_angle {
                inside += 1;
            } else if angle < outer_cone_angle {
                ramp += 1;
            } else {
                outside += 1;
                assert_eq!(got, 0.0, "light outside the outer cone at ({x}, {y})");
            }
        }
    }
    assert!(
        inside > 50 && ramp > 50 && outside > 50,
        "{inside}/{ramp}/{outside}"
    );
    assert!(worst < 0.01, "worst error {worst} of the peak");
}

#[test]
fn blocker_casts_its_geometric_shadow() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("plane-blocker");
    let (frame, camera) = render(&ctx, &scene, small(128, 128));
    let light = light_position(&scene);
    let intensity = scene.lights[0].radiometric().x;
    // The blocker spans |x|,|z| ≤ 0.2 at heights 0.49–0.5 under a light at height 1: its
    // umbra on the ground spans |x|,|z| ≤ 0.2·1/(1−0.49) ≈ 0.392, its outer edge 0.4. Seen
    // from the camera at height 2.5 the blocker itself hides the ground out to
    // 0.2·2.5/(2.5−0.5) = 0.25, so the visible umbra is the ring 0.25 < max(|x|,|z|) < 0.39.
    let (mut shadowed, mut lit) = (0, 0);
    for y in 0..128 {
        for x in 0..128 {
            let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) else {
                continue;
            };
            let got = frame.direct.get(x, y)[0];
            let m = p.x.abs().max(p.z.abs());
            if m > 0.27 && m < 0.37 {
                assert!(got < 1e-4, "light leaks into the umbra at {p}: {got}");
                shadowed += 1;
            } else if m > 0.45 && m < 1.9 {
                let to_light = light - p;
                let d = to_light.length();
                let expected =
                    ALBEDO / std::f32::consts::PI * intensity * (to_light.y / d) / (d * d);
                assert!(
                    (got - expected).abs() < 0.01 * expected,
                    "false shadow or wrong light at {p}: {got} vs {expected}"
                );
                lit += 1;
            }
        }
    }
    assert!(
        shadowed > 100 && lit > 100,
        "{shadowed} shadowed, {lit} lit"
    );
}

/// Mean RGB over a rectangle of pixels given as fractions of the image.
fn region_mean(image: &Image, x0: f32, x1: f32, y0: f32, y1: f32) -> Vec3 {
    let mut sum = Vec3::ZERO;
    let mut n = 0.0;
    for y in (y0 * image.height as f32) as u32..(y1 * image.height as f32) as u32 {
        for x in (x0 * image.width as f32) as u32..(x1 * image.width as f32) as u32 {
            let p = image.get(x, y);
            sum += Vec3::new(p[0], p[1], p[2]);
            n += 1.0;
        }
    }
    sum / n
}

#[test]
fn cornell_box_direct_light_is_oriented_and_plausible() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("cornell");
    let (frame, _) = render(&ctx, &scene, small(96, 96));
    let img = &frame.direct;
    let left_wall = region_mean(img, 0.08, 0.14, 0.4, 0.6);
    let right_wall = region_mean(img, 0.86, 0.92, 0.4, 0.6);
    let ceiling = region_mean(img, 0.3, 0.7, 0.04, 0.1);
    let floor = region_mean(img, 0.3, 0.45, 0.9, 0.97);
    assert!(
        left_wall.x > 3.0 * left_wall.y,
        "left wall is not red: {left_wall}"
    );
    assert!(
        right_wall.y > 2.0 * right_wall.x,
        "right wall is not green: {right_wall}"
    );
    assert_eq!(
        ceiling,
        Vec3::ZERO,
        "a downward spot must leave the ceiling black"
    );
    assert!(floor.x > 0.05, "floor under the spot is not lit: {floor}");
}

#[test]
fn supersampling_is_a_box_filter_of_the_finer_grid() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("cornell");
    let (fine, _) = render(&ctx, &scene, small(64, 64));
    let (ssaa, _) = render(
        &ctx,
        &scene,
        RenderSettings {
            ssaa: 2,
            ..small(32, 32)
        },
    );
    let mut worst: f32 = 0.0;
    let mut partial_edge_pixels = 0;
    for y in 0..32 {
        for x in 0..32 {
            let mut mean = [0.0f32; 3];
            let mut lum = Vec::new();
            for (sx, sy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let p = fine.direct.get(2 * x + sx, 2 * y + sy);
                for c in 0..3 {
                    mean[c] += p[c] / 4.0;
                }
                lum.push(p[0] + p[1] + p[2]);
            }
            let got = ssaa.direct.get(x, y);
            for c in 0..3 {
                worst = worst.max((got[c] - mean[c]).abs() / mean[c].max(1e-2));
            }
            let (lo, hi) = lum
                .iter()
                .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
            if hi > 2.0 * lo + 0.01 {
                partial_edge_pixels += 1;
            }
        }
    }
    assert!(
        worst < 1e-3,
        "SSAA differs from the 2×2 mean of the fine image by {worst}"
    );
    assert!(
        partial_edge_pixels > 10,
        "expected edges to average distinct samples"
    );
}

#[test]
fn scene_without_lights_renders_black_without_nan() {
    let Some(ctx) = common::gpu() else { return };
    let mut scene = load("plane-point");
    scene.lights.clear();
    let (frame, _) = render(&ctx, &scene, small(32, 32));
    assert!(frame
        .direct
        .pixels
        .iter()
        .all(|p| p[..3] == [0.0, 0.0, 0.0]));
}

#[test]
fn exr_round_trip_of_a_rendered_image_is_exact() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("cornell-point");
    let (frame, _) = render(&ctx, &scene, small(40, 30));
    let dir = common::temp_dir("exr");
    let path = dir.join("cornell-point.exr");
    frame.direct.write_exr(&path).expect("write exr");
    let back = Image::read_exr(&path).expect("read exr");
    assert_eq!(back, frame.direct);
    assert!(frame.direct.mean_rgb()[0] > 0.0);
}

/// A glTF written by another tool (pygltflib; see data/gltf/) with a coloured spot light and a
/// pure-Lambert material renders in the physical units of DESIGN §3: intensity × color in
/// W/sr, radiance ρ/π · I · attenuation · cosθ / d².
#[test]
fn external_gltf_spot_on_lambert_plane_is_in_physical_units() {
    let Some(ctx) = common::gpu() else { return };
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/gltf/spot_lambert_plane.gltf");
    let scene = valgi::scene::gltf_import::load(&path).expect("load glTF");
    assert_eq!(scene.materials[0].specular_factor, 0.0);
    let (frame, camera) = render(&ctx, &scene, small(96, 64));
    let light = light_position(&scene);
    let radiant_intensity = Vec3::new(2.0, 1.0, 0.5);
    let rho = 0.5;
    let (inner, outer) = (0.3f32, 0.6f32);
    let scale = 1.0 / (inner.cos() - outer.cos());
    let offset = -outer.cos() * scale;
    let peak = rho / std::f32::consts::PI * radiant_intensity.x / (light.y * light.y);
    let mut lit = 0;
    for y in 0..64 {
        for x in 0..96 {
            let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) else {
                continue;
            };
            if p.x.abs() > 0.98 || p.z.abs() > 0.98 {
                continue;
            }
            let to_light = light - p;
            let d = to_light.length();
            let cos = to_light.y / d;
            let attenuation = (cos * scale + offset).clamp(0.0, 1.0).powi(2);
            let expected =
                radiant_intensity * (rho / std::f32::consts::PI * attenuation * cos / (d * d));
            let got = frame.direct.get(x, y);
            for c in 0..3 {
                assert!(
                    (got[c] - expected[c]).abs() < 0.01 * peak,
                    "pixel ({x}, {y}) channel {c}: {} vs {}",
                    got[c],
                    expected[c]
                );
            }
            if attenuation > 0.99 {
                lit += 1;
            }
        }
    }
    assert!(lit > 50, "only {lit} pixels in the full cone");
}

#[test]
fn pass_timings_cover_every_pass_with_queries_and_with_the_wall_clock_fallback() {
    let Some(mut ctx) = common::gpu() else { return };
    let scene = load("cornell-point");
    let (with_queries, _) = render(&ctx, &scene, small(32, 32));
    ctx.timestamps = false;
    let (wall_clock, _) = render(&ctx, &scene, small(32, 32));
    assert!(!wall_clock.timings.gpu_timestamps);
    for frame in [&with_queries, &wall_clock] {
        for pass in ["shadow", "gbuffer", "direct", "resolve"] {
            let ms = frame.timings.get(pass).unwrap_or(-1.0);
            assert!(
                ms >= 0.0,
                "pass {pass} not timed: {:?}",
                frame.timings.passes
            );
        }
        assert!(frame.timings.total_ms() > 0.0);
    }
    // Both modes render the same image.
    assert_eq!(with_queries.direct, wall_clock.direct);
}

#[test]
fn directional_light_gives_uniform_irradiance_and_an_oblique_shadow() {
    let Some(ctx) = common::gpu() else { return };
    let scene = load("plane-directional");
    let (frame, camera) = render(&ctx, &scene, small(128, 128));
    let world = scene.world_from_node();
    let direction = world[scene.lights[0].node]
        .transform_vector3(Vec3::NEG_Z)
        .normalize();
    let irradiance = scene.lights[0].radiometric().x;
    let expected = ALBEDO / std::f32::consts::PI * irradiance * (-direction.y);
    // The blocker (|x|,|z| ≤ 0.2, height 0.49–0.5) shifts its shadow by height·tan 30°.
    let shift = 0.495 * direction.x / -direction.y;
    let (mut shadowed, mut lit) = (0, 0);
    for y in 0..128 {
        for x in 0..128 {
            let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) else {
                continue;
            };
            let got = frame.direct.get(x, y)[0];
            let hidden_by_blocker = p.x.abs() < 0.27 && p.z.abs() < 0.27;
            let in_shadow = (p.x - shift).abs() < 0.17 && p.z.abs() < 0.17;
            let clear = (p.x - shift).abs() > 0.25 || p.z.abs() > 0.25;
            if hidden_by_blocker || p.x.abs() > 1.9 || p.z.abs() > 1.9 {
                continue;
            }
            if in_shadow {
                assert!(got < 1e-4, "light in the shadow at {p}: {got}");
                shadowed += 1;
            } else if clear {
                assert!(
                    (got - expected).abs() < 0.01 * expected,
                    "at {p}: {got} vs {expected}"
                );
                lit += 1;
            }
        }
    }
    assert!(
        shadowed > 20 && lit > 1000,
        "{shadowed} shadowed, {lit} lit"
    );
}

/// Where a ray from `origin` along `dir` leaves the cube [−1, 1]³.
fn exit_cube(origin: Vec3, dir: Vec3) -> Vec3 {
    let t = [dir.x, dir.y, dir.z]
        .iter()
        .zip([origin.x, origin.y, origin.z])
        .map(|(&d, o)| {
            if d > 0.0 {
                (1.0 - o) / d
            } else if d < 0.0 {
                (-1.0 - o) / d
            } else {
                f32::MAX
            }
        })
        .fold(f32::MAX, f32::min);
    origin + dir * t
}

/// A point light inside a closed box lights every wall through its own cube-map face. Six
/// small blockers, one on each axis, must each shadow the wall behind them (so every face is
/// looked up with its own view), and everywhere else the walls follow the inverse-square
/// cosine law (no false shadows at face seams).
#[test]
fn point_light_cube_shadow_faces_each_shadow_their_own_wall() {
    let Some(ctx) = common::gpu() else { return };
    cube_faces_shadow_their_own_walls(&ctx, small(96, 96));
}

/// The same six shadows with the cube's faces packed as 128² tiles into one 512² layer (a
/// 1 MiB budget): a tile read at a wrong offset, or a filter tap reaching into a neighbour's
/// tile, puts a shadow on the wrong wall or a false one on a lit wall.
#[test]
fn point_light_cube_shadows_survive_packing_into_tiles_of_one_layer() {
    let Some(ctx) = common::gpu() else { return };
    cube_faces_shadow_their_own_walls(
        &ctx,
        RenderSettings {
            shadow_memory_mib: 1,
            ..small(96, 96)
        },
    );
}

fn cube_faces_shadow_their_own_walls(ctx: &GpuContext, settings: RenderSettings) {
    let mut scene = load("box-point");
    // 0.1 m squares 0.5 m from the light: their umbra on the walls (1 m away) is 0.2 m wide.
    let (blocker_half, blocker_distance) = (0.05, 0.5);
    let mut blockers = valgi::scene::mesh::MeshBuilder::new("blockers", scene.meshes[0].material);
    for axis in [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ] {
        let u = axis.any_orthonormal_vector() * blocker_half;
        let v = axis.cross(u);
        let c = axis * blocker_distance;
        blockers.add_quad(c - u - v, c + u - v, c + u + v, c - u + v, Vec3::ZERO, 0.05);
    }
    scene.meshes.push(blockers.build());
    scene.instances.push(valgi::scene::Instance {
        mesh: scene.meshes.len() - 1,
        node: scene.instances[0].node,
    });
    let world = scene.world_from_node();
    let raster = Rasterizer::new(ctx, &scene, settings).expect("rasterizer");
    let umbra_half = blocker_half / blocker_distance;
    let mut worst: f32 = 0.0;
    let (mut lit, mut shadowed_walls) = (0, std::collections::HashSet::new());
    // Off-axis eyes, so the blockers on the z axis do not hide their own shadows.
    for (eye, target) in [
        (Vec3::new(0.5, 0.4, 0.9), Vec3::new(0.0, 0.0, -1.0)),
        (Vec3::new(-0.5, -0.4, -0.9), Vec3::new(0.0, 0.0, 1.0)),
    ] {
        let view_from_world = glam::camera::rh::view::look_at_mat4(eye, target, Vec3::Y);
        let camera = CameraView {
            world_from_view: view_from_world.inverse(),
            yfov: 100f32.to_radians(),
            aspect: 1.0,
            znear: 0.01,
            zfar: 4.0,
            off_axis: None,
        };
        let frame = raster.render_direct(ctx, &scene, &world, &camera).unwrap();
        let world_from_clip = camera.clip_from_world().inverse();
        for y in 0..96 {
            for x in 0..96 {
                let ndc_x = (x as f32 + 0.5) / 96.0 * 2.0 - 1.0;
                let ndc_y = 1.0 - (y as f32 + 0.5) / 96.0 * 2.0;
                let far = world_from_clip * Vec4::new(ndc_x, ndc_y, 1.0, 1.0);
                let eye = camera.position();
                let dir = (far.truncate() / far.w - eye).normalize();
                let p = exit_cube(eye, dir);
                // The camera must not look at a blocker itself.
                let through_blocker = [
                    Vec3::X,
                    Vec3::NEG_X,
                    Vec3::Y,
                    Vec3::NEG_Y,
                    Vec3::Z,
                    Vec3::NEG_Z,
                ]
                .iter()
                .any(|axis| {
                    let t = (blocker_distance - axis.dot(eye)) / axis.dot(dir);
                    let q = eye + dir * t;
                    t > 0.0
                        && (q - *axis * blocker_distance).abs().max_element() < blocker_half + 0.02
                });
                let on_edge = [p.x, p.y, p.z].iter().filter(|c| c.abs() > 0.97).count() > 1;
                if through_blocker || on_edge {
                    continue;
                }
                let wall_axis = if p.x.abs() > 0.999 {
                    Vec3::new(p.x.signum(), 0.0, 0.0)
                } else if p.y.abs() > 0.999 {
                    Vec3::new(0.0, p.y.signum(), 0.0)
                } else {
                    Vec3::new(0.0, 0.0, p.z.signum())
                };
                let in_plane = (p - wall_axis).abs().max_element();
                let got = frame.direct.get(x, y)[0];
                if in_plane < umbra_half - 0.03 {
                    assert!(got < 1e-4, "wall {wall_axis} not shadowed at {p}: {got}");
                    shadowed_walls.insert(format!("{wall_axis}"));
                } else if in_plane > umbra_half + 0.03 {
                    let d = p.length();
                    let expected = 0.5 / std::f32::consts::PI * wall_axis.dot(p / d) / (d * d);
                    worst = worst.max((got - expected).abs() / expected);
                    lit += 1;
                }
            }
        }
    }
    assert_eq!(
        shadowed_walls.len(),
        6,
        "shadows seen on {shadowed_walls:?}"
    );
    assert!(lit > 5000, "{lit}");
    assert!(worst < 0.01, "worst relative error {worst}");
}

/// The glossy lobe on the GPU against the CPU twin (`valgi::shading`), per pixel, for
/// dielectric and metallic materials and a scaled `KHR_materials_specular` factor: the view
/// direction, ρ_s, k and the normalization (k+2)/(2π) all show in the highlight.
#[test]
fn glossy_materials_match_the_cpu_twin_per_pixel() {
    let Some(ctx) = common::gpu() else { return };
    use valgi::scene::Material;
    use valgi::shading::WorldLight;
    // (base colour, metallic, roughness, specular factor)
    let materials = [
        (Vec3::new(0.6, 0.3, 0.2), 0.0, 0.3, 1.0),
        (Vec3::new(0.9, 0.7, 0.3), 1.0, 0.45, 1.0),
        (Vec3::new(0.5, 0.5, 0.5), 0.0, 0.2, 0.5),
    ];
    for (base, metallic, roughness, specular_factor) in materials {
        let mut scene = load("plane-point");
        // Move the light off the camera's axis so the highlight is away from the centre.
        let light_node = scene.lights[0].node;
        scene.nodes[light_node].local.translation = Vec3::new(0.4, 1.0, 0.2);
        scene.materials[0] = Material {
            base_color: base.extend(1.0),
            metallic,
            roughness,
            specular_factor,
            ..Material::lambert("glossy", base)
        };
        let (frame, camera) = render(&ctx, &scene, small(96, 96));
        let world = scene.world_from_node();
        let lights = WorldLight::from_scene(&scene, &world);
        let rho_d = Material::diffuse_albedo(base, metallic);
        let rho_s = Material::specular_albedo(base, metallic, specular_factor);
        let k = Material::phong_exponent(roughness);
        let mut peak: f32 = 0.0;
        let mut expected_image = Vec::new();
        for y in 0..96 {
            for x in 0..96 {
                if let Some(p) = pixel_on_ground(&camera, &frame.direct, x, y) {
                    if p.x.abs() < 1.9 && p.z.abs() < 1.9 {
                        let e = lights[0].reflected(p, Vec3::Y, camera.position(), rho_d, rho_s, k);
                        peak = peak.max(e.max_element());
                        expected_image.push((x, y, e));
                    }
                }
            }
        }
        // The highlight must be a real feature: its peak well above the diffuse level.
        let diffuse_peak = (rho_d / std::f32::consts::PI * 1.0 / 0.8f32.powi(2)).max_element();
        assert!(
            peak > 1.5 * diffuse_peak,
            "no visible highlight for {base} m={metallic}"
        );
        for (x, y, e) in expected_image {
            let got = frame.direct.get(x, y);
            for c in 0..3 {
                assert!(
                    (got[c] - e[c]).abs() < 0.01 * e[c] + 2e-3 * peak,
                    "material {base} m={metallic} r={roughness} s={specular_factor} at ({x},{y}) channel {c}: GPU {} vs CPU {}",
                    got[c],
                    e[c]
                );
            }
        }
    }
}

/// A light given on the command line (`--light`) is the same light as one in the file: adding
/// a copy of each built-in plane scene's own light through `SceneEdits` doubles every pixel
/// of the direct image (point, spot and directional alike; the shadow maps come along).
#[test]
fn lights_added_by_edits_shade_like_the_scenes_own() {
    use valgi::scene::edits::{LightSpec, SceneEdits};
    use valgi::shading::WorldLight;
    let Some(ctx) = common::gpu() else { return };
    for name in ["plane-point", "plane-spot", "plane-directional"] {
        let scene = load(name);
        let (single, _) = render(&ctx, &scene, small(48, 48));
        let world = scene.world_from_node();
        let own = WorldLight::from_scene(&scene, &world)[0];
        let spec = match own.kind {
            LightKind::Point => LightSpec::Point {
                position: own.position,
                intensity: own.intensity,
            },
            LightKind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => LightSpec::Spot {
                position: own.position,
                direction: own.direction,
                inner_cone_angle,
                outer_cone_angle,
                intensity: own.intensity,
            },
            LightKind::Directional => LightSpec::Sun {
                direction: own.direction,
                irradiance: own.intensity,
            },
            LightKind::Emitter => unreachable!("{name} has no emissive surfaces"),
        };
        let mut doubled_scene = scene.clone();
        let edits = SceneEdits {
            lights: vec![spec],
            ..SceneEdits::default()
        };
        edits.apply(&mut doubled_scene, None, 1.0).unwrap();
        assert_eq!(doubled_scene.lights.len(), scene.lights.len() + 1);
        let (doubled, _) = render(&ctx, &doubled_scene, small(48, 48));
        let (mut worst, mut lit) = (0.0f32, 0);
        for (a, b) in single.direct.pixels.iter().zip(&doubled.direct.pixels) {
            if a[0] > 1e-4 {
                lit += 1;
                worst = worst.max((b[0] / a[0] - 2.0).abs());
            }
        }
        assert!(lit > 200, "{name}: only {lit} lit pixels");
        assert!(worst < 2e-3, "{name}: worst ratio error {worst} against 2");
    }
}
