//! `--quality auto`: the sparse method's budget knobs (sparse points, RSM side, occlusion)
//! chosen per scene from a cheap survey of the scene and, under a FLIP target, a few small
//! pilot frames that measure its predictions, not from a table of scenes.
//!
//! **The survey** ([`Survey::new`], CPU, 0.1–0.3 s on the built-in scenes) measures what the
//! knobs trade against:
//! - *Lit samples*: photons from every light over its RSM views (the texel grid the VALs come
//!   from), each hit carrying the diffusely reflected flux Φ_s = ρ_d·I(ω)·Ω_s and the surface
//!   area its texel covers, d²·Ω_s / cos θ. Their sum is the lit area A_lit, and the hit
//!   share of the views gives the VAL count of a side R: V(R) = R²·Σ views·f_hit. The hits
//!   are resampled by flux to [`SURVEY_LIT_SAMPLES`] samples of equal flux.
//! - *Receivers*: the surface points the scene's default camera sees through a jittered
//!   grid of [`SURVEY_RECEIVERS`] pixels, where the image's error is (by area without one).
//! - *Transfer*: for every receiver r and lit sample s the one-bounce irradiance share
//!   w_rs = Φ_s·cos θ_s·cos θ_r / (π (d² + r_s²)) (each sample a disc of its share of the lit
//!   area, r_s² = A_lit / (π·samples)), and whether a shadow ray finds the segment open
//!   (v_rs).
//!
//! **Error terms**, each a per-receiver relative error averaged with weights
//! u_r = E_r / (E_r + Ē) (bright receivers count in full, dark ones fade, as in a tone-mapped
//! image):
//! - ε(h): irradiance from a source at distance d varies over lengths of order d, so sampled
//!   at spacing h and interpolated it is off by a relative (h/d)², saturating at 1:
//!   Σ_s w v·min(1, h²/d²) / Σ_s w v. For the points h = √(A / N) (their spacing over the
//!   scene's area A), for the VALs s = √(A_lit / V(R)).
//! - δ(h), measured: the one-bounce radiance toward the eye (diffuse and glossy, through the
//!   surface's own BRDF, shading normal and visibility) at two surface points ±h away along
//!   a tangent against the receiver's own, |L± − L| / L. It sees what ε misses: curved and
//!   glossy surfaces and the edges of indirect shadows. Probed at the spacings of
//!   [`PROBE_POINTS`] points and interpolated log-log between them.
//! - o: leaving occlusion out shows the unoccluded irradiance where only the seen part is
//!   right: per receiver Σ w(1−v) / Σ w.
//!
//! **Model** ([`model`], fitted to `valgi eval --sweep` over the built-in failure scenes, the
//! Cornell box, the door room and Sponza; `src/vals/README.md`, "Budget mode", has the fit
//! and how far it is off per scene): the predicted *convergence* FLIP (indirect FLIP against
//! the fully converged setting, the error the knobs control) is
//! a·(ε(h) + δ(h) + c_vals·ε(s) + c_off·o)^b, with o only when occlusion is off. The frame
//! time is predicted from the work it does: N·V(R) gathered pairs and, with rays,
//! N·clusters visibility tests, at rates measured on lavapipe.
//!
//! By the survey alone ([`Survey::choose`]) the choice is the cheapest candidate whose
//! predicted FLIP meets `--target-flip`, or with `--budget-ms` the most accurate one whose
//! predicted time fits.
//!
//! **Timing pilots** ([`timed`]). Under `--budget-ms` the candidates are timed: a few frames
//! of each at the render's own size on the render's device, the measured times refitting the
//! predicted ones (their fixed part, which the survey prices from the median scene's passes
//! and the pixels a frame shades, most of all), until the most accurate candidate within the budget is one measured
//! within it. Small pilot frames then rank the candidates within the budget by measured
//! accuracy ([`Survey::search_within`]), which the survey's prediction misjudges between
//! kinds of occlusion.
//!
//! **Pilot frames** ([`Survey::search`]). The survey ranks the candidates well within a scene
//! but misjudges how its relative errors become FLIP in a given scene (a factor 1.6 rms, from
//! 0.6× to 1.8× by scene), and no cheap scene measurement tried closed that gap. So under a
//! FLIP target the method renders a few small frames: the richest candidate as the converged
//! image, then, cheapest first, the candidates the survey calibrated by what was measured so
//! far predicts to meet the target. The pilots' measured convergence FLIP over their
//! predictions (a geometric mean, kept apart for each kind of occlusion, rays, none and summed
//! discs: [`pilot_scale`]) scales every prediction. Once a pilot has measured one kind, the
//! most accurate candidate of a kind not measured yet is measured next if the widest gap seen
//! between two scales could let it meet the target ([`UNMEASURED_SPREAD`]). `sum`, which
//! never converges and which the survey prices as no occlusion, is a candidate of the pilots
//! only: the survey alone never chooses it. When no candidate
//! cheaper than the best found is predicted to meet the target, the one predicted most
//! accurate is still measured if its prediction lies within the scaled model's own spread of
//! the target ([`PROBE_SPREAD`]). The choice is the cheapest candidate *measured* to meet the
//! target, the richest one when none was. The pilots measure against the richest candidate,
//! so they can say the target is met only where that candidate itself is near convergence:
//! `met` also needs its own prediction, scaled by the pilots, within the target (on Sponza the
//! richest candidate is predicted 0.18 from convergence and measured 0.20 from 32 768 points
//! with RSM 256; every built-in scene's is predicted at 0.013 or less).

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use crate::sampling::{basis, Rng};
use crate::scene::{CameraView, LightKind, Scene};
use crate::shading::{spot_attenuation, WorldLight};
use crate::trace::Tracer;

pub mod timed;

/// Photons shot from all lights together.
pub const SURVEY_PHOTONS: usize = 4096;
/// Lit samples the transfer uses (resampled from the photon hits by flux).
pub const SURVEY_LIT_SAMPLES: usize = 192;
/// Receivers spread over the surface.
pub const SURVEY_RECEIVERS: usize = 768;
/// Point counts whose spacings the variation probe measures at (densest first, so the
/// spacings ascend).
pub const PROBE_POINTS: [usize; 5] = [65536, 16384, 4096, 1024, 256];

/// One lit sample: a photon hit, standing for part of the RSM's reflected flux.
#[derive(Clone, Copy, Debug)]
pub struct LitSample {
    pub position: Vec3,
    pub normal: Vec3,
    /// Diffusely reflected flux (the mean of the channels), W.
    pub flux: f64,
    /// Visibility cluster (RSM tile over all views) the sample falls in.
    pub tile: u32,
}

/// One receiver–lit-sample pair that carries light.
#[derive(Clone, Copy, Debug)]
struct Pair {
    /// Irradiance share w_rs (W/m²), before visibility.
    w: f64,
    d2: f64,
    visible: bool,
    tile: u32,
}

/// One receiver's pairs and what they sum to.
#[derive(Clone, Debug, Default)]
struct Receiver {
    position: Vec3,
    /// Unit normal on the side that receives light.
    normal: Vec3,
    pairs: Vec<Pair>,
    /// Irradiance that arrives (W/m²) and that geometry blocks.
    seen: f64,
    hidden: f64,
    /// Σ over cluster tiles of min(seen, hidden): what deciding each tile whole gets wrong.
    partial: f64,
    /// Its weight in the means, u_r (see [`Survey::mean_over_receivers`]).
    weight: f64,
}

/// What the survey measured.
#[derive(Clone, Debug)]
pub struct Survey {
    /// World-space surface area, m².
    pub area: f64,
    /// Area the lights' RSM views see lit, m².
    pub lit_area: f64,
    /// Σ over RSM views of the share of the view's texels that hit lit geometry: the VAL
    /// count of side R is `R²·lit_views`.
    pub lit_views: f64,
    /// Visibility clusters a frame shoots rays at (per point).
    pub clusters: u32,
    /// The relative error of leaving visibility out: per receiver the blocked irradiance over
    /// the unoccluded, Σ w(1−v) / Σ w, averaged with weights by the unoccluded irradiance.
    pub occluded_share: f64,
    /// The relative error of deciding visibility per whole cluster tile (`--visibility-rays
    /// adaptive` settles a tile seen in part one way): per receiver Σ over tiles of
    /// min(seen, hidden) over the arriving, averaged.
    pub partial_share: f64,
    receivers: Vec<Receiver>,
    /// Surface area the camera sees, m² (all of it without a camera).
    pub visible_area: f64,
    /// The camera's position, when receivers are what it sees.
    pub eye: Option<Vec3>,
    /// (h, δ(h)) at the spacings of [`PROBE_POINTS`] points, h ascending.
    pub variation: Vec<(f64, f64)>,
    pub lit_samples: usize,
    pub survey_ms: f64,
    /// Predicted times are the fitted model's times × this: 1 on the fitting device, its FMA
    /// peak over the device's for another ([`model::FIT_FMA_PEAK`]).
    pub time_scale: f64,
    /// Whether the gather will gather glossy light (`glossy auto` leaves the lobes out of an
    /// all-Lambert scene): it prices the gather ([`model::gather_cost`]).
    pub gathers_glossy: bool,
    /// The pixels a frame shades (width × height × SSAA² × views): they price the per-pixel
    /// passes ([`model::FRAME_MS_PER_PIXEL`]); [`model::FIT_PIXELS`] unless told
    /// ([`Survey::shading`]).
    pub frame_pixels: f64,
}

/// Light views as the RSM lays them out: (light, forward, up, tan of the half field of view)
/// for perspective views, and a directional light's square.
enum LightView {
    Perspective {
        light: usize,
        origin: Vec3,
        forward: Vec3,
        tan_half: f32,
    },
    Orthographic {
        light: usize,
        center: Vec3,
        direction: Vec3,
        half: f32,
    },
}

fn light_views(lights: &[WorldLight], center: Vec3, radius: f32) -> Vec<LightView> {
    let mut views = vec![];
    for (i, light) in lights.iter().enumerate() {
        match light.kind {
            LightKind::Point | LightKind::Emitter => {
                for (forward, _) in crate::raster::shadows::CUBE_FACES {
                    views.push(LightView::Perspective {
                        light: i,
                        origin: light.position,
                        forward,
                        tan_half: 1.0,
                    });
                }
            }
            LightKind::Spot {
                outer_cone_angle, ..
            } => views.push(LightView::Perspective {
                light: i,
                origin: light.position,
                forward: light.direction,
                tan_half: outer_cone_angle.clamp(1e-3, 85f32.to_radians()).tan(),
            }),
            LightKind::Directional => views.push(LightView::Orthographic {
                light: i,
                center,
                direction: light.direction,
                half: radius,
            }),
        }
    }
    views
}

/// Grey value of a colour: the mean of its channels.
fn grey(c: Vec3) -> f64 {
    ((c.x + c.y + c.z) / 3.0) as f64
}

impl Survey {
    /// Surveys the scene posed by `world_from_node`, seen by `camera` (receivers spread by
    /// area without one). Deterministic for a given `seed`.
    pub fn new(
        scene: &Scene,
        world_from_node: &[Mat4],
        camera: Option<&CameraView>,
        seed: u64,
    ) -> Survey {
        let started = std::time::Instant::now();
        let tracer = Tracer::new(scene, world_from_node);
        let triangles = tracer.world_triangles();
        let areas: Vec<f64> = triangles
            .iter()
            .map(|[a, b, c]| 0.5 * (*b - *a).cross(*c - *a).length() as f64)
            .map(|a| if a.is_finite() { a } else { 0.0 })
            .collect();
        let area: f64 = areas.iter().sum();
        let bounds = scene.world_bounds(world_from_node);
        let (center, radius) = if bounds.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            (bounds.center(), (bounds.extent().length() * 0.5).max(1e-3))
        };
        let views = light_views(&tracer.lights, center, radius);
        let layers: u32 = views.len() as u32;
        let tiles = crate::light::rsm::cluster_tiles(128, layers);
        let clusters = (tiles * tiles * layers).min(crate::light::rsm::MAX_CLUSTERS);

        // Photons: the same count per view, on a jittered grid of its image plane.
        let per_view = if views.is_empty() {
            0
        } else {
            (SURVEY_PHOTONS / views.len()).max(16)
        };
        let side = (per_view as f64).sqrt().ceil() as usize;
        let mut lit = vec![];
        let mut lit_area = 0.0;
        let mut lit_views = 0.0;
        let mut rng = Rng::new(seed, 0x5u64, 0);
        for (view_index, view) in views.iter().enumerate() {
            let mut hits = 0usize;
            for j in 0..side * side {
                let u = ((j % side) as f32 + rng.next_f32()) / side as f32 * 2.0 - 1.0;
                let v = ((j / side) as f32 + rng.next_f32()) / side as f32 * 2.0 - 1.0;
                let cell = |t: f32| (((t + 1.0) * 0.5 * tiles as f32) as u32).min(tiles - 1);
                let tile = crate::light::rsm::layer_tile(
                    tiles,
                    tiles,
                    view_index as u32,
                    cell(u),
                    cell(v),
                ) % crate::light::rsm::MAX_CLUSTERS;
                let (origin, dir, light, solid_or_area, ortho) = match *view {
                    LightView::Perspective {
                        light,
                        origin,
                        forward,
                        tan_half,
                    } => {
                        let (right, up) = basis(forward);
                        let (x, y) = (u * tan_half, v * tan_half);
                        let raw = forward + right * x + up * y;
                        // Solid angle of the sample's share of the image plane.
                        let plane = (2.0 * tan_half).powi(2) / (side * side) as f32;
                        let omega = plane / (1.0 + x * x + y * y).powf(1.5);
                        (origin, raw.normalize(), light, omega, false)
                    }
                    LightView::Orthographic {
                        light,
                        center,
                        direction,
                        half,
                    } => {
                        let (right, up) = basis(direction);
                        let origin = center - direction * (2.0 * half)
                            + right * (u * half)
                            + up * (v * half);
                        let cell = (2.0 * half).powi(2) / (side * side) as f32;
                        (origin, direction, light, cell, true)
                    }
                };
                let Some(hit) = tracer.intersect(origin, dir, f32::INFINITY) else {
                    continue;
                };
                let light = &tracer.lights[light];
                let cos = hit.geometric_normal.dot(-dir).abs().max(0.05);
                let (incoming, texel_area) = if ortho {
                    (
                        grey(light.intensity) * solid_or_area as f64,
                        solid_or_area / cos,
                    )
                } else {
                    let mut intensity = grey(light.intensity);
                    if let LightKind::Spot {
                        inner_cone_angle,
                        outer_cone_angle,
                    } = light.kind
                    {
                        intensity *= spot_attenuation(
                            inner_cone_angle,
                            outer_cone_angle,
                            light.direction.dot(dir),
                        ) as f64;
                    } else if light.kind == LightKind::Emitter {
                        intensity *= crate::shading::emitter_lobe(light.direction, dir) as f64;
                    }
                    (
                        intensity * solid_or_area as f64,
                        hit.t * hit.t * solid_or_area / cos,
                    )
                };
                let flux = incoming * grey(hit.rho_d);
                if !(flux > 0.0 && flux.is_finite()) {
                    continue;
                }
                hits += 1;
                lit_area += texel_area as f64;
                let normal = if hit.geometric_normal.dot(dir) < 0.0 {
                    hit.geometric_normal
                } else {
                    -hit.geometric_normal
                };
                lit.push(LitSample {
                    position: hit.position,
                    normal,
                    flux,
                    tile,
                });
            }
            lit_views += hits as f64 / (side * side) as f64;
        }
        let lit = resample_by_flux(&lit, SURVEY_LIT_SAMPLES, &mut rng);

        // Receivers: what the camera sees, where the image's error is; uniform by area when
        // the camera sees nothing.
        let (mut receivers, mut visible_area) = camera
            .map(|c| view_receivers(&tracer, c, SURVEY_RECEIVERS, &mut rng))
            .unwrap_or_default();
        visible_area = visible_area.min(area);
        if receivers.is_empty() {
            visible_area = area;
            receivers = sample_by_area(&triangles, &areas, SURVEY_RECEIVERS, &mut rng);
        }
        let epsilon = tracer.epsilon;
        // Each lit sample stands for its share of the lit area: a disc of that area, whose
        // irradiance stays finite at contact.
        let sample_disc = lit_area / lit.len().max(1) as f64 / std::f64::consts::PI;
        let per_receiver: Vec<(Vec3, Vec<Pair>)> = receivers
            .par_iter()
            .map(|&(x, n)| receiver_pairs(&tracer, &lit, sample_disc, x, n, epsilon))
            .collect();
        // Each receiver's seen and hidden irradiance, per cluster tile.
        let mut receivers_out = Vec::with_capacity(per_receiver.len());
        for ((x, _), (n, pairs)) in receivers.iter().zip(per_receiver) {
            let mut by_tile: std::collections::BTreeMap<u32, (f64, f64)> = Default::default();
            for p in &pairs {
                let entry = by_tile.entry(p.tile).or_default();
                if p.visible {
                    entry.0 += p.w;
                } else {
                    entry.1 += p.w;
                }
            }
            let (mut seen, mut hidden, mut partial) = (0.0, 0.0, 0.0);
            for (s, h) in by_tile.into_values() {
                seen += s;
                hidden += h;
                partial += s.min(h);
            }
            receivers_out.push(Receiver {
                position: *x,
                normal: n,
                pairs,
                seen,
                hidden,
                partial,
                weight: 0.0,
            });
        }
        let mean_seen =
            receivers_out.iter().map(|r| r.seen).sum::<f64>() / receivers_out.len().max(1) as f64;
        for r in &mut receivers_out {
            r.weight = if mean_seen > 0.0 {
                r.seen / (r.seen + mean_seen)
            } else {
                0.0
            };
        }
        let mut survey = Survey {
            area,
            lit_area,
            lit_views,
            clusters,
            occluded_share: 0.0,
            partial_share: 0.0,
            receivers: receivers_out,
            visible_area,
            eye: camera.map(CameraView::position),
            variation: vec![],
            lit_samples: lit.len(),
            survey_ms: 0.0,
            time_scale: 1.0,
            gathers_glossy: true,
            frame_pixels: model::FIT_PIXELS,
        };
        // Leaving visibility out shows seen + hidden where seen is right: relative to the
        // brighter of the two, hidden / (seen + hidden), and weighted by that brightness (a
        // receiver wholly in shadow, seen = 0, is where the leak shows most).
        let mean_unoccluded = survey
            .receivers
            .iter()
            .map(|r| r.seen + r.hidden)
            .sum::<f64>()
            / survey.receivers.len().max(1) as f64;
        let (mut num, mut den) = (0.0, 0.0);
        for r in survey.receivers.iter().filter(|r| r.seen + r.hidden > 0.0) {
            let unoccluded = r.seen + r.hidden;
            let u = unoccluded / (unoccluded + mean_unoccluded);
            num += u * r.hidden / unoccluded;
            den += u;
        }
        survey.occluded_share = if den > 0.0 { num / den } else { 0.0 };
        survey.partial_share = survey.mean_over_receivers(|r| (r.partial / r.seen).min(1.0));
        survey.variation = PROBE_POINTS
            .iter()
            .map(|&n| {
                let h = survey.point_spacing(n);
                (
                    h,
                    survey.variation_probe(&tracer, &lit, sample_disc, h, seed),
                )
            })
            .collect();
        survey.survey_ms = started.elapsed().as_secs_f64() * 1000.0;
        survey
    }

    /// δ(h) measured: per receiver, the irradiance at two surface points ±h away along a
    /// tangent (found by a ray down onto the surface, with their own shading normals and
    /// visibility) against the receiver's own, mean |E± − E| / E, averaged.
    fn variation_probe(
        &self,
        tracer: &Tracer,
        lit: &[LitSample],
        disc_radius2: f64,
        h: f64,
        seed: u64,
    ) -> f64 {
        let eye = self.eye;
        let h = h as f32;
        let deltas: Vec<Option<f64>> = self
            .receivers
            .par_iter()
            .enumerate()
            .map(|(i, r)| {
                if r.seen <= 0.0 {
                    return None;
                }
                let (t1, t2) = basis(r.normal);
                let angle = Rng::new(seed, 0x9, i as u64).next_f32() * std::f32::consts::TAU;
                let t = t1 * angle.cos() + t2 * angle.sin();
                let center = surface_below(tracer, r.position, r.normal, 0.0)?;
                let l0 = radiance_at(tracer, lit, disc_radius2, &center, eye);
                if l0 <= 0.0 {
                    return None;
                }
                let mut sum = 0.0;
                for sign in [1.0f32, -1.0] {
                    let l = match surface_below(tracer, r.position + t * (sign * h), r.normal, h) {
                        Some(hit) => radiance_at(tracer, lit, disc_radius2, &hit, eye),
                        // Off the surface's edge: the neighbourhood holds no second sample.
                        None => l0,
                    };
                    sum += ((l - l0).abs() / l0).min(1.0);
                }
                Some(sum / 2.0)
            })
            .collect();
        self.mean_over_receivers_indexed(|i| deltas[i])
    }

    /// [`Survey::mean_over_receivers`] of a per-receiver value given by index (receivers
    /// without one are left out).
    fn mean_over_receivers_indexed(&self, f: impl Fn(usize) -> Option<f64>) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (i, r) in self.receivers.iter().enumerate() {
            if let Some(v) = f(i) {
                num += r.weight * v;
                den += r.weight;
            }
        }
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }

    /// Σ u_r·f(r) / Σ u_r over the receivers that see light, u_r = E_r / (E_r + Ē): a
    /// receiver's relative error counts in full where it is bright and fades where it is
    /// dark, as a tone-mapped image shows it.
    fn mean_over_receivers(&self, f: impl Fn(&Receiver) -> f64) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for r in self.receivers.iter().filter(|r| r.seen > 0.0) {
            num += r.weight * f(r);
            den += r.weight;
        }
        if den > 0.0 {
            num / den
        } else {
            0.0
        }
    }

    /// Spacing of `points` sparse points over the scene's area, m.
    /// Prices the gather the method will compile for `glossy` on `scene`: the lobes only
    /// where some material reflects glossily ([`model::gather_cost`]). Both surveys, the
    /// tessellation's and the method's, price it so, and so pick the same point count.
    pub fn pricing_glossy(mut self, glossy: crate::light::GlossyGather, scene: &Scene) -> Self {
        self.gathers_glossy = glossy.gathers(crate::light::reflects_glossily(scene));
        self
    }

    pub fn point_spacing(&self, points: usize) -> f64 {
        (self.area / points.max(1) as f64).sqrt()
    }

    /// VALs an RSM of side `rsm` makes (texels that see lit geometry).
    pub fn val_count(&self, rsm: u32) -> f64 {
        (rsm as f64).powi(2) * self.lit_views
    }

    /// Spacing of the VALs of an RSM of side `rsm` over the lit area, m.
    pub fn val_spacing(&self, rsm: u32) -> f64 {
        (self.lit_area / self.val_count(rsm).max(1.0)).sqrt()
    }

    /// ε(h): the relative interpolation error of irradiance sampled at spacing `h`, per
    /// receiver Σ_s w v·min(1, h²/d²) / Σ_s w v, averaged over the receivers (module docs).
    pub fn interpolation_error(&self, h: f64) -> f64 {
        let h2 = h * h;
        self.mean_over_receivers(|r| {
            let off: f64 = r
                .pairs
                .iter()
                .filter(|p| p.visible)
                .map(|p| p.w * (h2 / p.d2).min(1.0))
                .sum();
            off / r.seen
        })
    }

    /// δ(h): the measured relative variation of irradiance over a distance h on the surface,
    /// interpolated log-log between the probed spacings (clamped at their ends).
    pub fn variation_error(&self, h: f64) -> f64 {
        let v = &self.variation;
        match v.len() {
            0 => 0.0,
            1 => v[0].1,
            _ => {
                let i = v
                    .iter()
                    .position(|&(hk, _)| hk >= h)
                    .unwrap_or(v.len() - 1)
                    .max(1);
                let ((h0, e0), (h1, e1)) = (v[i - 1], v[i]);
                if e0 <= 0.0 || e1 <= 0.0 {
                    return e0 + (e1 - e0) * ((h - h0) / (h1 - h0)).clamp(0.0, 1.0);
                }
                let t = ((h / h0).ln() / (h1 / h0).ln()).clamp(0.0, 1.0);
                (e0.ln() + t * (e1.ln() - e0.ln())).exp()
            }
        }
    }

    /// True when the lights reach no surface: there is no indirect light to budget for.
    pub fn is_dark(&self) -> bool {
        !self.receivers.iter().any(|r| r.seen > 0.0)
    }
}

/// `count` samples drawn with probability ∝ flux (systematic resampling), each carrying an
/// equal share of the total flux.
fn resample_by_flux(samples: &[LitSample], count: usize, rng: &mut Rng) -> Vec<LitSample> {
    let total: f64 = samples.iter().map(|s| s.flux).sum();
    if samples.is_empty() || total <= 0.0 || !total.is_finite() {
        return vec![];
    }
    let n = count.min(samples.len());
    let step = total / n as f64;
    let mut next = rng.next_f32() as f64 * step;
    let mut acc = 0.0;
    let mut out = Vec::with_capacity(n);
    for s in samples {
        acc += s.flux;
        while next < acc && out.len() < n {
            out.push(LitSample { flux: step, ..*s });
            next += step;
        }
    }
    out
}

/// The surface points `camera`'s rays hit through a jittered grid of about `count` pixels,
/// with their geometric normals on the camera's side.
fn view_receivers(
    tracer: &Tracer,
    camera: &CameraView,
    count: usize,
    rng: &mut Rng,
) -> (Vec<(Vec3, Vec3)>, f64) {
    let [l, r, b, t] = camera.tangent_extents();
    let side = (count as f64).sqrt().ceil() as usize;
    let eye = camera.position();
    let mut out = Vec::with_capacity(side * side);
    let plane = ((r - l) * (t - b)) as f64 / (side * side) as f64;
    let mut area = 0.0;
    for j in 0..side * side {
        let u = ((j % side) as f32 + rng.next_f32()) / side as f32;
        let v = ((j / side) as f32 + rng.next_f32()) / side as f32;
        let in_view = Vec3::new(l + (r - l) * u, b + (t - b) * v, -1.0);
        let dir = camera
            .world_from_view
            .transform_vector3(in_view)
            .normalize();
        if let Some(hit) = tracer.intersect(eye, dir, f32::INFINITY) {
            // The pixel's solid angle, and the surface it covers at the hit.
            let omega = plane / (in_view.length() as f64).powi(3);
            let cos = (hit.geometric_normal.dot(dir).abs() as f64).max(0.05);
            area += (hit.t as f64).powi(2) * omega / cos;
            out.push((hit.position, hit.geometric_normal));
        }
    }
    (out, area)
}

/// `count` points uniform by area over `triangles` (stratified in the area CDF), with their
/// triangles' unit normals.
fn sample_by_area(
    triangles: &[[Vec3; 3]],
    areas: &[f64],
    count: usize,
    rng: &mut Rng,
) -> Vec<(Vec3, Vec3)> {
    let total: f64 = areas.iter().sum();
    if total <= 0.0 || triangles.is_empty() {
        return vec![];
    }
    let mut out = Vec::with_capacity(count);
    let mut acc = 0.0;
    let mut k = 0usize;
    for (tri, &a) in triangles.iter().zip(areas) {
        acc += a;
        while k < count && (k as f64 + 0.5) / count as f64 * total < acc {
            let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let [p0, p1, p2] = *tri;
            let x = p0 + (p1 - p0) * u + (p2 - p0) * v;
            let n = (p1 - p0).cross(p2 - p0).normalize_or_zero();
            if n != Vec3::ZERO {
                out.push((x, n));
            }
            k += 1;
        }
    }
    out
}

/// The transfer from lit sample `s` to a receiver at `origin` with unit normal `n`.
struct Link {
    /// Unit direction to the sample, and its distance.
    wi: Vec3,
    d: f32,
    /// d² + r_s² (the sample a disc of radius r_s).
    d2_disc: f64,
    /// w = Φ·cos θ_s·cos θ_r / (π (d² + r_s²)): a disc of radius r on axis delivers
    /// Φ/(π(d² + r²)), finite at contact.
    w: f64,
}

/// The link from `s` (lifted `lift` off its surface) to `origin`, `None` when either side
/// faces away.
fn link(origin: Vec3, n: Vec3, s: &LitSample, lift: f32, disc_radius2: f64) -> Option<Link> {
    let to = s.position + s.normal * lift - origin;
    let d2 = to.length_squared();
    if d2 <= 0.0 || !d2.is_finite() {
        return None;
    }
    let d = d2.sqrt();
    let wi = to / d;
    let (cos_r, cos_s) = (n.dot(wi), -s.normal.dot(wi));
    if cos_r <= 0.0 || cos_s <= 0.0 {
        return None;
    }
    let d2_disc = d2 as f64 + disc_radius2;
    Some(Link {
        wi,
        d,
        d2_disc,
        w: s.flux * (cos_r * cos_s) as f64 / (std::f64::consts::PI * d2_disc),
    })
}

/// The pairs of one receiver, on the side of its surface that receives more light (a
/// triangle's winding need not face the room), and that side's normal.
fn receiver_pairs(
    tracer: &Tracer,
    lit: &[LitSample],
    disc_radius2: f64,
    x: Vec3,
    n: Vec3,
    epsilon: f32,
) -> (Vec3, Vec<Pair>) {
    let side_weight = |n: Vec3| -> f64 {
        lit.iter()
            .filter_map(|s| link(x, n, s, 0.0, disc_radius2))
            .map(|l| l.w)
            .sum()
    };
    let n = if side_weight(-n) > side_weight(n) {
        -n
    } else {
        n
    };
    (n, pairs_at(tracer, lit, disc_radius2, x, n, epsilon))
}

/// The transfer pairs of a receiver at `x` with unit normal `n`.
fn pairs_at(
    tracer: &Tracer,
    lit: &[LitSample],
    disc_radius2: f64,
    x: Vec3,
    n: Vec3,
    epsilon: f32,
) -> Vec<Pair> {
    let origin = x + n * (4.0 * epsilon);
    lit.iter()
        .filter_map(|s| {
            let l = link(origin, n, s, 4.0 * epsilon, disc_radius2)?;
            Some(Pair {
                w: l.w,
                d2: l.d2_disc,
                visible: tracer.unoccluded(origin, l.wi, l.d * (1.0 - 1e-4)),
                tile: s.tile,
            })
        })
        .collect()
}

/// One-bounce radiance (grey) leaving `hit` toward `eye` from the lit samples it sees, through
/// its own BRDF: diffuse and glossy, so that curved and glossy surfaces vary as the image
/// does. Without an eye, the diffuse part toward the normal.
fn radiance_at(
    tracer: &Tracer,
    lit: &[LitSample],
    disc_radius2: f64,
    hit: &crate::trace::Hit,
    eye: Option<Vec3>,
) -> f64 {
    let n = hit.normal;
    let wo = eye.map_or(n, |e| (e - hit.position).normalize_or(n));
    let lift = 4.0 * tracer.epsilon;
    let origin = hit.position + n * lift;
    lit.iter()
        .filter_map(|s| {
            let l = link(origin, n, s, lift, disc_radius2)?;
            let f = grey(crate::shading::brdf(
                hit.rho_d, hit.rho_s, hit.k, n, l.wi, wo,
            ));
            (f > 0.0 && tracer.unoccluded(origin, l.wi, l.d * (1.0 - 1e-4))).then_some(f * l.w)
        })
        .sum()
}

/// The surface under `x` along −`n` within `reach` (plus a margin), its shading normal
/// turned to `n`'s side.
fn surface_below(tracer: &Tracer, x: Vec3, n: Vec3, reach: f32) -> Option<crate::trace::Hit> {
    let lift = reach.max(100.0 * tracer.epsilon);
    // Tilted off the axes: an axis-aligned ray starting on a box's slab plane can slip through
    // the BVH's slab test (0·∞).
    let down = (-n + Vec3::new(1.3e-4, 2.1e-4, 3.7e-4)).normalize();
    let mut hit = tracer.intersect(x + n * lift, down, 2.5 * lift)?;
    if hit.normal.dot(n) < 0.0 {
        hit.normal = -hit.normal;
    }
    Some(hit)
}

/// The fitted model (module docs; `src/vals/README.md`, "Budget mode", has the fit and its
/// residuals): predicted convergence FLIP = `a·(ε(h) + δ(h) + c_vals·ε(s) + c_off·o)^b`.
pub mod model {
    pub const A: f64 = 0.302;
    pub const B: f64 = 1.025;
    /// Weight of the VALs' interpolation error ε(s).
    pub const C_VALS: f64 = 8.0;
    /// Weight of the occluded share o when visibility is off.
    pub const C_OFF: f64 = 1.5;
    /// Weight of the partial share p with adaptive rays (`--visibility-rays adaptive`: a
    /// cluster tile whose 2×2 coarse strata agree is taken whole). Fitted as an upper
    /// envelope to the sweep's adaptive-minus-all convergence FLIP per scene (median over
    /// the grid; `valgi eval --sweep --frames 3`, 9 built-in scenes): ΔFLIP / (a·p) was 0.97
    /// on Cornell (p = 0.137, ΔFLIP 0.040), 0.99 on the bunny in it, 0.50 coarse-wall, 0.52
    /// glossy-row, 0.32 door room, 0.14 aligned occluders, 0.09 bunny box; the corridor and
    /// the thin wall (p ≤ 0.001) lost nothing.
    pub const C_PARTIAL: f64 = 1.0;
    /// Gather cost per point–VAL pair, ms, before [`gather_cost`]: lavapipe on a 2-core AMD
    /// EPYC (FMA peak 57 GFMA/s), with the visibility constants below, fitted to the frame
    /// times of `valgi eval --sweep --frames 3` over nine built-in scenes at 128² (the `off`,
    /// `rays-adaptive` and `rays-all` rows; relative least squares with a fixed part per
    /// scene; rms log error 0.23). The constants before, 9.3e-6 ms a pair and 1.88e-3 ms a
    /// point and cluster, had been fitted before the gather's uniform windows and its 16
    /// points per invocation made a pair 3.4× cheaper, and were 0.54 off.
    pub const GATHER_MS_PER_PAIR: f64 = 2.74e-6;
    /// The gather's cost per pair relative to [`GATHER_MS_PER_PAIR`], which was fitted when
    /// every gather ran the glossy lobes and the cluster-visibility lookup whatever the
    /// options. A gather is now compiled without the parts its solution does not use
    /// (`glossy auto` leaves the lobes out of an all-Lambert scene, occlusion other than
    /// `rays` the lookup). Lavapipe, 16k VALs × 4k points (`valgi bench`, the old gather
    /// 216–242 ms in the same session): with lobes and visibility 193–201 ms, lobes only
    /// 181–185, neither 114–121; visibility without lobes costs 0.66 of both (Cornell, 15k
    /// VALs × 4k points, 131–155 against 185–216 ms). Since then the compute gather sums the
    /// spheres' moments only for the disc occlusion and takes 16 points per invocation on a
    /// CPU device: the same bench gave 134 ms with lobes and visibility (196–203 before, in
    /// that session: 0.85 × 134/200), 117 lobes only (176 before), 45 neither (97 before), and
    /// visibility without lobes 1.3× neither (Cornell, 9.8k VALs × 4k points, 41 against
    /// 28–35 ms). A CPU device's 1024-point solutions take 8 points per invocation and gain
    /// less; the factors are for the 16.
    pub fn gather_cost(glossy: bool, rays: bool) -> f64 {
        match (glossy, rays) {
            (true, true) => 0.57,
            (true, false) => 0.53,
            (false, true) => 0.30,
            (false, false) => 0.23,
        }
    }
    /// Visibility cost per point and cluster (16 rays), ms, and its fixed part (the same fit).
    pub const VISIBILITY_MS_PER_POINT_CLUSTER: f64 = 2.35e-3;
    pub const VISIBILITY_MS_FIXED: f64 = 18.7;
    /// The share of that per-point cost adaptive rays keep: the same sweep's visibility time
    /// (frame with rays less the frame without) with adaptive rays over all strata, median
    /// over the grid per scene, was 0.61–0.62 on five scenes, 0.67 bunny box, 0.74 door room,
    /// 0.89–0.92 on the aligned occluders and the coarse wall (whose tiles are more often
    /// split).
    pub const ADAPTIVE_RAY_COST: f64 = 0.7;
    /// The summed disc occlusion's cost over no occlusion, per pair of points and per
    /// point, ms: each point walks the other points' discs, and the gather sums the spheres'
    /// moments. Fitted to the median over nine built-in scenes of the `sum` row's frame less
    /// the `off` row's of the same setting (`valgi eval --sweep --frames 3`, 128², the same
    /// machine): 6–10 ms at 1024 points, 24, 78–79, 244–252 and 828–862 ms at 16384
    /// (this gives 11, 28, 78, 243, 831).
    pub const DISC_MS_PER_POINT_PAIR: f64 = 2.58e-6;
    pub const DISC_MS_PER_POINT: f64 = 8.5e-3;
    /// The rest of a frame (shadow maps, RSM, G-buffer, direct, interpolation, apply) at
    /// 128², ms: the same for every choice, so it only shifts the budget. The fit's fixed
    /// part per scene ran from 14 ms (Cornell) to 195 ms (glossy-row), median 66.
    pub const FRAME_MS_FIXED: f64 = 60.0;
    /// The pixels a frame of the fit shaded: one view of 128², no supersampling.
    pub const FIT_PIXELS: f64 = 128.0 * 128.0;
    /// What each further pixel a frame shades adds to [`FRAME_MS_FIXED`], ms: the G-buffer,
    /// direct light, apply and resolve run per pixel of every view. `valgi render --method
    /// sparse --sparse-points 1024 --rsm 32 --occlusion off --frames 3 --no-write` at 128²,
    /// 512² and 1280×720 (lavapipe, 2-core AMD EPYC; the faster of frames 2–3): Cornell 11.1,
    /// 47.0 and 120.2 ms, 1.46e-4 and 1.21e-4 ms a pixel over the 128² frame; the door room
    /// 125.5, 175.0 and 273.0 ms, 2.0e-4 and 1.63e-4. Before this term a time budget's
    /// survey priced a 1280×720 frame's fixed part at the 128² figure, and those frames
    /// overspent it by 1.15–1.88× (`budget-pilots=0`).
    pub const FRAME_MS_PER_PIXEL: f64 = 1.5e-4;
    /// The FMA peak (`gpu::peak::fma_peak`, the kernel with its body written out eight
    /// times) of the device the times above were fitted on, FMA/s: 56.5–56.9 GFMA/s on the
    /// fit's machine. On another device the times are scaled by this over that device's
    /// peak ([`Survey::time_scale`]).
    pub const FIT_FMA_PEAK: f64 = 57e9;
}

/// The point counts and RSM sides budget mode chooses among: the range the model was fitted
/// over (the sweep's 1024–16384 points and 32–128 texels), in steps of √2 and 1.5. Outside
/// it the measured error left the prediction by up to 3× (256 points on the Cornell box:
/// predicted 0.098, measured 0.159).
pub const CANDIDATE_POINTS: [usize; 9] = [1024, 1448, 2048, 2896, 4096, 5793, 8192, 11585, 16384];
pub const CANDIDATE_RSM: [u32; 5] = [32, 48, 64, 96, 128];

/// The indirect occlusion a candidate runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Visibility {
    /// No indirect occlusion (`--occlusion off`).
    Off,
    /// Shadow rays to every sample stratum of each cluster (`--occlusion rays`).
    Rays,
    /// The 2×2 coarse strata first, the rest where they disagree (`--occlusion rays
    /// --visibility-rays adaptive`).
    AdaptiveRays,
    /// The paper's disc occlusion, summed over the occluders (`--occlusion sum`). It never
    /// converges (it occludes twice behind aligned occluders) and the survey has no term for
    /// that, so only the pilots choose it ([`Survey::search`]), never the survey alone.
    Sum,
}

impl Visibility {
    pub const ALL: [Visibility; 4] = [
        Visibility::Off,
        Visibility::Rays,
        Visibility::AdaptiveRays,
        Visibility::Sum,
    ];

    /// Whether it shoots shadow rays.
    pub fn rays(self) -> bool {
        matches!(self, Visibility::Rays | Visibility::AdaptiveRays)
    }

    /// Which occlusion it is, for the pilots' scales ([`pilot_scale`]): none, discs, rays
    /// (to every stratum or adaptive).
    pub fn occlusion(self) -> OcclusionKind {
        match self {
            Visibility::Off => OcclusionKind::None,
            Visibility::Sum => OcclusionKind::Discs,
            Visibility::Rays | Visibility::AdaptiveRays => OcclusionKind::Rays,
        }
    }

    /// Order by how close to converged a candidate's visibility is: off, summed discs,
    /// adaptive rays, rays to every stratum.
    pub fn richness(self) -> u32 {
        match self {
            Visibility::Off => 0,
            Visibility::Sum => 1,
            Visibility::AdaptiveRays => 2,
            Visibility::Rays => 3,
        }
    }
}

/// The kinds of occlusion whose errors the survey misjudges each in its own way, so that the
/// pilots scale each kind apart ([`pilot_scale`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OcclusionKind {
    None,
    Discs,
    Rays,
}

/// What budget mode aims at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BudgetTarget {
    /// The cheapest setting whose predicted convergence FLIP is at most this.
    Flip(f64),
    /// The lowest predicted convergence FLIP whose predicted frame time is at most this many
    /// milliseconds (the fitted times scaled to the device by [`Survey::time_scale`]).
    Ms(f64),
}

/// One candidate setting with its predictions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BudgetChoice {
    pub points: usize,
    pub rsm: u32,
    pub visibility: Visibility,
    pub predicted_flip: f64,
    pub predicted_ms: f64,
    /// The error terms behind the prediction: ε(h) + δ(h) of the points, ε(s) of the VALs,
    /// and the occluded share o.
    pub variation: f64,
    pub val_error: f64,
    pub occluded_share: f64,
    /// False when no candidate meets the target (the choice is then the closest one).
    pub met: bool,
}

impl BudgetChoice {
    /// Whether `other` is the same setting (points, RSM side, visibility), whatever its
    /// predictions.
    pub fn same_setting(&self, other: &BudgetChoice) -> bool {
        (self.points, self.rsm, self.visibility) == (other.points, other.rsm, other.visibility)
    }

    /// Orders candidates by how close to converged they are: points, then RSM side, then
    /// visibility ([`Visibility::richness`]); the greatest is the pilots' converged image.
    pub fn richness(&self) -> (usize, u32, u32) {
        (self.points, self.rsm, self.visibility.richness())
    }
}

impl Survey {
    /// The survey pricing frames that shade `pixels` pixels (width × height × SSAA² × views).
    pub fn shading(mut self, pixels: f64) -> Self {
        if pixels.is_finite() && pixels > 0.0 {
            self.frame_pixels = pixels;
        }
        self
    }

    /// The part of every candidate's predicted frame time that no knob changes
    /// ([`model::FRAME_MS_FIXED`] at the fit's 128², and [`model::FRAME_MS_PER_PIXEL`] for
    /// every pixel more or fewer, on this device).
    pub fn predicted_fixed_ms(&self) -> f64 {
        let per_pixel = model::FRAME_MS_PER_PIXEL * (self.frame_pixels - model::FIT_PIXELS);
        self.time_scale * (model::FRAME_MS_FIXED + per_pixel).max(0.0)
    }

    /// Predicts a candidate's convergence FLIP and frame time.
    pub fn predict(&self, points: usize, rsm: u32, visibility: Visibility) -> BudgetChoice {
        let h = self.point_spacing(points);
        let variation = self.interpolation_error(h) + self.variation_error(h);
        let val_error = self.interpolation_error(self.val_spacing(rsm));
        let (visibility_error, ray_cost) = match visibility {
            // The survey has no term for the discs' double occlusion: `sum` is priced as
            // none, and its own pilots' scale corrects that.
            Visibility::Off | Visibility::Sum => (model::C_OFF * self.occluded_share, 0.0),
            Visibility::Rays => (0.0, 1.0),
            Visibility::AdaptiveRays => (
                model::C_PARTIAL * self.partial_share,
                model::ADAPTIVE_RAY_COST,
            ),
        };
        let rays = visibility.rays();
        let error = variation + model::C_VALS * val_error + visibility_error;
        let predicted_flip = model::A * error.max(0.0).powf(model::B);
        let pairs = points as f64 * self.val_count(rsm);
        let predicted_ms = self.predicted_fixed_ms()
            + self.time_scale
                * (model::GATHER_MS_PER_PAIR
                    * model::gather_cost(self.gathers_glossy, rays)
                    * pairs
                    + if rays {
                        model::VISIBILITY_MS_FIXED
                            + model::VISIBILITY_MS_PER_POINT_CLUSTER
                                * ray_cost
                                * points as f64
                                * self.clusters as f64
                    } else {
                        0.0
                    }
                    + if visibility == Visibility::Sum {
                        model::DISC_MS_PER_POINT_PAIR * (points as f64).powi(2)
                            + model::DISC_MS_PER_POINT * points as f64
                    } else {
                        0.0
                    });
        BudgetChoice {
            points,
            rsm,
            visibility,
            predicted_flip,
            predicted_ms,
            variation,
            val_error,
            occluded_share: self.occluded_share,
            met: true,
        }
    }

    /// The setting budget mode picks for `target` among the candidates (module docs).
    pub fn choose(&self, target: BudgetTarget) -> BudgetChoice {
        // `sum`'s prediction is a placeholder that only pilots correct.
        let all = self.candidates(|_, _, visibility| visibility != Visibility::Sum);
        let by_ms =
            |a: &&BudgetChoice, b: &&BudgetChoice| a.predicted_ms.total_cmp(&b.predicted_ms);
        let by_flip =
            |a: &&BudgetChoice, b: &&BudgetChoice| a.predicted_flip.total_cmp(&b.predicted_flip);
        let pick = match target {
            BudgetTarget::Flip(flip) => all
                .iter()
                .filter(|c| c.predicted_flip <= flip)
                .min_by(by_ms)
                .copied(),
            BudgetTarget::Ms(ms) => all
                .iter()
                .filter(|c| c.predicted_ms <= ms)
                .min_by(by_flip)
                .copied(),
        };
        pick.unwrap_or_else(|| {
            // Nothing meets the target: the most accurate (for an error target) or the
            // cheapest (for a time budget) candidate, marked as missing it.
            let closest = match target {
                BudgetTarget::Flip(_) => all.iter().min_by(by_flip),
                BudgetTarget::Ms(_) => all.iter().min_by(by_ms),
            };
            BudgetChoice {
                met: false,
                ..*closest.expect("candidates are never empty")
            }
        })
    }
}

/// Most pilot frames [`Survey::search`] renders after the converged one (`budget-pilots`'s
/// default). Replaying the search on seven `valgi eval --sweep` grids (nine scenes, two
/// targets each, the candidates restricted to the grid) with `sum` among the candidates, it
/// rendered 4.3 on average, and the choice came within 1.25× of the cheapest grid setting
/// meeting the target in 15–18 of 18 cases; with at most 6 pilots 13–16, since trying `sum`
/// takes one; without `sum`, 14–17 with 6 or 8. The survey's prediction alone managed 5–6.
/// In the harness itself, over all candidates: `src/vals/README.md`, "Budget mode".
/// Weighting each pilot's correction by its closeness to the candidate (in log₂ points, log₂
/// RSM side and visibility) did no better.
pub const DEFAULT_PILOTS: usize = 8;

/// How far above the target a candidate's scaled prediction may lie and still be measured
/// when none is predicted to meet it ([`Survey::search`]): e^0.35, the spread left in the
/// prediction once scaled, the standard deviation of ln(measured / predicted FLIP) about
/// each scene's mean, per occlusion (0.35 over the nine built-in scenes of a `valgi eval
/// --sweep` grid, 0.31 over its rows near the targets). Without it a prediction scaled a few
/// per cent too high ended the search at the converged setting: on the bunny box one pilot
/// measured 1.52× its prediction, and the 11 585- and 8192-point candidates that met 0.05
/// (0.040, 0.046) were predicted at 0.051 and 0.055.
pub const PROBE_SPREAD: f64 = 1.42;

/// How far above the target the scaled prediction of a candidate whose kind of occlusion (rays,
/// `off`, `sum`) no pilot has measured yet may lie and still be measured, once a pilot has
/// measured another ([`Survey::search`]). Its prediction is scaled by all pilots so far,
/// and the two scales can be far apart: over the nine built-in scenes of a `valgi eval
/// --sweep` grid the median of measured over predicted FLIP without occlusion was 0.31× (the
/// bunny box, whose floating bunny blocks less than the survey's occluded share says) to
/// 3.06× (the thin wall) the same median with rays. Without this the bunny box at 0.10 never
/// measured an `off` candidate and chose 1448 points with rays, 2.6× the time of 4096 points
/// without occlusion, which met the target.
pub const UNMEASURED_SPREAD: f64 = 3.0;

/// One pilot frame: a candidate and its measured convergence FLIP.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pilot {
    pub choice: BudgetChoice,
    pub measured_flip: f64,
}

/// What [`Survey::search`] chose and the pilots it measured on the way.
#[derive(Clone, Debug, PartialEq)]
pub struct PilotSearch {
    /// The cheapest candidate measured within the target of the converged one, or the
    /// converged one; `met` says whether the converged candidate is itself predicted within
    /// the target (`converged_flip`), without which no measurement against it meets it.
    pub choice: BudgetChoice,
    /// Its measured FLIP against the converged candidate (0 for that candidate itself).
    pub measured_flip: f64,
    /// The converged candidate's own predicted convergence FLIP, scaled by the pilots: how far
    /// the image the pilots are measured against is from convergence.
    pub converged_flip: f64,
    /// Every pilot after the converged one, in the order rendered.
    pub pilots: Vec<Pilot>,
}

impl Survey {
    /// Every candidate setting whose knobs `keep` allows, with its predictions.
    pub fn candidates(&self, keep: impl Fn(usize, u32, Visibility) -> bool) -> Vec<BudgetChoice> {
        let mut all = vec![];
        for &points in &CANDIDATE_POINTS {
            for &rsm in &CANDIDATE_RSM {
                for visibility in Visibility::ALL {
                    if keep(points, rsm, visibility) {
                        all.push(self.predict(points, rsm, visibility));
                    }
                }
            }
        }
        all
    }

    /// The pilot search for a FLIP target (module docs). `converged` is the candidate the
    /// pilots are measured against (the richest); `measure` renders a candidate and returns
    /// its convergence FLIP, NaN for one that could not be rendered (never chosen, and left
    /// out of [`pilot_scale`]). At most `max_pilots` candidates are measured.
    pub fn search<E>(
        candidates: &[BudgetChoice],
        converged: &BudgetChoice,
        target_flip: f64,
        max_pilots: usize,
        mut measure: impl FnMut(&BudgetChoice) -> Result<f64, E>,
    ) -> Result<PilotSearch, E> {
        let same = BudgetChoice::same_setting;
        let mut pilots: Vec<Pilot> = vec![];
        let mut best = (*converged, 0.0);
        for _ in 0..max_pilots {
            let scaled = |c: &BudgetChoice| c.predicted_flip * pilot_scale(&pilots, c.visibility);
            let untried: Vec<&BudgetChoice> = candidates
                .iter()
                .filter(|c| !same(c, converged) && !pilots.iter().any(|p| same(&p.choice, c)))
                .filter(|c| c.predicted_ms < best.0.predicted_ms)
                .collect();
            let most_accurate = |keep: &dyn Fn(&BudgetChoice) -> bool, spread: f64| {
                untried
                    .iter()
                    .copied()
                    .filter(|c| keep(c))
                    .min_by(|a, b| scaled(a).total_cmp(&scaled(b)))
                    .filter(|c| scaled(c) <= target_flip * spread)
            };
            // Once a pilot has measured one kind of occlusion, the most accurate candidate of a
            // kind not measured yet, while it may still meet the target; then the cheapest
            // predicted to meet it;
            // failing that, the most accurate while it may still meet it.
            let other_occlusion = if pilots.iter().any(|p| p.measured_flip.is_finite()) {
                most_accurate(
                    &|c| !occlusion_measured(&pilots, c.visibility),
                    UNMEASURED_SPREAD,
                )
            } else {
                None
            };
            let next = other_occlusion
                .or_else(|| {
                    untried
                        .iter()
                        .filter(|c| scaled(c) <= target_flip)
                        .min_by(|a, b| a.predicted_ms.total_cmp(&b.predicted_ms))
                        .copied()
                })
                .or_else(|| most_accurate(&|_| true, PROBE_SPREAD));
            let Some(next) = next else { break };
            let measured_flip = measure(next)?;
            pilots.push(Pilot {
                choice: *next,
                measured_flip,
            });
            if measured_flip <= target_flip {
                best = (*next, measured_flip);
            }
        }
        // A pilot within the target of a converged image that is not converged has not met
        // it: the richest candidate of a scene the knobs cannot converge is its own limit.
        let converged_flip = converged.predicted_flip * pilot_scale(&pilots, converged.visibility);
        Ok(PilotSearch {
            choice: BudgetChoice {
                // `best` is the converged candidate (0 against itself) or a pilot measured
                // within the target: whether the converged candidate is decides.
                met: converged_flip <= target_flip,
                ..best.0
            },
            measured_flip: best.1,
            converged_flip,
            pilots,
        })
    }
}

/// What [`Survey::search_within`] chose and the pilots it measured.
#[derive(Clone, Debug, PartialEq)]
pub struct WithinSearch {
    /// The candidate measured most accurate (lowest convergence FLIP against the converged
    /// candidate), `None` when no pilot measured one.
    pub choice: Option<Pilot>,
    /// Every pilot, in the order rendered.
    pub pilots: Vec<Pilot>,
}

impl Survey {
    /// Under a time budget, the most accurate of the candidates `within` it, by measurement:
    /// the survey ranks candidates of one kind of occlusion well but misjudges the kinds
    /// against each other (on the bunny box settings without occlusion are more accurate than
    /// it predicts, 0.075 against 0.087 with rays at 400 ms at 128²). So pilots measure, each
    /// time, the candidate the scaled predictions ([`pilot_scale`]) rank most accurate among
    /// those not measured: first the best of a kind of occlusion no pilot has measured (while
    /// its scaled prediction is within [`UNMEASURED_SPREAD`] of the best measured), then the
    /// best of any kind while its scaled prediction beats the best measured. `measure` gives
    /// a candidate's convergence FLIP against `converged` (NaN for one that failed).
    pub fn search_within<E>(
        within: &[BudgetChoice],
        converged: &BudgetChoice,
        max_pilots: usize,
        mut measure: impl FnMut(&BudgetChoice) -> Result<f64, E>,
    ) -> Result<WithinSearch, E> {
        let same = BudgetChoice::same_setting;
        let mut pilots: Vec<Pilot> = vec![];
        let best = |pilots: &[Pilot]| {
            pilots
                .iter()
                .filter(|p| p.measured_flip.is_finite())
                .min_by(|a, b| a.measured_flip.total_cmp(&b.measured_flip))
                .copied()
        };
        for _ in 0..max_pilots {
            let scaled = |c: &BudgetChoice| c.predicted_flip * pilot_scale(&pilots, c.visibility);
            let untried: Vec<&BudgetChoice> = within
                .iter()
                .filter(|c| !same(c, converged) && !pilots.iter().any(|p| same(&p.choice, c)))
                .collect();
            let most_accurate = |keep: &dyn Fn(&BudgetChoice) -> bool| {
                untried
                    .iter()
                    .copied()
                    .filter(|c| keep(c))
                    .min_by(|a, b| scaled(a).total_cmp(&scaled(b)))
            };
            let bar = best(&pilots).map(|p| p.measured_flip);
            let next = most_accurate(&|c| !occlusion_measured(&pilots, c.visibility))
                .filter(|c| bar.is_none_or(|b| scaled(c) <= b * UNMEASURED_SPREAD))
                .or_else(|| most_accurate(&|_| true).filter(|c| bar.is_none_or(|b| scaled(c) < b)));
            let Some(next) = next else { break };
            let measured_flip = measure(next)?;
            pilots.push(Pilot {
                choice: *next,
                measured_flip,
            });
        }
        Ok(WithinSearch {
            choice: best(&pilots),
            pilots,
        })
    }
}

/// How far the survey's predictions are off in this scene for a candidate with `visibility`,
/// by the pilots: the geometric mean of measured over predicted FLIP over the pilots of the
/// same kind of occlusion ([`Visibility::occlusion`]: rays, all strata or adaptive; `off`;
/// summed discs), over all pilots while none of that kind has been measured, and 1 without a
/// measured pilot. The survey's error is mostly a scale
/// per scene (its median prediction over the measurement ran from 0.64 to 1.78 by scene),
/// which one pilot already corrects; but an `off` candidate's prediction carries the
/// survey's occluded share, whose error is its own: the door room's pilots measured the survey
/// 2× pessimistic with rays and 1.0–1.35× optimistic without occlusion, the corridor's 0.43×
/// and 2.6×, and one scale for both sent half their pilots to `off` settings that missed.
/// `sum`'s prediction is `off`'s, which its own scale turns into its double occlusion.
pub fn pilot_scale(pilots: &[Pilot], visibility: Visibility) -> f64 {
    if occlusion_measured(pilots, visibility) {
        geometric_mean_error(
            pilots
                .iter()
                .filter(|p| p.choice.visibility.occlusion() == visibility.occlusion()),
        )
    } else {
        geometric_mean_error(pilots.iter())
    }
}

/// Whether a pilot with the kind of occlusion of `visibility` has been measured.
fn occlusion_measured(pilots: &[Pilot], visibility: Visibility) -> bool {
    pilots.iter().any(|p| {
        p.choice.visibility.occlusion() == visibility.occlusion() && p.measured_flip.is_finite()
    })
}

/// The geometric mean of the pilots' measured over predicted FLIP (1 without a measured one).
fn geometric_mean_error<'a>(pilots: impl Iterator<Item = &'a Pilot>) -> f64 {
    // Below this a measured FLIP is read as this: a pilot identical to the converged image
    // would otherwise scale every prediction to zero.
    const FLOOR: f64 = 1e-4;
    let logs: Vec<f64> = pilots
        .filter(|p| p.measured_flip.is_finite())
        .map(|p| (p.measured_flip.max(FLOOR) / p.choice.predicted_flip.max(FLOOR)).ln())
        .collect();
    if logs.is_empty() {
        return 1.0;
    }
    (logs.iter().sum::<f64>() / logs.len() as f64).exp()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The survey of a built-in scene from its own camera (also the timing search's tests').
    pub(super) fn survey_of(name: &str) -> Survey {
        let scene = crate::scene::load_with(name, &crate::scene::LoadParams::default())
            .expect("built-in scene");
        let world = scene.world_from_node_at(0.0);
        let camera = scene.camera_view(None, 1.0, &world).expect("camera");
        Survey::new(&scene, &world, Some(&camera), 1)
    }

    /// The per-pixel passes are priced by the pixels a frame shades: a 1280×720 frame's
    /// fixed part is the 128² fit's plus every further pixel's cost, the same for every
    /// candidate, so that under a time budget the survey alone picks a cheaper candidate for
    /// the larger frame, one whose whole predicted frame fits.
    #[test]
    fn a_larger_frame_prices_its_pixels_and_fits_a_cheaper_candidate_in_the_budget() {
        let small = survey_of("cornell");
        assert_eq!(small.frame_pixels, model::FIT_PIXELS);
        assert_eq!(small.predicted_fixed_ms(), model::FRAME_MS_FIXED);
        let pixels = 1280.0 * 720.0;
        let large = small.clone().shading(pixels);
        let extra = model::FRAME_MS_PER_PIXEL * (pixels - model::FIT_PIXELS);
        assert!((large.predicted_fixed_ms() - (model::FRAME_MS_FIXED + extra)).abs() < 1e-9);
        for (points, rsm, visibility) in
            [(1024, 32, Visibility::Off), (8192, 128, Visibility::Rays)]
        {
            let (a, b) = (
                small.predict(points, rsm, visibility),
                large.predict(points, rsm, visibility),
            );
            assert!((b.predicted_ms - a.predicted_ms - extra).abs() < 1e-6);
            assert_eq!(a.predicted_flip, b.predicted_flip);
        }
        // A nonsense pixel count leaves the fit's.
        assert_eq!(
            small.clone().shading(f64::NAN).frame_pixels,
            model::FIT_PIXELS
        );
        let budget = BudgetTarget::Ms(model::FRAME_MS_FIXED + extra + 100.0);
        let (at_small, at_large) = (small.choose(budget), large.choose(budget));
        assert!(at_large.met && at_large.predicted_ms <= model::FRAME_MS_FIXED + extra + 100.0);
        assert!(
            at_small.predicted_ms - small.predicted_fixed_ms()
                > at_large.predicted_ms - large.predicted_fixed_ms(),
            "{at_small:?} against {at_large:?}"
        );
    }

    #[test]
    fn a_spot_over_a_plane_lights_the_disc_its_outer_cone_cuts() {
        // plane-spot: outer cone 35°, 1 m above a 4 m plane. The lit disc has radius tan 35°
        // and fills π/4 of the RSM's square view.
        let survey = survey_of("plane-spot");
        let radius = 35f64.to_radians().tan();
        let disc = std::f64::consts::PI * radius * radius;
        assert!(
            (survey.lit_area / disc - 1.0).abs() < 0.02,
            "lit area {} vs {disc}",
            survey.lit_area
        );
        assert!(
            (survey.lit_views - std::f64::consts::FRAC_PI_4).abs() < 0.02,
            "{}",
            survey.lit_views
        );
        assert!((survey.area - 16.0).abs() < 1e-3, "{}", survey.area);
        assert!((survey.val_count(64) - 64.0 * 64.0 * survey.lit_views).abs() < 1e-9);
    }

    #[test]
    fn a_convex_room_needs_no_occlusion_and_a_room_behind_a_door_needs_rays() {
        // Nothing stands between any two points of a convex box's inner walls.
        let empty = survey_of("bunny-box-empty");
        assert!(empty.occluded_share < 1e-3, "{}", empty.occluded_share);
        assert!(empty.partial_share < 1e-3, "{}", empty.partial_share);
        assert_eq!(
            empty.choose(BudgetTarget::Flip(0.05)).visibility,
            Visibility::Off
        );
        // The door room's light arrives through a doorway: much of it is blocked.
        let door = survey_of("door-room");
        assert!(door.occluded_share > 0.05, "{}", door.occluded_share);
        let choice = door.choose(BudgetTarget::Flip(0.05));
        assert!(choice.visibility.rays() && choice.met, "{choice:?}");
        assert!(choice.predicted_flip <= 0.05);
    }

    #[test]
    fn adaptive_rays_are_taken_where_cluster_tiles_are_seen_whole() {
        // The thin wall's light is either all behind the wall or all in front of it: a tile's
        // coarse strata settle it, and adaptive rays cost less for the same error.
        let thin = survey_of("thin-wall");
        assert!(thin.partial_share < 1e-3, "{}", thin.partial_share);
        let choice = thin.choose(BudgetTarget::Flip(0.05));
        assert_eq!(choice.visibility, Visibility::AdaptiveRays, "{choice:?}");
        let all = thin.predict(choice.points, choice.rsm, Visibility::Rays);
        assert!(all.predicted_ms > choice.predicted_ms);
        assert!((all.predicted_flip - choice.predicted_flip).abs() < 1e-3);
        // In the Cornell box the tall block splits many tiles seen from the floor: there,
        // settling tiles whole costs more error than the rays it saves.
        let cornell = survey_of("cornell");
        assert!(cornell.partial_share > 0.05, "{}", cornell.partial_share);
        let choice = cornell.choose(BudgetTarget::Flip(0.05));
        assert_eq!(choice.visibility, Visibility::Rays, "{choice:?}");
        let adaptive = cornell.predict(choice.points, choice.rsm, Visibility::AdaptiveRays);
        assert!(adaptive.predicted_flip > 0.05, "{adaptive:?}");
    }

    #[test]
    fn the_interpolation_error_is_quadratic_in_the_spacing_below_every_distance() {
        // Every pair's distance is at least the sample disc's radius, so at spacings far below
        // it min(1, h²/d²) = h²/d² throughout and halving h quarters ε.
        let survey = survey_of("cornell");
        let (e1, e2) = (
            survey.interpolation_error(1e-4),
            survey.interpolation_error(5e-5),
        );
        assert!(e1 > 0.0);
        assert!((e1 / e2 - 4.0).abs() < 1e-6, "{e1} / {e2}");
        // And it saturates at 1 when the spacing exceeds every distance.
        assert!((survey.interpolation_error(1e6) - 1.0).abs() < 1e-9);
    }

    #[test]
    fn radiance_varies_more_over_longer_distances_and_tighter_targets_cost_more() {
        let survey = survey_of("cornell");
        let v = &survey.variation;
        assert_eq!(v.len(), PROBE_POINTS.len());
        for pair in v.windows(2) {
            assert!(pair[0].0 < pair[1].0, "spacings ascend: {v:?}");
            assert!(pair[0].1 <= pair[1].1 * 1.05, "δ grows with h: {v:?}");
        }
        assert!(v[0].1 > 0.0);
        let loose = survey.choose(BudgetTarget::Flip(0.1));
        let tight = survey.choose(BudgetTarget::Flip(0.03));
        assert!(loose.met && tight.met, "{loose:?} {tight:?}");
        assert!(tight.predicted_ms >= loose.predicted_ms);
        assert!(tight.predicted_flip <= 0.03 && loose.predicted_flip <= 0.1);
        // A time budget gets the most accurate setting that fits it.
        let budget = survey.choose(BudgetTarget::Ms(tight.predicted_ms));
        assert!(budget.predicted_ms <= tight.predicted_ms);
        assert!(budget.predicted_flip <= tight.predicted_flip);
        // An impossible target is marked, with the most accurate candidate.
        let impossible = survey.choose(BudgetTarget::Flip(1e-9));
        assert!(!impossible.met);
    }

    #[test]
    fn a_faster_device_affords_the_setting_a_proportionally_larger_budget_buys() {
        let mut survey = survey_of("cornell");
        let slow = survey.choose(BudgetTarget::Ms(300.0));
        assert!(slow.met, "{slow:?}");
        survey.time_scale = 0.01;
        // Every prediction is a hundredth: 3 ms now buys what 300 ms bought.
        let fast = survey.choose(BudgetTarget::Ms(3.0));
        assert_eq!(
            (fast.points, fast.rsm, fast.visibility),
            (slow.points, slow.rsm, slow.visibility)
        );
        assert!((fast.predicted_ms - slow.predicted_ms * 0.01).abs() < 1e-9 * slow.predicted_ms);
        // And 300 ms buys at least as accurate a setting as before.
        let rich = survey.choose(BudgetTarget::Ms(300.0));
        assert!(rich.predicted_flip <= slow.predicted_flip);
        // A FLIP target's choice does not depend on the device: the same setting, cheaper.
        let at_scale = survey.choose(BudgetTarget::Flip(0.05));
        survey.time_scale = 1.0;
        let at_one = survey.choose(BudgetTarget::Flip(0.05));
        assert_eq!(
            (at_scale.points, at_scale.rsm, at_scale.visibility),
            (at_one.points, at_one.rsm, at_one.visibility)
        );
    }

    /// The pilot search against a scene whose true convergence FLIP is `truth`.
    fn search_against(
        survey: &Survey,
        target: f64,
        truth: impl Fn(&BudgetChoice) -> f64,
    ) -> (PilotSearch, Vec<BudgetChoice>, BudgetChoice) {
        let candidates = survey.candidates(|_, _, _| true);
        let converged = *candidates
            .iter()
            .find(|c| {
                (c.points, c.rsm, c.visibility)
                    == (
                        *CANDIDATE_POINTS.last().unwrap(),
                        *CANDIDATE_RSM.last().unwrap(),
                        Visibility::Rays,
                    )
            })
            .expect("the richest candidate");
        let search = Survey::search(&candidates, &converged, target, DEFAULT_PILOTS, |c| {
            Ok::<_, ()>(truth(c))
        })
        .unwrap();
        (search, candidates, converged)
    }

    #[test]
    fn pilots_find_the_cheapest_setting_a_model_off_by_a_scale_misjudges() {
        let survey = survey_of("cornell");
        for scale in [0.5, 2.0] {
            let truth = |c: &BudgetChoice| scale * c.predicted_flip;
            let (search, candidates, converged) = search_against(&survey, 0.05, truth);
            let same = BudgetChoice::same_setting;
            // The cheapest candidate that truly meets the target.
            let cheapest = candidates
                .iter()
                .filter(|c| !same(c, &converged) && truth(c) <= 0.05)
                .min_by(|a, b| a.predicted_ms.total_cmp(&b.predicted_ms))
                .expect("some candidate meets 0.05");
            assert!(same(&search.choice, cheapest), "scale {scale}: {search:?}");
            assert!(search.choice.met && search.measured_flip <= 0.05);
            // The survey alone takes another setting: the pilots are what found it.
            let unmeasured = survey.choose(BudgetTarget::Flip(0.05));
            assert!(!same(&unmeasured, cheapest), "scale {scale}");
            // Few pilots, none measured twice, the converged one never among them.
            assert!(!search.pilots.is_empty() && search.pilots.len() <= DEFAULT_PILOTS);
            for (i, p) in search.pilots.iter().enumerate() {
                assert!(!same(&p.choice, &converged));
                assert!(search.pilots[..i]
                    .iter()
                    .all(|q| !same(&q.choice, &p.choice)));
            }
        }
    }

    /// The survey's occluded share is wrong on its own: the truth scales candidates without
    /// occlusion by another factor than those with rays (the corridor's pilots measured 2.6×
    /// and 0.43×). The search still finds the cheapest setting that truly meets the target.
    #[test]
    fn pilots_scale_settings_without_occlusion_apart_from_those_with_rays() {
        for (name, target) in [("cornell", 0.05), ("door-room", 0.05), ("corridor", 0.05)] {
            let survey = survey_of(name);
            for (rays, off) in [(0.45, 2.6), (0.5, 1.2), (1.1, 1.6)] {
                let truth = |c: &BudgetChoice| {
                    c.predicted_flip * if c.visibility.rays() { rays } else { off }
                };
                let (search, candidates, converged) = search_against(&survey, target, truth);
                let same = BudgetChoice::same_setting;
                let cheapest = candidates
                    .iter()
                    .filter(|c| !same(c, &converged) && truth(c) <= target)
                    .min_by(|a, b| a.predicted_ms.total_cmp(&b.predicted_ms))
                    .expect("some candidate meets the target");
                assert!(
                    same(&search.choice, cheapest),
                    "{name}, rays {rays}, off {off}: chose {:?}, cheapest {cheapest:?}, pilots {:?}",
                    search.choice,
                    search.pilots
                );
            }
        }
    }

    /// A candidate with the predictions given and no survey behind them.
    fn synthetic(
        points: usize,
        visibility: Visibility,
        predicted_flip: f64,
        predicted_ms: f64,
    ) -> BudgetChoice {
        BudgetChoice {
            points,
            rsm: 64,
            visibility,
            predicted_flip,
            predicted_ms,
            variation: 0.0,
            val_error: 0.0,
            occluded_share: 0.0,
            met: true,
        }
    }

    /// [`synthetic`] with rays to every stratum.
    fn with_rays(points: usize, predicted_flip: f64, predicted_ms: f64) -> BudgetChoice {
        synthetic(points, Visibility::Rays, predicted_flip, predicted_ms)
    }

    /// When the scaled predictions leave no candidate meeting the target, the most accurate
    /// one is measured while its prediction is within [`PROBE_SPREAD`] of the target, and
    /// not beyond.
    #[test]
    fn a_candidate_predicted_just_short_of_the_target_is_still_measured() {
        let candidate = with_rays;
        let converged = candidate(16384, 0.01, 1000.0);
        let cheap = candidate(1024, 0.05, 100.0);
        let near = candidate(4096, 0.034, 300.0);
        let far = candidate(8192, 0.049, 200.0);
        // The cheap one measures 1.5× its prediction; the near one, scaled to 0.051, meets
        // 0.05 in truth; the far one, scaled to 0.0735, is never measured.
        let truth = |c: &BudgetChoice| match c.points {
            1024 => 0.075,
            4096 => 0.045,
            _ => 0.03,
        };
        let search = Survey::search(&[cheap, near, converged], &converged, 0.05, 6, |c| {
            Ok::<_, ()>(truth(c))
        })
        .unwrap();
        assert_eq!(search.choice.points, 4096, "{search:?}");
        assert_eq!(search.measured_flip, 0.045);
        assert_eq!(search.pilots.len(), 2);
        let search = Survey::search(&[cheap, far, converged], &converged, 0.05, 6, |c| {
            Ok::<_, ()>(truth(c))
        })
        .unwrap();
        assert_eq!(search.choice.points, 16384, "{search:?}");
        assert_eq!(search.pilots.len(), 1);
    }

    /// After the first pilot, the other occlusion's most accurate candidate is measured while
    /// the widest gap seen between the two occlusions' scales could still let it meet the
    /// target; its own scale then leads to its cheapest setting.
    #[test]
    fn the_occlusion_no_pilot_measured_is_tried_once_the_other_is() {
        let candidate = synthetic;
        let converged = candidate(16384, Visibility::Rays, 0.01, 1000.0);
        let rays = candidate(1024, Visibility::Rays, 0.09, 300.0);
        let off_cheap = candidate(4096, Visibility::Off, 0.19, 130.0);
        let off_rich = candidate(8192, Visibility::Off, 0.17, 180.0);
        // Rays measure 1.1× their prediction, `off` half of it (the bunny box's survey
        // overrates what occlusion removes there).
        let truth =
            |c: &BudgetChoice| c.predicted_flip * if c.visibility.rays() { 1.1 } else { 0.5 };
        let all = [rays, off_cheap, off_rich, converged];
        let search = Survey::search(&all, &converged, 0.1, 6, |c| Ok::<_, ()>(truth(c))).unwrap();
        let order: Vec<usize> = search.pilots.iter().map(|p| p.choice.points).collect();
        assert_eq!(order, [1024, 8192, 4096], "{search:?}");
        assert_eq!(search.choice.points, 4096);
        // Where the survey prices `off` beyond any gap seen (scaled 0.44 against 0.1),
        // no pilot goes to it.
        let hopeless = candidate(4096, Visibility::Off, 0.4, 130.0);
        let search = Survey::search(&[rays, hopeless, converged], &converged, 0.1, 6, |c| {
            Ok::<_, ()>(truth(c))
        })
        .unwrap();
        assert_eq!(search.pilots.len(), 1, "{search:?}");
        assert_eq!(search.choice.points, 1024);
    }

    #[test]
    fn without_a_pilot_meeting_the_target_the_converged_setting_is_chosen() {
        let survey = survey_of("cornell");
        let (search, _, converged) = search_against(&survey, 0.05, |_| 0.5);
        assert_eq!(
            (
                search.choice.points,
                search.choice.rsm,
                search.choice.visibility
            ),
            (converged.points, converged.rsm, converged.visibility)
        );
        // Every pilot measured 0.5, 10–70× its prediction: scaled alike, the converged
        // candidate's own prediction misses 0.05 too, so the target is not called met.
        assert!(search.converged_flip > 0.05, "{search:?}");
        assert!(!search.choice.met);
        assert_eq!(search.measured_flip, 0.0);
        assert!(!search.pilots.is_empty());
        assert!(search.pilots.iter().all(|p| p.measured_flip > 0.05));
    }

    /// `sum` is priced as no occlusion, and its pilots scale it apart from `off`'s: where the
    /// discs remove what occlusion blocks (the corridor, where `sum` at 1024 points was the
    /// cheapest setting meeting 0.10) and leaving occlusion out does not, the search finds it.
    #[test]
    fn summed_discs_are_measured_with_a_scale_of_their_own() {
        let converged = synthetic(16384, Visibility::Rays, 0.01, 1000.0);
        let rays = synthetic(1024, Visibility::Rays, 0.09, 300.0);
        let off = synthetic(1024, Visibility::Off, 0.12, 100.0);
        let sum = synthetic(1024, Visibility::Sum, 0.12, 120.0);
        let truth = |c: &BudgetChoice| {
            c.predicted_flip
                * match c.visibility {
                    Visibility::Off => 2.0,
                    Visibility::Sum => 0.6,
                    _ => 1.0,
                }
        };
        let search = Survey::search(&[rays, off, sum, converged], &converged, 0.1, 6, |c| {
            Ok::<_, ()>(truth(c))
        })
        .unwrap();
        assert_eq!(search.choice.visibility, Visibility::Sum, "{search:?}");
        assert!(search.choice.met && (search.measured_flip - 0.072).abs() < 1e-9);
        let order: Vec<Visibility> = search.pilots.iter().map(|p| p.choice.visibility).collect();
        assert_eq!(order, [Visibility::Rays, Visibility::Off, Visibility::Sum]);
    }

    /// The pilots measure against the converged candidate; where that candidate is itself
    /// predicted (scaled by the pilots) to miss the target, as on Sponza, a pilot within the
    /// target of it has not met the target.
    #[test]
    fn the_target_is_met_only_where_the_converged_candidate_is_predicted_to_meet_it() {
        let candidate = with_rays;
        let converged = candidate(16384, 0.18, 1000.0);
        let cheap = candidate(1024, 0.12, 100.0);
        let mid = candidate(4096, 0.09, 300.0);
        let all = [cheap, mid, converged];
        let search_at = |scale: f64| {
            Survey::search(&all, &converged, 0.1, 6, |c| {
                Ok::<_, ()>(scale * c.predicted_flip)
            })
            .unwrap()
        };
        // Pilots at 0.7× their predictions: both within 0.1 of the converged image, which
        // is itself predicted 0.126 from convergence. The cheapest is chosen, but not as
        // meeting the target.
        let search = search_at(0.7);
        assert_eq!(search.choice.points, 1024, "{search:?}");
        assert!((search.converged_flip - 0.126).abs() < 1e-9);
        assert!(search.measured_flip <= 0.1 && !search.choice.met);
        // At 0.5× the converged candidate is predicted at 0.09, though the survey alone puts
        // it at 0.18: the target is met.
        let search = search_at(0.5);
        assert_eq!(search.choice.points, 1024, "{search:?}");
        assert!((search.converged_flip - 0.09).abs() < 1e-9);
        assert!(search.choice.met);
        // At 1.5× no pilot is within 0.1, and the converged candidate is kept, missing it.
        let search = search_at(1.5);
        assert_eq!(search.choice.points, 16384, "{search:?}");
        assert!(!search.pilots.is_empty() && !search.choice.met);
    }

    /// Under a time budget the survey ranks candidates without occlusion against those with
    /// rays by its occluded share, which on a floating bunny is pessimistic: the pilots
    /// measure the best of each kind and keep the one measured most accurate, and no more
    /// once nothing left is predicted to beat it.
    #[test]
    fn within_a_budget_the_kind_the_survey_misjudges_is_measured_and_taken() {
        let converged = with_rays(16384, 0.01, 1000.0);
        let within = [
            with_rays(1448, 0.08, 300.0),
            with_rays(1024, 0.10, 250.0),
            synthetic(16384, Visibility::Off, 0.12, 200.0),
            synthetic(8192, Visibility::Off, 0.14, 150.0),
        ];
        for (off_scale, chosen_points) in [(0.6, 16384), (1.5, 1448)] {
            let truth = |c: &BudgetChoice| {
                c.predicted_flip
                    * if c.visibility == Visibility::Off {
                        off_scale
                    } else {
                        1.0
                    }
            };
            let found = Survey::search_within(&within, &converged, DEFAULT_PILOTS, |c| {
                Ok::<_, ()>(truth(c))
            })
            .unwrap();
            let best = found.choice.expect("a measured candidate");
            assert_eq!(
                best.choice.points, chosen_points,
                "off × {off_scale}: {found:?}"
            );
            assert_eq!(best.measured_flip, truth(&best.choice));
            // The rays' best first, then the best without occlusion; with that one measured
            // 0.072 nothing left is predicted to beat it, and with it at 0.18 the rays'
            // 1024 points, scaled to 0.10, cannot beat 0.08 either.
            let measured: Vec<usize> = found.pilots.iter().map(|p| p.choice.points).collect();
            assert_eq!(measured, vec![1448, 16384], "off × {off_scale}");
        }
        let none = Survey::search_within(&within, &converged, 0, |_| Ok::<_, ()>(0.0)).unwrap();
        assert!(none.choice.is_none() && none.pilots.is_empty());
    }

    #[test]
    fn the_pilots_scale_the_predictions_by_their_geometric_mean_error() {
        let survey = survey_of("cornell");
        let pilot = |points, rsm, visibility, scale: f64| {
            let choice = survey.predict(points, rsm, visibility);
            Pilot {
                choice,
                measured_flip: scale * choice.predicted_flip,
            }
        };
        for visibility in Visibility::ALL {
            assert_eq!(pilot_scale(&[], visibility), 1.0);
        }
        // One pilot with rays scales every candidate, with rays or without, until one
        // without has been measured.
        let one = [pilot(2048, 64, Visibility::Rays, 3.0)];
        for visibility in Visibility::ALL {
            assert!((pilot_scale(&one, visibility) - 3.0).abs() < 1e-9);
        }
        // Then each occlusion has its own scale: adaptive rays share the rays' pilots.
        let two = [one[0], pilot(16384, 32, Visibility::Off, 1.0 / 12.0)];
        assert!((pilot_scale(&two, Visibility::Rays) - 3.0).abs() < 1e-9);
        assert!((pilot_scale(&two, Visibility::AdaptiveRays) - 3.0).abs() < 1e-9);
        assert!((pilot_scale(&two, Visibility::Off) - 1.0 / 12.0).abs() < 1e-9);
        let three = [
            two[0],
            two[1],
            pilot(1024, 32, Visibility::AdaptiveRays, 1.0 / 27.0),
        ];
        assert!(
            (pilot_scale(&three, Visibility::Rays) - 1.0 / 3.0).abs() < 1e-9,
            "{}",
            pilot_scale(&three, Visibility::Rays)
        );
        assert!((pilot_scale(&three, Visibility::Off) - 1.0 / 12.0).abs() < 1e-9);
        // A pilot that matches the converged image to the bit scales by the floor, not by 0;
        // one that could not be rendered does not count, nor decides which pilots count.
        let exact = [pilot(2048, 64, Visibility::Rays, 0.0)];
        assert!(pilot_scale(&exact, Visibility::Rays) > 0.0);
        let failed = [one[0], pilot(4096, 64, Visibility::Rays, f64::NAN)];
        assert!((pilot_scale(&failed, Visibility::Rays) - 3.0).abs() < 1e-9);
        let failed_off = [one[0], pilot(4096, 64, Visibility::Off, f64::NAN)];
        assert!((pilot_scale(&failed_off, Visibility::Off) - 3.0).abs() < 1e-9);
        // Summed discs have a scale of their own, borrowed from all pilots until measured.
        assert!((pilot_scale(&two, Visibility::Sum) - 0.5).abs() < 1e-9);
        let four = [two[0], two[1], pilot(2048, 64, Visibility::Sum, 2.0)];
        assert!((pilot_scale(&four, Visibility::Sum) - 2.0).abs() < 1e-9);
        assert!((pilot_scale(&four, Visibility::Off) - 1.0 / 12.0).abs() < 1e-9);
    }

    #[test]
    fn resampling_keeps_the_total_flux_and_favours_bright_samples() {
        let mk = |flux| LitSample {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            flux,
            tile: 0,
        };
        let samples = vec![mk(1.0), mk(3.0), mk(0.0), mk(4.0)];
        let mut rng = Rng::new(1, 2, 3);
        let out = resample_by_flux(&samples, 4, &mut rng);
        let total: f64 = out.iter().map(|s| s.flux).sum();
        assert!((total - 8.0).abs() < 1e-9, "{total}");
        assert_eq!(out.len(), 4);
    }
}
