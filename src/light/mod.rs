//! Light the indirect methods share: reflective shadow maps turned into virtual area lights
//! ([`rsm`]), the VAL record itself, and the parameter block every VAL consumer's shaders
//! read. `sparse`, `brute`, `lpv`/`holpv` all start from [`rsm::Rsm`]; none of them owns it.

pub mod bvh;
pub mod rsm;
pub mod sensor;
pub mod val_windows;

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
    /// Percent of the last frame's cluster visibility kept (0: none, or no history yet).
    pub visibility_history: u32,
}

/// VALs made by something other than the RSM — the surfels of a depth-sensor frame — that
/// join the RSM's VALs in the same buffer, so the sparse gather, brute force and every other
/// VAL consumer treat both alike. The producer fills `candidates` (`rows × row_length`
/// [`rsm::GpuVal`] records, row-major) each frame before [`rsm::Rsm::record`] runs; a
/// candidate whose area (`position_area.w`) is not positive is an empty slot (a depth hole)
/// and never becomes a VAL. [`rsm::Rsm::with_external`] reserves the slots and its `record`
/// appends the valid candidates after the RSM's, in row order; [`append_vals`] is the CPU
/// twin of that pass.
///
/// With a `sensor`, each candidate's `flux.w` is its tile of the sensor's image
/// ([`sensor::pixel_tile`]); the append makes those tiles clusters of the visibility pass
/// after the RSM's tiles, and the visibility pass also tests its rays against the sensor's
/// depth. Without one the appended VALs are in no cluster.
pub struct ExternalVals {
    pub candidates: wgpu::Buffer,
    pub rows: u32,
    pub row_length: u32,
    pub sensor: Option<sensor::SensorBuffers>,
}

impl ExternalVals {
    /// Clusters the candidates make (0: none).
    pub fn cluster_tiles(&self) -> u32 {
        self.sensor.as_ref().map_or(0, |s| s.tiles * s.tiles)
    }
}

/// Something that makes [`ExternalVals`] every frame (a depth sensor's frame turned into
/// surfels), for a method to append to its RSM VALs.
pub trait ValSource: Send {
    /// The candidate buffer and its shape (fixed for the source's life).
    fn external(&self) -> &ExternalVals;
    /// Uploads this frame's input and records the passes that fill its candidates.
    fn record(
        &mut self,
        ctx: &crate::gpu::GpuContext,
        passes: &mut crate::gpu::Passes,
    ) -> Result<(), crate::raster::RenderError>;
    fn gpu_bytes(&self) -> u64;
    /// Extra keys for the method's JSON report.
    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::Map::new()
    }
}

/// CPU twin of `vals_append.wgsl`: `candidates`' valid entries (positive area), in order,
/// after `vals`, up to `capacity` VALs in all.
pub fn append_vals(vals: &mut Vec<Val>, candidates: &[Val], capacity: usize) {
    for c in candidates.iter().filter(|c| c.area > 0.0) {
        if vals.len() >= capacity {
            break;
        }
        vals.push(*c);
    }
}

/// Glossy lobes on.
pub const FLAG_GLOSSY: u32 = 1;

/// Whether a VAL method gathers glossy light (its `glossy` option).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GlossyGather {
    /// Where some material reflects glossily ([`reflects_glossily`]). An all-Lambert
    /// scene's glossy term is zero at every pixel, so only diffuse light is gathered, by a
    /// pipeline built without the glossy code (`GLOSSY_GATHER` false): on a CPU device a
    /// uniform flag does not skip code, since llvmpipe runs both sides of every branch.
    #[default]
    Auto,
    On,
    Off,
}

impl GlossyGather {
    /// The option's values, as `MethodOptions::choice` takes them.
    pub const CHOICES: &'static [&'static str] = &["auto", "on", "off"];

    /// One of [`Self::CHOICES`] (anything else is `auto`; `choice` has checked it).
    pub fn parse(choice: &str) -> Self {
        match choice {
            "on" => Self::On,
            "off" => Self::Off,
            _ => Self::Auto,
        }
    }

    /// Whether this setting gathers glossy light in a scene where some material reflects
    /// glossily (`reflects_glossily`) or none does.
    pub fn gathers(self, reflects_glossily: bool) -> bool {
        match self {
            Self::On => true,
            Self::Off => false,
            Self::Auto => reflects_glossily,
        }
    }
}

/// Some material of `scene` has a glossy lobe: ρ_s = specular factor · mix(0.04, base,
/// metallic) (`specular_albedo`) is zero for every material whose specular factor is 0.
pub fn reflects_glossily(scene: &crate::scene::Scene) -> bool {
    scene.materials.iter().any(|m| m.specular_factor > 0.0)
}
/// Light positions averaged with flux weights instead of geometric ones.
pub const FLAG_FLUX_WEIGHTS: u32 = 2;
/// Recompute only the glossy half of the solution (per-view glossy eye); the diffuse half
/// of every point stays as the frame's update left it.
pub const FLAG_GLOSSY_ONLY: u32 = 4;
/// Scale each VAL by its cluster's visibility at the point (`--occlusion rays`).
pub const FLAG_VISIBILITY: u32 = 8;
/// Visibility rays go to a tile's 2×2 coarse strata first, and to its other strata only when
/// those disagree (`visibility-rays adaptive`).
pub const FLAG_ADAPTIVE_RAYS: u32 = 16;

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
                texel_area,
                tile_origin
            ]
        ),
        shared_layout!(
            "ValWindow",
            "val_windows.wgsl",
            val_windows::ValWindow,
            [first, pad0, pad1, pad2]
        ),
        shared_layout!(
            "AppendSize",
            "vals_append.wgsl",
            rsm::AppendSize,
            [rows, row_length, capacity, first_tile]
        ),
        shared_layout!(
            "SensorParams",
            "sensor_occluder.wgsl",
            sensor::SensorParams,
            [
                camera_from_world,
                fx,
                fy,
                cx,
                cy,
                width,
                height,
                tiles,
                occludes,
                thickness,
                has_frame,
                pad
            ]
        ),
        shared_layout!(
            "RsmSize",
            "vals_from_rsm.wgsl",
            rsm::RsmSize,
            [rows, views, capacity, tiles]
        ),
        shared_layout!(
            "RsmTile",
            "vals_from_rsm.wgsl",
            rsm::RsmTile,
            [origin, layer, side, first_row]
        ),
    ]);
    layouts
}
