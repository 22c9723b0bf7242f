//! CPU depth maps for the bake's visibility: a depth cube around a point (a point or spot light,
//! or a shooting VPL) and an orthographic map for directional lights. Faces store the depth
//! along the face axis; lookups compare a point's depth with a slope-scaled bias and report
//! whether the 3×3 taps around it agree, so the baker can leave the cases near a depth edge to
//! a ray ([`ShadowTest::settled`]).

use glam::{Vec2, Vec3};

/// Triangles in world space.
pub type Triangles = [[Vec3; 3]];

/// Face `f` looks along axis `f / 2` with sign `+` for even `f`. Local coordinates: depth `z`
/// along the face axis, `u`, `v` along the next two axes.
fn face_local(face: usize, d: Vec3) -> Vec3 {
    let a = face / 2;
    let s = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    Vec3::new(d[(a + 1) % 3], d[(a + 2) % 3], s * d[a])
}

/// Inverse of [`face_local`].
fn face_world(face: usize, l: Vec3) -> Vec3 {
    let a = face / 2;
    let s = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
    let mut d = Vec3::ZERO;
    d[a] = s * l.z;
    d[(a + 1) % 3] = l.x;
    d[(a + 2) % 3] = l.y;
    d
}

fn major_face(d: Vec3) -> usize {
    let a = d.abs();
    let axis = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    axis * 2 + usize::from(d[axis] < 0.0)
}

/// `max(0, ⌈v⌉)` as an integer (0 for NaN). Written with a truncating cast: without SSE4.1,
/// `f32::ceil` and `floor` are library calls, and a depth cube sets up every triangle of a
/// finely tessellated scene (most cover no texel), so the bounding box's rounding showed in
/// profiles.
#[inline]
fn ceil_at_least_zero(v: f32) -> i64 {
    if v.is_nan() || v <= 0.0 {
        return 0;
    }
    let t = v as i64;
    if (t as f32) < v {
        t.saturating_add(1)
    } else {
        t
    }
}

/// `⌊v⌋` for `v ≥ 0` (and NaN → 0), some negative number otherwise: an upper loop bound whose
/// lower bound is at least 0, where any negative value means an empty range.
#[inline]
fn floor_or_negative(v: f32) -> i64 {
    if v < 0.0 {
        -1
    } else {
        v as i64
    }
}

/// Rasterizes a screen-space triangle (x, y in texels, w = 1/depth) into `depth` (keeps the
/// smallest depth).
fn raster_triangle(depth: &mut [f32], res: usize, t: [Vec3; 3], perspective: bool) {
    let (a, b, c) = (t[0], t[1], t[2]);
    let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
    if area.abs() < 1e-12 {
        return;
    }
    let lo = a.min(b).min(c);
    let hi = a.max(b).max(c);
    let x0 = ceil_at_least_zero(lo.x - 0.5);
    let y0 = ceil_at_least_zero(lo.y - 0.5);
    let x1 = floor_or_negative(hi.x - 0.5).min(res as i64 - 1);
    let y1 = floor_or_negative(hi.y - 0.5).min(res as i64 - 1);
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let w0 = ((b.x - p.x) * (c.y - p.y) - (b.y - p.y) * (c.x - p.x)) / area;
            let w1 = ((c.x - p.x) * (a.y - p.y) - (c.y - p.y) * (a.x - p.x)) / area;
            let w2 = 1.0 - w0 - w1;
            if w0 < -1e-6 || w1 < -1e-6 || w2 < -1e-6 {
                continue;
            }
            let z = w0 * a.z + w1 * b.z + w2 * c.z;
            let d = if perspective { 1.0 / z.max(1e-12) } else { z };
            let slot = &mut depth[y as usize * res + x as usize];
            if d < *slot {
                *slot = d;
            }
        }
    }
}

/// How close to the receiver's tangent plane (in texel footprints) the centre tap's surface
/// must lie to be taken for the receiver itself.
const ON_RECEIVER: f32 = 0.1;

/// Six perspective faces (90° each) around `origin`.
pub struct DepthCube {
    pub origin: Vec3,
    pub res: usize,
    pub near: f32,
    /// 6 · res² depths along the face axis (∞ where nothing was drawn).
    pub depth: Vec<f32>,
}

impl DepthCube {
    pub fn new(origin: Vec3, res: usize, near: f32, triangles: &Triangles) -> Self {
        Self::rasterize(origin, res, near, triangles, true)
    }

    /// `one_face`: test triangles whose corners share a major face against that face only
    /// (false: every triangle against all six, the slow form the test compares with).
    fn rasterize(
        origin: Vec3,
        res: usize,
        near: f32,
        triangles: &Triangles,
        one_face: bool,
    ) -> Self {
        let mut depth = vec![f32::INFINITY; 6 * res * res];
        let half = res as f32 * 0.5;
        // A triangle whose corners share a major face lies in that face's cone (a convex
        // cone), so no other face can draw it: most of a finely tessellated scene is tested
        // against one face instead of six (the corridor's 82k triangles × 6 faces × one cube
        // per VPL were most of its visibility stage).
        let relative: Vec<[Vec3; 3]> = triangles.iter().map(|t| t.map(|p| p - origin)).collect();
        let face_masks: Vec<u8> = relative
            .iter()
            .map(|t| {
                let f = major_face(t[0]);
                if one_face && major_face(t[1]) == f && major_face(t[2]) == f {
                    1 << f
                } else {
                    0x3F
                }
            })
            .collect();
        for face in 0..6 {
            let slice = &mut depth[face * res * res..(face + 1) * res * res];
            for (tri, mask) in relative.iter().zip(&face_masks) {
                if mask & (1 << face) == 0 {
                    continue;
                }
                let l = tri.map(|d| face_local(face, d));
                // Quick rejects: behind the near plane or outside a side plane (|u| ≤ z).
                if l.iter().all(|p| p.z < near)
                    || l.iter().all(|p| p.x > p.z)
                    || l.iter().all(|p| p.x < -p.z)
                    || l.iter().all(|p| p.y > p.z)
                    || l.iter().all(|p| p.y < -p.z)
                {
                    continue;
                }
                // Clip against z ≥ near (Sutherland–Hodgman), then project and fan.
                let mut poly: [Vec3; 4] = [Vec3::ZERO; 4];
                let mut n = 0;
                for i in 0..3 {
                    let (p, q) = (l[i], l[(i + 1) % 3]);
                    let (pin, qin) = (p.z >= near, q.z >= near);
                    if pin {
                        poly[n] = p;
                        n += 1;
                    }
                    if pin != qin {
                        let t = (near - p.z) / (q.z - p.z);
                        poly[n] = p + (q - p) * t;
                        n += 1;
                    }
                }
                if n < 3 {
                    continue;
                }
                let proj = |p: Vec3| {
                    Vec3::new(
                        (p.x / p.z + 1.0) * half,
                        (p.y / p.z + 1.0) * half,
                        1.0 / p.z,
                    )
                };
                let s0 = proj(poly[0]);
                for k in 1..n - 1 {
                    raster_triangle(slice, res, [s0, proj(poly[k]), proj(poly[k + 1])], true);
                }
            }
        }
        Self {
            origin,
            res,
            near,
            depth,
        }
    }

    /// Fraction of the (2r+1)² texels around the direction to `p` whose surface is not in
    /// front of `p` (1 = visible). The bias grows with distance (texel footprint).
    /// Fraction of the cosine-weighted hemisphere around `n` in which the cube sees geometry:
    /// the exact form-factor sum from the cube's centre to the whole scene (1 in a closed
    /// room, less where light can leave).
    pub fn hemisphere_coverage(&self, n: Vec3) -> f32 {
        let res = self.res;
        let step = 2.0 / res as f32;
        let mut covered = 0.0f64;
        let mut total = 0.0f64;
        for face in 0..6usize {
            let a = face / 2;
            let s = if face.is_multiple_of(2) { 1.0 } else { -1.0 };
            for y in 0..res {
                for x in 0..res {
                    let u = (x as f32 + 0.5) * step - 1.0;
                    let v = (y as f32 + 0.5) * step - 1.0;
                    let mut d = Vec3::ZERO;
                    d[(a + 1) % 3] = u;
                    d[(a + 2) % 3] = v;
                    d[a] = s;
                    let r2 = 1.0 + u * u + v * v;
                    let cos = n.dot(d) / r2.sqrt();
                    if cos <= 0.0 {
                        continue;
                    }
                    let w = (cos * step * step / (r2 * r2.sqrt())) as f64;
                    total += w;
                    if self.depth[face * res * res + y * res + x].is_finite() {
                        covered += w;
                    }
                }
            }
        }
        if total > 0.0 {
            (covered / total) as f32
        } else {
            0.0
        }
    }

    /// The depth stored (along its face's axis) in the texel the direction `d` from the
    /// origin falls in, and the unit direction's component along that axis (the stored
    /// surface lies `depth / component` away along `d`).
    pub fn depth_toward(&self, d: Vec3) -> (f32, f32) {
        let d = d.normalize_or_zero();
        let face = major_face(d);
        let l = face_local(face, d);
        if l.z <= 0.0 {
            return (f32::INFINITY, 1.0);
        }
        let half = self.res as f32 * 0.5;
        let x = (((l.x / l.z + 1.0) * half) as i64).clamp(0, self.res as i64 - 1) as usize;
        let y = (((l.y / l.z + 1.0) * half) as i64).clamp(0, self.res as i64 - 1) as usize;
        (
            self.depth[face * self.res * self.res + y * self.res + x],
            l.z,
        )
    }

    /// The surface point the texel the direction `d` falls in stores, at the texel centre's
    /// own direction (exact for a plane drawn into it); `None` where nothing was drawn.
    pub fn surface_toward(&self, d: Vec3) -> Option<Vec3> {
        let face = major_face(d);
        let l = face_local(face, d);
        if l.z <= 0.0 {
            return None;
        }
        let half = self.res as f32 * 0.5;
        let x = (((l.x / l.z + 1.0) * half) as i64).clamp(0, self.res as i64 - 1);
        let y = (((l.y / l.z + 1.0) * half) as i64).clamp(0, self.res as i64 - 1);
        let depth = self.depth[face * self.res * self.res + y as usize * self.res + x as usize];
        depth.is_finite().then(|| {
            self.origin
                + face_world(
                    face,
                    Vec3::new(
                        ((x as f32 + 0.5) / half - 1.0) * depth,
                        ((y as f32 + 0.5) / half - 1.0) * depth,
                        depth,
                    ),
                )
        })
    }

    /// The centre tap's answer for `p`, whether its 3×3 neighbourhood agrees, and how far in
    /// front of the receiver the centre tap's surface lies (see [`ShadowTest`]). `n` is the
    /// receiver's normal: the point is pushed off its surface by about one texel footprint
    /// (normal-offset shadow mapping) so grazing receivers do not shadow themselves.
    pub fn shadow_test(&self, receiver: Vec3, n: Vec3) -> ShadowTest {
        let dist = (receiver - self.origin).length();
        let p = receiver + n * (dist * 2.0 / self.res as f32);
        let d = p - self.origin;
        let face = major_face(d);
        let l = face_local(face, d);
        if l.z <= self.near {
            return ShadowTest::LIT;
        }
        let half = self.res as f32 * 0.5;
        // |l.x|, |l.y| ≤ l.z on the major face, so both are in [0, res]: truncation is floor.
        let x = ((l.x / l.z + 1.0) * half) as i64;
        let y = ((l.y / l.z + 1.0) * half) as i64;
        let bias = l.z * (1.0 / self.res as f32) + 1e-5;
        let base = face * self.res * self.res;
        let at = |dx: i64, dy: i64| {
            let xx = (x + dx).clamp(0, self.res as i64 - 1) as usize;
            let yy = (y + dy).clamp(0, self.res as i64 - 1) as usize;
            self.depth[base + yy * self.res + xx]
        };
        let footprint = l.z * 2.0 / self.res as f32;
        // The surface the centre tap stores, at the tap's own direction.
        let centre = at(0, 0);
        let stored = self.origin
            + face_world(
                face,
                Vec3::new(
                    ((x as f32 + 0.5) / half - 1.0) * centre,
                    ((y as f32 + 0.5) / half - 1.0) * centre,
                    centre,
                ),
            );
        let on_receiver =
            centre.is_finite() && n.dot(stored - receiver).abs() <= ON_RECEIVER * footprint;
        ShadowTest::from_taps(l.z, bias, footprint, on_receiver, at)
    }
}

/// A depth map's answer for one receiver: its centre tap, and whether the taps around it
/// agree. Point-sampled depth is only trustworthy away from depth edges: within a texel of
/// one, the receiver may be on either side (a doorway's shadow edge cast three metres away
/// is ~20 cm wide with a 32² cube), and next to a concave edge the tap often holds the other
/// surface, just in front of the receiver.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowTest {
    /// The centre tap sees the receiver.
    pub lit: bool,
    /// All 3×3 taps give the centre's answer.
    pub agreed: bool,
    /// Distance from the centre tap's surface to the receiver along the map's depth axis, in
    /// texel footprints at the receiver (0 when lit).
    pub gap: f32,
}

impl ShadowTest {
    pub const LIT: Self = Self {
        lit: true,
        agreed: true,
        gap: 0.0,
    };

    /// `depth_at(dx, dy)`: the stored depth `dx`, `dy` taps from the centre.
    /// `centre_on_receiver`: the centre tap's surface point lies in the receiver's tangent
    /// plane. A surface stored less than the bias in front of the (normal-offset) receiver is
    /// the receiver itself only then; otherwise it is something standing just in front of it
    /// (the receiver is a hand's width behind a partition that stands on it), which the bias
    /// alone would call lit: light leaking under the wall. Such taps are not lit, and with no
    /// gap to speak of they are left to a ray.
    fn from_taps(
        z: f32,
        bias: f32,
        footprint: f32,
        centre_on_receiver: bool,
        depth_at: impl Fn(i64, i64) -> f32,
    ) -> Self {
        let centre = depth_at(0, 0);
        let lit = z <= centre || (z <= centre + bias && centre_on_receiver);
        let mut agreed = true;
        for dy in -1..=1 {
            for dx in -1..=1 {
                agreed &= (z <= depth_at(dx, dy) + bias) == lit;
            }
        }
        Self {
            lit,
            agreed,
            gap: ((z - bias - centre) / footprint).max(0.0),
        }
    }

    /// 1 or 0 where the map is sure; `None` where a ray must decide.
    pub fn settled(&self, confirm_gap: f32) -> Option<f32> {
        match (self.lit, self.agreed) {
            (true, true) => Some(1.0),
            (false, true) if self.gap > confirm_gap => Some(0.0),
            _ => None,
        }
    }
}

/// An orthographic depth map looking along `direction` over a bounding sphere.
pub struct DepthOrtho {
    pub direction: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    pub center: Vec3,
    pub radius: f32,
    pub res: usize,
    pub depth: Vec<f32>,
}

impl DepthOrtho {
    pub fn new(
        direction: Vec3,
        center: Vec3,
        radius: f32,
        res: usize,
        triangles: &Triangles,
    ) -> Self {
        let direction = direction.normalize();
        let u = direction.any_orthonormal_vector();
        let v = direction.cross(u);
        let mut map = Self {
            direction,
            u,
            v,
            center,
            radius,
            res,
            depth: vec![f32::INFINITY; res * res],
        };
        for tri in triangles {
            let s = tri.map(|p| map.project(p));
            raster_triangle(&mut map.depth, res, s, false);
        }
        map
    }

    fn project(&self, p: Vec3) -> Vec3 {
        let d = p - self.center;
        let half = self.res as f32 * 0.5;
        Vec3::new(
            (d.dot(self.u) / self.radius + 1.0) * half,
            (d.dot(self.v) / self.radius + 1.0) * half,
            d.dot(self.direction) + self.radius,
        )
    }

    /// See [`DepthCube::shadow_test`]; the footprint is the same everywhere.
    pub fn shadow_test(&self, receiver: Vec3, n: Vec3) -> ShadowTest {
        let p = receiver + n * (2.0 * self.radius / self.res as f32);
        let s = self.project(p);
        let (x, y) = (s.x.floor() as i64, s.y.floor() as i64);
        let bias = 2.0 * self.radius / self.res as f32 + 1e-5;
        let at = |dx: i64, dy: i64| {
            let xx = (x + dx).clamp(0, self.res as i64 - 1) as usize;
            let yy = (y + dy).clamp(0, self.res as i64 - 1) as usize;
            self.depth[yy * self.res + xx]
        };
        let footprint = 2.0 * self.radius / self.res as f32;
        let centre = at(0, 0);
        let half = self.res as f32 * 0.5;
        let stored = self.center
            + self.u * (((x as f32 + 0.5) / half - 1.0) * self.radius)
            + self.v * (((y as f32 + 0.5) / half - 1.0) * self.radius)
            + self.direction * (centre - self.radius);
        let on_receiver =
            centre.is_finite() && n.dot(stored - receiver).abs() <= ON_RECEIVER * footprint;
        ShadowTest::from_taps(s.z, bias, footprint, on_receiver, at)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::atlas::bake::CONFIRM_GAP;

    fn quad(y: f32, half: f32) -> Vec<[Vec3; 3]> {
        let a = Vec3::new(-half, y, -half);
        let b = Vec3::new(half, y, -half);
        let c = Vec3::new(half, y, half);
        let d = Vec3::new(-half, y, half);
        vec![[a, b, c], [a, c, d]]
    }

    #[test]
    fn bounding_box_rounding_matches_floor_and_ceil() {
        let values = [
            -1e30f32,
            -3.5,
            -1.0,
            -0.3,
            -0.0,
            0.0,
            1e-7,
            0.3,
            0.5,
            1.0,
            1.5,
            31.999,
            32.0,
            1e7,
            16_777_217.0,
            3e18,
            1e30,
        ];
        for v in values
            .into_iter()
            .chain([f32::NAN, f32::INFINITY, f32::NEG_INFINITY])
        {
            assert_eq!(ceil_at_least_zero(v), v.ceil().max(0.0) as i64, "ceil {v}");
            let f = floor_or_negative(v);
            if v >= 0.0 || v.is_nan() {
                assert_eq!(f, v.floor() as i64, "floor {v}");
            } else {
                assert!(f < 0 && v.floor() < 0.0, "floor {v}");
            }
        }
    }

    #[test]
    fn cube_sees_a_blocker() {
        // A small blocker 0.5 below the origin shadows the floor at y = -1 straight below it,
        // not the floor far to the side.
        let mut tris = quad(-0.5, 0.1);
        tris.extend(quad(-1.0, 5.0));
        let cube = DepthCube::new(Vec3::ZERO, 64, 1e-3, &tris);
        assert!(!cube.shadow_test(Vec3::new(0.0, -1.0, 0.0), Vec3::Y).lit);
        assert!(cube.shadow_test(Vec3::new(2.0, -1.0, 0.5), Vec3::Y).lit);
        assert!(cube.shadow_test(Vec3::new(0.0, -0.5, 0.0), Vec3::Y).lit);
    }

    #[test]
    fn depth_edges_are_left_to_a_ray() {
        // A 0.1 m blocker 0.25 below the origin shadows a 0.4 m square of the floor at y = -1.
        let mut tris = quad(-0.25, 0.05);
        tris.extend(quad(-1.0, 5.0));
        let cube = DepthCube::new(Vec3::ZERO, 32, 1e-3, &tris);
        let at = |x: f32| cube.shadow_test(Vec3::new(x, -1.0, 0.0), Vec3::Y);
        // Well inside the shadow, well outside it: the map is sure.
        assert_eq!(at(0.0).settled(CONFIRM_GAP), Some(0.0));
        assert_eq!(at(1.5).settled(CONFIRM_GAP), Some(1.0));
        // On the shadow's edge (x = 0.2) the taps disagree: a ray decides.
        assert_eq!(at(0.2).settled(CONFIRM_GAP), None);
        assert!(!at(0.2).agreed);
        // A shadow cast from just in front of the receiver is never settled by the map.
        let close = DepthCube::new(Vec3::new(0.0, 0.0, 0.0), 32, 1e-3, &quad(-0.95, 3.0));
        let t = close.shadow_test(Vec3::new(0.3, -1.0, 0.0), Vec3::NEG_Y);
        assert!(!t.lit && t.gap < CONFIRM_GAP);
        assert_eq!(t.settled(CONFIRM_GAP), None);
    }

    /// A wall standing on the floor at x = 0, the map's centre 0.6 m up on the −x side:
    /// floor points a few centimetres behind the wall see the wall's foot stored less than
    /// the depth bias in front of them, which the bias alone took for the floor itself (lit:
    /// light under the wall, 10× the path tracer's bounce light behind the corridor's
    /// partition). The map no longer settles any of them lit; the floor on the near side, stored
    /// where the receiver is, stays settled lit.
    #[test]
    fn a_wall_standing_on_the_receiver_is_not_taken_for_it() {
        let (a, b) = (Vec3::new(0.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 3.0));
        let (c, d) = (Vec3::new(0.0, 2.0, 3.0), Vec3::new(0.0, 2.0, -3.0));
        let mut tris = quad(0.0, 3.0);
        tris.extend([[a, b, c], [a, c, d]]);
        let cube = DepthCube::new(Vec3::new(-0.65, 0.6, 0.8), 32, 1e-3, &tris);
        let (mut bias_alone, mut settled_lit, mut total) = (0, 0, 0);
        for i in 0..10 {
            for k in 0..40 {
                let behind = Vec3::new(0.005 + 0.01 * i as f32, 0.0, -1.0 + 0.05 * k as f32);
                total += 1;
                if cube.shadow_test(behind, Vec3::Y).settled(CONFIRM_GAP) == Some(1.0) {
                    settled_lit += 1;
                }
                // The same taps under the bias-only rule (every stored surface within the
                // bias counted as the receiver).
                let d =
                    behind + Vec3::Y * ((behind - cube.origin).length() * 2.0 / 32.0) - cube.origin;
                let face = major_face(d);
                let l = face_local(face, d);
                let x = ((l.x / l.z + 1.0) * 16.0).floor() as i64;
                let y = ((l.y / l.z + 1.0) * 16.0).floor() as i64;
                let at = |dx: i64, dy: i64| {
                    let (xx, yy) = ((x + dx).clamp(0, 31), (y + dy).clamp(0, 31));
                    cube.depth[face * 32 * 32 + yy as usize * 32 + xx as usize]
                };
                let old = ShadowTest::from_taps(l.z, l.z / 32.0 + 1e-5, l.z / 16.0, true, at);
                if old.settled(CONFIRM_GAP) == Some(1.0) {
                    bias_alone += 1;
                }
            }
        }
        eprintln!(
            "{total} floor points behind the wall: {bias_alone} settled lit by the bias alone, \
             {settled_lit} now"
        );
        assert!(bias_alone >= 20, "not exercised: {bias_alone} of {total}");
        assert_eq!(settled_lit, 0);
        for x in [-0.3f32, -0.8, -1.5] {
            let t = cube.shadow_test(Vec3::new(x, 0.0, 0.2), Vec3::Y);
            assert_eq!(t.settled(CONFIRM_GAP), Some(1.0), "{x}: {t:?}");
        }
    }

    /// A built-in scene tessellated to 10 cm, placed.
    fn built_in(name: &str) -> (crate::scene::Scene, Vec<glam::Mat4>) {
        let params = crate::scene::builtin::BuiltinParams { max_edge: 0.1 };
        let scene = crate::scene::load(name, &params).unwrap();
        let world = scene.world_from_node();
        (scene, world)
    }

    /// Drawing a triangle whose corners share a major face into that face alone gives the
    /// same cube, texel for texel, as drawing every triangle into all six faces: on a finely
    /// tessellated scene (the built-in Cornell box) seen from points near walls, corners and
    /// edges, where many triangles straddle faces.
    #[test]
    fn one_face_culling_draws_the_same_cube() {
        let (scene, world) = built_in("cornell");
        let tris = scene.world_triangles(&world);
        assert!(tris.len() > 500, "{} triangles", tris.len());
        let mut straddling = 0;
        let bounds = scene.world_bounds(&world);
        for at in [
            Vec3::new(0.5, 0.5, 0.5),
            Vec3::new(0.02, 0.01, 0.03),
            Vec3::new(0.97, 0.95, 0.4),
            Vec3::new(0.3, 0.002, 0.6),
        ] {
            let origin = bounds.min + (bounds.max - bounds.min) * at;
            let fast = DepthCube::rasterize(origin, 32, 1e-4, &tris, true);
            let slow = DepthCube::rasterize(origin, 32, 1e-4, &tris, false);
            assert_eq!(fast.depth, slow.depth, "cube at {origin}");
            straddling += tris
                .iter()
                .filter(|t| {
                    let f = major_face(t[0] - origin);
                    major_face(t[1] - origin) != f || major_face(t[2] - origin) != f
                })
                .count();
        }
        assert!(
            straddling > 50,
            "only {straddling} triangles straddle faces"
        );
    }

    /// The bake draws its cubes from the tracer's merged triangles, where a wall is two
    /// triangles spanning several faces and reaching past the near plane. They must draw the
    /// cube the tessellated walls draw, seen from where shooting VPLs sit.
    #[test]
    fn merged_walls_draw_the_cube_the_tessellated_walls_draw() {
        let (scene, world) = built_in("corridor");
        let fine = scene.world_triangles(&world);
        let merged = crate::trace::Tracer::new(&scene, &world).world_triangles();
        assert!(
            merged.len() * 100 < fine.len(),
            "{} of {}",
            merged.len(),
            fine.len()
        );
        // Points 5 mm off the floor, the walls and the partition, as shooting VPLs sit.
        let mut origins = vec![Vec3::new(1.0, 1.2, 1.0), Vec3::new(4.195, 2.395, 1.995)];
        for k in 0..6 {
            let t = (k as f32 + 0.5) / 6.0;
            origins.extend([
                Vec3::new(4.2 * t, 0.005, 2.0 * (1.0 - t)),
                Vec3::new(0.005, 2.4 * t, 2.0 * t),
                Vec3::new(4.2 * t, 2.4 * (1.0 - t), 1.995),
                Vec3::new(2.095, 2.4 * t, 0.6 * t),
            ]);
        }
        for origin in origins {
            // The bake's offsets: VPLs 10 ε off their surface, the near plane at ε.
            let a = DepthCube::new(origin, 32, 5e-4, &fine);
            let b = DepthCube::new(origin, 32, 5e-4, &merged);
            // A closed room has no empty texel in either. Texels whose centre falls on the
            // partition's or the door's silhouette may take either side.
            let empty = |c: &DepthCube| c.depth.iter().filter(|d| !d.is_finite()).count();
            assert_eq!(
                (empty(&a), empty(&b)),
                (0, 0),
                "empty texels, cube at {origin}"
            );
            let differing = a
                .depth
                .iter()
                .zip(&b.depth)
                .filter(|(x, y)| (*x - *y).abs() > 1e-3 * x.abs().max(1e-3))
                .count();
            assert!(
                differing * 500 <= a.depth.len(),
                "cube at {origin}: {differing} of {} texels differ",
                a.depth.len()
            );
        }
    }

    #[test]
    fn hemisphere_coverage_above_a_floor() {
        // Above an infinite-ish floor looking down: all of the lower hemisphere is covered.
        let tris = quad(-1.0, 1000.0);
        let cube = DepthCube::new(Vec3::ZERO, 32, 1e-3, &tris);
        assert!((cube.hemisphere_coverage(Vec3::NEG_Y) - 1.0).abs() < 1e-3);
        assert!(cube.hemisphere_coverage(Vec3::Y) < 1e-3);
        // Half covered when the normal is horizontal.
        assert!((cube.hemisphere_coverage(Vec3::X) - 0.5).abs() < 0.02);
    }

    #[test]
    fn ortho_sees_a_blocker() {
        let mut tris = quad(0.5, 0.2);
        tris.extend(quad(-1.0, 3.0));
        let map = DepthOrtho::new(Vec3::NEG_Y, Vec3::ZERO, 4.0, 256, &tris);
        assert!(!map.shadow_test(Vec3::new(0.0, -1.0, 0.0), Vec3::Y).lit);
        assert!(map.shadow_test(Vec3::new(1.0, -1.0, 1.0), Vec3::Y).lit);
    }
}
