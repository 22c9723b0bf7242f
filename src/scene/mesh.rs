//! Geometry utilities shared by the glTF importer and the built-in scenes: normals, tangents,
//! clean-up, validation, edge-length tessellation and a small builder for procedural quads.
//!
//! Everything here works in model space and must never produce NaN: the sparse-point placement
//! and the light atlas downstream divide by normals and areas, so a single bad vertex would
//! poison a whole frame.

use super::{Mesh, Scene};
use glam::{Vec2, Vec3, Vec4};
use std::collections::HashMap;

/// Triangle count above which [`tessellate`] stops refining (with a warning): beyond it the
/// GPU buffers and the sparse-point preprocessing get impractically large.
pub const MAX_TESSELLATED_TRIANGLES: usize = 4_000_000;

/// Area-weighted vertex normals: every triangle adds its (unnormalized) cross product, whose
/// length is twice its area, to its three vertices. A vertex that no valid triangle touches, or
/// whose contributions cancel, gets +Y so downstream code never sees a zero or NaN normal.
/// Triangles with an out-of-range index are skipped.
pub fn compute_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut sums = vec![Vec3::ZERO; positions.len()];
    for tri in indices.chunks_exact(3) {
        let Some([a, b, c]) = triangle(tri, positions.len()) else {
            continue;
        };
        let n = (positions[b] - positions[a]).cross(positions[c] - positions[a]);
        if !n.is_finite() {
            continue;
        }
        sums[a] += n;
        sums[b] += n;
        sums[c] += n;
    }
    sums.into_iter().map(|n| n.normalize_or(Vec3::Y)).collect()
}

/// Per-vertex tangents (xyz unit, w = bitangent handedness ±1) from the UV derivatives of the
/// incident triangles (Lengyel's method), orthogonalized against the vertex normal
/// (Gram–Schmidt). Where the UVs are degenerate (zero UV area, missing UVs) the tangent falls
/// back to an arbitrary unit vector perpendicular to the normal, so normal mapping degrades to
/// "some frame" instead of NaN.
pub fn compute_tangents(
    positions: &[Vec3],
    normals: &[Vec3],
    uvs: &[Vec2],
    indices: &[u32],
) -> Vec<Vec4> {
    let n = positions.len();
    let mut tan_u = vec![Vec3::ZERO; n];
    let mut tan_v = vec![Vec3::ZERO; n];
    let uv = |i: usize| uvs.get(i).copied().unwrap_or(Vec2::ZERO);
    for tri in indices.chunks_exact(3) {
        let Some([a, b, c]) = triangle(tri, n) else {
            continue;
        };
        let e1 = positions[b] - positions[a];
        let e2 = positions[c] - positions[a];
        let d1 = uv(b) - uv(a);
        let d2 = uv(c) - uv(a);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det.abs() < 1e-20 || !det.is_finite() {
            continue;
        }
        // ∂p/∂u and ∂p/∂v are (e1·d2.y − e2·d1.y)/det and (e2·d1.x − e1·d2.x)/det. Scaling
        // both by |det| (the triangle's UV area) weights each triangle's contribution by its
        // share of the texture, and avoids dividing by tiny determinants.
        let sign = det.signum();
        let su = (e1 * d2.y - e2 * d1.y) * sign;
        let sv = (e2 * d1.x - e1 * d2.x) * sign;
        if !su.is_finite() || !sv.is_finite() {
            continue;
        }
        for v in [a, b, c] {
            tan_u[v] += su;
            tan_v[v] += sv;
        }
    }
    (0..n)
        .map(|i| {
            let normal = normals
                .get(i)
                .copied()
                .unwrap_or(Vec3::Y)
                .normalize_or(Vec3::Y);
            let t = tan_u[i] - normal * normal.dot(tan_u[i]);
            let t = t
                .try_normalize()
                .unwrap_or_else(|| normal.any_orthonormal_vector());
            let w = if normal.cross(t).dot(tan_v[i]) < 0.0 {
                -1.0
            } else {
                1.0
            };
            t.extend(w)
        })
        .collect()
}

/// Removes triangles that cannot be shaded: repeated indices, out-of-range indices, and
/// (near-)zero area, where "zero" is `area < 1e-12 × bbox_diagonal²` so the test scales with the
/// model's units. A trailing incomplete triangle is dropped too. Returns the number of
/// triangles removed.
pub fn remove_degenerate_triangles(positions: &[Vec3], indices: &mut Vec<u32>) -> usize {
    let mut min = Vec3::splat(f32::INFINITY);
    let mut max = Vec3::splat(f32::NEG_INFINITY);
    for p in positions.iter().filter(|p| p.is_finite()) {
        min = min.min(*p);
        max = max.max(*p);
    }
    let diag2 = if min.x <= max.x {
        (max - min).length_squared()
    } else {
        0.0
    };
    let min_area = 1e-12 * diag2;
    let before = indices.len() / 3;
    let mut kept = Vec::with_capacity(indices.len());
    for tri in indices.chunks_exact(3) {
        let Some([a, b, c]) = triangle(tri, positions.len()) else {
            continue;
        };
        let area = 0.5
            * (positions[b] - positions[a])
                .cross(positions[c] - positions[a])
                .length();
        // `area > min_area` is false for NaN, which removes non-finite triangles as well.
        if area > min_area {
            kept.extend_from_slice(tri);
        }
    }
    *indices = kept;
    before - indices.len() / 3
}

/// Checks that every position is finite; the error names the first offending vertex.
pub fn validate_positions(positions: &[Vec3]) -> Result<(), String> {
    match positions.iter().position(|p| !p.is_finite()) {
        None => Ok(()),
        Some(i) => Err(format!(
            "vertex {i} has a non-finite position ({}, {}, {})",
            positions[i].x, positions[i].y, positions[i].z
        )),
    }
}

/// Refines `mesh` until no triangle edge is longer than `max_edge` (model-space units).
///
/// Each pass marks every edge longer than `max_edge` and splits it at its midpoint; the
/// midpoint vertex is shared through a map keyed by the sorted vertex-index pair, and each
/// triangle is re-triangulated according to how many of its edges are marked (1 → 2, 2 → 3,
/// 3 → 4 triangles). Because the marking is per edge rather than per triangle, both triangles
/// on an edge split it identically, so no T-junctions or cracks appear. This is longest-edge
/// midpoint subdivision done breadth-first: the longest edges are always among those split.
/// New interior edges are either shorter than `max_edge` (medians in the 1-edge case) or
/// picked up by the next pass.
///
/// All vertex attributes are interpolated: positions and UVs linearly, normals and tangent
/// directions renormalized. Refinement stops with a warning before the mesh would exceed
/// [`MAX_TESSELLATED_TRIANGLES`]. Returns whether every edge now is at most `max_edge`.
pub fn tessellate(mesh: &mut Mesh, max_edge: f32) -> bool {
    if !(max_edge.is_finite() && max_edge > 0.0) {
        log::warn!(
            "tessellate {}: ignoring invalid max_edge {max_edge}",
            mesh.name
        );
        return false;
    }
    let mut complete = true;
    let max2 = max_edge * max_edge;
    let vertex_count = mesh.positions.len();
    let has_normals = mesh.normals.len() == vertex_count;
    let has_tangents = mesh.tangents.len() == vertex_count;
    let has_uv0 = mesh.uv0.len() == vertex_count;
    let has_uv1 = mesh.uv1.as_ref().is_some_and(|u| u.len() == vertex_count);
    if !has_uv1 {
        // A light-map UV set of the wrong length cannot be interpolated; drop it rather than
        // hand out a mesh whose attributes disagree.
        mesh.uv1 = None;
    }
    // Drop triangles that reference missing vertices up front; they would index out of bounds.
    let mut tris: Vec<[u32; 3]> = mesh
        .indices
        .chunks_exact(3)
        .filter_map(|t| triangle(t, vertex_count).map(|_| [t[0], t[1], t[2]]))
        .collect();

    loop {
        let long = |a: u32, b: u32| {
            (mesh.positions[a as usize] - mesh.positions[b as usize]).length_squared() > max2
        };
        // Edges to split this pass, mapped to their (future) midpoint vertex.
        let mut midpoints: HashMap<(u32, u32), u32> = HashMap::new();
        let mut new_tri_count = 0usize;
        for t in &tris {
            let mut marked = 0;
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if long(a, b) {
                    marked += 1;
                    midpoints.insert(edge_key(a, b), u32::MAX);
                }
            }
            new_tri_count += 1 + marked;
        }
        if midpoints.is_empty() {
            break;
        }
        if new_tri_count > MAX_TESSELLATED_TRIANGLES {
            log::warn!(
                "tessellate {}: stopping at {} triangles (next pass would make {new_tri_count}, \
                 cap {MAX_TESSELLATED_TRIANGLES}); some edges stay longer than {max_edge}",
                mesh.name,
                tris.len()
            );
            complete = false;
            break;
        }
        if mesh.positions.len() + midpoints.len() > u32::MAX as usize {
            log::warn!("tessellate {}: vertex count would overflow u32", mesh.name);
            complete = false;
            break;
        }
        // Create midpoint vertices in a deterministic order (sorted edge keys) so the result
        // does not depend on HashMap iteration order.
        let mut keys: Vec<(u32, u32)> = midpoints.keys().copied().collect();
        keys.sort_unstable();
        for (a, b) in keys {
            let (ia, ib) = (a as usize, b as usize);
            let index = mesh.positions.len() as u32;
            mesh.positions
                .push((mesh.positions[ia] + mesh.positions[ib]) * 0.5);
            if has_normals {
                let n = (mesh.normals[ia] + mesh.normals[ib]).normalize_or(mesh.normals[ia]);
                mesh.normals.push(n);
            }
            if has_tangents {
                let (ta, tb) = (mesh.tangents[ia], mesh.tangents[ib]);
                let t = (ta.truncate() + tb.truncate()).normalize_or(ta.truncate());
                mesh.tangents.push(t.extend(ta.w));
            }
            if has_uv0 {
                mesh.uv0.push((mesh.uv0[ia] + mesh.uv0[ib]) * 0.5);
            }
            if has_uv1 {
                if let Some(uv1) = mesh.uv1.as_mut() {
                    uv1.push((uv1[ia] + uv1[ib]) * 0.5);
                }
            }
            midpoints.insert((a, b), index);
        }
        let positions = &mesh.positions;
        let mut next = Vec::with_capacity(new_tri_count);
        for t in &tris {
            let mid = |k: usize| midpoints.get(&edge_key(t[k], t[(k + 1) % 3])).copied();
            let m = [mid(0), mid(1), mid(2)];
            split_triangle(*t, m, positions, &mut next);
        }
        tris = next;
    }
    mesh.indices = tris.into_iter().flatten().collect();
    complete
}

/// Triangle budget of [`tessellate_instanced`] over all of a scene's meshes.
pub const MAX_IMPORTED_TRIANGLES: usize = 2_000_000;

/// Number of triangles [`tessellate`] makes of the triangle `corners` for an edge bound
/// whose square is `max2`, counting down `budget`; `None` once the budget runs out.
///
/// Exact, because refinement is local: whether an edge is split depends only on its length,
/// which both triangles on it see alike, and the midpoint is the same `(a + b) / 2` from
/// either side; so each input triangle refines as if alone, through [`split_triangle`] itself.
fn refined_triangle_count(corners: [Vec3; 3], max2: f32, budget: usize) -> Option<usize> {
    let mut count = 0usize;
    let mut stack = vec![corners];
    let mut children = Vec::with_capacity(4);
    while let Some(p) = stack.pop() {
        let long = |k: usize| (p[k] - p[(k + 1) % 3]).length_squared() > max2;
        let marks = [long(0), long(1), long(2)];
        if !marks.iter().any(|&m| m) {
            count += 1;
            if count > budget {
                return None;
            }
            continue;
        }
        let local = [
            p[0],
            p[1],
            p[2],
            (p[0] + p[1]) * 0.5,
            (p[1] + p[2]) * 0.5,
            (p[2] + p[0]) * 0.5,
        ];
        let m = [0, 1, 2].map(|k| marks[k].then_some(3 + k as u32));
        children.clear();
        split_triangle([0, 1, 2], m, &local, &mut children);
        stack.extend(children.iter().map(|c| c.map(|i| local[i as usize])));
    }
    Some(count)
}

/// What [`tessellate_instanced`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TessellationOutcome {
    /// The world-space edge bound the meshes were refined to: the one asked for, or the
    /// shortest that keeps the scene within [`MAX_IMPORTED_TRIANGLES`]. `None` when nothing
    /// was tessellated (an invalid bound).
    pub used_max_edge: Option<f32>,
    /// Triangles over all meshes afterwards.
    pub triangles: usize,
    /// Warnings, each prefixed with the source.
    pub warnings: Vec<String>,
}

/// Refines every instanced mesh of `scene` so that no edge is longer than `max_edge` metres in
/// world space (at the rest pose): a mesh placed with scale s is tessellated to `max_edge / s`
/// in its model space, s being the largest axis scale of any instance of it. When the refined
/// scene would exceed [`MAX_IMPORTED_TRIANGLES`] (counted exactly, before any refinement, by
/// [`refined_triangle_count`]), the edge is raised to the shortest that fits, within 1 %, and
/// a warning says so.
pub fn tessellate_instanced(scene: &mut Scene, max_edge: f32, source: &str) -> TessellationOutcome {
    tessellate_within(scene, max_edge, source, MAX_IMPORTED_TRIANGLES)
}

/// [`tessellate_instanced`] with a triangle budget of `triangle_budget`.
fn tessellate_within(
    scene: &mut Scene,
    max_edge: f32,
    source: &str,
    triangle_budget: usize,
) -> TessellationOutcome {
    let mut outcome = TessellationOutcome::default();
    let existing: usize = scene.meshes.iter().map(|m| m.indices.len() / 3).sum();
    if !(max_edge.is_finite() && max_edge > 0.0) {
        outcome.warnings.push(format!(
            "{source}: max_edge {max_edge} is not a positive length; meshes not tessellated"
        ));
        outcome.triangles = existing;
        return outcome;
    }
    let world = scene.world_from_node();
    let mut scale = vec![0.0f32; scene.meshes.len()];
    for inst in &scene.instances {
        let (Some(m), Some(s)) = (world.get(inst.node), scale.get_mut(inst.mesh)) else {
            continue;
        };
        let axes = [m.x_axis, m.y_axis, m.z_axis].map(|a| a.truncate().length());
        let largest = axes[0].max(axes[1]).max(axes[2]);
        if largest.is_finite() {
            *s = s.max(largest);
        }
    }
    // Meshes no instance places are left as they are, and count as they are.
    let unplaced: usize = scene
        .meshes
        .iter()
        .zip(&scale)
        .filter(|(_, &s)| s <= 0.0)
        .map(|(m, _)| m.indices.len() / 3)
        .sum();
    let budget = triangle_budget.saturating_sub(unplaced);
    // Triangles the placed meshes would have at world edge `edge`; `None` past the budget.
    let count = |edge: f64| -> Option<usize> {
        let mut total = 0usize;
        for (mesh, &s) in scene.meshes.iter().zip(&scale) {
            if s <= 0.0 {
                continue;
            }
            let model_edge = (edge / s as f64) as f32;
            let max2 = model_edge * model_edge;
            for t in mesh.indices.chunks_exact(3) {
                let Some([a, b, c]) = triangle(t, mesh.positions.len()) else {
                    continue;
                };
                let corners = [mesh.positions[a], mesh.positions[b], mesh.positions[c]];
                total += refined_triangle_count(corners, max2, budget.checked_sub(total)?)?;
            }
        }
        Some(total)
    };
    if count(f64::INFINITY).is_none() {
        // Over budget before any refinement: refining could only add to it.
        outcome.warnings.push(format!(
            "{source}: the meshes already have {existing} triangles, over the budget of \
             {triangle_budget}; not tessellated (--max-edge {max_edge} m not applied)"
        ));
        outcome.triangles = existing;
        return outcome;
    }
    let mut edge = max_edge as f64;
    if count(edge).is_none() {
        // Bracket the shortest edge that fits, then bisect (in log space) to 1 %. An edge
        // longer than every edge of the scene fits (checked above), so the doubling ends.
        let mut low = edge;
        let mut high = edge * 2.0;
        while count(high).is_none() && high < f64::MAX / 2.0 {
            low = high;
            high *= 2.0;
        }
        while high / low > 1.01 {
            let mid = (low * high).sqrt();
            if count(mid).is_some() {
                high = mid;
            } else {
                low = mid;
            }
        }
        edge = high;
        outcome.warnings.push(format!(
            "{source}: --max-edge {max_edge} m would refine the meshes past the budget of \
             {triangle_budget} triangles; using {edge:.4} m, the shortest edge that fits"
        ));
    }
    let mut incomplete = Vec::new();
    for (mesh, &s) in scene.meshes.iter_mut().zip(&scale) {
        if s <= 0.0 {
            continue;
        }
        if !tessellate(mesh, (edge / s as f64) as f32) {
            incomplete.push(mesh.name.clone());
        }
    }
    if !incomplete.is_empty() {
        outcome.warnings.push(format!(
            "{source}: mesh(es) {} keep edges longer than {edge:.4} m (triangle cap reached)",
            incomplete.join(", ")
        ));
    }
    outcome.used_max_edge = Some(edge as f32);
    outcome.triangles = scene.meshes.iter().map(|m| m.indices.len() / 3).sum();
    outcome
}

/// Re-triangulates triangle `t` whose edges k = (t[k], t[k+1]) have midpoints `m[k]` where
/// they were split, preserving the winding.
fn split_triangle(t: [u32; 3], m: [Option<u32>; 3], positions: &[Vec3], out: &mut Vec<[u32; 3]>) {
    let count = m.iter().filter(|x| x.is_some()).count();
    match count {
        0 => out.push(t),
        3 => {
            let (m0, m1, m2) = (m[0].unwrap_or(0), m[1].unwrap_or(0), m[2].unwrap_or(0));
            out.push([t[0], m0, m2]);
            out.push([m0, t[1], m1]);
            out.push([m2, m1, t[2]]);
            out.push([m0, m1, m2]);
        }
        1 => {
            // Rotate so the split edge is (a, b).
            let k = m.iter().position(|x| x.is_some()).unwrap_or(0);
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let mab = m[k].unwrap_or(a);
            out.push([a, mab, c]);
            out.push([mab, b, c]);
        }
        _ => {
            // Two split edges: rotate so they are (a, b) and (b, c), with (c, a) intact.
            let k = (0..3)
                .find(|&k| m[k].is_some() && m[(k + 1) % 3].is_some())
                .unwrap_or(0);
            let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
            let mab = m[k].unwrap_or(a);
            let mbc = m[(k + 1) % 3].unwrap_or(b);
            out.push([mab, b, mbc]);
            // The remaining quad (a, mab, mbc, c): cut along its shorter diagonal.
            let p = |i: u32| positions[i as usize];
            if p(a).distance_squared(p(mbc)) <= p(mab).distance_squared(p(c)) {
                out.push([a, mab, mbc]);
                out.push([a, mbc, c]);
            } else {
                out.push([a, mab, c]);
                out.push([mab, mbc, c]);
            }
        }
    }
}

fn edge_key(a: u32, b: u32) -> (u32, u32) {
    if a < b {
        (a, b)
    } else {
        (b, a)
    }
}

/// The three indices of a triangle as `usize`, or `None` when one is out of range or two are
/// equal.
pub(crate) fn triangle(tri: &[u32], vertex_count: usize) -> Option<[usize; 3]> {
    let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
    if a >= vertex_count || b >= vertex_count || c >= vertex_count || a == b || b == c || a == c {
        return None;
    }
    Some([a, b, c])
}

/// Builds single-material meshes from planar-ish quads, for the procedural scenes.
///
/// Every quad becomes its own regular grid with its own vertices (no sharing across quads), so
/// a flat face gets exactly its face normal and box edges stay sharp.
#[derive(Clone, Debug)]
pub struct MeshBuilder {
    name: String,
    material: usize,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uv0: Vec<Vec2>,
    indices: Vec<u32>,
}

impl MeshBuilder {
    pub fn new(name: &str, material: usize) -> Self {
        Self {
            name: name.into(),
            material,
            positions: Vec::new(),
            normals: Vec::new(),
            uv0: Vec::new(),
            indices: Vec::new(),
        }
    }

    /// Adds the quad p0 → p1 → p2 → p3 (corners in order around it) as a regular grid whose
    /// triangles all have edges ≤ `max_edge`, front side (and normals) towards the point
    /// `facing`. uv0 is the grid parameter: (0,0) at p0, (1,0) at p1, (1,1) at p2.
    ///
    /// Each side gets at least ceil(side/max_edge) cells; the counts grow further until the
    /// cells' diagonals also fit, because the diagonal is a triangle edge too and downstream
    /// code (sparse points, atlas texels) relies on the bound holding for every edge.
    pub fn add_quad(
        &mut self,
        p0: Vec3,
        p1: Vec3,
        p2: Vec3,
        p3: Vec3,
        facing: Vec3,
        max_edge: f32,
    ) {
        let max_edge = if max_edge.is_finite() && max_edge > 0.0 {
            max_edge
        } else {
            f32::INFINITY
        };
        let len_u = p0.distance(p1).max(p3.distance(p2));
        let len_v = p0.distance(p3).max(p1.distance(p2));
        const MAX_CELLS: usize = 4096;
        let cells = |len: f32| ((len / max_edge).ceil() as usize).clamp(1, MAX_CELLS);
        let (mut nu, mut nv) = (cells(len_u), cells(len_v));
        let corner = |u: f32, v: f32| {
            p0 * ((1.0 - u) * (1.0 - v))
                + p1 * (u * (1.0 - v))
                + p2 * (u * v)
                + p3 * ((1.0 - u) * v)
        };
        // Cheap estimate first (rectangle cell diagonal), then the exact check on the grid.
        while nu < MAX_CELLS || nv < MAX_CELLS {
            let (cu, cv) = (len_u / nu as f32, len_v / nv as f32);
            if cu * cu + cv * cv <= max_edge * max_edge {
                break;
            }
            if (cu >= cv && nu < MAX_CELLS) || nv >= MAX_CELLS {
                nu += 1;
            } else {
                nv += 1;
            }
        }
        loop {
            let longest = grid_longest_edge(&corner, nu, nv);
            if longest <= max_edge * (1.0 + 1e-5) || (nu >= MAX_CELLS && nv >= MAX_CELLS) {
                break;
            }
            nu = (nu + 1).min(MAX_CELLS);
            nv = (nv + 1).min(MAX_CELLS);
        }

        let base = self.positions.len() as u32;
        let mut positions = Vec::with_capacity((nu + 1) * (nv + 1));
        let mut uvs = Vec::with_capacity(positions.capacity());
        for j in 0..=nv {
            for i in 0..=nu {
                let (u, v) = (i as f32 / nu as f32, j as f32 / nv as f32);
                positions.push(corner(u, v));
                uvs.push(Vec2::new(u, v));
            }
        }
        // Orientation: the quad's normal by the cross product of its diagonals.
        let centre = (p0 + p1 + p2 + p3) * 0.25;
        let quad_normal = (p2 - p0).cross(p3 - p1);
        let flip = quad_normal.dot(facing - centre) < 0.0;
        let row = nu + 1;
        let mut local = Vec::with_capacity(nu * nv * 6);
        for j in 0..nv {
            for i in 0..nu {
                let a = (j * row + i) as u32;
                let b = a + 1;
                let c = a + 1 + row as u32;
                let d = a + row as u32;
                let p = |x: u32| positions[x as usize];
                // Counter-clockwise (a, b, c, d) when seen along −quad_normal.
                let cell = if p(a).distance_squared(p(c)) <= p(b).distance_squared(p(d)) {
                    [a, b, c, a, c, d]
                } else {
                    [a, b, d, b, c, d]
                };
                local.extend_from_slice(&cell);
            }
        }
        if flip {
            for tri in local.chunks_exact_mut(3) {
                tri.swap(1, 2);
            }
        }
        let normals = compute_normals(&positions, &local);
        self.positions.extend(positions);
        self.normals.extend(normals);
        self.uv0.extend(uvs);
        self.indices.extend(local.into_iter().map(|i| i + base));
    }

    /// Adds a box whose top face has the corners `top` (in order around it) and whose sides go
    /// straight down to `bottom_y`: the top and four side faces, normals pointing out of the
    /// box. The bottom is left open (it rests on a floor in every scene that uses it).
    pub fn add_box_from_top(&mut self, top: [Vec3; 4], bottom_y: f32, max_edge: f32) {
        let top_centre = (top[0] + top[1] + top[2] + top[3]) * 0.25;
        let centre = Vec3::new(top_centre.x, (top_centre.y + bottom_y) * 0.5, top_centre.z);
        self.add_quad(
            top[0],
            top[1],
            top[2],
            top[3],
            top_centre + Vec3::Y,
            max_edge,
        );
        for k in 0..4 {
            let t0 = top[k];
            let t1 = top[(k + 1) % 4];
            let b0 = Vec3::new(t0.x, bottom_y, t0.z);
            let b1 = Vec3::new(t1.x, bottom_y, t1.z);
            let mid = (t0 + t1 + b0 + b1) * 0.25;
            let mut outward = mid - centre;
            outward.y = 0.0;
            self.add_quad(b0, b1, t1, t0, mid + outward, max_edge);
        }
    }

    /// The finished mesh (no tangents: procedural materials have no normal maps).
    pub fn build(self) -> Mesh {
        Mesh {
            name: self.name,
            positions: self.positions,
            normals: self.normals,
            tangents: Vec::new(),
            uv0: self.uv0,
            uv1: None,
            indices: self.indices,
            material: self.material,
        }
    }
}

/// Longest edge (sides and both diagonals, whichever the triangulation may pick is bounded by
/// the longer) over a bilinear grid; used to size grids so the edge bound holds exactly.
fn grid_longest_edge(corner: &impl Fn(f32, f32) -> Vec3, nu: usize, nv: usize) -> f32 {
    let mut longest2: f32 = 0.0;
    let at = |i: usize, j: usize| corner(i as f32 / nu as f32, j as f32 / nv as f32);
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            let diag = a.distance_squared(c).min(b.distance_squared(d));
            longest2 = longest2
                .max(a.distance_squared(b))
                .max(b.distance_squared(c))
                .max(c.distance_squared(d))
                .max(d.distance_squared(a))
                .max(diag);
        }
    }
    longest2.sqrt()
}

/// Longest triangle edge of a mesh (model space); 0 for an empty mesh.
pub fn longest_edge(mesh: &Mesh) -> f32 {
    let n = mesh.positions.len();
    let mut longest2: f32 = 0.0;
    for tri in mesh.indices.chunks_exact(3) {
        let Some([a, b, c]) = triangle(tri, n) else {
            continue;
        };
        let p = &mesh.positions;
        longest2 = longest2
            .max(p[a].distance_squared(p[b]))
            .max(p[b].distance_squared(p[c]))
            .max(p[c].distance_squared(p[a]));
    }
    longest2.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Instance, Node, Trs};
    use std::collections::HashMap;

    /// A closed unit cube with shared corner vertices (8 vertices, 12 outward triangles).
    fn closed_cube(size: f32) -> Mesh {
        let s = size;
        let positions = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(s, 0.0, 0.0),
            Vec3::new(s, s, 0.0),
            Vec3::new(0.0, s, 0.0),
            Vec3::new(0.0, 0.0, s),
            Vec3::new(s, 0.0, s),
            Vec3::new(s, s, s),
            Vec3::new(0.0, s, s),
        ];
        #[rustfmt::skip]
        let indices = vec![
            0, 2, 1, 0, 3, 2, // z = 0, facing −z
            4, 5, 6, 4, 6, 7, // z = s
            0, 1, 5, 0, 5, 4, // y = 0
            3, 7, 6, 3, 6, 2, // y = s
            0, 4, 7, 0, 7, 3, // x = 0
            1, 2, 6, 1, 6, 5, // x = s
        ];
        let normals = compute_normals(&positions, &indices);
        let uv0 = positions.iter().map(|p| Vec2::new(p.x, p.y)).collect();
        Mesh {
            name: "cube".into(),
            positions,
            normals,
            uv0,
            indices,
            ..Mesh::default()
        }
    }

    #[test]
    fn flat_grid_normals_are_exact() {
        let mut b = MeshBuilder::new("grid", 0);
        b.add_quad(
            Vec3::new(-1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(-1.0, 0.0, 1.0),
            Vec3::new(0.0, 5.0, 0.0),
            0.3,
        );
        let mesh = b.build();
        assert!(mesh.triangle_count() > 2);
        for n in &mesh.normals {
            assert!((*n - Vec3::Y).length() < 1e-6, "normal {n}");
        }
        // Winding agrees with the normals.
        for tri in mesh.indices.chunks_exact(3) {
            let p = |i: u32| mesh.positions[i as usize];
            let fn_ = (p(tri[1]) - p(tri[0])).cross(p(tri[2]) - p(tri[0]));
            assert!(fn_.y > 0.0);
        }
        assert!(longest_edge(&mesh) <= 0.3 * (1.0 + 1e-5));
    }

    #[test]
    fn quad_faces_the_given_point() {
        let mut b = MeshBuilder::new("wall", 0);
        b.add_quad(
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(-3.0, 0.5, 0.5),
            1.0,
        );
        let mesh = b.build();
        for n in &mesh.normals {
            assert!((*n + Vec3::X).length() < 1e-6);
        }
    }

    #[test]
    fn isolated_and_degenerate_vertices_get_up_normal() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0, Vec3::Z * 5.0];
        let normals = compute_normals(&positions, &[0, 1, 2]);
        for n in normals {
            assert_eq!(n, Vec3::Y);
        }
    }

    #[test]
    fn tessellation_bound_holds_without_cracks() {
        let mut mesh = closed_cube(1.0);
        tessellate(&mut mesh, 0.3);
        assert!(
            longest_edge(&mesh) <= 0.3 + 1e-6,
            "longest {}",
            longest_edge(&mesh)
        );
        assert!(mesh.triangle_count() > 12);
        assert_eq!(mesh.normals.len(), mesh.positions.len());
        assert_eq!(mesh.uv0.len(), mesh.positions.len());
        // Closed 2-manifold: every edge is used exactly twice, once in each direction.
        let mut edges: HashMap<(u32, u32), i32> = HashMap::new();
        for t in mesh.indices.chunks_exact(3) {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry(edge_key(a, b)).or_default() += if a < b { 1 } else { 100 };
            }
        }
        for (e, count) in edges {
            assert_eq!(
                count, 101,
                "edge {e:?} not shared by exactly two opposite triangles"
            );
        }
        // Total area and orientation are preserved.
        let area: f32 = mesh
            .indices
            .chunks_exact(3)
            .map(|t| {
                let p = |i: u32| mesh.positions[i as usize];
                0.5 * (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length()
            })
            .sum();
        assert!((area - 6.0).abs() < 1e-4);
        for n in &mesh.normals {
            assert!((n.length() - 1.0).abs() < 1e-5);
        }
    }

    /// The cube, sheared and stretched so its triangles have unequal edges, plus a sliver.
    fn lopsided_mesh() -> Mesh {
        let mut mesh = closed_cube(1.0);
        for p in &mut mesh.positions {
            *p = Vec3::new(p.x * 2.3 + 0.4 * p.y, p.y * 0.7, p.z * 1.1 + 0.3 * p.x);
        }
        let base = mesh.positions.len() as u32;
        mesh.positions.extend([
            Vec3::new(0.0, 3.0, 0.0),
            Vec3::new(4.0, 3.0, 0.0),
            Vec3::new(2.0, 3.05, 0.0),
        ]);
        mesh.indices.extend([base, base + 1, base + 2]);
        mesh.normals = compute_normals(&mesh.positions, &mesh.indices);
        mesh.uv0 = vec![Vec2::ZERO; mesh.positions.len()];
        mesh
    }

    #[test]
    fn refined_triangle_count_is_what_tessellation_makes() {
        for edge in [5.0, 1.0, 0.61, 0.3, 0.137, 0.05] {
            let original = lopsided_mesh();
            let mut refined = original.clone();
            assert!(tessellate(&mut refined, edge));
            let counted: usize = original
                .indices
                .chunks_exact(3)
                .map(|t| {
                    let p = |i: u32| original.positions[i as usize];
                    refined_triangle_count([p(t[0]), p(t[1]), p(t[2])], edge * edge, usize::MAX)
                        .unwrap()
                })
                .sum();
            assert_eq!(counted, refined.triangle_count(), "edge {edge}");
        }
        // The budget stops the count as soon as it is exceeded.
        let p = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let all = refined_triangle_count(p, 0.01, usize::MAX).unwrap();
        assert!(all > 100);
        assert_eq!(refined_triangle_count(p, 0.01, all), Some(all));
        assert_eq!(refined_triangle_count(p, 0.01, all - 1), None);
    }

    fn scene_of(mesh: Mesh, scale: f32) -> Scene {
        Scene {
            nodes: vec![Node {
                name: "placed".into(),
                parent: None,
                local: Trs {
                    scale: Vec3::splat(scale),
                    ..Trs::default()
                },
            }],
            meshes: vec![mesh],
            instances: vec![Instance { mesh: 0, node: 0 }],
            ..Scene::default()
        }
    }

    #[test]
    fn an_edge_too_fine_for_the_budget_is_raised_to_the_shortest_that_fits() {
        let budget = 3000;
        let mut scene = scene_of(lopsided_mesh(), 2.0);
        let outcome = tessellate_within(&mut scene, 0.01, "test.gltf", budget);
        let used = outcome.used_max_edge.unwrap();
        assert!(used > 0.01, "used {used}");
        assert_eq!(outcome.triangles, scene.meshes[0].triangle_count());
        assert!(
            outcome.triangles <= budget,
            "{} triangles",
            outcome.triangles
        );
        assert!(outcome.warnings.iter().any(|w| w.contains("test.gltf")
            && w.contains("3000")
            && w.contains("shortest edge that fits")));
        // Model-space edges are the world edge over the instance's scale of 2.
        assert!(longest_edge(&scene.meshes[0]) <= used / 2.0 + 1e-6);
        // Tight: 2 % finer no longer fits.
        let mut finer = lopsided_mesh();
        tessellate(&mut finer, used / 1.02 / 2.0);
        assert!(
            finer.triangle_count() > budget,
            "{}",
            finer.triangle_count()
        );

        // Within the budget, the edge asked for is the one used, without a warning.
        let mut scene = scene_of(lopsided_mesh(), 2.0);
        let outcome = tessellate_within(&mut scene, 0.5, "test.gltf", budget);
        assert_eq!(outcome.used_max_edge, Some(0.5));
        assert!(outcome.warnings.is_empty(), "{:?}", outcome.warnings);

        // Already over the budget: left alone, with a warning.
        let mut scene = scene_of(lopsided_mesh(), 2.0);
        let outcome = tessellate_within(&mut scene, 0.5, "test.gltf", 5);
        assert_eq!(outcome.used_max_edge, None);
        assert_eq!(outcome.triangles, 13);
        assert!(outcome.warnings[0].contains("already have 13 triangles"));
    }

    #[test]
    fn box_from_top_is_outward_and_bounded() {
        let mut b = MeshBuilder::new("box", 0);
        let top = [
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
        ];
        b.add_box_from_top(top, 0.0, 0.25);
        let mesh = b.build();
        assert!(longest_edge(&mesh) <= 0.25 * (1.0 + 1e-5));
        let centre = Vec3::splat(0.5);
        for (p, n) in mesh.positions.iter().zip(&mesh.normals) {
            assert!(n.dot(*p - centre) > 0.0, "normal {n} at {p} points inwards");
        }
        assert!(
            mesh.normals.iter().all(|n| n.y > -0.5),
            "no bottom face expected"
        );
    }

    #[test]
    fn degenerate_triangles_are_removed() {
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::X * 2.0];
        let mut indices = vec![0, 1, 2, 0, 1, 3, 1, 1, 2, 0, 2, 9];
        let removed = remove_degenerate_triangles(&positions, &mut indices);
        assert_eq!(removed, 3);
        assert_eq!(indices, vec![0, 1, 2]);
    }

    #[test]
    fn validate_names_first_bad_vertex() {
        let positions = vec![Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::INFINITY];
        let err = validate_positions(&positions).unwrap_err();
        assert!(err.contains("vertex 1"), "{err}");
        assert!(validate_positions(&positions[..1]).is_ok());
    }

    #[test]
    fn tangents_are_orthogonal_unit_and_handed() {
        let mut mesh = closed_cube(1.0);
        tessellate(&mut mesh, 0.5);
        let tangents = compute_tangents(&mesh.positions, &mesh.normals, &mesh.uv0, &mesh.indices);
        assert_eq!(tangents.len(), mesh.positions.len());
        for (t, n) in tangents.iter().zip(&mesh.normals) {
            assert!(t.is_finite());
            assert!((t.truncate().length() - 1.0).abs() < 1e-4);
            assert!(t.truncate().dot(*n).abs() < 1e-4);
            assert!(t.w == 1.0 || t.w == -1.0);
        }
        // A flat quad in xz with u along +x: tangent is +x.
        let positions = vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, -1.0)];
        let normals = vec![Vec3::Y; 3];
        let uvs = vec![Vec2::ZERO, Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0)];
        let t = compute_tangents(&positions, &normals, &uvs, &[0, 1, 2]);
        assert!((t[0].truncate() - Vec3::X).length() < 1e-6);
        // Degenerate UVs still give a perpendicular unit vector.
        let t = compute_tangents(&positions, &normals, &[Vec2::ZERO; 3], &[0, 1, 2]);
        for t in t {
            assert!(t.truncate().dot(Vec3::Y).abs() < 1e-6);
            assert!((t.truncate().length() - 1.0).abs() < 1e-6);
        }
    }
}
