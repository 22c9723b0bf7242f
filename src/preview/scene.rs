//! The preview room: a 2.4 × 2.4 × 3.4 m box with a red left wall and a green right wall (white
//! elsewhere, as a Cornell box), one point light up and to the right in front of the ball, the
//! ball (a sphere or the Stanford bunny) resting on the floor in the middle, the camera in front
//! looking at it. Only the ball's material changes from one preview to the next.

use std::path::PathBuf;

use glam::{Quat, Vec2, Vec3};

use crate::scene::builtin::procedural::{bunny_candidates, icosphere, load_ply};
use crate::scene::mesh::{compute_normals, MeshBuilder};
use crate::scene::{
    Camera, FovAxis, Instance, Light, LightKind, Material, Mesh, Node, Scene, SceneError, Trs,
};

use super::spec::PreviewMaterial;

/// Room corners, metres: x ∈ [−1.2, 1.2], y ∈ [0, 2.4], z ∈ [−1.2, 2.2].
pub const ROOM_MIN: Vec3 = Vec3::new(-1.2, 0.0, -1.2);
pub const ROOM_MAX: Vec3 = Vec3::new(1.2, 2.4, 2.2);
/// Sphere radius, metres; the bunny is scaled to the same height.
pub const BALL_RADIUS: f32 = 0.5;
/// Centre of the sphere (it rests on the floor).
pub const BALL_CENTRE: Vec3 = Vec3::new(0.0, BALL_RADIUS, 0.0);
/// The point light: above, right of and in front of the ball, so that its mirror reflection
/// lies on the hemisphere the camera sees (upper right of the ball's centre in the image).
pub const LIGHT_POSITION: Vec3 = Vec3::new(0.7, 1.9, 1.3);
/// W/sr.
pub const LIGHT_INTENSITY: f32 = 4.0;
pub const CAMERA_EYE: Vec3 = Vec3::new(0.0, 0.95, 2.0);
pub const CAMERA_TARGET: Vec3 = Vec3::new(0.0, 0.5, 0.0);
/// Vertical field of view: the sphere spans about two thirds of the image height.
pub const CAMERA_YFOV_DEGREES: f32 = 45.0;

/// The shape the material is shown on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BallShape {
    Sphere,
    /// The Stanford bunny (`../shared/data/bunny/bun_zipper_res2.ply`), as tall as the sphere.
    Bunny,
}

impl std::str::FromStr for BallShape {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "sphere" => Ok(BallShape::Sphere),
            "bunny" => Ok(BallShape::Bunny),
            other => Err(format!("unknown ball '{other}' (sphere|bunny)")),
        }
    }
}

/// The ball's mesh in model space (resting on y = 0, centred on the y axis), built once and
/// shared by every preview scene. The bunny must exist: a preview of a stand-in would mislead.
pub fn ball_mesh(shape: BallShape, max_edge: f32) -> Result<Mesh, SceneError> {
    match shape {
        BallShape::Sphere => {
            let mut mesh = icosphere("ball", 0, BALL_RADIUS, max_edge, false);
            for p in &mut mesh.positions {
                p.y += BALL_RADIUS;
            }
            Ok(mesh)
        }
        BallShape::Bunny => bunny_ball(&bunny_candidates(), max_edge),
    }
}

/// The bunny from the first of `candidates` that exists, scaled to the sphere's height.
fn bunny_ball(candidates: &[PathBuf], max_edge: f32) -> Result<Mesh, SceneError> {
    let Some(path) = candidates.iter().find(|p| p.is_file()) else {
        return Err(SceneError::Other {
            path: candidates
                .first()
                .map(PathBuf::as_path)
                .unwrap_or(std::path::Path::new("bun_zipper_res2.ply"))
                .display()
                .to_string(),
            message: format!(
                "--ball bunny needs the Stanford bunny; not found (looked for {}); \
                 use --ball sphere",
                candidates
                    .iter()
                    .map(|p| p.display().to_string())
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        });
    };
    let mut mesh = load_ply(path)?;
    mesh.name = "ball (bunny)".into();
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in &mesh.positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let scale = 2.0 * BALL_RADIUS / (hi.y - lo.y).max(1e-6);
    let foot = Vec3::new((lo.x + hi.x) * 0.5, lo.y, (lo.z + hi.z) * 0.5);
    for p in &mut mesh.positions {
        *p = (*p - foot) * scale;
    }
    mesh.normals = compute_normals(&mesh.positions, &mesh.indices);
    if mesh.uv0.len() != mesh.positions.len() {
        mesh.uv0 = vec![Vec2::ZERO; mesh.positions.len()];
    }
    mesh.material = 0;
    crate::scene::mesh::tessellate(&mut mesh, max_edge);
    Ok(mesh)
}

/// The preview scene of one material on `ball` (from [`ball_mesh`]); walls tessellated to
/// `max_edge`. Scenes of different materials differ only in the ball's material, so the
/// sparse method's per-mesh point cache serves every one after the first.
pub fn preview_scene(name: &str, material: &PreviewMaterial, ball: &Mesh, max_edge: f32) -> Scene {
    let mut scene = Scene {
        name: name.into(),
        ..Scene::default()
    };
    let add_material = |scene: &mut Scene, m: Material| {
        scene.materials.push(m);
        scene.materials.len() - 1
    };
    let white = add_material(
        &mut scene,
        Material::lambert("white", Vec3::new(0.75, 0.75, 0.75)),
    );
    let red = add_material(
        &mut scene,
        Material::lambert("red", Vec3::new(0.63, 0.06, 0.05)),
    );
    let green = add_material(
        &mut scene,
        Material::lambert("green", Vec3::new(0.12, 0.45, 0.09)),
    );
    let node = |scene: &mut Scene, name: &str, local: Trs| {
        scene.nodes.push(Node {
            name: name.into(),
            parent: None,
            local,
        });
        scene.nodes.len() - 1
    };
    let centre = (ROOM_MIN + ROOM_MAX) * 0.5;
    let walls = [
        ("wall_-x", red, 0, false),
        ("wall_+x", green, 0, true),
        ("floor", white, 1, false),
        ("ceiling", white, 1, true),
        ("wall_-z", white, 2, false),
        ("wall_+z", white, 2, true),
    ];
    for (wall, material, axis, high) in walls {
        let [p0, p1, p2, p3] = box_face(ROOM_MIN, ROOM_MAX, axis, high);
        let mut mb = MeshBuilder::new(wall, material);
        mb.add_quad(p0, p1, p2, p3, centre, max_edge);
        let n = node(&mut scene, wall, Trs::default());
        scene.meshes.push(mb.build());
        scene.instances.push(Instance {
            mesh: scene.meshes.len() - 1,
            node: n,
        });
    }
    // The ball's material keeps its texture indices relative to the scene's texture list.
    let mut ball_material = material.material.clone();
    let offset = scene.textures.len();
    for slot in [
        &mut ball_material.base_color_texture,
        &mut ball_material.metallic_roughness_texture,
        &mut ball_material.normal_texture,
        &mut ball_material.emissive_texture,
    ] {
        if let Some(t) = slot.as_mut() {
            *t += offset;
        }
    }
    scene.textures.extend(material.textures.iter().cloned());
    let ball_material = add_material(&mut scene, ball_material);
    let mut ball = ball.clone();
    ball.material = ball_material;
    let n = node(&mut scene, "ball", Trs::default());
    scene.meshes.push(ball);
    scene.instances.push(Instance {
        mesh: scene.meshes.len() - 1,
        node: n,
    });
    let light = node(
        &mut scene,
        "light",
        Trs {
            translation: LIGHT_POSITION,
            rotation: Quat::from_rotation_arc(
                Vec3::NEG_Z,
                (BALL_CENTRE - LIGHT_POSITION).normalize(),
            ),
            ..Trs::default()
        },
    );
    scene.lights.push(Light {
        name: "point".into(),
        node: light,
        kind: LightKind::Point,
        color: Vec3::ONE,
        intensity: LIGHT_INTENSITY,
        range: None,
    });
    let camera = node(
        &mut scene,
        "camera",
        Trs::looking_at(CAMERA_EYE, CAMERA_TARGET),
    );
    scene.cameras.push(Camera {
        name: "camera".into(),
        node: camera,
        yfov: CAMERA_YFOV_DEGREES.to_radians(),
        fov_axis: FovAxis::Vertical,
        aspect: None,
        znear: 0.02,
        zfar: Some(20.0),
    });
    scene
}

/// The point on a sphere (centre, radius) where a point light at `light` is seen mirrored from
/// `eye`: where the normal bisects the directions to the light and to the eye. Found by fixed
/// point iteration from the bisector seen from the centre (it converges in a few steps when the
/// light and eye are well outside the sphere).
pub fn mirror_point(centre: Vec3, radius: f32, light: Vec3, eye: Vec3) -> Vec3 {
    let mut normal = ((light - centre).normalize() + (eye - centre).normalize()).normalize();
    for _ in 0..100 {
        let p = centre + radius * normal;
        normal = ((light - p).normalize() + (eye - p).normalize()).normalize();
    }
    centre + radius * normal
}

/// Corners of the face of box [min, max] normal to `axis` on its high side or not.
fn box_face(min: Vec3, max: Vec3, axis: usize, high: bool) -> [Vec3; 4] {
    let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
    let corner = |a: bool, b: bool| {
        let mut p = Vec3::ZERO;
        p[axis] = if high { max[axis] } else { min[axis] };
        p[u] = if a { max[u] } else { min[u] };
        p[v] = if b { max[v] } else { min[v] };
        p
    };
    [
        corner(false, false),
        corner(true, false),
        corner(true, true),
        corner(false, true),
    ]
}

/// Built-in names: `preview` (the sweep's default material, roughness 0.5), and
/// `preview-r<R>[-m<M>]` for roughness R % and metallic M % (whole numbers 0..=100) on the grey
/// base: scene names cannot hold a '.', which would make them file names.
pub const BUILTIN_NAMES: &[(&str, &str)] = &[(
    "preview",
    "material preview room: grey sphere (roughness 0.5, dielectric), red/green walls, one point light; preview-r<R>[-m<M>] sets roughness and metallic in percent (e.g. preview-r20, preview-r30-m100)",
)];

/// The built-in preview scene `name` when it is one (`None` otherwise).
pub fn builtin(name: &str, max_edge: f32) -> Option<Result<Scene, SceneError>> {
    let rest = name.strip_prefix("preview")?;
    let mut material = super::spec::default_material();
    let bad = |message: String| SceneError::Other {
        path: name.into(),
        message,
    };
    if !rest.is_empty() {
        let Some(rest) = rest.strip_prefix('-') else {
            return Some(Err(SceneError::UnknownBuiltin { name: name.into() }));
        };
        for part in rest.split('-') {
            let (field, value) = match part.split_at_checked(1) {
                Some(("r", v)) => (&mut material.roughness, v),
                Some(("m", v)) => (&mut material.metallic, v),
                _ => {
                    return Some(Err(bad(format!(
                        "'{part}': preview scenes take -r<roughness> and -m<metallic>, e.g. \
                         preview-r20-m0"
                    ))))
                }
            };
            match value.parse::<u32>() {
                Ok(percent) if percent <= 100 => *field = percent as f32 / 100.0,
                _ => {
                    return Some(Err(bad(format!(
                        "'{part}': '{value}' must be a whole percentage 0..=100"
                    ))))
                }
            }
        }
    }
    let ball = match ball_mesh(BallShape::Sphere, max_edge) {
        Ok(ball) => ball,
        Err(e) => return Some(Err(e)),
    };
    let cell = PreviewMaterial::plain(name, material);
    Some(Ok(preview_scene(name, &cell, &ball, max_edge)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mirror_point_obeys_the_reflection_law() {
        let p = mirror_point(BALL_CENTRE, BALL_RADIUS, LIGHT_POSITION, CAMERA_EYE);
        assert!((p.distance(BALL_CENTRE) - BALL_RADIUS).abs() < 1e-5);
        let n = (p - BALL_CENTRE).normalize();
        let to_light = (LIGHT_POSITION - p).normalize();
        let to_eye = (CAMERA_EYE - p).normalize();
        let reflected = 2.0 * n.dot(to_eye) * n - to_eye;
        assert!(
            reflected.dot(to_light) > 1.0 - 1e-5,
            "{reflected} vs {to_light}"
        );
        // Visible from the camera and lit: the highlight can be seen.
        assert!(n.dot(to_eye) > 0.3 && n.dot(to_light) > 0.3);
    }

    #[test]
    fn builtin_names_parse() {
        let scene = builtin("preview-r20-m100", 0.2).unwrap().unwrap();
        let ball = scene.materials.last().unwrap();
        assert_eq!((ball.roughness, ball.metallic), (0.2, 1.0));
        assert_eq!(scene.lights.len(), 1);
        assert_eq!(scene.meshes.len(), 7);
        assert!(builtin("cornell", 0.2).is_none());
        let e = builtin("preview-r0.2", 0.2)
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("'0.2' must be a whole percentage 0..=100"),
            "{e}"
        );
        let e = builtin("preview-x0.1", 0.2)
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(e.contains("-r<roughness>"), "{e}");
    }

    #[test]
    fn bunny_ball_is_as_tall_as_the_sphere_or_a_clear_error() {
        let missing = [PathBuf::from("no/such/bunny.ply")];
        let e = bunny_ball(&missing, 0.1).unwrap_err().to_string();
        assert!(
            e.contains("--ball bunny needs the Stanford bunny") && e.contains("no/such/bunny.ply"),
            "{e}"
        );
        let candidates = bunny_candidates();
        if !candidates.iter().any(|p| p.is_file()) {
            eprintln!("SKIPPED: no bunny in the shared data");
            return;
        }
        let mesh = bunny_ball(&candidates, 0.1).unwrap();
        let (lo, hi) = mesh.positions.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        assert!(
            lo.y.abs() < 1e-5 && (hi.y - 2.0 * BALL_RADIUS).abs() < 1e-4,
            "{lo} {hi}"
        );
        assert!(((lo.x + hi.x) * 0.5).abs() < 1e-4);
    }

    #[test]
    fn walls_face_the_ball() {
        let scene = builtin("preview", 0.3).unwrap().unwrap();
        for mesh in &scene.meshes[..6] {
            let p = mesh.positions[0];
            let n = mesh.normals[0];
            assert!(n.dot(BALL_CENTRE - p) > 0.0, "{} faces away", mesh.name);
        }
    }
}
