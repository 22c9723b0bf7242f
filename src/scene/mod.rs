//! Scene model shared by every method: meshes in model space, node hierarchy with TRS animation,
//! metallic-roughness materials reduced to DESIGN §3's Lambert + normalized Phong, punctual lights
//! in radiometric units, and perspective cameras.
//!
//! Units: metres, seconds, linear RGB. Light `intensity × color` is radiant intensity in W/sr
//! (point, spot) or irradiance in W/m² (directional).

pub mod animation;
pub mod builtin;
pub mod edits;
pub mod emitters;
pub mod files;
pub mod gltf_import;
pub mod merge;
pub mod mesh;
pub mod mitsuba;
mod mitsuba_xml;
pub mod obj;
pub mod pick;
pub mod ply;
pub mod sanitize;
pub mod spectrum;

use glam::{Mat4, Quat, Vec2, Vec3, Vec4};

pub use animation::{Animation, Channel, Interpolation, Property};

/// Errors raised while building or loading a scene. Every variant names the file (or built-in)
/// and what is wrong with it.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("{path}: cannot read glTF: {message}")]
    Gltf { path: String, message: String },
    #[error("{path}: required glTF extension(s) not supported by valgi: {extensions}")]
    UnsupportedRequiredExtension { path: String, extensions: String },
    #[error("{path}: invalid geometry in {what}: {message}")]
    InvalidGeometry {
        path: String,
        what: String,
        message: String,
    },
    #[error("unknown built-in scene '{name}' (run `valgi scenes` for the list)")]
    UnknownBuiltin { name: String },
    #[error("{path}: {message}")]
    Other { path: String, message: String },
}

/// Translation, rotation, scale of a node relative to its parent.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    pub translation: Vec3,
    pub rotation: Quat,
    pub scale: Vec3,
}

impl Default for Trs {
    fn default() -> Self {
        Self {
            translation: Vec3::ZERO,
            rotation: Quat::IDENTITY,
            scale: Vec3::ONE,
        }
    }
}

impl Trs {
    pub fn matrix(&self) -> Mat4 {
        Mat4::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }

    /// A node pose at `eye` looking at `target` with +y up (a camera looks along its −z).
    pub fn looking_at(eye: Vec3, target: Vec3) -> Self {
        let forward = (target - eye).normalize();
        let right = forward.cross(Vec3::Y).normalize();
        let up = right.cross(forward);
        Self {
            translation: eye,
            rotation: Quat::from_mat3(&glam::Mat3::from_cols(right, up, -forward)),
            ..Self::default()
        }
    }
}

/// A node of the transform hierarchy. Parents always come before their children in
/// `Scene::nodes`, so world transforms are computed in one forward sweep.
#[derive(Clone, Debug)]
pub struct Node {
    pub name: String,
    pub parent: Option<usize>,
    pub local: Trs,
}

/// One triangle mesh with a single material, in model space.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub name: String,
    pub positions: Vec<Vec3>,
    /// Unit vertex normals (computed from the triangles when the source has none).
    pub normals: Vec<Vec3>,
    /// Tangent xyz and handedness w (MikkTSpace convention), present when the material has a
    /// normal map (computed when the source has none).
    pub tangents: Vec<Vec4>,
    pub uv0: Vec<Vec2>,
    /// Light-map UVs (glTF TEXCOORD_1) when the source has them.
    pub uv1: Option<Vec<Vec2>>,
    /// Triangle list, three indices per triangle, degenerate triangles already removed.
    pub indices: Vec<u32>,
    pub material: usize,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Bounds of the vertices in model space.
    pub fn model_bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in &self.positions {
            b.grow(*p);
        }
        b
    }
}

/// Which colour space a texture's texels are stored in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorSpace {
    Srgb,
    Linear,
}

/// An RGBA8 texture as decoded from the source file.
#[derive(Clone, Debug)]
pub struct Texture {
    pub name: String,
    pub width: u32,
    pub height: u32,
    pub rgba8: Vec<u8>,
    pub color_space: ColorSpace,
}

impl Texture {
    /// Bilinear lookup in linear RGBA with repeat wrapping (the GPU sampler's address mode,
    /// without its mip filtering). A texture whose texels are missing reads as white.
    pub fn sample_bilinear(&self, uv: Vec2) -> Vec4 {
        let (w, h) = (self.width.max(1) as i64, self.height.max(1) as i64);
        if self.rgba8.len() < (w * h * 4) as usize || !uv.is_finite() {
            return Vec4::ONE;
        }
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y * h as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let texel = |ix: i64, iy: i64| -> Vec4 {
            let (ix, iy) = (ix.rem_euclid(w), iy.rem_euclid(h));
            let o = ((iy * w + ix) * 4) as usize;
            let px = &self.rgba8[o..o + 4];
            let decode = |v: u8| {
                let c = v as f32 / 255.0;
                match self.color_space {
                    ColorSpace::Srgb => srgb_to_linear(c),
                    ColorSpace::Linear => c,
                }
            };
            Vec4::new(
                decode(px[0]),
                decode(px[1]),
                decode(px[2]),
                px[3] as f32 / 255.0,
            )
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = texel(x0, y0).lerp(texel(x0 + 1, y0), fx);
        let bottom = texel(x0, y0 + 1).lerp(texel(x0 + 1, y0 + 1), fx);
        top.lerp(bottom, fy)
    }
}

fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// glTF metallic-roughness material with the extensions valgi reads. The reduction to the
/// shading model of DESIGN §3 lives in [`Material::diffuse_albedo`] and friends, so every
/// method and the reference derive ρ_d, ρ_s and k the same way.
#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    pub base_color: Vec4,
    pub base_color_texture: Option<usize>,
    pub metallic: f32,
    pub roughness: f32,
    /// Texture with roughness in G and metallic in B (glTF convention).
    pub metallic_roughness_texture: Option<usize>,
    pub normal_texture: Option<usize>,
    pub normal_scale: f32,
    /// Emitted radiance, W/(m²·sr) per channel: `emissiveFactor × emissive_strength`.
    pub emissive: Vec3,
    pub emissive_texture: Option<usize>,
    /// `KHR_materials_specular.specularFactor`: scales ρ_s; 0 gives a pure Lambertian surface.
    pub specular_factor: f32,
    pub double_sided: bool,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            base_color: Vec4::ONE,
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            metallic_roughness_texture: None,
            normal_texture: None,
            normal_scale: 1.0,
            emissive: Vec3::ZERO,
            emissive_texture: None,
            specular_factor: 1.0,
            double_sided: false,
        }
    }
}

impl Material {
    /// True when any of the material's inputs is sampled from a texture (so its meshes' uvs
    /// are read at render time).
    pub fn has_textures(&self) -> bool {
        self.base_color_texture.is_some()
            || self.metallic_roughness_texture.is_some()
            || self.normal_texture.is_some()
            || self.emissive_texture.is_some()
    }

    /// A pure Lambertian material of albedo `rho` (no specular lobe).
    pub fn lambert(name: &str, rho: Vec3) -> Self {
        Self {
            name: name.into(),
            base_color: rho.extend(1.0),
            metallic: 0.0,
            roughness: 1.0,
            specular_factor: 0.0,
            ..Self::default()
        }
    }

    /// ρ_d = base·(1−metallic) (DESIGN §3), for given base colour and metallic values.
    pub fn diffuse_albedo(base: Vec3, metallic: f32) -> Vec3 {
        base * (1.0 - metallic)
    }

    /// ρ_s = specular_factor · mix(0.04, base, metallic) (DESIGN §3 and KHR_materials_specular).
    pub fn specular_albedo(base: Vec3, metallic: f32, specular_factor: f32) -> Vec3 {
        Vec3::splat(0.04).lerp(base, metallic) * specular_factor
    }

    /// Phong exponent k = clamp(2/α² − 2, 1, 10000) with α = roughness² (DESIGN §3).
    pub fn phong_exponent(roughness: f32) -> f32 {
        let alpha = (roughness * roughness).max(1e-4);
        (2.0 / (alpha * alpha) - 2.0).clamp(1.0, 10000.0)
    }
}

/// A punctual light's shape. Angles in radians.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    Point,
    Spot {
        inner_cone_angle: f32,
        outer_cone_angle: f32,
    },
    Directional,
    /// A proxy for a cluster of emissive triangles ([`emitters`]): a Lambertian emitter whose
    /// radiant intensity is `I0 · max(0, n̄·ω)` (`intensity × color` = I0, W/sr; n̄ = the
    /// light's direction), so its power is π·I0, the cluster's. Every method but the reference
    /// lights with it; the reference samples the emissive triangles themselves.
    Emitter,
}

impl LightKind {
    /// True for lights derived from emissive surfaces, which the reference skips (it samples
    /// the surfaces they stand for).
    pub fn is_emission_proxy(&self) -> bool {
        matches!(self, LightKind::Emitter)
    }

    /// Shadow-map (and RSM) layers the light needs: a cube's six faces for the lights that
    /// shine from a point into many directions, one view otherwise.
    pub fn shadow_layers(&self) -> u32 {
        match self {
            LightKind::Point | LightKind::Emitter => 6,
            LightKind::Spot { .. } | LightKind::Directional => 1,
        }
    }
}

/// A KHR_lights_punctual light attached to a node. It sits at the node's origin and points
/// down the node's −z axis.
#[derive(Clone, Debug)]
pub struct Light {
    pub name: String,
    pub node: usize,
    pub kind: LightKind,
    pub color: Vec3,
    /// W/sr (point, spot, emitter: I0) or W/m² (directional), multiplied by `color`.
    pub intensity: f32,
    /// Distance at which the light's influence reaches zero (KHR smooth window), when set.
    pub range: Option<f32>,
}

impl Light {
    /// Radiant intensity (W/sr) or irradiance (W/m²) per channel.
    pub fn radiometric(&self) -> Vec3 {
        self.color * self.intensity
    }
}

/// A perspective camera attached to a node; it looks down the node's −z axis with +y up.
#[derive(Clone, Debug)]
pub struct Camera {
    pub name: String,
    pub node: usize,
    /// Field of view, radians: vertical, or across the image axis `fov_axis` names.
    pub yfov: f32,
    /// The image axis `yfov` spans; the others follow from the aspect (Mitsuba's `fov_axis`).
    pub fov_axis: FovAxis,
    /// Width / height; `None` takes the output image's aspect.
    pub aspect: Option<f32>,
    pub znear: f32,
    pub zfar: Option<f32>,
}

/// The image axis a camera's field of view spans.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FovAxis {
    /// Top to bottom (glTF's `yfov`, the built-in cameras).
    #[default]
    Vertical,
    /// Left to right.
    Horizontal,
    /// The shorter of the two sides.
    Smaller,
    /// The longer of the two sides.
    Larger,
    /// Corner to corner.
    Diagonal,
}

impl Camera {
    /// The vertical field of view, radians, of an image of `aspect` (width / height): the
    /// angle along [`Self::fov_axis`] is kept and the vertical one follows (the tangents of the
    /// half-angles scale with the sides).
    pub fn vertical_fov(&self, aspect: f32) -> f32 {
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect
        } else {
            1.0
        };
        let tan_half = (self.yfov * 0.5).tan();
        let tan_half_vertical = match self.fov_axis {
            FovAxis::Vertical => return self.yfov,
            FovAxis::Horizontal => tan_half / aspect,
            FovAxis::Smaller if aspect < 1.0 => tan_half / aspect,
            FovAxis::Smaller => tan_half,
            FovAxis::Larger if aspect > 1.0 => tan_half / aspect,
            FovAxis::Larger => tan_half,
            FovAxis::Diagonal => tan_half / (1.0 + aspect * aspect).sqrt(),
        };
        2.0 * tan_half_vertical.atan()
    }
}

/// A mesh placed in the world by a node.
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    pub mesh: usize,
    pub node: usize,
}

/// Everything a method needs to render a frame.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub name: String,
    pub nodes: Vec<Node>,
    pub meshes: Vec<Mesh>,
    pub materials: Vec<Material>,
    pub textures: Vec<Texture>,
    pub instances: Vec<Instance>,
    pub lights: Vec<Light>,
    pub cameras: Vec<Camera>,
    pub animations: Vec<Animation>,
    /// Non-fatal problems found while loading (ignored extensions, repaired geometry, …).
    pub warnings: Vec<String>,
}

/// World-space placement of a camera, ready to build view and projection matrices.
#[derive(Clone, Copy, Debug)]
pub struct CameraView {
    pub world_from_view: Mat4,
    pub yfov: f32,
    pub aspect: f32,
    pub znear: f32,
    pub zfar: f32,
    /// An off-axis frustum (a CAVE wall seen from a tracked head): the view-space x and y of
    /// the frustum's left, right, bottom and top edges at distance 1 in front of the eye.
    /// `None` is the symmetric frustum of `yfov` and `aspect`.
    pub off_axis: Option<[f32; 4]>,
}

impl CameraView {
    /// Left, right, bottom and top of the frustum at unit distance (view space, −z forward).
    pub fn tangent_extents(&self) -> [f32; 4] {
        self.off_axis.unwrap_or_else(|| {
            let t = (self.yfov * 0.5).tan();
            [-t * self.aspect, t * self.aspect, -t, t]
        })
    }

    pub fn position(&self) -> Vec3 {
        self.world_from_view.w_axis.truncate()
    }

    pub fn view_from_world(&self) -> Mat4 {
        self.world_from_view.inverse()
    }

    /// Right-handed projection with depth in [0, 1] (wgpu's clip space).
    pub fn clip_from_view(&self) -> Mat4 {
        let Some([l, r, b, t]) = self.off_axis else {
            // glam 0.34 moved projections to `glam::camera`; `directx` is wgpu's convention
            // (right-handed view space, NDC z in [0, 1], y up), the old `Mat4::perspective_rh`.
            return glam::camera::rh::proj::directx::perspective(
                self.yfov,
                self.aspect,
                self.znear,
                self.zfar,
            );
        };
        // The general (off-axis) perspective with the same depth convention: x_ndc = ±1 on
        // the left/right edges, y_ndc = ±1 on bottom/top, z_ndc = 0 at znear and 1 at zfar.
        let (n, f) = (self.znear, self.zfar);
        let (sx, sy) = (2.0 / (r - l), 2.0 / (t - b));
        Mat4::from_cols(
            glam::Vec4::new(sx, 0.0, 0.0, 0.0),
            glam::Vec4::new(0.0, sy, 0.0, 0.0),
            glam::Vec4::new((r + l) / (r - l), (t + b) / (t - b), f / (n - f), -1.0),
            glam::Vec4::new(0.0, 0.0, n * f / (n - f), 0.0),
        )
    }

    pub fn clip_from_world(&self) -> Mat4 {
        self.clip_from_view() * self.view_from_world()
    }
}

/// Axis-aligned bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x
    }

    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    pub fn center(&self) -> Vec3 {
        (self.min + self.max) * 0.5
    }

    pub fn extent(&self) -> Vec3 {
        self.max - self.min
    }

    /// Bounds of this box after the affine transform `m` (of its eight corners).
    pub fn transformed(&self, m: Mat4) -> Aabb {
        let mut b = Aabb::EMPTY;
        if self.is_empty() {
            return b;
        }
        for i in 0..8 {
            let corner = Vec3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            );
            b.grow(m.transform_point3(corner));
        }
        b
    }

    pub fn union(&self, other: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }
}

impl Scene {
    /// A fingerprint of everything in the scene that what is made from it reads (an atlas
    /// bake, the GPU upload, the meshes' BVHs, the sparse points): the nodes, meshes,
    /// materials, textures, instances, lights and animations (the cameras, the name and the
    /// warnings are left out). Their derived `Debug` forms feed the hash, so a field added to
    /// any of them counts without this function knowing of it; the meshes' vertex arrays and
    /// the textures' bytes are hashed as bytes (spelled out, Sponza took 0.34 s; as bytes
    /// 0.05 s), the meshes taken apart field by field so that a field added to `Mesh` fails to
    /// compile here until it counts.
    pub fn content_key(&self) -> u64 {
        use std::hash::{Hash, Hasher};
        struct HashWriter<'h>(&'h mut std::collections::hash_map::DefaultHasher);
        impl std::fmt::Write for HashWriter<'_> {
            fn write_str(&mut self, s: &str) -> std::fmt::Result {
                s.hash(self.0);
                Ok(())
            }
        }
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        let _ = std::fmt::Write::write_fmt(
            &mut HashWriter(&mut hasher),
            format_args!(
                "{:?}",
                (
                    &self.nodes,
                    &self.materials,
                    &self.instances,
                    &self.lights,
                    &self.animations,
                )
            ),
        );
        for mesh in &self.meshes {
            let Mesh {
                name,
                positions,
                normals,
                tangents,
                uv0,
                uv1,
                indices,
                material,
            } = mesh;
            (name, material).hash(&mut hasher);
            let bytes: [&[u8]; 5] = [
                bytemuck::cast_slice(positions),
                bytemuck::cast_slice(normals),
                bytemuck::cast_slice(tangents),
                bytemuck::cast_slice(uv0),
                bytemuck::cast_slice(indices),
            ];
            bytes.hash(&mut hasher);
            uv1.as_deref()
                .map(bytemuck::cast_slice::<_, u8>)
                .hash(&mut hasher);
        }
        for texture in &self.textures {
            (texture.width, texture.height, &texture.rgba8).hash(&mut hasher);
            format!("{:?}", texture.color_space).hash(&mut hasher);
        }
        hasher.finish()
    }

    /// World transform of every node at animation time `time` (seconds). Animations override
    /// the animated TRS components of their target nodes; with no animations the result is the
    /// rest pose.
    pub fn world_from_node_at(&self, time: f32) -> Vec<Mat4> {
        let mut locals: Vec<Trs> = self.nodes.iter().map(|n| n.local).collect();
        for animation in &self.animations {
            animation.apply(time, &mut locals);
        }
        let mut world = Vec::with_capacity(self.nodes.len());
        for (i, node) in self.nodes.iter().enumerate() {
            let local = locals[i].matrix();
            let m = match node.parent {
                Some(p) => world[p] * local,
                None => local,
            };
            world.push(m);
        }
        world
    }

    /// Per node, whether an animation channel moves it or one of its ancestors.
    pub fn moving_nodes(&self) -> Vec<bool> {
        let mut moving = vec![false; self.nodes.len()];
        for channel in self.animations.iter().flat_map(|a| &a.channels) {
            if let Some(m) = moving.get_mut(channel.node) {
                *m = true;
            }
        }
        // Parents come before their children.
        for i in 0..self.nodes.len() {
            if let Some(p) = self.nodes[i].parent {
                moving[i] |= moving.get(p).copied().unwrap_or(false);
            }
        }
        moving
    }

    /// World transforms in the rest pose.
    pub fn world_from_node(&self) -> Vec<Mat4> {
        self.world_from_node_at(0.0)
    }

    /// Every instanced triangle in world space (triangles with an out-of-range or repeated
    /// index are skipped).
    pub fn world_triangles(&self, world_from_node: &[Mat4]) -> Vec<[Vec3; 3]> {
        let mut out = vec![];
        for inst in &self.instances {
            let mesh = &self.meshes[inst.mesh];
            let m = world_from_node[inst.node];
            for t in mesh.indices.chunks_exact(3) {
                let Some(corners) = mesh::triangle(t, mesh.positions.len()) else {
                    continue;
                };
                out.push(corners.map(|k| m.transform_point3(mesh.positions[k])));
            }
        }
        out
    }

    /// Bounds of all instanced geometry in world space.
    pub fn world_bounds(&self, world_from_node: &[Mat4]) -> Aabb {
        let mut b = Aabb::EMPTY;
        for inst in &self.instances {
            let m = world_from_node[inst.node];
            for p in &self.meshes[inst.mesh].positions {
                b.grow(m.transform_point3(*p));
            }
        }
        b
    }

    /// Bounds of the instances from precomputed model-space mesh bounds (`mesh_bounds[i]` for
    /// `meshes[i]`): eight corners per instance instead of every vertex, for per-frame use. It
    /// may be looser than [`Scene::world_bounds`] for rotated meshes, never tighter.
    pub fn instance_bounds(&self, mesh_bounds: &[Aabb], world_from_node: &[Mat4]) -> Aabb {
        self.instances
            .iter()
            .map(|inst| mesh_bounds[inst.mesh].transformed(world_from_node[inst.node]))
            .fold(Aabb::EMPTY, |a, b| a.union(&b))
    }

    pub fn triangle_count(&self) -> usize {
        self.instances
            .iter()
            .map(|i| self.meshes[i.mesh].triangle_count())
            .sum()
    }

    /// Duration of the longest animation, seconds (0 when there are none).
    pub fn animation_duration(&self) -> f32 {
        self.animations
            .iter()
            .map(|a| a.duration())
            .fold(0.0, f32::max)
    }

    /// The index of the camera `selector` names: a number is an index, anything else a name;
    /// `None` is the first camera. `None` when there is no such camera.
    pub fn camera_index(&self, selector: Option<&str>) -> Option<usize> {
        match selector {
            None => (!self.cameras.is_empty()).then_some(0),
            Some(sel) => match sel.parse::<usize>() {
                Ok(i) => (i < self.cameras.len()).then_some(i),
                Err(_) => self.cameras.iter().position(|c| c.name == sel),
            },
        }
    }

    /// Resolves a camera by name or index. `None` picks the scene's first camera, or a default
    /// camera framing the scene when it has none.
    pub fn camera_view(
        &self,
        selector: Option<&str>,
        output_aspect: f32,
        world_from_node: &[Mat4],
    ) -> Result<CameraView, SceneError> {
        let bounds = self.world_bounds(world_from_node);
        let found = self.camera_index(selector).map(|i| &self.cameras[i]);
        let camera = match selector {
            None => found,
            Some(sel) => {
                if found.is_none() {
                    let names: Vec<String> = self
                        .cameras
                        .iter()
                        .enumerate()
                        .map(|(i, c)| format!("{i}:{}", c.name))
                        .collect();
                    return Err(SceneError::Other {
                        path: self.name.clone(),
                        message: format!(
                            "no camera '{sel}' (cameras: {})",
                            if names.is_empty() {
                                "none".to_string()
                            } else {
                                names.join(", ")
                            }
                        ),
                    });
                }
                found
            }
        };
        let radius = if bounds.is_empty() {
            1.0
        } else {
            (bounds.extent().length() * 0.5).max(1e-3)
        };
        Ok(match camera {
            Some(c) => {
                let world_from_view = world_from_node[c.node];
                let eye = world_from_view.w_axis.truncate();
                // Without a far plane (infinite glTF projection) bound depth by the scene.
                let far_needed = if bounds.is_empty() {
                    1000.0
                } else {
                    (eye - bounds.center()).length() + radius
                };
                CameraView {
                    world_from_view: orthonormalize(world_from_view),
                    yfov: c.vertical_fov(c.aspect.unwrap_or(output_aspect)),
                    aspect: c.aspect.unwrap_or(output_aspect),
                    znear: c.znear.max(1e-4),
                    zfar: c.zfar.unwrap_or(far_needed * 1.5).max(c.znear * 2.0),
                    off_axis: None,
                }
            }
            None => default_camera(&bounds, radius, output_aspect),
        })
    }
}

/// Removes scale from a camera's transform so the view matrix is a rigid motion.
fn orthonormalize(m: Mat4) -> Mat4 {
    let (_, rotation, translation) = m.to_scale_rotation_translation();
    Mat4::from_rotation_translation(rotation, translation)
}

/// The vertical field of view of the framing default camera.
pub const DEFAULT_YFOV_DEGREES: f32 = 45.0;

/// A camera framing the bounds from the +z side, slightly above, with a 45° vertical fov.
fn default_camera(bounds: &Aabb, radius: f32, aspect: f32) -> CameraView {
    framing_camera(bounds, radius, aspect, DEFAULT_YFOV_DEGREES.to_radians())
}

/// A camera looking at the bounds' centre from the +z side, slightly above, with vertical
/// field of view `yfov`, as close as it can be while all eight corners of the box stay inside
/// the frustum: the box fills the frame's width or height instead of leaving the margin a
/// bounding sphere would.
pub fn framing_camera(bounds: &Aabb, radius: f32, aspect: f32, yfov: f32) -> CameraView {
    let center = if bounds.is_empty() {
        Vec3::ZERO
    } else {
        bounds.center()
    };
    let backward = Vec3::new(0.0, 0.35, 1.0).normalize();
    let right = Vec3::Y.cross(backward).normalize();
    let up = backward.cross(right);
    let tan_v = (yfov * 0.5).tan();
    let tan_h = aspect.max(1e-3) * tan_v;
    // A corner at offset c from the centre, seen from centre + backward·d, has view depth
    // d − c·backward; it is inside the frustum when |c·right| ≤ tan_h·depth and
    // |c·up| ≤ tan_v·depth, so the distance is the largest of those bounds over the corners.
    let half = if bounds.is_empty() {
        Vec3::splat(radius / 3f32.sqrt())
    } else {
        bounds.extent() * 0.5
    };
    let mut fit = 0.0f32;
    for i in 0..8 {
        let sign = |bit: usize| if i & bit == 0 { -1.0 } else { 1.0 };
        let c = half * Vec3::new(sign(1), sign(2), sign(4));
        let along = c.dot(backward);
        fit = fit
            .max(along + c.dot(right).abs() / tan_h)
            .max(along + c.dot(up).abs() / tan_v);
    }
    // 2 % of margin so silhouettes do not touch the border; never inside the box.
    let fit = (fit * 1.02).max(radius * 1.01);
    let eye = center + backward * fit;
    let view_from_world = glam::camera::rh::view::look_at_mat4(eye, center, Vec3::Y);
    CameraView {
        world_from_view: view_from_world.inverse(),
        yfov,
        aspect,
        znear: (fit - radius).max(radius * 1e-3),
        zfar: fit + radius * 2.0,
        off_axis: None,
    }
}

/// Scene file formats [`load`] reads, by extension (any case), as listed in its errors.
pub const SUPPORTED_FORMATS: &str =
    ".gltf, .glb (glTF 2.0), .obj (Wavefront with its MTL), .ply (ASCII or binary), \
     .xml (Mitsuba 0.5 and 3 scene subset)";

/// What [`load`] needs besides the spec.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoadParams {
    /// Longest triangle edge in world space, metres, for built-in and imported meshes alike.
    pub max_edge: f32,
    /// Admit buffer, image and mesh references outside the scene file's folder (absolute
    /// paths, `..`); device files and other non-regular files stay refused either way.
    pub allow_external_paths: bool,
    /// Most lights the scene's emissive triangles become ([`emitters`]), in total; 0 = none
    /// (emissive surfaces then light nothing but through the reference's paths).
    pub emitter_lights: u32,
}

impl Default for LoadParams {
    fn default() -> Self {
        Self {
            max_edge: builtin::BuiltinParams::default().max_edge,
            allow_external_paths: false,
            emitter_lights: emitters::DEFAULT_EMITTER_LIGHTS,
        }
    }
}

impl From<&builtin::BuiltinParams> for LoadParams {
    fn from(params: &builtin::BuiltinParams) -> Self {
        Self {
            max_edge: params.max_edge,
            ..Self::default()
        }
    }
}

impl LoadParams {
    fn policy(&self) -> files::ReadPolicy {
        files::ReadPolicy {
            allow_external_paths: self.allow_external_paths,
        }
    }
}

/// Loads a scene from a spec with the default [`LoadParams`] except `max_edge` (see
/// [`load_with`]).
pub fn load(spec: &str, params: &builtin::BuiltinParams) -> Result<Scene, SceneError> {
    load_with(spec, &LoadParams::from(params))
}

/// Loads a scene from a spec: a path with a scene-file extension (see [`SUPPORTED_FORMATS`],
/// any case) is imported from disk and its meshes are tessellated to `max_edge`; a bare name
/// without extension or folder names a built-in scene (see [`builtin::names`]). A path with any
/// other extension is an error that lists the supported formats.
pub fn load_with(spec: &str, params: &LoadParams) -> Result<Scene, SceneError> {
    Ok(load_choosing_max_edge(spec, params, |_| None)?.0)
}

/// Scene names that stand for a file of the shared data folder (benchmark scenes too large
/// for the repository), relative to the working directory.
pub const FILE_ALIASES: &[(&str, &str)] = &[("sponza", "../shared/data/sponza/Sponza.gltf")];

/// `spec` with a [`FILE_ALIASES`] name replaced by its file; an alias whose file is missing is
/// an error that names the path.
pub fn resolve_alias(spec: &str) -> Result<String, SceneError> {
    let Some((_, path)) = FILE_ALIASES.iter().find(|(name, _)| *name == spec) else {
        return Ok(spec.to_string());
    };
    if std::path::Path::new(path).is_file() {
        Ok((*path).to_string())
    } else {
        Err(SceneError::Other {
            path: (*path).to_string(),
            message: format!(
                "scene '{spec}' is this file, relative to the working directory, and it is not \
                 there (run from the repository root beside ../shared, or give the file's path)"
            ),
        })
    }
}

/// True when `spec` names a scene file rather than a built-in scene (see [`load_with`]).
pub fn is_file_spec(spec: &str) -> bool {
    std::path::Path::new(spec).extension().is_some() || spec.contains('/') || spec.contains('\\')
}

/// The tessellation [`load_choosing_max_edge`] settled on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EdgeChoice {
    /// What the `choose` callback returned. A built-in scene is built at `params.max_edge`
    /// first; a chosen edge, at least that long, then refines what is still coarser (walls
    /// of two triangles).
    pub chosen: Option<f32>,
    /// The world-space edge the meshes were refined to: the one asked for unless the triangle
    /// budget raised it; `None` when nothing was refined.
    pub used: Option<f32>,
}

/// [`load_with`], except that the tessellation may be chosen from the scene as read: `choose`
/// sees it before tessellation and returns the longest edge to refine to, or `None` for
/// `params.max_edge`. A built-in scene is built at `params.max_edge` (some of its meshes are
/// two triangles whatever it says: `bunny-box`'s walls, seed 002's scene, and `coarse-wall`'s
/// wall), then refined to the chosen edge, or `params.max_edge` if that is longer, so that a
/// method that lights vertices finds no mesh coarser than it would in an imported scene.
/// Returns the scene and the edges chosen and used.
pub fn load_choosing_max_edge(
    spec: &str,
    params: &LoadParams,
    choose: impl FnOnce(&Scene) -> Option<f32>,
) -> Result<(Scene, EdgeChoice), SceneError> {
    let resolved = resolve_alias(spec)?;
    let spec = resolved.as_str();
    let path = std::path::Path::new(spec);
    let extension = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    emitters::check_budget(params.emitter_lights).map_err(|message| SceneError::Other {
        path: spec.to_string(),
        message,
    })?;
    if !is_file_spec(spec) {
        let mut scene = builtin::load(
            spec,
            &builtin::BuiltinParams {
                max_edge: params.max_edge,
            },
        )?;
        // Never finer than the scene was built: the built-in scenes' measured figures are
        // at `params.max_edge`, and only the meshes built coarser need the chosen edge.
        let chosen = choose(&scene).map(|edge| edge.max(params.max_edge));
        let mut used = Some(params.max_edge);
        if let Some(edge) = chosen {
            let outcome = mesh::tessellate_instanced(&mut scene, edge, spec);
            scene.warnings.extend(outcome.warnings);
            // Meshes built finer than `edge` stay so: the longest edge left is `edge`.
            used = outcome.used_max_edge.or(used);
        }
        emitters::add_emitter_lights(&mut scene, params.emitter_lights);
        return Ok((scene, EdgeChoice { chosen, used }));
    }
    let policy = params.policy();
    let mut scene = match extension.as_deref() {
        Some("gltf" | "glb") => {
            if !path.is_file() {
                return Err(SceneError::Gltf {
                    path: spec.to_string(),
                    message: "file not found".into(),
                });
            }
            gltf_import::load_with(path, policy)?
        }
        Some("obj") => obj::load(path, policy)?,
        Some("ply") => ply::load(path)?,
        Some("xml") => mitsuba::load(path, policy)?,
        other => {
            return Err(SceneError::Other {
                path: spec.to_string(),
                message: format!(
                    "unsupported scene format {}; supported: {SUPPORTED_FORMATS}, or a built-in \
                     scene name (run `valgi scenes`)",
                    other.map_or("(no extension)".to_string(), |e| format!("'.{e}'"))
                ),
            })
        }
    };
    let chosen = choose(&scene);
    let outcome = mesh::tessellate_instanced(&mut scene, chosen.unwrap_or(params.max_edge), spec);
    scene.warnings.extend(outcome.warnings);
    emitters::add_emitter_lights(&mut scene, params.emitter_lights);
    Ok((
        scene,
        EdgeChoice {
            chosen,
            used: outcome.used_max_edge,
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cornell() -> Scene {
        builtin::load("cornell", &builtin::BuiltinParams::default()).unwrap()
    }

    #[test]
    fn cameras_are_chosen_by_name_index_or_default() {
        let scene = builtin::load("box-point", &builtin::BuiltinParams::default()).unwrap();
        let world = scene.world_from_node();
        let first = scene.camera_view(None, 1.5, &world).unwrap();
        let by_index = scene.camera_view(Some("1"), 1.5, &world).unwrap();
        let by_name = scene.camera_view(Some("toward +z"), 1.5, &world).unwrap();
        assert_eq!(first.position(), Vec3::new(0.0, 0.0, 0.9));
        assert_eq!(by_index.position(), by_name.position());
        // No aspect in the camera: the output's is used.
        assert_eq!(first.aspect, 1.5);
        let err = scene.camera_view(Some("nope"), 1.0, &world).unwrap_err();
        assert!(err.to_string().contains("toward -z"), "{err}");
    }

    #[test]
    fn a_chosen_edge_refines_built_in_meshes_built_coarser_and_no_others() {
        let params = LoadParams::default();
        let longest = |scene: &Scene, name: &str| {
            let mesh = scene.meshes.iter().find(|m| m.name == name).unwrap();
            (mesh::longest_edge(mesh), mesh.triangle_count())
        };
        // bunny-box's walls are two triangles (seed 002's scene) whatever `max_edge` says.
        let (built, _) = load_choosing_max_edge("bunny-box-empty", &params, |_| None).unwrap();
        assert_eq!(longest(&built, "floor").1, 2);
        let (refined, edges) =
            load_choosing_max_edge("bunny-box-empty", &params, |_| Some(0.3)).unwrap();
        let (edge, triangles) = longest(&refined, "floor");
        assert!(
            edge <= 0.3 && triangles > 100,
            "{edge} m, {triangles} triangles"
        );
        assert_eq!((edges.chosen, edges.used), (Some(0.3), Some(0.3)));
        // Never finer than the scene was built: Cornell at 5 cm stays as it is.
        let asked = params.max_edge * 0.25;
        let (cornell_refined, edges) =
            load_choosing_max_edge("cornell", &params, |_| Some(asked)).unwrap();
        assert_eq!(cornell_refined.triangle_count(), cornell().triangle_count());
        assert_eq!(edges.chosen, Some(params.max_edge));
    }

    #[test]
    fn default_camera_frames_the_whole_scene() {
        let mut scene = cornell();
        scene.cameras.clear();
        let world = scene.world_from_node();
        let bounds = scene.world_bounds(&world);
        for aspect in [0.5, 1.0, 2.0] {
            let view = scene.camera_view(None, aspect, &world).unwrap();
            let clip_from_world = view.clip_from_world();
            for i in 0..8 {
                let corner = Vec3::new(
                    if i & 1 == 0 {
                        bounds.min.x
                    } else {
                        bounds.max.x
                    },
                    if i & 2 == 0 {
                        bounds.min.y
                    } else {
                        bounds.max.y
                    },
                    if i & 4 == 0 {
                        bounds.min.z
                    } else {
                        bounds.max.z
                    },
                );
                let clip = clip_from_world * corner.extend(1.0);
                let ndc = clip.truncate() / clip.w;
                assert!(
                    clip.w > 0.0 && ndc.x.abs() <= 1.0 && ndc.y.abs() <= 1.0,
                    "corner {corner} outside the view at aspect {aspect}: {ndc}"
                );
                assert!(
                    (0.0..=1.0).contains(&ndc.z),
                    "corner {corner} clipped in depth"
                );
            }
        }
    }
}
