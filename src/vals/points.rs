//! Sparse receiver points: the method's preprocessing, once per mesh and in model space
//! (DESIGN §4). Points are spread with density proportional to area by weighted sample
//! elimination (Yuksel 2015: a blue-noise subset of area-uniform candidates), seeded and
//! deterministic. Every vertex links to its 8 nearest points of the same mesh with the
//! interpolation weights of paper eq. 12, which rigid motion leaves unchanged, so they are
//! computed here once. Every point gets an occluder-disc radius from its Voronoi region.

use std::cell::OnceCell;
use std::collections::BinaryHeap;
use std::hash::{Hash, Hasher};
use std::num::NonZero;
use std::sync::{Arc, Mutex};

use glam::{Mat3, Mat4, Vec3};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;

use super::math::{link_weights, morton_spread};
use super::recent::Recent;
use crate::sampling::Rng;
use crate::scene::{Mesh, Scene};

/// Links per vertex.
pub const LINKS: usize = 8;

/// Fewest points any mesh with surface area gets, so every vertex has a full set of links.
pub const MIN_POINTS_PER_MESH: usize = LINKS;

/// Candidates per kept point for sample elimination (Yuksel suggests 3–5).
const CANDIDATES_PER_POINT: usize = 5;

/// One vertex's link: a mesh-local point index and its normalized weight.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Link {
    pub point: u32,
    pub weight: f32,
}

/// A mesh's sparse points and its vertices' links, all in model space.
#[derive(Clone, Debug, Default)]
pub struct MeshPoints {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// Occluder-disc radius: the farthest mesh vertex in the point's Voronoi region, and at
    /// least the radius of the point's share of the area (coarse meshes have regions with no
    /// vertex at all; their discs must not vanish).
    pub disc_radius: Vec<f32>,
    /// `LINKS` links per vertex; weights sum to 1, or are all 0 when no linked point faces
    /// the vertex's way.
    pub links: Vec<[Link; LINKS]>,
}

impl MeshPoints {
    /// The bytes its arrays hold.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(self.positions.as_slice())
            + std::mem::size_of_val(self.normals.as_slice())
            + std::mem::size_of_val(self.disc_radius.as_slice())
            + std::mem::size_of_val(self.links.as_slice())
    }
}

/// Points per mesh: `total` split by area (model-space area × instances), each mesh's share
/// raised by its [`curvature_boost`], at least `MIN_POINTS_PER_MESH` for any mesh with area,
/// none for meshes without.
///
/// Area alone gives a curved object the density of a flat wall: seed 002's bunny, 3 % of
/// `bunny-box`'s area, got 127 of 4096 points, 11 cm apart on a 0.8 m bunny whose normals
/// turn 40° between neighbouring points, and its head came out black (0.63 of the
/// reference's indirect light over the bunny; `src/vals/README.md`).
pub fn points_per_mesh(scene: &Scene, total: usize) -> Vec<usize> {
    let areas: Vec<f64> = scene.meshes.iter().map(mesh_area).collect();
    let area_counts = counts_by_weight(scene, total, &areas);
    let weights: Vec<f64> = scene
        .meshes
        .iter()
        .zip(areas.iter().zip(&area_counts))
        .enumerate()
        .map(|(mi, (mesh, (&area, &count)))| {
            if count == 0 || area <= 0.0 {
                return 0.0;
            }
            let spacing = (area / count as f64).sqrt() as f32;
            area * curvature_boost(mesh, spacing, mi as u64)
        })
        .collect();
    counts_by_weight(scene, total, &weights)
}

/// `total` split over the meshes in proportion to their `weights` × instances (rounded), at
/// least `MIN_POINTS_PER_MESH` for a placed mesh of positive weight.
fn counts_by_weight(scene: &Scene, total: usize, weights: &[f64]) -> Vec<usize> {
    let mut instances = vec![0usize; scene.meshes.len()];
    for inst in &scene.instances {
        instances[inst.mesh] += 1;
    }
    let sum: f64 = weights
        .iter()
        .zip(&instances)
        .map(|(w, &n)| w * n as f64)
        .sum();
    weights
        .iter()
        .zip(&instances)
        .map(|(&w, &n)| {
            // NaN weights count as none.
            if w.is_nan() || w <= 0.0 || sum.is_nan() || sum <= 0.0 || n == 0 {
                0
            } else {
                // Per instance of the mesh, so instances × count ≈ the weight's share.
                ((total as f64 * w / sum).round() as usize).max(MIN_POINTS_PER_MESH)
            }
        })
        .collect()
}

/// Mean angle, in radians, that neighbouring points' normals may differ by before a mesh
/// gets more points than its area's share. A vertex takes its lights from its 8 nearest
/// points, weighted by `n_v·n_j`, and each light sits where that point's VALs are: across a
/// larger turn the linked points face other VALs than the vertex does.
pub const NEIGHBOUR_NORMAL_TURN: f32 = 0.25;

/// The most a mesh's density may be raised over its area's share (a small, crumpled mesh
/// must not take every point of the scene).
pub const MAX_CURVATURE_BOOST: f64 = 16.0;

/// Surface samples per point of the area share when measuring a mesh's turn (so that pairs
/// about one spacing apart exist), within `[64, 4096]`.
const TURN_SAMPLES_PER_POINT: usize = 4;

/// How much denser than its area's share `mesh` needs its points: `(θ/θ₀)²` clamped to
/// `[1, MAX_CURVATURE_BOOST]`, θ being the mean angle between the normals of surface samples
/// 0.5–1.5 `spacing` apart ([`normal_turn`]) and θ₀ = [`NEIGHBOUR_NORMAL_TURN`]. On a smooth
/// surface θ grows with the spacing, so `(θ/θ₀)²` times the points bring it down to θ₀; on a
/// flat one θ = 0 and the area's share stands.
pub fn curvature_boost(mesh: &Mesh, spacing: f32, seed: u64) -> f64 {
    let turn = normal_turn(mesh, spacing, seed);
    ((turn / NEIGHBOUR_NORMAL_TURN) as f64)
        .powi(2)
        .clamp(1.0, MAX_CURVATURE_BOOST)
}

/// Mean angle between the shading normals of area-uniform samples of `mesh` whose distance
/// is within 0.5–1.5 `spacing` (0 with no such pair): the turn of the surface over one point
/// spacing. Measured at that scale, not per triangle, so a scanned mesh's fine bumps (which
/// the pixels' own normals handle) do not count as curvature.
pub fn normal_turn(mesh: &Mesh, spacing: f32, seed: u64) -> f32 {
    let area = mesh_area(mesh);
    if spacing.is_nan() || spacing <= 0.0 || area.is_nan() || area <= 0.0 {
        return 0.0;
    }
    let count = ((TURN_SAMPLES_PER_POINT as f64 * area / (spacing as f64).powi(2)) as usize)
        .clamp(64, 4096);
    let mut rng = Rng::from_state(seed ^ 0x7A1B_C0DE_7A1B_C0DE);
    let (positions, normals) = surface_samples(mesh, count, &mut rng);
    let coords: Vec<[f32; 3]> = positions.iter().map(|p| p.to_array()).collect();
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(&coords);
    let (near, far) = (0.5 * spacing, 1.5 * spacing);
    let (mut sum, mut pairs) = (0.0f64, 0usize);
    for (i, c) in coords.iter().enumerate() {
        for nn in tree.within_unsorted::<SquaredEuclidean>(c, far * far) {
            let j = nn.item as usize;
            let cos = normals[i].dot(normals[j]);
            // Pairs 84° or more apart are the two faces of a thin slab (a door) or a crease
            // (a box's edge, cos 0 give or take rounding), where each face has its own
            // points and the links' `n_v·n_j` weight keeps them apart: not a turn the points
            // must follow.
            if j > i && nn.distance >= near * near && cos > 0.1 {
                sum += cos.min(1.0).acos() as f64;
                pairs += 1;
            }
        }
    }
    if pairs == 0 {
        0.0
    } else {
        (sum / pairs as f64) as f32
    }
}

/// Spacing of `total` sparse points spread over the scene as placed at rest: the side of
/// one point's share of the world-space surface area, √(A / total) (the distance between
/// neighbours is about 1.07× that in the hexagonal packing sample elimination aims for).
/// `None` when the scene has no area or `total` is 0.
pub fn point_spacing(scene: &Scene, total: usize) -> Option<f32> {
    let world = scene.world_from_node();
    let mut area = 0.0f64;
    for inst in &scene.instances {
        let (Some(mesh), Some(m)) = (scene.meshes.get(inst.mesh), world.get(inst.node)) else {
            continue;
        };
        for t in mesh.indices.chunks_exact(3) {
            let Some([a, b, c]) = t
                .iter()
                .map(|&i| {
                    mesh.positions
                        .get(i as usize)
                        .map(|&p| m.transform_point3(p))
                })
                .collect::<Option<Vec<_>>>()
                .map(|v| [v[0], v[1], v[2]])
            else {
                continue;
            };
            let tri = 0.5 * (b - a).cross(c - a).length() as f64;
            if tri.is_finite() {
                area += tri;
            }
        }
    }
    (total > 0 && area > 0.0).then(|| (area / total as f64).sqrt() as f32)
}

pub fn mesh_area(mesh: &Mesh) -> f64 {
    mesh.indices
        .chunks_exact(3)
        .map(|t| triangle_area(mesh, t) as f64)
        .sum()
}

fn triangle_area(mesh: &Mesh, t: &[u32]) -> f32 {
    let [a, b, c] = [0, 1, 2].map(|i| mesh.positions[t[i] as usize]);
    0.5 * (b - a).cross(c - a).length()
}

/// `count` area-uniform samples of `mesh` with their interpolated shading normals (the face
/// normal where the mesh has none, or they cancel); none for a mesh without area.
fn surface_samples(mesh: &Mesh, count: usize, rng: &mut Rng) -> (Vec<Vec3>, Vec<Vec3>) {
    let triangles: Vec<&[u32]> = mesh.indices.chunks_exact(3).collect();
    let mut cdf = Vec::with_capacity(triangles.len());
    let mut area = 0.0f64;
    for t in &triangles {
        area += triangle_area(mesh, t) as f64;
        cdf.push(area);
    }
    let mut positions = Vec::with_capacity(count);
    let mut normals = Vec::with_capacity(count);
    if area <= 0.0 {
        return (positions, normals);
    }
    for _ in 0..count {
        let target = rng.next_f32() as f64 * area;
        let ti = cdf
            .partition_point(|&c| c < target)
            .min(triangles.len() - 1);
        let t = triangles[ti];
        let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
        if u + v > 1.0 {
            (u, v) = (1.0 - u, 1.0 - v);
        }
        let [a, b, c] = [0, 1, 2].map(|i| mesh.positions[t[i] as usize]);
        positions.push(a + u * (b - a) + v * (c - a));
        let face = (b - a).cross(c - a).normalize_or_zero();
        let normal = if mesh.normals.len() == mesh.positions.len() {
            let [na, nb, nc] = [0, 1, 2].map(|i| mesh.normals[t[i] as usize]);
            let n = (1.0 - u - v) * na + u * nb + v * nc;
            if n.length_squared() > 1e-12 {
                n.normalize()
            } else {
                face
            }
        } else {
            face
        };
        normals.push(normal);
    }
    (positions, normals)
}

/// Places `count` points on `mesh` and links its vertices. Meshes without area get none.
pub fn place(mesh: &Mesh, count: usize, seed: u64) -> MeshPoints {
    let area = mesh_area(mesh);
    if count == 0 || area <= 0.0 {
        return MeshPoints {
            links: vec![[Link::default(); LINKS]; mesh.positions.len()],
            ..Default::default()
        };
    }

    // Area-uniform candidates.
    // A fixed stream per seed: the placement must not change between runs or machines.
    let mut rng = Rng::from_state(seed ^ 0x5EED_5EED_5EED_5EED);
    let (candidates, candidate_normals) =
        surface_samples(mesh, count * CANDIDATES_PER_POINT, &mut rng);

    let mut kept = eliminate(&candidates, count, area as f32);
    // Morton order: consecutive points form compact patches, so the occlusion pass, which
    // culls whole tiles of consecutive points, can skip the ones far from a point's light.
    sort_by_morton_code(&mut kept, &candidates);
    let positions: Vec<Vec3> = kept.iter().map(|&i| candidates[i]).collect();
    let normals: Vec<Vec3> = kept.iter().map(|&i| candidate_normals[i]).collect();

    // Links: the 8 nearest points of each vertex, weighted by eq. 12.
    let coords: Vec<[f32; 3]> = positions.iter().map(|p| p.to_array()).collect();
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(&coords);
    let wanted = NonZero::new(LINKS.min(positions.len())).expect("at least one point");
    let mut disc_radius = vec![0.0f32; positions.len()];
    let mut links = Vec::with_capacity(mesh.positions.len());
    for (vi, v) in mesh.positions.iter().enumerate() {
        let nearest = tree.nearest_n::<SquaredEuclidean>(&v.to_array(), wanted);
        if let Some(first) = nearest.first() {
            let owner = first.item as usize;
            disc_radius[owner] = disc_radius[owner].max(first.distance.sqrt());
        }
        let vertex_normal = mesh.normals.get(vi).copied().unwrap_or(Vec3::ZERO);
        let linked: Vec<(Vec3, Vec3)> = nearest
            .iter()
            .map(|nn| (positions[nn.item as usize], normals[nn.item as usize]))
            .collect();
        let weights = link_weights(*v, vertex_normal, &linked);
        let total: f32 = weights.iter().sum();
        let mut row = [Link::default(); LINKS];
        if total > 0.0 {
            for (slot, (nn, w)) in row.iter_mut().zip(nearest.iter().zip(&weights)) {
                *slot = Link {
                    point: nn.item as u32,
                    weight: w / total,
                };
            }
        }
        links.push(row);
    }
    let share_radius = (area as f32 / (std::f32::consts::PI * positions.len() as f32)).sqrt();
    for r in &mut disc_radius {
        *r = r.max(share_radius);
    }
    MeshPoints {
        positions,
        normals,
        disc_radius,
        links,
    }
}

/// Sorts `indices` into `positions` along the Z-order curve over their bounding box (10 bits
/// an axis; ties keep their order, so the result is deterministic).
fn sort_by_morton_code(indices: &mut [usize], positions: &[Vec3]) {
    let (lo, hi) = indices.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), &i| (lo.min(positions[i]), hi.max(positions[i])),
    );
    let scale = 1023.0 / (hi - lo).max(Vec3::splat(1e-12));
    let code = |i: usize| {
        let q = ((positions[i] - lo) * scale).round().as_uvec3();
        morton_spread(q.x) | (morton_spread(q.y) << 1) | (morton_spread(q.z) << 2)
    };
    indices.sort_by_key(|&i| code(i));
}

/// Weighted sample elimination: repeatedly drop the candidate whose neighbours crowd it most
/// until `count` remain. Returns the kept candidates' indices in ascending order.
fn eliminate(candidates: &[Vec3], count: usize, area: f32) -> Vec<usize> {
    if candidates.len() <= count {
        return (0..candidates.len()).collect();
    }
    // Yuksel's r_max for a 2D domain: the spacing of `count` points in hexagonal packing.
    let r_max = (area / (2.0 * 3f32.sqrt() * count as f32)).sqrt();
    let reach = 2.0 * r_max;
    let coords: Vec<[f32; 3]> = candidates.iter().map(|p| p.to_array()).collect();
    let tree: ImmutableKdTree<f32, u64, 3, 32> = ImmutableKdTree::new_from_slice(&coords);
    let contribution = |d: f32| (1.0 - (d / reach).min(1.0)).powi(8);
    let neighbours: Vec<Vec<(u32, f32)>> = coords
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut found: Vec<(u32, f32)> = tree
                .within_unsorted::<SquaredEuclidean>(c, reach * reach)
                .into_iter()
                .filter(|nn| nn.item as usize != i)
                .map(|nn| (nn.item as u32, contribution(nn.distance.sqrt())))
                .collect();
            found.sort_by_key(|(j, _)| *j);
            found
        })
        .collect();
    let mut weight: Vec<f32> = neighbours
        .iter()
        .map(|n| n.iter().map(|(_, w)| w).sum())
        .collect();
    let mut alive = vec![true; candidates.len()];
    // Max-heap keyed by weight, then index for determinism; stale entries are skipped.
    let mut heap: BinaryHeap<(u32, std::cmp::Reverse<usize>)> = weight
        .iter()
        .enumerate()
        .map(|(i, w)| (w.to_bits(), std::cmp::Reverse(i)))
        .collect();
    let mut remaining = candidates.len();
    while remaining > count {
        let Some((bits, std::cmp::Reverse(i))) = heap.pop() else {
            break;
        };
        if !alive[i] || bits != weight[i].to_bits() {
            continue;
        }
        alive[i] = false;
        remaining -= 1;
        for &(j, w) in &neighbours[i] {
            let j = j as usize;
            if alive[j] {
                weight[j] = (weight[j] - w).max(0.0);
                heap.push((weight[j].to_bits(), std::cmp::Reverse(j)));
            }
        }
    }
    (0..candidates.len()).filter(|&i| alive[i]).collect()
}

/// Both faces of a two-sided sheet (a double-sided material: a partition, a door, a leaf):
/// the front points again with flipped normals after them, and the vertices' links again
/// after theirs, pointing at the flipped copies. A vertex `v` of such a mesh has its front
/// lights at `v` and its back lights at `v + n` (n vertices), and the apply pass picks by the
/// pixel's facing, so light that reaches the back never shows on the front or the reverse.
pub fn two_sided(front: &MeshPoints) -> MeshPoints {
    let count = front.positions.len() as u32;
    let mut out = front.clone();
    out.positions.extend_from_slice(&front.positions);
    out.normals.extend(front.normals.iter().map(|n| -*n));
    out.disc_radius.extend_from_slice(&front.disc_radius);
    out.links.extend(front.links.iter().map(|row| {
        row.map(|l| Link {
            point: l.point + count,
            weight: l.weight,
        })
    }));
    out
}

/// Identity of a mesh's geometry for the cache.
fn mesh_key(mesh: &Mesh, count: usize, seed: u64) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    for p in &mesh.positions {
        p.to_array().map(f32::to_bits).hash(&mut h);
    }
    for n in &mesh.normals {
        n.to_array().map(f32::to_bits).hash(&mut h);
    }
    mesh.indices.hash(&mut h);
    count.hash(&mut h);
    seed.hash(&mut h);
    h.finish()
}

/// Most bytes the process-wide placement cache holds before it drops the meshes used least
/// recently. A viewer session that tries point count after point count on a large scene would
/// otherwise keep every placement: on Sponza as refined for 16384 points the vertices' links
/// alone are 28 MB a count (429 708 vertices × 8 links × 8 bytes).
pub const PLACEMENT_CACHE_BYTES: usize = 1 << 30;

/// Each mesh's placed points by [`mesh_key`], at their bytes, within [`PLACEMENT_CACHE_BYTES`].
type PlacementCache = Recent<u64, Arc<MeshPoints>>;

fn cache() -> &'static Mutex<PlacementCache> {
    static CACHE: Mutex<PlacementCache> = Mutex::new(Recent::new(PLACEMENT_CACHE_BYTES));
    &CACHE
}

/// Whether a mesh is a two-sided sheet: its material says so (glTF `doubleSided`, Mitsuba
/// `twosided`, OBJ, the built-in partitions and doors).
pub fn is_two_sided(scene: &Scene, mesh: &Mesh) -> bool {
    scene
        .materials
        .get(mesh.material)
        .is_some_and(|m| m.double_sided)
}

/// Most sparse points one mesh may hold: vertex links address them with 16 bits.
pub const MAX_POINTS_PER_MESH: usize = 1 << 16;

/// The first mesh whose count of `counts` ([`points_per_mesh`]) is more than
/// [`MAX_POINTS_PER_MESH`] (both sides of a two-sided mesh count), with that count — checked
/// before any placement, which at such counts takes minutes.
pub fn oversized_mesh<'a>(scene: &'a Scene, counts: &[usize]) -> Option<(&'a str, usize)> {
    scene
        .meshes
        .iter()
        .zip(counts)
        .map(|(mesh, &count)| {
            let sides = if is_two_sided(scene, mesh) { 2 } else { 1 };
            (mesh.name.as_str(), count * sides)
        })
        .find(|&(_, count)| count > MAX_POINTS_PER_MESH)
}

/// Points for every mesh of the scene, `total` split by [`points_per_mesh`]: see
/// [`scene_points_for`].
pub fn scene_points(scene: &Scene, total: usize, seed: u64) -> (Vec<Arc<MeshPoints>>, usize) {
    scene_points_for(scene, &points_per_mesh(scene, total), seed)
}

/// Points for every mesh of the scene, `counts[m]` on mesh m, from the process-wide cache
/// where this mesh was already processed with the same count and seed. Returns the points
/// and how many meshes were computed (not cached).
pub fn scene_points_for(
    scene: &Scene,
    counts: &[usize],
    seed: u64,
) -> (Vec<Arc<MeshPoints>>, usize) {
    let mut computed = 0;
    let points = scene
        .meshes
        .iter()
        .zip(counts)
        .enumerate()
        .map(|(mi, (mesh, &count))| {
            let sides = if is_two_sided(scene, mesh) { 2 } else { 1 };
            let key = mesh_key(mesh, count, seed).wrapping_add(sides);
            if let Some(hit) = cache().lock().ok().and_then(|mut c| c.get(&key).cloned()) {
                return hit;
            }
            computed += 1;
            let front = place(mesh, count, seed.wrapping_add(mi as u64));
            let placed = Arc::new(if sides == 2 { two_sided(&front) } else { front });
            if let Ok(mut c) = cache().lock() {
                c.insert(key, placed.clone(), placed.heap_bytes());
            }
            placed
        })
        .collect();
    (points, computed)
}

/// The part of a link's segment at either end, in tracer epsilons, where other geometry does
/// not count as a wall between the vertex and the point (see [`cut_links_through_walls`]).
const JUNCTION_MARGIN: f32 = 8.0;

/// What [`cut_links_through_walls`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkCut {
    /// Meshes whose links were tested (placed once, never moving).
    pub meshes: usize,
    /// Links (of positive weight) dropped because other geometry stands between the vertex
    /// and the point.
    pub links: usize,
    /// Vertex rows whose every link was blocked, kept as they were.
    pub kept_rows: usize,
}

/// Drops the links that pass through other geometry, and renormalizes the rest of each row.
/// Links join a vertex to the nearest points of its own mesh, and a mesh that runs past a
/// thin wall (a room's back wall under a partition) links vertices on one side to points on
/// the other, leaking the light of one room into the other at the junction. Tested are the
/// meshes placed once whose node never moves, against the other instances that never move
/// (the links stay in model space and stay right for the whole animation); a segment runs
/// between the vertex and the point, each lifted off its surface along its normal by the
/// tracer's epsilon. The mesh's own triangles are not blockers: on a curved surface the chord
/// between two of its points dips under it.
pub fn cut_links_through_walls(
    scene: &Scene,
    points: &[Arc<MeshPoints>],
) -> (Vec<Arc<MeshPoints>>, LinkCut) {
    cut_links_with(scene, points, &OnceCell::new())
}

/// [`cut_links_through_walls`] with the tracer of `scene` at rest kept in `tracer`: built on
/// first use, and reused by the next call over the same scene (one per budget pilot).
pub fn cut_links_with<'s>(
    scene: &'s Scene,
    points: &[Arc<MeshPoints>],
    tracer: &OnceCell<crate::trace::Tracer<'s>>,
) -> (Vec<Arc<MeshPoints>>, LinkCut) {
    let moving = scene.moving_nodes();
    let mut uses = vec![0usize; scene.meshes.len()];
    for inst in &scene.instances {
        if let Some(u) = uses.get_mut(inst.mesh) {
            *u += 1;
        }
    }
    let still = |instance: usize| !moving[scene.instances[instance].node];
    let testable: Vec<usize> = (0..scene.instances.len())
        .filter(|&i| still(i) && uses[scene.instances[i].mesh] == 1)
        .filter(|&i| {
            points
                .get(scene.instances[i].mesh)
                .is_some_and(|p| !p.positions.is_empty())
        })
        .collect();
    let mut out = points.to_vec();
    let mut cut = LinkCut::default();
    if testable.is_empty() {
        return (out, cut);
    }
    let world_from_node = scene.world_from_node_at(0.0);
    let tracer = tracer.get_or_init(|| crate::trace::Tracer::new(scene, &world_from_node));
    let eps = tracer.epsilon;
    // A vertex or point on the seam with another mesh (a ceiling's edge against a wall) sits
    // on that mesh's surface: the segment leaves it at t = 0, which is no wall between them.
    // Walls thinner than `margin` are not seen.
    let margin = JUNCTION_MARGIN * eps;
    for instance in testable {
        let mesh_index = scene.instances[instance].mesh;
        let mesh = &scene.meshes[mesh_index];
        let mesh_points = &points[mesh_index];
        let world_from_model = world_from_node[scene.instances[instance].node];
        let normal_from_model = Mat3::from_mat4(world_from_model).inverse().transpose();
        let to_world = |p: Vec3, n: Vec3| {
            let n = (normal_from_model * n).normalize_or_zero();
            world_from_model.transform_point3(p) + n * eps
        };
        let vertex_count = mesh.positions.len();
        let lifted_points: Vec<Vec3> = mesh_points
            .positions
            .iter()
            .zip(&mesh_points.normals)
            .map(|(&p, &n)| to_world(p, n))
            .collect();
        let skip = |other: usize| other == instance || !still(other);
        let mut links = mesh_points.links.clone();
        let mut changed = false;
        for (row_index, row) in links.iter_mut().enumerate() {
            let original_row = *row;
            let v = row_index % vertex_count.max(1);
            let (Some(&position), Some(&normal)) = (mesh.positions.get(v), mesh.normals.get(v))
            else {
                continue;
            };
            // The back rows of a two-sided sheet face the other way.
            let side = if row_index >= vertex_count { -1.0 } else { 1.0 };
            let from = to_world(position, side * normal);
            let mut dropped = 0;
            for link in row.iter_mut().filter(|l| l.weight > 0.0) {
                let Some(&to) = lifted_points.get(link.point as usize) else {
                    continue;
                };
                let d = to - from;
                let length = d.length();
                if length <= 2.0 * margin {
                    continue;
                }
                let dir = d / length;
                if !tracer.unoccluded_except(from + dir * margin, dir, length - 2.0 * margin, skip)
                {
                    link.weight = 0.0;
                    dropped += 1;
                }
            }
            if dropped == 0 {
                continue;
            }
            let total: f32 = row.iter().map(|l| l.weight).sum();
            if total <= 0.0 {
                // Every link blocked: a vertex inside other geometry (a column's foot sunk
                // into the floor) rather than behind a wall. Darkening it would smear dark
                // into the visible triangles it shares, so it keeps its links.
                *row = original_row;
                cut.kept_rows += 1;
                continue;
            }
            for l in row.iter_mut() {
                l.weight /= total;
            }
            changed = true;
            cut.links += dropped;
        }
        cut.meshes += 1;
        if changed {
            out[mesh_index] = Arc::new(MeshPoints {
                links,
                ..(**mesh_points).clone()
            });
        }
    }
    (out, cut)
}

/// The viewer's links and occluder views at a picked surface (`Method::debug_pick`): the
/// picked vertex's link row (its back-face row for the back of a two-sided sheet, as the apply
/// pass chooses by facing) placed in world space, and the instance's point nearest the pick
/// among those facing the eye (the nearest of all when none does), with its index in the
/// points as `SparseGpu` flattens them over instances.
pub fn debug_pick(
    scene: &Scene,
    world_from_node: &[Mat4],
    points: &[Arc<MeshPoints>],
    pick: &crate::scene::pick::ScenePick,
    eye: Vec3,
) -> Option<crate::frame::DebugPick> {
    let instance = scene.instances.get(pick.instance)?;
    let mesh = scene.meshes.get(instance.mesh)?;
    let mesh_points = points.get(instance.mesh)?;
    let world_from_model = *world_from_node.get(instance.node)?;
    let normal_from_model = Mat3::from_mat4(world_from_model).inverse().transpose();
    let place = |i: usize| world_from_model.transform_point3(mesh_points.positions[i]);
    let (vertex, vertex_normal) = pick.vertex_world(scene, world_from_node);
    let n = mesh.positions.len();
    let two_sided = n > 0 && mesh_points.links.len() == 2 * n;
    let back = two_sided && vertex_normal.dot(eye - vertex) < 0.0;
    let row = mesh_points
        .links
        .get(pick.vertex as usize + if back { n } else { 0 })?;
    let links = row
        .iter()
        .filter(|l| (l.point as usize) < mesh_points.positions.len())
        .map(|l| (place(l.point as usize), l.weight))
        .collect();
    let offset: usize = scene.instances[..pick.instance]
        .iter()
        .map(|i| points.get(i.mesh).map_or(0, |p| p.positions.len()))
        .sum();
    let distance = |i: usize| (place(i) - pick.position).length_squared();
    let facing =
        |i: usize| (normal_from_model * mesh_points.normals[i]).dot(eye - pick.position) >= 0.0;
    let nearest = |candidates: &mut dyn Iterator<Item = usize>| {
        candidates.min_by(|&a, &b| distance(a).total_cmp(&distance(b)))
    };
    let count = mesh_points.positions.len();
    let point =
        nearest(&mut (0..count).filter(|&i| facing(i))).or_else(|| nearest(&mut (0..count)));
    Some(crate::frame::DebugPick {
        vertex,
        links,
        point: point.map(|i| ((offset + i) as u32, place(i))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::mesh::MeshBuilder;

    /// A placement's cost in the cache is the bytes its arrays hold (the store's order and
    /// bound: `recent::tests`).
    #[test]
    fn a_placement_costs_the_bytes_of_its_arrays() {
        let points = MeshPoints {
            positions: vec![Vec3::ZERO; 10],
            normals: vec![Vec3::Y; 10],
            disc_radius: vec![0.1; 10],
            links: vec![[Link::default(); LINKS]; 10],
        };
        assert_eq!(points.heap_bytes(), 10 * (12 + 12 + 4 + LINKS * 8));
    }

    fn plane(max_edge: f32) -> Mesh {
        let mut b = MeshBuilder::new("plane", 0);
        b.add_quad(
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::Y,
            max_edge,
        );
        b.build()
    }

    /// A closed box, its six faces each with its own vertices and face normal.
    fn slab(size: Vec3, max_edge: f32) -> Mesh {
        let mut b = MeshBuilder::new("slab", 0);
        let h = size * 0.5;
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                let n = Vec3::AXES[axis] * sign;
                let (u, v) = (Vec3::AXES[(axis + 1) % 3], Vec3::AXES[(axis + 2) % 3]);
                let (hu, hv) = (u * h.dot(u), v * h.dot(v));
                let c = n * h.dot(n.abs());
                b.add_quad(
                    c - hu - hv,
                    c + hu - hv,
                    c + hu + hv,
                    c - hu + hv,
                    c * 2.0,
                    max_edge,
                );
            }
        }
        b.build()
    }

    #[test]
    fn the_turn_is_the_angle_the_surface_bends_over_one_spacing() {
        // On a sphere of radius R, samples r apart have normals r/R apart (to first order);
        // over the band 0.5–1.5 h, weighted by the ring's length, the mean r is 13/12 h.
        let sphere = crate::scene::builtin::procedural::icosphere("sphere", 0, 1.0, 0.02, false);
        for h in [0.05f32, 0.1, 0.2] {
            let turn = normal_turn(&sphere, h, 3);
            let expected = 13.0 / 12.0 * h;
            assert!(
                (turn / expected - 1.0).abs() < 0.05,
                "h {h}: turn {turn} vs {expected}"
            );
        }
        // Flat: no turn; a box's creases and a thin slab's two faces are not turns either.
        assert_eq!(normal_turn(&plane(0.1), 0.05, 3), 0.0);
        for size in [Vec3::splat(1.0), Vec3::new(1.0, 0.04, 1.0)] {
            let turn = normal_turn(&slab(size, 0.1), 0.1, 3);
            assert!(turn < 1e-3, "box {size}: turn {turn}");
        }
    }

    #[test]
    fn curved_meshes_get_points_for_their_turn_flat_ones_for_their_area() {
        let scene = crate::scene::builtin::load(
            "glossy-row",
            &crate::scene::builtin::BuiltinParams::default(),
        )
        .unwrap();
        let total = 4096;
        let counts = points_per_mesh(&scene, total);
        let areas: Vec<f64> = scene.meshes.iter().map(mesh_area).collect();
        let sum: f64 = areas.iter().sum();
        let mut spheres = 0;
        for ((mesh, &count), &area) in scene.meshes.iter().zip(&counts).zip(&areas) {
            let share = total as f64 * area / sum;
            let turn = normal_turn(mesh, (area / share).sqrt() as f32, 0);
            if mesh.name.starts_with("sphere") {
                // Spheres of radius 0.28 m, 64 points by area: 13/12 h/R, about 28°, between
                // neighbours, so (θ/θ₀)² ≈ 3.8 times the points (less what the walls give up).
                spheres += 1;
                let expected = 13.0 / 12.0 * (area / share).sqrt() as f32 / 0.28;
                assert!(
                    (turn / expected - 1.0).abs() < 0.05,
                    "{}: turn {turn}",
                    mesh.name
                );
                assert!(
                    count as f64 > 2.5 * share,
                    "{}: {count} of share {share:.0}",
                    mesh.name
                );
            } else {
                assert_eq!(turn, 0.0, "{} is flat", mesh.name);
                assert!(
                    (count as f64) < share,
                    "{}: {count} of share {share:.0}",
                    mesh.name
                );
            }
        }
        assert_eq!(spheres, 4);
        let placed: usize = counts.iter().sum();
        assert!(
            placed.abs_diff(total) <= scene.meshes.len(),
            "{placed} placed"
        );
        // The boost is bounded: a unit sphere sampled 1.8 apart turns more than a radian per
        // spacing, (θ/θ₀)² > 16, and gets the cap.
        assert_eq!(curvature_boost(&plane(0.1), 0.05, 0), 1.0);
        let sphere = crate::scene::builtin::procedural::icosphere("sphere", 0, 1.0, 0.05, false);
        assert!(normal_turn(&sphere, 1.8, 0) > 1.0);
        assert_eq!(curvature_boost(&sphere, 1.8, 0), MAX_CURVATURE_BOOST);
    }

    #[test]
    fn points_come_in_compact_patches() {
        // Consecutive runs of 32 of 512 points cover a small part of the plane on average
        // (a sixteenth, where a run straddles no curve jump): in a random order every run
        // would span nearly all of it.
        let a = place(&plane(0.1), 512, 3);
        let areas: Vec<f32> = a
            .positions
            .chunks(32)
            .map(|run| {
                let (lo, hi) = run.iter().fold(
                    (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
                    |(lo, hi), p| (lo.min(*p), hi.max(*p)),
                );
                (hi.x - lo.x) * (hi.z - lo.z)
            })
            .collect();
        let mean = areas.iter().sum::<f32>() / areas.len() as f32;
        assert!(
            mean < 0.15,
            "runs of 32 span {mean} of the plane on average: {areas:?}"
        );
    }

    #[test]
    fn placement_is_deterministic_blue_noise_on_the_surface() {
        let mesh = plane(0.1);
        let a = place(&mesh, 200, 7);
        let b = place(&mesh, 200, 7);
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.positions.len(), 200);
        for p in &a.positions {
            assert!(p.y.abs() < 1e-6 && (0.0..=1.0).contains(&p.x) && (0.0..=1.0).contains(&p.z));
        }
        // Blue noise: no two points much closer than the packing spacing. Uniform random
        // points would have a minimum distance far below it.
        let spacing = (1.0 / (2.0 * 3f32.sqrt() * 200.0)).sqrt() * 2.0;
        let mut min_d = f32::MAX;
        for (i, p) in a.positions.iter().enumerate() {
            for q in &a.positions[i + 1..] {
                min_d = min_d.min((*p - *q).length());
            }
        }
        assert!(
            min_d > 0.4 * spacing,
            "min distance {min_d} vs spacing {spacing}"
        );
    }

    #[test]
    fn links_are_nearest_and_normalized() {
        let mesh = plane(0.1);
        let pts = place(&mesh, 64, 1);
        assert_eq!(pts.links.len(), mesh.positions.len());
        for (v, row) in mesh.positions.iter().zip(&pts.links) {
            let total: f32 = row.iter().map(|l| l.weight).sum();
            assert!((total - 1.0).abs() < 1e-5);
            // The nearest point overall is among the links, with the largest weight.
            let nearest = (0..pts.positions.len())
                .min_by(|&a, &b| {
                    (pts.positions[a] - *v)
                        .length()
                        .total_cmp(&(pts.positions[b] - *v).length())
                })
                .unwrap();
            let best = row
                .iter()
                .max_by(|a, b| a.weight.total_cmp(&b.weight))
                .unwrap();
            assert_eq!(best.point as usize, nearest);
        }
        assert!(pts.disc_radius.iter().all(|&r| r > 0.0));
    }

    #[test]
    fn a_pick_shows_the_vertex_s_links_and_the_nearest_point_of_its_instance() {
        use crate::scene::Instance;
        let mesh = plane(0.1);
        let front = place(&mesh, 64, 5);
        let sheet = two_sided(&front);
        let scene = Scene {
            meshes: vec![mesh.clone(), mesh],
            instances: vec![Instance { mesh: 0, node: 0 }, Instance { mesh: 1, node: 1 }],
            ..Default::default()
        };
        let shift = Vec3::new(5.0, 0.0, 0.0);
        let world = vec![Mat4::IDENTITY, Mat4::from_translation(shift)];
        let points = vec![Arc::new(front.clone()), Arc::new(sheet.clone())];

        // From above, on the second instance: the front row, placed by its instance; the
        // point index counts the first instance's 64 points first.
        let eye = shift + Vec3::new(0.3, 2.0, 0.6);
        let hit = crate::scene::pick::pick(
            &scene,
            &world,
            eye,
            shift + Vec3::new(0.31, 0.0, 0.42) - eye,
        )
        .expect("the ray hits the sheet");
        assert_eq!(hit.instance, 1);
        let shown = debug_pick(&scene, &world, &points, &hit, eye).unwrap();
        let row = &sheet.links[hit.vertex as usize];
        let expected: Vec<(Vec3, f32)> = row
            .iter()
            .map(|l| (sheet.positions[l.point as usize] + shift, l.weight))
            .collect();
        assert_eq!(shown.links, expected);
        let total: f32 = shown.links.iter().map(|l| l.1).sum();
        assert!((total - 1.0).abs() < 1e-5, "weights sum to {total}");
        let (index, position) = shown.point.unwrap();
        let local = index as usize - 64;
        assert!(
            local < 64,
            "a front point (normal +y) faces the eye above: {local}"
        );
        let d = (position - hit.position).length();
        for p in &front.positions {
            assert!(d <= (*p + shift - hit.position).length() + 1e-6);
        }

        // From below, the back row and a flipped point: light that reaches the back.
        let eye = shift + Vec3::new(0.3, -2.0, 0.6);
        let hit = crate::scene::pick::pick(
            &scene,
            &world,
            eye,
            shift + Vec3::new(0.31, 0.0, 0.42) - eye,
        )
        .unwrap();
        let shown = debug_pick(&scene, &world, &points, &hit, eye).unwrap();
        let n = scene.meshes[1].positions.len();
        let back = &sheet.links[hit.vertex as usize + n];
        assert!(back.iter().all(|l| l.point as usize >= 64));
        assert_eq!(shown.links.len(), back.len());
        assert!(shown.point.unwrap().0 as usize >= 64 + 64);
    }

    /// The thin-wall room: the 2 cm wall at x ∈ [1.99, 2.01] stands on the floor and meets the
    /// back and front walls, which run through both halves of the room.
    fn thin_wall_scene(name: &str) -> Scene {
        crate::scene::load_with(name, &crate::scene::LoadParams::default()).unwrap()
    }

    /// Positive-weight links of the meshes' vertices on one side of the thin wall to points on
    /// the other side, through the wall (not over its top).
    fn links_across(scene: &Scene, points: &[Arc<MeshPoints>]) -> usize {
        let world = scene.world_from_node_at(0.0);
        let mut across = 0;
        for inst in &scene.instances {
            let (mesh, mp) = (&scene.meshes[inst.mesh], &points[inst.mesh]);
            let m = world[inst.node];
            for (row_index, row) in mp.links.iter().enumerate() {
                let v = m.transform_point3(mesh.positions[row_index % mesh.positions.len()]);
                for l in row.iter().filter(|l| l.weight > 0.0) {
                    let p = m.transform_point3(mp.positions[l.point as usize]);
                    let sides = (v.x > 2.01 && p.x < 1.99) || (v.x < 1.99 && p.x > 2.01);
                    // Where the segment meets the wall's mid-plane: below its 1.8 m top.
                    let t = (2.0 - v.x) / (p.x - v.x);
                    let through = (v + t * (p - v)).y < 1.8;
                    across += (sides && through) as usize;
                }
            }
        }
        across
    }

    #[test]
    fn links_through_a_thin_wall_are_cut_and_the_rest_renormalized() {
        let scene = thin_wall_scene("thin-wall");
        let (points, _) = scene_points(&scene, 4096, 1);
        let before = links_across(&scene, &points);
        let (cut_points, cut) = cut_links_through_walls(&scene, &points);
        let after = links_across(&scene, &cut_points);
        eprintln!("links across the thin wall: {before} → {after}; {cut:?}");
        assert!(
            before > 100,
            "the room's walls link across the thin wall: {before}"
        );
        // What is left belongs to rows whose every link was blocked (kept whole).
        assert!(
            after <= 8 * cut.kept_rows,
            "{after} of {before} links still cross"
        );
        assert_eq!(
            cut.meshes,
            scene.instances.len(),
            "every mesh is placed once and still"
        );
        assert!(cut.links > 0);
        for (a, b) in points.iter().zip(&cut_points) {
            for (ra, rb) in a.links.iter().zip(&b.links) {
                let total: f32 = rb.iter().map(|l| l.weight).sum();
                let was: f32 = ra.iter().map(|l| l.weight).sum();
                assert!(
                    (total - was).abs() < 1e-4,
                    "a row's weights sum to {total}, were {was}"
                );
                for (la, lb) in ra.iter().zip(rb) {
                    assert_eq!(la.point, lb.point, "a cut keeps the points, zeroes weights");
                    assert!(lb.weight == 0.0 || la.weight > 0.0);
                }
            }
        }
        // Nothing is cut where nothing stands between: one lone quad.
        let open = Scene {
            meshes: vec![plane(0.1)],
            instances: vec![crate::scene::Instance { mesh: 0, node: 0 }],
            nodes: scene.nodes[..1].to_vec(),
            ..Default::default()
        };
        let (open_points, _) = scene_points(&open, 64, 1);
        let (_, open_cut) = cut_links_through_walls(&open, &open_points);
        assert_eq!((open_cut.meshes, open_cut.links), (1, 0));
    }

    #[test]
    fn moving_geometry_neither_blocks_nor_is_tested() {
        // The door of door-room-moving swings: its links are not tested, and it blocks no
        // link of the still walls, so every cut is one the still door-room (door at 30°)
        // makes too, and the door itself is never cut.
        let moving = thin_wall_scene("door-room-moving");
        let flags = moving.moving_nodes();
        assert!(flags.iter().any(|&m| m) && !flags.iter().all(|&m| m));
        let door: Vec<usize> = (0..moving.instances.len())
            .filter(|&i| flags[moving.instances[i].node])
            .collect();
        assert!(!door.is_empty(), "the door's instances move");
        let (points, _) = scene_points(&moving, 4096, 1);
        let (cut_points, cut) = cut_links_through_walls(&moving, &points);
        assert_eq!(cut.meshes, moving.instances.len() - door.len());
        for &i in &door {
            let mesh = moving.instances[i].mesh;
            assert_eq!(
                points[mesh].links, cut_points[mesh].links,
                "a moving mesh is not cut"
            );
        }
    }
}
