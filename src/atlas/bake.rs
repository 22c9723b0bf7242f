//! The multi-bounce light-atlas baker (seed 000, DESIGN §5), on the CPU with rayon:
//! discretize into VPL patches, distribute direct light with depth-map visibility, progressive
//! refinement with depth cubes at the shooters, then fill the atlas from every patch with PCF
//! visibility. Irradiance is kept per bounce, so callers pick any range of bounces.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use glam::{Mat4, Vec2, Vec3};
use rayon::prelude::*;

use super::depth::{DepthCube, DepthOrtho};
use super::layout::{self, AtlasLayout};
use crate::image_io::{Image, ImageError};
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
    /// PCF radius (texels) in the atlas fill. 0 by default: with the 32² shooter cubes a 3×3
    /// neighbourhood reaches a texel footprint past the receiver and picks up surfaces seen at
    /// grazing angles (the wall beside a floor texel), a false shadow along every concave
    /// edge that took 1–2 % off the mean; the sum over hundreds of shooters is soft anyway.
    pub pcf_radius: i64,
    /// Stop shooting when the largest unshot power is below this fraction of the emitted.
    pub threshold: f64,
    /// Dilation passes across chart borders.
    pub dilate: u32,
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
            pcf_radius: 0,
            threshold: 1e-5,
            dilate: 4,
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
/// radii the patch is split into its sample points, so receivers near a patch (corners,
/// contact) see its real extent instead of one clamped point, which would darken concave
/// corners. Each sample is a disc of its own area: larger discs (overlapping their
/// neighbours) smooth the sample noise but clamp the near field and darken the texels
/// within about a sample spacing of a concave corner (4× the area: ~13 % darker within
/// 5 mm of Cornell's edges).
#[inline]
pub fn patch_transfer(
    patch: &Patch,
    samples: &[SurfaceSample],
    sample_area: f32,
    x: Vec3,
    n_x: Vec3,
) -> f32 {
    let d2 = patch.position.distance_squared(x);
    if d2 > 16.0 * patch.area / std::f32::consts::PI {
        return transfer(patch.position, patch.normal, patch.area, x, n_x);
    }
    let own = &samples[patch.samples.clone()];
    let sum: f32 = own
        .iter()
        .map(|s| transfer(s.position, s.normal, sample_area, x, n_x))
        .sum();
    sum / own.len() as f32
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
    let owner = assign_samples(&raw, &sites, total_area, settings.vpls);
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
    for (li, light) in lights.iter().enumerate() {
        progress("direct", li, lights.len());
        let vis: Box<dyn Fn(Vec3, Vec3) -> f32 + Sync> = match light.kind {
            LightKind::Directional => {
                let map = DepthOrtho::new(
                    light.direction,
                    bounds.center(),
                    scene_size * 0.5 + eps,
                    settings.light_map_res * 4,
                    &triangles,
                );
                Box::new(move |p: Vec3, n: Vec3| map.visibility(p, n, 1))
            }
            _ => {
                let cube = DepthCube::new(light.position, settings.light_map_res, eps, &triangles);
                Box::new(move |p: Vec3, n: Vec3| cube.visibility(p, n, 1))
            }
        };
        check(cancel)?;
        let received: Vec<Vec3> = patches
            .par_iter()
            .map(|patch| {
                let mut sum = Vec3::ZERO;
                for s in &samples[patch.samples.clone()] {
                    let (wi, e) = light.incident(s.position);
                    let cos = s.normal.dot(wi);
                    if cos <= 0.0 {
                        continue;
                    }
                    sum += e * cos * vis(s.position, s.normal);
                }
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
                &triangles,
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
                        let t = patch_transfer(pi, &samples, sample_area, s.position, s.normal);
                        if t > 0.0 {
                            sum += t * cubes[i].visibility(s.position, s.normal, 0);
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
    // Power leaving patch i toward bounce g+1: ρ_i A_i I_i^(g).
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
                    let g = patch_transfer(p, &samples, sample_area, t.position, t.normal);
                    if g <= 0.0 {
                        continue;
                    }
                    let v = cubes[i].visibility(t.position, t.normal, settings.pcf_radius);
                    if v <= 0.0 {
                        continue;
                    }
                    let gv = g * v;
                    for (b, pw) in power.iter().enumerate() {
                        let e = pw[i] * gv;
                        let o = &mut out[k * b_count + b];
                        o[0] += e.x;
                        o[1] += e.y;
                        o[2] += e.z;
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
        stage_ms,
    })
}

/// Each sample's patch: the nearest site with a compatible normal (grid search).
fn assign_samples(raw: &[SurfaceSample], sites: &[usize], total_area: f64, n: usize) -> Vec<usize> {
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

/// Bilinear lookup of an atlas image at `uv` (texel centres at (i+0.5)/R), the CPU twin of
/// the lookup in `shaders/atlas_render.wgsl`.
pub fn sample_bilinear(image: &Image, uv: Vec2) -> [f32; 3] {
    let (w, h) = (image.width as i64, image.height as i64);
    let p = uv * Vec2::new(w as f32, h as f32) - Vec2::splat(0.5);
    let base = p.floor();
    let f = p - base;
    let mut out = [0.0f32; 3];
    for (dx, dy, wgt) in [
        (0, 0, (1.0 - f.x) * (1.0 - f.y)),
        (1, 0, f.x * (1.0 - f.y)),
        (0, 1, (1.0 - f.x) * f.y),
        (1, 1, f.x * f.y),
    ] {
        let x = (base.x as i64 + dx).clamp(0, w - 1) as u32;
        let y = (base.y as i64 + dy).clamp(0, h - 1) as u32;
        let v = image.get(x, y);
        for c in 0..3 {
            out[c] += v[c] * wgt;
        }
    }
    out
}
