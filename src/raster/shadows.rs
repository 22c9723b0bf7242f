//! Shadow-map views for every light, all in one depth texture array: a spot light takes one
//! perspective layer, a point light or an emitter six (a cube's faces as layers), a directional light one
//! orthographic layer fitted to the scene's bounding sphere.

use glam::{Mat4, Quat, Vec3};

use super::types::{
    GpuLight, ShadowView, LIGHT_DIRECTIONAL, LIGHT_EMITTER, LIGHT_POINT, LIGHT_SPOT,
};
use crate::scene::{Aabb, LightKind, Scene};
use crate::shading::WorldLight;

/// Lights in world space and the shadow views they need.
pub struct LightSetup {
    pub lights: Vec<GpuLight>,
    pub views: Vec<ShadowView>,
}

/// Builds the light records and views, light `i`'s at `sides[i]` texels a side (each view a
/// whole layer, `atlas_layer` = the view's index, until a caller places it in a tile).
/// `margin_texels` widens perspective views by that many
/// texels per side: shadow maps need it so filter kernels near a cube face's edge stay inside
/// that face; reflective shadow maps use 0 so that cube faces tile the sphere exactly and every
/// direction is counted once.
pub fn setup_lights(
    scene: &Scene,
    world_from_node: &[Mat4],
    bounds: &Aabb,
    sides: &[u32],
    margin_texels: f32,
) -> LightSetup {
    let (center, radius) = if bounds.is_empty() {
        (Vec3::ZERO, 1.0)
    } else {
        (bounds.center(), (bounds.extent().length() * 0.5).max(1e-4))
    };
    let mut lights = Vec::new();
    let mut views = Vec::new();
    for (light_index, light) in WorldLight::from_scene(scene, world_from_node)
        .into_iter()
        .enumerate()
    {
        let res = sides[light_index] as f32;
        let (position, direction) = (light.position, light.direction);
        let first_shadow_view = views.len() as u32;
        // Far enough to see everything, near as far out as possible for depth precision.
        let far = ((position - center).length() + radius) * 1.01;
        let near = (far * 1e-4).max(1e-5);
        let (kind, cone_scale, cone_offset) = match light.kind {
            LightKind::Point | LightKind::Emitter => {
                // An emitter's lobe covers a hemisphere: a cube like a point light's keeps the
                // shader's face choice the same for both.
                let fov = 2.0 * (1.0 + 2.0 * margin_texels / res).atan();
                for (forward, up) in CUBE_FACES {
                    views.push(perspective_view(position, forward, up, fov, near, far, res));
                }
                let kind = if light.kind == LightKind::Emitter {
                    LIGHT_EMITTER
                } else {
                    LIGHT_POINT
                };
                (kind, 0.0, 1.0)
            }
            LightKind::Spot {
                inner_cone_angle,
                outer_cone_angle,
            } => {
                let outer = outer_cone_angle.clamp(1e-3, std::f32::consts::FRAC_PI_2);
                let inner = inner_cone_angle.clamp(0.0, outer);
                let margin = 2.0 * margin_texels / res;
                let fov = (2.0 * ((outer.tan() * (1.0 + margin)).atan())).min(170f32.to_radians());
                views.push(perspective_view(
                    position,
                    direction,
                    map_up(direction),
                    fov,
                    near,
                    far,
                    res,
                ));
                // KHR_lights_punctual reference implementation.
                let scale = 1.0 / (inner.cos() - outer.cos()).max(0.001);
                (LIGHT_SPOT, scale, -outer.cos() * scale)
            }
            LightKind::Directional => {
                let eye = center - direction * (2.0 * radius);
                let view_from_world =
                    glam::camera::rh::view::look_at_mat4(eye, center, map_up(direction));
                let clip_from_view = glam::camera::rh::proj::directx::orthographic(
                    -radius,
                    radius,
                    -radius,
                    radius,
                    radius * 0.5,
                    radius * 3.5,
                );
                views.push(ShadowView {
                    clip_from_world: (clip_from_view * view_from_world).to_cols_array_2d(),
                    origin: [0.0; 4],
                    texel: [2.0 * radius / res, res, radius * 0.5, radius * 3.5],
                    ..whole_layer()
                });
                (LIGHT_DIRECTIONAL, 0.0, 1.0)
            }
        };
        let intensity = light.intensity;
        lights.push(GpuLight {
            position: position.extend(1.0).to_array(),
            direction: direction.extend(light.range.unwrap_or(0.0)).to_array(),
            intensity: intensity.extend(0.0).to_array(),
            kind,
            first_shadow_view,
            cone_scale,
            cone_offset,
        });
    }
    for (index, view) in views.iter_mut().enumerate() {
        view.atlas_layer = index as u32;
    }
    LightSetup { lights, views }
}

/// Cube faces in the order the shader's `cube_face` picks them: +X, −X, +Y, −Y, +Z, −Z.
pub const CUBE_FACES: [(Vec3, Vec3); 6] = [
    (Vec3::X, Vec3::Y),
    (Vec3::NEG_X, Vec3::Y),
    (Vec3::Y, Vec3::Z),
    (Vec3::NEG_Y, Vec3::Z),
    (Vec3::Z, Vec3::Y),
    (Vec3::NEG_Z, Vec3::Y),
];

pub(crate) fn perspective_view(
    position: Vec3,
    forward: Vec3,
    up: Vec3,
    fov: f32,
    near: f32,
    far: f32,
    res: f32,
) -> ShadowView {
    let view_from_world = glam::camera::rh::view::look_at_mat4(position, position + forward, up);
    let clip_from_view = glam::camera::rh::proj::directx::perspective(fov, 1.0, near, far);
    ShadowView {
        clip_from_world: (clip_from_view * view_from_world).to_cols_array_2d(),
        origin: position.extend(1.0).to_array(),
        texel: [2.0 * (fov * 0.5).tan() / res, res, near, far],
        ..whole_layer()
    }
}

/// A view that fills its layer; [`setup_lights`] numbers the layers.
fn whole_layer() -> ShadowView {
    ShadowView {
        clip_from_world: [[0.0; 4]; 4],
        origin: [0.0; 4],
        texel: [0.0; 4],
        atlas_rect: [0.0, 0.0, 1.0, 0.0],
        atlas_layer: 0,
        _pad: [0; 3],
    }
}

/// Roll of a spot's or a sun's map (shadow map and RSM) about the light's axis, away from the
/// world's axes: atan(1/φ²) = 20.9°. With image rows along the axes, a room's axis-aligned
/// corner lines run along texel rows, and as the light moves a whole row of RSM texels
/// switches from the floor to the wall in one frame (thin-wall-moving: 58 texels every two
/// or three frames), a step in every VAL method's indirect light. At a slope of 1/φ² (φ the
/// golden ratio, the number fractions approximate worst) no row follows such a line, and the
/// texels switch a few at a time.
pub const MAP_ROLL: f32 = 0.364_863;

/// The up vector of a spot's or a sun's map looking along `direction`: [`any_perpendicular`]
/// turned by [`MAP_ROLL`] about the direction.
fn map_up(direction: Vec3) -> Vec3 {
    let axis = direction.try_normalize().unwrap_or(Vec3::NEG_Y);
    Quat::from_axis_angle(axis, MAP_ROLL) * any_perpendicular(axis)
}

/// An up vector that is not parallel to `d`.
fn any_perpendicular(d: Vec3) -> Vec3 {
    if d.y.abs() < 0.99 {
        Vec3::Y
    } else {
        Vec3::Z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cube_faces_cover_their_axis() {
        // The centre of each face's frustum is its axis; the shader's face choice must agree.
        for (i, (forward, up)) in CUBE_FACES.iter().enumerate() {
            let v = perspective_view(Vec3::ZERO, *forward, *up, 1.6, 0.01, 10.0, 256.0);
            let m = Mat4::from_cols_array_2d(&v.clip_from_world);
            let clip = m * (*forward * 2.0).extend(1.0);
            let ndc = clip.truncate() / clip.w;
            assert!(
                ndc.x.abs() < 1e-5 && ndc.y.abs() < 1e-5,
                "face {i}: {ndc:?}"
            );
            assert!(ndc.z > 0.0 && ndc.z < 1.0);
        }
    }

    /// A light looking straight down, sideways or obliquely: the world axes across its map (for
    /// the oblique one the vertical, which the map's frame is taken from) run at MAP_ROLL
    /// (20.9°) or its complement to the texel rows, never along them, and the map still looks
    /// along the light.
    #[test]
    fn maps_are_rolled_off_the_world_axes() {
        for direction in [Vec3::NEG_Y, Vec3::X, Vec3::new(0.3, -1.0, 0.2)] {
            let axis_aligned = direction.abs().max_element() == direction.length();
            let up = map_up(direction);
            let view = perspective_view(Vec3::ZERO, direction, up, 1.2, 0.01, 10.0, 128.0);
            let m = Mat4::from_cols_array_2d(&view.clip_from_world);
            let ndc = |p: Vec3| {
                let c = m * p.extend(1.0);
                glam::Vec2::new(c.x, c.y) / c.w
            };
            let centre = direction.normalize() * 2.0;
            assert!(
                ndc(centre).length() < 1e-5,
                "{direction}: {:?}",
                ndc(centre)
            );
            for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
                let reference = axis == any_perpendicular(direction.normalize());
                if axis.dot(direction.normalize()).abs() > 0.9 || !(axis_aligned || reference) {
                    continue;
                }
                let across = axis.reject_from(direction.normalize()).normalize();
                let d = ndc(centre + across * 1e-2) - ndc(centre);
                let degrees = d.y.atan2(d.x).to_degrees().rem_euclid(90.0);
                let off = degrees.min(90.0 - degrees);
                assert!(
                    off > 15.0 && (off - MAP_ROLL.to_degrees()).abs() < 0.5,
                    "{direction}, axis {axis}: rows at {degrees}°"
                );
            }
        }
    }
}
