//! The one seeded generator (SplitMix64) every part of valgi draws from — sparse-point
//! placement, the bakers, the path tracer — plus the path tracer's and bakers' direction
//! samplers (cosine hemisphere, BRDF importance sampling).

use std::f32::consts::PI;

use glam::Vec3;

use crate::shading::{brdf, reflect};

/// SplitMix64: a tiny counter-based generator. Every (seed, pixel, sample) gets its own stream,
/// so images do not depend on how threads split the work.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// The raw stream whose state starts at `state` (the first number is that of state +
    /// the golden-ratio increment).
    pub fn from_state(state: u64) -> Self {
        Rng(state)
    }

    pub fn new(seed: u64, stream: u64, index: u64) -> Self {
        let mut rng = Rng(seed ^ mix(stream.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ mix(index)));
        rng.next_u64();
        rng
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix(self.0)
    }

    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }
}

fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Orthonormal basis (t, b) around the unit vector `n` (Duff et al. 2017).
pub fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Direction around `axis` with `cos θ = cos_theta` and azimuth `phi`.
fn around(axis: Vec3, cos_theta: f32, phi: f32) -> Vec3 {
    let (t, b) = basis(axis);
    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
    (t * (phi.cos() * sin_theta) + b * (phi.sin() * sin_theta) + axis * cos_theta).normalize()
}

/// Cosine-weighted direction about `n`; pdf = cos θ / π.
pub fn cosine_hemisphere(n: Vec3, u1: f32, u2: f32) -> Vec3 {
    around(n, (1.0 - u1).sqrt(), 2.0 * PI * u2)
}

/// Probability of picking the glossy lobe: its share of the mean albedo.
fn glossy_probability(rho_d: Vec3, rho_s: Vec3) -> Option<f32> {
    let (d, s) = (rho_d.element_sum().max(0.0), rho_s.element_sum().max(0.0));
    (d + s > 0.0).then(|| s / (d + s))
}

/// Density of [`sample_brdf`] choosing `wi`: the mixture
/// `(1−P_s)·cos θ/π + P_s·(k+1)/(2π)·max(0, r·ω_i)^k`.
pub fn brdf_pdf(rho_d: Vec3, rho_s: Vec3, k: f32, n: Vec3, wo: Vec3, wi: Vec3) -> f32 {
    let Some(p_s) = glossy_probability(rho_d, rho_s) else {
        return 0.0;
    };
    let cos = n.dot(wi).max(0.0);
    let r = reflect(-wo, n);
    let lobe = r.dot(wi).max(0.0).powf(k);
    (1.0 - p_s) * cos / PI + p_s * (k + 1.0) / (2.0 * PI) * lobe
}

/// Draws `wi` from the mixture of a cosine lobe (diffuse) and the Phong lobe about the mirror
/// direction (glossy), picked by their albedo shares, and returns `(wi, f·cos θ / pdf)`.
/// `None` when the material is black or the direction falls below the surface (a zero sample).
pub fn sample_brdf(
    rho_d: Vec3,
    rho_s: Vec3,
    k: f32,
    n: Vec3,
    wo: Vec3,
    rng: &mut Rng,
) -> Option<(Vec3, Vec3)> {
    let p_s = glossy_probability(rho_d, rho_s)?;
    let (u0, u1, u2) = (rng.next_f32(), rng.next_f32(), rng.next_f32());
    let wi = if u0 < p_s {
        let r = reflect(-wo, n);
        around(r, u1.powf(1.0 / (k + 1.0)), 2.0 * PI * u2)
    } else {
        cosine_hemisphere(n, u1, u2)
    };
    let cos = n.dot(wi);
    if cos <= 0.0 || !wi.is_finite() {
        return None;
    }
    let pdf = brdf_pdf(rho_d, rho_s, k, n, wo, wi);
    if pdf <= 0.0 || !pdf.is_finite() {
        return None;
    }
    let weight = brdf(rho_d, rho_s, k, n, wi, wo) * (cos / pdf);
    weight.is_finite().then_some((wi, weight))
}
