//! Light the indirect methods share: reflective shadow maps turned into virtual area lights
//! ([`rsm`]), the VAL record itself, and the parameter block every VAL consumer's shaders
//! read. `sparse`, `brute`, `lpv`/`holpv` all start from [`rsm::Rsm`]; none of them owns it.

pub mod bvh;
pub mod rsm;

use std::f32::consts::PI;

use bytemuck::{Pod, Zeroable};
use glam::Vec3;

/// One virtual area light: a disc at `position` facing `normal` that reflects `flux` (W, RGB),
/// with the area `area` (m²) of its footprint had the surface faced the light.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Val {
    pub position: Vec3,
    pub normal: Vec3,
    pub flux: Vec3,
    pub area: f32,
}

impl Val {
    /// r² = A/π.
    pub fn radius_squared(&self) -> f32 {
        self.area / PI
    }
}

/// `SparseParams` in `shaders/vals/vals_common.wgsl`: what a VAL gather is told (the eye of its
/// glossy lobes, counts, flags, the workgroup tile).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ValParams {
    pub eye: [f32; 4],
    pub point_count: u32,
    pub instance_count: u32,
    pub flags: u32,
    pub occlusion_mode: u32,
    pub tile: u32,
    pub vertex_count: u32,
    /// RSM cluster tiles over all layers (`--occlusion rays`).
    pub rsm_tiles: u32,
    pub pad1: u32,
}

/// Glossy lobes on.
pub const FLAG_GLOSSY: u32 = 1;
/// Light positions averaged with flux weights instead of geometric ones.
pub const FLAG_FLUX_WEIGHTS: u32 = 2;
/// Recompute only the glossy half of the solution (per-view glossy eye); the diffuse half
/// of every point stays as the frame's update left it.
pub const FLAG_GLOSSY_ONLY: u32 = 4;
/// Scale each VAL by its cluster's visibility at the point (`--occlusion rays`).
pub const FLAG_VISIBILITY: u32 = 8;

/// The light module's structs shared with WGSL, for the layout test.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout;
    let mut layouts = bvh::shared_layouts();
    layouts.extend(vec![
        shared_layout!(
            "Val",
            "vals_common.wgsl",
            rsm::GpuVal,
            [position_area, normal, flux]
        ),
        shared_layout!(
            "RsmView",
            "vals_rsm.wgsl",
            rsm::RsmView,
            [
                clip_from_world,
                light_index,
                resolution,
                tan_half_fov,
                texel_area
            ]
        ),
        shared_layout!(
            "RsmSize",
            "vals_from_rsm.wgsl",
            rsm::RsmSize,
            [resolution, layers, capacity, tiles]
        ),
    ]);
    layouts
}
