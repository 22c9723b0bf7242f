//! The material and light model of DESIGN §3 on the CPU: the twin of `shaders/base/common.wgsl`
//! and of the per-light loop in `shaders/base/direct_light.wgsl`. Tests evaluate it next to GPU
//! images; the reference path tracer uses the same functions, so every method shares one
//! definition of the physics.

use glam::{Mat4, Vec3};

use crate::scene::{LightKind, Scene};

/// Y of linear Rec. 709 RGB.
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// `f_r = ρ_d/π + ρ_s·(k+2)/(2π)·max(0, r·ω_i)^k` with `r = reflect(−ω_o, n)`.
pub fn brdf(rho_d: Vec3, rho_s: Vec3, k: f32, n: Vec3, wi: Vec3, wo: Vec3) -> Vec3 {
    let r = reflect(-wo, n);
    let lobe = r.dot(wi).max(0.0).powf(k);
    rho_d / std::f32::consts::PI + rho_s * ((k + 2.0) / (2.0 * std::f32::consts::PI)) * lobe
}

/// Mirror direction of `d` about the unit normal `n` (WGSL's `reflect`).
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * n.dot(d) * n
}

/// KHR_lights_punctual spot cone: `saturate(cos·scale + offset)²` with
/// `scale = 1/max(0.001, cos inner − cos outer)` and `offset = −cos outer · scale`.
/// `cos_angle` is the cosine between the spot's axis and the direction to the surface.
pub fn spot_attenuation(inner_cone_angle: f32, outer_cone_angle: f32, cos_angle: f32) -> f32 {
    let scale = 1.0 / (inner_cone_angle.cos() - outer_cone_angle.cos()).max(0.001);
    let offset = -outer_cone_angle.cos() * scale;
    (cos_angle * scale + offset).clamp(0.0, 1.0).powi(2)
}

/// KHR_lights_punctual smooth range window `clamp(1 − (d/range)⁴, 0, 1)`; 1 without a range.
pub fn range_window(range: Option<f32>, distance: f32) -> f32 {
    match range {
        Some(range) if range > 0.0 => (1.0 - (distance / range).powi(4)).clamp(0.0, 1.0),
        _ => 1.0,
    }
}

/// Lambertian emitter lobe `max(0, n̄·ω)`: the share of an emitter proxy's I0 sent toward the
/// unit direction `to_surface` (n̄ = `axis`, the direction the light points along).
pub fn emitter_lobe(axis: Vec3, to_surface: Vec3) -> f32 {
    axis.dot(to_surface).max(0.0)
}

/// A punctual light placed in the world.
#[derive(Clone, Copy, Debug)]
pub struct WorldLight {
    pub kind: LightKind,
    pub position: Vec3,
    /// Unit direction the light points along.
    pub direction: Vec3,
    /// W/sr (point, spot; I0 of an emitter) or W/m² (directional), per channel.
    pub intensity: Vec3,
    pub range: Option<f32>,
}

impl WorldLight {
    /// Every light of the scene placed by the node transforms `world_from_node`. A light sits
    /// at its node's origin and points down the node's −z axis.
    pub fn from_scene(scene: &Scene, world_from_node: &[Mat4]) -> Vec<WorldLight> {
        scene
            .lights
            .iter()
            .map(|light| {
                let m = world_from_node[light.node];
                WorldLight {
                    kind: light.kind,
                    position: m.transform_point3(Vec3::ZERO),
                    direction: m
                        .transform_vector3(Vec3::NEG_Z)
                        .try_normalize()
                        .unwrap_or(Vec3::NEG_Z),
                    intensity: light.radiometric(),
                    range: light.range,
                }
            })
            .collect()
    }

    /// Direction from `p` to the light and the irradiance it delivers at `p` on a surface
    /// facing it (no cosine, no visibility).
    pub fn incident(&self, p: Vec3) -> (Vec3, Vec3) {
        match self.kind {
            LightKind::Directional => (-self.direction, self.intensity),
            LightKind::Point | LightKind::Spot { .. } | LightKind::Emitter => {
                let to_light = self.position - p;
                let d2 = to_light.length_squared().max(1e-12);
                let d = d2.sqrt();
                let wi = to_light / d;
                let mut falloff = range_window(self.range, d) / d2;
                if let LightKind::Spot {
                    inner_cone_angle,
                    outer_cone_angle,
                } = self.kind
                {
                    falloff *= spot_attenuation(
                        inner_cone_angle,
                        outer_cone_angle,
                        self.direction.dot(-wi),
                    );
                } else if self.kind == LightKind::Emitter {
                    falloff *= emitter_lobe(self.direction, -wi);
                }
                (wi, self.intensity * falloff)
            }
        }
    }

    /// Radiance toward `eye` from an unoccluded point `p` with normal `n` and material
    /// (ρ_d, ρ_s, k), lit by this light alone.
    pub fn reflected(&self, p: Vec3, n: Vec3, eye: Vec3, rho_d: Vec3, rho_s: Vec3, k: f32) -> Vec3 {
        let (wi, irradiance) = self.incident(p);
        let cos = n.dot(wi);
        if cos <= 0.0 {
            return Vec3::ZERO;
        }
        let wo = (eye - p).normalize();
        brdf(rho_d, rho_s, k, n, wi, wo) * irradiance * cos
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn phong_lobe_is_normalized() {
        // ∫ (k+2)/(2π) cos^k(α) cos θ dω = 1 when the lobe points along the normal (normal
        // incidence), so a white specular surface reflects all the light there.
        let n = Vec3::Y;
        for k in [1.0f32, 10.0, 100.0] {
            let steps = 2000;
            let mut integral = 0.0f64;
            for i in 0..steps {
                let theta = (i as f64 + 0.5) / steps as f64 * std::f64::consts::FRAC_PI_2;
                let wi = Vec3::new(theta.sin() as f32, theta.cos() as f32, 0.0);
                let f = brdf(Vec3::ZERO, Vec3::ONE, k, n, wi, n).x as f64;
                integral += f
                    * theta.cos()
                    * theta.sin()
                    * 2.0
                    * std::f64::consts::PI
                    * (std::f64::consts::FRAC_PI_2 / steps as f64);
            }
            assert!((integral - 1.0).abs() < 2e-3, "k = {k}: {integral}");
        }
    }

    #[test]
    fn spot_cone_edges() {
        let (inner, outer) = (0.3f32, 0.6f32);
        assert_eq!(spot_attenuation(inner, outer, inner.cos()), 1.0);
        assert_eq!(spot_attenuation(inner, outer, 1.0), 1.0);
        assert_eq!(spot_attenuation(inner, outer, outer.cos()), 0.0);
        let mid = (inner.cos() + outer.cos()) * 0.5;
        assert!((spot_attenuation(inner, outer, mid) - 0.25).abs() < 1e-5);
    }

    #[test]
    fn range_window_ends_at_range() {
        assert_eq!(range_window(None, 100.0), 1.0);
        assert_eq!(range_window(Some(2.0), 2.0), 0.0);
        assert!((range_window(Some(2.0), 1.0) - (1.0 - 1.0 / 16.0)).abs() < 1e-6);
    }
}
