//! Lights and a camera added to a loaded scene from the command line (`--light`,
//! `--camera-eye`, `--camera-target`, `--fov`), so that any asset can be lit and framed without
//! editing its file. The edits become ordinary nodes, lights and cameras of the [`Scene`], so
//! every method, the reference and the viewer see the same ones.
//!
//! Formats (all numbers decimal, world space, metres; colours linear RGB, default white):
//! - `point:X,Y,Z,INTENSITY[,R,G,B]`: INTENSITY in W/sr.
//! - `spot:X,Y,Z,DX,DY,DZ,INNER_DEG,OUTER_DEG,INTENSITY[,R,G,B]`: a cone along (DX,DY,DZ)
//!   with the KHR_lights_punctual falloff between the inner and outer half-angles.
//! - `sun:DX,DY,DZ,IRRADIANCE[,R,G,B]`: a directional light travelling along (DX,DY,DZ),
//!   IRRADIANCE in W/m².
//! - `headlight:INTENSITY[,R,G,B]`: a point light at the camera, moving with it.

use std::str::FromStr;

use glam::{Quat, Vec3};

use super::{Camera, FovAxis, Light, LightKind, Node, Scene, SceneError, Trs};

/// A light given on the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightSpec {
    Point {
        position: Vec3,
        intensity: Vec3,
    },
    Spot {
        position: Vec3,
        direction: Vec3,
        inner_cone_angle: f32,
        outer_cone_angle: f32,
        intensity: Vec3,
    },
    Sun {
        direction: Vec3,
        irradiance: Vec3,
    },
    Headlight {
        intensity: Vec3,
    },
}

/// The formats of [`LightSpec`], for error messages and help.
pub const LIGHT_FORMATS: &str = "point:X,Y,Z,INTENSITY[,R,G,B] | \
     spot:X,Y,Z,DX,DY,DZ,INNER_DEG,OUTER_DEG,INTENSITY[,R,G,B] | sun:DX,DY,DZ,IRRADIANCE[,R,G,B] | \
     headlight:INTENSITY[,R,G,B]";

/// Brightest intensity or irradiance accepted per channel: far above any real light, low enough
/// that squared and summed radiometry stays finite in f32.
const MAX_POWER: f32 = 1e9;

impl FromStr for LightSpec {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        let fail = |why: String| format!("--light '{text}': {why} (formats: {LIGHT_FORMATS})");
        let (kind, rest) = text
            .split_once(':')
            .ok_or_else(|| fail("expected KIND:NUMBERS".into()))?;
        let numbers = rest
            .split(',')
            .map(|n| {
                let value = n
                    .trim()
                    .parse::<f32>()
                    .map_err(|_| fail(format!("'{n}' is not a number")))?;
                if value.is_finite() {
                    Ok(value)
                } else {
                    Err(fail(format!("'{n}' is not finite")))
                }
            })
            .collect::<Result<Vec<f32>, String>>()?;
        let (fixed, name) = match kind {
            "point" => (4, "point"),
            "spot" => (9, "spot"),
            "sun" => (4, "sun"),
            "headlight" => (1, "headlight"),
            other => return Err(fail(format!("unknown light kind '{other}'"))),
        };
        if numbers.len() != fixed && numbers.len() != fixed + 3 {
            return Err(fail(format!(
                "{name} takes {fixed} numbers, or {} with a colour; got {}",
                fixed + 3,
                numbers.len()
            )));
        }
        let colour = if numbers.len() == fixed + 3 {
            Vec3::from_slice(&numbers[fixed..])
        } else {
            Vec3::ONE
        };
        if colour.min_element() < 0.0 {
            return Err(fail("colour components must not be negative".into()));
        }
        let power = numbers[fixed - 1];
        if !(0.0..=MAX_POWER).contains(&power) {
            return Err(fail(format!(
                "intensity {power} must be within 0..={MAX_POWER:e}"
            )));
        }
        let scaled = colour * power;
        let direction = |slice: &[f32]| {
            Vec3::from_slice(slice)
                .try_normalize()
                .ok_or_else(|| fail("the direction is zero".into()))
        };
        Ok(match kind {
            "point" => LightSpec::Point {
                position: Vec3::from_slice(&numbers[0..3]),
                intensity: scaled,
            },
            "spot" => {
                let (inner, outer) = (numbers[6], numbers[7]);
                if !(0.0..=90.0).contains(&outer) || outer <= 0.0 {
                    return Err(fail(format!("outer angle {outer}° must be within (0, 90]")));
                }
                if !(0.0..=outer).contains(&inner) {
                    return Err(fail(format!(
                        "inner angle {inner}° must be within 0..=outer ({outer}°)"
                    )));
                }
                LightSpec::Spot {
                    position: Vec3::from_slice(&numbers[0..3]),
                    direction: direction(&numbers[3..6])?,
                    inner_cone_angle: inner.to_radians(),
                    outer_cone_angle: outer.to_radians(),
                    intensity: scaled,
                }
            }
            "sun" => LightSpec::Sun {
                direction: direction(&numbers[0..3])?,
                irradiance: scaled,
            },
            _ => LightSpec::Headlight { intensity: scaled },
        })
    }
}

/// A camera given on the command line; every field left `None` keeps the scene camera's value.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CameraEdit {
    /// World-space eye position.
    pub eye: Option<Vec3>,
    /// World-space point looked at (default with an eye: the centre of the scene's bounds).
    pub target: Option<Vec3>,
    /// Vertical field of view, degrees.
    pub yfov_degrees: Option<f32>,
}

impl CameraEdit {
    pub fn is_empty(&self) -> bool {
        self.eye.is_none() && self.target.is_none() && self.yfov_degrees.is_none()
    }
}

/// Parses `X,Y,Z` (an option's value) into a point.
pub fn parse_point(option: &str, text: &str) -> Result<Vec3, String> {
    let numbers: Vec<f32> = text
        .split(',')
        .map(|n| n.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("{option} '{text}': expected X,Y,Z (three numbers)"))?;
    if numbers.len() != 3 || numbers.iter().any(|v| !v.is_finite()) {
        return Err(format!(
            "{option} '{text}': expected X,Y,Z (three finite numbers)"
        ));
    }
    Ok(Vec3::from_slice(&numbers))
}

/// Everything the command line adds to a scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SceneEdits {
    pub lights: Vec<LightSpec>,
    pub camera: CameraEdit,
    /// Drop the scene's own lights and emission before adding [`SceneEdits::lights`]
    /// (`--no-scene-lights`): the asset is lit by the command line's lights alone, in every
    /// method and in the reference (which would otherwise still sample emissive triangles).
    pub drop_scene_lights: bool,
}

/// Removes every light of `scene` (punctual lights and the proxies of emissive surfaces) and
/// every material's emission, so that nothing but lights added afterwards lights it.
fn drop_lights_and_emission(scene: &mut Scene) {
    scene.lights.clear();
    for material in &mut scene.materials {
        material.emissive = Vec3::ZERO;
        material.emissive_texture = None;
    }
}

/// Name of the camera [`SceneEdits::apply`] adds.
pub const EDIT_CAMERA_NAME: &str = "command line";

impl SceneEdits {
    pub fn is_empty(&self) -> bool {
        self.lights.is_empty() && self.camera.is_empty() && !self.drop_scene_lights
    }

    /// Adds the lights and the camera to `scene`. `selector` is the camera the user chose (as
    /// for [`Scene::camera_view`]) and `aspect` the output's; returns the selector to render
    /// with afterwards: the added camera when one was added, else `selector` unchanged.
    pub fn apply(
        &self,
        scene: &mut Scene,
        selector: Option<&str>,
        aspect: f32,
    ) -> Result<Option<String>, SceneError> {
        if self.drop_scene_lights {
            drop_lights_and_emission(scene);
        }
        let mut selector = selector.map(str::to_string);
        let needs_camera_node = self
            .lights
            .iter()
            .any(|l| matches!(l, LightSpec::Headlight { .. }));
        if !self.camera.is_empty() || needs_camera_node {
            selector = Some(self.apply_camera(scene, selector.as_deref(), aspect)?);
        }
        let camera_node = selector
            .as_deref()
            .and_then(|sel| scene.camera_index(Some(sel)))
            .map(|i| scene.cameras[i].node);
        for (i, spec) in self.lights.iter().enumerate() {
            let name = format!("--light {}", i + 1);
            let (parent, local, kind, intensity) = match *spec {
                LightSpec::Point {
                    position,
                    intensity,
                } => (None, at(position, Vec3::NEG_Z), LightKind::Point, intensity),
                LightSpec::Spot {
                    position,
                    direction,
                    inner_cone_angle,
                    outer_cone_angle,
                    intensity,
                } => (
                    None,
                    at(position, direction),
                    LightKind::Spot {
                        inner_cone_angle,
                        outer_cone_angle,
                    },
                    intensity,
                ),
                LightSpec::Sun {
                    direction,
                    irradiance,
                } => (
                    None,
                    at(Vec3::ZERO, direction),
                    LightKind::Directional,
                    irradiance,
                ),
                LightSpec::Headlight { intensity } => {
                    (camera_node, Trs::default(), LightKind::Point, intensity)
                }
            };
            // The light's colour carries the spectrum, `intensity` its scale, as in glTF.
            let scale = intensity.max_element();
            let color = if scale > 0.0 {
                intensity / scale
            } else {
                Vec3::ONE
            };
            let node = push_node(scene, &name, parent, local);
            scene.lights.push(Light {
                name,
                node,
                kind,
                color,
                intensity: scale,
                range: None,
            });
        }
        Ok(selector)
    }

    /// Adds (or, for a field-of-view change of a scene camera, edits) the camera; returns its
    /// selector.
    fn apply_camera(
        &self,
        scene: &mut Scene,
        selector: Option<&str>,
        aspect: f32,
    ) -> Result<String, SceneError> {
        let edit = self.camera;
        if let Some(fov) = edit.yfov_degrees {
            if !(fov > 0.5 && fov < 179.0) {
                return Err(SceneError::Other {
                    path: scene.name.clone(),
                    message: format!("--fov {fov}: must be within (0.5, 179) degrees"),
                });
            }
        }
        let world = scene.world_from_node();
        let base = scene.camera_view(selector, aspect, &world)?;
        let scene_camera = scene.camera_index(selector);
        // Only the field of view changes on a scene camera: edit it in place so that an
        // animated camera keeps its animation.
        if let (Some(index), None, None) = (scene_camera, edit.eye, edit.target) {
            if let Some(fov) = edit.yfov_degrees {
                scene.cameras[index].yfov = fov.to_radians();
                scene.cameras[index].fov_axis = FovAxis::Vertical;
            }
            return Ok(index.to_string());
        }
        let bounds = scene.world_bounds(&world);
        let radius = if bounds.is_empty() {
            1.0
        } else {
            (bounds.extent().length() * 0.5).max(1e-3)
        };
        let yfov = edit.yfov_degrees.map_or(base.yfov, f32::to_radians);
        let view = match (edit.eye, edit.target) {
            // The framing default with another field of view.
            (None, None) => super::framing_camera(&bounds, radius, aspect, yfov),
            (eye, target) => {
                let eye = eye.unwrap_or(base.position());
                let target = target.unwrap_or(if edit.eye.is_some() && !bounds.is_empty() {
                    bounds.center()
                } else {
                    eye + base.world_from_view.transform_vector3(Vec3::NEG_Z)
                });
                if (target - eye).length() < 1e-6 {
                    return Err(SceneError::Other {
                        path: scene.name.clone(),
                        message: format!(
                            "--camera-eye {eye} and --camera-target {target} coincide"
                        ),
                    });
                }
                let up = if (target - eye).normalize().y.abs() > 0.999 {
                    Vec3::NEG_Z
                } else {
                    Vec3::Y
                };
                let view_from_world = glam::camera::rh::view::look_at_mat4(eye, target, up);
                let far = if bounds.is_empty() {
                    1000.0
                } else {
                    (eye - bounds.center()).length() + radius
                };
                let near = if bounds.is_empty() {
                    1e-2
                } else {
                    ((eye - bounds.center()).length() - radius).max(radius * 1e-3)
                };
                super::CameraView {
                    world_from_view: view_from_world.inverse(),
                    yfov,
                    aspect,
                    znear: near,
                    zfar: far * 1.5,
                    off_axis: None,
                }
            }
        };
        let (_, rotation, translation) = view.world_from_view.to_scale_rotation_translation();
        let node = push_node(
            scene,
            EDIT_CAMERA_NAME,
            None,
            Trs {
                translation,
                rotation,
                scale: Vec3::ONE,
            },
        );
        scene.cameras.push(Camera {
            name: EDIT_CAMERA_NAME.into(),
            node,
            yfov: view.yfov,
            fov_axis: FovAxis::Vertical,
            aspect: None,
            znear: view.znear,
            zfar: Some(view.zfar),
        });
        Ok((scene.cameras.len() - 1).to_string())
    }
}

/// A node at `position` whose −z axis (the way lights and cameras point) is `direction`.
fn at(position: Vec3, direction: Vec3) -> Trs {
    Trs {
        translation: position,
        rotation: Quat::from_rotation_arc(Vec3::NEG_Z, direction.normalize()),
        scale: Vec3::ONE,
    }
}

fn push_node(scene: &mut Scene, name: &str, parent: Option<usize>, local: Trs) -> usize {
    scene.nodes.push(Node {
        name: name.to_string(),
        parent,
        local,
    });
    scene.nodes.len() - 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin::{self, BuiltinParams};
    use crate::shading::WorldLight;

    fn cornell() -> Scene {
        builtin::load("cornell", &BuiltinParams::default()).unwrap()
    }

    #[test]
    fn light_specs_parse_with_and_without_colour() {
        assert_eq!(
            "point:1,2,3,10".parse::<LightSpec>().unwrap(),
            LightSpec::Point {
                position: Vec3::new(1.0, 2.0, 3.0),
                intensity: Vec3::splat(10.0)
            }
        );
        assert_eq!(
            "sun:0,-2,0,3,1,0.5,0".parse::<LightSpec>().unwrap(),
            LightSpec::Sun {
                direction: Vec3::NEG_Y,
                irradiance: Vec3::new(3.0, 1.5, 0.0)
            }
        );
        let spot = "spot:0,1,0,0,-1,0,20,30,5".parse::<LightSpec>().unwrap();
        let LightSpec::Spot {
            inner_cone_angle,
            outer_cone_angle,
            ..
        } = spot
        else {
            panic!("{spot:?}")
        };
        assert!((inner_cone_angle - 20f32.to_radians()).abs() < 1e-6);
        assert!((outer_cone_angle - 30f32.to_radians()).abs() < 1e-6);
    }

    #[test]
    fn bad_light_specs_say_what_is_wrong() {
        for (text, needle) in [
            ("lamp:1,2,3,4", "unknown light kind 'lamp'"),
            ("point:1,2,3", "point takes 4 numbers"),
            ("point:1,2,x,4", "'x' is not a number"),
            ("point:1,2,3,NaN", "not finite"),
            ("point:1,2,3,-4", "intensity -4"),
            ("point:1,2,3,4,1,-1,1", "colour"),
            ("sun:0,0,0,3", "direction is zero"),
            ("spot:0,1,0,0,-1,0,40,30,5", "inner angle"),
            ("spot:0,1,0,0,-1,0,10,120,5", "outer angle"),
            ("point", "KIND:NUMBERS"),
        ] {
            let err = text.parse::<LightSpec>().unwrap_err();
            assert!(err.contains(needle), "{text}: {err}");
            assert!(
                err.contains(text),
                "{text}: the message names the value: {err}"
            );
        }
    }

    #[test]
    fn added_lights_land_where_the_spec_says() {
        let mut scene = cornell();
        let before = scene.lights.len();
        let edits = SceneEdits {
            lights: vec![
                "spot:0.1,0.5,0.2,0,-1,0,10,30,7,1,0.5,0.25"
                    .parse()
                    .unwrap(),
                "sun:1,-1,0,2".parse().unwrap(),
            ],
            ..SceneEdits::default()
        };
        assert_eq!(edits.apply(&mut scene, None, 1.0).unwrap(), None);
        let world = scene.world_from_node();
        let lights = WorldLight::from_scene(&scene, &world);
        let spot = lights[before];
        assert!((spot.position - Vec3::new(0.1, 0.5, 0.2)).length() < 1e-6);
        assert!((spot.direction - Vec3::NEG_Y).length() < 1e-6);
        assert!((spot.intensity - Vec3::new(7.0, 3.5, 1.75)).length() < 1e-5);
        let sun = lights[before + 1];
        assert_eq!(sun.kind, LightKind::Directional);
        assert!((sun.direction - Vec3::new(1.0, -1.0, 0.0).normalize()).length() < 1e-6);
        assert!((sun.intensity - Vec3::splat(2.0)).length() < 1e-6);
    }

    #[test]
    fn dropping_scene_lights_leaves_only_the_added_ones_and_no_emission() {
        let params = crate::scene::LoadParams::default();
        let mut scene = crate::scene::load_with("emissive-quad", &params).unwrap();
        assert!(!scene.lights.is_empty(), "the quad's proxy lights");
        assert!(scene.materials.iter().any(|m| m.emissive != Vec3::ZERO));
        let edits = SceneEdits {
            lights: vec!["point:0,1,0,2".parse().unwrap()],
            drop_scene_lights: true,
            ..SceneEdits::default()
        };
        assert!(!edits.is_empty());
        edits.apply(&mut scene, None, 1.0).unwrap();
        assert_eq!(scene.lights.len(), 1);
        assert_eq!(scene.lights[0].kind, LightKind::Point);
        assert!(scene
            .materials
            .iter()
            .all(|m| m.emissive == Vec3::ZERO && m.emissive_texture.is_none()));
    }

    #[test]
    fn camera_eye_and_target_give_a_camera_looking_there() {
        let mut scene = cornell();
        let edits = SceneEdits {
            lights: vec!["headlight:3".parse().unwrap()],
            camera: CameraEdit {
                eye: Some(Vec3::new(0.2, 0.3, 2.0)),
                target: Some(Vec3::new(0.0, 0.25, 0.0)),
                yfov_degrees: Some(30.0),
            },
            ..SceneEdits::default()
        };
        let selector = edits.apply(&mut scene, Some("0"), 1.5).unwrap();
        let world = scene.world_from_node();
        let view = scene.camera_view(selector.as_deref(), 1.5, &world).unwrap();
        assert!((view.position() - Vec3::new(0.2, 0.3, 2.0)).length() < 1e-5);
        assert!((view.yfov - 30f32.to_radians()).abs() < 1e-6);
        // The target projects to the image centre.
        let clip = view.clip_from_world() * Vec3::new(0.0, 0.25, 0.0).extend(1.0);
        assert!((clip.truncate() / clip.w).truncate().length() < 1e-4);
        // The headlight sits at the eye.
        let lights = WorldLight::from_scene(&scene, &world);
        let head = lights.last().unwrap();
        assert!((head.position - view.position()).length() < 1e-5);
    }

    #[test]
    fn fov_alone_edits_the_scene_camera_in_place() {
        let mut scene = cornell();
        let cameras = scene.cameras.len();
        let position = scene
            .camera_view(None, 1.0, &scene.world_from_node())
            .unwrap()
            .position();
        let edits = SceneEdits {
            lights: vec![],
            camera: CameraEdit {
                yfov_degrees: Some(20.0),
                ..CameraEdit::default()
            },
            ..SceneEdits::default()
        };
        let selector = edits.apply(&mut scene, None, 1.0).unwrap();
        assert_eq!(scene.cameras.len(), cameras, "no camera added");
        let view = scene
            .camera_view(selector.as_deref(), 1.0, &scene.world_from_node())
            .unwrap();
        assert_eq!(view.position(), position);
        assert!((view.yfov - 20f32.to_radians()).abs() < 1e-6);
        let bad = SceneEdits {
            lights: vec![],
            camera: CameraEdit {
                yfov_degrees: Some(0.0),
                ..CameraEdit::default()
            },
            ..SceneEdits::default()
        };
        assert!(bad
            .apply(&mut scene, None, 1.0)
            .unwrap_err()
            .to_string()
            .contains("--fov 0"));
    }

    #[test]
    fn framing_camera_fills_the_frame_with_the_bounds() {
        // A wide, flat object (a helmet-like box): the default framing must make it touch
        // the frame's border on one axis, not float in a bounding sphere's margin.
        let bounds = crate::scene::Aabb {
            min: Vec3::new(-1.0, -0.6, -0.8),
            max: Vec3::new(1.0, 0.6, 0.8),
        };
        let radius = bounds.extent().length() * 0.5;
        for aspect in [0.75, 1.0, 16.0 / 9.0] {
            let view = crate::scene::framing_camera(&bounds, radius, aspect, 45f32.to_radians());
            let clip_from_world = view.clip_from_world();
            let (mut max_x, mut max_y) = (0.0f32, 0.0f32);
            for i in 0..8 {
                let pick = |bit: usize, lo: f32, hi: f32| if i & bit == 0 { lo } else { hi };
                let corner = Vec3::new(
                    pick(1, bounds.min.x, bounds.max.x),
                    pick(2, bounds.min.y, bounds.max.y),
                    pick(4, bounds.min.z, bounds.max.z),
                );
                let clip = clip_from_world * corner.extend(1.0);
                let ndc = clip.truncate() / clip.w;
                assert!(ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0, "{aspect}: {ndc}");
                max_x = max_x.max(ndc.x.abs());
                max_y = max_y.max(ndc.y.abs());
            }
            assert!(
                max_x.max(max_y) > 0.97,
                "aspect {aspect}: the box spans only {max_x} × {max_y} of the frame"
            );
        }
    }
}
