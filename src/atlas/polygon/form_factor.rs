//! Irradiance from polygon and sphere lights (seed 001 §6, methods §B.7–B.8): the analytic
//! point-to-polygon form factor (Eqs. 3–4) after clipping the polygon to the receiver's
//! horizon, the ε-shift of receivers at corners, the point-light fallback at tiny solid
//! angles, and the horizon-clipped sphere cap. Evaluated in f64: in f32 the edge sum loses
//! its digits where the polygon subtends a tiny angle (the instability the paper works
//! around with its point-light switch).

use glam::{DVec3, Vec3};

/// Largest polygon light after horizon clipping: 8 vertices (the paper's limit) re-simplified
/// after cell clipping, plus one from the horizon.
pub const MAX_CLIPPED: usize = 16;

/// Bounding radius over distance below which a light is evaluated as a point light.
pub const POINT_FALLBACK: f64 = 0.01;

/// Point-to-polygon form factor `F_{dA_y→A}` of the convex or concave polygon `vertices`
/// (world space, any winding) from the point `p` with unit normal `n`, the polygon clipped to
/// the half-space above `p`'s tangent plane first (Eq. 3 holds only for a fully visible
/// polygon). `F = 1/(2π)·Σ γ_i·n·Γ̂_i`, `Γ_i = V_i × V_{i+1}`, `γ_i = ∠(V_i, V_{i+1})`; the
/// sign follows the winding, so the magnitude is returned.
pub fn polygon_form_factor(p: DVec3, n: DVec3, vertices: &[DVec3]) -> f64 {
    let mut clipped = [DVec3::ZERO; MAX_CLIPPED];
    let count = clip_to_horizon(p, n, vertices, &mut clipped);
    if count < 3 {
        return 0.0;
    }
    unclipped_form_factor(p, n, &clipped[..count])
}

/// Eq. 3 without horizon clipping (exact only when the whole polygon is above the horizon).
pub fn unclipped_form_factor(p: DVec3, n: DVec3, vertices: &[DVec3]) -> f64 {
    let k = vertices.len();
    let mut sum = 0.0;
    for i in 0..k {
        let a = vertices[i] - p;
        let b = vertices[(i + 1) % k] - p;
        let cross = a.cross(b);
        let len = cross.length();
        if len <= 1e-300 {
            continue;
        }
        let gamma = len.atan2(a.dot(b));
        sum += gamma * n.dot(cross) / len;
    }
    (sum / (2.0 * std::f64::consts::PI)).abs()
}

/// Sutherland–Hodgman against the plane `n·(q − p) ≥ 0`; returns the vertex count written
/// into `out` (a convex k-gon stays convex with at most k + 1 vertices).
pub fn clip_to_horizon(p: DVec3, n: DVec3, vertices: &[DVec3], out: &mut [DVec3]) -> usize {
    let k = vertices.len();
    let mut m = 0;
    for i in 0..k {
        let a = vertices[i];
        let b = vertices[(i + 1) % k];
        let (da, db) = (n.dot(a - p), n.dot(b - p));
        if da >= 0.0 && m < out.len() {
            out[m] = a;
            m += 1;
        }
        if (da >= 0.0) != (db >= 0.0) && m < out.len() {
            let t = da / (da - db);
            out[m] = a + (b - a) * t;
            m += 1;
        }
    }
    m
}

/// The point-light law from a light of power `power` at `c` with normal `n_c` to `(p, n_p)`:
/// `Φ·max(0, n_c·ω̂)·max(0, −n_p·ω̂)/(π d²)`, ω̂ from the light to p.
pub fn point_irradiance(power: f64, c: DVec3, n_c: DVec3, p: DVec3, n_p: DVec3) -> f64 {
    let d = p - c;
    let d2 = d.length_squared();
    if d2 <= 1e-300 {
        return 0.0;
    }
    let w = d / d2.sqrt();
    power * n_c.dot(w).max(0.0) * (-n_p.dot(w)).max(0.0) / (std::f64::consts::PI * d2)
}

/// A polygon light as the accumulation sees it.
#[derive(Clone, Debug)]
pub struct PolygonLight {
    /// Convex, counter-clockwise about `normal`, at most [`super::lights::MAX_VERTICES`].
    pub vertices: Vec<Vec3>,
    pub normal: Vec3,
    pub centre: Vec3,
    /// Φ (W per channel): the sum of its VPLs' powers.
    pub power: [f64; 3],
    pub area: f32,
    /// Largest distance from the centre to a vertex.
    pub radius: f32,
}

/// A sphere light for a non-planar cluster (Hašan et al. 2009's approximation, §B.7).
#[derive(Clone, Debug)]
pub struct SphereLight {
    pub centre: Vec3,
    pub radius: f32,
    /// Emission lobe: Lambertian about this normal, or isotropic when `None`.
    pub normal: Option<Vec3>,
    pub power: [f64; 3],
}

/// Irradiance per watt of the polygon light at the receiver `(p, n)`, with the ε-shift: a
/// receiver facing the light's centre whose height above the light's plane is within `eps`
/// slides in its tangent plane until it is `eps` above (at most `max_shift`), so texels at a
/// concave corner (whose centres may lie on or just below the other surface's plane) see the
/// light the surface next to them sees. The shifted point is used for the form factor only,
/// and only where `clear(p, p′)` says the slide crosses no geometry (with coarse texels the
/// ε-region reaches through walls: a door's face beside its hinge would slide through the
/// partition and take the light of the partition's far side).
pub fn polygon_irradiance(
    light: &PolygonLight,
    p: Vec3,
    n: Vec3,
    eps: f32,
    max_shift: f32,
    clear: &dyn Fn(Vec3, Vec3) -> bool,
) -> f64 {
    let (nl, c) = (light.normal.as_dvec3(), light.centre.as_dvec3());
    let (mut p, n) = (p.as_dvec3(), n.as_dvec3());
    let h = nl.dot(p - c);
    let eps = eps as f64;
    if h.abs() < eps {
        // Only a receiver meeting the light's plane at an angle (a concave corner) slides; one
        // parallel to it within the ε-region is on the light's own surface or on the back of
        // the same sheet (a door's other face, whose fitted plane may be tilted by 10⁻⁵ and put
        // the receiver a micrometre "in front"), and gets nothing.
        let u = nl - n * nl.dot(n);
        let along = u.length();
        if n.dot(c - p) <= 0.0 || nl.dot(n).abs() > 0.9 || along < 1e-3 {
            return 0.0;
        }
        let shift = ((eps - h) / along).min(max_shift as f64);
        let shifted = p + u / along * shift;
        if !clear(p.as_vec3(), shifted.as_vec3()) {
            return 0.0;
        }
        p = shifted;
    }
    // Early exits: behind the emitting side, or the whole polygon below the horizon.
    if nl.dot(p - c) <= 0.0 {
        return 0.0;
    }
    let mut vertices = [DVec3::ZERO; MAX_CLIPPED];
    let count = light.vertices.len().min(MAX_CLIPPED);
    for (d, v) in vertices.iter_mut().zip(&light.vertices) {
        *d = v.as_dvec3();
    }
    let vertices = &vertices[..count];
    if vertices.iter().all(|v| n.dot(*v - p) <= 0.0) {
        return 0.0;
    }
    let d = (p - c).length();
    let area = light.area as f64;
    if light.radius as f64 <= POINT_FALLBACK * d {
        return point_irradiance(1.0, c, nl, p, n);
    }
    polygon_form_factor(p, n, vertices) / area
}

/// `∫_cap max(0, n·ω) dω` over the cap of half-angle α (sin α = r/d) around the direction at
/// angle β from n, clipped at the horizon; π when the point is inside the sphere.
pub fn sphere_cap_cosine(r: f64, d: f64, cos_beta: f64) -> f64 {
    use std::f64::consts::PI;
    if d <= r {
        return PI;
    }
    let sin_alpha = r / d;
    let h = d / r;
    if cos_beta >= sin_alpha {
        return PI * cos_beta * sin_alpha * sin_alpha;
    }
    if cos_beta <= -sin_alpha {
        return 0.0;
    }
    // Partly below the horizon (Snyder 1996 as written in Lagarde & de Rousiers 2014).
    let sin_beta = (1.0 - cos_beta * cos_beta).max(0.0).sqrt();
    let x = (h * h - 1.0).sqrt();
    let y = if sin_beta > 1e-12 {
        (-x * cos_beta / sin_beta).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let s = (1.0 - y * y).max(0.0).sqrt();
    ((cos_beta * y.acos() - x * sin_beta * s) / (h * h) + (sin_beta * s / x).atan()).max(0.0)
}

/// Irradiance per watt of the sphere light at `(p, n)`: `J(ω)/(π r²)·∫_cap cos`, the radiant
/// intensity `J = max(0, n̄·ω)/π` (Lambertian) or `1/(4π)` (isotropic), so far away it is the
/// point-light law and near the sphere it stays bounded.
pub fn sphere_irradiance(light: &SphereLight, p: Vec3, n: Vec3) -> f64 {
    use std::f64::consts::PI;
    let (c, p, n) = (light.centre.as_dvec3(), p.as_dvec3(), n.as_dvec3());
    let to = p - c;
    let d = to.length();
    if d <= 1e-12 {
        return 0.0;
    }
    let w = to / d;
    let intensity = match light.normal {
        Some(nl) => nl.as_dvec3().dot(w).max(0.0) / PI,
        None => 0.25 / PI,
    };
    if intensity <= 0.0 {
        return 0.0;
    }
    let r = (light.radius as f64).max(1e-6 * d);
    let cos_beta = -n.dot(w);
    if r <= POINT_FALLBACK * d {
        return intensity * cos_beta.max(0.0) / (d * d);
    }
    intensity / (PI * r * r) * sphere_cap_cosine(r, d, cos_beta)
}
