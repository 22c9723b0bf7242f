//! The scene placed in the world for ray tracing: world-space triangles in a BVH (the `obvhs`
//! crate's compressed wide BVH; flat regions merged by [`crate::scene::merge`], the same
//! surface and attributes with far fewer triangles), closest-hit and shadow queries, and the
//! material at a hit reduced to DESIGN §3's (ρ_d, ρ_s, k, emission) exactly as
//! `shaders/base/gbuffer.wgsl` does it (base colour, metallic-roughness, normal and emissive
//! textures; back faces shade with the flipped normal).

use std::time::Duration;

use glam::{Mat3, Mat4, Vec2, Vec3, Vec4};
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;

use crate::scene::emitters::{emission_at, emissive_triangles, EmissiveTriangle};
use crate::scene::merge::flat_region_indices;
use crate::scene::{Material, Scene};
use crate::shading::WorldLight;

/// The scene's emissive triangles for next-event estimation: a triangle picked with
/// probability ∝ its L_e·A (summed over channels), then a uniform point on it, so the
/// area density of a point is `p(tri) / A`.
pub struct EmitterSampler {
    pub triangles: Vec<EmissiveTriangle>,
    /// Normalized cumulative weights: triangle i covers (cdf[i−1], cdf[i]].
    cdf: Vec<f32>,
}

/// A point on an emitter drawn by [`EmitterSampler::sample`].
#[derive(Clone, Copy, Debug)]
pub struct EmitterPoint {
    pub position: Vec3,
    /// Unit normal of the emitting side.
    pub normal: Vec3,
    /// Emitted radiance at the point (emissive texture read there), W/(m²·sr).
    pub radiance: Vec3,
    /// Area density of the point, 1/m².
    pub pdf_area: f32,
}

impl EmitterSampler {
    pub fn new(scene: &Scene, world_from_node: &[Mat4]) -> Self {
        let triangles = emissive_triangles(scene, world_from_node);
        let mut cdf = Vec::with_capacity(triangles.len());
        let mut total = 0.0f64;
        for t in &triangles {
            total += t.weight() as f64;
            cdf.push(total);
        }
        let cdf = cdf.iter().map(|c| (c / total.max(1e-300)) as f32).collect();
        Self { triangles, cdf }
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// Probability of picking triangle `i`.
    fn pmf(&self, i: usize) -> f32 {
        let below = if i == 0 { 0.0 } else { self.cdf[i - 1] };
        self.cdf[i] - below
    }

    /// A point on the emitters from three uniform numbers in [0, 1).
    pub fn sample(&self, scene: &Scene, u: [f32; 3]) -> Option<EmitterPoint> {
        if self.is_empty() {
            return None;
        }
        let i = self
            .cdf
            .partition_point(|&c| c <= u[0])
            .min(self.cdf.len() - 1);
        let pmf = self.pmf(i);
        let t = &self.triangles[i];
        if pmf <= 0.0 {
            return None;
        }
        // Uniform on the triangle: b = (1 − √u1, √u1 (1 − u2), √u1 u2).
        let su = u[1].sqrt();
        let bary = Vec3::new(1.0 - su, su * (1.0 - u[2]), su * u[2]);
        let position = t.corners[0] * bary.x + t.corners[1] * bary.y + t.corners[2] * bary.z;
        let mesh = &scene.meshes[scene.instances[t.instance].mesh];
        Some(EmitterPoint {
            position,
            normal: t.normal,
            radiance: emission_at(scene, mesh, t.first_index, bary).max(Vec3::ZERO),
            pdf_area: pmf / t.area,
        })
    }
}

/// One instance's vertices in world space.
struct PlacedMesh {
    mesh: usize,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    /// World tangent xyz and handedness w; empty when the mesh has none.
    tangents: Vec<Vec4>,
}

/// Everything a ray needs to know about the surface it hit.
#[derive(Clone, Copy, Debug)]
pub struct Hit {
    pub t: f32,
    pub position: Vec3,
    /// Unit geometric normal, on the side the ray came from.
    pub geometric_normal: Vec3,
    /// Unit shading normal (interpolated, normal-mapped), flipped with the geometric one.
    pub normal: Vec3,
    pub rho_d: Vec3,
    pub rho_s: Vec3,
    pub k: f32,
    pub emission: Vec3,
}

/// World-space geometry, BVH, and lights of one frame.
pub struct Tracer<'a> {
    scene: &'a Scene,
    placed: Vec<PlacedMesh>,
    triangles: Vec<Triangle>,
    /// (placed mesh, first index into its mesh's entry of `indices`) per triangle.
    triangle_source: Vec<(u32, u32)>,
    /// Each scene mesh's triangles with its flat regions merged
    /// ([`crate::scene::merge::flat_region_indices`]): the same surface and attributes, far
    /// fewer triangles on the tessellated built-in scenes.
    indices: Vec<Vec<u32>>,
    bvh: Option<CwBvh>,
    /// Every light of the scene, emitter proxies included (the methods' view of the light).
    pub lights: Vec<WorldLight>,
    /// The emissive triangles themselves, for the reference's next-event estimation.
    pub emitters: EmitterSampler,
    /// Offset for secondary-ray origins, metres (scaled with the scene).
    pub epsilon: f32,
    /// Drop every material's specular lobe from the hits (`ρ_s = 0`): the light that the
    /// diffuse-only methods model, for comparing them like with like (glTF dielectrics
    /// reflect 4 % specularly, which on dark textures is a large share of their light).
    pub diffuse_only: bool,
}

impl<'a> Tracer<'a> {
    /// Places every instance by `world_from_node` and builds the BVH.
    pub fn new(scene: &'a Scene, world_from_node: &[Mat4]) -> Self {
        let indices: Vec<Vec<u32>> = scene
            .meshes
            .iter()
            .map(|mesh| {
                let textured = scene
                    .materials
                    .get(mesh.material)
                    .is_some_and(Material::has_textures);
                flat_region_indices(mesh, textured)
            })
            .collect();
        let mut placed = Vec::with_capacity(scene.instances.len());
        let mut triangles = Vec::new();
        let mut triangle_source = Vec::new();
        for inst in &scene.instances {
            let mesh = &scene.meshes[inst.mesh];
            let m = world_from_node[inst.node];
            let normal_from_model = Mat3::from_mat4(m).inverse().transpose();
            let linear = Mat3::from_mat4(m);
            let positions: Vec<Vec3> = mesh
                .positions
                .iter()
                .map(|p| m.transform_point3(*p))
                .collect();
            let normals: Vec<Vec3> = mesh
                .normals
                .iter()
                .map(|n| (normal_from_model * *n).normalize_or_zero())
                .collect();
            let tangents: Vec<Vec4> = mesh
                .tangents
                .iter()
                .map(|t| (linear * t.truncate()).extend(t.w))
                .collect();
            let index = placed.len() as u32;
            for (i, tri) in indices[inst.mesh].chunks_exact(3).enumerate() {
                let n = positions.len();
                if tri.iter().any(|&v| v as usize >= n) {
                    continue;
                }
                let [a, b, c] = [tri[0], tri[1], tri[2]].map(|v| positions[v as usize]);
                if !(a.is_finite() && b.is_finite() && c.is_finite()) {
                    continue;
                }
                triangles.push(Triangle {
                    v0: a.into(),
                    v1: b.into(),
                    v2: c.into(),
                });
                triangle_source.push((index, (i * 3) as u32));
            }
            placed.push(PlacedMesh {
                mesh: inst.mesh,
                positions,
                normals,
                tangents,
            });
        }
        let bounds = scene.world_bounds(world_from_node);
        let size = if bounds.is_empty() {
            1.0
        } else {
            bounds.extent().max_element().max(1e-3)
        };
        let bvh = (!triangles.is_empty()).then(|| {
            build_cwbvh_from_tris(
                &triangles,
                BvhBuildParams::medium_build(),
                &mut Duration::default(),
            )
        });
        Self {
            scene,
            placed,
            triangles,
            triangle_source,
            indices,
            bvh,
            lights: WorldLight::from_scene(scene, world_from_node),
            emitters: EmitterSampler::new(scene, world_from_node),
            epsilon: 1e-4 * size,
            diffuse_only: false,
        }
    }

    /// The scene the tracer places.
    pub fn scene(&self) -> &'a Scene {
        self.scene
    }

    /// Triangles in the BVH (after merging flat regions).
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// The BVH's triangles in world space: the scene's surface with its flat regions merged,
    /// for rasterizing depth maps.
    pub fn world_triangles(&self) -> Vec<[Vec3; 3]> {
        self.triangles
            .iter()
            .map(|t| [t.v0, t.v1, t.v2].map(Vec3::from))
            .collect()
    }

    /// Closest hit along `origin + t·dir`, t in (0, `t_max`).
    pub fn intersect(&self, origin: Vec3, dir: Vec3, t_max: f32) -> Option<Hit> {
        let bvh = self.bvh.as_ref()?;
        let ray = obvhs_ray(origin, dir, 0.0, t_max);
        let mut hit = RayHit::none();
        let found = bvh.ray_traverse(ray, &mut hit, |ray, id| {
            self.triangles[bvh.primitive_indices[id] as usize].intersect(ray)
        });
        if !found || !hit.t.is_finite() {
            return None;
        }
        let tri = bvh.primitive_indices[hit.primitive_id as usize] as usize;
        Some(self.surface(tri, origin, dir, hit.t))
    }

    /// True when nothing blocks the segment `origin + t·dir`, t in (0, `t_max`).
    pub fn unoccluded(&self, origin: Vec3, dir: Vec3, t_max: f32) -> bool {
        self.unoccluded_by(origin, dir, t_max, |_| true)
    }

    /// [`Tracer::unoccluded`] with the triangles of every instance `skip` names left out
    /// (indices into `Scene::instances`).
    pub fn unoccluded_except(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        skip: impl Fn(usize) -> bool,
    ) -> bool {
        // Every instance is placed, in order: the placed index is the instance's.
        self.unoccluded_by(origin, dir, t_max, |tri| {
            !skip(self.triangle_source[tri].0 as usize)
        })
    }

    /// The segment test over the triangles `blocks` accepts (indices into `triangles`).
    fn unoccluded_by(
        &self,
        origin: Vec3,
        dir: Vec3,
        t_max: f32,
        blocks: impl Fn(usize) -> bool,
    ) -> bool {
        let Some(bvh) = self.bvh.as_ref() else {
            return true;
        };
        if t_max <= 0.0 {
            return true;
        }
        let ray = obvhs_ray(origin, dir, 0.0, t_max);
        bvh.ray_traverse_miss(ray, |ray, id| {
            let tri = bvh.primitive_indices[id] as usize;
            if blocks(tri) {
                self.triangles[tri].intersect(ray)
            } else {
                f32::INFINITY
            }
        })
    }

    /// Irradiance from the punctual lights (emitter proxies included) at `x` on the side of
    /// the unit normal `n`, with ray-traced visibility (the shadow ray starts `epsilon` off the
    /// surface).
    pub fn direct_irradiance(&self, x: Vec3, n: Vec3) -> Vec3 {
        self.irradiance_from_lights(x, n, true)
    }

    /// [`Tracer::direct_irradiance`] without the emitter proxies: the reference's punctual
    /// lights (it reaches the emissive surfaces themselves by sampling them).
    pub fn punctual_irradiance(&self, x: Vec3, n: Vec3) -> Vec3 {
        self.irradiance_from_lights(x, n, false)
    }

    fn irradiance_from_lights(&self, x: Vec3, n: Vec3, with_proxies: bool) -> Vec3 {
        let origin = x + n * self.epsilon;
        let mut e = Vec3::ZERO;
        for light in &self.lights {
            if !with_proxies && light.kind.is_emission_proxy() {
                continue;
            }
            let (wi, irradiance) = light.incident(x);
            let cos = n.dot(wi);
            if cos <= 0.0 || irradiance == Vec3::ZERO {
                continue;
            }
            let t_max = match light.kind {
                crate::scene::LightKind::Directional => f32::INFINITY,
                _ => (light.position - origin).length() - self.epsilon,
            };
            if self.unoccluded(origin, wi, t_max) {
                e += irradiance * cos;
            }
        }
        e
    }

    /// Origin for a ray leaving `hit` toward `dir`: pushed off the surface on `dir`'s side.
    pub fn spawn(&self, hit: &Hit, dir: Vec3) -> Vec3 {
        let side = if hit.geometric_normal.dot(dir) >= 0.0 {
            1.0
        } else {
            -1.0
        };
        hit.position + hit.geometric_normal * (side * self.epsilon)
    }

    fn surface(&self, tri: usize, origin: Vec3, dir: Vec3, t: f32) -> Hit {
        let (placed_index, first) = self.triangle_source[tri];
        let placed = &self.placed[placed_index as usize];
        let mesh = &self.scene.meshes[placed.mesh];
        let indices = &self.indices[placed.mesh];
        let idx = [0, 1, 2].map(|j| indices[first as usize + j] as usize);
        let [a, b, c] = idx.map(|i| placed.positions[i]);
        let position = origin + dir * t;
        // Barycentrics of the hit point.
        let (e1, e2) = (b - a, c - a);
        let cross = e1.cross(e2);
        let area2 = cross.length_squared().max(1e-30);
        let rel = position - a;
        let w1 = rel.cross(e2).dot(cross) / area2;
        let w2 = e1.cross(rel).dot(cross) / area2;
        let bary = Vec3::new(1.0 - w1 - w2, w1, w2);
        let mut ng = cross.normalize_or_zero();
        // wgpu's default front face is counter-clockwise: the winding normal faces the viewer.
        let front = ng.dot(-dir) >= 0.0;
        let side = if front { 1.0 } else { -1.0 };
        ng *= side;
        let interp3 = |v: &[Vec3]| -> Option<Vec3> {
            (v.len() == placed.positions.len())
                .then(|| v[idx[0]] * bary.x + v[idx[1]] * bary.y + v[idx[2]] * bary.z)
        };
        let mut n = interp3(&placed.normals)
            .and_then(|n| n.try_normalize())
            .map(|n| n * side)
            .unwrap_or(ng);
        let uv = if mesh.uv0.len() == placed.positions.len() {
            mesh.uv0[idx[0]] * bary.x + mesh.uv0[idx[1]] * bary.y + mesh.uv0[idx[2]] * bary.z
        } else {
            Vec2::ZERO
        };
        let material = self
            .scene
            .materials
            .get(mesh.material)
            .cloned()
            .unwrap_or_default();
        let sample = |texture: Option<usize>, default: Vec4| -> Vec4 {
            texture
                .and_then(|t| self.scene.textures.get(t))
                .map(|t| t.sample_bilinear(uv))
                .unwrap_or(default)
        };
        // Normal map, as in gbuffer.wgsl.
        if material.normal_texture.is_some() && placed.tangents.len() == placed.positions.len() {
            let t4 = placed.tangents[idx[0]] * bary.x
                + placed.tangents[idx[1]] * bary.y
                + placed.tangents[idx[2]] * bary.z;
            let t_raw = t4.truncate();
            if t_raw.length() > 0.0 {
                if let Some(t) = (t_raw - n * n.dot(t_raw)).try_normalize() {
                    let w = if placed.tangents[idx[0]].w < 0.0 {
                        -1.0
                    } else {
                        1.0
                    };
                    let bt = n.cross(t) * w;
                    let tex = sample(material.normal_texture, Vec4::new(0.5, 0.5, 1.0, 1.0));
                    let tn = tex.truncate() * 2.0 - Vec3::ONE;
                    let tn = Vec3::new(
                        tn.x * material.normal_scale,
                        tn.y * material.normal_scale,
                        tn.z,
                    );
                    let mapped = t * tn.x + bt * tn.y + n * tn.z;
                    if mapped.length_squared() > 1e-12 {
                        n = mapped.normalize();
                    }
                }
            }
        }
        let emissive_tex = sample(material.emissive_texture, Vec4::ONE);
        let (base, metallic, roughness) = base_metallic_roughness(self.scene, &material, uv);
        Hit {
            t,
            position,
            geometric_normal: ng,
            normal: n,
            rho_d: Material::diffuse_albedo(base, metallic),
            rho_s: if self.diffuse_only {
                Vec3::ZERO
            } else {
                Material::specular_albedo(base, metallic, material.specular_factor)
            },
            k: Material::phong_exponent(roughness),
            emission: material.emissive * emissive_tex.truncate(),
        }
    }
}

/// Base colour, metallic and roughness of `material` at texture coordinate `uv`: the factors
/// times the base-colour and metallic-roughness textures (roughness in G, metallic in B), as
/// `shaders/base/gbuffer.wgsl` reads them. A glTF material without `metallicFactor` is
/// metallic 1 by default and takes its metalness from the texture alone (Sponza's materials
/// do): the factors by themselves would call it a metal with no diffuse albedo.
pub fn base_metallic_roughness(scene: &Scene, material: &Material, uv: Vec2) -> (Vec3, f32, f32) {
    let sample = |texture: Option<usize>| -> Vec4 {
        texture
            .and_then(|t| scene.textures.get(t))
            .map_or(Vec4::ONE, |t| t.sample_bilinear(uv))
    };
    let base = material.base_color.truncate() * sample(material.base_color_texture).truncate();
    let mr = sample(material.metallic_roughness_texture);
    let roughness = (material.roughness * mr.y).clamp(0.0, 1.0);
    let metallic = (material.metallic * mr.z).clamp(0.0, 1.0);
    (base, metallic, roughness)
}

/// Diffuse albedo ρ_d of material `material` of `scene` at texture coordinate `uv` (textures
/// included); the ρ_d a ray hit there reports.
pub fn diffuse_albedo_at(scene: &Scene, material: usize, uv: Vec2) -> Vec3 {
    let Some(m) = scene.materials.get(material) else {
        let (base, metallic, _) = base_metallic_roughness(scene, &Material::default(), uv);
        return Material::diffuse_albedo(base, metallic);
    };
    let (base, metallic, _) = base_metallic_roughness(scene, m, uv);
    Material::diffuse_albedo(base, metallic)
}

/// An obvhs ray. Its traversal finds nothing along a direction with a component of exactly
/// −0.0, while +0.0 and any tiny value work: a negated direction in an axis plane (the shadow
/// rays of a sun travelling along (0.5, −0.87, 0), whose `−direction` has z = −0.0) saw no
/// blocker, and the path tracer drew `plane-directional` without its shadow. Adding +0.0
/// turns −0.0 into +0.0 and leaves every other value as it is.
pub fn obvhs_ray(origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Ray {
    Ray::new(origin.into(), (dir + Vec3::ZERO).into(), t_min, t_max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shadow_rays_along_a_negated_axis_plane_direction_find_their_blocker() {
        // plane-directional: a 0.4 m slab at 0.5 m over a plane, the sun travelling along
        // (sin 30°, −cos 30°, 0): its shadow on the plane spans x ∈ [0.09, 0.49].
        let scene = crate::scene::builtin::load(
            "plane-directional",
            &crate::scene::builtin::BuiltinParams::default(),
        )
        .unwrap();
        let tracer = Tracer::new(&scene, &scene.world_from_node());
        let (wi, _) = tracer.lights[0].incident(Vec3::ZERO);
        assert!(wi.z == 0.0 && wi.z.is_sign_negative(), "the case: {wi}");
        for z in [-0.13f32, 0.0, 0.05] {
            let shadowed = tracer.direct_irradiance(Vec3::new(0.3, 0.0, z), Vec3::Y);
            let lit = tracer.direct_irradiance(Vec3::new(0.7, 0.0, z), Vec3::Y);
            assert_eq!(shadowed, Vec3::ZERO, "z {z}");
            assert!(lit.min_element() > 1.7, "z {z}: {lit}");
            let hit = tracer.intersect(Vec3::new(0.3, 1e-3, z), wi, f32::INFINITY);
            assert!(
                hit.is_some_and(|h| (h.position.y - 0.49).abs() < 1e-4),
                "z {z}"
            );
        }
    }
}
