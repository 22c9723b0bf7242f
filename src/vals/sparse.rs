//! The sparse points on the GPU: static model-space buffers built once from the preprocessing,
//! and the per-frame passes gather → renormalize → occlusion → interpolation → apply.
//!
//! Memory per sparse point, 64 bytes: model position + octahedral normal (16), Phong k and
//! disc radius as f16 + instance index (8), and the solution: diffuse and glossy intensities
//! as f32 RGB with the averaged positions as f16 offsets from the point (16 + 16), the offsets'
//! z and the two occlusion spheres as f16 (8). Per vertex: the interpolated lights, 48 bytes
//! (f32, they are varyings of the apply pass), plus 48 bytes of static links per mesh vertex:
//! 8 × (u16 point index + unorm16 weight), and the vertex's model position and octahedral
//! normal for the interpolation's cap on blended lights.

use std::sync::Arc;

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Mat4, Vec3};
use half::f16;

use super::math::{OcclusionMode, PointLights, Weights};
use super::points::{MeshPoints, LINKS};
use crate::frame::View;
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{compute_pipeline_groups, linear_groups, GpuBytes, GpuContext, GpuError, Passes};
use crate::light::bvh::{MeshBvhs, SceneBvh, BVH_ROW_TEXELS};
use crate::light::rsm::{Rsm, MAX_CLUSTERS};
use crate::light::sensor::SensorBuffers;
use crate::light::val_windows::{self, ValReads, ValWindows};
use crate::raster::scene_gpu::SceneGpu;
use crate::raster::{
    buffer_binding, cleared, RenderError, ScenePipeline, POSITION_ONLY, RADIANCE_FORMAT,
};
use crate::scene::{Material, Scene};

pub use crate::light::{
    ValParams as SparseParams, FLAG_ADAPTIVE_RAYS, FLAG_FLUX_WEIGHTS, FLAG_GLOSSY,
    FLAG_GLOSSY_ONLY, FLAG_VISIBILITY,
};

/// Most discs a workgroup of the occlusion pass holds at once (`TILE_MAX` in
/// `vals_occlusion.wgsl` and `vals_occluder_bounds.wgsl`).
pub const OCCLUSION_TILE_MAX: u32 = 256;

/// vec4 words per node (tile or internal) of the occlusion tree (`BOUNDS_VEC4S` in
/// `vals_occluder_bounds.wgsl` and `vals_occlusion.wgsl`; [`super::math::OccluderBounds`]):
/// the centre and radius of the sphere around its disc centres; the half size of their box
/// and the largest disc radius.
pub const OCCLUDER_BOUNDS_VEC4S: u32 = 2;

/// Nodes per level of the occlusion tree over `point_count` discs at `tile` (clamped to
/// 1..=[`OCCLUSION_TILE_MAX`]) a leaf: tiles first, then internal levels up to one root
/// ([`super::math::occlusion_levels`]).
pub fn occlusion_levels(point_count: u32, tile: u32) -> Vec<u32> {
    super::math::occlusion_levels(
        point_count as usize,
        tile.clamp(1, OCCLUSION_TILE_MAX) as usize,
    )
    .into_iter()
    .map(|n| n as u32)
    .collect()
}

/// Invocations per workgroup of the solution kernels (gather, renormalize, occlusion,
/// interpolation: `@workgroup_size(64, 1, 1)`, checked against naga by
/// `tests/shader_layout.rs`).
pub const POINT_GROUP: u32 = 64;

/// Invocations per workgroup of the window-form gather (`WINDOW_GROUP` in
/// `shaders/vals/vals_gather.wgsl`): small, so that a CPU device's threads end at most one
/// small workgroup apart.
pub const WINDOW_POINT_GROUP: u32 = 16;

/// Invocations per workgroup of the compute gather: [`WINDOW_POINT_GROUP`] in the window form,
/// [`POINT_GROUP`] in the tile form.
pub fn gather_workgroup_invocations(windows: bool) -> u32 {
    if windows {
        WINDOW_POINT_GROUP
    } else {
        POINT_GROUP
    }
}

/// Sparse points a gather invocation takes on a GPU (`GATHER_SLOTS` in
/// `shaders/vals/vals_gather.wgsl`), the count the H200's figures were measured with: a gather
/// workgroup covers `POINT_GROUP` times this many.
pub const GATHER_POINTS_PER_INVOCATION_GPU: u32 = 4;

/// The most points a gather invocation takes (`POINT_SLOTS` in `vals_gather_common.wgsl`).
pub const GATHER_POINTS_PER_INVOCATION_MAX: u32 = 16;

/// Sparse points each gather invocation takes (`GATHER_SLOTS`): `requested` where it is 4, 8
/// or 16 (`gather-points`); else on a GPU [`GATHER_POINTS_PER_INVOCATION_GPU`]. On a CPU
/// device the workgroups (of [`POINT_GROUP`] invocations in the tile form, of
/// [`WINDOW_POINT_GROUP`] in the window form) run on `threads` CPU threads in rounds, and the
/// count that takes the fewest rounds is not the one that takes the least time:
/// - The tile form (`windows` false) reads every VAL from workgroup memory in each invocation,
///   a loop over the SIMD lanes per float on llvmpipe, so it takes the most of 16, 8 and 4
///   that still gives every thread a workgroup: more points per read ran it 1.4–2.1× faster
///   (lavapipe, 16k VALs × 4k points, 16 points against 4).
/// - The window form reads each VAL from a uniform block, one load for all lanes, so the
///   per-VAL work an invocation shares among its points is small, about
///   [`WINDOW_VAL_SLOTS`] points' worth; it takes the count with the least
///   rounds × (points + that). Its workgroups of 256 points (at 16) leave little idle in the
///   last round, so that is 16 from 1024 points up on two threads; with workgroups of 64 it
///   had split 4215 points (Sponza) into nine of 512 rather than five of 1024.
pub fn gather_points_per_invocation(
    requested: u32,
    cpu_device: bool,
    windows: bool,
    point_count: u32,
    threads: u32,
) -> u32 {
    if matches!(requested, 4 | 8 | 16) {
        return requested;
    }
    if !cpu_device {
        return GATHER_POINTS_PER_INVOCATION_GPU;
    }
    let threads = threads.max(1);
    let group = gather_workgroup_invocations(windows);
    let workgroups = |slots: u32| point_count.div_ceil(group * slots);
    if !windows {
        return [16, 8]
            .into_iter()
            .find(|&slots| workgroups(slots) >= threads)
            .unwrap_or(4);
    }
    // Ties go to the most points an invocation: `min_by_key` keeps the first minimum.
    [16, 8, 4]
        .into_iter()
        .min_by_key(|&slots| workgroups(slots).div_ceil(threads) * (slots + WINDOW_VAL_SLOTS))
        .unwrap_or(GATHER_POINTS_PER_INVOCATION_MAX)
}

/// The per-VAL work of a window-form gather invocation (the VAL's uniform read, Φ/π, its
/// position's square, the cluster word) in points' worth, from lavapipe's Cornell gather
/// (4095 points, 16k VALs, diffuse): 16, 8 and 4 points an invocation in 2, 4 and 8 rounds of
/// two threads took 54, 58 and 75 ms, which rounds × (points + c) matches with c = 1.3–2.4.
pub const WINDOW_VAL_SLOTS: u32 = 2;

/// The CPU threads a software device runs workgroups on: Mesa's `LP_NUM_THREADS` where set,
/// else the machine's (asked once per process: every frame's gather dispatch needs it).
pub fn cpu_device_threads() -> u32 {
    static THREADS: std::sync::OnceLock<u32> = std::sync::OnceLock::new();
    *THREADS.get_or_init(|| {
        std::env::var("LP_NUM_THREADS")
            .ok()
            .and_then(|v| v.trim().parse::<u32>().ok())
            .filter(|&n| n > 0)
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get() as u32))
    })
}

/// vec4 words per (slice, point) of the split gather's partial sums (`PARTIAL_VEC4S` in
/// `shaders/vals/vals_gather_partials.wgsl`): the 20 floats of one point's sums.
pub const GATHER_PARTIAL_VEC4S: u64 = 5;

/// At most this many VAL slices (`gather-slices`).
pub const GATHER_SLICES_MAX: u32 = 256;

/// Workgroups the automatic split aims for: enough to keep every multiprocessor of a large
/// GPU busy. On an H200, 4096 points × 16k VALs gathered in 0.84 ms at 16 and at 64 slices
/// (256 and 1024 workgroups), 1.08 ms at 256 slices, 12.3 ms unsplit (16 workgroups).
pub const GATHER_TARGET_WORKGROUPS: u32 = 1024;

/// The split gather's partial sums take at most this many bytes.
pub const GATHER_PARTIAL_BYTES_MAX: u64 = 64 << 20;

/// How many slices of the VAL list the compute gather runs as (dispatch z; 1 = unsplit).
///
/// `requested` 0 is automatic: unsplit on a CPU device, whose few threads the points already
/// fill (splitting there only adds the reduction); on a GPU enough slices that the
/// workgroups (of 64 invocations × `points_per_invocation` points) reach [`GATHER_TARGET_WORKGROUPS`], each slice at least one `tile` of
/// `val_capacity` VALs. Any request is capped by [`GATHER_SLICES_MAX`] and by the partial
/// sums' size (`max_bytes`, also the device's largest binding).
pub fn gather_slices(
    requested: u32,
    cpu_device: bool,
    point_count: u32,
    points_per_invocation: u32,
    val_capacity: u64,
    tile: u32,
    max_bytes: u64,
) -> u32 {
    let per_slice = u64::from(point_count.max(1)) * GATHER_PARTIAL_VEC4S * 16;
    let by_bytes =
        (max_bytes.min(GATHER_PARTIAL_BYTES_MAX) / per_slice).min(u64::from(u32::MAX)) as u32;
    let most = GATHER_SLICES_MAX.min(by_bytes).max(1);
    let wanted = match requested {
        0 if cpu_device => 1,
        0 => {
            let groups = point_count
                .div_ceil(POINT_GROUP * points_per_invocation.max(1))
                .max(1);
            let by_vals = val_capacity.div_ceil(u64::from(tile.max(1))).max(1);
            GATHER_TARGET_WORKGROUPS
                .div_ceil(groups)
                .min(by_vals.min(u64::from(u32::MAX)) as u32)
        }
        n => n,
    };
    wanted.clamp(1, most)
}

/// `InstanceRange` in `shaders/vals/vals_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct InstanceRange {
    pub vertex_offset: u32,
    /// Vertices with lights: the mesh's, twice for a two-sided sheet.
    pub vertex_count: u32,
    pub point_offset: u32,
    pub link_offset: u32,
    /// Where a two-sided sheet's back-face lights start after `vertex_offset` (its mesh's
    /// vertex count); 0 for a one-sided mesh.
    pub back_offset: u32,
}

/// The knobs of the sparse passes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseOptions {
    pub tile: u32,
    /// How the gather runs: a compute pass, or a fragment pass over a point target.
    pub gather: GatherForm,
    pub glossy: crate::light::GlossyGather,
    pub occlusion: OcclusionMode,
    pub weights: Weights,
    /// `--occlusion rays`: percent of last frame's visibility blended into this frame's.
    pub visibility_history: u32,
    /// `--occlusion rays`: each tile's coarse strata first, the rest only where they disagree
    /// (`visibility-rays adaptive`; [`crate::vals::visibility::cluster_visibility`]).
    pub adaptive_rays: bool,
    /// Slices of the VAL list the compute gather is split into (0: automatic, see
    /// [`gather_slices`]).
    pub gather_slices: u32,
    /// Points per compute-gather invocation, 4, 8 or 16 (0: automatic, see
    /// [`gather_points_per_invocation`]).
    pub gather_points: u32,
    /// How the compute gather picks a VAL's cluster visibility (`visibility-lookup`).
    pub visibility_lookup: VisibilityLookup,
    /// How the compute gather reads the VAL list (`gather-vals`).
    pub gather_vals: ValReads,
}

/// How the compute gather picks a VAL's cluster visibility from its points' words
/// (`VISIBILITY_SELECT_TREE` in `vals_gather.wgsl`). Both read the same word.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VisibilityLookup {
    /// The tree on a CPU device, the switch on a GPU.
    #[default]
    Auto,
    /// A select tree on the word index: every case of a switch runs under a mask on a CPU
    /// device, and there the tree made the gather 10–15 % faster.
    Tree,
    /// A switch on the word index, uniform over the workgroup: measured 10–13 % faster than a
    /// private array on an H200; the tree has not been timed on a GPU.
    Switch,
}

impl VisibilityLookup {
    /// The option's values, as `MethodOptions::choice` takes them.
    pub const CHOICES: &'static [&'static str] = &["auto", "tree", "switch"];

    /// One of [`Self::CHOICES`] (anything else is `auto`; `choice` has checked it), as
    /// [`crate::light::GlossyGather::parse`].
    pub fn parse(choice: &str) -> Self {
        match choice {
            "tree" => Self::Tree,
            "switch" => Self::Switch,
            _ => Self::Auto,
        }
    }

    /// Whether the gather is built with the select tree, on a CPU device or a GPU.
    pub fn select_tree(self, cpu_device: bool) -> bool {
        match self {
            Self::Auto => cpu_device,
            Self::Tree => true,
            Self::Switch => false,
        }
    }
}

/// The two forms of the gather (`--gather`), which compute the same sums.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GatherForm {
    /// `vals_gather.wgsl`: workgroups of 64 invocations × [`gather_points_per_invocation`]
    /// points, the VALs streamed through workgroup memory.
    #[default]
    Compute,
    /// `vals_gather_raster.wgsl`: one fragment per point on a [`RASTER_GATHER_WIDTH`]-wide
    /// target, each reading every VAL from the buffer (the paper's pixel-shader form).
    Raster,
}

/// Width of the raster gather's point target (`RASTER_WIDTH` in `vals_gather_raster.wgsl`):
/// point i is texel (i mod W, i div W).
pub const RASTER_GATHER_WIDTH: u32 = 256;

/// The VAL buffer copied into an rgba32uint texture of [`BVH_ROW_TEXELS`]-wide rows, VAL i at
/// texels 3i..3i+2 (`val_texel_record` in `vals_visibility.wgsl`), for the visibility pass's
/// stratum samples. Every lane of a visibility workgroup (one cluster) reads the same sample
/// VAL, which llvmpipe reads from a storage buffer lane by lane and from a texture with one
/// gathered load per texel (`light::bvh::BVH_ROW_TEXELS` has the measurement).
struct ValTexels {
    texture: wgpu::Texture,
    /// The VAL buffer, whole.
    source: wgpu::Buffer,
    bytes: u64,
}

impl ValTexels {
    fn new(ctx: &GpuContext, vals: &wgpu::Buffer) -> Result<Self, GpuError> {
        let (texture, bytes) = crate::light::bvh::texel_row_texture(
            ctx,
            "the VALs as texels for the visibility rays",
            vals.size() / 16,
            "Lower --rsm, or use --occlusion sum or off",
        )?;
        Ok(Self {
            texture,
            source: vals.clone(),
            bytes,
        })
    }

    /// Copies the VAL buffer in: its whole rows, then what is left as part of one more.
    fn record_copy(&self, encoder: &mut wgpu::CommandEncoder) {
        let row_bytes = u64::from(BVH_ROW_TEXELS) * 16;
        let size = self.source.size();
        let (full, rest) = (size / row_bytes, size % row_bytes);
        let copy = |encoder: &mut wgpu::CommandEncoder, row: u64, width: u32, height: u32| {
            encoder.copy_buffer_to_texture(
                wgpu::TexelCopyBufferInfo {
                    buffer: &self.source,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: row * row_bytes,
                        bytes_per_row: Some(row_bytes as u32),
                        rows_per_image: None,
                    },
                },
                wgpu::TexelCopyTextureInfo {
                    texture: &self.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: row as u32,
                        z: 0,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
            );
        };
        if full > 0 {
            copy(encoder, 0, BVH_ROW_TEXELS, full as u32);
        }
        if rest > 0 {
            copy(encoder, full, (rest / 16) as u32, 1);
        }
    }
}

/// The raster gather's pipeline and its (never stored) colour target, built on first use.
struct RasterGather {
    pipeline: wgpu::RenderPipeline,
    target: wgpu::TextureView,
}

/// A point's model-space position from its `points model` record (xyz as f32 bits).
fn model_position(model: &[u32; 4]) -> Vec3 {
    Vec3::new(
        f32::from_bits(model[0]),
        f32::from_bits(model[1]),
        f32::from_bits(model[2]),
    )
}

/// Octahedral encoding of a unit vector in two snorm16 (`oct_decode` in the shader).
pub fn oct_encode(n: Vec3) -> u32 {
    let n = n / (n.x.abs() + n.y.abs() + n.z.abs()).max(1e-30);
    let (mut x, mut y) = (n.x, n.y);
    if n.z < 0.0 {
        let (ox, oy) = (x, y);
        x = (1.0 - oy.abs()) * if ox >= 0.0 { 1.0 } else { -1.0 };
        y = (1.0 - ox.abs()) * if oy >= 0.0 { 1.0 } else { -1.0 };
    }
    let snorm = |v: f32| ((v.clamp(-1.0, 1.0) * 32767.0).round() as i16) as u16 as u32;
    snorm(x) | (snorm(y) << 16)
}

pub fn oct_decode(packed: u32) -> Vec3 {
    let unorm = |bits: u32| ((bits as u16 as i16) as f32 / 32767.0).max(-1.0);
    let (x, y) = (unorm(packed & 0xffff), unorm(packed >> 16));
    let mut n = Vec3::new(x, y, 1.0 - x.abs() - y.abs());
    if n.z < 0.0 {
        let sx = if n.x >= 0.0 { 1.0 } else { -1.0 };
        let sy = if n.y >= 0.0 { 1.0 } else { -1.0 };
        n = Vec3::new((1.0 - n.y.abs()) * sx, (1.0 - n.x.abs()) * sy, n.z);
    }
    n.normalize()
}

/// WGSL `pack2x16float` / `unpack2x16float`.
pub fn pack_half2(a: f32, b: f32) -> u32 {
    f16::from_f32(a).to_bits() as u32 | ((f16::from_f32(b).to_bits() as u32) << 16)
}

pub fn unpack_half2(v: u32) -> (f32, f32) {
    (
        f16::from_bits(v as u16).to_f32(),
        f16::from_bits((v >> 16) as u16).to_f32(),
    )
}

/// A sparse point decoded on the CPU exactly as the shaders decode it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DecodedPoint {
    pub position: Vec3,
    pub normal: Vec3,
    pub k: f32,
    pub disc_radius: f32,
}

/// The per-point solution buffers read back and decoded.
#[derive(Clone, Debug, Default)]
pub struct PointsReadback {
    pub points: Vec<DecodedPoint>,
    /// Diffuse/glossy channel values (sums after gather, intensities after renormalize) and
    /// positions, plus the occlusion spheres.
    pub lights: Vec<PointLights>,
    pub spheres: Vec<(f32, f32)>,
}

pub struct SparseGpu {
    pub point_count: u32,
    pub vertex_count: u32,
    pub instance_count: u32,
    /// Workgroups one dispatch dimension may hold (the device's
    /// `max_compute_workgroups_per_dimension`): longer kernels wrap into another dimension
    /// ([`crate::gpu::linear_groups`]). Lower only to exercise the wrap.
    pub max_groups_per_dimension: u32,
    /// Bytes of the per-point buffers (static + solution).
    pub point_bytes: u64,
    /// Bytes of the per-instance-vertex lights.
    pub vertex_light_bytes: u64,
    /// Bytes of the per-mesh-vertex links.
    pub link_bytes: u64,
    pub bytes: GpuBytes,
    params_buffer: wgpu::Buffer,
    points_model: Vec<[u32; 4]>,
    points_meta: Vec<[u32; 2]>,
    point_instances: Vec<usize>,
    /// The GPU copies of `points_model` and `points_meta` (the kernels' bind groups hold
    /// them too; kept for the debug view's draw).
    points_model_buffer: wgpu::Buffer,
    points_meta_buffer: wgpu::Buffer,
    point_diffuse: wgpu::Buffer,
    point_glossy: wgpu::Buffer,
    point_extra: wgpu::Buffer,
    pub clamp_buffer: wgpu::Buffer,
    vertex_lights: wgpu::Buffer,
    ranges_buffer: wgpu::Buffer,
    gather: Kernel,
    /// The device's pipelines: the gather's reduction and partial-sum group, visibility and
    /// apply are used from here; the other kernels hold theirs.
    pipelines: std::sync::Arc<SparsePipelines>,
    /// The largest storage binding the device allows (caps the partial sums).
    max_binding: u64,
    /// The partial sums last recorded: (bytes, buffer, group), made when their size changes
    /// (slices of a split gather, or the window form's running sums).
    partials: std::cell::RefCell<Option<(u64, wgpu::Buffer, wgpu::BindGroup)>>,
    /// The window form's group and window count, where the VAL buffer holds whole windows.
    val_windows: Option<ValWindows>,
    /// VALs the VAL buffer holds at most (the automatic split sizes its slices by it).
    val_capacity: u64,
    /// A CPU device (the automatic split leaves the gather whole).
    cpu_device: bool,
    /// Some material of the scene reflects glossily (`glossy auto` gathers glossy light).
    reflects_glossily: bool,
    /// The gather as a fragment pass (`--gather raster`), sharing `gather`'s bind groups.
    raster_gather: std::cell::OnceCell<RasterGather>,
    renormalize: Kernel,
    occlusion: Kernel,
    /// The bounds of the occlusion pass's disc tiles (view-free, its own parameter block).
    occluder_bounds: Kernel,
    /// Each point's place in the occlusion walk.
    occluder_walk: Vec<u32>,
    interpolate: Kernel,
    bvh: SceneBvh,
    visibility_buffer: wgpu::Buffer,
    /// The VAL buffer as texels, copied in before each visibility pass.
    val_texels: ValTexels,
    /// Last frame's visibility, blended into this frame's (`visibility-history`).
    visibility_history: wgpu::Buffer,
    /// Solutions recorded so far: the first has no history to blend.
    solutions_recorded: std::cell::Cell<u64>,
    visibility_group: wgpu::BindGroup,
    /// The visibility pass's group 2: a depth sensor's image (or the shared empty one).
    sensor_group: wgpu::BindGroup,
    /// RSM cluster tiles over all layers.
    rsm_tiles: u32,
    /// A depth sensor's tiles, clusters after the RSM's (0 without a sensor).
    sensor_tiles: u32,
    /// Whether a depth sensor's image takes part in the visibility (its VALs, its depth).
    has_sensor: bool,
}

/// Bytes of cluster visibility per sparse point: one per cluster.
pub const VISIBILITY_BYTES_PER_POINT: u64 = MAX_CLUSTERS as u64;

/// `vals_apply.wgsl` (vertex and fragment): the view's frame, the instances, their vertex
/// ranges, the vertex lights, the G-buffer's normal, diffuse and specular, and the parameters.
const APPLY_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::Storage,
    Slot::Storage,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::Uniform,
];

use Slot::{Storage as R, StorageRw as W};

/// The solution kernels' bindings, each list once (binding 0 is the parameter block, read-only
/// storage; see `GpuBytes::params`). The gather's: instances, points (model, meta), VALs, VAL
/// count, then the point diffuse, glossy and extra slots it writes, and the cluster visibility.
const GATHER_BINDINGS: &[Slot] = &[R, R, R, R, R, R, W, W, W, R];
/// Instances, points, point diffuse and glossy (renormalized in place), extra, clamp counts.
const RENORMALIZE_BINDINGS: &[Slot] = &[R, R, R, R, W, W, R, W];
/// Instances, points, the tree's bounds and the world-space discs it writes, the walk order.
const OCCLUDER_BOUNDS_BINDINGS: &[Slot] = &[R, R, R, R, W, W, R];
/// Instances, points, point diffuse and glossy (dimmed in place), extra, occluder bounds,
/// world-space discs.
const OCCLUSION_BINDINGS: &[Slot] = &[R, R, R, R, W, W, R, R, R];
/// Instances, points, point lights, instance ranges, links, the vertex lights it writes.
const INTERPOLATE_BINDINGS: &[Slot] = &[R, R, R, R, R, R, R, R, R, R, W];
/// Instances, points, VALs, RSM cluster samples, the visibility it writes, last frame's.
const VISIBILITY_BINDINGS: &[Slot] = &[R, R, R, R, Slot::UintTexture, R, W, R];
/// Group 2 of the visibility pass (`sensor_occluder.wgsl`): a depth sensor's parameters,
/// filtered depth and ray samples ([`crate::light::sensor::SensorBuffers`]).
const SENSOR_BINDINGS: &[Slot] = &[Slot::Uniform, R, R];

/// What the compute gather's code does besides diffuse light. A pipeline compiled without a
/// part has none of its code: a uniform flag alone leaves the code in, and a CPU device
/// (llvmpipe runs both sides of every branch under a mask) pays for it with the flag off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct GatherCode {
    /// The glossy lobes and their sums.
    glossy: bool,
    /// The cluster visibility of `--occlusion rays`.
    visibility: bool,
    /// The visibility lookup as a select tree, else as a switch ([`VisibilityLookup`]).
    select_tree: bool,
    /// The second position moments that size the disc occlusion's light spheres.
    spheres: bool,
    /// Points per invocation: 4, 8 or 16 ([`gather_points_per_invocation`]).
    slots: u32,
    /// The window form (`cs_window`, [`ValReads::Windows`]), else the tiles (`cs_main`).
    windows: bool,
}

impl GatherCode {
    /// Every part, with the device's own lookup: the pipeline built with the others.
    fn full(ctx: &GpuContext) -> Self {
        Self {
            glossy: true,
            visibility: true,
            select_tree: VisibilityLookup::Auto.select_tree(ctx.is_software()),
            spheres: true,
            slots: if ctx.is_software() {
                GATHER_POINTS_PER_INVOCATION_MAX
            } else {
                GATHER_POINTS_PER_INVOCATION_GPU
            },
            windows: ctx.is_software(),
        }
    }

    /// The entry point of `vals_gather.wgsl` that runs it.
    fn entry(self) -> &'static str {
        if self.windows {
            "cs_window"
        } else {
            "cs_main"
        }
    }

    /// The pipeline constants that build it (`vals_gather.wgsl`).
    fn constants(self) -> [(&'static str, f64); 5] {
        let flag = |on: bool| if on { 1.0 } else { 0.0 };
        [
            ("GLOSSY_GATHER", flag(self.glossy)),
            ("GATHER_VISIBILITY", flag(self.visibility)),
            ("VISIBILITY_SELECT_TREE", flag(self.select_tree)),
            ("GATHER_SPHERES", flag(self.spheres)),
            ("GATHER_SLOTS", f64::from(self.slots)),
        ]
    }

    /// The slot in `SparsePipelines::gather_variants`.
    fn variant(self) -> usize {
        let slots = match self.slots {
            16 => 2,
            8 => 1,
            _ => 0,
        };
        (self.glossy as usize
            | (self.visibility as usize) << 1
            | (self.select_tree as usize) << 2
            | (self.spheres as usize) << 3
            | slots << 4)
            + 48 * self.windows as usize
    }
}

/// `entry` of `shader` with its pipeline constants set, compiled into `slot` the first time
/// it is asked for.
fn specialized_once<'a>(
    slot: &'a std::sync::OnceLock<wgpu::ComputePipeline>,
    ctx: &GpuContext,
    label: &str,
    (shader, entry): (&str, &str),
    layouts: &[&wgpu::BindGroupLayout],
    constants: &[(&str, f64)],
) -> Result<&'a wgpu::ComputePipeline, GpuError> {
    if let Some(pipeline) = slot.get() {
        return Ok(pipeline);
    }
    let what = format!("a specialized {label} pipeline ({entry})");
    let pipeline = ctx.scoped(&what, None, crate::raster::PIPELINE_REMEDY, || {
        crate::gpu::compute_pipeline_groups(
            &ctx.device,
            label,
            &ctx.shader(shader),
            layouts,
            entry,
            constants,
        )
    })?;
    Ok(slot.get_or_init(|| pipeline))
}

/// The sparse passes' layouts and pipelines, compiled once per device and shared by every
/// solution on it (a preview's balls, a viewer's rebuilds, an eval sweep's settings): each
/// binds its own buffers. On lavapipe compiling them took ~300 ms of every method's set-up.
struct SparsePipelines {
    gather: (GroupLayout, wgpu::ComputePipeline),
    /// The gather without the code a solution does not run, built when first used and indexed
    /// by [`GatherCode::variant`]: the glossy lobes (`GLOSSY_GATHER` false), the cluster
    /// visibility (`GATHER_VISIBILITY` false), the other visibility lookup, the light spheres'
    /// moments (`GATHER_SPHERES` false), the other way of reading the VALs. `gather` is
    /// [`GatherCode::full`].
    gather_variants: [std::sync::OnceLock<wgpu::ComputePipeline>; 96],
    gather_reduce: wgpu::ComputePipeline,
    partials: GroupLayout,
    /// The window form's group 2 ([`val_windows::WINDOW_BINDINGS`]).
    window: GroupLayout,
    renormalize: (GroupLayout, wgpu::ComputePipeline),
    /// The bounds kernel's discs stage (`cs_main`); `occluder_stages` are its tiles and
    /// internal-node stages (`cs_tiles`, `cs_nodes`), on the same layout.
    occluder_bounds: (GroupLayout, wgpu::ComputePipeline),
    occluder_stages: [wgpu::ComputePipeline; 2],
    occlusion: (GroupLayout, wgpu::ComputePipeline),
    interpolate: (GroupLayout, wgpu::ComputePipeline),
    /// Group 1 is the scene BVH's ([`SceneBvh::layout`]), group 2 a depth sensor's.
    visibility: (GroupLayout, wgpu::ComputePipeline),
    /// The visibility pass without the depth sensor's code (`SENSOR_RAYS` false), for the
    /// solutions without a sensor, built when first used.
    visibility_no_sensor: std::sync::OnceLock<wgpu::ComputePipeline>,
    sensor: GroupLayout,
    /// Group 2 for solutions without a sensor: no tiles, no frame.
    no_sensor: wgpu::BindGroup,
    apply: (GroupLayout, wgpu::RenderPipeline),
}

impl SparsePipelines {
    fn shared(ctx: &GpuContext) -> Result<std::sync::Arc<Self>, GpuError> {
        ctx.shared(|| Self::new(ctx))
    }

    /// The compute gather compiled with the code `code` runs and no more.
    fn gather_pipeline(
        &self,
        ctx: &GpuContext,
        code: GatherCode,
    ) -> Result<&wgpu::ComputePipeline, GpuError> {
        if code == GatherCode::full(ctx) {
            return Ok(&self.gather.1);
        }
        specialized_once(
            &self.gather_variants[code.variant()],
            ctx,
            "gather",
            ("vals_gather.wgsl", code.entry()),
            &Self::gather_groups(&self.gather.0, &self.partials, &self.window, code.windows),
            &code.constants(),
        )
    }

    /// The gather's groups: its bindings, the partial sums, and for the window form the
    /// window.
    fn gather_groups<'a>(
        gather: &'a GroupLayout,
        partials: &'a GroupLayout,
        window: &'a GroupLayout,
        windows: bool,
    ) -> Vec<&'a wgpu::BindGroupLayout> {
        let all = [&gather.layout, &partials.layout, &window.layout];
        all[..if windows { 3 } else { 2 }].to_vec()
    }

    fn visibility_without_sensor(
        &self,
        ctx: &GpuContext,
    ) -> Result<&wgpu::ComputePipeline, GpuError> {
        specialized_once(
            &self.visibility_no_sensor,
            ctx,
            "visibility",
            ("vals_visibility.wgsl", "cs_main"),
            &[
                &self.visibility.0.layout,
                &SceneBvh::layout(ctx).layout,
                &self.sensor.layout,
            ],
            &[("SENSOR_RAYS", 0.0)],
        )
    }

    fn new(ctx: &GpuContext) -> Result<Self, GpuError> {
        let device = &ctx.device;
        let cs = wgpu::ShaderStages::COMPUTE;
        let entry_point = |name: &'static str,
                           module: &wgpu::ShaderModule,
                           groups: &[&wgpu::BindGroupLayout],
                           entry: &str|
         -> Result<wgpu::ComputePipeline, GpuError> {
            ctx.scoped(
                &format!("the {name} pipeline ({entry})"),
                None,
                crate::raster::PIPELINE_REMEDY,
                || compute_pipeline_groups(device, name, module, groups, entry, &[]),
            )
        };
        let compute = |name: &'static str,
                       shader: &str,
                       groups: &[&wgpu::BindGroupLayout]|
         -> Result<wgpu::ComputePipeline, GpuError> {
            entry_point(name, &ctx.shader(shader), groups, "cs_main")
        };
        let kernel = |name: &'static str, shader: &str, slots: &'static [Slot]| {
            let layout = GroupLayout::new(device, name, cs, slots);
            let pipeline = compute(name, shader, &[&layout.layout])?;
            Ok::<_, GpuError>((layout, pipeline))
        };
        let partials = GroupLayout::new(device, "gather partials", cs, &[W]);
        // The raster gather binds the gather's group in a fragment shader.
        let gather_layout = GroupLayout::new(
            device,
            "gather",
            cs | wgpu::ShaderStages::FRAGMENT,
            GATHER_BINDINGS,
        );
        let window = val_windows::layout(device, cs);
        let groups = [&gather_layout.layout, &partials.layout];
        let full = GatherCode::full(ctx);
        let gather = ctx.scoped(
            &format!("the gather pipeline ({})", full.entry()),
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                let shader = ctx.shader("vals_gather.wgsl");
                let constants = full.constants();
                let layouts = Self::gather_groups(&gather_layout, &partials, &window, full.windows);
                let pipeline = crate::gpu::compute_pipeline_groups;
                pipeline(
                    device,
                    "gather",
                    &shader,
                    &layouts,
                    full.entry(),
                    &constants,
                )
            },
        )?;
        let gather_reduce = compute("gather reduce", "vals_gather_reduce.wgsl", &groups)?;
        let bvh = SceneBvh::layout(ctx);
        let visibility_layout = GroupLayout::new(device, "visibility", cs, VISIBILITY_BINDINGS);
        let sensor = GroupLayout::new(device, "visibility sensor", cs, SENSOR_BINDINGS);
        let visibility = compute(
            "visibility",
            "vals_visibility.wgsl",
            &[&visibility_layout.layout, &bvh.layout, &sensor.layout],
        )?;
        let no_sensor = {
            use wgpu::util::DeviceExt;
            let zeros = |label: &str, size: usize, usage: wgpu::BufferUsages| {
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: &vec![0u8; size],
                    usage,
                })
            };
            let params = zeros(
                "no sensor",
                std::mem::size_of::<crate::light::sensor::SensorParams>(),
                wgpu::BufferUsages::UNIFORM,
            );
            let storage = wgpu::BufferUsages::STORAGE;
            let depth = zeros("no sensor depth", 16, storage);
            let samples = zeros(
                "no sensor samples",
                std::mem::size_of::<crate::light::rsm::GpuVal>(),
                storage,
            );
            sensor.bind(device, &[&params, &depth, &samples])
        };
        // Apply: a raster pass over the scene, depth-tested Equal against the G-buffer.
        let vs_fs = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let apply_layout = GroupLayout::new(device, "apply", vs_fs, APPLY_BINDINGS);
        let apply_module = ctx.shader("vals_apply.wgsl");
        let apply_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("apply"),
                bind_group_layouts: &[Some(&apply_layout.layout)],
                immediate_size: 0,
            });
        let apply = ScenePipeline {
            label: "apply",
            module: &apply_module,
            layout: &apply_pipeline_layout,
            vertex: POSITION_ONLY,
            // Equal against the G-buffer's depth (both vertex stages are @invariant): each
            // pixel is shaded once, by the surface the G-buffer holds.
            depth_write: false,
            depth_compare: wgpu::CompareFunction::Equal,
            depth_bias: wgpu::DepthBiasState::default(),
            targets: &[RADIANCE_FORMAT],
        }
        .build(device);
        // One module, three entry points on one layout.
        let occluder_layout =
            GroupLayout::new(device, "occluder bounds", cs, OCCLUDER_BOUNDS_BINDINGS);
        let occluder_module = ctx.shader("vals_occluder_bounds.wgsl");
        let occluder_stage = |entry: &str| {
            entry_point(
                "occluder bounds",
                &occluder_module,
                &[&occluder_layout.layout],
                entry,
            )
        };
        let occluder_stages = [occluder_stage("cs_tiles")?, occluder_stage("cs_nodes")?];
        let occluder_discs = occluder_stage("cs_main")?;
        let occluder_bounds = (occluder_layout, occluder_discs);
        Ok(Self {
            gather: (gather_layout, gather),
            gather_variants: std::array::from_fn(|_| std::sync::OnceLock::new()),
            gather_reduce,
            partials,
            window,
            renormalize: kernel("renormalize", "vals_renormalize.wgsl", RENORMALIZE_BINDINGS)?,
            occluder_stages,
            occluder_bounds,
            occlusion: kernel("occlusion", "vals_occlusion.wgsl", OCCLUSION_BINDINGS)?,
            interpolate: kernel(
                "interpolation",
                "vals_interpolate.wgsl",
                INTERPOLATE_BINDINGS,
            )?,
            visibility: (visibility_layout, visibility),
            sensor,
            no_sensor,
            visibility_no_sensor: Default::default(),
            apply: (apply_layout, apply),
        })
    }
}

/// One compute pass of the solution: pipeline, layout, and the buffers after the parameter
/// block in binding order.
struct Kernel {
    label: &'static str,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    buffers: Vec<wgpu::Buffer>,
    /// Bound to the solution's own parameter block.
    group: Option<wgpu::BindGroup>,
}

impl Kernel {
    fn bind(&self, device: &wgpu::Device, params: &wgpu::Buffer) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = std::iter::once(params)
            .chain(&self.buffers)
            .enumerate()
            .map(|(i, b)| buffer_binding(i as u32, b))
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.layout,
            entries: &entries,
        })
    }
}

/// The solution kernels bound to one view's parameter block.
pub struct KernelGroups([wgpu::BindGroup; 4]);

/// Which passes a frame runs; tests stop early to read intermediate buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Stage {
    Gather,
    Renormalize,
    Occlusion,
    Interpolate,
    Apply,
}

impl SparseGpu {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        (scene_gpu, mesh_bvhs): (&SceneGpu, Arc<MeshBvhs>),
        points: &[Arc<MeshPoints>],
        rsm: &Rsm,
        sensor: Option<&SensorBuffers>,
    ) -> Result<Self, RenderError> {
        let (vals_buffer, val_count_buffer) = (&rsm.vals_buffer, &rsm.val_count_buffer);
        let device = &ctx.device;
        let limits = device.limits();
        // Static model-space data, flattened over instances.
        let mut points_model = Vec::new();
        let mut points_meta = Vec::new();
        let mut point_instances = Vec::new();
        let mut ranges = Vec::with_capacity(scene.instances.len());
        let mut link_offsets = Vec::with_capacity(scene.meshes.len());
        let mut links = Vec::<[u32; 4]>::new();
        let mut vertex_model = Vec::<[u32; 4]>::new();
        for (mesh, mesh_points) in scene.meshes.iter().zip(points) {
            if mesh_points.positions.len() > u16::MAX as usize + 1 {
                return Err(RenderError::Settings(format!(
                    "mesh '{}' got {} sparse points; links address at most 65536 per mesh: lower --sparse-points",
                    mesh.name,
                    mesh_points.positions.len()
                )));
            }
            link_offsets.push((links.len() / 2) as u32);
            // Each link row's vertex in model space (a two-sided sheet's back rows with the
            // normal flipped), for the interpolation's renormalization at the vertex.
            let n = mesh.positions.len().max(1);
            for row in 0..mesh_points.links.len() {
                let (position, normal) = (
                    mesh.positions.get(row % n).copied().unwrap_or_default(),
                    mesh.normals.get(row % n).copied().unwrap_or_default(),
                );
                let normal = if row >= n { -normal } else { normal };
                vertex_model.push([
                    position.x.to_bits(),
                    position.y.to_bits(),
                    position.z.to_bits(),
                    oct_encode(normal),
                ]);
            }
            for row in &mesh_points.links {
                let packed: Vec<u32> = row
                    .iter()
                    .map(|l| {
                        let w = (l.weight.clamp(0.0, 1.0) * 65535.0).round() as u32;
                        (l.point & 0xffff) | (w << 16)
                    })
                    .collect();
                debug_assert_eq!(packed.len(), LINKS);
                links.push([packed[0], packed[1], packed[2], packed[3]]);
                links.push([packed[4], packed[5], packed[6], packed[7]]);
            }
        }
        let mut vertex_offset = 0u32;
        for (instance_index, instance) in scene.instances.iter().enumerate() {
            let mesh = &scene.meshes[instance.mesh];
            let mesh_points = &points[instance.mesh];
            let material = scene
                .materials
                .get(mesh.material)
                .cloned()
                .unwrap_or_default();
            let k = Material::phong_exponent(material.roughness);
            // A two-sided sheet has a link row per vertex and face (`points::two_sided`).
            let n = mesh.positions.len() as u32;
            let two_sided = mesh_points.links.len() as u32 == 2 * n && n > 0;
            let lit_vertices = if two_sided { 2 * n } else { n };
            ranges.push(InstanceRange {
                vertex_offset,
                vertex_count: lit_vertices,
                point_offset: points_model.len() as u32,
                link_offset: link_offsets[instance.mesh],
                back_offset: if two_sided { n } else { 0 },
            });
            vertex_offset += lit_vertices;
            for ((p, n), r) in mesh_points
                .positions
                .iter()
                .zip(&mesh_points.normals)
                .zip(&mesh_points.disc_radius)
            {
                points_model.push([p.x.to_bits(), p.y.to_bits(), p.z.to_bits(), oct_encode(*n)]);
                points_meta.push([pack_half2(k, *r), instance_index as u32]);
                point_instances.push(instance_index);
            }
        }
        let point_count = points_model.len() as u32;
        let vertex_count = vertex_offset;
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let vertex_light_size = vertex_count.max(1) as u64 * 48;
        if vertex_light_size > max_binding {
            return Err(RenderError::Settings(format!(
                "scene '{}' has {vertex_count} instance vertices needing {vertex_light_size} bytes of vertex lights; the device binds at most {max_binding}",
                scene.name
            )));
        }

        let mut bytes = GpuBytes::default();
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let readable = storage | wgpu::BufferUsages::COPY_SRC;
        let init = |bytes: &mut GpuBytes, label: &str, data: &[u8]| {
            let dummy = [0u8; 16];
            bytes.buffer_init(
                device,
                label,
                if data.is_empty() { &dummy } else { data },
                readable,
            )
        };
        let points_model_buffer = init(
            &mut bytes,
            "points model",
            bytemuck::cast_slice(&points_model),
        );
        let points_meta_buffer = init(
            &mut bytes,
            "points meta",
            bytemuck::cast_slice(&points_meta),
        );
        let empty = |bytes: &mut GpuBytes, label: &str, size: u64| {
            bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some(label),
                    size: size.max(16),
                    usage: readable,
                    mapped_at_creation: false,
                },
            )
        };
        let n = point_count as u64;
        let points_remedy = "Lower --sparse-points";
        ctx.check_storage_buffer(
            &format!("the sparse points' cluster visibility ({point_count} points)"),
            n * VISIBILITY_BYTES_PER_POINT,
            points_remedy,
        )?;
        ctx.check_storage_buffer(
            &format!("the vertex links ({} rows)", links.len()),
            (links.len() * 16) as u64,
            "Use a coarser tessellation (--max-edge) or a smaller scene",
        )?;
        let point_buffers_bytes = n * (16 + 16 + 8 + 2 * VISIBILITY_BYTES_PER_POINT);
        let (point_diffuse, point_glossy, point_extra, visibility_buffer, visibility_history) = ctx
            .scoped(
                &format!("the sparse point buffers ({point_count} points)"),
                Some(point_buffers_bytes),
                points_remedy,
                || {
                    (
                        empty(&mut bytes, "point diffuse", n * 16),
                        empty(&mut bytes, "point glossy", n * 16),
                        empty(&mut bytes, "point extra", n * 8),
                        // One byte per (point, cluster): the VAL clusters' visibility
                        // (`--occlusion rays`).
                        empty(
                            &mut bytes,
                            "point cluster visibility",
                            n * VISIBILITY_BYTES_PER_POINT,
                        ),
                        empty(
                            &mut bytes,
                            "point cluster visibility history",
                            n * VISIBILITY_BYTES_PER_POINT,
                        ),
                    )
                },
            )?;
        let point_bytes = bytes.0;
        let ranges_buffer = init(&mut bytes, "instance ranges", bytemuck::cast_slice(&ranges));
        let links_buffer = init(&mut bytes, "vertex links", bytemuck::cast_slice(&links));
        let vertex_model_buffer = init(
            &mut bytes,
            "link vertices",
            bytemuck::cast_slice(&vertex_model),
        );
        let link_bytes = (links.len() * 16 + vertex_model.len() * 16) as u64;
        let vertex_lights = ctx.scoped(
            &format!("the vertex lights ({vertex_count} instance vertices)"),
            Some(vertex_light_size),
            "Use a coarser tessellation (--max-edge) or fewer instances",
            || empty(&mut bytes, "vertex lights", vertex_light_size),
        )?;
        let clamp_buffer = empty(&mut bytes, "renormalize clamps", 8);
        let params_buffer = bytes.params::<SparseParams>(device, "sparse params");

        let pipelines = SparsePipelines::shared(ctx)?;
        let val_windows = ValWindows::new(ctx, rsm, &pipelines.window);
        let instances = &scene_gpu.instance_buffer;
        // One kernel per pass: the device's pipeline and layout for it, and this solution's
        // buffers after the parameter block in the binding order of its slot list: every
        // kernel reads the instances and the points first, then `list`.
        let kernel = |name: &'static str,
                      (layout, pipeline): &(GroupLayout, wgpu::ComputePipeline),
                      list: &[&wgpu::Buffer]| {
            let buffers: Vec<wgpu::Buffer> = [instances, &points_model_buffer, &points_meta_buffer]
                .into_iter()
                .chain(list.iter().copied())
                .cloned()
                .collect();
            debug_assert_eq!(buffers.len() + 1, layout.slot_count(), "{name}: bindings");
            let mut kernel = Kernel {
                label: name,
                pipeline: pipeline.clone(),
                layout: layout.layout.clone(),
                buffers,
                group: None,
            };
            kernel.group = Some(kernel.bind(device, &params_buffer));
            kernel
        };
        let lights = [&point_diffuse, &point_glossy, &point_extra];
        let gather = kernel(
            "gather",
            &pipelines.gather,
            &[
                vals_buffer,
                val_count_buffer,
                lights[0],
                lights[1],
                lights[2],
                &visibility_buffer,
            ],
        );
        let renormalize = kernel(
            "renormalize",
            &pipelines.renormalize,
            &[&lights[..], &[&clamp_buffer]].concat(),
        );
        // The most nodes: one tile per point.
        let most_nodes: u32 = occlusion_levels(point_count.max(1), 1).iter().sum();
        let occluder_bounds = empty(
            &mut bytes,
            "occluder bounds",
            16 * OCCLUDER_BOUNDS_VEC4S as u64 * most_nodes as u64,
        );
        // Every point's disc in world space (centre, radius; normal), in walk order.
        let occluder_discs = empty(&mut bytes, "occluder discs", 32 * point_count.max(1) as u64);
        // The walk order: the points' Morton order where the scene first stands, so that a
        // tile of the walk is a compact patch across instances as within a mesh. Instances
        // that move later keep their places (the bounds follow them; only culling loosens).
        let world = scene.world_from_node();
        let centres: Vec<Vec3> = points_model
            .iter()
            .zip(&point_instances)
            .map(|(model, &instance)| {
                world[scene.instances[instance].node].transform_point3(model_position(model))
            })
            .collect();
        let occluder_walk = super::math::walk_order(&centres);
        let occluder_walk_buffer = init(
            &mut bytes,
            "occluder walk",
            bytemuck::cast_slice(&occluder_walk),
        );
        let occluder_bounds_kernel = kernel(
            "occluder bounds",
            &pipelines.occluder_bounds,
            &[&occluder_bounds, &occluder_discs, &occluder_walk_buffer],
        );
        let occlusion = kernel(
            "occlusion",
            &pipelines.occlusion,
            &[&lights[..], &[&occluder_bounds, &occluder_discs]].concat(),
        );
        let interpolate = kernel(
            "interpolation",
            &pipelines.interpolate,
            &[
                &lights[..],
                &[
                    &ranges_buffer,
                    &links_buffer,
                    &vertex_model_buffer,
                    &vertex_lights,
                ],
            ]
            .concat(),
        );

        // Visibility: group 0 its buffers, group 1 the scene's BVH.
        let bvh = SceneBvh::over(ctx, scene, mesh_bvhs)?;
        bytes.add(GpuBytes(bvh.bytes.0));
        let val_texels = ValTexels::new(ctx, vals_buffer)?;
        bytes.add(GpuBytes(val_texels.bytes));
        let sensor_group = match sensor {
            Some(sensor) => pipelines
                .sensor
                .bind(device, &[&sensor.params, &sensor.depth, &sensor.samples]),
            None => pipelines.no_sensor.clone(),
        };
        let visibility_group = pipelines.visibility.0.bind(
            device,
            &[
                &params_buffer,
                instances,
                &points_model_buffer,
                &points_meta_buffer,
                &val_texels.texture.create_view(&Default::default()),
                &rsm.cluster_samples,
                &visibility_buffer,
                &visibility_history,
            ],
        );

        Ok(Self {
            point_count,
            vertex_count,
            instance_count: ranges.len() as u32,
            max_groups_per_dimension: limits.max_compute_workgroups_per_dimension,
            point_bytes,
            vertex_light_bytes: vertex_light_size,
            link_bytes,
            bytes,
            params_buffer,
            points_model,
            points_meta,
            point_instances,
            points_model_buffer,
            points_meta_buffer,
            point_diffuse,
            point_glossy,
            point_extra,
            clamp_buffer,
            vertex_lights,
            ranges_buffer,
            gather,
            max_binding,
            partials: std::cell::RefCell::new(None),
            val_windows,
            val_capacity: vals_buffer.size()
                / std::mem::size_of::<crate::light::rsm::GpuVal>() as u64,
            cpu_device: ctx.adapter_info.device_type == wgpu::DeviceType::Cpu,
            reflects_glossily: crate::light::reflects_glossily(scene),
            raster_gather: std::cell::OnceCell::new(),
            renormalize,
            occlusion,
            occluder_bounds: occluder_bounds_kernel,
            occluder_walk,
            interpolate,
            bvh,
            visibility_buffer,
            val_texels,
            visibility_history,
            solutions_recorded: std::cell::Cell::new(0),
            pipelines,
            visibility_group,
            sensor_group,
            rsm_tiles: rsm.tile_count(),
            sensor_tiles: sensor.map_or(0, |s| s.tiles * s.tiles),
            has_sensor: sensor.is_some(),
        })
    }

    /// The raster gather, built the first time a frame asks for it: a full-target triangle
    /// over `RASTER_GATHER_WIDTH × ⌈points / width⌉` texels.
    fn raster_gather(&self, ctx: &GpuContext) -> Result<&RasterGather, GpuError> {
        if let Some(raster) = self.raster_gather.get() {
            return Ok(raster);
        }
        let device = &ctx.device;
        let width = RASTER_GATHER_WIDTH.min(self.point_count.max(1));
        let height = self.point_count.div_ceil(RASTER_GATHER_WIDTH).max(1);
        const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
        let target = ctx.scoped(
            "the raster gather's point target",
            Some(u64::from(width) * u64::from(height)),
            "use the compute gather (--gather compute) or fewer --sparse-points",
            || {
                // Built lazily behind `&self`: its few kilobytes are not in the solution's
                // byte count.
                crate::gpu::GpuBytes::default().texture_2d(
                    device,
                    "raster gather target",
                    (width, height),
                    FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT,
                )
            },
        )?;
        let module = ctx.shader("vals_gather_raster.wgsl");
        let pipeline = ctx.scoped(
            "the raster gather pipeline",
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                // The sums go to the storage buffers; the colour is not kept.
                crate::raster::fullscreen_pipeline(
                    device,
                    "raster gather",
                    &module,
                    &self.gather.layout,
                    FORMAT,
                    wgpu::ColorWrites::empty(),
                )
            },
        )?;
        let raster = RasterGather {
            pipeline,
            target: target.create_view(&Default::default()),
        };
        Ok(self.raster_gather.get_or_init(|| raster))
    }

    /// Points per compute-gather invocation under `options` on this device for this point
    /// count.
    pub fn gather_points_per_invocation(&self, options: &SparseOptions) -> u32 {
        gather_points_per_invocation(
            options.gather_points,
            self.cpu_device,
            self.gathers_in_windows(options),
            self.point_count,
            cpu_device_threads(),
        )
    }

    /// Whether the compute gather looks visibility up through the select tree (else a switch).
    pub fn visibility_select_tree(&self, options: &SparseOptions) -> bool {
        options.visibility_lookup.select_tree(self.cpu_device)
    }

    /// Whether the compute gather reads the VALs in uniform windows under `options` on this
    /// device ([`ValReads`]).
    pub fn gathers_in_windows(&self, options: &SparseOptions) -> bool {
        options.gather_vals.windows(
            self.cpu_device,
            self.val_windows.is_some(),
            options.gather_slices,
        )
    }

    /// The VAL slices the compute gather runs as under `options` on this device (1 when it
    /// reads windows).
    pub fn gather_slices(&self, options: &SparseOptions) -> u32 {
        if self.gathers_in_windows(options) {
            return 1;
        }
        gather_slices(
            options.gather_slices,
            self.cpu_device,
            self.point_count,
            self.gather_points_per_invocation(options),
            self.val_capacity,
            options.tile,
            self.max_binding,
        )
    }

    /// Whether `other` binds to the same compiled pipelines (one device's).
    pub fn shares_pipelines_with(&self, other: &SparseGpu) -> bool {
        std::sync::Arc::ptr_eq(&self.pipelines, &other.pipelines)
    }

    /// Bytes of the gather's partial sums as last recorded (a split gather's slices or the
    /// window form's running sums; 0 for neither).
    pub fn gather_partial_bytes(&self) -> u64 {
        match &*self.partials.borrow() {
            Some((bytes, buffer, _)) if *bytes > 16 => buffer.size(),
            _ => 0,
        }
    }

    /// The partial sums' group for `slices` slices, or with `windows` one (a 16-byte
    /// placeholder for an unsplit tile gather), made again only when the size changes.
    fn partials_for(
        &self,
        ctx: &GpuContext,
        slices: u32,
        windows: bool,
    ) -> Result<wgpu::BindGroup, GpuError> {
        let size = if slices > 1 || windows {
            u64::from(slices) * u64::from(self.point_count) * GATHER_PARTIAL_VEC4S * 16
        } else {
            16
        };
        if let Some((held, _, group)) = &*self.partials.borrow() {
            if *held == size {
                return Ok(group.clone());
            }
        }
        let buffer = ctx.scoped(
            &format!("the gather's partial sums ({slices} slices)"),
            Some(size),
            "use fewer --gather-slices",
            || {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("gather partials"),
                    size,
                    usage: wgpu::BufferUsages::STORAGE,
                    mapped_at_creation: false,
                })
            },
        )?;
        let group = self.pipelines.partials.bind(&ctx.device, &[&buffer]);
        *self.partials.borrow_mut() = Some((size, buffer, group.clone()));
        Ok(group)
    }

    /// The point buffers a debug view draws (with the scene's instance matrices).
    pub fn debug_points<'a>(
        &'a self,
        scene_gpu: &'a crate::raster::scene_gpu::SceneGpu,
    ) -> crate::frame::DebugPointSource<'a> {
        crate::frame::DebugPointSource {
            instances: &scene_gpu.instance_buffer,
            points_model: &self.points_model_buffer,
            points_meta: &self.points_meta_buffer,
            point_diffuse: &self.point_diffuse,
            point_glossy: &self.point_glossy,
            point_extra: &self.point_extra,
            count: self.point_count,
        }
    }

    /// Places the BVH's instances for this frame (rays of `--occlusion rays`).
    pub fn prepare_bvh(&mut self, ctx: &GpuContext, scene: &Scene, world_from_node: &[Mat4]) {
        self.bvh.update(ctx, scene, world_from_node);
    }

    /// The scene BVH the visibility rays trace (its CPU twin answers the same queries).
    pub fn bvh(&self) -> &SceneBvh {
        &self.bvh
    }

    /// The per-(point, cluster) visibility of the last recorded frame, V·255 per byte.
    /// The occlusion tree's bounds of the last frame that ran the pass, as
    /// [`super::math::OccluderBounds`] per level: tiles (`tile` discs of the walk order
    /// each), then each internal level up to the root.
    pub fn read_occluder_bounds(
        &self,
        ctx: &GpuContext,
        tile: u32,
    ) -> Result<Vec<Vec<super::math::OccluderBounds>>, GpuError> {
        let buffer = &self.occluder_bounds.buffers[3];
        let raw: Vec<[f32; 4]> = crate::gpu::read_buffer(ctx, buffer)?;
        let mut all = raw
            .chunks_exact(OCCLUDER_BOUNDS_VEC4S as usize)
            .map(|slot| super::math::OccluderBounds {
                center: Vec3::new(slot[0][0], slot[0][1], slot[0][2]),
                radius: slot[0][3],
                half_extent: Vec3::new(slot[1][0], slot[1][1], slot[1][2]),
                max_disc_radius: slot[1][3],
            });
        Ok(occlusion_levels(self.point_count, tile)
            .iter()
            .map(|&n| all.by_ref().take(n as usize).collect())
            .collect())
    }

    /// Each point's place in the occlusion pass's walk order
    /// ([`super::math::walk_order`], fixed when the solution is built).
    pub fn occluder_walk(&self) -> &[u32] {
        &self.occluder_walk
    }

    pub fn read_visibility(&self, ctx: &GpuContext) -> Result<Vec<u8>, GpuError> {
        let words: Vec<u32> = crate::gpu::read_buffer(ctx, &self.visibility_buffer)?;
        Ok(bytemuck::cast_slice(&words).to_vec())
    }

    /// The parameter block for `eye` and the options (`glossy_only`: the per-view glossy
    /// re-run).
    /// Whether `options` gather glossy light in this scene.
    pub fn gathers_glossy(&self, options: &SparseOptions) -> bool {
        options.glossy.gathers(self.reflects_glossily)
    }

    /// Whether the gather sums the second position moments, which size the light spheres of
    /// the disc occlusion (`sum`, `union`): the compute gather leaves them out for other
    /// solutions; the raster form keeps one build. Either way the spheres are written only
    /// for those modes.
    pub fn gathers_spheres(&self, options: &SparseOptions) -> bool {
        options.gather == GatherForm::Raster
            || matches!(options.occlusion, OcclusionMode::Sum | OcclusionMode::Union)
    }

    pub fn params(&self, eye: Vec3, options: &SparseOptions, glossy_only: bool) -> SparseParams {
        let mut flags = 0;
        if self.gathers_glossy(options) {
            flags |= FLAG_GLOSSY;
        }
        if options.occlusion == OcclusionMode::Rays {
            flags |= FLAG_VISIBILITY;
        }
        if options.adaptive_rays {
            flags |= FLAG_ADAPTIVE_RAYS;
        }
        if options.weights == Weights::Flux {
            flags |= FLAG_FLUX_WEIGHTS;
        }
        if glossy_only {
            flags |= FLAG_GLOSSY_ONLY;
        }
        SparseParams {
            eye: eye.extend(1.0).to_array(),
            point_count: self.point_count,
            instance_count: self.instance_count,
            flags,
            occlusion_mode: match options.occlusion {
                OcclusionMode::Off | OcclusionMode::Rays => 0,
                OcclusionMode::Sum => 1,
                OcclusionMode::Union => 2,
            },
            tile: options.tile,
            vertex_count: self.vertex_count,
            rsm_tiles: self.rsm_tiles,
            visibility_history: if self.solutions_recorded.get() > 0 {
                options.visibility_history
            } else {
                0
            },
        }
    }

    /// Uploads this frame's parameters: the solution eye for the glossy lobes and the options.
    pub fn prepare(&self, ctx: &GpuContext, eye: Vec3, options: &SparseOptions) {
        let params = self.params(eye, options, false);
        ctx.queue
            .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&params));
    }

    /// Bind groups of the four solution kernels over another parameter block (a view's).
    pub fn bind_kernels(&self, device: &wgpu::Device, params: &wgpu::Buffer) -> KernelGroups {
        KernelGroups([
            self.gather.bind(device, params),
            self.renormalize.bind(device, params),
            self.occlusion.bind(device, params),
            self.interpolate.bind(device, params),
        ])
    }

    /// Records the view-free sparse passes up to and including `last` (at most
    /// interpolation): the solution every view reads.
    pub fn record_solution(
        &self,
        passes: &mut Passes,
        options: &SparseOptions,
        last: Stage,
    ) -> Result<(), GpuError> {
        passes.encoder().clear_buffer(&self.clamp_buffer, 0, None);
        if options.occlusion == OcclusionMode::Rays && self.point_count > 0 {
            passes.encoder().copy_buffer_to_buffer(
                &self.visibility_buffer,
                0,
                &self.visibility_history,
                0,
                None,
            );
            passes
                .encoder()
                .clear_buffer(&self.visibility_buffer, 0, None);
            self.val_texels.record_copy(passes.encoder());
            self.solutions_recorded
                .set(self.solutions_recorded.get() + 1);
            let clusters = (self.rsm_tiles + self.sensor_tiles).clamp(1, MAX_CLUSTERS);
            let (x, chunks) = linear_groups(
                self.point_count.div_ceil(POINT_GROUP),
                self.max_groups_per_dimension,
            );
            let pipeline = if self.has_sensor {
                &self.pipelines.visibility.1
            } else {
                self.pipelines.visibility_without_sensor(passes.ctx())?
            };
            passes.compute("visibility", |pass| {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, &self.visibility_group, &[]);
                pass.set_bind_group(1, &self.bvh.group, &[]);
                pass.set_bind_group(2, &self.sensor_group, &[]);
                pass.dispatch_workgroups(x, clusters, chunks);
            })?;
        }
        let groups = [
            self.gather.group.as_ref(),
            self.renormalize.group.as_ref(),
            self.occlusion.group.as_ref(),
            self.interpolate.group.as_ref(),
        ]
        .map(|g| g.expect("kernels are bound at creation"));
        self.record_kernels(passes, options, last, groups)
    }

    /// The glossy half of the solution again, for one view's eye (`--glossy-eye per-view`):
    /// the kernels run with that view's parameter block, whose glossy-only flag leaves the
    /// diffuse half as the update left it.
    pub fn record_view_glossy(
        &self,
        passes: &mut Passes,
        options: &SparseOptions,
        groups: &KernelGroups,
    ) -> Result<(), GpuError> {
        let [g, r, o, i] = &groups.0;
        self.record_kernels(passes, options, Stage::Interpolate, [g, r, o, i])
    }

    fn record_kernels(
        &self,
        passes: &mut Passes,
        options: &SparseOptions,
        last: Stage,
        [gather, renormalize, occlusion, interpolate]: [&wgpu::BindGroup; 4],
    ) -> Result<(), GpuError> {
        let points = self.point_count.div_ceil(POINT_GROUP);
        let max_groups = self.max_groups_per_dimension;
        let compute = |passes: &mut Passes, kernel: &Kernel, group: &wgpu::BindGroup, n: u32| {
            if n == 0 {
                // No points or no vertices (a scene without faces): nothing to do, and the
                // placeholder buffers bound in their place are smaller than one element.
                return Ok(());
            }
            let (x, y) = linear_groups(n, max_groups);
            passes.compute(kernel.label, |pass| {
                pass.set_pipeline(&kernel.pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(x, y, 1);
            })
        };
        match options.gather {
            GatherForm::Compute if self.point_count > 0 => {
                let slices = self.gather_slices(options);
                let windows = self
                    .val_windows
                    .as_ref()
                    .filter(|_| self.gathers_in_windows(options));
                let partials = self.partials_for(passes.ctx(), slices, windows.is_some())?;
                let code = GatherCode {
                    glossy: self.gathers_glossy(options),
                    visibility: options.occlusion == OcclusionMode::Rays,
                    select_tree: self.visibility_select_tree(options),
                    spheres: self.gathers_spheres(options),
                    slots: self.gather_points_per_invocation(options),
                    windows: windows.is_some(),
                };
                let group = gather_workgroup_invocations(code.windows);
                let (x, y) =
                    linear_groups(self.point_count.div_ceil(group * code.slots), max_groups);
                let pipeline = if code == GatherCode::full(passes.ctx()) {
                    &self.gather.pipeline
                } else {
                    self.pipelines.gather_pipeline(passes.ctx(), code)?
                };
                passes.compute(self.gather.label, |pass| {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, gather, &[]);
                    pass.set_bind_group(1, &partials, &[]);
                    match windows {
                        Some(windows) => windows.for_each(pass, 2, |pass| {
                            pass.dispatch_workgroups(x, y, 1);
                        }),
                        None => pass.dispatch_workgroups(x, y, slices),
                    }
                })?;
                if slices > 1 {
                    let (x, y) = linear_groups(points, max_groups);
                    passes.compute("gather reduce", |pass| {
                        pass.set_pipeline(&self.pipelines.gather_reduce);
                        pass.set_bind_group(0, gather, &[]);
                        pass.set_bind_group(1, &partials, &[]);
                        pass.dispatch_workgroups(x, y, 1);
                    })?;
                }
            }
            GatherForm::Compute => {}
            GatherForm::Raster if self.point_count > 0 => {
                let raster = self.raster_gather(passes.ctx())?;
                passes.render(
                    self.gather.label,
                    &[Some(wgpu::RenderPassColorAttachment {
                        view: &raster.target,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                            store: wgpu::StoreOp::Discard,
                        },
                    })],
                    None,
                    |pass| {
                        pass.set_pipeline(&raster.pipeline);
                        pass.set_bind_group(0, gather, &[]);
                        pass.draw(0..3, 0..1);
                    },
                )?
            }
            GatherForm::Raster => {}
        }
        if last >= Stage::Renormalize {
            compute(passes, &self.renormalize, renormalize, points)?;
        }
        let disc_occlusion = matches!(options.occlusion, OcclusionMode::Sum | OcclusionMode::Union);
        if last >= Stage::Occlusion && disc_occlusion && self.point_count > 0 {
            let levels = occlusion_levels(self.point_count, options.tile);
            let own = self
                .occluder_bounds
                .group
                .as_ref()
                .expect("bound at creation");
            // The discs in walk order, the tiles' bounds from them, then every internal node's
            // from its tiles: three dispatches, each reading what the one before wrote.
            let internal: u32 = levels[1..].iter().sum();
            let stages = [
                (&self.occluder_bounds.pipeline, self.point_count),
                (&self.pipelines.occluder_stages[0], levels[0]),
                (&self.pipelines.occluder_stages[1], internal),
            ];
            passes.compute(self.occluder_bounds.label, |pass| {
                pass.set_bind_group(0, own, &[]);
                for (pipeline, n) in stages {
                    if n == 0 {
                        continue;
                    }
                    let (x, y) = linear_groups(n.div_ceil(POINT_GROUP), max_groups);
                    pass.set_pipeline(pipeline);
                    pass.dispatch_workgroups(x, y, 1);
                }
            })?;
            compute(passes, &self.occlusion, occlusion, points)?;
        }
        if last >= Stage::Interpolate {
            compute(
                passes,
                &self.interpolate,
                interpolate,
                self.vertex_count.div_ceil(POINT_GROUP),
            )?;
        }
        Ok(())
    }

    /// The apply pass of one view: each pixel evaluates its vertices' interpolated lights
    /// with its own normal, drawn into `indirect` (cleared first; `RADIANCE_FORMAT` at the
    /// view's render resolution).
    pub fn record_apply(
        &self,
        ctx: &GpuContext,
        passes: &mut Passes,
        scene_gpu: &SceneGpu,
        view: &View,
        indirect: &wgpu::TextureView,
    ) -> Result<(), GpuError> {
        let targets = &view.targets;
        let group = self.pipelines.apply.0.bind(
            &ctx.device,
            &[
                &view.frame_buffer,
                &scene_gpu.instance_buffer,
                &self.ranges_buffer,
                &self.vertex_lights,
                &targets.normal,
                &targets.diffuse,
                &targets.specular,
                &self.params_buffer,
            ],
        );
        passes.render(
            "apply",
            &[cleared(indirect)],
            Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            |pass| {
                pass.set_pipeline(&self.pipelines.apply.1);
                pass.set_bind_group(0, &group, &[]);
                scene_gpu.draw(pass, None);
            },
        )
    }

    /// The sparse points in world space for the given transforms, decoded like the shaders.
    pub fn decoded_points(&self, scene: &Scene, world_from_node: &[Mat4]) -> Vec<DecodedPoint> {
        self.points_model
            .iter()
            .zip(&self.points_meta)
            .zip(&self.point_instances)
            .map(|((model, meta), &instance)| {
                let world = world_from_node[scene.instances[instance].node];
                let p = model_position(model);
                let normal_from_model = Mat3::from_mat4(world).inverse().transpose();
                let (k, disc_radius) = unpack_half2(meta[0]);
                DecodedPoint {
                    position: world.transform_point3(p),
                    normal: (normal_from_model * oct_decode(model[3])).normalize(),
                    k,
                    disc_radius,
                }
            })
            .collect()
    }

    /// Reads the per-point buffers after the last recorded frame.
    pub fn read_points(
        &self,
        ctx: &GpuContext,
        scene: &Scene,
        world_from_node: &[Mat4],
    ) -> Result<PointsReadback, GpuError> {
        let points = self.decoded_points(scene, world_from_node);
        let d: Vec<[u32; 4]> = crate::gpu::read_buffer(ctx, &self.point_diffuse)?;
        let s: Vec<[u32; 4]> = crate::gpu::read_buffer(ctx, &self.point_glossy)?;
        let e: Vec<[u32; 2]> = crate::gpu::read_buffer(ctx, &self.point_extra)?;
        let mut lights = Vec::with_capacity(points.len());
        let mut spheres = Vec::with_capacity(points.len());
        for (i, point) in points.iter().enumerate() {
            let rgb = |v: &[u32; 4]| {
                Vec3::new(
                    f32::from_bits(v[0]),
                    f32::from_bits(v[1]),
                    f32::from_bits(v[2]),
                )
            };
            let (dx, dy) = unpack_half2(d[i][3]);
            let (sx, sy) = unpack_half2(s[i][3]);
            let (dz, sz) = unpack_half2(e[i][0]);
            lights.push(PointLights {
                diffuse_position: point.position + Vec3::new(dx, dy, dz),
                diffuse: rgb(&d[i]),
                glossy_position: point.position + Vec3::new(sx, sy, sz),
                glossy: rgb(&s[i]),
            });
            spheres.push(unpack_half2(e[i][1]));
        }
        Ok(PointsReadback {
            points,
            lights,
            spheres,
        })
    }

    /// The interpolated lights of every instance vertex.
    pub fn read_vertex_lights(&self, ctx: &GpuContext) -> Result<Vec<PointLights>, GpuError> {
        let raw: Vec<[f32; 12]> = crate::gpu::read_buffer(ctx, &self.vertex_lights)?;
        Ok(raw
            .iter()
            .take(self.vertex_count as usize)
            .map(|v| PointLights {
                diffuse_position: Vec3::new(v[0], v[1], v[2]),
                diffuse: Vec3::new(v[3], v[4], v[5]),
                glossy_position: Vec3::new(v[6], v[7], v[8]),
                glossy: Vec3::new(v[9], v[10], v[11]),
            })
            .collect())
    }

    /// How many points clamped their (diffuse, glossy) renormalization last frame.
    pub fn read_clamps(&self, ctx: &GpuContext) -> Result<(u32, u32), GpuError> {
        let c: Vec<u32> = crate::gpu::read_buffer(ctx, &self.clamp_buffer)?;
        Ok((
            c.first().copied().unwrap_or(0),
            c.get(1).copied().unwrap_or(0),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MIB64: u64 = 64 << 20;

    #[test]
    fn a_cpu_device_takes_the_points_per_invocation_that_balance_its_threads() {
        let tiles = |points, threads| gather_points_per_invocation(0, true, false, points, threads);
        let windows =
            |points, threads| gather_points_per_invocation(0, true, true, points, threads);
        // A GPU keeps the four it was measured with, whatever the count and the form.
        assert_eq!(gather_points_per_invocation(0, false, false, 1 << 16, 2), 4);
        assert_eq!(gather_points_per_invocation(0, false, true, 1 << 16, 2), 4);
        // Tiles, two threads: 16 points an invocation while there are two workgroups of 1024.
        assert_eq!(tiles(4096, 2), 16);
        assert_eq!(tiles(2048, 2), 16);
        assert_eq!(tiles(1025, 2), 16);
        assert_eq!(tiles(1024, 2), 8);
        assert_eq!(tiles(513, 2), 8);
        assert_eq!(tiles(512, 2), 4);
        // More threads want more workgroups.
        assert_eq!(tiles(4096, 16), 4);
        // Windows, two threads, workgroups of 16 invocations (256 points at 16 an invocation):
        // rounds × (points + 2) keeps 16 (4096: 8 rounds × 18 against 16 × 10 and 32 × 6) ...
        assert_eq!(windows(4096, 2), 16);
        assert_eq!(windows(16384, 2), 16);
        // ... and Sponza's 4215 and the door room's 4422 points too, now that the last round
        // is one small workgroup (9 × 18 against 17 × 10 and 18 × 10); with workgroups of 64
        // they took 8 (nine of 512 against five of 1024, three rounds with a thread idle).
        assert_eq!(windows(4215, 2), 16);
        assert_eq!(windows(4422, 2), 16);
        assert_eq!(windows(1024, 2), 16);
        // One workgroup would idle the second thread.
        assert_eq!(windows(256, 2), 8);
        // Equal estimates go to the most points (2049: 5 × 18 = 9 × 10).
        assert_eq!(windows(2049, 2), 16);
        // Sixteen threads: one round of sixteen workgroups.
        assert_eq!(windows(4096, 16), 16);
        assert_eq!(windows(1024, 16), 4);
        // An explicit choice stands; anything else is automatic.
        assert_eq!(gather_points_per_invocation(16, false, false, 64, 2), 16);
        assert_eq!(gather_points_per_invocation(8, true, true, 1 << 16, 2), 8);
        assert_eq!(gather_points_per_invocation(5, true, false, 4096, 2), 16);
    }

    #[test]
    fn the_automatic_split_fills_a_gpu_and_leaves_a_cpu_device_whole() {
        // A CPU device: whole, whatever the sizes.
        assert_eq!(gather_slices(0, true, 4096, 4, 16384, 128, MIB64), 1);
        // 4096 points are 16 workgroups: 64 slices reach the 1024-workgroup target.
        assert_eq!(gather_slices(0, false, 4096, 4, 16384, 128, MIB64), 64);
        // Each slice keeps at least one tile: 1000 VALs at 128 a tile give 8.
        assert_eq!(gather_slices(0, false, 4096, 4, 1000, 128, MIB64), 8);
        // Enough points alone: whole.
        assert_eq!(gather_slices(0, false, 1 << 20, 4, 1 << 20, 128, MIB64), 1);
        // 1024 points of a sensor frame: the slice cap.
        assert_eq!(
            gather_slices(0, false, 1024, 4, 300_000, 128, MIB64),
            GATHER_SLICES_MAX
        );
    }

    #[test]
    fn requests_are_capped_by_the_partial_sums_bytes() {
        assert_eq!(gather_slices(7, true, 4096, 4, 16384, 128, MIB64), 7);
        assert_eq!(
            gather_slices(1000, false, 16, 4, 16384, 128, MIB64),
            GATHER_SLICES_MAX
        );
        // 65536 points × 80 B = 5 MiB a slice: 12 fit in 64 MiB, 3 in a 16 MiB binding.
        assert_eq!(gather_slices(100, false, 65536, 4, 1 << 20, 128, MIB64), 12);
        assert_eq!(
            gather_slices(100, false, 65536, 4, 1 << 20, 128, 16 << 20),
            3
        );
        // Not even one slice fits: whole, which needs no partial sums.
        assert_eq!(gather_slices(0, false, 1 << 20, 4, 16384, 128, 1 << 20), 1);
    }
}
