//! Reflective shadow maps → virtual area lights (DESIGN §4). Every light renders an R×R RSM
//! (a spot light one perspective layer, a point light six cube faces that tile the sphere
//! exactly, a directional light an orthographic layer fitted to the scene); a compute pass then
//! compacts every lit texel of every layer, in texel order, into one storage buffer of
//! [`GpuVal`] records (deterministic: the same VAL list every run).
//! Later passes (the sparse gather, brute force, LPV injection) read `vals_buffer` and the
//! count in `val_count_buffer`.

use bytemuck::{Pod, Zeroable};
use glam::Mat4;

use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{GpuBytes, GpuContext, GpuError, Passes};
use crate::raster::scene_gpu::SceneGpu;
use crate::raster::shadows::setup_lights;
use crate::raster::types::{GpuLight, Vertex};
use crate::raster::{cleared, Rasterizer, RenderError, ScenePipeline, DEPTH_FORMAT};
use crate::scene::{Aabb, Scene};

use super::{ExternalVals, Val};

/// One VAL as the shaders store it (`Val` in `shaders/vals/vals_common.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GpuVal {
    /// xyz: world position; w: area A (m²).
    pub position_area: [f32; 4],
    pub normal: [f32; 4],
    /// rgb: reflected flux Φ (W).
    pub flux: [f32; 4],
}

impl GpuVal {
    pub fn from_val(val: &Val) -> Self {
        Self {
            position_area: val.position.extend(val.area).to_array(),
            normal: val.normal.extend(0.0).to_array(),
            flux: val.flux.extend(0.0).to_array(),
        }
    }

    pub fn to_val(&self) -> Val {
        Val {
            position: glam::Vec4::from(self.position_area).truncate(),
            normal: glam::Vec4::from(self.normal).truncate(),
            flux: glam::Vec4::from(self.flux).truncate(),
            area: self.position_area[3],
        }
    }

    /// The VAL's cluster (`flux.w`, see [`texel_cluster`]).
    pub fn cluster(&self) -> u32 {
        self.flux[3] as u32
    }
}

/// `RsmView` in `shaders/light/vals_rsm.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RsmView {
    pub clip_from_world: [[f32; 4]; 4],
    pub light_index: u32,
    pub resolution: u32,
    /// tan(fov/2) of a perspective view; 0 for orthographic.
    pub tan_half_fov: f32,
    /// World area of one texel of an orthographic view.
    pub texel_area: f32,
    /// Top-left texel of the view's tile in its physical layer ([`Rsm::physical_texel`]).
    pub tile_origin: [u32; 2],
    pub _pad: [u32; 2],
}

/// `RsmSize` in `shaders/light/vals_from_rsm.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RsmSize {
    /// Rows of all views together (Σ sides).
    pub rows: u32,
    pub views: u32,
    pub capacity: u32,
    /// Cluster tiles per view side ([`cluster_tiles`]).
    pub tiles: u32,
}

/// The most VAL clusters a frame has: visibility is kept per (sparse point, cluster), one
/// byte each.
pub const MAX_CLUSTERS: u32 = 32;

/// The cluster id (`flux.w`) of VALs from no RSM tile (appended external VALs): the gather
/// gives them no cluster visibility.
pub const UNCLUSTERED: u32 = MAX_CLUSTERS;

/// Clusters the tiling aims at (at most [`MAX_CLUSTERS`]). 16 clusters of 8×8 samples
/// (2.6× the rays) measured the same error and the same flicker on `cornell-moving` as 25
/// of 4×4, at several times the cost.
pub const CLUSTER_BUDGET: u32 = 32;

/// Samples per cluster tile side: each tile has `CLUSTER_SAMPLE_SIDE²` strata whose centre
/// texels are the VALs visibility rays are shot at.
pub const CLUSTER_SAMPLE_SIDE: u32 = 4;

/// Cluster tiles per layer side: as many as [`MAX_CLUSTERS`] allows over all layers (a spot
/// light's one layer is cut 5×5, a point light's six layers 2×2), and at least one sample
/// stratum a texel wide.
pub fn cluster_tiles(resolution: u32, layers: u32) -> u32 {
    cluster_tiles_within(resolution, layers, CLUSTER_BUDGET)
}

/// [`cluster_tiles`] with `budget` clusters for the RSM (the rest go to external VALs'
/// clusters, [`ExternalVals::cluster_tiles`]).
pub fn cluster_tiles_within(resolution: u32, layers: u32, budget: u32) -> u32 {
    let by_budget = ((budget / layers.max(1)) as f32).sqrt().floor() as u32;
    by_budget.clamp(1, (resolution / CLUSTER_SAMPLE_SIDE).max(1))
}

/// The cluster of a texel: its tile over all layers, folded into [`MAX_CLUSTERS`] when the
/// lights have more layers than that (then one cluster holds several whole layers).
pub fn texel_cluster(resolution: u32, tiles: u32, layer: u32, x: u32, y: u32) -> u32 {
    (layer_tile(resolution, tiles, layer, x, y)) % MAX_CLUSTERS
}

/// A texel's tile over all layers: `layer·T² + ty·T + tx`.
pub fn layer_tile(resolution: u32, tiles: u32, layer: u32, x: u32, y: u32) -> u32 {
    let tx = x * tiles / resolution;
    let ty = y * tiles / resolution;
    layer * tiles * tiles + ty * tiles + tx
}

/// The RSM side every view gets under `max_vals`: the requested one, or the largest whose
/// `views · side²` texels fit (`None` when not even one texel per view does).
pub fn budget_resolution(requested: u32, views: u32, max_vals: u32) -> Option<u32> {
    if views == 0 {
        return Some(requested);
    }
    let fit = ((max_vals as f64 / views as f64).sqrt().floor() as u32).min(requested);
    // The float root can land one off near perfect squares; settle it in integers.
    let fits = |side: u32| views as u64 * side as u64 * side as u64 <= max_vals as u64;
    let side = (fit.saturating_sub(1)..=(fit + 1).min(requested))
        .rev()
        .find(|&side| fits(side))?;
    (side > 0).then_some(side)
}

/// VALs per uniform window of the VAL buffer: 48 KiB, a multiple of the 256-byte offset
/// alignment and under the 64 KiB a uniform binding may hold. The buffer is padded to whole
/// windows ([`Rsm::val_windows`]) so that a kernel can bind any window at a dynamic offset
/// and read it as a uniform block (`light::val_windows`, `val_windows.wgsl`), which a CPU device
/// reads far faster than the same VALs from storage or workgroup memory when every
/// invocation reads the same one (`src/vals/README.md`, "How lavapipe loads memory").
pub const VAL_WINDOW: u64 = 1024;

/// Most RSM VALs the VAL buffer holds beside `external_slots` external VALs when the device
/// binds at most `max_binding` bytes (the buffer is bound whole); `None` when not even the
/// external VALs fit.
pub fn binding_val_fit(max_binding: u64, external_slots: u64) -> Option<u32> {
    let slots = max_binding / std::mem::size_of::<GpuVal>() as u64;
    slots
        .checked_sub(external_slots)
        .map(|fit| fit.min(u32::MAX as u64) as u32)
}

/// Views of at most this side take the exact texel solid angle ([`texel_solid_angle`]).
pub const EXACT_SOLID_ANGLE_SIDE: u32 = 16;

/// Solid angle of texel (x, y) of a `side`² perspective view with tan(fov/2) = `t`, as the RSM
/// pass computes it (`texel_solid_angle` in `vals_rsm.wgsl`): the integral of
/// (1+u²+v²)^{-3/2} over the texel's square on the unit image plane — exact from its corners
/// for small views (the centre rule would give a 2² cube face 4 % too much, a 1² face 91 %),
/// by 2×2 Gauss points for larger ones (where differences of corner terms cancel in f32).
pub fn texel_solid_angle(x: u32, y: u32, side: u32, t: f32) -> f32 {
    let delta = 2.0 * t / side as f32;
    let (u0, v0) = (-t + x as f32 * delta, t - (y + 1) as f32 * delta);
    let (u1, v1) = (u0 + delta, v0 + delta);
    if side <= EXACT_SOLID_ANGLE_SIDE {
        let corner = |u: f32, v: f32| (u * v / (1.0 + u * u + v * v).sqrt()).atan();
        return (corner(u1, v1) - corner(u0, v1) - corner(u1, v0) + corner(u0, v0)).abs();
    }
    let (uc, vc) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
    let g = delta / (2.0 * 3f32.sqrt());
    let sum: f32 = [(-g, -g), (g, -g), (-g, g), (g, g)]
        .iter()
        .map(|&(du, dv)| {
            let q = 1.0 + (uc + du).powi(2) + (vc + dv).powi(2);
            1.0 / (q * q.sqrt())
        })
        .sum();
    0.25 * sum * delta * delta
}

/// One light's claim on the VAL budget: its views (six for a cube) and its power in watts
/// (luminance-weighted; `f32::INFINITY` for a sun, whose RSM covers the whole scene).
#[derive(Clone, Copy, Debug)]
pub struct SideRequest {
    pub views: u32,
    pub power: f32,
}

/// Each light's RSM side under `max_vals` VALs in all (`None` when not even one texel per
/// view fits).
///
/// While every light fits at `requested`, every light gets it. Otherwise the VALs are shared
/// in proportion to power: a light's side is the largest with `views·side² ≤ λ·power`, the
/// same λ for all, clamped to `1..=requested` and λ the largest that fits. So every VAL
/// carries about the same flux whatever light made it — a dim light is not sampled as finely
/// as a bright one, whose VALs would otherwise each carry more of the image's error. Suns
/// keep the largest side that fits beside one texel per view of every other light.
pub fn share_sides(requests: &[SideRequest], requested: u32, max_vals: u32) -> Option<Vec<u32>> {
    let texels = |views: u32, side: u32| views as u64 * side as u64 * side as u64;
    let total_views: u64 = requests.iter().map(|r| r.views as u64).sum();
    if total_views > max_vals as u64 {
        return None;
    }
    let all: u64 = requests.iter().map(|r| texels(r.views, requested)).sum();
    if all <= max_vals as u64 {
        return Some(vec![requested; requests.len()]);
    }
    let is_sun = |r: &SideRequest| r.power.is_infinite() && r.power > 0.0;
    let sun_views: u32 = requests.iter().filter(|r| is_sun(r)).map(|r| r.views).sum();
    let other_views = total_views - sun_views as u64;
    let sun_budget = (max_vals as u64 - other_views) as u32;
    let sun_side = budget_resolution(requested, sun_views, sun_budget)?;
    let budget = max_vals as u64 - texels(sun_views, sun_side);
    // Power per view: NaN and negative powers claim nothing beyond their one texel.
    let weight = |r: &SideRequest| {
        if r.power.is_finite() && r.power > 0.0 {
            r.power as f64 / r.views.max(1) as f64
        } else {
            0.0
        }
    };
    let side_at = |r: &SideRequest, lambda: f64| {
        if is_sun(r) {
            sun_side
        } else {
            ((lambda * weight(r)).sqrt().floor().min(requested as f64) as u32).max(1)
        }
    };
    let used = |lambda: f64| -> u64 {
        requests
            .iter()
            .map(|r| texels(r.views, side_at(r, lambda)))
            .sum()
    };
    // λ at which the weakest light with power reaches `requested`: past it nothing changes.
    let smallest_weight = requests
        .iter()
        .map(weight)
        .filter(|&w| w > 0.0)
        .fold(f64::INFINITY, f64::min);
    let mut hi = if smallest_weight.is_finite() {
        (requested as f64 + 1.0).powi(2) / smallest_weight
    } else {
        0.0
    };
    let mut lo = 0.0;
    if used(hi) <= budget {
        lo = hi;
    } else {
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if used(mid) <= budget {
                lo = mid;
            } else {
                hi = mid;
            }
        }
    }
    Some(requests.iter().map(|r| side_at(r, lo)).collect())
}

/// Where one RSM view lives in the texture arrays, and its rows in the compaction
/// (`RsmTile` in `shaders/light/vals_from_rsm.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RsmTile {
    /// Top-left texel in its physical layer.
    pub origin: [u32; 2],
    /// Physical array layer.
    pub layer: u32,
    /// Side in texels (the light's RSM resolution).
    pub side: u32,
    /// Index of the view's first row among all views' rows, in view order.
    pub first_row: u32,
    /// WGSL rounds the struct to its 8-byte alignment.
    pub _pad: u32,
}

/// The views' tiles in layers of `side`² texels.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RsmPacking {
    pub side: u32,
    pub layers: u32,
    /// Per view, in view order.
    pub tiles: Vec<RsmTile>,
}

/// Packs square views of the given sides into the fewest texels of texture array: layers of
/// side `k·largest` for the `k` whose shelf packing (views sorted large to small, rows left to
/// right) takes the least memory within `max_layers` and `max_side` (`None` when no `k` does).
/// Views of one side pack row-major, `k²` to a layer, with no hole before the last view; while
/// the views fit the array layers one to a layer, that is `k = 1`.
pub fn pack_views(sides: &[u32], max_layers: u32, max_side: u32) -> Option<RsmPacking> {
    let largest = sides.iter().copied().max().unwrap_or(1).max(1);
    let mut order: Vec<usize> = (0..sides.len()).collect();
    order.sort_by_key(|&v| std::cmp::Reverse(sides[v]));
    let shelf_pack = |layer_side: u32| -> Option<Vec<RsmTile>> {
        let mut tiles = vec![RsmTile::default(); sides.len()];
        let (mut layer, mut x, mut y, mut shelf) = (0u32, 0u32, 0u32, 0u32);
        for &v in &order {
            let s = sides[v].max(1);
            if x + s > layer_side {
                (x, y) = (0, y + shelf);
                shelf = 0;
            }
            if y + s > layer_side {
                (layer, x, y, shelf) = (layer + 1, 0, 0, 0);
            }
            if layer >= max_layers {
                return None;
            }
            tiles[v] = RsmTile {
                origin: [x, y],
                layer,
                side: s,
                ..Default::default()
            };
            x += s;
            shelf = shelf.max(s);
        }
        Some(tiles)
    };
    let mut best: Option<(u64, RsmPacking)> = None;
    for k in 1..=(max_side / largest).max(1) {
        let side = k * largest;
        if side > max_side {
            break;
        }
        let Some(mut tiles) = shelf_pack(side) else {
            continue;
        };
        let layers = tiles.iter().map(|t| t.layer + 1).max().unwrap_or(0);
        let texels = layers as u64 * side as u64 * side as u64;
        let mut first_row = 0;
        for t in &mut tiles {
            t.first_row = first_row;
            first_row += t.side;
        }
        if best.as_ref().is_none_or(|(b, _)| texels < *b) {
            best = Some((
                texels,
                RsmPacking {
                    side,
                    layers,
                    tiles,
                },
            ));
        }
        if layers <= 1 {
            // A larger layer only adds texels.
            break;
        }
    }
    best.map(|(_, packing)| packing)
}

/// The view whose rows include `row` (rows numbered over all views in view order): the
/// CPU twin of `view_of_row` in `vals_from_rsm.wgsl`.
pub fn view_of_row(tiles: &[RsmTile], row: u32) -> usize {
    tiles
        .partition_point(|t| t.first_row <= row)
        .saturating_sub(1)
}

/// Sample candidates per stratum: its centre texel, then its four corner texels. A stratum's
/// ray sample at a point is the first candidate whose VAL reaches the point
/// (`vals::visibility`). Where the centre lies on a surface facing away from the point (or in
/// its plane), a corner on another surface of the stratum stands in, so more of the light
/// that does reach the point is sampled. With centres alone, a cluster none of whose centres
/// reached a point counted as fully seen, though other texels of it lit the point: a thin
/// strip of floor at a tile's edge, behind a wall.
pub const SAMPLE_CANDIDATES: u32 = 5;

/// The role of coordinate `x` in its stratum along one axis: 1 the centre, 2 the first, 3 the
/// last texel, 0 none (with the stratum). Strata split the tile's texels (those with
/// `⌊x·T/R⌋ = t`) into `CLUSTER_SAMPLE_SIDE` spans; the centre wins where roles coincide.
fn stratum_role(resolution: u32, tiles: u32, x: u32) -> (u32, u32) {
    // Tile t holds the texels with ⌊x·T/R⌋ = t: from ⌈t·R/T⌉ to ⌈(t+1)·R/T⌉.
    let t = x * tiles / resolution;
    let x0 = (t * resolution).div_ceil(tiles);
    let x1 = ((t + 1) * resolution).div_ceil(tiles);
    let width = (x1 - x0).max(1);
    // The stratum whose span `[x0 + s·w/S, x0 + (s+1)·w/S)` holds x.
    let stratum = ((x - x0 + 1) * CLUSTER_SAMPLE_SIDE - 1) / width;
    let first = x0 + stratum * width / CLUSTER_SAMPLE_SIDE;
    let last = x0 + (stratum + 1) * width / CLUSTER_SAMPLE_SIDE - 1;
    let centre = x0 + (2 * stratum + 1) * width / (2 * CLUSTER_SAMPLE_SIDE);
    let role = if x == centre {
        1
    } else if x == first {
        2
    } else if x == last {
        3
    } else {
        0
    };
    (stratum, role)
}

/// Where texel (x, y) of a view writes itself as a sample candidate: its stratum
/// (`sy·CLUSTER_SAMPLE_SIDE + sx`) and candidate (0 the centre, 1–4 the corners: first/last
/// column, first/last row), or `None`. `sample_candidate` in `vals_from_rsm.wgsl` is the twin.
pub fn sample_candidate(resolution: u32, tiles: u32, x: u32, y: u32) -> Option<(u32, u32)> {
    let (sx, rx) = stratum_role(resolution, tiles, x);
    let (sy, ry) = stratum_role(resolution, tiles, y);
    let candidate = match (rx, ry) {
        (1, 1) => 0,
        (2 | 3, 2 | 3) => 1 + (rx - 2) + 2 * (ry - 2),
        _ => return None,
    };
    Some((sy * CLUSTER_SAMPLE_SIDE + sx, candidate))
}

const POSITION_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;
const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
const FLUX_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Float;

/// GPU bytes one RSM texel and its VAL slot take: position (16), normal (8), flux (16) and
/// depth (4) texels, and the 48-byte [`GpuVal`].
pub const BYTES_PER_VAL: u64 = 16 + 8 + 16 + 4 + std::mem::size_of::<GpuVal>() as u64;

/// Default `--max-vals`: a million VALs (about 90 MB of RSM and VAL storage); every scene
/// built in fits at the methods' default `rsm`.
pub const DEFAULT_MAX_VALS: u32 = 1 << 20;

/// RSM texels a scene's lights share when a VAL method is not given `--rsm`: one point light's
/// six views at the default side 128. One light keeps its full RSM; with several (a proxy per
/// emissive patch, a room of lamps) each gets a side by its power ([`share_sides`]), so the
/// VAL count, and with it the gather's time, follows the light there is, not the number of
/// lights: an emissive quad's eight proxies made 303 265 VALs at 128² each.
pub const DEFAULT_SHARED_TEXELS: u32 = 6 * 128 * 128;

/// The RSMs of every light and the VAL buffer made from them.
///
/// A *layer* here is one light view (six per point light) of its light's side² texels: every
/// light has `resolution` while all fit `--max-vals`, else a side by its power
/// ([`share_sides`]). The views are tiles in physical layers of the arrays ([`pack_views`]);
/// every texture read goes through [`Rsm::physical_texel`] (and its WGSL twin), so consumers
/// still think in views.
pub struct Rsm {
    /// The largest side of any view (the requested `--rsm` unless the budget shrank every
    /// light).
    pub resolution: u32,
    pub layer_count: u32,
    /// Per light, its views' side.
    pub light_sides: Vec<u32>,
    /// Per view, its tile.
    pub view_tiles: Vec<RsmTile>,
    /// Physical layers of the arrays, and their side.
    pub physical_layers: u32,
    pub physical_side: u32,
    /// Views in each physical layer (what one render pass draws).
    views_by_layer: Vec<Vec<usize>>,
    /// Capacity in RSM VALs (every texel of every layer).
    pub capacity: u32,
    /// Further slots after the RSM's for [`ExternalVals`] (0 without).
    pub external_capacity: u32,
    pub vals_buffer: wgpu::Buffer,
    /// Whether `vals_buffer` holds whole [`VAL_WINDOW`]s that a kernel may bind as uniform
    /// blocks (false only where the device's binding limits leave no room for the padding).
    pub val_windows: bool,
    /// One u32: how many VALs this frame produced.
    pub val_count_buffer: wgpu::Buffer,
    /// Cluster tiles per layer side ([`cluster_tiles`]); every VAL's `flux.w` holds its
    /// cluster.
    pub tiles: u32,
    /// Per tile over all layers and per stratum of its `CLUSTER_SAMPLE_SIDE²`,
    /// [`SAMPLE_CANDIDATES`] slots: 1 + the index of the VAL at the candidate texel, or 0
    /// where that texel is unlit.
    pub cluster_samples: wgpu::Buffer,
    pub bytes: GpuBytes,
    lights_buffer: wgpu::Buffer,
    layer_buffers: Vec<wgpu::Buffer>,
    layer_groups: Vec<wgpu::BindGroup>,
    /// Per layer: position, normal and flux attachment views.
    layer_views: Vec<[wgpu::TextureView; 3]>,
    depth_view: wgpu::TextureView,
    pipeline: wgpu::RenderPipeline,
    /// count_rows, scan_rows, write_rows of `vals_from_rsm.wgsl`.
    compact_pipelines: [wgpu::ComputePipeline; 3],
    compact_group: wgpu::BindGroup,
    mesh_bounds: Vec<Aabb>,
    /// Position/area, normal and flux of every layer, as 2-D arrays (read by techniques that
    /// sample the RSM itself rather than its VAL list).
    pub array_views: [wgpu::TextureView; 3],
    append: Option<Append>,
}

/// The passes of `vals_append.wgsl` bound to one [`ExternalVals`].
struct Append {
    /// count_rows, append_rows.
    pipelines: [wgpu::ComputePipeline; 2],
    group: wgpu::BindGroup,
    rows: u32,
}

/// Invocations per workgroup of the append passes (`@workgroup_size(64, 1, 1)`), one
/// workgroup per row of candidates.
pub const APPEND_GROUP: u32 = 64;

/// `vals_rsm.wgsl`: the layer's view, the instance transforms and the lights.
const VIEW_BINDINGS: &[Slot] = &[Slot::Uniform, Slot::Storage, Slot::Storage];

/// `vals_from_rsm.wgsl`: the RSM size, its position, normal and flux arrays, the VALs, their
/// count, the row offsets and the cluster samples it writes, and the views' tiles.
const COMPACT_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::TextureArray,
    Slot::TextureArray,
    Slot::TextureArray,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::Storage,
];

/// `vals_append.wgsl`: its size block, the external candidates, and the VALs, their count and
/// the per-row counts it writes.
const APPEND_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
];

/// RSM rows per workgroup of the compaction's count and write passes (`count_rows`,
/// `write_rows` in `vals_from_rsm.wgsl`).
pub const ROW_GROUP: u32 = 64;

/// Threads of the compaction's single scan workgroup (`scan_rows`; its `SCAN_GROUP`).
pub const SCAN_GROUP: u32 = 256;

/// `AppendSize` in `shaders/light/vals_append.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct AppendSize {
    pub rows: u32,
    pub row_length: u32,
    pub capacity: u32,
    /// The tile index of the candidates' tile 0 (after the RSM's tiles), or
    /// [`NO_EXTERNAL_TILES`]: the candidates are in no cluster.
    pub first_tile: u32,
}

/// `AppendSize::first_tile` of candidates without clusters.
pub const NO_EXTERNAL_TILES: u32 = u32::MAX;

impl Rsm {
    /// The VAL buffer and its GPU-side count, for a viewer's debug view: every slot, the
    /// external ones included (the drawer skips those past the count).
    pub fn debug_vals(&self) -> crate::frame::DebugValSource<'_> {
        crate::frame::DebugValSource {
            vals: &self.vals_buffer,
            val_count: &self.val_count_buffer,
            capacity: self.capacity.saturating_add(self.external_capacity),
        }
    }

    /// The RSMs of `scene`'s lights at `resolution` per view, drawn from `raster`'s scene
    /// upload and within its `max_vals`.
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        raster: &Rasterizer,
        resolution: u32,
    ) -> Result<Self, RenderError> {
        Self::with_external(ctx, scene, raster, resolution, None, None)
    }

    /// The RSMs, every view at most `requested_resolution`² and, with `shared_texels`, all
    /// views together at most that many texels (shared by power, [`DEFAULT_SHARED_TEXELS`]),
    /// with room after their VALs for `external`'s valid candidates, which [`Rsm::record`]
    /// appends every frame (see [`ExternalVals`]).
    pub fn with_external(
        ctx: &GpuContext,
        scene: &Scene,
        raster: &Rasterizer,
        requested_resolution: u32,
        shared_texels: Option<u32>,
        external: Option<&ExternalVals>,
    ) -> Result<Self, RenderError> {
        let scene_gpu = &raster.scene_gpu;
        let device = &ctx.device;
        let limits = device.limits();
        let external_slots = external.map_or(0, |e| e.rows as u64 * e.row_length as u64);
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let settings_budget = raster.settings.val_budget();
        let binding_fit = binding_val_fit(max_binding, external_slots).ok_or_else(|| {
            RenderError::Settings(format!(
                "{external_slots} external VALs need {} of VAL storage; the device binds at \
                 most {}: lower the external VALs (depth frame size or block size)",
                crate::gpu::format_bytes(external_slots * std::mem::size_of::<GpuVal>() as u64),
                crate::gpu::format_bytes(max_binding),
            ))
        })?;
        // The VAL buffer is bound whole: past what one binding holds, the RSMs share that
        // many VALs by power as they share --max-vals (the lights keep their power).
        let max_vals = settings_budget.min(binding_fit);
        let budget = if binding_fit < settings_budget {
            format!(
                "the {binding_fit} VALs one binding of the device holds ({} beside {external_slots} external VALs)",
                crate::gpu::format_bytes(max_binding)
            )
        } else {
            raster.settings.budget_name(
                &format!("--max-vals {}", raster.settings.max_vals),
                &format!("{max_vals} VALs"),
            )
        };
        if requested_resolution == 0 || requested_resolution > limits.max_texture_dimension_2d {
            return Err(RenderError::Settings(format!(
                "--rsm {requested_resolution}: the RSM resolution must be 1..={}",
                limits.max_texture_dimension_2d
            )));
        }
        let layer_count: u32 = scene.lights.iter().map(|l| l.kind.shadow_layers()).sum();
        let requests: Vec<SideRequest> = scene
            .lights
            .iter()
            .map(|light| SideRequest {
                views: light.kind.shadow_layers(),
                power: crate::raster::light_power(light),
            })
            .collect();
        let total_views: u32 = requests.iter().map(|r| r.views).sum();
        // The default share never asks for less than one texel a view: only a real budget
        // (--max-vals, the device's binding) refuses a scene.
        let shared_max = shared_texels.map_or(max_vals, |t| max_vals.min(t.max(total_views)));
        let light_sides =
            share_sides(&requests, requested_resolution, shared_max).ok_or_else(|| {
                let remedy = if binding_fit < settings_budget {
                    "use fewer lights".to_string()
                } else {
                    format!("raise --max-vals to at least {layer_count}")
                };
                RenderError::Settings(format!(
                    "{budget}: scene '{}' has {layer_count} light views ({}), so not even one VAL \
                     per view fits; {remedy}",
                    scene.name,
                    crate::gpu::count_of(scene.lights.len(), "light"),
                ))
            })?;
        let reduced = light_sides
            .iter()
            .filter(|&&side| side < requested_resolution)
            .count();
        let requested_texels: u64 = requests
            .iter()
            .map(|r| r.views as u64 * requested_resolution as u64 * requested_resolution as u64)
            .sum();
        let smallest = light_sides
            .iter()
            .min()
            .copied()
            .unwrap_or(requested_resolution);
        if reduced > 0 && requested_texels <= max_vals as u64 {
            // Only the default share shrank them: nothing the user set was overruled.
            log::info!(
                "scene '{}': {} share {shared_max} RSM texels by power (views {}²–{}²; \
                 --rsm {requested_resolution} gives every view {requested_resolution}²)",
                scene.name,
                crate::gpu::count_of(scene.lights.len(), "light"),
                smallest,
                light_sides
                    .iter()
                    .max()
                    .copied()
                    .unwrap_or(requested_resolution),
            );
        } else if reduced > 0 {
            log::warn!(
                "scene '{}': {layer_count} RSM views at --rsm {requested_resolution} would make \
                 {} VALs, over {budget}; {reduced} of {} get smaller RSMs by \
                 power (down to {}²; each VAL carries its share of the flux, so every light's \
                 power is unchanged)",
                scene.name,
                requested_texels,
                crate::gpu::count_of(scene.lights.len(), "light"),
                smallest,
            );
        }
        let view_sides: Vec<u32> = requests
            .iter()
            .zip(&light_sides)
            .flat_map(|(r, &side)| std::iter::repeat_n(side, r.views as usize))
            .collect();
        let resolution = view_sides
            .iter()
            .copied()
            .max()
            .unwrap_or(requested_resolution);
        let packing = pack_views(
            &view_sides,
            limits.max_texture_array_layers,
            limits.max_texture_dimension_2d,
        )
        .ok_or_else(|| {
            RenderError::Settings(format!(
                "scene '{}' needs {layer_count} RSM views of up to {resolution}²; the device's {} \
                 array layers of at most {}² cannot hold them: lower --rsm or --max-vals",
                scene.name, limits.max_texture_array_layers, limits.max_texture_dimension_2d
            ))
        })?;
        let physical_side = packing.side;
        let physical_layers = packing.layers;
        let mut views_by_layer = vec![Vec::new(); physical_layers as usize];
        for (view, tile) in packing.tiles.iter().enumerate() {
            views_by_layer[tile.layer as usize].push(view);
        }
        let rows: u64 = view_sides.iter().map(|&s| s as u64).sum();
        let texels: u64 = view_sides.iter().map(|&s| s as u64 * s as u64).sum();
        let slots = texels + external_slots;
        if slots > u32::MAX as u64 {
            return Err(RenderError::Settings(format!(
                "{texels} RSM VALs and {external_slots} external VALs exceed the 2³² VAL indices"
            )));
        }
        let val_bytes = slots.max(1) * std::mem::size_of::<GpuVal>() as u64;
        debug_assert!(val_bytes <= max_binding.max(std::mem::size_of::<GpuVal>() as u64));
        // Whole windows where the binding limit allows: the padding is never a VAL (every
        // reader stops at the count).
        let window_bytes = VAL_WINDOW * std::mem::size_of::<GpuVal>() as u64;
        let padded = val_bytes.next_multiple_of(window_bytes);
        // Dynamic offsets are u32.
        let windows = padded <= max_binding.min(u64::from(u32::MAX))
            && window_bytes <= limits.max_uniform_buffer_binding_size
            && window_bytes.is_multiple_of(u64::from(limits.min_uniform_buffer_offset_alignment));
        let val_bytes = if windows { padded } else { val_bytes };
        let mut bytes = GpuBytes::default();
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let vals_buffer = ctx.scoped(
            &format!("the VAL buffer ({slots} VALs)"),
            Some(val_bytes),
            "Lower --rsm, or use fewer lights or external VALs",
            || {
                bytes.buffer(
                    device,
                    &wgpu::BufferDescriptor {
                        label: Some("vals"),
                        size: val_bytes,
                        usage: storage | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::UNIFORM,
                        mapped_at_creation: false,
                    },
                )
            },
        )?;
        let val_count_buffer = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("val count"),
                size: 4,
                usage: storage | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            },
        );
        let lights_buffer = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("rsm lights"),
                size: (scene.lights.len().max(1) * std::mem::size_of::<GpuLight>()) as u64,
                usage: storage,
                mapped_at_creation: false,
            },
        );
        let layers = layer_count.max(1);
        let physical = physical_layers.max(1);
        let side = physical_side as u64 * physical_side as u64;
        let rsm_bytes = side
            * (physical as u64
                * [POSITION_FORMAT, NORMAL_FORMAT, FLUX_FORMAT]
                    .map(crate::gpu::resources::block_bytes)
                    .iter()
                    .sum::<u64>()
                + crate::gpu::resources::block_bytes(DEPTH_FORMAT));
        let (textures, depth) = ctx.scoped(
            &format!(
                "the RSMs of scene '{}' ({}: {layers} views of up to {resolution}×{resolution} in {physical} layers of {physical_side}²)",
                scene.name,
                crate::gpu::count_of(scene.lights.len(), "light")
            ),
            Some(rsm_bytes),
            "Lower --rsm or --max-vals (a point light takes six views) or use fewer lights",
            || {
                let mut array = |label: &str, format| {
                    bytes.texture(
                        device,
                        &wgpu::TextureDescriptor {
                            label: Some(label),
                            size: wgpu::Extent3d {
                                width: physical_side,
                                height: physical_side,
                                depth_or_array_layers: physical,
                            },
                            mip_level_count: 1,
                            sample_count: 1,
                            dimension: wgpu::TextureDimension::D2,
                            format,
                            usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                                | wgpu::TextureUsages::TEXTURE_BINDING,
                            view_formats: &[],
                        },
                    )
                };
                let textures = [
                    array("rsm position", POSITION_FORMAT),
                    array("rsm normal", NORMAL_FORMAT),
                    array("rsm flux", FLUX_FORMAT),
                ];
                let depth = bytes.texture_2d(
                    device,
                    "rsm depth",
                    (physical_side, physical_side),
                    DEPTH_FORMAT,
                    wgpu::TextureUsages::RENDER_ATTACHMENT,
                );
                (textures, depth)
            },
        )?;
        let depth_view = depth.create_view(&Default::default());
        let layer_views: Vec<[wgpu::TextureView; 3]> = (0..physical_layers)
            .map(|layer| {
                textures.each_ref().map(|t| {
                    t.create_view(&wgpu::TextureViewDescriptor {
                        label: Some("rsm layer"),
                        dimension: Some(wgpu::TextureViewDimension::D2),
                        base_array_layer: layer,
                        array_layer_count: Some(1),
                        ..Default::default()
                    })
                })
            })
            .collect();
        let array_views = textures.each_ref().map(|t| {
            t.create_view(&wgpu::TextureViewDescriptor {
                label: Some("rsm array"),
                dimension: Some(wgpu::TextureViewDimension::D2Array),
                ..Default::default()
            })
        });

        let vs_fs = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let view_bgl = GroupLayout::new(device, "rsm view", vs_fs, VIEW_BINDINGS);
        let layer_buffers: Vec<wgpu::Buffer> = (0..layer_count)
            .map(|_| bytes.uniform::<RsmView>(device, "rsm view"))
            .collect();
        let layer_groups = layer_buffers
            .iter()
            .map(|buffer| {
                view_bgl.bind(
                    device,
                    &[buffer, &scene_gpu.instance_buffer, &lights_buffer],
                )
            })
            .collect();
        let module = ctx.shader("vals_rsm.wgsl");
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("rsm"),
            bind_group_layouts: &[
                Some(&view_bgl.layout),
                Some(&scene_gpu.material_layout.layout),
            ],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2];
        let pipeline = ctx.scoped(
            "the RSM pipeline",
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                ScenePipeline {
                    label: "rsm",
                    module: &module,
                    layout: &layout,
                    vertex: wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<Vertex>() as u64,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes: &attributes,
                    },
                    depth_write: true,
                    depth_compare: wgpu::CompareFunction::Less,
                    depth_bias: wgpu::DepthBiasState::default(),
                    targets: &[POSITION_FORMAT, NORMAL_FORMAT, FLUX_FORMAT],
                }
                .build(device)
            },
        )?;

        let cs = wgpu::ShaderStages::COMPUTE;
        let compact_bgl = GroupLayout::new(device, "vals from rsm", cs, COMPACT_BINDINGS);
        let smallest = view_sides.iter().copied().min().unwrap_or(resolution);
        // External clusters come after the RSM's and take their share of the budget.
        let external_tiles = external.map_or(0, ExternalVals::cluster_tiles);
        let tiles = cluster_tiles_within(
            smallest,
            layer_count,
            CLUSTER_BUDGET.saturating_sub(external_tiles).max(1),
        );
        let cluster_samples = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("rsm cluster samples"),
                size: (layers as u64
                    * (tiles * tiles * CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE) as u64
                    * SAMPLE_CANDIDATES as u64
                    * 4)
                .max(4),
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            },
        );
        let capacity = texels.min(u32::MAX as u64) as u32;
        let size_buffer = bytes.buffer_init(
            device,
            "rsm size",
            bytemuck::bytes_of(&RsmSize {
                rows: rows as u32,
                views: layer_count,
                capacity,
                tiles,
            }),
            wgpu::BufferUsages::UNIFORM,
        );
        let row_offsets = bytes.buffer(
            device,
            &wgpu::BufferDescriptor {
                label: Some("rsm row offsets"),
                size: rows.max(1) * 4,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            },
        );
        let no_tiles = [RsmTile::default()];
        let tiles_buffer = bytes.buffer_init(
            device,
            "rsm view tiles",
            bytemuck::cast_slice(if packing.tiles.is_empty() {
                &no_tiles
            } else {
                &packing.tiles
            }),
            wgpu::BufferUsages::STORAGE,
        );
        let compact_group = compact_bgl.bind(
            device,
            &[
                &size_buffer,
                &array_views[0],
                &array_views[1],
                &array_views[2],
                &vals_buffer,
                &val_count_buffer,
                &row_offsets,
                &cluster_samples,
                &tiles_buffer,
            ],
        );
        let module = ctx.shader("vals_from_rsm.wgsl");
        let compact_pipelines = ctx.scoped(
            "the VAL compaction pipelines",
            None,
            crate::raster::PIPELINE_REMEDY,
            || {
                ["count_rows", "scan_rows", "write_rows"].map(|entry| {
                    crate::raster::compute_pipeline_at(
                        device,
                        entry,
                        &module,
                        &compact_bgl.layout,
                        entry,
                    )
                })
            },
        )?;
        let append = external.map(|e| {
            let bgl = GroupLayout::new(device, "vals append", cs, APPEND_BINDINGS);
            let size = bytes.buffer_init(
                device,
                "vals append size",
                bytemuck::bytes_of(&AppendSize {
                    rows: e.rows,
                    row_length: e.row_length,
                    capacity: slots as u32,
                    first_tile: if e.cluster_tiles() > 0 {
                        layer_count * tiles * tiles
                    } else {
                        NO_EXTERNAL_TILES
                    },
                }),
                wgpu::BufferUsages::UNIFORM,
            );
            let row_counts = bytes.buffer(
                device,
                &wgpu::BufferDescriptor {
                    label: Some("vals append rows"),
                    size: (e.rows as u64 + 1) * 4,
                    usage: wgpu::BufferUsages::STORAGE,
                    mapped_at_creation: false,
                },
            );
            let group = bgl.bind(
                device,
                &[
                    &size,
                    &e.candidates,
                    &vals_buffer,
                    &val_count_buffer,
                    &row_counts,
                ],
            );
            let module = ctx.shader("vals_append.wgsl");
            Append {
                pipelines: ["count_rows", "append_rows"].map(|entry| {
                    crate::raster::compute_pipeline_at(device, entry, &module, &bgl.layout, entry)
                }),
                group,
                rows: e.rows,
            }
        });
        Ok(Self {
            resolution,
            layer_count,
            light_sides,
            view_tiles: packing.tiles,
            physical_layers,
            physical_side,
            views_by_layer,
            capacity,
            external_capacity: external_slots as u32,
            val_windows: windows,
            vals_buffer,
            val_count_buffer,
            tiles,
            cluster_samples,
            bytes,
            lights_buffer,
            layer_buffers,
            layer_groups,
            layer_views,
            depth_view,
            pipeline,
            compact_pipelines,
            compact_group,
            mesh_bounds: scene.meshes.iter().map(|m| m.model_bounds()).collect(),
            array_views,
            append,
        })
    }

    /// Uploads this frame's light records and RSM views.
    pub fn prepare(&self, ctx: &GpuContext, scene: &Scene, world_from_node: &[Mat4]) {
        let setup = self.light_setup(scene, world_from_node);
        if !setup.lights.is_empty() {
            ctx.queue
                .write_buffer(&self.lights_buffer, 0, bytemuck::cast_slice(&setup.lights));
        }
        let mut layer = 0usize;
        for (light_index, light) in setup.lights.iter().enumerate() {
            let layers = if matches!(
                light.kind,
                crate::raster::types::LIGHT_POINT | crate::raster::types::LIGHT_EMITTER
            ) {
                6
            } else {
                1
            };
            for _ in 0..layers {
                let view = &setup.views[layer];
                let tile = &self.view_tiles[layer];
                let perspective = view.origin[3] > 0.5;
                let rsm_view = RsmView {
                    clip_from_world: view.clip_from_world,
                    light_index: light_index as u32,
                    resolution: tile.side,
                    tan_half_fov: if perspective {
                        0.5 * view.texel[0] * tile.side as f32
                    } else {
                        0.0
                    },
                    texel_area: if perspective {
                        0.0
                    } else {
                        view.texel[0] * view.texel[0]
                    },
                    tile_origin: tile.origin,
                    _pad: [0; 2],
                };
                ctx.queue.write_buffer(
                    &self.layer_buffers[layer],
                    0,
                    bytemuck::bytes_of(&rsm_view),
                );
                layer += 1;
            }
        }
    }

    /// This frame's light records and RSM layer views (layers in light order, six per point
    /// light), exactly as [`Rsm::prepare`] uploads them.
    pub fn light_setup(
        &self,
        scene: &Scene,
        world_from_node: &[Mat4],
    ) -> crate::raster::shadows::LightSetup {
        let bounds = scene.instance_bounds(&self.mesh_bounds, world_from_node);
        // No margin: cube faces must meet exactly so that no direction is counted twice.
        setup_lights(scene, world_from_node, &bounds, &self.light_sides, 0.0)
    }

    /// Renders every RSM layer and compacts the lit texels into VALs (passes "rsm"), then
    /// appends the external VALs' valid candidates (pass "vals append"); their producer must
    /// have recorded its passes before this.
    pub fn record(&self, passes: &mut Passes, scene_gpu: &SceneGpu) -> Result<(), GpuError> {
        self.record_maps(passes, scene_gpu)?;
        self.record_compaction(passes)
    }

    /// Renders every RSM layer (pass "rsm") and nothing else: for a consumer that reads
    /// the maps' texels itself and never the VAL list (seed 002's positive lights read N
    /// texels; the compaction walks every texel of every row, about 10 of the pass's ~55 ms
    /// on bunny-box at 256² on lavapipe).
    pub fn record_maps(&self, passes: &mut Passes, scene_gpu: &SceneGpu) -> Result<(), GpuError> {
        for (views, in_layer) in self.layer_views.iter().zip(&self.views_by_layer) {
            passes.render(
                "rsm",
                &[cleared(&views[0]), cleared(&views[1]), cleared(&views[2])],
                Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &self.depth_view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                |pass| {
                    pass.set_pipeline(&self.pipeline);
                    for &view in in_layer {
                        let tile = &self.view_tiles[view];
                        let ([x, y], r) = (tile.origin, tile.side);
                        pass.set_viewport(x as f32, y as f32, r as f32, r as f32, 0.0, 1.0);
                        pass.set_scissor_rect(x, y, r, r);
                        pass.set_bind_group(0, &self.layer_groups[view], &[]);
                        scene_gpu.draw(pass, Some(1));
                    }
                },
            )?;
        }
        Ok(())
    }

    /// The lit texels of the maps [`Rsm::record_maps`] rendered into the VAL list (passes
    /// "rsm"), then the external VALs' candidates appended (pass "vals append").
    fn record_compaction(&self, passes: &mut Passes) -> Result<(), GpuError> {
        if self.layer_count > 0 {
            // One thread per row; rows past 65535 workgroups wrap into a second dimension.
            let rows: u32 = self.view_tiles.iter().map(|t| t.side).sum();
            let groups = rows.div_ceil(ROW_GROUP);
            let (gx, gy) = crate::gpu::linear_groups(groups, 65535);
            passes
                .encoder()
                .clear_buffer(&self.cluster_samples, 0, None);
            let [count, scan, write] = &self.compact_pipelines;
            for (pipeline, (x, y)) in [(count, (gx, gy)), (scan, (1, 1)), (write, (gx, gy))] {
                passes.compute("rsm", |pass| {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, &self.compact_group, &[]);
                    pass.dispatch_workgroups(x, y, 1);
                })?;
            }
        } else {
            passes
                .encoder()
                .clear_buffer(&self.val_count_buffer, 0, None);
        }
        if let Some(append) = self.append.as_ref().filter(|a| a.rows > 0) {
            let max_groups = passes
                .ctx()
                .device
                .limits()
                .max_compute_workgroups_per_dimension;
            for pipeline in &append.pipelines {
                passes.compute("vals append", |pass| {
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(0, &append.group, &[]);
                    let (x, y) = crate::gpu::linear_groups(append.rows, max_groups);
                    pass.dispatch_workgroups(x, y, 1);
                })?;
            }
        }
        Ok(())
    }

    /// The VALs of the last recorded frame.
    pub fn read_vals(&self, ctx: &GpuContext) -> Result<Vec<Val>, GpuError> {
        let count = self
            .read_count(ctx)?
            .min(self.capacity.saturating_add(self.external_capacity)) as usize;
        let all: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.vals_buffer)?;
        Ok(all[..count.min(all.len())]
            .iter()
            .map(GpuVal::to_val)
            .collect())
    }

    /// The VALs of the last recorded frame as the GPU holds them (with their clusters).
    pub fn read_gpu_vals(&self, ctx: &GpuContext) -> Result<Vec<GpuVal>, GpuError> {
        let count = self.read_count(ctx)?.min(self.capacity) as usize;
        let mut all: Vec<GpuVal> = crate::gpu::read_buffer(ctx, &self.vals_buffer)?;
        all.truncate(count);
        Ok(all)
    }

    /// The cluster sample slots of the last recorded frame (see [`Rsm::cluster_samples`]).
    pub fn read_cluster_samples(&self, ctx: &GpuContext) -> Result<Vec<u32>, GpuError> {
        crate::gpu::read_buffer(ctx, &self.cluster_samples)
    }

    /// Where texel (x, y) of view `layer` lives: (physical layer, x, y) (`rsm_texel` in
    /// `vals_from_rsm.wgsl` is the WGSL twin).
    pub fn physical_texel(&self, layer: u32, x: u32, y: u32) -> (u32, u32, u32) {
        let tile = &self.view_tiles[layer as usize];
        (tile.layer, tile.origin[0] + x, tile.origin[1] + y)
    }

    /// Tiles over all layers (each with `CLUSTER_SAMPLE_SIDE²` sample slots).
    pub fn tile_count(&self) -> u32 {
        self.layer_count * self.tiles * self.tiles
    }

    pub fn read_count(&self, ctx: &GpuContext) -> Result<u32, GpuError> {
        let count: Vec<u32> = crate::gpu::read_buffer(ctx, &self.val_count_buffer)?;
        Ok(count.first().copied().unwrap_or(0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_binding_holds_whole_vals_after_the_external_ones() {
        let val = std::mem::size_of::<GpuVal>() as u64;
        assert_eq!(binding_val_fit(200 * val, 0), Some(200));
        assert_eq!(binding_val_fit(200 * val + val - 1, 50), Some(150));
        assert_eq!(binding_val_fit(200 * val, 200), Some(0));
        assert_eq!(binding_val_fit(200 * val, 201), None);
        assert_eq!(binding_val_fit(u64::MAX, 0), Some(u32::MAX));
    }

    #[test]
    fn every_stratum_has_one_centre_and_four_distinct_corner_candidates() {
        // A 128² view in 5×5 tiles: tiles 25–26 texels, strata 6–7.
        let (resolution, tiles) = (128, 5);
        let mut found = std::collections::HashMap::new();
        for y in 0..resolution {
            for x in 0..resolution {
                if let Some((s, k)) = sample_candidate(resolution, tiles, x, y) {
                    let tile = layer_tile(resolution, tiles, 0, x, y);
                    let previous = found.insert((tile, s, k), (x, y));
                    assert!(
                        previous.is_none(),
                        "tile {tile} stratum {s} candidate {k} twice"
                    );
                }
            }
        }
        let strata = (tiles * tiles * CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE) as usize;
        assert_eq!(found.len(), strata * SAMPLE_CANDIDATES as usize);
        // Tile 0 holds texels 0–25 (⌊x·5/128⌋ = 0), its stratum 0 texels 0–5: centre 3,
        // corners 0 and 5.
        assert_eq!(found[&(0, 0, 0)], (3, 3));
        assert_eq!(found[&(0, 0, 1)], (0, 0));
        assert_eq!(found[&(0, 0, 2)], (5, 0));
        assert_eq!(found[&(0, 0, 3)], (0, 5));
        assert_eq!(found[&(0, 0, 4)], (5, 5));
    }

    #[test]
    fn the_val_budget_shrinks_every_view_to_the_largest_side_that_fits() {
        assert_eq!(budget_resolution(64, 6, u32::MAX), Some(64));
        assert_eq!(budget_resolution(64, 6000, 1 << 20), Some(13)); // 6000·13² ≤ 2²⁰ < 6000·14²
        assert_eq!(budget_resolution(64, 6, 6 * 49), Some(7));
        assert_eq!(budget_resolution(64, 6, 6 * 49 - 1), Some(6));
        assert_eq!(budget_resolution(64, 6, 5), None);
        assert_eq!(budget_resolution(64, 0, 1), Some(64));
    }

    fn point_lights(powers: &[f32]) -> Vec<SideRequest> {
        powers
            .iter()
            .map(|&power| SideRequest { views: 6, power })
            .collect()
    }

    fn vals(requests: &[SideRequest], sides: &[u32]) -> u64 {
        requests
            .iter()
            .zip(sides)
            .map(|(r, &s)| r.views as u64 * s as u64 * s as u64)
            .sum()
    }

    #[test]
    fn vals_are_shared_by_power() {
        // Everything fits: the requested side for all, however unequal the powers.
        let few = point_lights(&[1.0, 1000.0]);
        assert_eq!(share_sides(&few, 64, u32::MAX), Some(vec![64, 64]));
        // Equal powers: the same side for all, the one the uniform budget gives.
        let equal = point_lights(&[2.0; 1000]);
        let sides = share_sides(&equal, 64, 1 << 20).unwrap();
        assert!(sides.iter().all(|&s| s == 13), "{sides:?}");
        assert_eq!(budget_resolution(64, 6000, 1 << 20), Some(13));
        // Four times the power: four times the VALs (twice the side, to the texel).
        let unequal = [
            SideRequest {
                views: 1,
                power: 4.0,
            },
            SideRequest {
                views: 1,
                power: 1.0,
            },
        ];
        let sides = share_sides(&unequal, 64, 5000).unwrap();
        assert!(vals(&unequal, &sides) <= 5000);
        assert!(
            sides[0].abs_diff(2 * sides[1]) <= 1 && sides[0] >= 60,
            "{sides:?}"
        );
        // The bright light is capped at the request; the dim ones take what it leaves.
        let capped = point_lights(&[1e6, 1.0, 1.0]);
        let sides = share_sides(&capped, 16, 6 * 16 * 16 + 2 * 6 * 64).unwrap();
        assert_eq!(sides, vec![16, 8, 8]);
    }

    #[test]
    fn texel_solid_angles_tile_a_cube_face_exactly() {
        // Six faces of tan(fov/2) = 1 tile the sphere: each is 4π/6 at every side.
        for side in [1, 2, 3, 16, 17, 64, 512] {
            let mut face = 0.0f64;
            for y in 0..side {
                for x in 0..side {
                    face += texel_solid_angle(x, y, side, 1.0) as f64;
                }
            }
            let exact = 4.0 * std::f64::consts::PI / 6.0;
            assert!(
                (face / exact - 1.0).abs() < 2e-4,
                "{side}²: {face} vs {exact}"
            );
        }
        // A lone texel of a narrow view: nearly the flat Δ².
        let narrow = texel_solid_angle(0, 0, 1, 0.01);
        assert!((narrow / 0.0004 - 1.0).abs() < 1e-3, "{narrow}");
    }

    #[test]
    fn a_sun_keeps_its_side_and_powerless_lights_keep_one_texel() {
        let mut requests = point_lights(&[1.0; 100]);
        requests.push(SideRequest {
            views: 1,
            power: f32::INFINITY,
        });
        requests.push(SideRequest {
            views: 6,
            power: f32::NAN,
        });
        requests.push(SideRequest {
            views: 1,
            power: 0.0,
        });
        let sides = share_sides(&requests, 256, 100_000).unwrap();
        assert_eq!(sides[100], 256);
        assert_eq!(&sides[101..], &[1, 1]);
        assert!(vals(&requests, &sides) <= 100_000);
        // Not one texel a view: refused.
        assert_eq!(share_sides(&point_lights(&[1.0; 10]), 8, 59), None);
        assert_eq!(share_sides(&[], 8, 0), Some(vec![]));
    }

    #[test]
    fn views_pack_one_to_a_layer_until_the_array_layers_run_out() {
        let one_each = pack_views(&[64; 2048], 2048, 16384).unwrap();
        assert_eq!((one_each.side, one_each.layers), (64, 2048));
        assert!(one_each.tiles.iter().all(|t| t.origin == [0, 0]));
        // Four times the layers: two a side, row-major, every layer full.
        let packed = pack_views(&[64; 8192], 2048, 16384).unwrap();
        assert_eq!((packed.side, packed.layers), (128, 2048));
        let t = &packed.tiles;
        assert_eq!(
            (t[1].origin, t[2].origin, t[3].origin),
            ([64, 0], [0, 64], [64, 64])
        );
        assert_eq!(
            (t[4].layer, t[4].origin, t[5].first_row),
            (1, [0, 0], 5 * 64)
        );
        // One view past a full array: the side whose last layer wastes least (5·64, 82 layers
        // of 25 views, one slot empty).
        let over = pack_views(&[64; 2049], 2048, 16384).unwrap();
        assert_eq!((over.side, over.layers), (320, 82));
        assert_eq!(pack_views(&[4096; 100_000], 2048, 16384), None);
        assert_eq!(view_of_row(t, 0), 0);
        assert_eq!(view_of_row(t, 64 * 5 + 63), 5);
        assert_eq!(view_of_row(t, 64 * 8192 - 1), 8191);
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        #[test]
        fn shared_sides_fit_the_budget_and_follow_power(
            powers in proptest::collection::vec(0.0f32..1e4, 1..40),
            requested in 1u32..128,
            per_view in 1u32..5000,
        ) {
            let requests = point_lights(&powers);
            let max_vals = per_view * 6 * powers.len() as u32;
            let sides = share_sides(&requests, requested, max_vals).unwrap();
            proptest::prop_assert!(vals(&requests, &sides) <= max_vals as u64);
            for (i, &a) in sides.iter().enumerate() {
                proptest::prop_assert!((1..=requested).contains(&a));
                for (j, &b) in sides.iter().enumerate() {
                    if powers[i] > powers[j] {
                        proptest::prop_assert!(a >= b, "{powers:?} -> {sides:?}");
                    }
                }
            }
        }

        #[test]
        fn packed_views_never_overlap_and_stay_inside_their_layers(
            sides in proptest::collection::vec(1u32..40, 1..200),
            max_layers in 1u32..8,
        ) {
            // At most 200·39² texels: one layer of 1024² always holds them.
            let packing = pack_views(&sides, max_layers, 1024).expect("fits one layer");
            proptest::prop_assert!(packing.layers <= max_layers && packing.side <= 1024);
            let mut rows = 0;
            for (v, t) in packing.tiles.iter().enumerate() {
                proptest::prop_assert_eq!(t.side, sides[v]);
                proptest::prop_assert_eq!(t.first_row, rows);
                rows += t.side;
                proptest::prop_assert!(t.layer < packing.layers);
                proptest::prop_assert!(t.origin[0] + t.side <= packing.side);
                proptest::prop_assert!(t.origin[1] + t.side <= packing.side);
                proptest::prop_assert_eq!(view_of_row(&packing.tiles, t.first_row + t.side - 1), v);
                for u in &packing.tiles[..v] {
                    let apart = u.layer != t.layer
                        || u.origin[0] + u.side <= t.origin[0]
                        || t.origin[0] + t.side <= u.origin[0]
                        || u.origin[1] + u.side <= t.origin[1]
                        || t.origin[1] + t.side <= u.origin[1];
                    proptest::prop_assert!(apart, "{u:?} overlaps {t:?}");
                }
            }
        }
    }
}
