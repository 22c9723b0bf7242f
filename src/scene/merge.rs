//! Flat regions merged into a few triangles: the same surface with the same interpolated
//! attributes, for the ray tracer's BVH and the light bake's depth maps.
//!
//! The built-in scenes tessellate every wall into ~5 cm triangles because the per-vertex
//! methods need vertices there (the corridor has 82 482 triangles, ten rectangles' worth). A ray
//! or a depth-map rasterizer gains nothing from them and pays per triangle: merged, the
//! corridor is 20 triangles, and its path tracer and its light bake both run over 2× faster.
//!
//! A region (triangles joined by shared edges, in one plane, facing one way) becomes a fan over
//! its corners only when nothing a renderer reads can change:
//! - it is a topological disc (one boundary loop, V − E + F = 1, every interior edge shared by
//!   two triangles of opposite winding) whose boundary, after dropping collinear vertices, is a
//!   strictly convex polygon, so the fan covers exactly the region (areas are compared too);
//! - vertex normals and tangents are constant over it, and uv0 and uv1 are affine in position
//!   (checked at every vertex), so barycentric interpolation over a fan triangle gives what it
//!   gave over the original ones.
//!
//! The fans index the mesh's own vertex arrays (corners are original vertices), so nothing is
//! copied or re-derived. Everything else is kept as it was.

use std::collections::{HashMap, HashSet};

use glam::{DVec3, Vec3};

use super::{mesh, Mesh};

/// Vertices may lie this far off a region's plane, relative to the mesh's extent (a grid
/// vertex interpolated from four corners is a few ulps off; 4e-6 of a 5 m room is 20 µm, far
/// below the tracer's 1e-4 ray offset).
const PLANE_TOLERANCE: f32 = 4e-6;

/// Looser bound used while a region grows around its first triangle, whose own normal is only
/// as precise as its few-centimetre edges allow (tilted by ~1e-5 on the corridor's walls:
/// 30 µm at the far end of a 2.4 m wall). The grown region's plane is then fitted to all its
/// triangles and every vertex checked against [`PLANE_TOLERANCE`].
const GROWTH_TOLERANCE: f32 = 1e-4;

/// Largest difference per component of unit normals and tangents counted as equal (a
/// vertex normal averaged over a few 5 cm triangles wobbles by ~2e-5).
const DIRECTION_TOLERANCE: f32 = 1e-4;

/// Largest relative difference of a vertex's uv from the region's affine fit.
const UV_TOLERANCE: f32 = 1e-5;

/// Index list of `mesh` with every mergeable flat region replaced by a fan over its corners
/// (see the module docs). Triangles with an out-of-range or repeated index are left out; every
/// other triangle is kept or merged, so the surface is unchanged. `uvs_matter: false` skips
/// the uv check, for a caller that never reads them (the tracer on an untextured material:
/// Cornell's trapezoid walls have bilinear grid uvs but nothing samples them).
pub fn flat_region_indices(mesh: &Mesh, uvs_matter: bool) -> Vec<u32> {
    let vertex_count = mesh.positions.len();
    let triangles: Vec<[u32; 3]> = mesh
        .indices
        .chunks_exact(3)
        .filter(|t| mesh::triangle(t, vertex_count).is_some())
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    let p = |v: u32| mesh.positions[v as usize];
    let normals: Vec<Option<Vec3>> = triangles
        .iter()
        .map(|&[a, b, c]| {
            (p(b) - p(a))
                .cross(p(c) - p(a))
                .try_normalize()
                .filter(|_| p(a).is_finite() && p(b).is_finite() && p(c).is_finite())
        })
        .collect();
    let mut edges: HashMap<(u32, u32), (u32, u32, u8)> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let e = edges
                .entry((a.min(b), a.max(b)))
                .or_insert((t as u32, u32::MAX, 0));
            if e.2 == 1 {
                e.1 = t as u32;
            }
            e.2 = e.2.saturating_add(1);
        }
    }
    let extent = mesh
        .model_bounds()
        .extent()
        .max_element()
        .clamp(1e-6, f32::MAX);
    let plane_tolerance = PLANE_TOLERANCE * extent;
    let growth_tolerance = GROWTH_TOLERANCE * extent;

    let mut visited = vec![false; triangles.len()];
    let mut out = Vec::with_capacity(mesh.indices.len());
    let mut region = Vec::new();
    for seed in 0..triangles.len() {
        if visited[seed] {
            continue;
        }
        visited[seed] = true;
        let Some(n0) = normals[seed] else {
            out.extend_from_slice(&triangles[seed]);
            continue;
        };
        let seed_vertex = triangles[seed][0];
        let d0 = n0.dot(p(seed_vertex));
        let fits = |t: usize| {
            normals[t].is_some_and(|n| n.dot(n0) > 1.0 - 1e-5)
                && triangles[t].iter().all(|&v| {
                    (n0.dot(p(v)) - d0).abs() <= growth_tolerance
                        && same_shading_frame(mesh, v, seed_vertex)
                })
        };
        if !fits(seed) {
            out.extend_from_slice(&triangles[seed]);
            continue;
        }
        region.clear();
        region.push(seed);
        let mut next = 0;
        while next < region.len() {
            let current = region[next];
            let tri = triangles[current];
            next += 1;
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                let &(t0, t1, count) = &edges[&(a.min(b), a.max(b))];
                if count != 2 {
                    continue;
                }
                let other = if t0 as usize == current { t1 } else { t0 } as usize;
                if !visited[other] && fits(other) {
                    visited[other] = true;
                    region.push(other);
                }
            }
        }
        region.sort_unstable();
        let members: Vec<[u32; 3]> = region.iter().map(|&t| triangles[t]).collect();
        // The region's plane: area-weighted normal and centroid of its triangles, summed in
        // f64 (in f32, 13k small terms put the corridor ceiling's centroid 0.5 mm off).
        let (mut normal_sum, mut centroid_sum, mut area_sum) = (DVec3::ZERO, DVec3::ZERO, 0.0);
        for &[a, b, c] in &members {
            let [a, b, c] = [a, b, c].map(|v| p(v).as_dvec3());
            let cross = (b - a).cross(c - a);
            let area = cross.length();
            normal_sum += cross;
            centroid_sum += (a + b + c) * (area / 3.0);
            area_sum += area;
        }
        let normal = normal_sum.normalize_or_zero().as_vec3();
        let centroid = (centroid_sum / area_sum.max(f64::MIN_POSITIVE)).as_vec3();
        let flat = normal != Vec3::ZERO
            && members
                .iter()
                .flatten()
                .all(|&v| normal.dot(p(v) - centroid).abs() <= plane_tolerance);
        match flat
            .then(|| fan(mesh, &members, normal, plane_tolerance, uvs_matter))
            .flatten()
        {
            Some(fan) if fan.len() < members.len() => {
                out.extend(fan.into_iter().flatten());
            }
            _ => out.extend(members.into_iter().flatten()),
        }
    }
    out
}

/// Equal normals and tangents at vertices `a` and `b` (where the mesh has them).
fn same_shading_frame(mesh: &Mesh, a: u32, b: u32) -> bool {
    let (a, b) = (a as usize, b as usize);
    let close = |x: Vec3, y: Vec3| (x - y).abs().max_element() <= DIRECTION_TOLERANCE;
    let normals =
        mesh.normals.len() != mesh.positions.len() || close(mesh.normals[a], mesh.normals[b]);
    let tangents = mesh.tangents.len() != mesh.positions.len()
        || (close(mesh.tangents[a].truncate(), mesh.tangents[b].truncate())
            && mesh.tangents[a].w == mesh.tangents[b].w);
    normals && tangents
}

/// The fan over a flat region's corners when the region is a disc bounded by a convex
/// polygon with affine uvs; `None` otherwise.
fn fan(
    mesh: &Mesh,
    region: &[[u32; 3]],
    n0: Vec3,
    plane_tolerance: f32,
    uvs_matter: bool,
) -> Option<Vec<[u32; 3]>> {
    let p = |v: u32| mesh.positions[v as usize];
    let mut directed: HashSet<(u32, u32)> = HashSet::with_capacity(region.len() * 3);
    let mut vertices: Vec<u32> = Vec::with_capacity(region.len() * 3);
    for tri in region {
        for k in 0..3 {
            if !directed.insert((tri[k], tri[(k + 1) % 3])) {
                return None; // two triangles wound the same way over one edge: a fold
            }
            vertices.push(tri[k]);
        }
    }
    vertices.sort_unstable();
    vertices.dedup();
    // Boundary: directed edges whose twin is not in the region; one outgoing per vertex.
    let mut next: HashMap<u32, u32> = HashMap::new();
    for &(a, b) in &directed {
        if !directed.contains(&(b, a)) && next.insert(a, b).is_some() {
            return None; // the boundary touches itself at a
        }
    }
    let boundary = next.len();
    let edge_count = boundary + (directed.len() - boundary) / 2;
    if vertices.len() as i64 - edge_count as i64 + region.len() as i64 != 1 {
        return None;
    }
    // Walk the loop from its smallest vertex (deterministic), along the triangles' winding.
    let start = *next.keys().min()?;
    let mut ring = Vec::with_capacity(boundary);
    let mut v = start;
    loop {
        ring.push(v);
        v = next[&v];
        if v == start {
            break;
        }
        if ring.len() > boundary {
            return None;
        }
    }
    if ring.len() != boundary {
        return None; // several loops: holes
    }
    // Corners: vertices where the boundary turns, i.e. further than the tolerance from the
    // line through their neighbours (an angle test would call a few ulps of noise on a 5 cm
    // edge a corner).
    let m = ring.len();
    let corners: Vec<usize> = (0..m)
        .filter(|&i| {
            let (a, b, c) = (p(ring[(i + m - 1) % m]), p(ring[i]), p(ring[(i + 1) % m]));
            let (base, side) = (c - a, b - a);
            base.cross(side).length() > plane_tolerance * base.length()
                || side.dot(base) <= 0.0
                || side.dot(base) >= base.length_squared()
        })
        .collect();
    if corners.len() < 3 {
        return None;
    }
    // The dropped vertices must lie on the chords between their corners, and every corner
    // must turn the way the triangles wind (strictly convex).
    for (k, &c) in corners.iter().enumerate() {
        let c_next = corners[(k + 1) % corners.len()];
        let (a, b) = (p(ring[c]), p(ring[c_next]));
        let chord = b - a;
        let mut i = (c + 1) % m;
        while i != c_next {
            let x = p(ring[i]) - a;
            let along = x.dot(chord) / chord.length_squared();
            let off_line = x - chord * along;
            if off_line.length() > plane_tolerance || !(0.0..=1.0).contains(&along) {
                return None;
            }
            i = (i + 1) % m;
        }
        let after = p(ring[corners[(k + 2) % corners.len()]]);
        if chord.cross(after - b).dot(n0) <= 0.0 {
            return None;
        }
    }
    let corner_vertices: Vec<u32> = corners.iter().map(|&i| ring[i]).collect();
    let fan: Vec<[u32; 3]> = (1..corner_vertices.len() - 1)
        .map(|i| {
            [
                corner_vertices[0],
                corner_vertices[i],
                corner_vertices[i + 1],
            ]
        })
        .collect();
    let area = |t: &[u32; 3]| 0.5 * (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).dot(n0) as f64;
    let (region_area, fan_area): (f64, f64) =
        (region.iter().map(area).sum(), fan.iter().map(area).sum());
    if (region_area - fan_area).abs() > 1e-5 * region_area.abs() {
        return None; // overlapping triangles
    }
    if !uvs_matter {
        return Some(fan);
    }
    // uvs affine in position: fit on a well-spread corner triangle, check every vertex.
    let c0 = corner_vertices[0];
    let c1 = *corner_vertices.iter().max_by(|&&a, &&b| {
        p(a).distance_squared(p(c0))
            .total_cmp(&p(b).distance_squared(p(c0)))
    })?;
    let c2 = *corner_vertices.iter().max_by(|&&a, &&b| {
        let spread = |v: u32| (p(c1) - p(c0)).cross(p(v) - p(c0)).length_squared();
        spread(a).total_cmp(&spread(b))
    })?;
    let frame = [c0, c1, c2];
    let [a, b, c] = frame.map(p);
    let (e1, e2) = (b - a, c - a);
    let cross = e1.cross(e2);
    let area2 = cross.length_squared();
    // Barycentrics of every region vertex in the frame triangle (extended over the plane).
    let weights: Vec<(f32, f32)> = vertices
        .iter()
        .map(|&v| {
            let rel = p(v) - a;
            (
                rel.cross(e2).dot(cross) / area2,
                e1.cross(rel).dot(cross) / area2,
            )
        })
        .collect();
    for uvs in [Some(&mesh.uv0), mesh.uv1.as_ref()].into_iter().flatten() {
        if uvs.len() != mesh.positions.len() {
            continue;
        }
        if area2 <= 0.0 {
            return None;
        }
        let [ua, ub, uc] = frame.map(|v| uvs[v as usize]);
        for (&v, &(w1, w2)) in vertices.iter().zip(&weights) {
            let want = uvs[v as usize];
            let got = ua + (ub - ua) * w1 + (uc - ua) * w2;
            if (got - want).abs().max_element() > UV_TOLERANCE * (1.0 + want.abs().max_element()) {
                return None;
            }
        }
    }
    Some(fan)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::mesh::MeshBuilder;
    use glam::{Vec2, Vec4};

    fn built(build: impl FnOnce(&mut MeshBuilder)) -> Mesh {
        let mut b = MeshBuilder::new("test", 0);
        build(&mut b);
        b.build()
    }

    fn rectangle(max_edge: f32) -> Mesh {
        built(|b| {
            b.add_quad(
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.6),
                Vec3::new(0.0, 0.0, 0.6),
                Vec3::new(0.5, 1.0, 0.3),
                max_edge,
            )
        })
    }

    /// Barycentric uv0 of the point `x` of the plane y = `y` under `indices`, or `None` when
    /// no triangle covers it (a vertical ray at x, z).
    fn uv_at(mesh: &Mesh, indices: &[u32], x: f32, z: f32) -> Option<(Vec2, Vec3)> {
        for t in indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|v| mesh.positions[v as usize]);
            let (e1, e2) = (b - a, c - a);
            let n = e1.cross(e2);
            if n.y.abs() < 1e-12 {
                continue;
            }
            let y = a.y - (n.x * (x - a.x) + n.z * (z - a.z)) / n.y;
            let q = Vec3::new(x, y, z) - a;
            let w1 = q.cross(e2).dot(n) / n.length_squared();
            let w2 = e1.cross(q).dot(n) / n.length_squared();
            if w1 >= 0.0 && w2 >= 0.0 && w1 + w2 <= 1.0 {
                let uv = [t[0], t[1], t[2]].map(|v| mesh.uv0[v as usize]);
                return Some((
                    uv[0] * (1.0 - w1 - w2) + uv[1] * w1 + uv[2] * w2,
                    n.normalize(),
                ));
            }
        }
        None
    }

    #[test]
    fn tessellated_rectangle_becomes_two_triangles_with_the_same_surface_and_uvs() {
        let mesh = rectangle(0.05);
        assert!(mesh.triangle_count() > 400);
        let merged = flat_region_indices(&mesh, true);
        assert_eq!(merged.len(), 6, "a rectangle is two triangles");
        // Same coverage, same uv and the same winding at points inside and outside.
        let mut inside = 0;
        for i in 0..=40 {
            for k in 0..=40 {
                let (x, z) = (
                    -0.1 + 1.2 * i as f32 / 40.0 + 1e-3,
                    -0.1 + 0.8 * k as f32 / 40.0,
                );
                let fine = uv_at(&mesh, &mesh.indices, x, z);
                let coarse = uv_at(&mesh, &merged, x, z);
                assert_eq!(fine.is_some(), coarse.is_some(), "coverage at ({x}, {z})");
                if let (Some((a, na)), Some((b, nb))) = (fine, coarse) {
                    inside += 1;
                    assert!((a - b).abs().max_element() < 1e-5, "uv {a} vs {b}");
                    assert!(na.dot(nb) > 0.999_99, "winding");
                }
            }
        }
        assert!(inside > 500);
    }

    #[test]
    fn a_box_merges_face_by_face() {
        let mesh = built(|b| {
            b.add_box_from_top(
                [
                    Vec3::new(0.0, 1.0, 0.0),
                    Vec3::new(1.0, 1.0, 0.0),
                    Vec3::new(1.0, 1.0, 1.0),
                    Vec3::new(0.0, 1.0, 1.0),
                ],
                0.0,
                0.1,
            )
        });
        assert_eq!(flat_region_indices(&mesh, true).len(), 5 * 6);
    }

    #[test]
    fn a_trapezoid_with_bilinear_uvs_is_kept() {
        // Planar and convex, but the grid's uv is bilinear, not affine, in position.
        let mesh = built(|b| {
            b.add_quad(
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(0.7, 0.0, 1.0),
                Vec3::new(0.3, 0.0, 1.0),
                Vec3::new(0.5, 1.0, 0.5),
                0.1,
            )
        });
        assert_eq!(flat_region_indices(&mesh, true), mesh.indices);
        assert_eq!(
            flat_region_indices(&mesh, false).len(),
            6,
            "geometry alone merges"
        );
    }

    /// An n × n grid of unit cells in y = 0 with shared vertices, uv = (x, z), leaving out
    /// the cells for which `skip` is true.
    fn grid(n: u32, skip: impl Fn(u32, u32) -> bool) -> Mesh {
        let mut positions = vec![];
        let mut uv0 = vec![];
        for k in 0..=n {
            for i in 0..=n {
                positions.push(Vec3::new(i as f32, 0.0, k as f32));
                uv0.push(Vec2::new(i as f32, k as f32));
            }
        }
        let mut indices = vec![];
        for k in 0..n {
            for i in 0..n {
                if skip(i, k) {
                    continue;
                }
                let a = k * (n + 1) + i;
                let (b, c, d) = (a + 1, a + n + 2, a + n + 1);
                // Counter-clockwise seen from +y.
                indices.extend_from_slice(&[a, c, b, a, d, c]);
            }
        }
        Mesh {
            name: "grid".into(),
            normals: vec![Vec3::Y; positions.len()],
            positions,
            tangents: vec![],
            uv0,
            uv1: None,
            indices,
            material: 0,
        }
    }

    #[test]
    fn shared_vertex_grid_merges_and_non_convex_or_holed_regions_are_kept() {
        let full = grid(4, |_, _| false);
        assert_eq!(flat_region_indices(&full, true).len(), 6);
        let l_shape = grid(4, |i, k| i >= 2 && k >= 2);
        assert_eq!(flat_region_indices(&l_shape, true), l_shape.indices);
        let ring = grid(3, |i, k| i == 1 && k == 1);
        assert_eq!(flat_region_indices(&ring, true), ring.indices);
    }

    #[test]
    fn varying_normals_tangents_or_uv1_stop_a_merge() {
        let mut smooth = grid(3, |_, _| false);
        smooth.normals[5] = Vec3::new(0.1, 1.0, 0.0).normalize();
        let merged = flat_region_indices(&smooth, true);
        assert!(merged.len() > 6, "the vertex with its own normal must stay");
        // Whatever merges around it, nothing is lost: the areas add up.
        let area = |idx: &[u32]| -> f32 {
            idx.chunks_exact(3)
                .map(|t| {
                    let [a, b, c] = [t[0], t[1], t[2]].map(|v| smooth.positions[v as usize]);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum()
        };
        assert!((area(&merged) - 9.0).abs() < 1e-4);

        let mut tangents = grid(2, |_, _| false);
        tangents.tangents = vec![Vec4::new(1.0, 0.0, 0.0, 1.0); tangents.positions.len()];
        assert_eq!(flat_region_indices(&tangents, true).len(), 6);
        tangents.tangents[4].w = -1.0;
        assert_eq!(flat_region_indices(&tangents, true), tangents.indices);

        let mut uv1 = grid(2, |_, _| false);
        uv1.uv1 = Some(uv1.uv0.iter().map(|uv| *uv * 0.5).collect());
        assert_eq!(flat_region_indices(&uv1, true).len(), 6);
        uv1.uv1.as_mut().unwrap()[4].x += 0.1;
        assert_eq!(flat_region_indices(&uv1, true), uv1.indices);
    }

    #[test]
    fn bent_and_broken_input_is_kept_without_panicking() {
        let mut bent = grid(2, |_, _| false);
        bent.positions[4].y = 0.01;
        bent.normals = mesh::compute_normals(&bent.positions, &bent.indices);
        let merged = flat_region_indices(&bent, true);
        assert_eq!(
            merged.len(),
            bent.indices.len(),
            "nothing flat enough to merge"
        );

        let mut broken = grid(2, |_, _| false);
        broken.positions[0] = Vec3::NAN;
        broken.indices.extend_from_slice(&[0, 0, 1, 2, 3, 99]);
        let merged = flat_region_indices(&broken, true);
        assert!(merged
            .iter()
            .all(|&v| (v as usize) < broken.positions.len()));
        // The NaN corner's triangle is kept (the tracer drops it); the rest still covers its
        // part of the grid.
        assert!(merged.chunks_exact(3).any(|t| t.contains(&0)));
    }
}
