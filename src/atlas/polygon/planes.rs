//! Plane search over VPLs (seed 001 §5.2, methods §B.4): RANSAC after Schnabel et al. 2007,
//! which the paper names without parameters. Ours (CGAL's defaults where it has them):
//! - a candidate plane is one VPL's position and normal (VPLs carry the exact surface normal,
//!   so the three-point fit Schnabel needs for raw point clouds adds nothing);
//! - inliers lie within ε = 1 % of the bounding-box diagonal of the plane and have a normal
//!   within 25° (cos ≥ 0.9) **with its sign**, so the two faces of a thin wall stay apart;
//! - a candidate's support is its largest connected component, connectivity
//!   max(1 % of the diagonal, 3 mean VPL spacings √(A/n)) (Schnabel's cluster ε is tied to
//!   the sampling density; 1 % alone splits a 20k-VPL Cornell box into fragments);
//! - a segment needs max(3 × the target cluster size, 0.5 % of the VPLs) points;
//! - the search stops when the candidates drawn since the last accepted plane would have hit
//!   a segment of that minimum size with probability 1 − 0.05.
//!
//! The plane's emitting normal is the mean VPL normal. The in-plane basis is world-axis
//! aligned where the plane is, PCA otherwise, so kd splits follow walls.

use std::collections::HashMap;

use glam::{Vec2, Vec3};

use super::lights::PlaneFrame;
use crate::atlas::bake::Rng;

/// RANSAC parameters (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlaneSearch {
    /// Point-to-plane distance, fraction of the bounding-box diagonal.
    pub epsilon: f32,
    /// Connectivity, fraction of the bounding-box diagonal (at least 3 VPL spacings).
    pub connectivity: f32,
    /// Cosine of the largest normal deviation.
    pub normal_cos: f32,
    /// Probability of missing a minimum-size segment at which the search stops.
    pub miss_probability: f64,
    /// Fraction of the VPLs a segment needs at least (and 3 × the target cluster size).
    pub min_fraction: f32,
    /// Candidates scored per round.
    pub candidates: usize,
}

impl Default for PlaneSearch {
    fn default() -> Self {
        Self {
            epsilon: 0.01,
            connectivity: 0.01,
            normal_cos: 0.9,
            miss_probability: 0.05,
            min_fraction: 0.005,
            candidates: 16,
        }
    }
}

/// One planar segment: its frame and members (indices into the input VPLs).
#[derive(Clone, Debug)]
pub struct Segment {
    pub frame: PlaneFrame,
    pub members: Vec<usize>,
}

/// Splits VPLs into planar segments and the rest. `spacing` is the mean VPL spacing √(A/n).
pub fn find_planes(
    positions: &[Vec3],
    normals: &[Vec3],
    params: &PlaneSearch,
    target: usize,
    spacing: f32,
    seed: u64,
) -> (Vec<Segment>, Vec<usize>) {
    let n = positions.len();
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for p in positions {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let diag = (hi - lo).length().max(1e-6);
    let eps = params.epsilon * diag;
    let conn = (params.connectivity * diag).max(3.0 * spacing);
    let min_points = (3 * target)
        .max((params.min_fraction * n as f32).ceil() as usize)
        .max(3);
    let mut remaining: Vec<usize> = (0..n).collect();
    let mut segments = Vec::new();
    let mut rng = Rng::from_state(seed ^ 0x0A45_5AC0);
    let mut draws_since_accept = 0usize;
    let inliers = |origin: Vec3, normal: Vec3, among: &[usize]| -> Vec<usize> {
        among
            .iter()
            .copied()
            .filter(|&i| {
                normals[i].dot(normal) >= params.normal_cos
                    && (positions[i] - origin).dot(normal).abs() <= eps
            })
            .collect()
    };
    while remaining.len() >= min_points {
        // Draws needed to hit a minimum segment with probability 1 − p.
        let frac = min_points as f64 / remaining.len() as f64;
        let needed = if frac >= 1.0 {
            1
        } else {
            (params.miss_probability.ln() / (1.0 - frac).ln()).ceil() as usize
        };
        if draws_since_accept >= needed {
            break;
        }
        let mut best: Option<(usize, Vec<usize>)> = None;
        for _ in 0..params.candidates {
            draws_since_accept += 1;
            let i = remaining[rng.next_u64() as usize % remaining.len()];
            let support = inliers(positions[i], normals[i], &remaining);
            if best.as_ref().is_none_or(|(s, _)| support.len() > *s) {
                best = Some((support.len(), support));
            }
        }
        let Some((count, support)) = best else { break };
        if count < min_points {
            continue;
        }
        // Refit to the inliers (centroid, mean normal), collect again, keep the largest
        // connected component.
        let (origin, normal) = fit(positions, normals, &support);
        let support = inliers(origin, normal, &remaining);
        let component = largest_component(positions, &support, conn);
        if component.len() < min_points {
            continue;
        }
        let (origin, normal) = fit(positions, normals, &component);
        let frame = plane_frame(origin, normal, positions, &component);
        let taken: std::collections::HashSet<usize> = component.iter().copied().collect();
        remaining.retain(|i| !taken.contains(i));
        segments.push(Segment {
            frame,
            members: component,
        });
        draws_since_accept = 0;
    }
    (segments, remaining)
}

fn fit(positions: &[Vec3], normals: &[Vec3], members: &[usize]) -> (Vec3, Vec3) {
    let k = members.len().max(1) as f32;
    let origin = members.iter().map(|&i| positions[i]).sum::<Vec3>() / k;
    let normal = members
        .iter()
        .map(|&i| normals[i])
        .sum::<Vec3>()
        .try_normalize()
        .unwrap_or(Vec3::Y);
    (origin, normal)
}

/// The largest set of `members` connected by steps of at most `reach` (grid flood fill).
fn largest_component(positions: &[Vec3], members: &[usize], reach: f32) -> Vec<usize> {
    let key = |p: Vec3| {
        let q = (p / reach).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    let mut grid: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
    for (k, &i) in members.iter().enumerate() {
        grid.entry(key(positions[i])).or_default().push(k);
    }
    let mut label = vec![usize::MAX; members.len()];
    let mut best: Vec<usize> = Vec::new();
    let reach2 = reach * reach;
    for start in 0..members.len() {
        if label[start] != usize::MAX {
            continue;
        }
        label[start] = start;
        let mut stack = vec![start];
        let mut comp = Vec::new();
        while let Some(k) = stack.pop() {
            comp.push(members[k]);
            let p = positions[members[k]];
            let (cx, cy, cz) = key(p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(list) = grid.get(&(cx + dx, cy + dy, cz + dz)) else {
                            continue;
                        };
                        for &o in list {
                            if label[o] == usize::MAX
                                && positions[members[o]].distance_squared(p) <= reach2
                            {
                                label[o] = start;
                                stack.push(o);
                            }
                        }
                    }
                }
            }
        }
        if comp.len() > best.len() {
            best = comp;
        }
    }
    best
}

/// The plane's frame: world axes where the normal is one, else the principal in-plane axis
/// of the members. `u × v = normal`.
fn plane_frame(origin: Vec3, normal: Vec3, positions: &[Vec3], members: &[usize]) -> PlaneFrame {
    let axis = normal.abs().max_element();
    let u = if axis > 0.999 {
        let a = if normal.x.abs() == axis {
            0
        } else if normal.y.abs() == axis {
            1
        } else {
            2
        };
        let mut u = Vec3::ZERO;
        u[(a + 1) % 3] = 1.0;
        u
    } else {
        let (b0, b1) = crate::sampling::basis(normal);
        let (mut sxx, mut sxy, mut syy) = (0.0f64, 0.0f64, 0.0f64);
        for &i in members {
            let d = positions[i] - origin;
            let q = Vec2::new(d.dot(b0), d.dot(b1)).as_dvec2();
            sxx += q.x * q.x;
            sxy += q.x * q.y;
            syy += q.y * q.y;
        }
        let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        b0 * angle.cos() as f32 + b1 * angle.sin() as f32
    };
    let u = (u - normal * u.dot(normal)).normalize();
    let v = normal.cross(u);
    PlaneFrame {
        origin,
        u,
        v,
        normal,
    }
}
