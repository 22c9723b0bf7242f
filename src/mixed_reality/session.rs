//! One mixed-reality session: virtual objects placed in the room a depth sensor sees, lit by
//! the sensor's VALs (appended to the virtual lights' RSM VALs, gathered at sparse points on
//! the virtual objects only) and composited into the camera's photo.
//!
//! The composite is differential rendering over a local model of the real surfaces: every
//! valid depth pixel is a Lambertian patch whose albedo is its decoded colour `c`, lit by the
//! room as a uniform incident radiance `k` (`--real-scale`), so that the model reproduces the
//! photo (`ρ/π · πk = k·c`). The difference the object makes to that model — the virtual
//! lights' shadow, the room's light it blocks and the light it reflects back — is ray traced
//! per pixel and added to the photo:
//! `ΔE(x) = Σ_virtual E_l(x)·(V(x) − 1) + ∫_blocked (L_o(ω) − k) cos θ dω`, `ΔL = c/π · ΔE`,
//! with `L_o` the object's radiance toward x (its albedo × (virtual direct + πk) / π).

use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{Mat4, Quat, Vec3};
use rayon::prelude::*;

use super::depth_vals::{DepthValSettings, DepthVals, FrameSlot};
use super::math;
use super::rgbd::{Intrinsics, RgbdFrame};
use crate::frame::{record_frame, View};
use crate::gpu::{GpuContext, PassTimings};
use crate::image_io::Image;
use crate::raster::{RenderError, RenderSettings};
use crate::scene::{Aabb, CameraView, Light, LightKind, Node, Scene, Trs};
use crate::shading::WorldLight;
use crate::trace::Tracer;
use crate::vals::{SparseMethod, SparseSettings};

/// Where a virtual object stands: its bounding box's bottom centre at `base` (world, the
/// sensor trajectory's frame), turned by `yaw` about world +y and scaled uniformly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub base: Vec3,
    pub yaw: f32,
    pub scale: f32,
}

/// `x,y,z` (metres, the trajectory's world).
pub fn parse_point(text: &str) -> Result<Vec3, RenderError> {
    let v: Vec<f32> = text
        .split(',')
        .map(|t| t.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| bad_place(text))?;
    if v.len() != 3 || v.iter().any(|x| !x.is_finite()) {
        return Err(bad_place(text));
    }
    Ok(Vec3::from_slice(&v))
}

fn bad_place(text: &str) -> RenderError {
    RenderError::Settings(format!("--place {text}: expected auto or x,y,z (metres)"))
}

/// A virtual point light: `point:x,y,z:intensity[:r,g,b]` (W/sr).
pub fn parse_light(text: &str) -> Result<(Vec3, Vec3), RenderError> {
    let bad = || {
        RenderError::Settings(format!(
            "--light {text}: expected point:x,y,z:intensity[:r,g,b] (W/sr)"
        ))
    };
    let parts: Vec<&str> = text.split(':').collect();
    if !(3..=4).contains(&parts.len()) || parts[0] != "point" {
        return Err(bad());
    }
    let vec3 = |s: &str| -> Option<Vec3> {
        let v: Vec<f32> = s.split(',').filter_map(|t| t.trim().parse().ok()).collect();
        (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| Vec3::from_slice(&v))
    };
    let position = vec3(parts[1]).ok_or_else(bad)?;
    let intensity: f32 = parts[2].trim().parse().map_err(|_| bad())?;
    let color = match parts.get(3) {
        Some(c) => vec3(c).ok_or_else(bad)?,
        None => Vec3::ONE,
    };
    if !(intensity >= 0.0 && intensity.is_finite()) || color.min_element() < 0.0 {
        return Err(bad());
    }
    Ok((position, color * intensity))
}

/// The object's scene re-rooted under one node that places it, plus the virtual lights.
pub fn place_object(
    mut object: Scene,
    placement: Placement,
    lights: &[(Vec3, Vec3)],
) -> Result<Scene, RenderError> {
    if object.instances.is_empty() {
        return Err(RenderError::Settings(format!(
            "the object '{}' has no meshes",
            object.name
        )));
    }
    let bounds: Aabb = object.instance_bounds(
        &object
            .meshes
            .iter()
            .map(|m| m.model_bounds())
            .collect::<Vec<_>>(),
        &object.world_from_node(),
    );
    let bottom = Vec3::new(
        0.5 * (bounds.min.x + bounds.max.x),
        bounds.min.y,
        0.5 * (bounds.min.z + bounds.max.z),
    );
    let rotation = Quat::from_rotation_y(placement.yaw);
    let translation = placement.base - rotation * (bottom * placement.scale);
    // The placement is a uniform-scale TRS, so composing it onto every root node's local
    // TRS is exact (nodes list parents before children; a new root would break that).
    for node in object.nodes.iter_mut().filter(|n| n.parent.is_none()) {
        let local = node.local;
        node.local = Trs {
            translation: translation + rotation * (local.translation * placement.scale),
            rotation: rotation * local.rotation,
            scale: local.scale * placement.scale,
        };
    }
    // The object's own lights and cameras stay (its lights light it); the sensor is the camera.
    for (i, (position, intensity)) in lights.iter().enumerate() {
        object.nodes.push(Node {
            name: format!("virtual light {i}"),
            parent: None,
            local: Trs {
                translation: *position,
                ..Trs::default()
            },
        });
        object.lights.push(Light {
            name: format!("virtual light {i}"),
            node: object.nodes.len() - 1,
            kind: LightKind::Point,
            color: *intensity,
            intensity: 1.0,
            range: None,
        });
    }
    Ok(object)
}

/// The renderer's camera for a sensor of `k` at `world_from_camera`: the off-axis frustum
/// of the intrinsics, so that pixel (u, v) of the render is pixel (u, v) of the photo.
pub fn sensor_camera(k: &Intrinsics, world_from_camera: Mat4) -> CameraView {
    let left = (-0.5 - k.cx) / k.fx;
    let right = (k.width as f32 - 0.5 - k.cx) / k.fx;
    let top = (k.cy + 0.5) / k.fy;
    let bottom = -(k.height as f32 - 0.5 - k.cy) / k.fy;
    CameraView {
        world_from_view: super::world_from_view(world_from_camera),
        yfov: 2.0 * (0.5 * (top - bottom)).atan(),
        aspect: (right - left) / (top - bottom),
        znear: 0.05,
        zfar: 50.0,
        off_axis: Some([left, right, bottom, top]),
    }
}

/// Everything `valgi mr` can be told beyond the files.
#[derive(Clone, Copy, Debug)]
pub struct MrSettings {
    pub depth: DepthValSettings,
    pub sparse: SparseSettings,
    pub shadow_resolution: u32,
    /// Cosine-weighted rays per real pixel for the differential pass (0: no shadow/bounce
    /// on the real surfaces).
    pub differential_rays: u32,
    /// A real surface this much nearer than the object hides it (metres).
    pub depth_bias: f32,
}

impl Default for MrSettings {
    fn default() -> Self {
        Self {
            depth: DepthValSettings::default(),
            // The sparse default, cluster rays: the sensor's image tiles are clusters too,
            // and its depth blocks the rays (`light::sensor`).
            sparse: SparseSettings::default(),
            shadow_resolution: 1024,
            differential_rays: 16,
            depth_bias: 0.01,
        }
    }
}

/// One composited frame, every image in radiance (the photo's pixels are `k · c`).
pub struct MrFrame {
    pub composite: Image,
    /// The object's radiance (direct + indirect) where it is visible; alpha = coverage.
    pub object: Image,
    pub alpha: Vec<f32>,
    /// The object's indirect light alone.
    pub indirect: Image,
    /// What the object adds to the real surfaces (negative in its shadow).
    pub differential: Image,
    pub timings: PassTimings,
    pub real_vals: u32,
    pub composite_ms: f64,
}

pub struct MixedReality {
    pub method: SparseMethod,
    pub scene: Scene,
    pub intrinsics: Intrinsics,
    pub settings: MrSettings,
    slot: FrameSlot,
    view: Option<View>,
}

impl MixedReality {
    pub fn new(
        ctx: &GpuContext,
        scene: Scene,
        intrinsics: Intrinsics,
        settings: MrSettings,
    ) -> Result<Self, RenderError> {
        let mut source = DepthVals::new(ctx, intrinsics, settings.depth)?;
        // The sparse points lie on the virtual objects, which stand still in the room (every
        // frame is drawn at rest): `--real-cut` measures from their bounding sphere.
        let bounds = scene.world_bounds(&scene.world_from_node());
        source.receivers = (!bounds.is_empty()).then(|| math::Receivers {
            centre: bounds.center(),
            radius: 0.5 * bounds.extent().length(),
        });
        let slot = source.slot.clone();
        let render = RenderSettings {
            width: intrinsics.width,
            height: intrinsics.height,
            ssaa: 1,
            shadow_resolution: settings.shadow_resolution,
            ..RenderSettings::default()
        };
        let method = SparseMethod::with_val_source(
            ctx,
            &scene,
            render,
            settings.sparse,
            Some(Box::new(source)),
        )?;
        Ok(Self {
            method,
            scene,
            intrinsics,
            settings,
            slot,
            view: None,
        })
    }

    /// The diffuse irradiance the last frame left at every sparse point of the object (its
    /// renormalized point light evaluated at the point): view-independent, so it changes
    /// between frames only when the light does.
    pub fn point_irradiance(&self, ctx: &GpuContext) -> Result<Vec<Vec3>, RenderError> {
        let world = self.scene.world_from_node();
        let read = self.method.sparse.read_points(ctx, &self.scene, &world)?;
        Ok(read
            .points
            .iter()
            .zip(&read.lights)
            .map(|(p, l)| {
                crate::vals::math::diffuse_point(
                    p.position,
                    p.normal,
                    l.diffuse_position,
                    l.diffuse,
                )
            })
            .collect())
    }

    /// The sparse method's report of the last frame (VAL counts, per-pass times).
    pub fn method_report(&self) -> serde_json::Map<String, serde_json::Value> {
        crate::frame::Method::report(&self.method)
    }

    /// Lights the object with `frame` seen from `world_from_camera` and composites it.
    pub fn render(
        &mut self,
        ctx: &GpuContext,
        frame: &RgbdFrame,
        world_from_camera: Mat4,
    ) -> Result<MrFrame, RenderError> {
        let k = self.intrinsics;
        if (frame.width, frame.height) != (k.width, k.height) {
            return Err(RenderError::Settings(format!(
                "the RGB-D frame is {}×{} but the intrinsics are for {}×{}",
                frame.width, frame.height, k.width, k.height
            )));
        }
        *self
            .slot
            .lock()
            .map_err(|_| RenderError::Settings("the RGB-D frame slot was poisoned".into()))? =
            Some((frame.clone(), world_from_camera));
        let camera = sensor_camera(&k, world_from_camera);
        let view = match self.view.take() {
            Some(mut v) => {
                v.camera = camera;
                v
            }
            None => View::new(ctx, "sensor", camera, (k.width, k.height), 1)?,
        };
        let world = self.scene.world_from_node();
        let recorded = record_frame(
            &mut self.method,
            ctx,
            &self.scene,
            &world,
            std::slice::from_ref(&view),
        )?;
        let (direct, indirect) = view.read(ctx, recorded.results[0].has_indirect())?;
        self.view = Some(view);
        let real_vals = self.method.rsm.read_count(ctx)?;
        let started = Instant::now();
        let composed = self.composite(frame, world_from_camera, &world, &direct, &indirect);
        Ok(MrFrame {
            composite: composed.0,
            object: composed.1,
            alpha: composed.2,
            indirect,
            differential: composed.3,
            timings: recorded.timings.merged(),
            real_vals,
            composite_ms: started.elapsed().as_secs_f64() * 1000.0,
        })
    }

    /// (composite, object layer, alpha, differential) on the CPU, ray traced against the
    /// virtual scene.
    fn composite(
        &self,
        frame: &RgbdFrame,
        world_from_camera: Mat4,
        world: &[Mat4],
        direct: &Image,
        indirect: &Image,
    ) -> (Image, Image, Vec<f32>, Image) {
        let k = self.intrinsics;
        let scale = self.settings.depth.real_scale;
        let tracer = Tracer::new(&self.scene, world);
        let lights = WorldLight::from_scene(&self.scene, world);
        let eye = world_from_camera.transform_point3(Vec3::ZERO);
        // The real surfaces' positions and normals: the surfel pass's CPU twin.
        let p = self.settings.depth.kernel_params(&k, world_from_camera);
        let filtered = math::bilateral(&frame.depth, &p);
        let surfels = math::surfels(&filtered, &frame.color, &p);
        let rays = self.settings.differential_rays;
        let bias = self.settings.depth_bias;
        let width = k.width as usize;
        let pixels: Vec<CompositePixel> = (0..frame.depth.len())
            .into_par_iter()
            .map(|i| {
                let (u, v) = ((i % width) as f32, (i / width) as f32);
                let photo = Vec3::from(frame.color[i]) * scale;
                let ray_camera = Vec3::new((u - k.cx) / k.fx, (v - k.cy) / k.fy, 1.0);
                let dir = world_from_camera.transform_vector3(ray_camera).normalize();
                let object_depth = tracer
                    .intersect(eye, dir, f32::INFINITY)
                    .map(|hit| hit.t * dir.dot(world_from_camera.z_axis.truncate()));
                let real_depth = frame.depth[i];
                let visible =
                    object_depth.is_some_and(|z| real_depth <= 0.0 || z < real_depth + bias);
                let object = Vec3::from_slice(&direct.pixels[i][..3])
                    + Vec3::from_slice(&indirect.pixels[i][..3]);
                let delta = if visible || rays == 0 || !surfels[i].is_valid() {
                    Vec3::ZERO
                } else {
                    let s = surfels[i].val;
                    let albedo = Vec3::from(frame.color[i]);
                    albedo / std::f32::consts::PI
                        * differential_irradiance(
                            &tracer, &lights, s.position, s.normal, scale, rays, i,
                        )
                };
                let composite = if visible { object } else { photo + delta };
                let alpha = visible as u32 as f32;
                (
                    composite.extend(1.0).to_array(),
                    (object * alpha).extend(alpha).to_array(),
                    alpha,
                    delta.extend(1.0).to_array(),
                )
            })
            .collect();
        let (w, h) = (k.width, k.height);
        (
            Image::from_rgba(w, h, pixels.iter().map(|p| p.0).collect()),
            Image::from_rgba(w, h, pixels.iter().map(|p| p.1).collect()),
            pixels.iter().map(|p| p.2).collect(),
            Image::from_rgba(w, h, pixels.iter().map(|p| p.3).collect()),
        )
    }
}

/// One pixel of the composite: (composite, object layer, alpha, differential).
type CompositePixel = ([f32; 4], [f32; 4], f32, [f32; 4]);

/// `ΔE` at a real surface point: the virtual lights' shadow plus the room's light the object
/// blocks, replaced by the light the object sends back (module docs).
fn differential_irradiance(
    tracer: &Tracer,
    lights: &[WorldLight],
    x: Vec3,
    n: Vec3,
    room_radiance: f32,
    rays: u32,
    pixel: usize,
) -> Vec3 {
    let origin = x + n * tracer.epsilon.max(1e-3);
    let mut delta = Vec3::ZERO;
    for light in lights {
        let (wi, irradiance) = light.incident(x);
        let cos = n.dot(wi);
        if cos > 0.0 && irradiance != Vec3::ZERO {
            let t_max = (light.position - origin).length();
            if !tracer.unoccluded(origin, wi, t_max) {
                delta -= irradiance * cos;
            }
        }
    }
    // Stratified cosine-weighted directions, rotated per pixel (Cranley–Patterson).
    let side = (rays as f32).sqrt().ceil() as u32;
    let shift = crate::sampling::Rng::new(7, pixel as u64, 0);
    let mut rng = shift;
    let (s1, s2) = (rng.next_f32(), rng.next_f32());
    let mut blocked = Vec3::ZERO;
    for j in 0..rays {
        let u1 = (((j % side) as f32 + s1) / side as f32).fract();
        let u2 = (((j / side) as f32 + s2) / (rays.div_ceil(side)) as f32).fract();
        let dir = crate::sampling::cosine_hemisphere(n, u1, u2);
        if let Some(hit) = tracer.intersect(origin, dir, f32::INFINITY) {
            let at = hit.position + hit.geometric_normal * tracer.epsilon.max(1e-4);
            let lit = tracer.direct_irradiance(at, hit.normal)
                + Vec3::splat(std::f32::consts::PI * room_radiance);
            let radiance = hit.rho_d / std::f32::consts::PI * lit + hit.emission;
            blocked += radiance - Vec3::splat(room_radiance);
        }
    }
    delta + blocked * (std::f32::consts::PI / rays as f32)
}

/// Folder layout of the bundled Open3D frames: `DIR/color`, `DIR/depth`, `DIR/trajectory.log`.
pub fn default_trajectory(dir: &Path) -> Option<PathBuf> {
    let p = dir.join("trajectory.log");
    p.is_file().then_some(p)
}

/// A horizontal real surface near the image centre (an upward-facing surfel, the one nearest
/// the point at 50 %, 80 % of the image): where `--place auto` stands the object.
pub fn find_floor_point(
    frame: &RgbdFrame,
    k: &Intrinsics,
    world_from_camera: Mat4,
) -> Option<Vec3> {
    let s = DepthValSettings::default();
    let p = s.kernel_params(k, world_from_camera);
    let surfels = math::surfels(&math::bilateral(&frame.depth, &p), &frame.color, &p);
    let target = (k.width as f32 * 0.5, k.height as f32 * 0.8);
    surfels
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_valid() && s.val.normal.y > 0.95)
        .min_by(|(a, _), (b, _)| {
            let d = |i: usize| {
                let (u, v) = ((i % k.width as usize) as f32, (i / k.width as usize) as f32);
                (u - target.0).powi(2) + (v - target.1).powi(2)
            };
            d(*a).total_cmp(&d(*b))
        })
        .map(|(_, s)| s.val.position)
}
