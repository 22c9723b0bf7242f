//! What lies under a pixel: the first triangle a ray hits, which instance and mesh vertex it
//! belongs to. The viewer's debug views ask it for "the vertex under the cursor". One ray per
//! cursor move, so it tests triangles directly (culled per instance by a world-space box)
//! instead of building a BVH a click would wait for.

use glam::{Mat3, Mat4, Vec3};

use super::Scene;

/// The surface under a ray.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScenePick {
    pub instance: usize,
    /// The hit triangle: indices `3·triangle ..` of the instance's mesh.
    pub triangle: usize,
    /// The triangle's vertex nearest the hit (largest barycentric weight), a mesh vertex index.
    pub vertex: u32,
    /// World-space hit position and distance along the (unit) ray.
    pub position: Vec3,
    pub t: f32,
    /// Unit world-space geometric normal of the triangle, as the mesh winds it.
    pub geometric_normal: Vec3,
}

impl ScenePick {
    /// The mesh vertex's world position and unit normal.
    pub fn vertex_world(&self, scene: &Scene, world_from_node: &[Mat4]) -> (Vec3, Vec3) {
        let instance = &scene.instances[self.instance];
        let mesh = &scene.meshes[instance.mesh];
        let world_from_model = world_from_node[instance.node];
        let normal_from_model = Mat3::from_mat4(world_from_model).inverse().transpose();
        let v = self.vertex as usize;
        (
            world_from_model.transform_point3(mesh.positions[v]),
            (normal_from_model * mesh.normals[v]).normalize_or_zero(),
        )
    }
}

/// Möller–Trumbore against the triangle (v0, v0 + e1, v0 + e2), both faces: the ray
/// parameter and the barycentrics (u, v) of vertices 1 and 2 of a hit at t > 0. The CPU
/// BVH's ray test ([`crate::light::bvh::ray_triangle`], the shader's twin) is this one.
pub fn ray_triangle(
    origin: Vec3,
    dir: Vec3,
    v0: Vec3,
    e1: Vec3,
    e2: Vec3,
) -> Option<(f32, f32, f32)> {
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > 0.0).then_some((t, u, v))
}

/// Slab test of a ray against a box: true when [0, t_max] overlaps the box's span
/// (`inv_dir` from [`safe_inverse`]).
pub fn ray_box(origin: Vec3, inv_dir: Vec3, t_max: f32, min: Vec3, max: Vec3) -> bool {
    let t0 = (min - origin) * inv_dir;
    let t1 = (max - origin) * inv_dir;
    let near = t0.min(t1).max_element().max(0.0);
    let far = t0.max(t1).min_element().min(t_max);
    near <= far
}

/// `1/d` per axis with zeros replaced by a huge value of the same sign, so the slab test
/// never meets 0·∞ (the BVH shader does the same).
pub fn safe_inverse(d: Vec3) -> Vec3 {
    let f = |x: f32| {
        if x.abs() < 1e-20 {
            1e20f32.copysign(x)
        } else {
            1.0 / x
        }
    };
    Vec3::new(f(d.x), f(d.y), f(d.z))
}

/// The first surface along the ray from `origin` in direction `dir` (normalized here), with
/// the scene placed by `world_from_node`; `None` when the ray leaves the scene.
pub fn pick(scene: &Scene, world_from_node: &[Mat4], origin: Vec3, dir: Vec3) -> Option<ScenePick> {
    let dir = dir.normalize_or_zero();
    if dir == Vec3::ZERO || !origin.is_finite() {
        return None;
    }
    let inv_dir = safe_inverse(dir);
    let mut best: Option<ScenePick> = None;
    for (instance_index, instance) in scene.instances.iter().enumerate() {
        let (Some(mesh), Some(world_from_model)) = (
            scene.meshes.get(instance.mesh),
            world_from_node.get(instance.node),
        ) else {
            continue;
        };
        let world: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|p| world_from_model.transform_point3(*p))
            .collect();
        let (lo, hi) = world.iter().fold(
            (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let t_max = best.map_or(f32::MAX, |b| b.t);
        if world.is_empty() || !ray_box(origin, inv_dir, t_max, lo, hi) {
            continue;
        }
        for (triangle, corners) in mesh.indices.chunks_exact(3).enumerate() {
            let [i0, i1, i2] = [corners[0], corners[1], corners[2]].map(|i| i as usize);
            let (Some(&a), Some(&b), Some(&c)) = (world.get(i0), world.get(i1), world.get(i2))
            else {
                continue;
            };
            let Some((t, u, v)) = ray_triangle(origin, dir, a, b - a, c - a) else {
                continue;
            };
            if best.is_some_and(|best| best.t <= t) {
                continue;
            }
            let weights = [1.0 - u - v, u, v];
            let nearest = (0..3)
                .max_by(|&x, &y| weights[x].total_cmp(&weights[y]))
                .unwrap_or(0);
            best = Some(ScenePick {
                instance: instance_index,
                triangle,
                vertex: corners[nearest],
                position: origin + t * dir,
                t,
                geometric_normal: (b - a).cross(c - a).normalize_or_zero(),
            });
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Mesh};

    /// Two unit quads facing +z, at z = 0 and (a second instance of the same mesh) z = −1;
    /// `pick` takes the nodes' world matrices, so the scene needs no node records.
    fn two_quads() -> (Scene, Vec<Mat4>) {
        let mesh = Mesh {
            name: "quad".into(),
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            normals: vec![Vec3::Z; 4],
            indices: vec![0, 1, 2, 0, 2, 3],
            ..Default::default()
        };
        let scene = Scene {
            meshes: vec![mesh],
            instances: vec![Instance { mesh: 0, node: 0 }, Instance { mesh: 0, node: 1 }],
            ..Default::default()
        };
        let world = vec![
            Mat4::IDENTITY,
            Mat4::from_translation(Vec3::new(0.0, 0.0, -1.0)),
        ];
        (scene, world)
    }

    #[test]
    fn the_nearest_surface_and_its_nearest_vertex_are_picked() {
        let (scene, world) = two_quads();
        let origin = Vec3::new(0.8, 0.7, 5.0);
        let hit = pick(&scene, &world, origin, -Vec3::Z).expect("the ray hits the quads");
        assert_eq!(hit.instance, 0, "the front quad hides the back one");
        assert!((hit.t - 5.0).abs() < 1e-5);
        assert!((hit.position - Vec3::new(0.8, 0.7, 0.0)).length() < 1e-5);
        assert_eq!(hit.vertex, 2, "(0.8, 0.7) is nearest the corner (1, 1)");
        assert!((hit.geometric_normal - Vec3::Z).length() < 1e-5);
        let (p, n) = hit.vertex_world(&scene, &world);
        assert_eq!((p, n), (Vec3::new(1.0, 1.0, 0.0), Vec3::Z));

        // From behind, the back quad comes first; its vertex is placed by its instance.
        let hit = pick(&scene, &world, Vec3::new(-0.9, -0.8, -5.0), Vec3::Z).unwrap();
        assert_eq!(hit.instance, 1);
        assert_eq!(hit.vertex, 0);
        assert_eq!(
            hit.vertex_world(&scene, &world).0,
            Vec3::new(-1.0, -1.0, -1.0)
        );
    }

    #[test]
    fn rays_that_miss_or_are_degenerate_pick_nothing() {
        let (scene, world) = two_quads();
        assert_eq!(
            pick(&scene, &world, Vec3::new(3.0, 0.0, 5.0), -Vec3::Z),
            None
        );
        assert_eq!(
            pick(&scene, &world, Vec3::new(0.0, 0.0, 5.0), Vec3::Z),
            None
        );
        assert_eq!(
            pick(&scene, &world, Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO),
            None
        );
        assert_eq!(pick(&scene, &world, Vec3::NAN, -Vec3::Z), None);
        // Too few matrices for the instances: the unplaced one is skipped, not a panic.
        let hit = pick(&scene, &world[..1], Vec3::new(0.0, 0.0, -5.0), Vec3::Z).unwrap();
        assert_eq!(hit.instance, 0);
    }
}
