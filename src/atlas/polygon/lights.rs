//! Virtual lights from clusters (seed 001 §5.2, methods §B.6–B.7): for a cluster on a plane,
//! the 2-D convex hull of its VPLs, simplified to at most [`MAX_VERTICES`] by removing the
//! vertex whose removal loses the least area, enlarged by the border b = 1.5·√(A/n) (every
//! edge offset outward, neighbouring edges intersected), clipped to the cluster's kd cell and
//! simplified again; its power is the sum of its VPLs'. Clusters off any plane, and planar
//! ones whose hull has no area, become sphere lights.

use glam::{Vec2, Vec3};

use super::form_factor::{PolygonLight, SphereLight};

/// Vertex limit of a polygon light (the paper's GPU limit).
pub const MAX_VERTICES: usize = 8;

/// Border factor: the hull grows by this many mean VPL spacings √(A/n).
pub const BORDER: f32 = 1.5;

/// Below this |Σ Φ_i n_i| / Σ Φ_i a sphere light emits isotropically.
pub const ISOTROPIC_BELOW: f32 = 0.3;

/// Andrew's monotone chain: the convex hull counter-clockwise, collinear points dropped.
pub fn convex_hull(points: &[Vec2]) -> Vec<Vec2> {
    let mut p: Vec<Vec2> = points.to_vec();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<Vec2> = Vec::with_capacity(2 * p.len());
    for &q in &p {
        while hull.len() >= 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
            hull.pop();
        }
        hull.push(q);
    }
    let lower = hull.len() + 1;
    for &q in p.iter().rev().skip(1) {
        while hull.len() >= lower && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
            hull.pop();
        }
        hull.push(q);
    }
    hull.pop();
    hull
}

/// Signed area (positive counter-clockwise).
pub fn polygon_area(poly: &[Vec2]) -> f32 {
    let n = poly.len();
    (0..n)
        .map(|i| poly[i].perp_dot(poly[(i + 1) % n]))
        .sum::<f32>()
        * 0.5
}

/// Removes the vertex whose removal loses the least area until at most `max` remain (a
/// subset of a convex polygon's vertices stays convex).
pub fn simplify(mut poly: Vec<Vec2>, max: usize) -> Vec<Vec2> {
    while poly.len() > max.max(3) {
        let n = poly.len();
        let loss = |i: usize| {
            let (a, b, c) = (poly[(i + n - 1) % n], poly[i], poly[(i + 1) % n]);
            (b - a).perp_dot(c - a).abs()
        };
        let worst = (0..n)
            .min_by(|&i, &j| loss(i).total_cmp(&loss(j)))
            .unwrap_or(0);
        poly.remove(worst);
    }
    poly
}

/// Offsets every edge of the convex counter-clockwise polygon outward by `b` and intersects
/// neighbouring edges (a miter offset: the vertex count stays).
pub fn grow(poly: &[Vec2], b: f32) -> Vec<Vec2> {
    let n = poly.len();
    if n < 3 || b <= 0.0 {
        return poly.to_vec();
    }
    // Outward normal of edge i (from i to i+1) of a counter-clockwise polygon: (dy, −dx).
    let normal = |i: usize| {
        let d = poly[(i + 1) % n] - poly[i];
        Vec2::new(d.y, -d.x).normalize_or_zero()
    };
    (0..n)
        .map(|i| {
            let (n0, n1) = (normal((i + n - 1) % n), normal(i));
            let m = n0 + n1;
            let denom = 1.0 + n0.dot(n1);
            if denom < 1e-3 {
                return poly[i] + n1 * b;
            }
            // The miter vertex: at distance b from both offset edges.
            poly[i] + m * (b / denom)
        })
        .collect()
}

/// Sutherland–Hodgman of a convex polygon against the box [lo, hi].
pub fn clip_to_box(poly: &[Vec2], lo: Vec2, hi: Vec2) -> Vec<Vec2> {
    let mut out = poly.to_vec();
    for (axis, bound, keep_below) in [
        (0, lo.x, false),
        (0, hi.x, true),
        (1, lo.y, false),
        (1, hi.y, true),
    ] {
        let inside = |p: Vec2| {
            let v = if axis == 0 { p.x } else { p.y };
            if keep_below {
                v <= bound
            } else {
                v >= bound
            }
        };
        let input = std::mem::take(&mut out);
        let k = input.len();
        for i in 0..k {
            let (a, b) = (input[i], input[(i + 1) % k]);
            if inside(a) {
                out.push(a);
            }
            if inside(a) != inside(b) {
                let (va, vb) = if axis == 0 { (a.x, b.x) } else { (a.y, b.y) };
                let t = (bound - va) / (vb - va);
                out.push(a + (b - a) * t);
            }
        }
        if out.len() < 3 {
            return Vec::new();
        }
    }
    out
}

/// A plane with an in-plane basis: world = origin + u·x + v·y, normal = u × v.
#[derive(Clone, Copy, Debug)]
pub struct PlaneFrame {
    pub origin: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub normal: Vec3,
}

impl PlaneFrame {
    pub fn to_plane(&self, p: Vec3) -> Vec2 {
        let d = p - self.origin;
        Vec2::new(d.dot(self.u), d.dot(self.v))
    }

    pub fn to_world(&self, q: Vec2) -> Vec3 {
        self.origin + self.u * q.x + self.v * q.y
    }
}

/// The polygon light of a planar cluster: `plane_points` in-plane, `powers` per VPL, the kd
/// cell [lo, hi]. `None` when the hull has no area (the caller makes a sphere light).
pub fn polygon_light(
    frame: &PlaneFrame,
    plane_points: &[Vec2],
    powers: &[[f64; 3]],
    lo: Vec2,
    hi: Vec2,
) -> Option<PolygonLight> {
    let hull = convex_hull(plane_points);
    if hull.len() < 3 {
        return None;
    }
    let hull = simplify(hull, MAX_VERTICES);
    let area = polygon_area(&hull);
    if area <= 0.0 {
        return None;
    }
    let border = BORDER * (area / plane_points.len() as f32).sqrt();
    let clipped = clip_to_box(&grow(&hull, border), lo, hi);
    let poly = simplify(clipped, MAX_VERTICES);
    let area = polygon_area(&poly);
    if poly.len() < 3 || area <= 0.0 {
        return None;
    }
    let centroid2 = poly.iter().copied().sum::<Vec2>() / poly.len() as f32;
    let vertices: Vec<Vec3> = poly.iter().map(|q| frame.to_world(*q)).collect();
    let centre = frame.to_world(centroid2);
    let radius = vertices
        .iter()
        .map(|v| v.distance(centre))
        .fold(0.0f32, f32::max);
    Some(PolygonLight {
        vertices,
        normal: frame.normal,
        centre,
        power: sum_power(powers),
        area,
        radius,
    })
}

/// The sphere light of a cluster: centre the power-weighted centroid, radius the RMS
/// distance from it, Lambertian about the power-weighted mean normal unless that is short.
pub fn sphere_light(positions: &[Vec3], normals: &[Vec3], powers: &[[f64; 3]]) -> SphereLight {
    let weight = |p: &[f64; 3]| (p[0] + p[1] + p[2]).max(0.0);
    let total: f64 = powers.iter().map(weight).sum();
    let w = |i: usize| {
        if total > 0.0 {
            weight(&powers[i]) / total
        } else {
            1.0 / positions.len() as f64
        }
    };
    let centre = (0..positions.len())
        .map(|i| positions[i].as_dvec3() * w(i))
        .sum::<glam::DVec3>()
        .as_vec3();
    let rms = (0..positions.len())
        .map(|i| positions[i].distance_squared(centre) as f64 * w(i))
        .sum::<f64>()
        .sqrt() as f32;
    let lobe = (0..normals.len())
        .map(|i| normals[i].as_dvec3() * w(i))
        .sum::<glam::DVec3>();
    let normal = if lobe.length() >= ISOTROPIC_BELOW as f64 {
        Some(lobe.normalize().as_vec3())
    } else {
        None
    };
    SphereLight {
        centre,
        radius: rms,
        normal,
        power: sum_power(powers),
    }
}

pub fn sum_power(powers: &[[f64; 3]]) -> [f64; 3] {
    let mut s = [0.0; 3];
    for p in powers {
        for c in 0..3 {
            s[c] += p[c];
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hull_simplify_grow_clip() {
        let pts: Vec<Vec2> = (0..100)
            .map(|i| {
                let a = i as f32 * 0.0628;
                Vec2::new(a.cos(), a.sin())
            })
            .chain([Vec2::ZERO, Vec2::new(0.1, 0.2)])
            .collect();
        let hull = convex_hull(&pts);
        assert_eq!(hull.len(), 100);
        assert!(polygon_area(&hull) > 3.1);
        let s = simplify(hull, 8);
        assert_eq!(s.len(), 8);
        // A regular-ish octagon inscribed in the unit circle has area 2√2 ≈ 2.83.
        assert!(
            (polygon_area(&s) - 2.83).abs() < 0.1,
            "{}",
            polygon_area(&s)
        );
        // A unit square grown by 0.5 is a 2×2 square.
        let sq = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        let g = grow(&sq, 0.5);
        assert!((polygon_area(&g) - 4.0).abs() < 1e-5, "{g:?}");
        let c = clip_to_box(&g, Vec2::ZERO, Vec2::splat(10.0));
        assert!((polygon_area(&c) - 2.25).abs() < 1e-5, "{c:?}");
    }
}
