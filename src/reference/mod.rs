//! The ground truth: a CPU path tracer (rayon over rows, the `obvhs` BVH) with the same scene
//! model, material model (`crate::shading::brdf`) and punctual lights
//! (`crate::shading::WorldLight`) as the GPU methods, and an exact bounce count. See README.md
//! beside this file for the estimators.

/// The scene's ray tracer and the seeded sampler live in the base layer (the bakers use them
/// too); the path tracer's names for them stay.
pub use crate::sampling;
pub use crate::trace as rt;

use std::fmt;
use std::str::FromStr;
use std::time::Instant;

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use crate::frame::{FrameInput, Method, View, ViewResult};
use crate::gpu::{GpuContext, Passes};
use crate::image_io::Image;
use crate::method::{Entry, MethodOptions, OptionKind, OptionSpec};
use crate::raster::{RenderError, RenderSettings};
use crate::sampling::{cosine_hemisphere, sample_brdf, Rng};
use crate::scene::{CameraView, Scene};
pub use crate::trace::{Hit, Tracer};

/// How many indirect bounces a path may take: `Limited(0)` is direct light only,
/// `Limited(1)` adds one bounce, …; `Unbounded` ends paths by Russian roulette.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Bounces {
    Limited(u32),
    Unbounded,
}

impl Bounces {
    fn allows(self, bounce: u32) -> bool {
        match self {
            Bounces::Limited(b) => bounce <= b,
            Bounces::Unbounded => true,
        }
    }
}

impl FromStr for Bounces {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "inf" | "infinite" | "unbounded" => Ok(Bounces::Unbounded),
            t => t
                .parse::<u32>()
                .map(Bounces::Limited)
                .map_err(|_| format!("bounces '{s}': expected a count (0, 1, …) or 'inf'")),
        }
    }
}

impl fmt::Display for Bounces {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Bounces::Limited(b) => write!(f, "{b}"),
            Bounces::Unbounded => f.write_str("inf"),
        }
    }
}

/// Russian roulette starts after this many bounces (unbounded paths only).
const ROULETTE_AFTER: u32 = 3;

/// Knobs of one reference render.
#[derive(Clone, Copy, Debug)]
pub struct ReferenceSettings {
    pub width: u32,
    pub height: u32,
    /// Paths per pixel.
    pub spp: u32,
    pub bounces: Bounces,
    pub seed: u64,
    /// Draw a progress bar with ETA on stderr (only when stderr is a terminal).
    pub progress: bool,
    /// Keep the materials' specular lobes (`false`: [`Tracer::diffuse_only`], the light the
    /// diffuse-only methods — the atlas bake, the VALs' bounce — model).
    pub specular: bool,
}

impl Default for ReferenceSettings {
    fn default() -> Self {
        Self {
            width: 512,
            height: 512,
            spp: 64,
            bounces: Bounces::Limited(1),
            seed: 0,
            progress: true,
            specular: true,
        }
    }
}

/// A reference frame: the direct and indirect parts, and the estimated variance of each pixel
/// mean (per channel) of the full image and of the indirect image.
#[derive(Clone, Debug)]
pub struct ReferenceImage {
    pub direct: Image,
    pub indirect: Image,
    pub variance: Image,
    pub variance_indirect: Image,
    /// Camera paths traced (pixels × spp).
    pub paths: u64,
    pub seconds: f64,
}

impl ReferenceImage {
    pub fn radiance(&self, indirect_only: bool) -> Image {
        if indirect_only {
            self.indirect.clone()
        } else {
            self.direct.add(&self.indirect)
        }
    }

    pub fn variance_of(&self, indirect_only: bool) -> &Image {
        if indirect_only {
            &self.variance_indirect
        } else {
            &self.variance
        }
    }
}

/// What one camera path brings back, split by where the light came from.
#[derive(Clone, Copy, Debug, Default)]
pub struct PathSample {
    pub hit: bool,
    /// Emission of the first surface.
    pub emission: Vec3,
    /// Punctual lights and emissive triangles at the first surface (next-event estimation,
    /// exact visibility).
    pub direct: Vec3,
    /// Everything that arrives after at least one bounce.
    pub indirect: Vec3,
}

/// Radiance leaving `hit` toward `wo` straight from the punctual lights, with ray-traced
/// visibility: `Σ_l f_r · E_l · cos θ · V`. Emitter proxies are skipped: [`emitter_light`]
/// samples the surfaces they stand for.
pub fn direct_light(tracer: &Tracer, hit: &Hit, wo: Vec3) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for light in &tracer.lights {
        if light.kind.is_emission_proxy() {
            continue;
        }
        let (wi, irradiance) = light.incident(hit.position);
        let cos = hit.normal.dot(wi);
        if cos <= 0.0 || irradiance.max_element() <= 0.0 {
            continue;
        }
        let origin = tracer.spawn(hit, wi);
        let t_max = match light.kind {
            crate::scene::LightKind::Directional => f32::INFINITY,
            _ => (light.position - origin).length() - tracer.epsilon,
        };
        if !tracer.unoccluded(origin, wi, t_max) {
            continue;
        }
        sum += crate::shading::brdf(hit.rho_d, hit.rho_s, hit.k, hit.normal, wi, wo)
            * irradiance
            * cos;
    }
    sum
}

/// Radiance leaving `hit` toward `wo` straight from the emissive triangles, one sample of
/// next-event estimation by area: `f_r · L_e(y) · cos θ_x · cos θ_y / d² · V / p_A(y)`, with
/// y drawn by [`crate::trace::EmitterSampler`]. A scene without emitters draws no random
/// numbers (its paths stay as they were).
pub fn emitter_light(tracer: &Tracer, hit: &Hit, wo: Vec3, rng: &mut Rng) -> Vec3 {
    if tracer.emitters.is_empty() {
        return Vec3::ZERO;
    }
    let u = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
    let Some(y) = tracer.emitters.sample(tracer.scene(), u) else {
        return Vec3::ZERO;
    };
    let to_y = y.position - hit.position;
    let d2 = to_y.length_squared();
    if !d2.is_finite() || d2 <= 0.0 || y.pdf_area <= 0.0 || y.radiance.max_element() <= 0.0 {
        return Vec3::ZERO;
    }
    let wi = to_y / d2.sqrt();
    let cos_x = hit.normal.dot(wi);
    let cos_y = -y.normal.dot(wi);
    if cos_x <= 0.0 || cos_y <= 0.0 {
        return Vec3::ZERO;
    }
    let origin = tracer.spawn(hit, wi);
    // Stop short of y so that its own triangle does not count as a blocker.
    let t_max = (y.position - origin).length() - 2.0 * tracer.epsilon;
    if !tracer.unoccluded(origin, wi, t_max) {
        return Vec3::ZERO;
    }
    crate::shading::brdf(hit.rho_d, hit.rho_s, hit.k, hit.normal, wi, wo)
        * y.radiance
        * (cos_x * cos_y / (d2 * y.pdf_area))
}

/// Traces one path from `origin` along `dir`.
pub fn trace_path(
    tracer: &Tracer,
    origin: Vec3,
    dir: Vec3,
    bounces: Bounces,
    rng: &mut Rng,
) -> PathSample {
    let Some(first) = tracer.intersect(origin, dir, f32::INFINITY) else {
        return PathSample::default();
    };
    let mut out = PathSample {
        hit: true,
        emission: first.emission,
        direct: direct_light(tracer, &first, -dir) + emitter_light(tracer, &first, -dir, rng),
        indirect: Vec3::ZERO,
    };
    let (mut hit, mut wo) = (first, -dir);
    let mut throughput = Vec3::ONE;
    let mut bounce = 1;
    while bounces.allows(bounce) {
        let Some((wi, weight)) = sample_brdf(hit.rho_d, hit.rho_s, hit.k, hit.normal, wo, rng)
        else {
            break;
        };
        throughput *= weight;
        if bounces == Bounces::Unbounded && bounce > ROULETTE_AFTER {
            let survive = throughput.max_element().min(0.95);
            if survive <= 0.0 || rng.next_f32() >= survive {
                break;
            }
            throughput /= survive;
        }
        if throughput.max_element() <= 0.0 {
            break;
        }
        let Some(next) = tracer.intersect(tracer.spawn(&hit, wi), wi, f32::INFINITY) else {
            break;
        };
        // The emitters' light reaches `next` by next-event estimation only; the emission a
        // bounce lands on would count it twice (with emitters in the scene).
        let landed = if tracer.emitters.is_empty() {
            next.emission
        } else {
            Vec3::ZERO
        };
        out.indirect += throughput
            * (landed + direct_light(tracer, &next, -wi) + emitter_light(tracer, &next, -wi, rng));
        hit = next;
        wo = -wi;
        bounce += 1;
    }
    out
}

/// Primary ray through the image-plane point (`px`, `py`) in pixels (top-left origin), matching
/// the GPU's projection (`CameraView::clip_from_view`).
pub fn camera_ray(camera: &CameraView, width: u32, height: u32, px: f32, py: f32) -> (Vec3, Vec3) {
    let ndc_x = px / width as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - py / height as f32 * 2.0;
    let view_dir = match camera.off_axis {
        None => {
            let tan = (camera.yfov * 0.5).tan();
            Vec3::new(ndc_x * tan * camera.aspect, ndc_y * tan, -1.0)
        }
        Some([l, r, b, t]) => {
            let lerp = |a: f32, c: f32, s: f32| a + (c - a) * (s * 0.5 + 0.5);
            Vec3::new(lerp(l, r, ndc_x), lerp(b, t, ndc_y), -1.0)
        }
    };
    let m = camera.world_from_view;
    let dir = m.transform_vector3(view_dir).normalize();
    // Start on the near plane, as rasterization does.
    let origin = m.transform_point3(view_dir * camera.znear);
    (origin, dir)
}

/// The surface each pixel's centre sees first (`None` where its ray leaves the scene), row by
/// row: what a pixel of the image stands for, for masks over the image.
pub fn first_hits(
    tracer: &crate::trace::Tracer,
    camera: &CameraView,
    width: u32,
    height: u32,
) -> Vec<Option<crate::trace::Hit>> {
    (0..width * height)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
            let (o, d) = camera_ray(camera, width, height, x, y);
            tracer.intersect(o, d, f32::INFINITY)
        })
        .collect()
}

/// Renders the scene at `world_from_node` through `camera`. Each pixel averages `spp` paths
/// through uniformly jittered points of the pixel (a box filter, like the GPU's SSAA resolve).
pub fn render(
    scene: &Scene,
    world_from_node: &[Mat4],
    camera: &CameraView,
    settings: &ReferenceSettings,
) -> ReferenceImage {
    let mut image = None;
    render_progressive(
        scene,
        world_from_node,
        camera,
        settings,
        &[settings.spp],
        |_, frame| image = Some(frame),
    );
    image.expect("one checkpoint gives one image")
}

/// [`render`] stopped at every paths-per-pixel count in `checkpoints` (sorted and deduplicated
/// here; `settings.spp` is ignored): `at(spp, image)` gets the image a separate `render` with
/// that `spp` and the same seed returns, bit for bit (path s of a pixel depends only on the
/// seed, the pixel and s, and each pixel sums its paths in order), with `seconds` the time that
/// separate render would take: the tracer's build and the paths up to `spp`, without the other
/// checkpoints' images or the time spent in `at`. One run gives a whole convergence curve for
/// the price of its longest point.
pub fn render_progressive(
    scene: &Scene,
    world_from_node: &[Mat4],
    camera: &CameraView,
    settings: &ReferenceSettings,
    checkpoints: &[u32],
    mut at: impl FnMut(u32, ReferenceImage),
) {
    let started = Instant::now();
    let mut tracer = Tracer::new(scene, world_from_node);
    tracer.diffuse_only = !settings.specular;
    let (w, h) = (settings.width.max(1), settings.height.max(1));
    let mut stops: Vec<u32> = checkpoints.iter().map(|&s| s.max(1)).collect();
    stops.sort_unstable();
    stops.dedup();
    let mut stats = vec![PixelStats::default(); w as usize * h as usize];
    // Time spent outside the paths of the checkpoint being timed (earlier images, `at`).
    let mut excluded = std::time::Duration::ZERO;
    let mut done = 0u32;
    for spp in stops {
        let bar = crate::progress::Step::new(
            settings.progress,
            h as u64,
            &format!("path tracing rows ({spp} spp)"),
        );
        let passes = done..spp;
        stats
            .par_chunks_mut(w as usize)
            .enumerate()
            .for_each(|(y, row)| {
                for (x, stats) in row.iter_mut().enumerate() {
                    // After Ctrl-C the remaining pixels are skipped; callers see the flag
                    // and discard the image.
                    if crate::progress::cancelled() {
                        return;
                    }
                    let pixel = (y as u64) * w as u64 + x as u64;
                    for s in passes.clone() {
                        let mut rng = Rng::new(settings.seed, pixel, s as u64);
                        let (jx, jy) = (rng.next_f32(), rng.next_f32());
                        let (o, d) = camera_ray(camera, w, h, x as f32 + jx, y as f32 + jy);
                        let path = trace_path(&tracer, o, d, settings.bounces, &mut rng);
                        stats.add(&path);
                    }
                }
                bar.inc(1);
            });
        bar.finish();
        done = spp;
        let resolving = Instant::now();
        let mut image = resolve(&stats, w, h, spp);
        let resolve_time = resolving.elapsed();
        image.seconds = (started.elapsed() - excluded).as_secs_f64();
        let handed_over = Instant::now();
        at(spp, image);
        // This checkpoint's image belongs to its own time, not to the next checkpoint's.
        excluded += resolve_time + handed_over.elapsed();
        if crate::progress::cancelled() {
            break;
        }
    }
}

/// Pixel means and variances of `spp` paths per pixel.
fn resolve(stats: &[PixelStats], w: u32, h: u32, spp: u32) -> ReferenceImage {
    let n = spp as f32;
    let mut out = ReferenceImage {
        direct: Image::new(w, h),
        indirect: Image::new(w, h),
        variance: Image::new(w, h),
        variance_indirect: Image::new(w, h),
        paths: w as u64 * h as u64 * spp as u64,
        seconds: 0.0,
    };
    for (i, s) in stats.iter().enumerate() {
        let alpha = s.hits / n;
        let direct = s.direct / n;
        let indirect = s.indirect / n;
        out.direct.pixels[i] = [direct.x, direct.y, direct.z, alpha];
        out.indirect.pixels[i] = [indirect.x, indirect.y, indirect.z, alpha];
        let var = mean_variance(s.full, s.full_sq, n);
        let var_i = mean_variance(s.indirect, s.indirect_sq, n);
        out.variance.pixels[i] = [var.x, var.y, var.z, 1.0];
        out.variance_indirect.pixels[i] = [var_i.x, var_i.y, var_i.z, 1.0];
    }
    out
}

/// Variance of the mean of `n` samples from their sum and sum of squares:
/// `s² / n` with the unbiased sample variance `s²` (0 for a single sample).
fn mean_variance(sum: Vec3, sum_sq: Vec3, n: f32) -> Vec3 {
    if n < 2.0 {
        return Vec3::ZERO;
    }
    let mean = sum / n;
    ((sum_sq - mean * sum) / (n - 1.0) / n).max(Vec3::ZERO)
}

#[derive(Clone, Copy, Default)]
struct PixelStats {
    hits: f32,
    direct: Vec3,
    indirect: Vec3,
    full: Vec3,
    full_sq: Vec3,
    indirect_sq: Vec3,
}

impl PixelStats {
    fn add(&mut self, path: &PathSample) {
        let direct = sanitize(path.emission + path.direct);
        let indirect = sanitize(path.indirect);
        let full = direct + indirect;
        self.hits += path.hit as u32 as f32;
        self.direct += direct;
        self.indirect += indirect;
        self.full += full;
        self.full_sq += full * full;
        self.indirect_sq += indirect * indirect;
    }
}

/// A non-finite sample (never expected) is dropped to zero rather than poisoning a pixel.
fn sanitize(v: Vec3) -> Vec3 {
    if v.is_finite() {
        v
    } else {
        Vec3::ZERO
    }
}

/// Which light an irradiance estimate counts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IrradianceSettings {
    /// Include the punctual lights' direct irradiance (exact, ray-traced visibility) and the
    /// emission of surfaces seen directly.
    pub direct: bool,
    /// Light that bounced 1..=B times before arriving (`Limited(0)` = none).
    pub bounces: Bounces,
    /// Hemisphere samples per point.
    pub samples: u32,
    pub seed: u64,
    /// Keep the materials' specular lobes (`false`: diffuse reflection only, the light an
    /// irradiance atlas models; see [`ReferenceSettings::specular`]).
    pub specular: bool,
}

/// Estimated irradiance E(x) = ∫ L_in(x, ω) cos θ dω at each surface point `(x, n)` (world
/// space, unit normal facing the side to gather from), for checking light atlases and
/// per-point methods. The direct part is exact next-event estimation; the indirect part uses
/// cosine-weighted directions: `E_ind ≈ π/N · Σ L_in(ω_i)`. Points are offset along `n`.
pub fn irradiance_at(
    scene: &Scene,
    world_from_node: &[Mat4],
    points: &[(Vec3, Vec3)],
    settings: &IrradianceSettings,
) -> Vec<Vec3> {
    let mut tracer = Tracer::new(scene, world_from_node);
    tracer.diffuse_only = !settings.specular;
    let samples = settings.samples.max(1);
    points
        .par_iter()
        .enumerate()
        .map(|(i, &(x, n))| {
            let n = n.try_normalize().unwrap_or(Vec3::Y);
            let origin = x + n * tracer.epsilon;
            let mut e = Vec3::ZERO;
            if settings.direct {
                e += tracer.punctual_irradiance(x, n);
            }
            let gather_emission = settings.direct;
            let gather_indirect = settings.bounces != Bounces::Limited(0);
            if gather_emission || gather_indirect {
                let rest = match settings.bounces {
                    Bounces::Limited(b) => Bounces::Limited(b.saturating_sub(1)),
                    Bounces::Unbounded => Bounces::Unbounded,
                };
                let mut sum = Vec3::ZERO;
                for s in 0..samples {
                    let mut rng = Rng::new(settings.seed, i as u64, s as u64);
                    let dir = cosine_hemisphere(n, rng.next_f32(), rng.next_f32());
                    let path = trace_path(&tracer, origin, dir, rest, &mut rng);
                    if gather_emission {
                        sum += sanitize(path.emission);
                    }
                    if gather_indirect {
                        sum += sanitize(path.direct + path.indirect);
                    }
                }
                e += sum * (std::f32::consts::PI / samples as f32);
            }
            e
        })
        .collect()
}

/// `--method reference`: the path tracer behind the [`Method`] interface. Options: `bounces`
/// (count or `inf`, default 1), `spp` (default 64), `seed` (default 1). Timings are wall-clock
/// ms in one pass, `path_trace`; it owns no GPU memory.
pub struct ReferenceMethod {
    pub settings: ReferenceSettings,
    last: Option<ReferenceImage>,
}

impl ReferenceMethod {
    pub const DEFAULT_SPP: u32 = 64;
    pub const DEFAULT_SEED: u64 = 1;
    /// Camera paths one frame may trace: 4096 spp at 1024² (hours on a CPU already).
    pub const MAX_PATHS: u64 = 1 << 32;

    pub fn new(settings: RenderSettings, options: &MethodOptions) -> Result<Self, RenderError> {
        let bounces: String = options.get("bounces", "1".to_string())?;
        let bounces = bounces.parse::<Bounces>().map_err(RenderError::Settings)?;
        let spp: u32 = options.get("spp", Self::DEFAULT_SPP)?;
        if spp == 0 {
            return Err(RenderError::Settings(
                "option spp=0: need at least 1".into(),
            ));
        }
        let paths = settings.width as u64 * settings.height as u64 * spp as u64;
        if paths > Self::MAX_PATHS {
            return Err(RenderError::Settings(format!(
                "option spp={spp}: {}×{} pixels × {spp} spp is {paths} paths, beyond the budget \
                 of {} per frame; lower --spp or the image size",
                settings.width,
                settings.height,
                Self::MAX_PATHS
            )));
        }
        let seed: u64 = options.get("seed", Self::DEFAULT_SEED)?;
        let specular = options.choice("specular", &["on", "off"])? == "on";
        Ok(Self {
            settings: ReferenceSettings {
                width: settings.width,
                height: settings.height,
                spp,
                bounces,
                seed,
                progress: true,
                specular,
            },
            last: None,
        })
    }

    /// The last frame's per-pixel variance of the full or the indirect image.
    pub fn last_variance(&self, indirect_only: bool) -> Option<&Image> {
        self.last.as_ref().map(|r| r.variance_of(indirect_only))
    }
}

pub static ENTRY: Entry = Entry {
    name: "reference",
    help: "CPU path tracer, the ground truth",
    options: &[
        OptionSpec {
            name: "bounces",
            kind: OptionKind::Text,
            default: "1",
            help: "indirect bounces: 0 = direct only, 1, 2, … or inf",
        },
        OptionSpec {
            name: "spp",
            kind: OptionKind::Int {
                min: 1,
                max: 1 << 20,
            },
            default: "64",
            help: "paths per pixel",
        },
        OptionSpec {
            name: "seed",
            kind: OptionKind::Int {
                min: 0,
                max: i64::MAX,
            },
            default: "1",
            help: "random seed of the paths",
        },
        OptionSpec {
            name: "specular",
            kind: OptionKind::Choice(&["on", "off"]),
            default: "on",
            help: "the materials' specular lobes (off: diffuse light only, as the light atlas and the VALs' bounce model it; glTF dielectrics reflect 4 % specularly)",
        },
    ],
    create: |_ctx, _scene, settings, options| {
        Ok(Box::new(ReferenceMethod::new(settings, options)?))
    },
};

impl Method for ReferenceMethod {
    fn name(&self) -> &'static str {
        "reference"
    }

    fn renders_on_gpu(&self) -> bool {
        false
    }

    fn settings(&self) -> RenderSettings {
        RenderSettings {
            width: self.settings.width,
            height: self.settings.height,
            ..RenderSettings::default()
        }
    }

    fn update(
        &mut self,
        _ctx: &GpuContext,
        _frame: &FrameInput,
        _views: &[&View],
        _passes: &mut Passes,
    ) -> Result<(), RenderError> {
        Ok(())
    }

    /// Path-traces the view on the CPU and writes the images into its outputs.
    fn record_view(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError> {
        let settings = ReferenceSettings {
            width: view.width,
            height: view.height,
            ..self.settings
        };
        let image = render(frame.scene, frame.world_from_node, &view.camera, &settings);
        crate::progress::check()?;
        passes.add_cpu("path_trace", image.seconds * 1000.0);
        view.write_outputs(ctx, &image.direct, &image.indirect);
        self.last = Some(image);
        Ok(ViewResult::Outputs)
    }

    fn gpu_bytes(&self) -> u64 {
        0
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut map = serde_json::Map::new();
        map.insert("spp".into(), self.settings.spp.into());
        map.insert("bounces".into(), self.settings.bounces.to_string().into());
        map.insert("seed".into(), self.settings.seed.into());
        map.insert(
            "specular".into(),
            if self.settings.specular { "on" } else { "off" }.into(),
        );
        if let Some(last) = &self.last {
            map.insert("paths".into(), last.paths.into());
            let rate = last.paths as f64 / last.seconds.max(1e-9);
            map.insert("paths_per_s".into(), (rate.round()).into());
        }
        map
    }

    fn variance(&self, indirect_only: bool) -> Option<Image> {
        self.last_variance(indirect_only).cloned()
    }
}
