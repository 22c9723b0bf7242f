//! The patch baker (seed 000, DESIGN §5): discretize into VPL patches, distribute direct
//! light with depth-map visibility, progressive refinement with depth cubes at the shooters,
//! then fill the atlas from every patch plus a short-ray near-field gather per texel. Depth
//! maps answer visibility where they are sure; a ray through the scene's BVH decides near
//! their depth edges. Irradiance is kept per bounce, so callers pick any range of bounces.

use std::num::NonZero;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use glam::{Mat4, Vec3};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use rayon::prelude::*;

use super::bake::{
    check, confirmed_visibility, light_power, Bake, BakeError, BakeScene, BakeSettings, Baker,
    EnergyAccount, Progress, Rng, Stages, SurfaceSample,
};
use super::depth::{DepthCube, DepthOrtho};
use crate::sampling::{cosine_hemisphere, Rng as SampleRng};
use crate::scene::{LightKind, Scene};
use crate::trace::Tracer;

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
            rho: Vec3::ZERO,
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

/// Relative standard error of a texel's near-field gather above which it gets 4× more rays
/// (the gather's noise shows as grain on dim faces lit from nearby bright ones).
pub const NEAR_NOISE: f32 = 0.04;

/// Upper bound of `--near-rays` (a 64×64 stratification per texel).
pub const MAX_NEAR_RAYS: u32 = 4096;

/// Upper bound of `--cube-res`.
pub const MAX_CUBE_RES: usize = 256;

/// Memory all shooters' depth cubes may take together.
pub const MAX_CUBE_BYTES: u64 = 4 << 30;
/// The patch baker (seed 000, DESIGN §5): discretize into VPL patches, distribute direct light
/// with depth-map visibility, progressive refinement with depth cubes at the shooters, then
/// fill the atlas from every patch plus a short-ray near-field gather per texel.
pub struct PatchBaker;

impl Baker for PatchBaker {
    fn name(&self) -> &'static str {
        "patches"
    }

    fn bake(
        &self,
        scene: &Scene,
        world_from_node: &[Mat4],
        settings: &BakeSettings,
        progress: Progress,
        cancel: &AtomicBool,
    ) -> Result<Bake, BakeError> {
        bake_patches(scene, world_from_node, settings, progress, cancel)
    }
}

fn bake_patches(
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
    let mut stages = Stages::new();
    let ctx = BakeScene::prepare(
        scene,
        world_from_node,
        settings,
        progress,
        cancel,
        &mut stages,
    )?;
    let (lights, tracer, occluders) = (&ctx.lights, &ctx.tracer, &ctx.occluders);
    let (bounds, scene_size, eps) = (ctx.bounds, ctx.scene_size, ctx.eps);
    let total_area = ctx.surface_area;

    // --- Discretize ---------------------------------------------------------------------
    let sample_count = settings.vpls * settings.samples_per_vpl;
    let mut rng = Rng::from_state(settings.seed);
    let raw = ctx.sample_surfaces(scene, sample_count, &mut rng);
    let sample_area = (total_area / sample_count as f64) as f32;
    stages.lap("discretize");

    // --- Direct light at every sample (before the sites: they follow the reflected power) ---
    let mut emitted = [0.0f64; 3];
    let mut received = [0.0f64; 3];
    let mut raw_direct = vec![Vec3::ZERO; raw.len()];
    for (li, light) in lights.iter().enumerate() {
        progress("direct", li, lights.len());
        let vis: Box<dyn Fn(Vec3, Vec3) -> f32 + Sync> = match light.kind {
            LightKind::Directional => {
                let map = DepthOrtho::new(
                    light.direction,
                    bounds.center(),
                    scene_size * 0.5 + eps,
                    settings.light_map_res * 4,
                    occluders,
                );
                let far = light.direction * (-2.0 * scene_size);
                let tracer = &tracer;
                Box::new(move |p: Vec3, n: Vec3| {
                    confirmed_visibility(map.shadow_test(p, n), tracer, p + far, p, n)
                })
            }
            _ => {
                let cube = DepthCube::new(light.position, settings.light_map_res, eps, occluders);
                let tracer = &tracer;
                let at = light.position;
                Box::new(move |p: Vec3, n: Vec3| {
                    confirmed_visibility(cube.shadow_test(p, n), tracer, at, p, n)
                })
            }
        };
        check(cancel)?;
        let at_samples: Vec<Vec3> = raw
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
        // Every sample stands for the same area C, so the power a light delivers is C·ΣE.
        let mut power = [0.0f64; 3];
        for (sum, e) in raw_direct.iter_mut().zip(&at_samples) {
            *sum += *e;
            for c in 0..3 {
                power[c] += (e[c] * sample_area) as f64;
            }
        }
        let total = light_power(light).map(|p| p.to_array().map(|x| x as f64));
        for c in 0..3 {
            received[c] += power[c];
            emitted[c] += total.map_or(power[c], |t| t[c]);
        }
    }
    progress("direct", lights.len(), lights.len());
    stages.lap("direct");
    check(cancel)?;

    let reflected: Vec<f32> = raw
        .iter()
        .zip(&raw_direct)
        .map(|(s, e)| crate::shading::luminance(s.rho * *e))
        .collect();
    let sites = choose_sites(&reflected, settings.vpls, &mut rng);
    let grid = SiteGrid::new(&raw, &sites, total_area, sites.len());
    let owner = assign_samples(&raw, &sites, &grid, tracer);
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); sites.len()];
    for (s, &o) in owner.iter().enumerate() {
        members[o].push(s);
    }
    let mut patches = Vec::new();
    let mut samples = Vec::with_capacity(sample_count);
    let mut direct = Vec::new();
    // Per sample, its direct irradiance over its patch's mean (R + G + B): bounce 1 leaves a
    // split patch from its lit part (`patch_transfer_pair`).
    let mut direct_weights = Vec::with_capacity(sample_count);
    let lum = |e: Vec3| e.x + e.y + e.z;
    for (j, m) in members.iter().enumerate() {
        if m.is_empty() {
            continue;
        }
        let site = raw[sites[j]];
        let start = samples.len();
        samples.extend(m.iter().map(|&s| raw[s]));
        // The patch reflects with its samples' mean albedo (textures included: a patch on a
        // textured wall is as bright as the wall's texture on average, not as its factor).
        let rho = m.iter().map(|&s| raw[s].rho).sum::<Vec3>() / m.len() as f32;
        let mean = m.iter().map(|&s| raw_direct[s]).sum::<Vec3>() / m.len() as f32;
        direct.push(mean);
        direct_weights.extend(m.iter().map(|&s| {
            if lum(mean) > 0.0 {
                lum(raw_direct[s]) / lum(mean)
            } else {
                1.0
            }
        }));
        patches.push(Patch {
            position: site.position,
            normal: site.normal,
            rho,
            area: m.len() as f32 * sample_area,
            samples: start..samples.len(),
        });
    }
    let n = patches.len();
    stages.lap("sites");
    check(cancel)?;
    let mut escaped = [0.0f64; 3];
    for c in 0..3 {
        escaped[c] += emitted[c] - received[c];
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
                occluders,
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
                                tracer,
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
    stages.lap("visibility");

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
    stages.lap("shoot");
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
    let near = if settings.near_rays > 0 {
        (settings.near_radius * sample_area.sqrt()).min(settings.near_radius_max * scene_size)
    } else {
        0.0
    };
    let lookup = SampleLookup::new(&patches, &samples);
    let regathered = AtomicUsize::new(0);
    let (irradiance, covered) = ctx.fill(b_count, progress, cancel, |block, out| {
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
                    tracer,
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
                        tracer,
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
    })?;
    stages.lap("fill");

    Ok(Bake {
        settings: settings.clone(),
        layout: ctx.layout.clone(),
        irradiance,
        covered,
        patches,
        samples,
        patch_irradiance: total_irr,
        energy,
        shots,
        regathered_texels: regathered.load(Ordering::Relaxed),
        polygon: None,
        virtual_lights: Vec::new(),
        stage_ms: stages.ms,
    })
}

/// Share of the VPL sites placed by the reflected direct power instead of by area.
///
/// Far from a receiver a patch is one disc at its site, and near it its samples are discs,
/// but its visibility is always its site's depth cube. With sites spread by area alone, a room
/// lit through an opening gets few patches in the light, each a large region whose site lies
/// anywhere in it, in a sheltered spot or an open one as the draw falls: on Sponza's atrium at
/// 800 VPLs the one-bounce atlas came out at 0.87, 0.50 and 0.62 of the (diffuse) path tracer
/// for three seeds, and at 0.78, 0.81 and 0.82 with half the sites by power (over the lower
/// storey's texels both placements spread alike, 0.87–1.26: `src/atlas/README.md`). Half stay
/// by area so that every surface keeps patches for the later bounces, which start where
/// bounce 1 lands.
pub(crate) const SITE_POWER_SHARE: f64 = 0.5;

/// The VPL sites: `n` of the raw samples (which come in area-stratified order), drawn by
/// systematic sampling of the density `(1 − s)/S + s·P_k/ΣP` over that order (P_k: sample k's
/// reflected direct power, s = [`SITE_POWER_SHARE`], or 0 when nothing is lit). Each site is
/// drawn once; a sample whose density spans several strata is one site (the list may be
/// shorter than `n`). Patch areas do not depend on this choice: a patch is its samples' area.
pub(crate) fn choose_sites(reflected: &[f32], n: usize, rng: &mut Rng) -> Vec<usize> {
    let count = reflected.len();
    if count == 0 || n == 0 {
        return Vec::new();
    }
    let total: f64 = reflected.iter().map(|&p| f64::from(p.max(0.0))).sum();
    let share = if total > 0.0 && total.is_finite() {
        SITE_POWER_SHARE
    } else {
        0.0
    };
    // Zero when nothing is lit (then `total` may be 0 and must not divide).
    let per_power = if share > 0.0 { share / total } else { 0.0 };
    let density =
        |k: usize| (1.0 - share) / count as f64 + per_power * f64::from(reflected[k].max(0.0));
    let mut sites = Vec::with_capacity(n);
    let mut k = 0usize;
    // The density of the samples before k.
    let mut below = 0.0f64;
    // One offset for all strata (systematic sampling): sites are exactly a stratum apart in
    // the density, so two coincide only where one sample's density exceeds a stratum.
    let offset = f64::from(rng.next_f32());
    for j in 0..n {
        let target = (j as f64 + offset) / n as f64;
        while k + 1 < count && below + density(k) <= target {
            below += density(k);
            k += 1;
        }
        if sites.last() != Some(&k) {
            sites.push(k);
        }
    }
    sites
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
/// search, ring by ring, up to [`ASSIGN_RINGS`] cells away; a sample no compatible site sees
/// takes the nearest site of any kind in that reach).
fn assign_samples(
    raw: &[SurfaceSample],
    sites: &[usize],
    grid: &SiteGrid,
    tracer: &Tracer,
) -> Vec<usize> {
    let (lo, hi) = (grid.lo, grid.hi);
    raw.par_iter()
        .map(|s| {
            let c = grid.key(s.position);
            let mut best: Option<(f32, usize)> = None;
            let mut fallback: Option<(f32, usize)> = None;
            for ring in 0..ASSIGN_RINGS {
                // Only the ring's shell, and of it only the cells inside the sites' bounds:
                // the full cube of a far ring is mostly empty cells (a sample that no
                // compatible site sees went through 2·64⁴ of them).
                let span = |a: usize| ((lo[a] - c[a]).max(-ring), (hi[a] - c[a]).min(ring));
                let ((x0, x1), (y0, y1), (z0, z1)) = (span(0), span(1), span(2));
                if x0 > x1 || y0 > y1 || z0 > z1 {
                    // The sites' box lies wholly beyond this ring: look further out.
                    continue;
                }
                let mut visit = |dx: i64, dy: i64, dz: i64| {
                    let Some(list) = grid.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        return;
                    };
                    for &j in list {
                        consider_site(raw, sites, j, s, tracer, &mut best, &mut fallback);
                    }
                };
                // The same order as a scan of the whole cube (x, then y, then z ascending),
                // so that ties between equally near sites go the same way.
                for dx in x0..=x1 {
                    for dy in y0..=y1 {
                        if dx.abs() == ring || dy.abs() == ring {
                            for dz in z0..=z1 {
                                visit(dx, dy, dz);
                            }
                        } else {
                            // |dx|, |dy| < ring, so ring > 0: the two caps differ.
                            for dz in [-ring, ring] {
                                if (z0..=z1).contains(&dz) {
                                    visit(dx, dy, dz);
                                }
                            }
                        }
                    }
                }
                // Stop once no closer site can lie in the next ring, or once the ring holds
                // the sites' whole box (no ring beyond has a site).
                if let Some((d, _)) = best {
                    let reach = ring as f32 * grid.cell;
                    if d <= reach * reach {
                        break;
                    }
                }
                let covered = (0..3).all(|a| c[a] - ring <= lo[a] && hi[a] <= c[a] + ring);
                if covered {
                    break;
                }
            }
            best.or(fallback).map(|(_, j)| j).unwrap_or(0)
        })
        .collect()
}

/// The VPL sites in a hash grid of cells about one patch wide (`total_area / n` each), with
/// the bounds of the cells that hold any.
struct SiteGrid {
    cell: f32,
    /// Cell → indices into `sites`.
    cells: std::collections::HashMap<[i64; 3], Vec<usize>>,
    lo: [i64; 3],
    hi: [i64; 3],
}

impl SiteGrid {
    fn new(raw: &[SurfaceSample], sites: &[usize], total_area: f64, n: usize) -> Self {
        let mut grid = Self {
            cell: ((total_area / n as f64).sqrt() as f32).max(1e-6),
            cells: Default::default(),
            lo: [i64::MAX; 3],
            hi: [i64::MIN; 3],
        };
        for (j, &s) in sites.iter().enumerate() {
            let k = grid.key(raw[s].position);
            grid.lo = std::array::from_fn(|a| grid.lo[a].min(k[a]));
            grid.hi = std::array::from_fn(|a| grid.hi[a].max(k[a]));
            grid.cells.entry(k).or_default().push(j);
        }
        grid
    }

    /// The cell holding `p`.
    fn key(&self, p: Vec3) -> [i64; 3] {
        let q = (p / self.cell).floor();
        [q.x as i64, q.y as i64, q.z as i64]
    }
}

/// How many grid rings [`assign_samples`] searches for a sample's site.
const ASSIGN_RINGS: i64 = 64;

/// Site `j` as sample `s`'s patch: the nearest so far of any kind (`fallback`), and the
/// nearest with a compatible normal (within ~37°) that `s` sees (`best`); both as
/// (squared distance, site).
fn consider_site(
    raw: &[SurfaceSample],
    sites: &[usize],
    j: usize,
    s: &SurfaceSample,
    tracer: &Tracer,
    best: &mut Option<(f32, usize)>,
    fallback: &mut Option<(f32, usize)>,
) {
    let site = &raw[sites[j]];
    let d = site.position.distance_squared(s.position);
    if fallback.is_none_or(|(bd, _)| d < bd) {
        *fallback = Some((d, j));
    }
    if site.normal.dot(s.normal) > 0.8
        && best.is_none_or(|(bd, _)| d < bd)
        && mutually_visible(tracer, site, s)
    {
        *best = Some((d, j));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sites(reflected: &[f32], n: usize) -> Vec<usize> {
        choose_sites(reflected, n, &mut Rng::from_state(7))
    }

    #[test]
    fn unlit_scenes_get_one_site_per_area_stratum() {
        let (n, per) = (50, 10);
        let s = sites(&vec![0.0; n * per], n);
        assert_eq!(s.len(), n);
        for (j, &k) in s.iter().enumerate() {
            assert!(
                (j * per..(j + 1) * per).contains(&k),
                "site {j} at sample {k}"
            );
        }
    }

    #[test]
    fn lit_samples_get_the_power_share_of_the_sites() {
        // The first half of the samples holds all the reflected power (each lit sample's
        // density stays below one stratum, so no two sites coincide).
        let (n, per) = (200, 10);
        let count = n * per;
        let reflected: Vec<f32> = (0..count)
            .map(|k| if k < count / 2 { 1.0 } else { 0.0 })
            .collect();
        let s = sites(&reflected, n);
        assert_eq!(s.len(), n);
        assert!(s.windows(2).all(|w| w[0] < w[1]), "sorted and distinct");
        let lit = s.iter().filter(|&&k| k < count / 2).count() as f64;
        // Expected: n·(share + (1 − share)/2) = 150 of 200.
        let expected = n as f64 * (SITE_POWER_SHARE + (1.0 - SITE_POWER_SHARE) * 0.5);
        assert!(
            (lit - expected).abs() <= 1.0,
            "{lit} lit sites, expected {expected}"
        );
        // The unlit half keeps its area share, spread over all of it.
        assert!(*s.last().unwrap() >= count - 2 * count / n);
    }

    #[test]
    fn a_sample_holding_most_of_the_power_is_one_site() {
        let mut reflected = vec![0.0f32; 1000];
        reflected[500] = 1.0;
        let s = sites(&reflected, 100);
        assert_eq!(s.iter().filter(|&&k| k == 500).count(), 1);
        // Half the strata fall on it; the other half stay spread by area.
        assert!((s.len() as i64 - 51).abs() <= 1, "{} sites", s.len());
        assert!(s.iter().all(|&k| k < 1000));
    }

    /// The search before it kept to the sites' bounds: every cell of every ring's cube.
    fn assign_samples_whole_cubes(
        raw: &[SurfaceSample],
        sites: &[usize],
        grid: &SiteGrid,
        tracer: &Tracer,
    ) -> Vec<usize> {
        raw.iter()
            .map(|s| {
                let [cx, cy, cz] = grid.key(s.position);
                let mut best: Option<(f32, usize)> = None;
                let mut fallback: Option<(f32, usize)> = None;
                for ring in 0..ASSIGN_RINGS {
                    for dx in -ring..=ring {
                        for dy in -ring..=ring {
                            for dz in -ring..=ring {
                                if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                                    continue;
                                }
                                let Some(list) = grid.cells.get(&[cx + dx, cy + dy, cz + dz])
                                else {
                                    continue;
                                };
                                for &j in list {
                                    consider_site(
                                        raw,
                                        sites,
                                        j,
                                        s,
                                        tracer,
                                        &mut best,
                                        &mut fallback,
                                    );
                                }
                            }
                        }
                    }
                    if let Some((d, _)) = best {
                        let reach = ring as f32 * grid.cell;
                        if d <= reach * reach {
                            break;
                        }
                    }
                }
                best.or(fallback).map(|(_, j)| j).unwrap_or(0)
            })
            .collect()
    }

    /// The shell search within the sites' bounds assigns every sample as the whole-cube scan
    /// does, including samples no compatible site sees (the fallback, which used to scan all
    /// 64 rings) and samples outside the sites' box.
    #[test]
    fn the_bounded_shell_search_assigns_as_the_whole_cube_scan() {
        let scene = crate::scene::builtin::load(
            "box-point",
            &crate::scene::builtin::BuiltinParams::default(),
        )
        .unwrap();
        let tracer = Tracer::new(&scene, &scene.world_from_node());
        let mut rng = Rng::from_state(11);
        let normals = [Vec3::X, Vec3::NEG_X, Vec3::Y, Vec3::Z, Vec3::NEG_Z];
        let mut raw: Vec<SurfaceSample> = (0..1500)
            .map(|_| {
                let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 1.6 - 0.8;
                SurfaceSample {
                    position: p,
                    normal: normals[(rng.next_f32() * 5.0) as usize % 5],
                    material: 0,
                    rho: Vec3::splat(0.5),
                }
            })
            .collect();
        // Facing down: no site does (fallback), and a corner cluster outside most rings.
        for k in 0..5 {
            raw.push(SurfaceSample {
                position: Vec3::new(0.85, -0.85, 0.8) - Vec3::splat(k as f32 * 0.002),
                normal: Vec3::NEG_Y,
                material: 0,
                rho: Vec3::splat(0.5),
            });
        }
        let sites: Vec<usize> = (0..1500).step_by(15).collect();
        // A cell of about 4 cm: the box spans 40 rings.
        let total_area = 0.04f64.powi(2) * sites.len() as f64;
        let grid = SiteGrid::new(&raw, &sites, total_area, sites.len());
        let bounded = assign_samples(&raw, &sites, &grid, &tracer);
        let whole = assign_samples_whole_cubes(&raw, &sites, &grid, &tracer);
        assert_eq!(bounded, whole);
        // The case the bound is for: samples facing away from every site get one anyway.
        assert!(bounded[1500..].iter().all(|&j| j < sites.len()));
    }

    #[test]
    fn non_finite_or_negative_power_falls_back_to_area() {
        let s = sites(&[f32::NAN; 100], 10);
        assert_eq!(s.len(), 10);
        let s = sites(&[-1.0; 100], 10);
        assert_eq!(s.len(), 10);
    }
}
