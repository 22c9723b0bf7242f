//! Percentage-closer soft shadows (Fernando 2005) from a depth cube at a virtual light's centre
//! (seed 001 §6: 5 occluder-search and 8 filter samples). Worked in angles around the
//! direction from the light to the receiver:
//! - the occluder search covers the light's angular radius as seen from the receiver, twice
//!   over (blockers from the receiver to a third of the way to the light) [V];
//! - the penumbra width at the receiver is `w·(d_r − d_b)/d_b` for a light of size w, the
//!   mean blocker distance d_b and the receiver's d_r, the filter radius half of it as seen
//!   from the light, at least one depth texel;
//! - each tap compares the stored depth with the receiver's *plane* along the tap's
//!   direction (receiver-plane depth), so a tilted receiver does not shadow itself, with a
//!   bias of one depth texel plus the tap's lateral offset, at most two texels more (a surface
//!   meeting the receiver at a concave edge can stand that far in front of its plane there);
//! - a polygon light's own plane is no blocker: what the cube stores at or behind it is the
//!   surface the light lies on, which a tap grazing the plane hits first.

use glam::Vec3;

use crate::atlas::depth::DepthCube;

/// Occluder-search taps (centre and a rotated cross).
pub const SEARCH_TAPS: usize = 5;
/// Filter taps (a Vogel disc).
pub const FILTER_TAPS: usize = 8;

/// The lateral-offset part of a tap's bias is capped at this many depth texels (beyond it, a
/// wall just behind a doorway's edge would stop shadowing the room it hides).
const SLOPE_TEXELS: f32 = 2.0;

/// Largest tap angle (radians) off the direction to the receiver.
const MAX_ANGLE: f32 = 1.0;

/// Visibility in [0, 1] of the light of size `light_size` (world units) whose depth cube is
/// `cube`, from the receiver `(p, n)`. `emitter` is a polygon light's plane (its centre,
/// normal, and the height above it below which a stored surface counts as the plane itself),
/// `None` for a sphere.
pub fn pcss_visibility(
    cube: &DepthCube,
    p: Vec3,
    n: Vec3,
    light_size: f32,
    emitter: Option<(Vec3, Vec3, f32)>,
) -> f32 {
    let texel = 2.0 / cube.res as f32;
    let dist0 = (p - cube.origin).length();
    if dist0 <= cube.near {
        return 1.0;
    }
    // Normal offset of about one depth texel's footprint (as the shadow test does).
    let p = p + n * (dist0 * texel);
    let to = p - cube.origin;
    let dist = to.length();
    let w = to / dist;
    let (t, b) = crate::sampling::basis(w);
    let plane = n.dot(p - cube.origin);
    // Distance from the origin along `s` to the receiver's plane (or to p when grazing).
    let receiver_along = |s: Vec3| {
        let ns = n.dot(s);
        if ns.abs() > 1e-3 {
            let t = plane / ns;
            if t > 0.0 && t < 4.0 * dist {
                return t;
            }
        }
        dist
    };
    let dir = |angle: f32, phi: f32| {
        let a = angle.min(MAX_ANGLE).tan();
        (w + (t * phi.cos() + b * phi.sin()) * a).normalize()
    };
    // A tap `angle` off the receiver's direction: Some(distance of the blocker along s) when
    // something stands in front of the receiver, None when lit.
    let tap = |s: Vec3, angle: f32| -> Option<f32> {
        let (stored, along_axis) = cube.depth_toward(s);
        if !stored.is_finite() {
            return None;
        }
        let r = receiver_along(s) * along_axis;
        let bias = r * (texel + angle.min(SLOPE_TEXELS * texel)) + 1e-5;
        if stored >= r - bias {
            return None;
        }
        let blocker = stored / along_axis;
        if let Some((c, nl, tolerance)) = emitter {
            let on_plane = cube
                .surface_toward(s)
                .is_some_and(|q| nl.dot(q - c) <= tolerance);
            if on_plane {
                return None;
            }
        }
        Some(blocker)
    };
    let search = ((0.5 * light_size / dist) * 2.0).max(texel);
    let mut blockers = 0usize;
    let mut depth_sum = 0.0f32;
    for k in 0..SEARCH_TAPS {
        let (s, angle) = if k == 0 {
            (w, 0.0)
        } else {
            (
                dir(search, 0.4 + k as f32 * std::f32::consts::FRAC_PI_2),
                search,
            )
        };
        if let Some(d) = tap(s, angle) {
            blockers += 1;
            depth_sum += d;
        }
    }
    if blockers == 0 {
        return 1.0;
    }
    let blocker = (depth_sum / blockers as f32).max(cube.near);
    let penumbra = light_size * (dist - blocker).max(0.0) / blocker;
    let radius = (0.5 * penumbra / dist).max(texel);
    let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let mut lit = 0usize;
    for k in 0..FILTER_TAPS {
        let rk = radius * ((k as f32 + 0.5) / FILTER_TAPS as f32).sqrt();
        if tap(dir(rk, k as f32 * golden), rk).is_none() {
            lit += 1;
        }
    }
    lit as f32 / FILTER_TAPS as f32
}
