//! Light-atlas baking on the CPU with rayon: the parts every baker shares and the [`Baker`]
//! interface. Two bakers fill the same atlas (per-bounce irradiance per texel, the same output
//! format and runtime):
//! - [`super::patches::PatchBaker`] (seed 000, DESIGN §5, `--lights patches`): VPL patches,
//!   progressive refinement with depth cubes at the shooters, disc kernels plus a near-field
//!   gather per texel;
//! - [`super::polygon::PolygonBaker`] (seed 001, `--lights polygons`): photon-traced VPLs per
//!   light and bounce clustered into polygon and sphere lights, the analytic form factor, PCSS
//!   visibility from a depth cube at each light.
//!
//! Shared here: settings and errors, the scene preparation (layout and texel coverage, the
//! tracer, occluders, scale), surface sampling, visibility (depth maps confirmed by rays near
//! their depth edges), the texel fill, the energy account, progress and cancel.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Instant;

use glam::{Mat4, Vec2, Vec3};
use rayon::prelude::*;

use super::depth::ShadowTest;
use super::layout::{self, AtlasLayout, Texel};
use crate::image_io::{Image, ImageError};
use crate::scene::{LightKind, Scene};
use crate::shading::{spot_attenuation, WorldLight};
use crate::trace::Tracer;

pub use super::patches::{
    near_field, patch_transfer, patch_transfer_pair, transfer, Patch, PatchBaker, SampleLookup,
    MAX_CUBE_BYTES, MAX_CUBE_RES, MAX_NEAR_RAYS, NEAR_NOISE,
};
pub use super::polygon::{PolygonBaker, PolygonSettings, PolygonStats};

/// Which virtual lights carry the indirect light into the atlas.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Lights {
    /// Seed 000: VPL patches and progressive refinement.
    #[default]
    Patches,
    /// Seed 001: photon-traced VPLs clustered into polygon and sphere lights.
    Polygons,
}

impl Lights {
    pub fn name(self) -> &'static str {
        match self {
            Lights::Patches => "patches",
            Lights::Polygons => "polygons",
        }
    }

    /// The baker for these lights.
    pub fn baker(self) -> &'static dyn Baker {
        match self {
            Lights::Patches => &PatchBaker,
            Lights::Polygons => &PolygonBaker,
        }
    }
}

impl std::str::FromStr for Lights {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "patches" | "000" => Ok(Lights::Patches),
            "polygons" | "001" => Ok(Lights::Polygons),
            other => Err(format!(
                "unknown lights '{other}': expected patches (seed 000) or polygons (seed 001)"
            )),
        }
    }
}

impl std::fmt::Display for Lights {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A light-atlas baker: the scene as placed by `world_from_node` in, per-bounce irradiance per
/// texel out. `progress` gets (stage, done, total); setting `cancel` stops the bake at its next
/// check with [`BakeError::Cancelled`].
pub trait Baker: Sync {
    fn name(&self) -> &'static str;
    fn bake(
        &self,
        scene: &Scene,
        world_from_node: &[Mat4],
        settings: &BakeSettings,
        progress: Progress,
        cancel: &AtomicBool,
    ) -> Result<Bake, BakeError>;
}

/// Bakes with the baker `settings.lights` names.
pub fn bake(
    scene: &Scene,
    world_from_node: &[Mat4],
    settings: &BakeSettings,
    progress: Progress,
    cancel: &AtomicBool,
) -> Result<Bake, BakeError> {
    settings
        .lights
        .baker()
        .bake(scene, world_from_node, settings, progress, cancel)
}

/// Knobs of one bake.
#[derive(Clone, Debug)]
pub struct BakeSettings {
    /// Which baker: patches (seed 000) or polygon lights (seed 001).
    pub lights: Lights,
    /// Number of VPL patches `n` (patches); photon paths traced from the lights (polygons,
    /// each leaving up to one VPL per bounce).
    pub vpls: usize,
    /// Indirect bounces `B` kept in the atlas (bounce 1 = light reflected once).
    pub bounces: u32,
    /// Atlas width and height in texels.
    pub atlas_res: u32,
    /// Sample points per patch (visibility and area).
    pub samples_per_vpl: usize,
    /// Face resolution of the shooters' depth cubes (patches).
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
    /// The polygon-light baker's knobs.
    pub polygon: PolygonSettings,
}

/// Most VPL patches: shooting is quadratic in them (the depth cubes' memory is checked by
/// the patch baker).
pub const MAX_PATCH_VPLS: usize = 16384;
/// Most photon paths of the polygon-light baker.
pub const MAX_PHOTON_PATHS: usize = 1 << 20;
/// Most bounces kept (light is spent long before).
pub const MAX_BOUNCES: u32 = 64;

impl BakeSettings {
    /// Refuses counts whose work or memory no bake could finish, before any is spent.
    pub fn check_budget(&self) -> Result<(), BakeError> {
        let max_vpls = match self.lights {
            Lights::Patches => MAX_PATCH_VPLS,
            Lights::Polygons => MAX_PHOTON_PATHS,
        };
        if self.vpls > max_vpls {
            return Err(BakeError::Settings(format!(
                "--vpls {}: at most {max_vpls} with --lights {}",
                self.vpls,
                self.lights.name()
            )));
        }
        if self.bounces > MAX_BOUNCES {
            return Err(BakeError::Settings(format!(
                "--bounces {}: at most {MAX_BOUNCES}",
                self.bounces
            )));
        }
        Ok(())
    }
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            lights: Lights::Patches,
            vpls: 400,
            // Enough for a closed room: with 4 the door room kept 20 % of its light unshot,
            // and the render default (sparse+atlas) was 0.237 FLIP from the all-bounce path
            // tracer there, 0.084 with 16 (cornell 0.137 → 0.078, corridor 0.282 → 0.057);
            // shooting stops earlier where the unshot power falls below `threshold`.
            bounces: 16,
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
            polygon: PolygonSettings::default(),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    #[error("scene '{0}' has no lights (no point, spot or directional light and no emissive surface): nothing to bake; add one with --light")]
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

/// A sample point on the surface.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceSample {
    pub position: Vec3,
    pub normal: Vec3,
    pub material: u32,
    /// Diffuse albedo ρ_d at the point, textures included.
    pub rho: Vec3,
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
    /// The polygon-light baker's figures (`None` for patches).
    pub polygon: Option<PolygonStats>,
    /// The polygon-light baker's virtual lights (empty for patches).
    pub virtual_lights: Vec<super::polygon::VirtualLight>,
    /// (stage, milliseconds) in order.
    pub stage_ms: Vec<(String, f64)>,
}

/// Progress reports: (stage, done, total).
pub type Progress<'a> = &'a (dyn Fn(&str, usize, usize) + Sync);

/// The bakers draw from the project's one seeded generator.
pub(crate) use crate::sampling::Rng;

pub(crate) fn check(cancel: &AtomicBool) -> Result<(), BakeError> {
    if cancel.load(Ordering::Relaxed) {
        Err(BakeError::Cancelled)
    } else {
        Ok(())
    }
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
        // ∫ I0·max(0, n̄·ω) dω = π·I0.
        LightKind::Emitter => Some(light.intensity * std::f32::consts::PI),
    }
}

/// Shadows further in front of the receiver than this many depth-texel footprints (with all
/// 3×3 taps agreeing) are taken from the depth map without a ray. The surface beside a concave
/// edge falls into the receiver's texel within about one footprint sideways, i.e. 1/tan α
/// footprints in depth for a ray at α to that surface: 8 covers every α above 7°.
pub const CONFIRM_GAP: f32 = 8.0;

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

/// The fill's result: `irradiance[b][texel]` and the covered texels.
pub(crate) type Filled = (Vec<Vec<[f32; 3]>>, Vec<bool>);

/// Stage timer: (stage, milliseconds) in order.
pub(crate) struct Stages {
    clock: Instant,
    pub(crate) ms: Vec<(String, f64)>,
}

impl Stages {
    pub(crate) fn new() -> Self {
        Self {
            clock: Instant::now(),
            ms: Vec::new(),
        }
    }

    /// Ends the stage `name` (its time runs from the previous lap).
    pub(crate) fn lap(&mut self, name: &str) {
        self.ms.push((
            name.to_string(),
            self.clock.elapsed().as_secs_f64() * 1000.0,
        ));
        self.clock = Instant::now();
    }
}

/// What every baker starts from: the lights, the atlas layout (its texels are the conservative
/// coverage: every texel a uv triangle overlaps), the tracer for exact visibility, the
/// occluder triangles depth maps are drawn from, and the scene's scale.
pub(crate) struct BakeScene<'a> {
    pub(crate) lights: Vec<WorldLight>,
    pub(crate) layout: Arc<AtlasLayout>,
    pub(crate) tracer: Tracer<'a>,
    pub(crate) occluders: Vec<[Vec3; 3]>,
    pub(crate) bounds: crate::scene::Aabb,
    /// The bounding box's diagonal.
    pub(crate) scene_size: f32,
    /// Depth-map near plane and offsets.
    pub(crate) eps: f32,
    /// Total surface area of the layout's meshes (m²).
    pub(crate) surface_area: f64,
}

impl<'a> BakeScene<'a> {
    /// Checks the settings every baker needs, then the "unwrap" stage.
    pub(crate) fn prepare(
        scene: &'a Scene,
        world_from_node: &[Mat4],
        settings: &BakeSettings,
        progress: Progress,
        cancel: &AtomicBool,
        stages: &mut Stages,
    ) -> Result<Self, BakeError> {
        if settings.vpls == 0 || settings.bounces == 0 {
            return Err(BakeError::Settings(
                "--vpls and --bounces must be at least 1".into(),
            ));
        }
        settings.check_budget()?;
        let lights = WorldLight::from_scene(scene, world_from_node);
        if lights.is_empty() {
            return Err(BakeError::NoLights(scene.name.clone()));
        }
        progress("unwrap", 0, 1);
        let layout = layout::layout(scene, world_from_node, settings.atlas_res)
            .map_err(BakeError::Layout)?;
        progress("unwrap", 1, 1);
        stages.lap("unwrap");
        check(cancel)?;
        // Exact visibility where depth maps are unsure. Depth maps are drawn from the
        // tracer's triangles: the same surface with flat regions merged (the corridor's 82k
        // triangles are 20 there, and drawing them into 1600 cubes took a fifth of the bake).
        let tracer = Tracer::new(scene, world_from_node);
        let occluders = tracer.world_triangles();
        let mut bounds = crate::scene::Aabb::EMPTY;
        let mut surface_area = 0.0f64;
        for m in &layout.meshes {
            for p in &m.world_positions {
                bounds.grow(*p);
            }
            for t in m.indices.chunks_exact(3) {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.world_positions[i as usize]);
                surface_area += 0.5 * (b - a).cross(c - a).length() as f64;
            }
        }
        if surface_area <= 0.0 {
            return Err(BakeError::Layout(
                "the scene's surfaces have no area".into(),
            ));
        }
        let scene_size = bounds.extent().length().max(1e-6);
        Ok(Self {
            lights,
            layout,
            tracer,
            occluders,
            bounds,
            scene_size,
            eps: 1e-4 * scene_size,
            surface_area,
        })
    }

    /// World-space size of one texel: √(world area / atlas area) over the layout (the charts
    /// share one texel density).
    pub(crate) fn texel_size(&self) -> f32 {
        let mut uv_area = 0.0f64;
        for m in &self.layout.meshes {
            for t in m.indices.chunks_exact(3) {
                let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.uvs[i as usize]);
                uv_area += 0.5 * ((b - a).perp_dot(c - a)).abs() as f64;
            }
        }
        let res = self.layout.resolution as f64;
        ((self.surface_area / uv_area.max(1e-12)).sqrt() / res) as f32
    }

    /// `count` points on the layout's surfaces, stratified along the area CDF (one per
    /// stratum), each with its triangle's face normal on the side of the shading normal.
    pub(crate) fn sample_surfaces(
        &self,
        scene: &Scene,
        count: usize,
        rng: &mut Rng,
    ) -> Vec<SurfaceSample> {
        let mut triangles: Vec<[Vec3; 3]> = Vec::new();
        let mut tri_normals: Vec<[Vec3; 3]> = Vec::new();
        let mut tri_uvs: Vec<Option<[Vec2; 3]>> = Vec::new();
        let mut tri_material: Vec<u32> = Vec::new();
        for m in &self.layout.meshes {
            for t in m.indices.chunks_exact(3) {
                let idx = [t[0] as usize, t[1] as usize, t[2] as usize];
                triangles.push(idx.map(|i| m.world_positions[i]));
                tri_normals.push(idx.map(|i| m.world_normals[i]));
                tri_uvs.push((!m.material_uvs.is_empty()).then(|| idx.map(|i| m.material_uvs[i])));
                tri_material.push(m.material as u32);
            }
        }
        let mut cdf = Vec::with_capacity(triangles.len());
        let mut acc = 0.0;
        for t in &triangles {
            acc += 0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length() as f64;
            cdf.push(acc / self.surface_area);
        }
        (0..count)
            .map(|k| {
                let u = (k as f64 + rng.next_f32() as f64) / count as f64;
                let ti = cdf.partition_point(|&c| c < u).min(triangles.len() - 1);
                let (r1, r2) = (rng.next_f32().sqrt(), rng.next_f32());
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
                let uv = tri_uvs[ti].map_or(Vec2::ZERO, |t| t[0] * w.x + t[1] * w.y + t[2] * w.z);
                SurfaceSample {
                    position: p,
                    normal: n,
                    material: tri_material[ti],
                    rho: crate::trace::diffuse_albedo_at(scene, tri_material[ti] as usize, uv),
                }
            })
            .collect()
    }

    /// The atlas fill: `block` runs on chunks of texels in parallel and adds into `out`,
    /// `bounces` values per texel (`out[k·bounces + b]` for texel k of the chunk, bounce b+1).
    /// Returns `irradiance[b][texel]` and the covered texels; every texel of the layout's
    /// coverage gets a value.
    pub(crate) fn fill(
        &self,
        bounces: usize,
        progress: Progress,
        cancel: &AtomicBool,
        block: impl Fn(&[Texel], &mut [[f32; 3]]) + Sync,
    ) -> Result<Filled, BakeError> {
        let texels = &self.layout.texels;
        let done = AtomicUsize::new(0);
        let chunk = 256;
        let filled: Vec<Vec<[f32; 3]>> = texels
            .par_chunks(chunk)
            .map(|texels_in| {
                let mut out = vec![[0.0f32; 3]; texels_in.len() * bounces];
                if cancel.load(Ordering::Relaxed) {
                    return out;
                }
                block(texels_in, &mut out);
                let d = done.fetch_add(texels_in.len(), Ordering::Relaxed) + texels_in.len();
                progress("fill", d, texels.len());
                out
            })
            .collect();
        check(cancel)?;
        let res = self.layout.resolution as usize;
        let mut irradiance = vec![vec![[0.0f32; 3]; res * res]; bounces];
        let mut covered = vec![false; res * res];
        for (texels_in, out) in texels.chunks(chunk).zip(&filled) {
            for (k, t) in texels_in.iter().enumerate() {
                covered[t.index as usize] = true;
                for (b, irr) in irradiance.iter_mut().enumerate() {
                    irr[t.index as usize] = out[k * bounces + b];
                }
            }
        }
        Ok((irradiance, covered))
    }
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
        let mut summary = serde_json::json!({
            "lights": self.settings.lights.name(),
            "vpls": self.polygon.as_ref().map_or(self.patches.len(), |p| p.vpls.iter().sum()),
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
            "prepass": layout::PrepassFigures::of(&self.layout).to_json(),
        });
        if let (Some(stats), Some(obj)) = (&self.polygon, summary.as_object_mut()) {
            obj.insert("polygon".into(), stats.to_json());
        }
        summary
    }
}

/// Writes `image` to `path` as EXR (whole or not at all) with the bounce range it holds in its
/// header, so a method that adds its own first bounce can refuse an atlas that has it too.
pub fn write_atlas_exr(
    image: &Image,
    path: &std::path::Path,
    bounces: std::ops::RangeInclusive<u32>,
) -> Result<(), ImageError> {
    image.write_exr_with(
        path,
        &[
            (super::FIRST_BOUNCE_ATTRIBUTE, *bounces.start() as i32),
            (super::LAST_BOUNCE_ATTRIBUTE, *bounces.end() as i32),
        ],
    )
}
