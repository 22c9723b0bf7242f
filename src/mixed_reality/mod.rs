//! Mixed reality (seed 003 §5): every pixel of a depth-sensor frame is a real surface patch
//! with a position, a normal, an area and a colour, so it becomes a virtual area light for the
//! virtual content. See README.md in this folder for the equations and the measured figures.
//!
//! - [`rgbd`]: colour + depth frames in four sensor layouts, intrinsics, poses.

pub mod rgbd;

use glam::Mat4;

/// The renderer's view axes (x right, y up, −z forward) from a sensor's OpenCV camera axes
/// (x right, y down, +z forward): `world_from_view = world_from_camera · VIEW_FROM_CAMERA⁻¹`.
pub fn world_from_view(world_from_camera: Mat4) -> Mat4 {
    world_from_camera * Mat4::from_scale(glam::Vec3::new(1.0, -1.0, -1.0))
}
