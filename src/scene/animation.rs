//! Keyframe animation of node TRS components (the glTF animation model without morph weights).
//!
//! Channels are sampled independently and overwrite the animated component of the target node's
//! local [`Trs`]; components no channel animates keep their rest value. Times outside the key
//! range clamp to the first / last key, as glTF viewers do, so a finished animation holds its
//! last pose instead of snapping back.

use super::Trs;
use glam::{Quat, Vec4};

/// Which TRS component a channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Property {
    Translation,
    Rotation,
    Scale,
}

/// How values between keys are obtained (glTF `sampler.interpolation`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    Step,
    Linear,
    CubicSpline,
}

/// One animated property of one node.
///
/// `values` holds one entry per key (`Step`, `Linear`) or three per key (`CubicSpline`:
/// in-tangent, value, out-tangent, as glTF stores them). Translation and scale use xyz;
/// rotation is a quaternion (x, y, z, w).
#[derive(Clone, Debug)]
pub struct Channel {
    /// Index into `Scene::nodes`.
    pub node: usize,
    pub property: Property,
    pub interpolation: Interpolation,
    /// Key times in seconds, strictly increasing.
    pub times: Vec<f32>,
    pub values: Vec<Vec4>,
}

/// A named set of channels played together.
#[derive(Clone, Debug, Default)]
pub struct Animation {
    pub name: String,
    pub channels: Vec<Channel>,
}

impl Animation {
    /// Overwrites the animated components of `locals` (indexed like `Scene::nodes`) with their
    /// values at `time` seconds. Channels targeting a node outside `locals`, or with no usable
    /// keys, are ignored so a malformed animation can never panic the renderer.
    pub fn apply(&self, time: f32, locals: &mut [Trs]) {
        for channel in &self.channels {
            let Some(local) = locals.get_mut(channel.node) else {
                continue;
            };
            let Some(value) = channel.sample(time) else {
                continue;
            };
            match channel.property {
                Property::Translation => local.translation = value.truncate(),
                Property::Scale => local.scale = value.truncate(),
                Property::Rotation => local.rotation = quat_from_vec4(value),
            }
        }
    }

    /// Time of the last key over all channels, seconds (0 when there are no keys).
    pub fn duration(&self) -> f32 {
        self.channels
            .iter()
            .filter_map(|c| c.times.last().copied())
            .filter(|t| t.is_finite())
            .fold(0.0, f32::max)
    }
}

impl Channel {
    /// Number of keys that have both a time and (all of) their values.
    fn key_count(&self) -> usize {
        let per_key = match self.interpolation {
            Interpolation::CubicSpline => 3,
            _ => 1,
        };
        self.times.len().min(self.values.len() / per_key)
    }

    /// The key's value (not a tangent).
    fn key_value(&self, k: usize) -> Vec4 {
        match self.interpolation {
            Interpolation::CubicSpline => self.values[3 * k + 1],
            _ => self.values[k],
        }
    }

    /// Samples the channel at `time`, clamped to the key range. Rotations come back as a
    /// normalized quaternion in xyzw; `None` when the channel has no keys.
    pub fn sample(&self, time: f32) -> Option<Vec4> {
        let n = self.key_count();
        if n == 0 {
            return None;
        }
        let first = self.times[0];
        let last = self.times[n - 1];
        if n == 1 || time.is_nan() || time <= first {
            return Some(self.finish(self.key_value(0)));
        }
        if time >= last {
            return Some(self.finish(self.key_value(n - 1)));
        }
        // First key strictly after `time`; it lies in 1..n because first < time < last.
        let next = self.times[..n]
            .partition_point(|&t| t <= time)
            .clamp(1, n - 1);
        let prev = next - 1;
        let dt = self.times[next] - self.times[prev];
        if dt.is_nan() || dt <= 0.0 {
            return Some(self.finish(self.key_value(next)));
        }
        let s = ((time - self.times[prev]) / dt).clamp(0.0, 1.0);
        let value = match self.interpolation {
            Interpolation::Step => self.key_value(prev),
            Interpolation::Linear => {
                let a = self.key_value(prev);
                let b = self.key_value(next);
                match self.property {
                    Property::Rotation => {
                        let qa = quat_from_vec4(a);
                        let qb = quat_from_vec4(b);
                        Vec4::from(qa.slerp(qb, s))
                    }
                    _ => a.lerp(b, s),
                }
            }
            Interpolation::CubicSpline => {
                // glTF Appendix C: Hermite spline with tangents scaled by the key interval.
                let v0 = self.values[3 * prev + 1];
                let out0 = self.values[3 * prev + 2];
                let in1 = self.values[3 * next];
                let v1 = self.values[3 * next + 1];
                let s2 = s * s;
                let s3 = s2 * s;
                v0 * (2.0 * s3 - 3.0 * s2 + 1.0)
                    + out0 * (dt * (s3 - 2.0 * s2 + s))
                    + v1 * (-2.0 * s3 + 3.0 * s2)
                    + in1 * (dt * (s3 - s2))
            }
        };
        Some(self.finish(value))
    }

    /// Rotations are renormalized (cubic interpolation leaves the unit sphere); other
    /// properties pass through.
    fn finish(&self, value: Vec4) -> Vec4 {
        match self.property {
            Property::Rotation => Vec4::from(quat_from_vec4(value)),
            _ => value,
        }
    }
}

/// Normalized quaternion from xyzw, falling back to identity for a zero or non-finite input.
fn quat_from_vec4(v: Vec4) -> Quat {
    let len = v.length();
    if len.is_finite() && len > 1e-12 {
        Quat::from_vec4(v / len)
    } else {
        Quat::IDENTITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::f32::consts::FRAC_PI_2;

    fn channel(
        property: Property,
        interpolation: Interpolation,
        times: &[f32],
        values: &[Vec4],
    ) -> Animation {
        Animation {
            name: "test".into(),
            channels: vec![Channel {
                node: 0,
                property,
                interpolation,
                times: times.to_vec(),
                values: values.to_vec(),
            }],
        }
    }

    #[test]
    fn linear_translation_interpolates_and_clamps() {
        let a = channel(
            Property::Translation,
            Interpolation::Linear,
            &[1.0, 3.0],
            &[Vec4::ZERO, Vec4::new(2.0, 4.0, 6.0, 0.0)],
        );
        let mut locals = [Trs::default()];
        a.apply(2.0, &mut locals);
        assert!((locals[0].translation - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6);
        a.apply(-5.0, &mut locals);
        assert_eq!(locals[0].translation, Vec3::ZERO);
        a.apply(10.0, &mut locals);
        assert_eq!(locals[0].translation, Vec3::new(2.0, 4.0, 6.0));
        assert_eq!(a.duration(), 3.0);
        // Untouched components keep their rest value.
        assert_eq!(locals[0].scale, Vec3::ONE);
    }

    #[test]
    fn step_holds_previous_key() {
        let a = channel(
            Property::Scale,
            Interpolation::Step,
            &[0.0, 1.0, 2.0],
            &[Vec4::splat(1.0), Vec4::splat(2.0), Vec4::splat(3.0)],
        );
        let mut locals = [Trs::default()];
        a.apply(1.5, &mut locals);
        assert_eq!(locals[0].scale, Vec3::splat(2.0));
        a.apply(0.999, &mut locals);
        assert_eq!(locals[0].scale, Vec3::splat(1.0));
    }

    #[test]
    fn linear_rotation_slerps() {
        let q0 = Quat::IDENTITY;
        let q1 = Quat::from_rotation_y(FRAC_PI_2);
        let a = channel(
            Property::Rotation,
            Interpolation::Linear,
            &[0.0, 1.0],
            &[Vec4::from(q0), Vec4::from(q1)],
        );
        let mut locals = [Trs::default()];
        a.apply(0.5, &mut locals);
        let expected = Quat::from_rotation_y(FRAC_PI_2 * 0.5);
        assert!(locals[0].rotation.angle_between(expected) < 1e-5);
        assert!((locals[0].rotation.length() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn cubic_spline_matches_hermite_and_hits_keys() {
        // Zero tangents: p(s) = v0 + (v1 - v0)(3s² - 2s³); at s = 0.5 the midpoint.
        let v = |x: f32| Vec4::new(x, 0.0, 0.0, 0.0);
        let a = channel(
            Property::Translation,
            Interpolation::CubicSpline,
            &[0.0, 2.0],
            &[v(0.0), v(0.0), v(0.0), v(0.0), v(4.0), v(0.0)],
        );
        let mut locals = [Trs::default()];
        a.apply(1.0, &mut locals);
        assert!((locals[0].translation.x - 2.0).abs() < 1e-6);
        a.apply(0.5, &mut locals);
        let s: f32 = 0.25;
        assert!((locals[0].translation.x - 4.0 * (3.0 * s * s - 2.0 * s * s * s)).abs() < 1e-5);
        a.apply(2.0, &mut locals);
        assert_eq!(locals[0].translation.x, 4.0);
    }

    #[test]
    fn cubic_rotation_is_normalized() {
        let q0 = Vec4::from(Quat::IDENTITY);
        let q1 = Vec4::from(Quat::from_rotation_x(1.0));
        let a = channel(
            Property::Rotation,
            Interpolation::CubicSpline,
            &[0.0, 1.0],
            &[Vec4::ZERO, q0, Vec4::ZERO, Vec4::ZERO, q1, Vec4::ZERO],
        );
        let mut locals = [Trs::default()];
        a.apply(0.3, &mut locals);
        assert!((locals[0].rotation.length() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn malformed_channels_do_not_panic() {
        let mut a = channel(
            Property::Translation,
            Interpolation::CubicSpline,
            &[0.0, 1.0],
            &[Vec4::ONE],
        );
        a.channels[0].node = 0;
        let mut locals = [Trs::default()];
        a.apply(0.5, &mut locals); // too few values: ignored
        assert_eq!(locals[0].translation, Vec3::ZERO);
        a.channels[0].node = 5;
        a.apply(0.5, &mut locals); // node out of range: ignored
        let empty = channel(Property::Scale, Interpolation::Linear, &[], &[]);
        empty.apply(f32::NAN, &mut locals);
        assert_eq!(empty.duration(), 0.0);
    }
}
