//! The polygon-light baker (seed 001, methods §B): photon-traced VPLs per light and per bounce
//! ([`photons`]), a RANSAC plane search ([`planes`]), gap-aware kd-tree clustering, 2-D on
//! planes and 3-D elsewhere ([`cluster`]), convex polygon lights (hull → ≤ 8 vertices →
//! border → clipped to the kd cell) and sphere lights for the rest ([`lights`]), accumulated
//! into the atlas with the analytic form factor ([`form_factor`]) and PCSS from a depth cube
//! at each light's centre ([`pcss`]). Each light and each bounce is clustered on its own
//! (joint clustering is an option, for the comparison). The atlas holds indirect irradiance
//! per bounce, like the patch baker's; direct light stays the renderer's.

pub mod cluster;
pub mod form_factor;
pub mod lights;
pub mod pcss;
pub mod photons;
pub mod planes;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use glam::{Mat4, Vec2, Vec3};
use rayon::prelude::*;

use self::form_factor::{polygon_irradiance, sphere_irradiance, PolygonLight, SphereLight};
use self::photons::Vpl;
use self::planes::PlaneSearch;
use super::bake::{
    check, Bake, BakeError, BakeScene, BakeSettings, Baker, Progress, Stages, MAX_CUBE_BYTES,
    MAX_CUBE_RES,
};
use super::depth::DepthCube;
use crate::scene::Scene;

/// Knobs of the polygon-light baker.
#[derive(Clone, Debug, PartialEq)]
pub struct PolygonSettings {
    /// Target VPLs per cluster (Fig. 12: 50).
    pub cluster_size: usize,
    /// Gap weighting ρ of the kd split (0.5; ∞ = median split).
    pub gap_rho: f32,
    /// Search for planes first (false: every cluster is a 3-D kd cell and a sphere light).
    pub planes: bool,
    pub plane_search: PlaneSearch,
    /// Cluster each bounce on its own (the paper's); false clusters all bounces of a light
    /// together (Fig. 9's comparison).
    pub per_bounce: bool,
    /// Face resolution of each light's depth cube.
    pub cube_res: usize,
    /// PCSS visibility (false: unshadowed, for tests of the form factor alone).
    pub shadows: bool,
    /// ε-region of the corner shift in texels (0.5; 0 turns it off).
    pub epsilon_texels: f32,
    /// Largest corner shift, texels.
    pub max_shift_texels: f32,
}

impl Default for PolygonSettings {
    fn default() -> Self {
        Self {
            cluster_size: 50,
            gap_rho: 0.5,
            planes: true,
            plane_search: PlaneSearch::default(),
            per_bounce: true,
            cube_res: 128,
            shadows: true,
            epsilon_texels: 0.5,
            max_shift_texels: 2.0,
        }
    }
}

/// Height of a light's depth cube above its surface, in depth-map near planes (as the patch
/// baker's).
const CUBE_LIFT: f32 = 10.0;

/// Upper bound of the photon paths of one bake.
pub const MAX_PATHS: usize = 50_000_000;

/// A virtual light: its shape and its power per bounce (one bounce unless clustered jointly).
#[derive(Clone, Debug)]
pub struct VirtualLight {
    pub shape: Shape,
    /// `power[b]`: the power its VPLs of bounce b + 1 carry (W per channel).
    pub power: Vec<[f64; 3]>,
}

#[derive(Clone, Debug)]
pub enum Shape {
    Polygon(PolygonLight),
    Sphere(SphereLight),
}

impl VirtualLight {
    /// Where the depth cube sits: the centre, lifted off the emitting surface.
    pub fn centre(&self) -> Vec3 {
        match &self.shape {
            Shape::Polygon(p) => p.centre,
            Shape::Sphere(s) => s.centre,
        }
    }

    /// The light's size for the penumbra: the polygon's bounding diameter, 2r for a sphere.
    pub fn size(&self) -> f32 {
        match &self.shape {
            Shape::Polygon(p) => 2.0 * p.radius,
            Shape::Sphere(s) => 2.0 * s.radius,
        }
    }

    /// Unshadowed irradiance per watt at `(p, n)`; `eps` and `max_shift` are the corner
    /// shift's (world units), `clear` confirms a shift (see [`polygon_irradiance`]).
    pub fn transfer(
        &self,
        p: Vec3,
        n: Vec3,
        eps: f32,
        max_shift: f32,
        clear: &dyn Fn(Vec3, Vec3) -> bool,
    ) -> f64 {
        match &self.shape {
            Shape::Polygon(l) => polygon_irradiance(l, p, n, eps, max_shift, clear),
            Shape::Sphere(s) => sphere_irradiance(s, p, n),
        }
    }
}

/// The polygon-light bake's figures.
#[derive(Clone, Debug, Default)]
pub struct PolygonStats {
    /// Photon paths traced.
    pub paths: usize,
    /// VPLs per bounce.
    pub vpls: Vec<usize>,
    pub polygons: usize,
    pub spheres: usize,
    /// Planar segments found.
    pub planes: usize,
    /// VPLs the photon stage made per second.
    pub vpls_per_second: f64,
}

impl PolygonStats {
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "paths": self.paths,
            "vpls_per_bounce": self.vpls,
            "polygon_lights": self.polygons,
            "sphere_lights": self.spheres,
            "planes": self.planes,
            "vpls_per_second": self.vpls_per_second.round(),
        })
    }
}

/// The polygon-light baker (seed 001).
pub struct PolygonBaker;

impl Baker for PolygonBaker {
    fn name(&self) -> &'static str {
        "polygons"
    }

    fn bake(
        &self,
        scene: &Scene,
        world_from_node: &[Mat4],
        settings: &BakeSettings,
        progress: Progress,
        cancel: &AtomicBool,
    ) -> Result<Bake, BakeError> {
        let ps = &settings.polygon;
        if ps.cluster_size == 0 || settings.vpls > MAX_PATHS {
            return Err(BakeError::Settings(format!(
                "--cluster-size must be at least 1 and --vpls (photon paths) at most \
                 {MAX_PATHS} (got {} and {})",
                ps.cluster_size, settings.vpls
            )));
        }
        let positive = ps.gap_rho > 0.0 && ps.epsilon_texels >= 0.0 && ps.max_shift_texels >= 0.0;
        if !(4..=MAX_CUBE_RES).contains(&ps.cube_res) || !positive {
            return Err(BakeError::Settings(format!(
                "polygon lights: the cube resolution must be 4..={MAX_CUBE_RES} (got {}), the \
                 gap weight positive and the corner shift non-negative",
                ps.cube_res
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
        let bounces = settings.bounces as usize;

        // --- Photons ------------------------------------------------------------------
        progress("photons", 0, 1);
        let started = Instant::now();
        let sphere = (ctx.bounds.center(), 0.5 * ctx.scene_size);
        let photons = photons::trace(
            &ctx.tracer,
            &ctx.lights,
            sphere,
            settings.vpls,
            bounces,
            settings.seed,
            cancel,
        );
        check(cancel)?;
        let vpl_count: usize = photons.vpls.iter().flatten().map(Vec::len).sum();
        let photon_s = started.elapsed().as_secs_f64();
        progress("photons", 1, 1);
        stages.lap("photons");

        // --- Clusters -----------------------------------------------------------------
        let mut groups: Vec<(Vec<Vpl>, Vec<usize>)> = Vec::new();
        for per_light in &photons.vpls {
            if ps.per_bounce {
                for (b, v) in per_light.iter().enumerate() {
                    groups.push((v.clone(), vec![b; v.len()]));
                }
            } else {
                let all: Vec<Vpl> = per_light.iter().flatten().copied().collect();
                let tags = per_light
                    .iter()
                    .enumerate()
                    .flat_map(|(b, v)| std::iter::repeat_n(b, v.len()))
                    .collect();
                groups.push((all, tags));
            }
        }
        let area = ctx.surface_area as f32;
        let clustered: Vec<(Vec<VirtualLight>, usize)> = groups
            .par_iter()
            .enumerate()
            .map(|(g, (vpls, bounce_of))| {
                cluster_lights(vpls, bounce_of, bounces, ps, area, settings.seed ^ g as u64)
            })
            .collect();
        let plane_count = clustered.iter().map(|c| c.1).sum();
        let lights: Vec<VirtualLight> = clustered.into_iter().flat_map(|c| c.0).collect();
        let polygons = lights
            .iter()
            .filter(|l| matches!(l.shape, Shape::Polygon(_)))
            .count();
        stages.lap("cluster");
        check(cancel)?;

        // --- Depth cubes at the lights' centres -----------------------------------------
        let cube_bytes = lights.len() as f64 * 24.0 * (ps.cube_res as f64).powi(2);
        if cube_bytes > MAX_CUBE_BYTES as f64 {
            return Err(BakeError::Settings(format!(
                "{} virtual lights × 6 × {}² depth texels do not fit in {} GiB: fewer photon \
                 paths, a larger --cluster-size or a smaller cube",
                lights.len(),
                ps.cube_res,
                MAX_CUBE_BYTES >> 30
            )));
        }
        let done = AtomicUsize::new(0);
        let cubes: Vec<Option<DepthCube>> = lights
            .par_iter()
            .map(|l| {
                if !ps.shadows || cancel.load(Ordering::Relaxed) {
                    return None;
                }
                let lift = match &l.shape {
                    Shape::Polygon(p) => p.normal * (ctx.eps * CUBE_LIFT),
                    Shape::Sphere(s) => s.normal.unwrap_or(Vec3::ZERO) * (ctx.eps * CUBE_LIFT),
                };
                let cube = DepthCube::new(l.centre() + lift, ps.cube_res, ctx.eps, &ctx.occluders);
                let d = done.fetch_add(1, Ordering::Relaxed) + 1;
                if d.is_multiple_of(64) || d == lights.len() {
                    progress("visibility", d, lights.len());
                }
                Some(cube)
            })
            .collect();
        check(cancel)?;
        stages.lap("visibility");

        // --- Accumulation -------------------------------------------------------------
        let texel = ctx.texel_size();
        let (eps, max_shift) = (ps.epsilon_texels * texel, ps.max_shift_texels * texel);
        let tracer = &ctx.tracer;
        // The cube sits CUBE_LIFT·eps above its polygon; stored surfaces within 3× that of the
        // light's plane are the surface it lies on.
        let lift = 3.0 * CUBE_LIFT * ctx.eps;
        let (irradiance, covered) = ctx.fill(bounces, progress, cancel, |block, out| {
            for (i, l) in lights.iter().enumerate() {
                for (k, t) in block.iter().enumerate() {
                    let clear = |from: Vec3, to: Vec3| {
                        let origin = from + t.normal * tracer.epsilon;
                        let d = to + t.normal * tracer.epsilon - origin;
                        let len = d.length();
                        len <= tracer.epsilon || tracer.unoccluded(origin, d / len, len)
                    };
                    let f = l.transfer(t.position, t.normal, eps, max_shift, &clear);
                    if f <= 0.0 {
                        continue;
                    }
                    let v = match &cubes[i] {
                        Some(cube) => {
                            let emitter = match &l.shape {
                                Shape::Polygon(p) => Some((p.centre, p.normal, lift)),
                                Shape::Sphere(_) => None,
                            };
                            pcss::pcss_visibility(cube, t.position, t.normal, l.size(), emitter)
                                as f64
                        }
                        None => 1.0,
                    };
                    if v <= 0.0 {
                        continue;
                    }
                    for (b, pw) in l.power.iter().enumerate() {
                        let o = &mut out[k * bounces + b];
                        for c in 0..3 {
                            o[c] += (pw[c] * f * v) as f32;
                        }
                    }
                }
            }
        })?;
        stages.lap("fill");
        let stats = PolygonStats {
            paths: photons.paths,
            vpls: (0..bounces)
                .map(|b| photons.vpls.iter().map(|l| l[b].len()).sum())
                .collect(),
            polygons,
            spheres: lights.len() - polygons,
            planes: plane_count,
            vpls_per_second: vpl_count as f64 / photon_s.max(1e-9),
        };
        Ok(Bake {
            settings: settings.clone(),
            layout: ctx.layout.clone(),
            irradiance,
            covered,
            patches: Vec::new(),
            samples: Vec::new(),
            patch_irradiance: Vec::new(),
            energy: photons.energy,
            shots: lights.len(),
            regathered_texels: 0,
            polygon: Some(stats),
            virtual_lights: lights,
            stage_ms: stages.ms,
        })
    }
}

/// Clusters one group of VPLs (`bounce_of[i]` is VPL i's bounce, 0-based) into virtual
/// lights; returns them and the number of planes found. `area` is the scene's surface area
/// (for the mean VPL spacing).
pub fn cluster_lights(
    vpls: &[Vpl],
    bounce_of: &[usize],
    bounces: usize,
    ps: &PolygonSettings,
    area: f32,
    seed: u64,
) -> (Vec<VirtualLight>, usize) {
    if vpls.is_empty() {
        return (Vec::new(), 0);
    }
    let positions: Vec<Vec3> = vpls.iter().map(|v| v.position).collect();
    let normals: Vec<Vec3> = vpls.iter().map(|v| v.normal).collect();
    let spacing = (area / vpls.len() as f32).sqrt();
    let (segments, rest) = if ps.planes {
        planes::find_planes(
            &positions,
            &normals,
            &ps.plane_search,
            ps.cluster_size,
            spacing,
            seed,
        )
    } else {
        (Vec::new(), (0..vpls.len()).collect())
    };
    let per_bounce = |members: &[usize]| {
        let mut p = vec![[0.0f64; 3]; bounces];
        for &i in members {
            for (sum, v) in p[bounce_of[i]].iter_mut().zip(vpls[i].power) {
                *sum += v;
            }
        }
        p
    };
    let mut out = Vec::new();
    let sphere_of = |members: &[usize]| {
        let pos: Vec<Vec3> = members.iter().map(|&i| vpls[i].position).collect();
        let nor: Vec<Vec3> = members.iter().map(|&i| vpls[i].normal).collect();
        let pw: Vec<[f64; 3]> = members.iter().map(|&i| vpls[i].power).collect();
        lights::sphere_light(&pos, &nor, &pw)
    };
    for seg in &segments {
        let coords: Vec<[f32; 2]> = seg
            .members
            .iter()
            .map(|&i| seg.frame.to_plane(vpls[i].position).to_array())
            .collect();
        for leaf in cluster::kd_clusters(&coords, ps.cluster_size, ps.gap_rho) {
            let members: Vec<usize> = leaf.members.iter().map(|&k| seg.members[k]).collect();
            let pts: Vec<Vec2> = leaf
                .members
                .iter()
                .map(|&k| Vec2::from(coords[k]))
                .collect();
            let pw: Vec<[f64; 3]> = members.iter().map(|&i| vpls[i].power).collect();
            let shape = match lights::polygon_light(
                &seg.frame,
                &pts,
                &pw,
                Vec2::from(leaf.cell_min),
                Vec2::from(leaf.cell_max),
            ) {
                Some(p) => Shape::Polygon(p),
                None => Shape::Sphere(sphere_of(&members)),
            };
            out.push(VirtualLight {
                shape,
                power: per_bounce(&members),
            });
        }
    }
    let coords: Vec<[f32; 3]> = rest.iter().map(|&i| vpls[i].position.to_array()).collect();
    for leaf in cluster::kd_clusters(&coords, ps.cluster_size, ps.gap_rho) {
        let members: Vec<usize> = leaf.members.iter().map(|&k| rest[k]).collect();
        out.push(VirtualLight {
            shape: Shape::Sphere(sphere_of(&members)),
            power: per_bounce(&members),
        });
    }
    (out, segments.len())
}
