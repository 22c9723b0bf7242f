//! Mixed reality (seed 003 §5): every pixel of a depth-sensor frame is a real surface patch
//! with a position, a normal, an area and a colour, so it becomes a virtual area light for the
//! virtual content. See README.md in this folder for the equations and the measured figures.
//!
//! - [`rgbd`]: colour + depth frames in four sensor layouts, intrinsics, poses.
//! - [`depth_vals`]: the GPU passes depth → VALs, a [`crate::light::ValSource`].
//! - [`math`]: their CPU twins and the equations.
//! - [`run`]: `valgi mr`.
//! - [`session`]: the object placed in the room, lit, and composited into the photo.

pub mod depth_vals;
pub mod math;
pub mod rgbd;
pub mod run;
pub mod session;

use glam::Mat4;

/// The renderer's view axes (x right, y up, −z forward) from a sensor's OpenCV camera axes
/// (x right, y down, +z forward): `world_from_view = world_from_camera · VIEW_FROM_CAMERA⁻¹`.
pub fn world_from_view(world_from_camera: Mat4) -> Mat4 {
    world_from_camera * Mat4::from_scale(glam::Vec3::new(1.0, -1.0, -1.0))
}

/// The mixed-reality structs shared with WGSL, for the layout test.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout;
    vec![shared_layout!(
        "DepthValParams",
        "depth_vals.wgsl",
        depth_vals::DepthValParams,
        [
            world_from_camera,
            fx,
            fy,
            cx,
            cy,
            width,
            height,
            grid_width,
            grid_height,
            sigma_spatial,
            sigma_range,
            real_scale,
            max_jump,
            radius,
            area_mode,
            cluster_tiles,
            pad1,
            receivers,
            cut_ratio,
            pad2,
            pad3,
            pad4
        ]
    )]
}
