//! Range checks on the numbers a scene file declares: colours, factors, intensities, angles,
//! camera planes and vertex attributes. Every reader's output passes through [`sanitize`], so
//! no file can hand the renderer a negative colour, an infinite intensity or a NaN texture
//! coordinate. Fixes are warnings that name the object and the field; objects that cannot be
//! repaired meaningfully (a light with a non-finite intensity) are dropped with a warning.

use super::{LightKind, Scene};
use glam::{Vec2, Vec3, Vec4};

/// Largest accepted emitted radiance, W/(m²·sr), and light intensity, W/sr or W/m². Far above
/// any physical source the renderer is meant for (the sun's irradiance is ~1000 W/m²), and small
/// enough that sums over many lights and the exposure scale stay finite in f32.
pub const MAX_RADIOMETRIC: f32 = 1e9;

/// Checks and repairs `scene` in place; `source` prefixes the warnings (the file name).
pub fn sanitize(scene: &mut Scene, source: &str) {
    let mut warnings = Vec::new();
    let mut warn = |message: String| warnings.push(format!("{source}: {message}"));

    for (i, m) in scene.materials.iter_mut().enumerate() {
        let what = format!("material {i} '{}'", m.name);
        let rgb = unit_range(
            m.base_color.truncate(),
            Vec3::ONE,
            &what,
            "base colour",
            &mut warn,
        );
        let alpha = unit_scalar(m.base_color.w, 1.0, &what, "base colour alpha", &mut warn);
        m.base_color = rgb.extend(alpha);
        m.metallic = unit_scalar(m.metallic, 1.0, &what, "metallic factor", &mut warn);
        m.roughness = unit_scalar(m.roughness, 1.0, &what, "roughness factor", &mut warn);
        // ρ_s = 0.04 · specular_factor for a dielectric, so 25 is the largest factor that keeps
        // ρ_s ≤ 1 (the OBJ/MTL mapping uses factors above 1 for strong Ks).
        m.specular_factor = bounded_scalar(
            m.specular_factor,
            1.0,
            25.0,
            &what,
            "specular factor",
            &mut warn,
        );
        if !m.normal_scale.is_finite() {
            warn(format!(
                "{what}: normal scale {} is not finite; using 1",
                m.normal_scale
            ));
            m.normal_scale = 1.0;
        }
        m.emissive = radiometric(m.emissive, &what, "emissive radiance", &mut warn);
    }

    let mut kept = Vec::with_capacity(scene.lights.len());
    for light in std::mem::take(&mut scene.lights) {
        let what = format!("light '{}'", light.name);
        let mut light = light;
        if !light.intensity.is_finite() || !light.color.is_finite() {
            warn(format!(
                "{what}: intensity {} or colour {} is not finite; light skipped",
                light.intensity, light.color
            ));
            continue;
        }
        if light.intensity < 0.0 {
            warn(format!(
                "{what}: negative intensity {}; light skipped",
                light.intensity
            ));
            continue;
        }
        if light.color.min_element() < 0.0 {
            warn(format!(
                "{what}: negative colour {} clamped to 0",
                light.color
            ));
            light.color = light.color.max(Vec3::ZERO);
        }
        let peak = (light.color * light.intensity).max_element();
        if peak > MAX_RADIOMETRIC {
            let scale = MAX_RADIOMETRIC / light.color.max_element();
            warn(format!(
                "{what}: intensity × colour peaks at {peak:e}, above the {MAX_RADIOMETRIC:e} \
                 limit; intensity clamped to {scale:e}"
            ));
            light.intensity = scale;
        }
        if let Some(range) = light.range {
            if !(range.is_finite() && range > 0.0) {
                warn(format!(
                    "{what}: range {range} is not a positive length; ignored"
                ));
                light.range = None;
            }
        }
        if let LightKind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } = light.kind
        {
            let half_pi = std::f32::consts::FRAC_PI_2;
            let outer = if outer_cone_angle.is_finite() {
                outer_cone_angle.clamp(1e-4, half_pi)
            } else {
                std::f32::consts::FRAC_PI_4
            };
            let inner = if inner_cone_angle.is_finite() {
                inner_cone_angle.clamp(0.0, outer)
            } else {
                0.0
            };
            if inner != inner_cone_angle || outer != outer_cone_angle {
                warn(format!(
                    "{what}: spot cone angles ({inner_cone_angle}, {outer_cone_angle}) outside \
                     0 ≤ inner ≤ outer ≤ π/2; using ({inner}, {outer})"
                ));
            }
            light.kind = LightKind::Spot {
                inner_cone_angle: inner,
                outer_cone_angle: outer,
            };
        }
        kept.push(light);
    }
    scene.lights = kept;

    let mut cameras = Vec::with_capacity(scene.cameras.len());
    for mut camera in std::mem::take(&mut scene.cameras) {
        let what = format!("camera '{}'", camera.name);
        if !(camera.yfov.is_finite() && camera.yfov > 0.0 && camera.yfov < std::f32::consts::PI) {
            warn(format!(
                "{what}: field of view {} rad is outside (0, π); camera skipped",
                camera.yfov
            ));
            continue;
        }
        if !(camera.znear.is_finite() && camera.znear > 0.0) {
            warn(format!(
                "{what}: near plane {} is not a positive distance; using 0.01",
                camera.znear
            ));
            camera.znear = 0.01;
        }
        if let Some(zfar) = camera.zfar {
            if !(zfar.is_finite() && zfar > camera.znear) {
                warn(format!(
                    "{what}: far plane {zfar} is not beyond the near plane; derived from the scene"
                ));
                camera.zfar = None;
            }
        }
        if let Some(aspect) = camera.aspect {
            if !(aspect.is_finite() && aspect > 0.0) {
                warn(format!("{what}: aspect {aspect} ignored"));
                camera.aspect = None;
            }
        }
        cameras.push(camera);
    }
    scene.cameras = cameras;

    for mesh in &mut scene.meshes {
        let bad_uv = |uvs: &mut Vec<Vec2>| {
            let mut n = 0;
            for uv in uvs.iter_mut().filter(|uv| !uv.is_finite()) {
                *uv = Vec2::ZERO;
                n += 1;
            }
            n
        };
        let n0 = bad_uv(&mut mesh.uv0);
        let n1 = mesh.uv1.as_mut().map_or(0, bad_uv);
        if n0 + n1 > 0 {
            warn(format!(
                "mesh '{}': {} non-finite texture coordinate(s) set to 0",
                mesh.name,
                n0 + n1
            ));
        }
        let mut bad_normals = 0;
        for n in &mut mesh.normals {
            if n.try_normalize().is_none() {
                *n = Vec3::Y;
                bad_normals += 1;
            }
        }
        if bad_normals > 0 {
            warn(format!(
                "mesh '{}': {bad_normals} zero or non-finite normal(s) replaced",
                mesh.name
            ));
        }
        let mut bad_tangents = 0;
        for t in &mut mesh.tangents {
            if !t.is_finite() || t.truncate().try_normalize().is_none() {
                *t = Vec4::new(1.0, 0.0, 0.0, 1.0);
                bad_tangents += 1;
            }
        }
        if bad_tangents > 0 {
            warn(format!(
                "mesh '{}': {bad_tangents} unusable tangent(s) replaced",
                mesh.name
            ));
        }
    }
    scene.warnings.extend(warnings);
}

/// A colour that must lie in [0, 1] per channel: non-finite channels take `default`'s,
/// out-of-range ones are clamped.
fn unit_range(
    value: Vec3,
    default: Vec3,
    what: &str,
    field: &str,
    warn: &mut impl FnMut(String),
) -> Vec3 {
    let mut out = value;
    for k in 0..3 {
        if !out[k].is_finite() {
            out[k] = default[k];
        }
    }
    let clamped = out.clamp(Vec3::ZERO, Vec3::ONE);
    if clamped != value {
        warn(format!(
            "{what}: {field} {value} outside [0, 1] or not finite; using {clamped}"
        ));
    }
    clamped
}

fn unit_scalar(
    value: f32,
    default: f32,
    what: &str,
    field: &str,
    warn: &mut impl FnMut(String),
) -> f32 {
    bounded_scalar(value, default, 1.0, what, field, warn)
}

fn bounded_scalar(
    value: f32,
    default: f32,
    max: f32,
    what: &str,
    field: &str,
    warn: &mut impl FnMut(String),
) -> f32 {
    let out = if value.is_finite() {
        value.clamp(0.0, max)
    } else {
        default
    };
    if out != value {
        warn(format!(
            "{what}: {field} {value} outside [0, {max}] or not finite; using {out}"
        ));
    }
    out
}

/// Emitted radiance: non-finite channels are rejected (0), negative ones clamped to 0, and
/// values above [`MAX_RADIOMETRIC`] clamped to it.
fn radiometric(value: Vec3, what: &str, field: &str, warn: &mut impl FnMut(String)) -> Vec3 {
    let mut out = value;
    for k in 0..3 {
        if !out[k].is_finite() {
            out[k] = 0.0;
        }
    }
    let out = out.clamp(Vec3::ZERO, Vec3::splat(MAX_RADIOMETRIC));
    if out != value {
        warn(format!(
            "{what}: {field} {value} is negative, not finite or above {MAX_RADIOMETRIC:e}; \
             using {out}"
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Camera, FovAxis, Light, Material};

    #[test]
    fn hostile_factors_are_repaired_with_named_warnings() {
        let mut scene = Scene::default();
        scene.materials.push(Material {
            name: "m".into(),
            base_color: Vec4::new(-2.48, f32::INFINITY, 0.5, 2.0),
            emissive: Vec3::new(-65504.0, f32::NAN, 1e39f64 as f32),
            metallic: f32::NAN,
            roughness: 3.0,
            ..Material::default()
        });
        scene.lights.push(Light {
            name: "inf".into(),
            node: 0,
            kind: LightKind::Point,
            color: Vec3::ONE,
            intensity: 1e39f64 as f32,
            range: None,
        });
        scene.lights.push(Light {
            name: "neg colour".into(),
            node: 0,
            kind: LightKind::Spot {
                inner_cone_angle: 2.0,
                outer_cone_angle: f32::NAN,
            },
            color: Vec3::new(-1.0, 1.0, 1.0),
            intensity: 3.0,
            range: Some(-1.0),
        });
        scene.lights.push(Light {
            name: "huge".into(),
            node: 0,
            kind: LightKind::Directional,
            color: Vec3::new(2.0, 1.0, 1.0),
            intensity: 1e30,
            range: None,
        });
        scene.cameras.push(Camera {
            name: "c".into(),
            node: 0,
            yfov: 1.0,
            fov_axis: FovAxis::Vertical,
            aspect: Some(f32::NAN),
            znear: -1.0,
            zfar: Some(f32::INFINITY),
        });
        sanitize(&mut scene, "x.gltf");
        let m = &scene.materials[0];
        assert_eq!(m.base_color, Vec4::new(0.0, 1.0, 0.5, 1.0));
        assert_eq!(m.emissive, Vec3::new(0.0, 0.0, 0.0));
        assert_eq!((m.metallic, m.roughness), (1.0, 1.0));
        assert_eq!(scene.lights.len(), 2, "the infinite light is dropped");
        assert_eq!(scene.lights[0].color, Vec3::new(0.0, 1.0, 1.0));
        assert_eq!(scene.lights[0].range, None);
        assert_eq!(
            scene.lights[0].kind,
            LightKind::Spot {
                inner_cone_angle: std::f32::consts::FRAC_PI_4,
                outer_cone_angle: std::f32::consts::FRAC_PI_4
            }
        );
        assert_eq!(scene.lights[1].radiometric().max_element(), MAX_RADIOMETRIC);
        let c = &scene.cameras[0];
        assert_eq!((c.znear, c.zfar, c.aspect), (0.01, None, None));
        let all = scene.warnings.join("\n");
        for needle in [
            "x.gltf: material 0 'm': base colour",
            "emissive radiance",
            "metallic factor",
            "light 'inf': intensity inf",
            "light 'neg colour': negative colour",
            "spot cone angles",
            "range -1",
            "light 'huge'",
            "camera 'c': near plane",
        ] {
            assert!(all.contains(needle), "missing '{needle}' in:\n{all}");
        }
    }

    #[test]
    fn valid_scenes_pass_unchanged() {
        let mut scene = crate::scene::builtin::load(
            "cornell",
            &crate::scene::builtin::BuiltinParams::default(),
        )
        .unwrap();
        let before = format!("{:?}", (&scene.materials, &scene.lights, &scene.cameras));
        sanitize(&mut scene, "cornell");
        assert!(scene.warnings.is_empty(), "{:?}", scene.warnings);
        assert_eq!(
            before,
            format!("{:?}", (&scene.materials, &scene.lights, &scene.cameras))
        );
    }
}
