//! Photon-traced VPLs (seed 001 §5.1, methods §B.3): photons leave each light with equal
//! shares of its power (the budget split across lights in proportion to power, so VPLs carry
//! about equal power); at each diffuse hit the photon leaves a VPL whose power is the photon's
//! times ρ_d (the light it reflects), and continues cosine-distributed with that power. The
//! VPLs of hit b carry bounce b. Every watt is accounted for: emitted = absorbed (1 − ρ_d at
//! each hit) + escaped (photons that leave the scene) + unshot (reflected at the last bounce).

use std::sync::atomic::{AtomicBool, Ordering};

use glam::{DVec3, Vec3};
use rayon::prelude::*;

use crate::atlas::bake::{light_power, EnergyAccount};
use crate::sampling::{cosine_hemisphere, Rng};
use crate::scene::LightKind;
use crate::shading::{spot_attenuation, WorldLight};
use crate::trace::Tracer;

/// A virtual point light left by a photon.
#[derive(Clone, Copy, Debug)]
pub struct Vpl {
    pub position: Vec3,
    /// Unit normal on the side the photon arrived from.
    pub normal: Vec3,
    /// Reflected power (W per channel).
    pub power: [f64; 3],
}

/// VPLs per light and bounce, and the account of the photons' power.
pub struct Photons {
    /// `vpls[light][bounce - 1]`.
    pub vpls: Vec<Vec<Vec<Vpl>>>,
    pub energy: EnergyAccount,
    /// Photon paths traced.
    pub paths: usize,
}

fn lum(v: DVec3) -> f64 {
    v.x + v.y + v.z
}

/// Traces `paths` photons in total from `lights` for `bounces` diffuse hits each. Directional
/// lights shoot from a disc just outside the scene's bounding sphere (centre, radius).
pub fn trace(
    tracer: &Tracer,
    lights: &[WorldLight],
    bounding_sphere: (Vec3, f32),
    paths: usize,
    bounces: usize,
    seed: u64,
    cancel: &AtomicBool,
) -> Photons {
    let (centre, radius) = bounding_sphere;
    let powers: Vec<DVec3> = lights
        .iter()
        .map(|l| match light_power(l) {
            Some(p) => p.as_dvec3(),
            None => l.intensity.as_dvec3() * std::f64::consts::PI * (radius as f64).powi(2),
        })
        .collect();
    let total: f64 = powers.iter().map(|p| lum(*p)).sum();
    let mut energy = EnergyAccount::default();
    let mut vpls = Vec::with_capacity(lights.len());
    let mut traced = 0;
    for (li, light) in lights.iter().enumerate() {
        let share = if total > 0.0 {
            lum(powers[li]) / total
        } else {
            0.0
        };
        let count = ((paths as f64 * share).round() as usize).max(1);
        traced += count;
        // Emission directions and their relative weights (the spot's falloff), normalized
        // so the photons' powers sum to the light's power exactly.
        let emitted: Vec<(Vec3, Vec3, f64)> = (0..count)
            .into_par_iter()
            .map(|i| {
                let mut rng = Rng::new(seed, 0xF070 + li as u64, i as u64);
                let (u1, u2) = (rng.next_f32(), rng.next_f32());
                emission(
                    light,
                    centre,
                    radius,
                    u1,
                    u2,
                    rng.next_f32(),
                    rng.next_f32(),
                )
            })
            .collect();
        let weight_sum: f64 = emitted.iter().map(|e| e.2).sum();
        energy.emitted = add(energy.emitted, powers[li]);
        if weight_sum <= 0.0 {
            energy.escaped = add(energy.escaped, powers[li]);
            vpls.push(vec![Vec::new(); bounces]);
            continue;
        }
        let chunk = 1024;
        let parts: Vec<(Vec<Vec<Vpl>>, [DVec3; 4])> = emitted
            .par_chunks(chunk)
            .enumerate()
            .map(|(ci, block)| {
                let mut out = vec![Vec::new(); bounces];
                // absorbed, escaped, unshot, received at the first hit.
                let mut acc = [DVec3::ZERO; 4];
                if cancel.load(Ordering::Relaxed) {
                    return (out, acc);
                }
                for (k, &(origin, dir, w)) in block.iter().enumerate() {
                    let i = ci * chunk + k;
                    let mut rng = Rng::new(seed, 0xB0B0 + li as u64, i as u64);
                    let mut power = powers[li] * (w / weight_sum);
                    let (mut origin, mut dir) = (origin, dir);
                    for (b, left) in out.iter_mut().enumerate() {
                        let Some(hit) = tracer.intersect(origin, dir, f32::INFINITY) else {
                            acc[1] += power;
                            break;
                        };
                        if b == 0 {
                            acc[3] += power;
                        }
                        let normal = if hit.geometric_normal.dot(dir) > 0.0 {
                            -hit.geometric_normal
                        } else {
                            hit.geometric_normal
                        };
                        let rho = hit.rho_d.as_dvec3().clamp(DVec3::ZERO, DVec3::ONE);
                        let reflected = power * rho;
                        acc[0] += power - reflected;
                        if reflected == DVec3::ZERO {
                            break;
                        }
                        left.push(Vpl {
                            position: hit.position,
                            normal,
                            power: reflected.to_array(),
                        });
                        if b + 1 == bounces {
                            acc[2] += reflected;
                            break;
                        }
                        power = reflected;
                        origin = hit.position + normal * tracer.epsilon;
                        dir = cosine_hemisphere(normal, rng.next_f32(), rng.next_f32());
                    }
                }
                (out, acc)
            })
            .collect();
        let mut per_bounce = vec![Vec::new(); bounces];
        for (out, acc) in parts {
            for (b, v) in out.into_iter().enumerate() {
                per_bounce[b].extend(v);
            }
            energy.absorbed = add(energy.absorbed, acc[0]);
            energy.escaped = add(energy.escaped, acc[1]);
            energy.unshot = add(energy.unshot, acc[2]);
            energy.direct_received = add(energy.direct_received, acc[3]);
        }
        vpls.push(per_bounce);
    }
    Photons {
        vpls,
        energy,
        paths: traced,
    }
}

fn add(a: [f64; 3], b: DVec3) -> [f64; 3] {
    [a[0] + b.x, a[1] + b.y, a[2] + b.z]
}

/// One photon's origin, direction and relative weight.
fn emission(
    light: &WorldLight,
    centre: Vec3,
    radius: f32,
    u1: f32,
    u2: f32,
    u3: f32,
    u4: f32,
) -> (Vec3, Vec3, f64) {
    let (b0, b1) = crate::sampling::basis(light.direction);
    let phi = 2.0 * std::f32::consts::PI * u2;
    let around = |cos: f32| {
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        (b0 * phi.cos() + b1 * phi.sin()) * sin + light.direction * cos
    };
    match light.kind {
        LightKind::Point => (light.position, around(1.0 - 2.0 * u1), 1.0),
        // Cosine-distributed about n̄ (pdf cos θ/π), as the Lambertian lobe sends its power.
        LightKind::Emitter => (light.position, around(u1.sqrt()), 1.0),
        LightKind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            // Uniform over the outer cone's solid angle, weighted by the falloff.
            let cos = 1.0 - u1 * (1.0 - outer_cone_angle.cos());
            let w = spot_attenuation(inner_cone_angle, outer_cone_angle, cos) as f64;
            (light.position, around(cos), w)
        }
        LightKind::Directional => {
            let r = radius * u3.sqrt();
            let a = 2.0 * std::f32::consts::PI * u4;
            let origin =
                centre - light.direction * (radius * 1.01) + (b0 * a.cos() + b1 * a.sin()) * r;
            (origin, light.direction, 1.0)
        }
    }
}
