//! Emissive surfaces as lights. Every method lights with a few proxy lights that stand for the
//! scene's emissive triangles (glTF `emissiveFactor × emissive_strength × emissiveTexture`,
//! OBJ `Ke`, Mitsuba area emitters); the reference path tracer samples the triangles
//! themselves (`crate::trace::EmitterSampler`).
//!
//! A proxy is a Lambertian emitter: radiant intensity `I(ω) = I0 · max(0, n̄·ω)` with
//! `I0 = Σ L_e,i · A_i` over its triangles (per channel; `L_e` the triangle's emitted radiance
//! averaged over a few points, emissive texture included), so its power `π·I0` is the power
//! the triangles emit. It sits at the cluster's power-weighted centroid, moved along n̄ just in
//! front of every triangle of the cluster (so that they cannot shadow it), on a new child node
//! of the instance's node: animation carries it along.
//!
//! A triangle emits from its front side (counter-clockwise winding, as the GPU rasterizes
//! it), and from both sides when its material is double-sided.

use glam::{Mat3, Mat4, Quat, Vec3};

use super::{mesh, Aabb, Light, LightKind, Mesh, Node, Scene, Trs};

/// Proxy lights a scene gets by default.
pub const DEFAULT_EMITTER_LIGHTS: u32 = 8;
/// Most proxy lights a scene may ask for: each takes six shadow-map layers.
pub const MAX_EMITTER_LIGHTS: u32 = 64;

/// Triangles whose normals are within this angle of a facing group's first triangle join it.
const FACING_COS: f32 = 0.866; // cos 30°

/// Barycentric points at which a triangle's emission is averaged (the centroid and the
/// midpoints toward each corner).
const AVERAGE_POINTS: [[f32; 3]; 4] = [
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
    [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
];

/// Checks a proxy-light budget (the `--emitter-lights` option).
pub fn check_budget(budget: u32) -> Result<(), String> {
    if budget > MAX_EMITTER_LIGHTS {
        return Err(format!(
            "--emitter-lights {budget}: must be 0..={MAX_EMITTER_LIGHTS} (0 turns emissive \
             surfaces' light off; each proxy light takes six shadow-map layers)"
        ));
    }
    Ok(())
}

/// One emitting side of an instanced triangle, in world space.
#[derive(Clone, Copy, Debug)]
pub struct EmissiveTriangle {
    pub instance: usize,
    /// Index of the triangle's first vertex index in its mesh's `indices`.
    pub first_index: usize,
    pub corners: [Vec3; 3],
    /// Unit normal of the emitting side.
    pub normal: Vec3,
    /// World-space area, m².
    pub area: f32,
    /// Emitted radiance averaged over the triangle, W/(m²·sr) per channel.
    pub radiance: Vec3,
}

impl EmissiveTriangle {
    /// The triangle's share of a proxy's I0: `L_e · A`, W/sr per channel.
    pub fn intensity(&self) -> Vec3 {
        self.radiance * self.area
    }

    pub fn centroid(&self) -> Vec3 {
        (self.corners[0] + self.corners[1] + self.corners[2]) / 3.0
    }

    /// A scalar weight for sampling and clustering: the sum of the channels of `L_e · A`.
    pub fn weight(&self) -> f32 {
        let i = self.intensity();
        i.x + i.y + i.z
    }
}

/// Emitted radiance of `mesh`'s triangle starting at `first_index` at barycentrics `bary`:
/// the material's emission times its emissive texture at the interpolated uv0, as the G-buffer
/// and the reference's hits read it.
pub fn emission_at(scene: &Scene, mesh: &Mesh, first_index: usize, bary: Vec3) -> Vec3 {
    let Some(material) = scene.materials.get(mesh.material) else {
        return Vec3::ZERO;
    };
    let Some(texture) = material
        .emissive_texture
        .and_then(|t| scene.textures.get(t))
    else {
        return material.emissive;
    };
    let tri = &mesh.indices[first_index..first_index + 3];
    let uv = if tri.iter().all(|&i| (i as usize) < mesh.uv0.len()) {
        let [a, b, c] = [0, 1, 2].map(|k| mesh.uv0[tri[k] as usize]);
        a * bary.x + b * bary.y + c * bary.z
    } else {
        glam::Vec2::ZERO
    };
    material.emissive * texture.sample_bilinear(uv).truncate()
}

/// Every emitting triangle side of the scene placed by `world_from_node` (triangles whose
/// emission is zero, negative or not finite are left out, and so are degenerate ones).
pub fn emissive_triangles(scene: &Scene, world_from_node: &[Mat4]) -> Vec<EmissiveTriangle> {
    let mut out = vec![];
    for (instance, inst) in scene.instances.iter().enumerate() {
        let Some(mesh) = scene.meshes.get(inst.mesh) else {
            continue;
        };
        let Some(material) = scene.materials.get(mesh.material) else {
            continue;
        };
        if !material.emissive.is_finite() || material.emissive.max_element() <= 0.0 {
            continue;
        }
        let Some(m) = world_from_node.get(inst.node) else {
            continue;
        };
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let Some(corners) = mesh::triangle(tri, mesh.positions.len()) else {
                continue;
            };
            let corners = corners.map(|k| m.transform_point3(mesh.positions[k]));
            let cross = (corners[1] - corners[0]).cross(corners[2] - corners[0]);
            let area = 0.5 * cross.length();
            if !area.is_finite() || area <= 0.0 {
                continue;
            }
            let first_index = t * 3;
            let radiance = AVERAGE_POINTS
                .iter()
                .map(|b| emission_at(scene, mesh, first_index, Vec3::from_array(*b)))
                .sum::<Vec3>()
                / AVERAGE_POINTS.len() as f32;
            let radiance = radiance.max(Vec3::ZERO);
            if !radiance.is_finite() || radiance.max_element() <= 0.0 {
                continue;
            }
            let normal = cross / (2.0 * area);
            let front = EmissiveTriangle {
                instance,
                first_index,
                corners,
                normal,
                area,
                radiance,
            };
            out.push(front);
            if material.double_sided {
                out.push(EmissiveTriangle {
                    normal: -normal,
                    ..front
                });
            }
        }
    }
    out
}

/// One proxy light's cluster of emissive triangles, in world space.
#[derive(Clone, Debug)]
pub struct EmitterCluster {
    pub instance: usize,
    /// Indices into the triangle list the clusters were built from.
    pub triangles: Vec<usize>,
    /// I0 = Σ L_e·A, W/sr per channel.
    pub intensity: Vec3,
    /// Unit mean emitting normal n̄ (weighted by each triangle's L_e·A).
    pub normal: Vec3,
    /// Where the proxy sits: the weighted centroid, moved along n̄ in front of every triangle.
    pub position: Vec3,
}

impl EmitterCluster {
    /// Radiant power π·I0, W per channel.
    pub fn power(&self) -> Vec3 {
        self.intensity * std::f32::consts::PI
    }
}

/// The clusters and what the budget left out.
#[derive(Clone, Debug, Default)]
pub struct Clustering {
    pub clusters: Vec<EmitterCluster>,
    /// Facing groups that got no light (more instances or facings than the budget).
    pub dropped_groups: usize,
    /// Share of the emitted power (summed over channels) of the dropped groups.
    pub dropped_power_fraction: f32,
}

/// A working cluster: its triangles and their sums.
#[derive(Clone, Debug)]
struct Group {
    instance: usize,
    triangles: Vec<usize>,
    weight: f32,
    intensity: Vec3,
    /// Σ weight · normal and Σ weight · centroid.
    normal_sum: Vec3,
    centroid_sum: Vec3,
    /// Bounds of the triangles' centroids.
    centroid_bounds: Aabb,
}

impl Group {
    fn new(instance: usize) -> Self {
        Self {
            instance,
            triangles: vec![],
            weight: 0.0,
            intensity: Vec3::ZERO,
            normal_sum: Vec3::ZERO,
            centroid_sum: Vec3::ZERO,
            centroid_bounds: Aabb::EMPTY,
        }
    }

    fn of(instance: usize, triangles: &[usize], all: &[EmissiveTriangle]) -> Self {
        let mut g = Self::new(instance);
        for &t in triangles {
            g.add(t, &all[t]);
        }
        g
    }

    fn add(&mut self, index: usize, t: &EmissiveTriangle) {
        let w = t.weight();
        self.triangles.push(index);
        self.weight += w;
        self.intensity += t.intensity();
        self.normal_sum += t.normal * w;
        self.centroid_sum += t.centroid() * w;
        self.centroid_bounds.grow(t.centroid());
    }

    fn merge(&mut self, other: Group) {
        self.triangles.extend(other.triangles);
        self.weight += other.weight;
        self.intensity += other.intensity;
        self.normal_sum += other.normal_sum;
        self.centroid_sum += other.centroid_sum;
        self.centroid_bounds = self.centroid_bounds.union(&other.centroid_bounds);
    }

    fn mean_normal(&self, all: &[EmissiveTriangle]) -> Vec3 {
        self.normal_sum.try_normalize().unwrap_or_else(|| {
            // Opposing normals cancelled: fall back on the heaviest triangle's.
            let heaviest = self
                .triangles
                .iter()
                .max_by(|a, b| all[**a].weight().total_cmp(&all[**b].weight()));
            heaviest.map_or(Vec3::Y, |&t| all[t].normal)
        })
    }

    /// How much splitting this group would improve the approximation: power × size.
    fn split_priority(&self) -> f32 {
        if self.triangles.len() < 2 || self.centroid_bounds.extent().max_element() <= 0.0 {
            return 0.0;
        }
        self.weight * self.centroid_bounds.extent().length()
    }

    /// Splits along the longest axis of the centroid bounds at the weighted median.
    fn split(self, all: &[EmissiveTriangle]) -> (Group, Group) {
        let extent = self.centroid_bounds.extent();
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        let mut sorted = self.triangles.clone();
        sorted.sort_by(|a, b| all[*a].centroid()[axis].total_cmp(&all[*b].centroid()[axis]));
        let mut cumulative = 0.0;
        let mut cut = sorted.len() / 2;
        for (i, &t) in sorted.iter().enumerate() {
            cumulative += all[t].weight();
            if cumulative >= self.weight * 0.5 {
                cut = i + 1;
                break;
            }
        }
        let cut = cut.clamp(1, sorted.len() - 1);
        (
            Group::of(self.instance, &sorted[..cut], all),
            Group::of(self.instance, &sorted[cut..], all),
        )
    }

    fn cluster(&self, all: &[EmissiveTriangle]) -> EmitterCluster {
        let normal = self.mean_normal(all);
        let centroid = if self.weight > 0.0 {
            self.centroid_sum / self.weight
        } else {
            self.centroid_bounds.center()
        };
        let mut ahead = 0.0f32;
        let mut bounds = Aabb::EMPTY;
        for &t in &self.triangles {
            for c in all[t].corners {
                ahead = ahead.max(normal.dot(c - centroid));
                bounds.grow(c);
            }
        }
        // A tiny gap beyond the frontmost corner, relative to the cluster's size.
        let gap = (1e-3 * bounds.extent().length()).max(1e-5);
        EmitterCluster {
            instance: self.instance,
            triangles: self.triangles.clone(),
            intensity: self.intensity,
            normal,
            position: centroid + normal * (ahead + gap),
        }
    }
}

/// Clusters emissive triangles into at most `budget` groups: first by instance and facing (a
/// triangle joins its instance's first group whose first normal is within 30°), so that the
/// faces of an emissive cube stay apart; over budget, the weakest instances are dropped until
/// each remaining one can keep a light, then the two most alike facings of one instance merge;
/// under budget,
/// the group with the largest power × size splits along its longest axis at its power median,
/// until the budget is reached or nothing can be split.
pub fn cluster(triangles: &[EmissiveTriangle], budget: u32) -> Clustering {
    let budget = budget as usize;
    if budget == 0 || triangles.is_empty() {
        return Clustering::default();
    }
    // Facing groups, per instance in first-seen order.
    let mut per_instance: Vec<Vec<(Vec3, Group)>> = vec![];
    let mut slot_of_instance = std::collections::HashMap::new();
    for (i, t) in triangles.iter().enumerate() {
        let slot = *slot_of_instance.entry(t.instance).or_insert_with(|| {
            per_instance.push(vec![]);
            per_instance.len() - 1
        });
        let groups = &mut per_instance[slot];
        match groups
            .iter_mut()
            .find(|(first, _)| first.dot(t.normal) >= FACING_COS)
        {
            Some((_, g)) => g.add(i, t),
            None => {
                let mut g = Group::new(t.instance);
                g.add(i, t);
                groups.push((t.normal, g));
            }
        }
    }
    let mut per_instance: Vec<Vec<Group>> = per_instance
        .into_iter()
        .map(|gs| gs.into_iter().map(|(_, g)| g).collect())
        .collect();
    let total_weight: f32 = triangles.iter().map(EmissiveTriangle::weight).sum();
    let mut dropped_groups = 0;
    let mut dropped_weight = 0.0f32;
    let mut count: usize = per_instance.iter().map(Vec::len).sum();
    // Every instance keeps at least one light, so more instances than lights drop the weakest.
    let mut instances_alive = per_instance.iter().filter(|g| !g.is_empty()).count();
    while instances_alive > budget {
        let weakest = per_instance
            .iter()
            .enumerate()
            .filter(|(_, g)| !g.is_empty())
            .min_by(|a, b| {
                let wa: f32 = a.1.iter().map(|g| g.weight).sum();
                let wb: f32 = b.1.iter().map(|g| g.weight).sum();
                wa.total_cmp(&wb)
            })
            .map(|(i, _)| i)
            .expect("an instance is alive");
        let groups = std::mem::take(&mut per_instance[weakest]);
        dropped_groups += groups.len();
        dropped_weight += groups.iter().map(|g| g.weight).sum::<f32>();
        count -= groups.len();
        instances_alive -= 1;
    }
    while count > budget {
        // The most alike pair of facings within one instance (ties: the weaker pair). Opposing
        // facings merge only when nothing else is left: their lobe is a poor fit, but the
        // power stays.
        let mut best: Option<(usize, usize, usize, f32, f32)> = None;
        for (s, groups) in per_instance.iter().enumerate() {
            let normals: Vec<Vec3> = groups.iter().map(|g| g.mean_normal(triangles)).collect();
            for a in 0..groups.len() {
                for b in a + 1..groups.len() {
                    let alike = normals[a].dot(normals[b]);
                    let weight = groups[a].weight + groups[b].weight;
                    let better = match best {
                        None => true,
                        Some((_, _, _, best_alike, best_weight)) => {
                            alike > best_alike + 1e-4
                                || (alike > best_alike - 1e-4 && weight < best_weight)
                        }
                    };
                    if better {
                        best = Some((s, a, b, alike, weight));
                    }
                }
            }
        }
        let (s, a, b, _, _) = best.expect("more groups than instances means a pair exists");
        let other = per_instance[s].remove(b);
        per_instance[s][a].merge(other);
        count -= 1;
    }
    let mut groups: Vec<Group> = per_instance.into_iter().flatten().collect();
    while groups.len() < budget {
        let Some((i, priority)) = groups
            .iter()
            .map(Group::split_priority)
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
        else {
            break;
        };
        if priority <= 0.0 {
            break;
        }
        let (a, b) = groups.swap_remove(i).split(triangles);
        groups.push(a);
        groups.push(b);
    }
    Clustering {
        clusters: groups.iter().map(|g| g.cluster(triangles)).collect(),
        dropped_groups,
        dropped_power_fraction: if total_weight > 0.0 {
            dropped_weight / total_weight
        } else {
            0.0
        },
    }
}

/// Adds up to `budget` proxy lights for the scene's emissive triangles (in the rest pose), each
/// on a new child node of its instance's node; warns when the budget leaves emitters dark.
pub fn add_emitter_lights(scene: &mut Scene, budget: u32) {
    if budget == 0 {
        return;
    }
    let world_from_node = scene.world_from_node();
    let triangles = emissive_triangles(scene, &world_from_node);
    let clustering = cluster(&triangles, budget);
    if clustering.dropped_groups > 0 {
        scene.warnings.push(format!(
            "emissive surfaces: {} emitting group(s) ({:.1}% of the emitted power) get no light \
             within the budget of {budget} emitter lights (raise --emitter-lights, up to \
             {MAX_EMITTER_LIGHTS})",
            clustering.dropped_groups,
            clustering.dropped_power_fraction * 100.0
        ));
    }
    for (k, cluster) in clustering.clusters.iter().enumerate() {
        let instance = scene.instances[cluster.instance];
        let parent = instance.node;
        let world_from_parent = world_from_node[parent];
        if world_from_parent.determinant().abs() <= f32::MIN_POSITIVE {
            continue;
        }
        let parent_from_world = world_from_parent.inverse();
        // The light shines down its node's −z axis: rotate −z onto n̄ as the parent sees it.
        let axis_in_parent = (Mat3::from_mat4(parent_from_world) * cluster.normal)
            .try_normalize()
            .unwrap_or(Vec3::NEG_Z);
        let node = scene.nodes.len();
        let parent_name = scene.nodes[parent].name.clone();
        scene.nodes.push(Node {
            name: format!("{parent_name}/emitter {k}"),
            parent: Some(parent),
            local: Trs {
                translation: parent_from_world.transform_point3(cluster.position),
                rotation: Quat::from_rotation_arc(Vec3::NEG_Z, axis_in_parent),
                scale: Vec3::ONE,
            },
        });
        let material = scene
            .meshes
            .get(instance.mesh)
            .and_then(|m| scene.materials.get(m.material))
            .map_or("?", |m| m.name.as_str());
        let peak = cluster.intensity.max_element();
        scene.lights.push(Light {
            name: format!("emitter {k} ({material})"),
            node,
            kind: LightKind::Emitter,
            color: cluster.intensity / peak,
            intensity: peak,
            range: None,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Material};

    /// A scene of one mesh per `(faces, material)`, each its own instance at the origin.
    fn scene_of(meshes: Vec<Mesh>, materials: Vec<Material>) -> Scene {
        let mut scene = Scene {
            name: "test".into(),
            materials,
            ..Scene::default()
        };
        for (i, mesh) in meshes.into_iter().enumerate() {
            scene.nodes.push(Node {
                name: format!("node {i}"),
                parent: None,
                local: Trs::default(),
            });
            scene.meshes.push(mesh);
            scene.instances.push(Instance { mesh: i, node: i });
        }
        scene
    }

    /// A unit cube's six faces (outward, counter-clockwise), each face split into 2×2 quads.
    fn cube(material: usize) -> Mesh {
        let mut mesh = Mesh {
            name: "cube".into(),
            material,
            ..Mesh::default()
        };
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let mut n = Vec3::ZERO;
                n[axis] = sign;
                let u =
                    Vec3::from_array(std::array::from_fn(|k| (k == (axis + 1) % 3) as u32 as f32));
                let v = n.cross(u);
                for (i, j) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                    let base = mesh.positions.len() as u32;
                    let (a, b) = (i as f32 * 0.5 - 0.5, j as f32 * 0.5 - 0.5);
                    for (du, dv) in [(0.0, 0.0), (0.5, 0.0), (0.5, 0.5), (0.0, 0.5)] {
                        mesh.positions.push(n * 0.5 + u * (a + du) + v * (b + dv));
                        mesh.normals.push(n);
                    }
                    mesh.indices
                        .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
                }
            }
        }
        mesh
    }

    fn emissive(name: &str, radiance: Vec3) -> Material {
        Material {
            emissive: radiance,
            ..Material::lambert(name, Vec3::splat(0.5))
        }
    }

    #[test]
    fn winding_is_front_facing() {
        let scene = scene_of(vec![cube(0)], vec![emissive("e", Vec3::ONE)]);
        for t in emissive_triangles(&scene, &scene.world_from_node()) {
            // The cube's faces point outward.
            assert!(t.normal.dot(t.centroid()) > 0.49, "{t:?}");
        }
    }

    #[test]
    fn cube_faces_land_in_separate_clusters() {
        let scene = scene_of(vec![cube(0)], vec![emissive("e", Vec3::ONE)]);
        let triangles = emissive_triangles(&scene, &scene.world_from_node());
        assert_eq!(triangles.len(), 6 * 8);
        for budget in [6, 8, 12] {
            let clustering = cluster(&triangles, budget);
            assert_eq!(clustering.clusters.len(), budget as usize);
            assert_eq!(clustering.dropped_groups, 0);
            for c in &clustering.clusters {
                // Every triangle of a cluster faces the way the cluster does.
                for &t in &c.triangles {
                    assert!(triangles[t].normal.dot(c.normal) > 0.999, "budget {budget}");
                }
                // In front of all of its triangles.
                for &t in &c.triangles {
                    for corner in triangles[t].corners {
                        assert!(c.normal.dot(c.position - corner) > 0.0);
                    }
                }
            }
        }
    }

    #[test]
    fn budget_is_honoured_and_power_preserved() {
        let meshes = vec![cube(0), cube(1), cube(2)];
        let materials = vec![
            emissive("a", Vec3::new(1.0, 2.0, 3.0)),
            emissive("b", Vec3::splat(0.5)),
            emissive("c", Vec3::splat(4.0)),
        ];
        let scene = scene_of(meshes, materials);
        let triangles = emissive_triangles(&scene, &scene.world_from_node());
        let emitted: Vec3 = triangles.iter().map(|t| t.intensity()).sum::<Vec3>() * PI;
        for budget in [3, 5, 8, 18, 30] {
            let clustering = cluster(&triangles, budget);
            assert!(clustering.clusters.len() <= budget as usize);
            assert_eq!(clustering.dropped_groups, 0, "budget {budget}");
            let power: Vec3 = clustering.clusters.iter().map(|c| c.power()).sum();
            assert!(
                (power - emitted).abs().max_element() < 1e-4 * emitted.max_element(),
                "budget {budget}: {power} vs {emitted}"
            );
            // Every triangle in exactly one cluster.
            let mut seen: Vec<usize> = clustering
                .clusters
                .iter()
                .flat_map(|c| c.triangles.iter().copied())
                .collect();
            seen.sort_unstable();
            assert_eq!(seen, (0..triangles.len()).collect::<Vec<_>>());
        }
        // Fewer lights than instances: the weakest cube is dropped, and said so.
        let clustering = cluster(&triangles, 2);
        assert_eq!(clustering.clusters.len(), 2);
        assert!(clustering.clusters.iter().all(|c| c.instance != 1));
        // All six facings of the weakest cube.
        assert_eq!(clustering.dropped_groups, 6);
        let share = (0.5 * 3.0) / (6.0 + 1.5 + 12.0);
        assert!((clustering.dropped_power_fraction - share).abs() < 1e-5);
    }

    const PI: f32 = std::f32::consts::PI;

    #[test]
    fn lights_hang_on_child_nodes_and_follow_their_instance() {
        let mut scene = scene_of(vec![cube(0)], vec![emissive("e", Vec3::ONE)]);
        scene.nodes[0].local.translation = Vec3::new(1.0, 2.0, 3.0);
        add_emitter_lights(&mut scene, 6);
        assert_eq!(scene.lights.len(), 6);
        let world = scene.world_from_node();
        for light in &scene.lights {
            assert_eq!(light.kind, LightKind::Emitter);
            assert_eq!(scene.nodes[light.node].parent, Some(0));
            let m = world[light.node];
            let axis = m.transform_vector3(Vec3::NEG_Z).normalize();
            let offset = m.transform_point3(Vec3::ZERO) - Vec3::new(1.0, 2.0, 3.0);
            // A face light sits just outside its face's centre, pointing out of it.
            assert!((offset - axis * 0.5).length() < 0.01, "{offset} {axis}");
            assert!((light.radiometric() - Vec3::ONE).abs().max_element() < 1e-5);
        }
        // Off: no lights.
        let mut off = scene_of(vec![cube(0)], vec![emissive("e", Vec3::ONE)]);
        add_emitter_lights(&mut off, 0);
        assert!(off.lights.is_empty());
        assert!(check_budget(MAX_EMITTER_LIGHTS + 1).is_err());
    }

    #[test]
    fn the_emissive_texture_scales_the_intensity() {
        let mut mesh = cube(0);
        mesh.uv0 = vec![glam::Vec2::splat(0.25); mesh.positions.len()];
        let mut material = emissive("e", Vec3::splat(2.0));
        material.emissive_texture = Some(0);
        let mut scene = scene_of(vec![mesh], vec![material]);
        // Linear texels 0.5 (left half, where the uvs are) and 1 (right half).
        scene.textures.push(crate::scene::Texture {
            name: "half".into(),
            width: 2,
            height: 1,
            rgba8: vec![128, 64, 255, 255, 255, 255, 255, 255],
            color_space: crate::scene::ColorSpace::Linear,
        });
        let triangles = emissive_triangles(&scene, &scene.world_from_node());
        // uv 0.25 is the first texel's centre: L_e = 2 × texel.
        let expected = Vec3::new(128.0, 64.0, 255.0) / 255.0 * 2.0;
        for t in &triangles {
            assert!(
                (t.radiance - expected).abs().max_element() < 1e-5,
                "{}",
                t.radiance
            );
        }
        let clustering = cluster(&triangles, 6);
        let total: Vec3 = clustering.clusters.iter().map(|c| c.intensity).sum();
        assert!((total - expected * 6.0).abs().max_element() < 1e-4);
    }

    #[test]
    fn double_sided_emitters_light_both_ways() {
        let mut quad = Mesh {
            name: "quad".into(),
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 1.0),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            indices: vec![0, 2, 1, 0, 3, 2],
            ..Mesh::default()
        };
        quad.normals = vec![Vec3::Y; 4];
        let mut material = emissive("e", Vec3::ONE);
        let scene = scene_of(vec![quad.clone()], vec![material.clone()]);
        let one = emissive_triangles(&scene, &scene.world_from_node());
        assert_eq!(one.len(), 2);
        assert!(one.iter().all(|t| t.normal == Vec3::Y));
        material.double_sided = true;
        let scene = scene_of(vec![quad], vec![material]);
        let triangles = emissive_triangles(&scene, &scene.world_from_node());
        let clustering = cluster(&triangles, 2);
        let mut normals: Vec<f32> = clustering.clusters.iter().map(|c| c.normal.y).collect();
        normals.sort_by(f32::total_cmp);
        assert_eq!(normals, vec![-1.0, 1.0]);
    }
}
