//! Contact cuts: where other geometry stands on or passes through a surface, light on the two
//! sides of the contact line differs (a partition standing on a floor: the lit room's floor
//! and the dark room's floor), but one chart runs on under it. One texel cannot hold both
//! sides, and plain bilinear filtering between a texel centre on one side and one on the other
//! ramps the light across a texel: a bright line at the foot of the wall on its dark side.
//!
//! The layout finds those contact lines (triangle–plane intersections, in world space), maps
//! them into the atlas's UV space and keeps, per texel, up to [`CUTS_PER_TEXEL`] pieces of
//! them clipped to the texel's square. The lookup (`shaders/atlas/atlas_render.wgsl`, CPU twin
//! [`lookup`]) leaves out every bilinear tap whose centre the pixel cannot reach in a
//! straight line without crossing a cut stored in one of the four taps' texels (a straight
//! path from the pixel to a tap centre stays inside those four squares), and renormalizes the
//! remaining weights. A tap on the pixel's side always remains for one straight cut (the pixel
//! is a convex combination of the four centres); when none remains (two cuts closer than a
//! texel) the lookup is plain bilinear.

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use super::layout::ChartMesh;
use crate::image_io::Image;

/// Cut pieces kept per texel (the two longest; a third is rare: three contact lines meeting
/// inside one texel).
pub const CUTS_PER_TEXEL: usize = 2;

/// Per texel, the contact-line pieces crossing its square, packed by [`pack_segment`]
/// (0 = none). Only texels with a cut are stored.
#[derive(Clone, Debug, Default)]
pub struct ContactCuts {
    pub texels: HashMap<u32, [u32; CUTS_PER_TEXEL]>,
    /// Contact segments found in world space (one per receiving triangle).
    pub segments: usize,
    /// Texels that crossed more than [`CUTS_PER_TEXEL`] non-collinear pieces (shortest dropped).
    pub dropped: usize,
}

impl ContactCuts {
    pub fn get(&self, texel: u32) -> [u32; CUTS_PER_TEXEL] {
        self.texels
            .get(&texel)
            .copied()
            .unwrap_or([0; CUTS_PER_TEXEL])
    }

    /// Row-major `R × R` array for the GPU (an `Rg32Uint` texture).
    pub fn dense(&self, resolution: u32) -> Vec<[u32; CUTS_PER_TEXEL]> {
        let mut out = vec![[0; CUTS_PER_TEXEL]; (resolution * resolution) as usize];
        for (&i, &c) in &self.texels {
            if let Some(slot) = out.get_mut(i as usize) {
                *slot = c;
            }
        }
        out
    }
}

/// A segment inside a texel's square, endpoints in texel-local [0, 1]² quantized to 1/255
/// (0.4 % of a texel): `ax | ay << 8 | bx << 16 | by << 24`. The shader unpacks the same way.
pub fn pack_segment(a: Vec2, b: Vec2) -> u32 {
    let q = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u32;
    q(a.x) | q(a.y) << 8 | q(b.x) << 16 | q(b.y) << 24
}

/// The segment [`pack_segment`] packed, texel-local; `None` for an empty (zero-length) slot.
pub fn unpack_segment(packed: u32) -> Option<(Vec2, Vec2)> {
    let c = |shift: u32| ((packed >> shift) & 0xff) as f32 / 255.0;
    let (a, b) = (Vec2::new(c(0), c(8)), Vec2::new(c(16), c(24)));
    (a != b).then_some((a, b))
}

/// Whether the straight path p→q crosses segment a→b: p and q strictly on opposite sides of
/// the segment's line, and the segment's ends not strictly on one side of the path (a cut's
/// end touching the path blocks it, so pieces of one line that meet at a texel border leave
/// no pinhole between them).
pub fn path_crosses(p: Vec2, q: Vec2, a: Vec2, b: Vec2) -> bool {
    let (ab, pq) = (b - a, q - p);
    let side_p = ab.perp_dot(p - a);
    let side_q = ab.perp_dot(q - a);
    let side_a = pq.perp_dot(a - p);
    let side_b = pq.perp_dot(b - p);
    side_p * side_q < 0.0 && side_a * side_b <= 0.0
}

/// The atlas lookup with cuts: bilinear over the four texels around `uv` (texel centres at
/// (i + ½)/R, clamped at the border), leaving out taps the pixel cannot reach without
/// crossing a cut. CPU twin of `fs_main` in `shaders/atlas/atlas_render.wgsl`.
pub fn lookup(image: &Image, cuts: &ContactCuts, uv: Vec2) -> [f32; 3] {
    let (w, h) = (image.width as i64, image.height as i64);
    let p = uv * Vec2::new(w as f32, h as f32) - Vec2::splat(0.5);
    let base = p.floor();
    let f = p - base;
    let taps = [(0, 0), (1, 0), (0, 1), (1, 1)];
    let weights = [
        (1.0 - f.x) * (1.0 - f.y),
        f.x * (1.0 - f.y),
        (1.0 - f.x) * f.y,
        f.x * f.y,
    ];
    let texel = |dx: i64, dy: i64| {
        let x = (base.x as i64 + dx).clamp(0, w - 1);
        let y = (base.y as i64 + dy).clamp(0, h - 1);
        (x, y)
    };
    // Cut pieces of the four texels, in the same (texel-centre-at-integer) frame as p.
    let mut pieces = Vec::with_capacity(4 * CUTS_PER_TEXEL);
    for &(dx, dy) in &taps {
        let (x, y) = texel(dx, dy);
        let origin = Vec2::new(x as f32, y as f32) - Vec2::splat(0.5);
        for packed in cuts.get((y * w + x) as u32) {
            if let Some((a, b)) = unpack_segment(packed) {
                pieces.push((origin + a, origin + b));
            }
        }
    }
    let mut sum = [0.0f32; 3];
    let mut plain = [0.0f32; 3];
    let mut total = 0.0f32;
    for (k, &(dx, dy)) in taps.iter().enumerate() {
        let (x, y) = texel(dx, dy);
        let v = image.get(x as u32, y as u32);
        let centre = base + Vec2::new(dx as f32, dy as f32);
        let reachable = !pieces.iter().any(|&(a, b)| path_crosses(p, centre, a, b));
        for c in 0..3 {
            plain[c] += v[c] * weights[k];
            if reachable {
                sum[c] += v[c] * weights[k];
            }
        }
        if reachable {
            total += weights[k];
        }
    }
    if total > 1e-6 {
        sum.map(|s| s / total)
    } else {
        plain
    }
}

struct Tri {
    mesh: usize,
    tri: usize,
    p: [Vec3; 3],
    n: Vec3,
    lo: Vec3,
    hi: Vec3,
}

/// Two triangles closer to parallel than this (|n·n'|) never cut each other: coplanar
/// neighbours, a sheet's two faces.
const PARALLEL: f32 = 0.999;
/// A contact along a triangle's edge cuts only where the surface goes on, flat within this
/// (cos ≈ 25°), across that edge; a wall meeting the floor's border edge does not.
const CONTINUES: f32 = 0.9;

/// Finds the contact lines of every chart mesh with every other triangle and rasterizes them
/// into texel pieces. `resolution` is the atlas's; `uvs` must be set.
pub fn contact_cuts(meshes: &[ChartMesh], resolution: u32) -> ContactCuts {
    use rayon::prelude::*;
    let mut tris = Vec::new();
    for (mi, m) in meshes.iter().enumerate() {
        for (ti, idx) in m.indices.chunks_exact(3).enumerate() {
            let p = [0, 1, 2].map(|k| m.world_positions[idx[k] as usize]);
            let Some(n) = (p[1] - p[0]).cross(p[2] - p[0]).try_normalize() else {
                continue;
            };
            tris.push(Tri {
                mesh: mi,
                tri: ti,
                p,
                n,
                lo: p[0].min(p[1]).min(p[2]),
                hi: p[0].max(p[1]).max(p[2]),
            });
        }
    }
    if tris.is_empty() {
        return ContactCuts::default();
    }
    let (lo, hi) = tris.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(l, h), t| (l.min(t.lo), h.max(t.hi)),
    );
    let diagonal = (hi - lo).length().max(1e-6);
    // Modelled contacts are rarely exact: a millimetre in a 1 m scene still counts.
    let eps = 1e-3 * diagonal;

    // Uniform grid of triangle bounding boxes for the candidate pairs.
    let mut extents: Vec<f32> = tris.iter().map(|t| (t.hi - t.lo).max_element()).collect();
    extents.sort_by(f32::total_cmp);
    let cell = (2.0 * extents[extents.len() / 2]).clamp(diagonal / 512.0, diagonal / 16.0);
    let key = |p: Vec3| ((p - lo) / cell).floor().as_ivec3();
    let mut grid: HashMap<glam::IVec3, Vec<u32>> = HashMap::new();
    for (i, t) in tris.iter().enumerate() {
        let (a, b) = (key(t.lo - Vec3::splat(eps)), key(t.hi + Vec3::splat(eps)));
        for z in a.z..=b.z {
            for y in a.y..=b.y {
                for x in a.x..=b.x {
                    grid.entry(glam::IVec3::new(x, y, z))
                        .or_default()
                        .push(i as u32);
                }
            }
        }
    }

    // Edges by exact end positions, per mesh: which triangles share an edge.
    type EdgeKey = (usize, [u32; 3], [u32; 3]);
    let edge_key = |mesh: usize, a: Vec3, b: Vec3| -> EdgeKey {
        let (ka, kb) = (
            a.to_array().map(f32::to_bits),
            b.to_array().map(f32::to_bits),
        );
        if ka <= kb {
            (mesh, ka, kb)
        } else {
            (mesh, kb, ka)
        }
    };
    let mut edges: HashMap<EdgeKey, Vec<u32>> = HashMap::new();
    for (i, t) in tris.iter().enumerate() {
        for k in 0..3 {
            edges
                .entry(edge_key(t.mesh, t.p[k], t.p[(k + 1) % 3]))
                .or_default()
                .push(i as u32);
        }
    }
    let continues_across = |i: usize, k: usize| {
        let t = &tris[i];
        edges[&edge_key(t.mesh, t.p[k], t.p[(k + 1) % 3])]
            .iter()
            .any(|&j| j as usize != i && tris[j as usize].n.dot(t.n) > CONTINUES)
    };

    // World-space contact segments per receiving triangle, mapped to texel units.
    let scale = resolution as f32;
    let uv_segments: Vec<(Vec2, Vec2)> = (0..tris.len())
        .into_par_iter()
        .flat_map_iter(|i| {
            let t = &tris[i];
            let (a, b) = (key(t.lo - Vec3::splat(eps)), key(t.hi + Vec3::splat(eps)));
            let mut candidates = Vec::new();
            for z in a.z..=b.z {
                for y in a.y..=b.y {
                    for x in a.x..=b.x {
                        if let Some(list) = grid.get(&glam::IVec3::new(x, y, z)) {
                            candidates.extend(list.iter().copied());
                        }
                    }
                }
            }
            candidates.sort_unstable();
            candidates.dedup();
            let mut found = Vec::new();
            for j in candidates {
                let u = &tris[j as usize];
                if j as usize == i
                    || u.n.dot(t.n).abs() > PARALLEL
                    || (u.lo - Vec3::splat(eps)).cmpgt(t.hi).any()
                    || (u.hi + Vec3::splat(eps)).cmplt(t.lo).any()
                {
                    continue;
                }
                let Some((s0, s1)) = plane_section(t, u, eps) else {
                    continue;
                };
                let Some((q0, q1, on_edge)) = clip_to_triangle(t, s0, s1, eps) else {
                    continue;
                };
                if on_edge.is_some_and(|k| !continues_across(i, k)) {
                    continue;
                }
                let m = &meshes[t.mesh];
                let idx = &m.indices[t.tri * 3..t.tri * 3 + 3];
                let uv = |q: Vec3| {
                    let w = barycentric_3d(q, t.p);
                    (m.uvs[idx[0] as usize] * w.x
                        + m.uvs[idx[1] as usize] * w.y
                        + m.uvs[idx[2] as usize] * w.z)
                        * scale
                };
                found.push((uv(q0), uv(q1)));
            }
            found
        })
        .collect();

    let mut pieces: HashMap<u32, Vec<(Vec2, Vec2)>> = HashMap::new();
    let r = resolution as i64;
    for &(a, b) in &uv_segments {
        let (mn, mx) = (a.min(b), b.max(a));
        let x0 = (mn.x.floor() as i64).clamp(0, r - 1);
        let x1 = (mx.x.floor() as i64).clamp(0, r - 1);
        let y0 = (mn.y.floor() as i64).clamp(0, r - 1);
        let y1 = (mx.y.floor() as i64).clamp(0, r - 1);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let origin = Vec2::new(x as f32, y as f32);
                if let Some((c0, c1)) = clip_to_square(a - origin, b - origin) {
                    if c0.distance(c1) > 1e-3 {
                        pieces.entry((y * r + x) as u32).or_default().push((c0, c1));
                    }
                }
            }
        }
    }
    let mut cuts = ContactCuts {
        segments: uv_segments.len(),
        ..Default::default()
    };
    for (texel, list) in pieces {
        let mut merged = merge_collinear(list);
        merged.sort_by(|a, b| b.0.distance(b.1).total_cmp(&a.0.distance(a.1)));
        if merged.len() > CUTS_PER_TEXEL {
            cuts.dropped += 1;
        }
        let mut packed = [0u32; CUTS_PER_TEXEL];
        for (slot, &(a, b)) in packed.iter_mut().zip(&merged) {
            *slot = pack_segment(a, b);
        }
        if packed.iter().any(|&s| unpack_segment(s).is_some()) {
            cuts.texels.insert(texel, packed);
        }
    }
    cuts
}

/// The part of triangle `u` that lies in the plane of `t` (within `eps`), as a segment, when
/// `u` touches or crosses that plane along a line.
fn plane_section(t: &Tri, u: &Tri, eps: f32) -> Option<(Vec3, Vec3)> {
    let d = u.p.map(|p| t.n.dot(p - t.p[0]));
    if d.iter().all(|&x| x > eps) || d.iter().all(|&x| x < -eps) {
        return None;
    }
    let mut points: Vec<Vec3> = Vec::with_capacity(3);
    for k in 0..3 {
        if d[k].abs() <= eps {
            points.push(u.p[k] - t.n * d[k]);
        }
        let l = (k + 1) % 3;
        if (d[k] > eps && d[l] < -eps) || (d[k] < -eps && d[l] > eps) {
            let s = d[k] / (d[k] - d[l]);
            points.push(u.p[k] + (u.p[l] - u.p[k]) * s);
        }
    }
    let dir = t.n.cross(u.n).try_normalize()?;
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    let (mut a, mut b) = (Vec3::ZERO, Vec3::ZERO);
    for p in points {
        let s = dir.dot(p);
        if s < lo {
            lo = s;
            a = p;
        }
        if s > hi {
            hi = s;
            b = p;
        }
    }
    (hi - lo > eps).then_some((a, b))
}

/// Clips segment s0→s1 (in `t`'s plane) to triangle `t`, with a hundredth of `eps` of slack
/// (a line through a corner of `t` leaves a piece far shorter than `eps`, which is dropped).
/// Returns the clipped ends and, when the whole piece lies along one of `t`'s edges (within
/// `eps`), that edge's index (edge k runs from vertex k to vertex k + 1).
fn clip_to_triangle(t: &Tri, s0: Vec3, s1: Vec3, eps: f32) -> Option<(Vec3, Vec3, Option<usize>)> {
    let slack = 0.01 * eps;
    let (mut l0, mut l1) = (0.0f32, 1.0f32);
    let d = s1 - s0;
    let inward: [Vec3; 3] = std::array::from_fn(|k| {
        let (a, b, c) = (t.p[k], t.p[(k + 1) % 3], t.p[(k + 2) % 3]);
        let m = t.n.cross(b - a).normalize_or_zero();
        if m.dot(c - a) < 0.0 {
            -m
        } else {
            m
        }
    });
    for (m, a) in inward.iter().zip(t.p) {
        // m·(s0 + λd − a) ≥ −slack
        let f0 = m.dot(s0 - a) + slack;
        let fd = m.dot(d);
        if fd.abs() < 1e-12 {
            if f0 < 0.0 {
                return None;
            }
        } else {
            let l = -f0 / fd;
            if fd > 0.0 {
                l0 = l0.max(l);
            } else {
                l1 = l1.min(l);
            }
        }
    }
    if (l1 - l0) * d.length() <= eps {
        return None;
    }
    let (q0, q1) = (s0 + d * l0, s0 + d * l1);
    // The edge the piece lies along: the nearest one, when both ends are within eps of it (a
    // short piece at a corner is near two edges' lines; it lies along the closer one).
    let off_edge = |k: usize| {
        let a = t.p[k];
        inward[k].dot(q0 - a).abs().max(inward[k].dot(q1 - a).abs())
    };
    let on_edge = (0..3)
        .min_by(|&i, &j| off_edge(i).total_cmp(&off_edge(j)))
        .filter(|&k| off_edge(k) <= eps);
    Some((q0, q1, on_edge))
}

/// Barycentric coordinates of q (in the triangle's plane, or near it), clamped to the triangle.
fn barycentric_3d(q: Vec3, p: [Vec3; 3]) -> Vec3 {
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    let area = n.length_squared();
    if area <= 0.0 {
        return Vec3::new(1.0, 0.0, 0.0);
    }
    let w1 = (q - p[0]).cross(p[2] - p[0]).dot(n) / area;
    let w2 = (p[1] - p[0]).cross(q - p[0]).dot(n) / area;
    let w = Vec3::new(1.0 - w1 - w2, w1, w2).max(Vec3::ZERO);
    w / w.element_sum().max(1e-12)
}

/// Liang–Barsky clip of a→b to the unit square (texel-local).
fn clip_to_square(a: Vec2, b: Vec2) -> Option<(Vec2, Vec2)> {
    let d = b - a;
    let (mut l0, mut l1) = (0.0f32, 1.0f32);
    for (p, q) in [(-d.x, a.x), (d.x, 1.0 - a.x), (-d.y, a.y), (d.y, 1.0 - a.y)] {
        if p.abs() < 1e-12 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                l0 = l0.max(r);
            } else {
                l1 = l1.min(r);
            }
        }
    }
    (l0 <= l1).then(|| (a + d * l0, a + d * l1))
}

/// Joins pieces that lie on one line and overlap or touch (one contact line is found once per
/// receiving triangle, and a sheet's two faces find it twice).
fn merge_collinear(mut list: Vec<(Vec2, Vec2)>) -> Vec<(Vec2, Vec2)> {
    // Texel units: one line mapped through neighbouring triangles wiggles by ~0.002, and the
    // stored ends are rounded to 1/255 anyway.
    const TOL: f32 = 1e-2;
    let mut changed = true;
    while changed {
        changed = false;
        'outer: for i in 0..list.len() {
            for j in i + 1..list.len() {
                let (a, b) = list[i];
                let (c, e) = list[j];
                let Some(dir) = (b - a).try_normalize() else {
                    continue;
                };
                let off = |p: Vec2| dir.perp_dot(p - a).abs();
                if off(c) > TOL || off(e) > TOL {
                    continue;
                }
                let s = |p: Vec2| dir.dot(p - a);
                let (i0, i1) = (0.0, s(b));
                let (j0, j1) = (s(c).min(s(e)), s(c).max(s(e)));
                if j0 > i1 + TOL || j1 < i0 - TOL {
                    continue;
                }
                let (lo, hi) = (j0.min(i0), j1.max(i1));
                list[i] = (a + dir * lo, a + dir * hi);
                list.swap_remove(j);
                changed = true;
                break 'outer;
            }
        }
    }
    list
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packing_round_trips_to_a_255th_of_a_texel() {
        let (a, b) = (Vec2::new(0.0, 0.37), Vec2::new(1.0, 0.62));
        let (c, d) = unpack_segment(pack_segment(a, b)).unwrap();
        assert!(c.distance(a) < 0.5 / 255.0 * 1.5 && d.distance(b) < 0.5 / 255.0 * 1.5);
        assert_eq!(unpack_segment(0), None);
    }

    #[test]
    fn a_cut_blocks_only_paths_across_it() {
        let (a, b) = (Vec2::new(0.5, -1.0), Vec2::new(0.5, 1.0));
        assert!(path_crosses(Vec2::ZERO, Vec2::new(1.0, 0.0), a, b));
        assert!(!path_crosses(Vec2::ZERO, Vec2::new(0.4, 0.9), a, b));
        // Past the cut's end the path is free.
        assert!(!path_crosses(
            Vec2::new(0.0, 2.0),
            Vec2::new(1.0, 2.0),
            a,
            b
        ));
        // Two pieces of one line meeting at a texel border leave no pinhole.
        let mid = Vec2::new(0.5, 0.0);
        let blocked = path_crosses(Vec2::ZERO, Vec2::new(1.0, 0.0), a, mid)
            || path_crosses(Vec2::ZERO, Vec2::new(1.0, 0.0), mid, b);
        assert!(blocked);
    }

    #[test]
    fn collinear_pieces_merge_and_others_stay() {
        let merged = merge_collinear(vec![
            (Vec2::new(0.0, 0.5), Vec2::new(0.4, 0.5)),
            (Vec2::new(0.4, 0.5), Vec2::new(1.0, 0.5)),
            (Vec2::new(0.5, 0.0), Vec2::new(0.5, 1.0)),
        ]);
        assert_eq!(merged.len(), 2);
        let long = merged
            .iter()
            .find(|(a, b)| (a.y - 0.5).abs() < 1e-6 && (b.y - 0.5).abs() < 1e-6)
            .unwrap();
        assert!((long.0.distance(long.1) - 1.0).abs() < 1e-5);
    }

    /// A 2×2-texel image, left column bright, right column dark, a vertical cut between the
    /// columns: a point left of the cut reads only the bright texels, right only the dark;
    /// without the cut both read the bilinear mix.
    #[test]
    fn lookup_does_not_filter_across_a_cut() {
        let image = Image {
            width: 2,
            height: 2,
            pixels: vec![
                [10.0, 10.0, 10.0, 1.0],
                [1.0, 1.0, 1.0, 1.0],
                [10.0, 10.0, 10.0, 1.0],
                [1.0, 1.0, 1.0, 1.0],
            ],
        };
        let mut cuts = ContactCuts::default();
        // The cut at u = 0.55 (texel x = 1.1): inside texel column 1, near its left edge.
        for y in 0..2u32 {
            cuts.texels.insert(
                y * 2 + 1,
                [pack_segment(Vec2::new(0.1, 0.0), Vec2::new(0.1, 1.0)), 0],
            );
        }
        let left = lookup(&image, &cuts, Vec2::new(0.52, 0.5));
        let right = lookup(&image, &cuts, Vec2::new(0.58, 0.5));
        let plain = lookup(&image, &ContactCuts::default(), Vec2::new(0.52, 0.5));
        assert!((left[0] - 10.0).abs() < 1e-4, "{left:?}");
        assert!((right[0] - 1.0).abs() < 1e-4, "{right:?}");
        assert!(plain[0] > 1.5 && plain[0] < 9.5, "{plain:?}");
    }

    /// Where walls stand on a surface, the texels under the contact line are cut; where two
    /// surfaces only meet at their edges (a closed box's walls), nothing is.
    #[test]
    fn cuts_follow_contacts_not_edges() {
        use crate::scene::{self, builtin::BuiltinParams};
        let params = BuiltinParams { max_edge: 0.1 };
        let layout_of = |name: &str| {
            let scene = scene::load(name, &params).unwrap();
            super::super::layout::layout(&scene, &scene.world_from_node(), 128).unwrap()
        };
        assert!(layout_of("box-point").cuts.texels.is_empty());

        let corridor = layout_of("corridor");
        let floor: Vec<_> = corridor
            .texels
            .iter()
            .filter(|t| t.normal.y > 0.9 && t.position.y < 1e-3 && t.centre)
            .collect();
        // Texel spacing on the floor: the smallest step between texel centres along x.
        let spacing = floor
            .iter()
            .map(|t| (t.position.x - floor[0].position.x).abs())
            .filter(|&d| d > 1e-4)
            .fold(f32::MAX, f32::min);
        // Texels whose square the partition's foot (x = 2.1) crosses, off the doorway.
        let under_wall: Vec<_> = floor
            .iter()
            .filter(|t| (t.position.x - 2.1).abs() < 0.45 * spacing)
            .filter(|t| t.position.z < 0.55 || t.position.z > 1.45)
            .collect();
        let cut = under_wall
            .iter()
            .filter(|t| corridor.cuts.texels.contains_key(&t.index))
            .count();
        assert!(under_wall.len() >= 10, "{}", under_wall.len());
        assert_eq!(cut, under_wall.len(), "spacing {spacing}");
        // Away from every contact the floor is not cut.
        let far = floor
            .iter()
            .filter(|t| t.position.x < 1.5 && corridor.cuts.texels.contains_key(&t.index))
            .count();
        assert_eq!(far, 0);
    }
}
