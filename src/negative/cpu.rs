//! The CPU half of the method and the CPU twin of every kernel in `shaders/negative/`.
//!
//! The Halton selections that depend only on a light's cone or a camera's frustum (never on
//! the scene) are computed here and uploaded: [`positive_samples`] (which RSM texel each
//! positive light reads, and the factor that turns the texel's flux into the light's) and
//! [`camera_candidates`] (the in-frustum pixels, in Halton order, that negative lights are
//! drawn from). The functions after them mirror the kernels one to one, so tests can feed them
//! the GPU's own inputs and compare the outputs.

use std::f32::consts::PI;

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3, Vec4};

use crate::light::rsm::texel_solid_angle;
use crate::raster::shadows::LightSetup;
use crate::raster::types::{LIGHT_DIRECTIONAL, LIGHT_EMITTER, LIGHT_POINT};
use crate::scene::CameraView;
use crate::shading::WorldLight;
use crate::trace::Tracer;

/// Radical inverse Φ_b(i) = Σ_k a_k b^(−k−1) of i = Σ_k a_k b^k.
pub fn radical_inverse(base: u32, mut i: u32) -> f32 {
    let inv = 1.0 / base as f64;
    let (mut f, mut value) = (inv, 0.0f64);
    while i > 0 {
        value += (i % base) as f64 * f;
        i /= base;
        f *= inv;
    }
    value as f32
}

/// The i-th Halton (2,3) direction on the unit sphere, uniform in solid angle:
/// φ = 2πΦ_2(i), δ = arcsin(2Φ_3(i) − 1), s = (sin φ cos δ, cos φ cos δ, sin δ).
pub fn halton_direction(i: u32) -> Vec3 {
    let phi = 2.0 * PI * radical_inverse(2, i);
    let z = 2.0 * radical_inverse(3, i) - 1.0;
    let cos_delta = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new(phi.sin() * cos_delta, phi.cos() * cos_delta, z)
}

/// Which RSM texel a positive light reads (`PositiveSample` in `negative_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PositiveSample {
    pub layer: u32,
    pub texel_x: u32,
    pub texel_y: u32,
    pub light: u32,
    /// Φ_l = flux of the texel × this: (Ω_cone/N)/Ω_texel, or R²/N texels for an
    /// orthographic (directional) layer.
    pub flux_scale: f32,
    pub pad0: f32,
    pub pad1: f32,
    pub pad2: f32,
}

/// A positive or negative indirect point light (`IndirectLight` in `negative_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct IndirectLight {
    /// xyz: world position; w: 1 when the light exists (its sample hit a lit surface).
    pub position: [f32; 4],
    /// xyz: the unit normal it emits about (Lambertian); w: r² of the disc it stands for.
    pub normal: [f32; 4],
    /// rgb: flux Φ (W).
    pub flux: [f32; 4],
}

impl IndirectLight {
    pub fn is_active(&self) -> bool {
        self.position[3] > 0.5
    }
    pub fn position(&self) -> Vec3 {
        Vec4::from(self.position).truncate()
    }
    pub fn normal(&self) -> Vec3 {
        Vec4::from(self.normal).truncate()
    }
    pub fn flux(&self) -> Vec3 {
        Vec4::from(self.flux).truncate()
    }
}

/// Solid angle of a cone of half-angle θ: 2π(1 − cos θ).
pub fn cone_solid_angle(half_angle: f32) -> f32 {
    2.0 * PI * (1.0 - half_angle.cos())
}

/// Solid angle of a symmetric frustum of half-angles α, β: 4·arcsin(sin α·sin β).
pub fn frustum_solid_angle(half_x: f32, half_y: f32) -> f32 {
    4.0 * (half_x.sin() * half_y.sin()).asin()
}

/// The texel of an NDC position on an R×R layer.
fn ndc_texel(ndc_x: f32, ndc_y: f32, resolution: u32) -> [u32; 2] {
    let r = resolution as f32;
    let x = (((ndc_x + 1.0) * 0.5 * r) as i64).clamp(0, resolution as i64 - 1);
    let y = (((1.0 - ndc_y) * 0.5 * r) as i64).clamp(0, resolution as i64 - 1);
    [x as u32, y as u32]
}

/// Halton candidates one light may try before giving up on filling its N samples (a cone of
/// a few degrees accepts a tiny share of the sphere).
const MAX_CANDIDATES: u32 = 1 << 22;

/// The positive-light samples of every light (§A.2): N per light, light by light.
///
/// - Spot: Halton (2,3) directions on the sphere in the spot's RSM frame (cone axis = +z,
///   image x and y = the frame's x and y), the first N with Φ_3(i) ≥ (1 + cos θ_outer)/2
///   kept, each projected to its RSM texel. The set depends on N, the cone and the RSM alone,
///   so a camera move cannot change it and a turning spot carries it along.
/// - Point (and emitter): the first N Halton directions in world axes, each on the cube face
///   that sees it.
/// - Directional: 2-D Halton (Φ_2, Φ_3) over the orthographic RSM square.
pub fn positive_samples(
    setup: &LightSetup,
    lights: &[WorldLight],
    light_sides: &[u32],
    n: u32,
) -> Vec<PositiveSample> {
    let mut out = vec![];
    let mut layer = 0u32;
    for (light_index, (gpu, world)) in setup.lights.iter().zip(lights).enumerate() {
        let resolution = light_sides[light_index];
        let sample = |layer: u32, texel: [u32; 2], flux_scale: f32| PositiveSample {
            layer,
            texel_x: texel[0],
            texel_y: texel[1],
            light: light_index as u32,
            flux_scale,
            ..Default::default()
        };
        // An emitter's cube is a point light's; the directions behind its lobe carry no flux.
        if gpu.kind == LIGHT_POINT || gpu.kind == LIGHT_EMITTER {
            let faces: Vec<Mat4> = (0..6)
                .map(|f| {
                    Mat4::from_cols_array_2d(&setup.views[(layer + f) as usize].clip_from_world)
                })
                .collect();
            let omega_each = 4.0 * PI / n.max(1) as f32;
            for i in 1..=n {
                let s = halton_direction(i);
                let target = world.position + s;
                for (f, clip_from_world) in faces.iter().enumerate() {
                    let clip = *clip_from_world * target.extend(1.0);
                    if clip.w <= 0.0 {
                        continue;
                    }
                    let (x, y) = (clip.x / clip.w, clip.y / clip.w);
                    if x.abs() <= 1.0 && y.abs() <= 1.0 {
                        let texel = ndc_texel(x, y, resolution);
                        let omega = texel_solid_angle(texel[0], texel[1], resolution, 1.0);
                        out.push(sample(layer + f as u32, texel, omega_each / omega));
                        break;
                    }
                }
            }
            layer += 6;
        } else if gpu.kind == LIGHT_DIRECTIONAL {
            let texels_each = (resolution as f32).powi(2) / n.max(1) as f32;
            for i in 1..=n {
                let (u, v) = (radical_inverse(2, i), radical_inverse(3, i));
                let r = resolution as f32;
                let texel = [
                    ((u * r) as u32).min(resolution - 1),
                    ((v * r) as u32).min(resolution - 1),
                ];
                out.push(sample(layer, texel, texels_each));
            }
            layer += 1;
        } else {
            let view = &setup.views[layer as usize];
            let t = view.texel[0] * resolution as f32 * 0.5;
            let half_angle = t.atan();
            let cos_outer = half_angle.cos();
            let omega_each = cone_solid_angle(half_angle) / n.max(1) as f32;
            let threshold = (1.0 + cos_outer) * 0.5;
            let mut kept = 0;
            let mut i = 1;
            while kept < n && i < MAX_CANDIDATES {
                if radical_inverse(3, i) >= threshold {
                    let s = halton_direction(i);
                    if s.z > 0.0 {
                        let texel = ndc_texel(s.x / s.z / t, s.y / s.z / t, resolution);
                        let omega = texel_solid_angle(texel[0], texel[1], resolution, t);
                        out.push(sample(layer, texel, omega_each / omega));
                        kept += 1;
                    }
                }
                i += 1;
            }
            layer += 1;
        }
    }
    out
}

/// The CPU twin of `negative_positives.wgsl`: each sample's texel re-found by a ray through
/// the texel centre instead of the raster RSM. Position, normal (facing the light) and
/// Φ = ρ_d ⊙ I(ω)·Ω_texel·scale (or ρ_d ⊙ E·A_texel·scale); a ray that hits nothing gives an
/// inactive light.
pub fn positive_lights_traced(
    tracer: &Tracer,
    setup: &LightSetup,
    lights: &[WorldLight],
    light_sides: &[u32],
    samples: &[PositiveSample],
) -> Vec<IndirectLight> {
    samples
        .iter()
        .map(|s| {
            let view = &setup.views[s.layer as usize];
            let light = &lights[s.light as usize];
            let resolution = light_sides[s.light as usize];
            let world_from_clip = Mat4::from_cols_array_2d(&view.clip_from_world).inverse();
            let r = resolution as f32;
            let ndc_x = (s.texel_x as f32 + 0.5) / r * 2.0 - 1.0;
            let ndc_y = 1.0 - (s.texel_y as f32 + 0.5) / r * 2.0;
            let near = world_from_clip.project_point3(Vec3::new(ndc_x, ndc_y, 0.0));
            let far = world_from_clip.project_point3(Vec3::new(ndc_x, ndc_y, 1.0));
            let dir = (far - near).normalize();
            let perspective = view.origin[3] > 0.5;
            let origin = if perspective { light.position } else { near };
            let Some(hit) = tracer.intersect(origin, dir, f32::INFINITY) else {
                return IndirectLight::default();
            };
            let (wi, irradiance) = light.incident(hit.position);
            let n = hit.geometric_normal;
            if n.dot(wi) <= 0.0 {
                return IndirectLight::default();
            }
            let (flux, area) = if perspective {
                let t = view.texel[0] * r * 0.5;
                let d2 = (hit.position - light.position).length_squared();
                let omega = texel_solid_angle(s.texel_x, s.texel_y, resolution, t);
                (hit.rho_d * irradiance * d2 * omega, omega * d2)
            } else {
                let area = view.texel[0] * view.texel[0];
                (hit.rho_d * irradiance * area, area)
            };
            let flux = flux * s.flux_scale;
            if flux.max_element() <= 0.0 {
                return IndirectLight::default();
            }
            IndirectLight {
                position: hit.position.extend(1.0).to_array(),
                normal: n.extend(area * s.flux_scale / PI).to_array(),
                flux: flux.extend(0.0).to_array(),
            }
        })
        .collect()
}

/// How the direction of a negative light is weighted (§A.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeightMode {
    /// Σ n_l weighted by the light's share of E_neg (the paper read literally).
    Literal = 0,
    /// Σ n_l weighted by the intensity arriving from every light, without the receiver factor.
    Arriving = 1,
    /// Σ of the propagation directions −t̂_{p→l}, weighted like `Literal`.
    Propagation = 2,
}

impl WeightMode {
    pub const NAMES: &'static [&'static str] = &["literal", "arriving", "propagation"];

    pub fn parse(name: &str) -> Self {
        match name {
            "arriving" => Self::Arriving,
            "propagation" => Self::Propagation,
            _ => Self::Literal,
        }
    }
}

/// A camera-visible surface point (`SurfacePoint` in `negative_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct SurfacePoint {
    /// xyz: world position; w: 1 where a surface covers the pixel.
    pub position: [f32; 4],
    /// xyz: unit normal facing the eye; w: distance to the eye.
    pub normal: [f32; 4],
}

impl SurfacePoint {
    pub fn covered(&self) -> bool {
        self.position[3] > 0.5
    }
    pub fn position(&self) -> Vec3 {
        Vec4::from(self.position).truncate()
    }
    pub fn normal(&self) -> Vec3 {
        Vec4::from(self.normal).truncate()
    }
}

/// What the positive lights give one point (`PositiveTerms` in `negative_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PositiveTerms {
    /// rgb: E_s, the irradiance from every positive light without visibility; a: how many of
    /// them hit the point falloff's d²_min guard.
    pub e_s: [f32; 4],
    /// rgb: E_neg, the irradiance from the lights behind the tangent plane.
    pub e_neg: [f32; 4],
    /// xyz: the weighted direction D (not normalized).
    pub direction: [f32; 4],
}

/// |cos| below which a light counts as in a point's tangent plane and adds nothing to E_neg
/// (`COPLANAR_COS` in `negative_common.wgsl`): positions rebuilt from depth wobble by a
/// fraction of a pixel, which would otherwise put a wall's own lights behind it.
pub const COPLANAR_COS: f32 = 0.01;

pub use crate::shading::luminance;

/// The distance term of every point light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Falloff {
    /// 1/max(d², d²_min): the paper's point lights with a tiny guard.
    Point { d2_min: f32 },
    /// 1/(d² + r²): each light the disc it stands for (r² in `normal.w`).
    Disc,
}

impl Falloff {
    pub const NAMES: &'static [&'static str] = &["point", "disc"];

    fn denominator(self, d2: f32, r2: f32) -> f32 {
        match self {
            Falloff::Point { d2_min } => d2.max(d2_min),
            Falloff::Disc => d2 + r2,
        }
    }
}

/// A Lambertian point light seen from p (the twin of `emitter`): with d = x_l − p, returns
/// Φ/π·max(0, −n_l·d)/(|d|²·D), D the falloff's distance term, together with d and |d|², so
/// that the irradiance at a receiver of normal n is that times max(0, n·d) =
/// Φ/π·max(0, n_l·t̂_{l→p})·max(0, n·t̂_{p→l})/D. The cosines stay unnormalized, as the shader
/// keeps them (one division a pair, no square root), so that near-grazing ones round alike.
/// `None` for an inactive light, or one at p (|d|²·D = 0).
fn light_terms(p: Vec3, light: &IndirectLight, falloff: Falloff) -> Option<(Vec3, Vec3, f32)> {
    let d = light.position() - p;
    let d2 = d.length_squared();
    let scale = d2 * falloff.denominator(d2, light.normal[3]);
    if !light.is_active() || scale <= 0.0 {
        return None;
    }
    let emit = light.normal().dot(-d).max(0.0) / scale;
    Some((light.flux() / PI * emit, d, d2))
}

/// Whether a light at d from a point of normal n lies behind its tangent plane by more than
/// `COPLANAR_COS`: −n·t̂ > c, as n·d < 0 and (n·d)² > c²·|d|².
fn behind_plane(n_dot_d: f32, d2: f32) -> bool {
    n_dot_d < 0.0 && n_dot_d * n_dot_d > COPLANAR_COS * COPLANAR_COS * d2
}

/// The CPU twin of `positive_terms` in `negative_view.wgsl` (§A.3, §A.4): E_s, E_neg and the
/// weighted direction at one point from all positive lights.
pub fn positive_terms(
    p: Vec3,
    n: Vec3,
    lights: &[IndirectLight],
    falloff: Falloff,
    mode: WeightMode,
) -> (Vec3, Vec3, Vec3) {
    let (mut e_s, mut e_neg, mut dir) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    for light in lights {
        let Some((emitted, d, d2)) = light_terms(p, light, falloff) else {
            continue;
        };
        let n_dot_d = n.dot(d);
        e_s += emitted * n_dot_d.max(0.0);
        let behind = if behind_plane(n_dot_d, d2) {
            emitted * -n_dot_d
        } else {
            Vec3::ZERO
        };
        e_neg += behind;
        dir += match mode {
            WeightMode::Literal => luminance(behind) * light.normal(),
            // The arriving intensity without the receiver's cosine.
            WeightMode::Arriving => luminance(emitted * d2.sqrt()) * light.normal(),
            WeightMode::Propagation => luminance(behind) * -(d / d2.sqrt()),
        };
    }
    (e_s, e_neg, dir)
}

/// How many lights' d² falls below the point falloff's d²_min at p (0 with the disc
/// falloff): the twin of the count `positive_terms` keeps in `e_s.w`.
pub fn distance_clamped(p: Vec3, lights: &[IndirectLight], falloff: Falloff) -> u32 {
    let Falloff::Point { d2_min } = falloff else {
        return 0;
    };
    lights
        .iter()
        .filter(|l| {
            let d2 = (l.position() - p).length_squared();
            l.is_active() && d2 > 0.0 && d2 < d2_min
        })
        .count() as u32
}

/// The CPU twin of `negative_irradiance`: E_n at one point from the negative lights (§A.6).
pub fn negative_irradiance(
    p: Vec3,
    n: Vec3,
    negatives: &[IndirectLight],
    falloff: Falloff,
) -> Vec3 {
    let mut e = Vec3::ZERO;
    for light in negatives {
        if let Some((emitted, d, _)) = light_terms(p, light, falloff) {
            e += emitted * n.dot(d).max(0.0);
        }
    }
    e
}

/// The in-frustum Halton (2,3) camera directions, in order, as full-resolution pixel indices
/// (§A.5): directions in the camera's frame (+z forward, x right, y up) kept when they fall in
/// the frustum, at most `limit` of them. Also returns the frustum's solid angle.
pub fn camera_candidates(
    camera: &CameraView,
    width: u32,
    height: u32,
    limit: u32,
) -> (Vec<u32>, f32) {
    let [left, right, bottom, top] = camera.tangent_extents();
    let half_x = right.max(-left).atan();
    let half_y = top.max(-bottom).atan();
    let omega = if camera.off_axis.is_none() {
        frustum_solid_angle(half_x, half_y)
    } else {
        // An off-axis frustum: the solid angle of its rectangle at unit distance.
        off_axis_solid_angle(left, right, bottom, top)
    };
    let mut out = vec![];
    let mut i = 1u32;
    while (out.len() as u32) < limit && i < MAX_CANDIDATES {
        let s = halton_direction(i);
        i += 1;
        if s.z <= 0.0 {
            continue;
        }
        let (x, y) = (s.x / s.z, s.y / s.z);
        if x < left || x > right || y < bottom || y > top {
            continue;
        }
        let px = (((x - left) / (right - left) * width as f32) as u32).min(width - 1);
        let py = (((top - y) / (top - bottom) * height as f32) as u32).min(height - 1);
        out.push(py * width + px);
    }
    (out, omega)
}

/// Solid angle of the rectangle [l, r]×[b, t] at unit distance (sum of the two triangles'
/// solid angles by Van Oosterom–Strackee).
fn off_axis_solid_angle(l: f32, r: f32, b: f32, t: f32) -> f32 {
    let c = [
        Vec3::new(l, b, 1.0),
        Vec3::new(r, b, 1.0),
        Vec3::new(r, t, 1.0),
        Vec3::new(l, t, 1.0),
    ];
    let tri = |a: Vec3, b: Vec3, c: Vec3| {
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let num = a.dot(b.cross(c)).abs();
        let den = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        2.0 * num.atan2(den)
    };
    tri(c[0], c[1], c[2]) + tri(c[0], c[2], c[3])
}

/// The CPU twin of `select_negatives` (§A.5): walks the candidates in order, keeps those
/// whose point has E_neg > 0 and a direction, until `m` are kept. K = candidates tried, and
/// Φ_m = E_neg·(Ω_frustum/K)·|p − eye|², no albedo. `terms(pixel)` gives the point and its
/// terms (the upsampled ones where the low-resolution path is on).
pub fn select_negatives(
    candidates: &[u32],
    m: u32,
    eye: Vec3,
    omega_frustum: f32,
    terms: impl Fn(u32) -> (SurfacePoint, PositiveTerms),
) -> (Vec<IndirectLight>, u32) {
    let mut picked = vec![];
    let mut tried = 0u32;
    for &pixel in candidates {
        if picked.len() as u32 >= m {
            break;
        }
        tried += 1;
        let (point, t) = terms(pixel);
        let e_neg = Vec4::from(t.e_neg).truncate();
        let dir = Vec4::from(t.direction).truncate();
        if point.covered() && luminance(e_neg) > 0.0 && dir.length_squared() > 0.0 {
            picked.push((point, e_neg, dir.normalize()));
        }
    }
    let k = tried.max(1) as f32;
    let lights = picked
        .into_iter()
        .map(|(point, e_neg, dir)| {
            let area = omega_frustum / k * (point.position() - eye).length_squared();
            IndirectLight {
                position: point.position().extend(1.0).to_array(),
                normal: dir.extend(area / PI).to_array(),
                flux: (e_neg * area).extend(0.0).to_array(),
            }
        })
        .collect();
    (lights, tried)
}

/// The CPU twin of `block_representative` (`points_blocks`): of a 2×2 block's covered points, the one whose eye distance
/// is nearest the block's median (`None` when none is covered).
pub fn block_representative(block: &[SurfacePoint]) -> Option<usize> {
    let mut depths: Vec<f32> = block
        .iter()
        .filter(|p| p.covered())
        .map(|p| p.normal[3])
        .collect();
    if depths.is_empty() {
        return None;
    }
    depths.sort_by(f32::total_cmp);
    let k = depths.len();
    let median = if k % 2 == 1 {
        depths[k / 2]
    } else {
        0.5 * (depths[k / 2 - 1] + depths[k / 2])
    };
    let mut best = None;
    let mut best_gap = f32::INFINITY;
    for (i, p) in block.iter().enumerate() {
        if p.covered() && (p.normal[3] - median).abs() < best_gap {
            best_gap = (p.normal[3] - median).abs();
            best = Some(i);
        }
    }
    best
}

/// The CPU twin of `discontinuous` (`points_blocks`, §A.7): a covered pixel must be
/// recomputed when its low-resolution parent is uncovered, lies more than τ_x pixel
/// footprints away, or turns its normal past τ_n. `footprint_scale` = 2·tan(fov_y/2)/H.
pub fn discontinuous(
    p: &SurfacePoint,
    parent: &SurfacePoint,
    threshold_pos: f32,
    threshold_normal: f32,
    footprint_scale: f32,
) -> bool {
    if !p.covered() {
        return false;
    }
    if !parent.covered() {
        return true;
    }
    let footprint = p.normal[3] * footprint_scale;
    (p.position() - parent.position()).length() > threshold_pos * footprint
        || p.normal().dot(parent.normal()) < threshold_normal
}

/// The CPU twin of `gather`: ρ_d/π·(E_s − E_n), clamped to ≥ 0 per channel; returns the
/// radiance and what the clamp removed.
pub fn final_indirect(rho_d: Vec3, e_s: Vec3, e_n: Vec3) -> (Vec3, Vec3) {
    let raw = rho_d / PI * (e_s - e_n);
    let clamped = raw.max(Vec3::ZERO);
    (clamped, clamped - raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A light at `position` emitting about `normal`, flux Φ = π (so Φ/π = 1) in every channel.
    fn light(position: Vec3, normal: Vec3, r2: f32) -> IndirectLight {
        IndirectLight {
            position: position.extend(1.0).to_array(),
            normal: normal.normalize().extend(r2).to_array(),
            flux: [PI, PI, PI, 0.0],
        }
    }

    fn near(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-5 * b.abs().max(1e-12)
    }

    const POINT: Falloff = Falloff::Point { d2_min: 1e-4 };

    /// The closed form of two Lambertian cosines over d² for a light at height h and lateral
    /// offset x above a receiver at the origin, both facing each other along z.
    #[test]
    fn one_light_gives_the_closed_form_in_front_of_and_behind_the_receiver() {
        let (x, h) = (0.7f32, 1.3f32);
        let r2 = x * x + h * h;
        let l = light(Vec3::new(x, 0.0, h), Vec3::NEG_Z, 0.0);
        // cos_l = cos_p = h/r: E = Φ/π·h²/r⁴.
        let expected = h * h / (r2 * r2);
        for mode in [
            WeightMode::Literal,
            WeightMode::Arriving,
            WeightMode::Propagation,
        ] {
            let (e_s, e_neg, dir) = positive_terms(Vec3::ZERO, Vec3::Z, &[l], POINT, mode);
            assert!(near(e_s.x, expected), "{e_s} vs {expected}");
            assert_eq!(e_neg, Vec3::ZERO);
            if mode == WeightMode::Arriving {
                // Y of the arriving intensity without the receiver's cosine: Φ/π·cos_l/d².
                let y = h / r2.sqrt() / r2;
                assert!((dir - y * Vec3::NEG_Z).length() <= 1e-5 * y, "{dir}");
            } else {
                assert_eq!(dir, Vec3::ZERO, "no light behind the plane");
            }
        }
        // The receiver turned over: the same light now arrives from behind its tangent plane.
        let (e_s, e_neg, dir) =
            positive_terms(Vec3::ZERO, Vec3::NEG_Z, &[l], POINT, WeightMode::Literal);
        assert_eq!(e_s, Vec3::ZERO);
        assert!(near(e_neg.x, expected), "{e_neg} vs {expected}");
        assert!((dir - expected * Vec3::NEG_Z).length() <= 1e-5 * expected);
        let (_, _, dir) = positive_terms(
            Vec3::ZERO,
            Vec3::NEG_Z,
            &[l],
            POINT,
            WeightMode::Propagation,
        );
        let away = -Vec3::new(x, 0.0, h) / r2.sqrt();
        assert!((dir - expected * away).length() <= 1e-5 * expected, "{dir}");
        // E_n takes the front side only, like E_s.
        let e_n = negative_irradiance(Vec3::ZERO, Vec3::Z, &[l], POINT);
        assert!(near(e_n.x, expected));
        assert_eq!(
            negative_irradiance(Vec3::ZERO, Vec3::NEG_Z, &[l], POINT),
            Vec3::ZERO
        );
    }

    #[test]
    fn the_falloffs_guard_and_soften_the_distance_term() {
        // Straight above at h: cos_l = cos_p = 1.
        let h = 0.005f32;
        let l = light(Vec3::new(0.0, 0.0, h), Vec3::NEG_Z, 0.02);
        let (e_s, ..) = positive_terms(Vec3::ZERO, Vec3::Z, &[l], POINT, WeightMode::Literal);
        assert!(near(e_s.x, 1.0 / 1e-4), "the guard: 1/d²_min, {e_s}");
        assert_eq!(distance_clamped(Vec3::ZERO, &[l], POINT), 1);
        let (e_s, ..) = positive_terms(
            Vec3::ZERO,
            Vec3::Z,
            &[l],
            Falloff::Disc,
            WeightMode::Literal,
        );
        assert!(
            near(e_s.x, 1.0 / (h * h + 0.02)),
            "the disc: 1/(d² + r²), {e_s}"
        );
        assert_eq!(distance_clamped(Vec3::ZERO, &[l], Falloff::Disc), 0);
        // A light at the receiver, or one that does not exist, adds nothing.
        let at = light(Vec3::ZERO, Vec3::NEG_Z, 0.0);
        let mut gone = light(Vec3::new(0.0, 0.0, 1.0), Vec3::NEG_Z, 0.0);
        gone.position[3] = 0.0;
        for l in [at, gone] {
            let (e_s, e_neg, dir) =
                positive_terms(Vec3::ZERO, Vec3::Z, &[l], POINT, WeightMode::Propagation);
            assert_eq!((e_s, e_neg, dir), (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO));
        }
    }

    #[test]
    fn a_light_in_the_receivers_tangent_plane_is_neither_in_front_nor_behind() {
        // −cos_p = 0.005 < COPLANAR_COS: not behind; 0.02 > COPLANAR_COS: behind. At 3 m, so
        // that the test's |d|² matters ((n·d)² = 2.25e-4 > c² = 1e-4 in the first case).
        for (z, behind) in [(-0.005f32, false), (-0.02, true)] {
            let position = 3.0 * Vec3::new((1.0 - z * z).sqrt(), 0.0, z);
            let l = light(position, Vec3::new(-1.0, 0.0, 0.0), 0.0);
            let (e_s, e_neg, _) =
                positive_terms(Vec3::ZERO, Vec3::Z, &[l], POINT, WeightMode::Literal);
            assert_eq!(e_s, Vec3::ZERO);
            assert_eq!(e_neg.x > 0.0, behind, "z = {z}: {e_neg}");
            if behind {
                // cos_l = √(1 − z²), −cos_p = −z, d² = 9.
                assert!(near(e_neg.x, (1.0 - z * z).sqrt() * -z / 9.0), "{e_neg}");
            }
        }
    }
}
