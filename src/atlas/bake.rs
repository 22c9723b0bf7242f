//! The multi-bounce light-atlas baker (seed 000, DESIGN §5), on the CPU with rayon:
//! discretize into VPL patches, distribute direct light with depth-map visibility, progressive
//! refinement with depth cubes at the shooters, then fill the atlas from every patch plus a
//! short-ray near-field gather per texel. Depth maps answer visibility where they are sure; a
//! ray through the scene's BVH decides near their depth edges. Irradiance is kept per bounce,
//! so callers pick any range of bounces.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use std::num::NonZero;

use glam::{Mat4, Vec3};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

use super::depth::{DepthCube, DepthOrtho, ShadowTest};
use super::layout::{self, AtlasLayout};
use crate::image_io::{Image, ImageError};
use crate::reference::sampling::{cosine_hemisphere, Rng as SampleRng};
use crate::reference::Tracer;
use crate::scene::{LightKind, Material, Scene};
use crate::shading::{spot_attenuation, WorldLight};

/// Knobs of one bake.
#[derive(Clone, Debug)]
pub struct BakeSettings {
    /// Number of VPL patches `n`.
    pub vpls: usize,
    /// Indirect bounces `B` kept in the atlas (bounce 1 = light reflected once).
    pub bounces: u32,
    /// Atlas width and height in texels.
    pub atlas_res: u32,
    /// Sample points per patch (visibility and area).
    pub samples_per_vpl: usize,
    /// Face resolution of the shooters' depth cubes.
    pub cube_res: usize,
    /// Face resolution of the lights' depth maps.
    pub light_map_res: usize,
    /// Stop shooting when the largest unshot power is below this fraction of the emitted.
    pub threshold: f64,
    /// Dilation passes across chart borders.
    pub dilate: u32,
    /// Cosine-weighted rays per texel (a square number: stratified √M × √M) of the near-field
    /// gather; 0 turns the gather off and every sample counts as a disc.
    pub near_rays: u32,
    /// Radius of the near field in sample spacings √C ...
    pub near_radius: f32,
    /// ... at most this fraction of the scene's bounding-box diagonal (few VPLs mean long
    /// near-field rays: at 100 VPLs 6√C is half of Cornell, and the gather took 5 of the
    /// bake's 5.5 s).
    pub near_radius_max: f32,
    pub seed: u64,
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            vpls: 400,
            bounces: 4,
            atlas_res: 256,
            samples_per_vpl: 10,
            cube_res: 32,
            light_map_res: 256,
            threshold: 1e-5,
            dilate: 4,
            near_rays: 64,
            near_radius: 6.0,
            near_radius_max: 0.1,
            seed: 1,
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("scene '{0}' has no punctual lights: nothing to bake (the baker distributes light from KHR_lights_punctual lights; emissive surfaces are not light sources here)")]
    NoLights(String),
    #[error("{0}")]
    Settings(String),
    #[error("atlas layout: {0}")]
    Layout(String),
    #[error("cancelled")]
    Cancelled,
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error(transparent)]
    Scene(#[from] crate::scene::SceneError),
}

/// Power balance in W per channel: `emitted = absorbed + escaped + unshot` (closes exactly up
/// to rounding). `escaped` is light that left the scene or that the discrete form factors did
/// not deliver; `unshot` is reflected light not propagated (bounce limit or threshold).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EnergyAccount {
    pub emitted: [f64; 3],
    pub absorbed: [f64; 3],
    pub escaped: [f64; 3],
    pub unshot: [f64; 3],
    /// Direct light that reached the patches (part of the split above, reported apart).
    pub direct_received: [f64; 3],
}

impl EnergyAccount {
    /// Largest |emitted − (absorbed + escaped + unshot)| / emitted over the channels.
    pub fn relative_residual(&self) -> f64 {
        (0..3)
            .map(|c| {
                let rest = self.absorbed[c] + self.escaped[c] + self.unshot[c];
                (self.emitted[c] - rest).abs() / self.emitted[c].max(1e-30)
            })
            .fold(0.0, f64::max)
    }

    pub fn to_json(&self) -> serde_json::Value {
        let r = |v: [f64; 3]| v.map(|x| (x * 1e6).round() / 1e6).to_vec();
        serde_json::json!({
            "emitted": r(self.emitted),
            "absorbed": r(self.absorbed),
            "escaped": r(self.escaped),
            "unshot": r(self.unshot),
            "direct_received": r(self.direct_received),
            "relative_residual": self.relative_residual(),
        })
    }
}

/// One VPL patch: the VPL and the sample points that make up its area.
#[derive(Clone, Debug)]
pub struct Patch {
    pub position: Vec3,
    pub normal: Vec3,
    pub rho: Vec3,
    pub area: f32,
    /// Range into [`Bake::samples`].
    pub samples: std::ops::Range<usize>,
}

/// A sample point on the surface.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceSample {
    pub position: Vec3,
    pub normal: Vec3,
    pub material: u32,
}

/// A finished bake: the layout, per-bounce irradiance per texel, patches and the account.
pub struct Bake {
    pub settings: BakeSettings,
    pub layout: Arc<AtlasLayout>,
    /// `irradiance[b][texel]` = irradiance (W/m²) of bounce b+1 at row-major texel.
    pub irradiance: Vec<Vec<[f32; 3]>>,
    /// Texels that stand for a surface point.
    pub covered: Vec<bool>,
    pub patches: Vec<Patch>,
    pub samples: Vec<SurfaceSample>,
    /// Patch irradiance per generation: `patch_irradiance[b][j]` (b = 0 is direct light).
    pub patch_irradiance: Vec<Vec<Vec3>>,
    pub energy: EnergyAccount,
    pub shots: usize,
    /// Texels whose near-field gather was noisy enough to get 4× more rays.
    pub regathered_texels: usize,
    /// (stage, milliseconds) in order.
    pub stage_ms: Vec<(String, f64)>,
}

/// Progress reports: (stage, done, total).
pub type Progress<'a> = &'a (dyn Fn(&str, usize, usize) + Sync);

struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        // splitmix64
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn check(cancel: &AtomicBool) -> Result<(), BakeError> {
    if cancel.load(Ordering::Relaxed) {
        Err(BakeError::Cancelled)
    } else {
        Ok(())
    }
}

fn material_rho(m: &Material) -> Vec3 {
    Material::diffuse_albedo(m.base_color.truncate(), m.metallic)
}

/// Total radiant power of a light (W per channel); `None` for directional lights, whose
/// power is what the scene intercepts.
pub fn light_power(light: &WorldLight) -> Option<Vec3> {
    match light.kind {
        LightKind::Point => Some(light.intensity * 4.0 * std::f32::consts::PI),
        LightKind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            // 2π ∫ attenuation(cos θ) d(cos θ) over the cone, midpoint rule.
            let lo = outer_cone_angle.cos() as f64;
            let steps = 4096;
            let mut sum = 0.0f64;
            for i in 0..steps {
                let c = lo + (1.0 - lo) * (i as f64 + 0.5) / steps as f64;
                sum += spot_attenuation(inner_cone_angle, outer_cone_angle, c as f32) as f64;
            }
            let solid = 2.0 * std::f64::consts::PI * sum * (1.0 - lo) / steps as f64;
            Some(light.intensity * solid as f32)
        }
        LightKind::Directional => None,
    }
}

/// Disc-to-point transfer: irradiance at (x, n_x) per watt leaving a disc VPL of area `area`
/// at (p, n_p): `max(0, n_p·ω)·max(0, −n_x·ω) / (π d² + A)`, ω from p to x (DESIGN §4's disc
/// VAL with r² = A/π).
#[inline]
pub fn transfer(p: Vec3, n_p: Vec3, area: f32, x: Vec3, n_x: Vec3) -> f32 {
    let d = x - p;
    let d2 = d.length_squared();
    if d2 < 1e-12 {
        return 0.0;
    }
    let w = d / d2.sqrt();
    let c = n_p.dot(w).max(0.0) * (-n_x.dot(w)).max(0.0);
    c / (std::f32::consts::PI * d2 + area)
}

/// Transfer from a whole patch: the disc formula from its VPL far away; within four disc
/// radii the patch is split into its sample points, each a disc of its own area C, so
/// receivers near a patch see its real extent instead of one clamped disc. Samples closer to
/// the receiver than `near` are left out: that ball is the near-field gather's (see
/// [`near_field`]), where no disc formula is accurate (a disc's kernel
/// `cos·cos/(πd² + C)` is off by C/(πd²): 8 % at two sample spacings, 35 % at one).
#[inline]
pub fn patch_transfer(
    patch: &Patch,
    samples: &[SurfaceSample],
    sample_area: f32,
    near: f32,
    x: Vec3,
    n_x: Vec3,
) -> f32 {
    patch_transfer_pair(patch, samples, None, sample_area, near, x, n_x)[1]
}

/// [`patch_transfer`] for the patch's first generation (index 0) and for the later ones
/// (index 1) in one pass over the samples. The first generation is the patch's direct light,
/// reflected, which can vary a lot across a patch (a patch straddling a shadow boundary):
/// where the patch is split into samples, sample k carries `direct_weights[k]` (its direct
/// irradiance over the patch mean; mean 1) of it, so bounce 1 leaves from the lit part.
/// Measured on Cornell: the lit floor's bounce onto the short box's shadowed front face came
/// out 13–38 % too bright with uniform samples, 4–18 % with weighted ones. Far away the patch
/// is one disc for every generation (moving it to the weighted centroid changed FLIP < 0.001).
#[inline]
pub fn patch_transfer_pair(
    patch: &Patch,
    samples: &[SurfaceSample],
    direct_weights: Option<&[f32]>,
    sample_area: f32,
    near: f32,
    x: Vec3,
    n_x: Vec3,
) -> [f32; 2] {
    let d2 = patch.position.distance_squared(x);
    if d2 > 16.0 * patch.area / std::f32::consts::PI && d2 > 4.0 * near * near {
        let uniform = transfer(patch.position, patch.normal, patch.area, x, n_x);
        return [uniform, uniform];
    }
    let near2 = near * near;
    let range = patch.samples.clone();
    let mut sum = [0.0f32; 2];
    for (k, s) in samples[range.clone()].iter().enumerate() {
        if s.position.distance_squared(x) < near2 {
            continue;
        }
        let t = transfer(s.position, s.normal, sample_area, x, n_x);
        sum[0] += direct_weights.map_or(t, |w| t * w[range.start + k]);
        sum[1] += t;
    }
    let m = range.len() as f32;
    [sum[0] / m, sum[1] / m]
}

/// The patch solution as seen from a ray hit: which patch a surface point belongs to (the
/// nearest sample facing the same way).
pub struct SampleLookup {
    tree: ImmutableKdTree<f32, u64, 3, 32>,
    sample_patch: Vec<u32>,
}

impl SampleLookup {
    pub fn new(patches: &[Patch], samples: &[SurfaceSample]) -> Self {
        let coords: Vec<[f32; 3]> = samples.iter().map(|s| s.position.to_array()).collect();
        let mut sample_patch = vec![0u32; samples.len()];
        for (i, p) in patches.iter().enumerate() {
            for s in p.samples.clone() {
                sample_patch[s] = i as u32;
            }
        }
        Self {
            tree: ImmutableKdTree::new_from_slice(&coords),
            sample_patch,
        }
    }

    /// The patch of the nearest of the 8 nearest samples whose normal is within 60° of `n` and
    /// that `(x, n)` can see; `None` if there is none (the hit's later generations are then
    /// left out rather than taken from the other side of a wall).
    pub fn patch_at(
        &self,
        tracer: &Tracer,
        samples: &[SurfaceSample],
        x: Vec3,
        n: Vec3,
    ) -> Option<usize> {
        let wanted = NonZero::new(8.min(samples.len()))?;
        let here = SurfaceSample {
            position: x,
            normal: n,
            material: 0,
        };
        let pick = self
            .tree
            .nearest_n::<SquaredEuclidean>(&x.to_array(), wanted)
            .into_iter()
            .find(|nn| {
                let s = &samples[nn.item as usize];
                s.normal.dot(n) > 0.5 && mutually_visible(tracer, &here, s)
            })?;
        Some(self.sample_patch[pick.item as usize] as usize)
    }
}

/// Near-field gather at `(x, n)`: `√M × √M` stratified cosine-weighted rays no longer than
/// `radius`. A ray that hits h adds `ρ(h)·E_g(h) / M` to bounce g + 1 (the estimator
/// `E = π/M · Σ L` with `L = ρ/π · E`), where E_0(h) is h's direct irradiance (exact, a shadow
/// ray per light) and E_g, g ≥ 1, the irradiance of generation g of h's patch. Corners and
/// contacts, where half of the irradiance comes from within a few millimetres, get their light
/// from the real geometry instead of from discs a sample spacing apart. Returns the variance
/// of the gathered luminance (R + G + B, all bounces) as an i.i.d. estimate, an upper bound
/// for the stratified one, so callers can shoot more rays where it is noisy.
#[allow(clippy::too_many_arguments)]
pub fn near_field(
    tracer: &Tracer,
    lookup: &SampleLookup,
    samples: &[SurfaceSample],
    patch_irradiance: &[Vec<Vec3>],
    x: Vec3,
    n: Vec3,
    radius: f32,
    rays: u32,
    seed: u64,
    out: &mut [Vec3],
) -> f32 {
    let side = (rays as f32).sqrt().round().max(1.0) as u32;
    let m = (side * side) as f32;
    let origin = x + n * tracer.epsilon;
    let mut rng = SampleRng::new(seed, 0x4EA5, 0);
    let (mut sum, mut sum_sq) = (0.0f32, 0.0f32);
    for a in 0..side {
        for b in 0..side {
            let u1 = (a as f32 + rng.next_f32()) / side as f32;
            let u2 = (b as f32 + rng.next_f32()) / side as f32;
            let dir = cosine_hemisphere(n, u1, u2);
            let Some(hit) = tracer.intersect(origin, dir, radius) else {
                continue;
            };
            if hit.rho_d == Vec3::ZERO {
                continue;
            }
            let mut value = hit.rho_d * tracer.direct_irradiance(hit.position, hit.normal);
            out[0] += value / m;
            if out.len() > 1 {
                if let Some(j) =
                    lookup.patch_at(tracer, samples, hit.position, hit.geometric_normal)
                {
                    for (g, o) in out.iter_mut().enumerate().skip(1) {
                        let e = hit.rho_d * patch_irradiance[g][j];
                        *o += e / m;
                        value += e;
                    }
                }
            }
            let l = value.x + value.y + value.z;
            sum += l;
            sum_sq += l * l;
        }
    }
    let mean = sum / m;
    ((sum_sq / m - mean * mean) / m).max(0.0)
}

/// Shadows further in front of the receiver than this many depth-texel footprints (with all
/// 3×3 taps agreeing) are taken from the depth map without a ray. The surface beside a concave
/// edge falls into the receiver's texel within about one footprint sideways, i.e. 1/tan α
/// footprints in depth for a ray at α to that surface: 8 covers every α above 7°.
pub const CONFIRM_GAP: f32 = 8.0;

/// Relative standard error of a texel's near-field gather above which it gets 4× more rays
/// (the gather's noise shows as grain on dim faces lit from nearby bright ones).
pub const NEAR_NOISE: f32 = 0.04;

/// Upper bound of `--near-rays` (a 64×64 stratification per texel).
pub const MAX_NEAR_RAYS: u32 = 4096;

/// Upper bound of `--cube-res`.
pub const MAX_CUBE_RES: usize = 256;

/// Memory all shooters' depth cubes may take together.
pub const MAX_CUBE_BYTES: u64 = 4 << 30;

/// Visibility of the point `source` from `(x, n)`, 1 or 0: the depth map's answer where it
/// is sure ([`ShadowTest::settled`]: all 3×3 taps lit, or all shadowed by a surface well in
/// front of x), a ray through the scene's BVH otherwise. A depth texel's footprint grows with
/// distance (a 32² cube's is ~3 cm half a metre away, ~20 cm at three metres), so next to a
/// concave edge its tap is often the neighbouring surface, just in front of the receiver (a
/// false shadow that darkened Cornell's edges and contacts by 10–20 % and its boxes' faces by
/// ~10 %), and a shadow edge cast far away is a footprint wide. Confirming only the shadows
/// lifted the false ones but kept the false lights: the corridor's second room, lit through
/// the doorway, came out 17 % too bright in bounce 1. Both sides near a depth edge take a ray.
#[inline]
pub fn confirmed_visibility(
    map: ShadowTest,
    tracer: &Tracer,
    source: Vec3,
    x: Vec3,
    n: Vec3,
) -> f32 {
    if let Some(v) = map.settled(CONFIRM_GAP) {
        return v;
    }
    let origin = x + n * tracer.epsilon;
    let to = source - origin;
    let len = to.length();
    if len <= 2.0 * tracer.epsilon || tracer.unoccluded(origin, to / len, len - tracer.epsilon) {
        1.0
    } else {
        0.0
    }
}

/// Bakes the scene as placed by `world_from_node`. `progress` is called with the stage and
/// counts; setting `cancel` stops the bake at the next check with [`BakeError::Cancelled`].
pub fn bake(
    scene: &Scene,
    world_from_node: &[Mat4],
    settings: &BakeSettings,
    progress: Progress,
    cancel: &AtomicBool,
) -> Result<Bake, BakeError> {
    if settings.vpls == 0 || settings.bounces == 0 || settings.samples_per_vpl == 0 {
        return Err(BakeError::Settings(
            "--vpls, --bounces and samples per VPL must be at least 1".into(),
        ));
    }
    if settings.near_rays > MAX_NEAR_RAYS
        || !(settings.near_radius > 0.0 && settings.near_radius_max > 0.0)
    {
        return Err(BakeError::Settings(format!(
            "--near-rays must be at most {MAX_NEAR_RAYS} (got {}) and the near radius positive",
            settings.near_rays
        )));
    }
    // One depth cube per patch stays in memory from the visibility stage to the fill (counted
    // in f64: no overflow for absurd settings).
    let cube_bytes = settings.vpls as f64 * 24.0 * (settings.cube_res as f64).powi(2);
    if !(4..=MAX_CUBE_RES).contains(&settings.cube_res) || cube_bytes > MAX_CUBE_BYTES as f64 {
        return Err(BakeError::Settings(format!(
            "--cube-res must be 4..={MAX_CUBE_RES} and the depth cubes fit in {} GiB \
             (got {} VPLs × 6 × {}² texels × 4 bytes = {:.2} GiB)",
            MAX_CUBE_BYTES >> 30,
            settings.vpls,
            settings.cube_res,
            cube_bytes / (1u64 << 30) as f64
        )));
    }
    let lights = WorldLight::from_scene(scene, world_from_node);
    if lights.is_empty() {
        return Err(BakeError::NoLights(scene.name.clone()));
    }
    let mut stage_ms = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |name: &str, stage_ms: &mut Vec<(String, f64)>| {
        stage_ms.push((name.to_string(), clock.elapsed().as_secs_f64() * 1000.0));
        clock = Instant::now();
    };

    // --- Layout -----------------------------------------------------------------------
    progress("unwrap", 0, 1);
    let layout =
        layout::layout(scene, world_from_node, settings.atlas_res).map_err(BakeError::Layout)?;
    progress("unwrap", 1, 1);
    lap("unwrap", &mut stage_ms);
    check(cancel)?;

    // Exact visibility where depth maps are unsure, and for patches' and lookups' membership.
    let tracer = Tracer::new(scene, world_from_node);
    // Depth maps are drawn from the tracer's triangles: the same surface with flat regions
    // merged (the corridor's 82k triangles are 20 there, and drawing them into 1600 cubes
    // took a fifth of the bake).
    let occluders = tracer.world_triangles();

    // --- Discretize ---------------------------------------------------------------------
    let mut triangles: Vec<[Vec3; 3]> = Vec::new();
    let mut tri_normals: Vec<[Vec3; 3]> = Vec::new();
    let mut tri_material: Vec<u32> = Vec::new();
    for m in &layout.meshes {
        for t in m.indices.chunks_exact(3) {
            let idx = [t[0] as usize, t[1] as usize, t[2] as usize];
            triangles.push(idx.map(|i| m.world_positions[i]));
            tri_normals.push(idx.map(|i| m.world_normals[i]));
            tri_material.push(m.material as u32);
        }
    }
    let areas: Vec<f64> = triangles
        .iter()
        .map(|t| 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length() as f64)
        .collect();
    let total_area: f64 = areas.iter().sum();
    if total_area <= 0.0 {
        return Err(BakeError::Layout(
            "the scene's surfaces have no area".into(),
        ));
    }
    let mut cdf = Vec::with_capacity(areas.len());
    let mut acc = 0.0;
    for a in &areas {
        acc += a;
        cdf.push(acc / total_area);
    }
    let sample_count = settings.vpls * settings.samples_per_vpl;
    let mut rng = Rng(settings.seed);
    let raw: Vec<SurfaceSample> = (0..sample_count)
        .map(|k| {
            let u = (k as f64 + rng.f32() as f64) / sample_count as f64;
            let ti = cdf.partition_point(|&c| c < u).min(triangles.len() - 1);
            let (r1, r2) = (rng.f32().sqrt(), rng.f32());
            let w = Vec3::new(1.0 - r1, r1 * (1.0 - r2), r1 * r2);
            let t = triangles[ti];
            let p = t[0] * w.x + t[1] * w.y + t[2] * w.z;
            let tn = tri_normals[ti];
            let mut n = (tn[0] * w.x + tn[1] * w.y + tn[2] * w.z)
                .try_normalize()
                .unwrap_or(Vec3::Y);
            if let Some(f) = (t[1] - t[0]).cross(t[2] - t[0]).try_normalize() {
                n = if f.dot(n) < 0.0 { -f } else { f };
            }
            SurfaceSample {
                position: p,
                normal: n,
                material: tri_material[ti],
            }
        })
        .collect();
    // One VPL site per stratum of samples (strata follow the area CDF).
    let spv = settings.samples_per_vpl;
    let sites: Vec<usize> = (0..settings.vpls)
        .map(|j| j * spv + (rng.next_u64() as usize % spv))
        .collect();
    let owner = assign_samples(&raw, &sites, total_area, settings.vpls, &tracer);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); sites.len()];
    for (s, &o) in owner.iter().enumerate() {
        members[o].push(s);
    }
    let sample_area = (total_area / sample_count as f64) as f32;
    let mut patches = Vec::new();
    let mut samples = Vec::with_capacity(sample_count);
    for (j, m) in members.iter().enumerate() {
        if m.is_empty() {
            continue;
        }
        let site = raw[sites[j]];
        let start = samples.len();
        samples.extend(m.iter().map(|&s| raw[s]));
        patches.push(Patch {
            position: site.position,
            normal: site.normal,
            rho: material_rho(&scene.materials[site.material as usize]),
            area: m.len() as f32 * sample_area,
            samples: start..samples.len(),
        });
    }
    let n = patches.len();
    lap("discretize", &mut stage_ms);
    check(cancel)?;

    // Scene scale for biases.
    let mut bounds = crate::scene::Aabb::EMPTY;
    for t in &triangles {
        for p in t {
            bounds.grow(*p);
        }
    }
    let scene_size = bounds.extent().length().max(1e-6);
    let eps = 1e-4 * scene_size;

    // --- Direct light ---------------------------------------------------------------------
    let mut emitted = [0.0f64; 3];
    let mut direct = vec![Vec3::ZERO; n];
    let mut sample_direct = vec![Vec3::ZERO; samples.len()];
    for (li, light) in lights.iter().enumerate() {
        progress("direct", li, lights.len());
        let vis: Box<dyn Fn(Vec3, Vec3) -> f32 + Sync> = match light.kind {
            LightKind::Directional => {
                let map = DepthOrtho::new(
                    light.direction,
                    bounds.center(),
                    scene_size * 0.5 + eps,
                    settings.light_map_res * 4,
                    &occluders,
                );
                let far = light.direction * (-2.0 * scene_size);
                let tracer = &tracer;
                Box::new(move |p: Vec3, n: Vec3| {
                    confirmed_visibility(map.shadow_test(p, n), tracer, p + far, p, n)
                })
            }
            _ => {
                let cube = DepthCube::new(light.position, settings.light_map_res, eps, &occluders);
                let tracer = &tracer;
                let at = light.position;
                Box::new(move |p: Vec3, n: Vec3| {
                    confirmed_visibility(cube.shadow_test(p, n), tracer, at, p, n)
                })
            }
        };
        check(cancel)?;
        let at_samples: Vec<Vec3> = samples
            .par_iter()
            .map(|s| {
                let (wi, e) = light.incident(s.position);
                let cos = s.normal.dot(wi);
                if cos <= 0.0 {
                    return Vec3::ZERO;
                }
                e * cos * vis(s.position, s.normal)
            })
            .collect();
        for (sum, e) in sample_direct.iter_mut().zip(&at_samples) {
            *sum += *e;
        }
        let received: Vec<Vec3> = patches
            .iter()
            .map(|patch| {
                let sum: Vec3 = at_samples[patch.samples.clone()].iter().sum();
                sum / patch.samples.len() as f32
            })
            .collect();
        let mut power = [0.0f64; 3];
        for (j, r) in received.iter().enumerate() {
            direct[j] += *r;
            for c in 0..3 {
                power[c] += (r[c] * patches[j].area) as f64;
            }
        }
        let total = light_power(light).map(|p| p.to_array().map(|x| x as f64));
        for c in 0..3 {
            emitted[c] += total.map_or(power[c], |t| t[c]);
        }
    }
    progress("direct", lights.len(), lights.len());
    let mut direct_weights = vec![1.0f32; samples.len()];
    for p in &patches {
        let lum = |e: Vec3| e.x + e.y + e.z;
        let range = p.samples.clone();
        let mean = range.clone().map(|k| lum(sample_direct[k])).sum::<f32>() / range.len() as f32;
        if mean > 0.0 {
            for k in range {
                direct_weights[k] = lum(sample_direct[k]) / mean;
            }
        }
    }
    lap("direct", &mut stage_ms);
    check(cancel)?;
    let mut escaped = [0.0f64; 3];
    let mut received = [0.0f64; 3];
    {
        for (j, e) in direct.iter().enumerate() {
            for c in 0..3 {
                received[c] += (e[c] * patches[j].area) as f64;
            }
        }
        for c in 0..3 {
            escaped[c] += emitted[c] - received[c];
        }
    }

    // --- Visibility: one depth cube per patch, and the form-factor rows -----------------
    // row[i][j] = irradiance at patch j per watt shot by patch i, visibility averaged over j's
    // samples.
    let done = AtomicUsize::new(0);
    let cubes: Vec<DepthCube> = patches
        .par_iter()
        .map(|p| {
            if cancel.load(Ordering::Relaxed) {
                return DepthCube {
                    origin: p.position,
                    res: 1,
                    near: eps,
                    depth: vec![f32::INFINITY; 6],
                };
            }
            let cube = DepthCube::new(
                p.position + p.normal * eps * 10.0,
                settings.cube_res,
                eps,
                &occluders,
            );
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            if d.is_multiple_of(64) || d == n {
                progress("visibility", d, n);
            }
            cube
        })
        .collect();
    check(cancel)?;
    let rows: Vec<Vec<f32>> = (0..n)
        .into_par_iter()
        .map(|i| {
            if cancel.load(Ordering::Relaxed) {
                return Vec::new();
            }
            let pi = &patches[i];
            (0..n)
                .map(|j| {
                    if i == j {
                        return 0.0;
                    }
                    let pj = &patches[j];
                    let mut sum = 0.0;
                    for s in &samples[pj.samples.clone()] {
                        let t =
                            patch_transfer(pi, &samples, sample_area, 0.0, s.position, s.normal);
                        if t > 0.0 {
                            let v = cubes[i].shadow_test(s.position, s.normal);
                            sum += t * confirmed_visibility(
                                v,
                                &tracer,
                                cubes[i].origin,
                                s.position,
                                s.normal,
                            );
                        }
                    }
                    sum / pj.samples.len() as f32
                })
                .collect()
        })
        .collect();
    check(cancel)?;
    // The disc transfer loses energy in the near field; scale each shooter so the fraction of
    // its power delivered to the receivers' samples equals the form-factor sum its depth cube
    // sees (the cosine-weighted hemisphere fraction covered by geometry): light leaves the
    // scene only where the cube sees nothing.
    let scale: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let delivered: f64 = rows[i]
                .iter()
                .zip(&patches)
                .map(|(f, p)| (*f * p.area) as f64)
                .sum();
            let coverage = cubes[i].hemisphere_coverage(patches[i].normal) as f64;
            if delivered > 1e-9 {
                (coverage / delivered).clamp(0.5, 2.0) as f32
            } else {
                1.0
            }
        })
        .collect();
    let rows: Vec<Vec<f32>> = rows
        .into_par_iter()
        .zip(&scale)
        .map(|(row, &k)| row.into_iter().map(|f| f * k).collect())
        .collect();
    lap("visibility", &mut stage_ms);

    // --- Progressive refinement -----------------------------------------------------------
    let b_count = settings.bounces as usize;
    // Generation g = 0 is direct light; generation g receives light reflected g times.
    let mut total_irr: Vec<Vec<Vec3>> = vec![vec![Vec3::ZERO; n]; b_count];
    let mut unshot: Vec<Vec<Vec3>> = vec![vec![Vec3::ZERO; n]; b_count];
    total_irr[0] = direct.clone();
    unshot[0] = direct.clone();
    let emitted_lum = emitted.iter().sum::<f64>();
    let lum = |v: Vec3| (v.x + v.y + v.z) as f64;
    let shootable = |unshot: &Vec<Vec<Vec3>>, j: usize| -> f64 {
        (0..b_count - 1)
            .map(|g| lum(unshot[g][j] * patches[j].rho) * patches[j].area as f64)
            .sum()
    };
    let mut shots = 0usize;
    let max_shots = n * b_count * 4;
    while b_count > 1 && shots < max_shots {
        if shots.is_multiple_of(256) {
            check(cancel)?;
            progress("shoot", shots, n * (b_count - 1));
        }
        let (best, power) = (0..n)
            .map(|j| (j, shootable(&unshot, j)))
            .fold((0, -1.0), |a, b| if b.1 > a.1 { b } else { a });
        if power <= settings.threshold * emitted_lum || power <= 0.0 {
            break;
        }
        let pi = &patches[best];
        let row = &rows[best];
        let delivered: f64 = row
            .iter()
            .zip(&patches)
            .map(|(f, p)| (*f * p.area) as f64)
            .sum();
        for g in 0..b_count - 1 {
            let shot = unshot[g][best] * pi.rho * pi.area;
            if shot == Vec3::ZERO {
                continue;
            }
            unshot[g][best] = Vec3::ZERO;
            for (j, f) in row.iter().enumerate() {
                if *f > 0.0 {
                    let add = shot * *f;
                    unshot[g + 1][j] += add;
                    total_irr[g + 1][j] += add;
                }
            }
            for c in 0..3 {
                escaped[c] += shot[c] as f64 * (1.0 - delivered);
            }
        }
        shots += 1;
    }
    progress("shoot", n * (b_count - 1), n * (b_count - 1));
    let mut absorbed = [0.0f64; 3];
    let mut unshot_power = [0.0f64; 3];
    for g in 0..b_count {
        for (j, p) in patches.iter().enumerate() {
            for c in 0..3 {
                let received = (total_irr[g][j][c] * p.area) as f64;
                absorbed[c] += received * (1.0 - p.rho[c] as f64);
                unshot_power[c] += (unshot[g][j][c] * p.rho[c] * p.area) as f64;
            }
        }
    }
    let energy = EnergyAccount {
        emitted,
        absorbed,
        escaped,
        unshot: unshot_power,
        direct_received: received,
    };
    lap("shoot", &mut stage_ms);
    check(cancel)?;

    // --- Atlas fill -----------------------------------------------------------------------
    // Power leaving patch i toward bounce g+1: ρ_i A_i I_i^(g), times the row scale k_i (with
    // the near-field gather the fill's near field is exact, but k_i also makes up the disc
    // kernels' smaller losses further out: without it Cornell's indirect mean came out 2 % low
    // at 400 VPLs and FLIP rose 0.050 → 0.055; the corridor's fell 0.109 → 0.097, whose second
    // room it brightens by ~2 %).
    let power: Vec<Vec<Vec3>> = (0..b_count)
        .map(|g| {
            patches
                .iter()
                .enumerate()
                .map(|(i, p)| total_irr[g][i] * p.rho * p.area * scale[i])
                .collect()
        })
        .collect();
    let res = settings.atlas_res as usize;
    let texels = &layout.texels;
    let near = if settings.near_rays > 0 {
        (settings.near_radius * sample_area.sqrt()).min(settings.near_radius_max * scene_size)
    } else {
        0.0
    };
    let lookup = SampleLookup::new(&patches, &samples);
    let regathered = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let chunk = 256;
    let filled: Vec<Vec<[f32; 3]>> = texels
        .par_chunks(chunk)
        .map(|block| {
            let mut out = vec![[0.0f32; 3]; block.len() * b_count];
            if cancel.load(Ordering::Relaxed) {
                return out;
            }
            // Patches outside, texels inside: each patch's depth cube stays in cache for the
            // whole block (per texel, the sum still runs over patches in order).
            for (i, p) in patches.iter().enumerate() {
                if power.iter().all(|pw| pw[i] == Vec3::ZERO) {
                    continue;
                }
                for (k, t) in block.iter().enumerate() {
                    let g = patch_transfer_pair(
                        p,
                        &samples,
                        Some(&direct_weights),
                        sample_area,
                        near,
                        t.position,
                        t.normal,
                    );
                    if g[0] <= 0.0 && g[1] <= 0.0 {
                        continue;
                    }
                    let v = confirmed_visibility(
                        cubes[i].shadow_test(t.position, t.normal),
                        &tracer,
                        cubes[i].origin,
                        t.position,
                        t.normal,
                    );
                    if v <= 0.0 {
                        continue;
                    }
                    for (b, pw) in power.iter().enumerate() {
                        let e = pw[i] * (g[usize::from(b > 0)] * v);
                        let o = &mut out[k * b_count + b];
                        o[0] += e.x;
                        o[1] += e.y;
                        o[2] += e.z;
                    }
                }
            }
            if settings.near_rays > 0 {
                let mut first = vec![Vec3::ZERO; b_count];
                let mut more = vec![Vec3::ZERO; b_count];
                for (k, t) in block.iter().enumerate() {
                    first.fill(Vec3::ZERO);
                    let gather = |rays: u32, stream: u64, into: &mut [Vec3]| {
                        near_field(
                            &tracer,
                            &lookup,
                            &samples,
                            &total_irr,
                            t.position,
                            t.normal,
                            near,
                            rays,
                            settings.seed ^ u64::from(t.index) ^ (stream << 40),
                            into,
                        )
                    };
                    let variance = gather(settings.near_rays, 0, &mut first);
                    let o = &mut out[k * b_count..(k + 1) * b_count];
                    let total: f32 = o.iter().map(|e| e[0] + e[1] + e[2]).sum::<f32>()
                        + first.iter().map(|e| e.x + e.y + e.z).sum::<f32>();
                    // Texels whose gather is noisier than NEAR_NOISE of their irradiance get
                    // 4× more rays, the two estimates weighted by ray count.
                    more.fill(Vec3::ZERO);
                    let w_first = if variance.sqrt() > NEAR_NOISE * total {
                        regathered.fetch_add(1, Ordering::Relaxed);
                        gather(settings.near_rays * 4, 1, &mut more);
                        0.2
                    } else {
                        1.0
                    };
                    for (b, e) in o.iter_mut().enumerate() {
                        let g = first[b] * w_first + more[b] * (1.0 - w_first);
                        e[0] += g.x;
                        e[1] += g.y;
                        e[2] += g.z;
                    }
                }
            }
            let d = done.fetch_add(block.len(), Ordering::Relaxed) + block.len();
            progress("fill", d, texels.len());
            out
        })
        .collect();
    check(cancel)?;
    let mut irradiance = vec![vec![[0.0f32; 3]; res * res]; b_count];
    let mut covered = vec![false; res * res];
    for (block, out) in texels.chunks(chunk).zip(&filled) {
        for (k, t) in block.iter().enumerate() {
            covered[t.index as usize] = true;
            for (b, irr) in irradiance.iter_mut().enumerate() {
                irr[t.index as usize] = out[k * b_count + b];
            }
        }
    }
    lap("fill", &mut stage_ms);

    Ok(Bake {
        settings: settings.clone(),
        layout,
        irradiance,
        covered,
        patches,
        samples,
        patch_irradiance: total_irr,
        energy,
        shots,
        regathered_texels: regathered.load(Ordering::Relaxed),
        stage_ms,
    })
}

/// True when the straight line between two surface samples (each lifted off its surface) is
/// free. A floor running under a zero-thickness wall has samples on both sides of it within a
/// sample spacing: without this test a patch (or a ray hit's lookup) takes light from the far
/// side, a bright line along the foot of the corridor's partition and door.
fn mutually_visible(tracer: &Tracer, a: &SurfaceSample, b: &SurfaceSample) -> bool {
    let from = a.position + a.normal * tracer.epsilon;
    let to = b.position + b.normal * tracer.epsilon;
    let d = to - from;
    let len = d.length();
    len <= tracer.epsilon || tracer.unoccluded(from, d / len, len)
}

/// Each sample's patch: the nearest site with a compatible normal that it can see (grid
/// search).
fn assign_samples(
    raw: &[SurfaceSample],
    sites: &[usize],
    total_area: f64,
    n: usize,
    tracer: &Tracer,
) -> Vec<usize> {
    let cell = ((total_area / n as f64).sqrt() as f32).max(1e-6);
    let key = |p: Vec3| {
        let q = (p / cell).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    let mut grid: std::collections::HashMap<(i64, i64, i64), Vec<usize>> = Default::default();
    for (j, &s) in sites.iter().enumerate() {
        grid.entry(key(raw[s].position)).or_default().push(j);
    }
    raw.par_iter()
        .map(|s| {
            let (cx, cy, cz) = key(s.position);
            let mut best: Option<(f32, usize)> = None;
            let mut fallback: Option<(f32, usize)> = None;
            for ring in 0..64i64 {
                for dx in -ring..=ring {
                    for dy in -ring..=ring {
                        for dz in -ring..=ring {
                            if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                                continue;
                            }
                            let Some(list) = grid.get(&(cx + dx, cy + dy, cz + dz)) else {
                                continue;
                            };
                            for &j in list {
                                let site = &raw[sites[j]];
                                let d = site.position.distance_squared(s.position);
                                if fallback.is_none_or(|(bd, _)| d < bd) {
                                    fallback = Some((d, j));
                                }
                                if site.normal.dot(s.normal) > 0.8
                                    && best.is_none_or(|(bd, _)| d < bd)
                                    && mutually_visible(tracer, site, s)
                                {
                                    best = Some((d, j));
                                }
                            }
                        }
                    }
                }
                // Stop once no closer site can lie in the next ring.
                if let Some((d, _)) = best {
                    let reach = ring as f32 * cell;
                    if d <= reach * reach {
                        break;
                    }
                }
            }
            best.or(fallback).map(|(_, j)| j).unwrap_or(0)
        })
        .collect()
}

impl Bake {
    /// Irradiance of bounces `from..=to` (1-based, clamped to the baked range) as an RGBA
    /// image: alpha 1 on texels that stand for a surface point, 0 elsewhere; empty texels next
    /// to charts hold dilated values so bilinear lookups at chart borders stay clean.
    pub fn atlas(&self, from: u32, to: u32) -> Image {
        let res = self.settings.atlas_res;
        let from = from.max(1) as usize;
        let to = (to as usize).min(self.irradiance.len());
        let mut values = vec![[0.0f32; 3]; (res * res) as usize];
        for b in from..=to {
            for (v, e) in values.iter_mut().zip(&self.irradiance[b - 1]) {
                for c in 0..3 {
                    v[c] += e[c];
                }
            }
        }
        let mut filled = self.covered.clone();
        layout::dilate(&mut values, &mut filled, res, self.settings.dilate);
        let pixels = values
            .iter()
            .zip(&self.covered)
            .map(|(v, &c)| [v[0], v[1], v[2], if c { 1.0 } else { 0.0 }])
            .collect();
        Image::from_rgba(res, res, pixels)
    }

    /// Texels that stand for a surface point.
    pub fn texel_count(&self) -> usize {
        self.layout.texels.len()
    }

    /// One JSON object with the bake's figures (stage times, VPLs, texels, energy).
    pub fn summary(&self) -> serde_json::Value {
        let stages: serde_json::Map<String, serde_json::Value> = self
            .stage_ms
            .iter()
            .map(|(k, v)| (k.clone(), serde_json::json!((v * 1000.0).round() / 1000.0)))
            .collect();
        serde_json::json!({
            "vpls": self.patches.len(),
            "samples": self.samples.len(),
            "bounces": self.settings.bounces,
            "atlas_res": self.settings.atlas_res,
            "texels": self.texel_count(),
            "uv_source": self.layout.source,
            "sheet_faces": self.layout.meshes.iter().filter(|m| m.sheet_face).count(),
            "shots": self.shots,
            "regathered_texels": self.regathered_texels,
            "stages_ms": stages,
            "total_ms": (self.stage_ms.iter().map(|(_, v)| v).sum::<f64>() * 1000.0).round() / 1000.0,
            "energy": self.energy.to_json(),
        })
    }
}

/// Writes `image` to `path` as EXR through a temporary file in the same folder, renamed into
/// place at the end, so an interrupted write never leaves a partial file at `path`.
pub fn write_atlas_exr(image: &Image, path: &std::path::Path) -> Result<(), ImageError> {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "atlas.exr".into());
    let tmp = path.with_file_name(format!(".{name}.partial-{}.exr", std::process::id()));
    let result = image.write_exr(&tmp).and_then(|_| {
        std::fs::rename(&tmp, path).map_err(|e| ImageError::Write {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}
