//! Second-order illumination with negative indirect lights (seed 002, Cochran & Steele 2007;
//! the reconstruction in `design/methods-002-001-003mr.md` §A). N positive point lights per
//! light are Halton-sampled from the light's RSM and shine without visibility (I_s); at every
//! camera-visible point the light arriving from behind its tangent plane (E_neg) and its
//! weighted direction are gathered in the same loop; M negative lights are Halton-sampled from
//! the camera view where E_neg > 0 and subtract their light (I_n); L = direct +
//! max(0, I_s − I_n). Both sums run at 2×2-reduced resolution, and the 8×8 tiles where a pixel
//! is discontinuous from its low-resolution parent are recomputed at full resolution through
//! an indirect dispatch, all on the GPU. See `README.md` for the equations and figures.

pub mod bench;
pub mod cpu;

use std::cell::Cell;

use crate::frame::{FrameInput, Method, View, ViewCache, ViewResult, PIXEL_TILE};
use crate::gpu::bindings::{GroupLayout, Slot};
use crate::gpu::{compute_pipeline_groups, FrameTimings, GpuBytes, GpuContext, GpuError, Passes};
use crate::light::rsm::Rsm;
use crate::method::{Entry, MethodOptions, OptionKind, OptionSpec};
use crate::raster::{
    compute_pipeline_at, Rasterizer, RenderError, RenderSettings, RADIANCE_FORMAT,
};

/// `negative_positives.wgsl`: the sample count and samples, the RSM's position, normal and
/// flux arrays, and the positive lights it writes.
const POSITIVES_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Storage,
    Slot::TextureArray,
    Slot::TextureArray,
    Slot::TextureArray,
    Slot::StorageRw,
];

/// `negative_view.wgsl`: frame and parameters, the G-buffer and the indirect target, the
/// positive lights, then the per-view work buffers (points, low/full-resolution terms, tiles)
/// the kernels write, the candidate list they read, and the negatives, their state, the
/// per-resolution energies and the statistics they write.
const VIEW_BINDINGS: &[Slot] = &[
    Slot::Uniform,
    Slot::Uniform,
    Slot::DepthTexture,
    Slot::Texture,
    Slot::Texture,
    Slot::Texture,
    Slot::StorageTexture(RADIANCE_FORMAT),
    Slot::Storage,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::Storage,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::StorageRw,
    Slot::Uniform,
    Slot::Uniform,
];
/// Lights in each of `negative_view.wgsl`'s uniform blocks (`LIGHT_BLOCK` there): 48 KiB,
/// under the 64 KiB every device binds.
pub const LIGHT_BLOCK: u32 = 1024;
use crate::scene::{Aabb, CameraView, Scene};
use crate::shading::WorldLight;
use bytemuck::{Pod, Zeroable};
pub use cpu::{Falloff, IndirectLight, PositiveSample, PositiveTerms, SurfacePoint, WeightMode};

const LOWRES: &[&str] = &["on", "off"];

pub static ENTRY: Entry = Entry {
    name: "negative",
    help: "second-order illumination: Halton positive lights from the RSM without visibility, corrected by negative lights on camera-visible back faces, at 2×2-reduced resolution with full-resolution patches (seed 002)",
    options: &[
        OptionSpec {
            name: "positive",
            kind: OptionKind::Int { min: 1, max: 4096 },
            default: "150",
            help: "N: positive indirect lights per light",
        },
        OptionSpec {
            name: "negative",
            kind: OptionKind::Int { min: 0, max: 1024 },
            default: "",
            help: "M: negative indirect lights per view (default N/2; 0 = none)",
        },
        OptionSpec {
            name: "lowres",
            kind: OptionKind::Choice(LOWRES),
            default: "on",
            help: "evaluate at 2×2-reduced resolution and recompute discontinuous 8×8 tiles",
        },
        OptionSpec {
            name: "threshold-pos",
            kind: OptionKind::Text,
            default: "3",
            help: "τ_x: a pixel further than this many pixel footprints from its low-resolution parent is recomputed",
        },
        OptionSpec {
            name: "threshold-normal",
            kind: OptionKind::Text,
            default: "0.94",
            help: "τ_n: a pixel whose normal·parent normal is below this is recomputed (−1..1)",
        },
        OptionSpec {
            name: "weight",
            kind: OptionKind::Choice(WeightMode::NAMES),
            default: "literal",
            help: "negative-light direction: literal (n_l by E_neg share), arriving (n_l by arriving intensity), propagation (−t̂ by E_neg share)",
        },
        OptionSpec {
            name: "dmin",
            kind: OptionKind::Text,
            default: "0.001",
            help: "distance clamp d_min of every point light, as a fraction of the scene diagonal",
        },
        OptionSpec {
            name: "falloff",
            kind: OptionKind::Choice(Falloff::NAMES),
            default: "point",
            help: "distance term: point (1/max(d², d²_min), the paper) or disc (1/(d² + r²), each light the disc it stands for)",
        },
        OptionSpec {
            name: "rsm",
            kind: OptionKind::Int { min: 1, max: 2048 },
            default: "256",
            help: "RSM resolution per light layer the positive lights are read from",
        },
    ],
    create,
};

fn create(
    ctx: &GpuContext,
    scene: &Scene,
    settings: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(NegativeMethod::new(
        ctx, scene, settings, options,
    )?))
}

/// The method's knobs, parsed and checked.
#[derive(Clone, Copy, Debug)]
pub struct NegativeSettings {
    pub positive: u32,
    pub negative: u32,
    pub lowres: bool,
    pub threshold_pos: f32,
    pub threshold_normal: f32,
    pub weight: WeightMode,
    pub dmin: f32,
    /// 1/(d² + r²) instead of 1/max(d², d²_min).
    pub disc: bool,
    pub rsm: u32,
}

impl NegativeSettings {
    pub fn from_options(options: &MethodOptions) -> Result<Self, RenderError> {
        let positive: u32 = options.get("positive", 150)?;
        let negative: u32 = options.get("negative", positive / 2)?;
        let lowres = options.choice("lowres", LOWRES)? == "on";
        let float = |key: &str, default: f32, ok: &dyn Fn(f32) -> bool, range: &str| {
            let v: f32 = options.get(key, default)?;
            if !v.is_finite() || !ok(v) {
                return Err(RenderError::Settings(format!(
                    "method 'negative': option {key}={v}: must be {range}"
                )));
            }
            Ok(v)
        };
        let threshold_pos = float("threshold-pos", 3.0, &|v| v >= 0.0, "≥ 0")?;
        let threshold_normal = float(
            "threshold-normal",
            0.94,
            &|v| (-1.0..=1.0).contains(&v),
            "in −1..=1",
        )?;
        let dmin = float("dmin", 1e-3, &|v| (0.0..=1.0).contains(&v), "in 0..=1")?;
        let weight = WeightMode::parse(options.choice("weight", WeightMode::NAMES)?);
        let disc = options.choice("falloff", Falloff::NAMES)? == "disc";
        let rsm: u32 = options.get("rsm", 256)?;
        if !(1..=4096).contains(&positive) || negative > 1024 {
            return Err(RenderError::Settings(format!(
                "method 'negative': positive={positive} must be 1..=4096 and negative={negative} 0..=1024"
            )));
        }
        Ok(Self {
            positive,
            negative,
            lowres,
            threshold_pos,
            threshold_normal,
            weight,
            dmin,
            disc,
            rsm,
        })
    }
}

/// `NegativeParams` in `shaders/negative/negative_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct NegativeParams {
    pub eye: [f32; 4],
    pub full_width: u32,
    pub full_height: u32,
    pub low_width: u32,
    pub low_height: u32,
    pub positive_count: u32,
    pub candidate_count: u32,
    pub negative_target: u32,
    /// The weight and the falloff are pipeline constants (`WEIGHT_MODE`, `DISC_FALLOFF`).
    pub pad0: u32,
    pub lowres: u32,
    pub tiles_x: u32,
    pub d2_min: f32,
    pub threshold_pos: f32,
    pub threshold_normal: f32,
    pub footprint_scale: f32,
    pub omega_frustum: f32,
    pub pad1: u32,
}

/// `SampleCount` in `shaders/negative/negative_positives.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct SampleCount {
    pub count: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Structs shared with WGSL, for the layout test.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout;
    vec![
        shared_layout!(
            "PositiveSample",
            "negative_common.wgsl",
            PositiveSample,
            [layer, texel_x, texel_y, light, flux_scale, pad0, pad1, pad2]
        ),
        shared_layout!(
            "IndirectLight",
            "negative_common.wgsl",
            IndirectLight,
            [position, normal, flux]
        ),
        shared_layout!(
            "SurfacePoint",
            "negative_common.wgsl",
            SurfacePoint,
            [position, normal]
        ),
        shared_layout!(
            "PositiveTerms",
            "negative_common.wgsl",
            PositiveTerms,
            [e_s, e_neg, direction]
        ),
        shared_layout!(
            "NegativeParams",
            "negative_common.wgsl",
            NegativeParams,
            [
                eye,
                full_width,
                full_height,
                low_width,
                low_height,
                positive_count,
                candidate_count,
                negative_target,
                pad0,
                lowres,
                tiles_x,
                d2_min,
                threshold_pos,
                threshold_normal,
                footprint_scale,
                omega_frustum,
                pad1
            ]
        ),
        shared_layout!(
            "SampleCount",
            "negative_positives.wgsl",
            SampleCount,
            [count, pad0, pad1, pad2]
        ),
    ]
}

/// Workgroup of the positive-light pass (`negative_positives.wgsl`).
pub const POSITIVE_GROUP: u32 = 64;
/// Workgroup of the negative-light selection (one workgroup).
pub const SELECT_GROUP: u32 = 256;
/// Entry points of `negative_view.wgsl` with 8×8 workgroups (one per 8×8 tile of pixels, of
/// low-resolution points, or of 2×2 blocks in `points_blocks`), unless listed below.
pub const VIEW_ENTRIES: &[&str] = &[
    "points_main",
    "points_blocks",
    "positive_low",
    "positive_tiles",
    "positive_full",
    "negative_low",
    "negative_tiles",
    "negative_full",
    "gather",
];
/// The entry points that run one workgroup of 8 × 8 / `COLUMN` invocations per 8 × 8 tile
/// (the flagged tiles' light loops, and the gather), a column of `COLUMN` pixels each.
pub const TILE_COLUMN_ENTRIES: &[&str] = &["positive_tiles", "negative_tiles", "gather"];
/// Pixels per invocation of the light loops (`COLUMN` in `negative_view.wgsl`): a column of
/// them, so that each light read serves that many pixels.
pub const COLUMN: u32 = 4;
/// Header words of the tile buffer (flagged count, 1, 1, recomputed pixels).
const TILE_HEADER: u64 = 4;

/// Every GPU buffer of one view, readable back for tests.
struct ViewState {
    params: wgpu::Buffer,
    points: wgpu::Buffer,
    low_points: wgpu::Buffer,
    low_terms: wgpu::Buffer,
    full_terms: wgpu::Buffer,
    tiles: wgpu::Buffer,
    candidates: wgpu::Buffer,
    negatives: wgpu::Buffer,
    /// The negatives as the uniform block the E_n passes read, copied after the selection.
    negatives_block: wgpu::Buffer,
    negative_state: wgpu::Buffer,
    low_en: wgpu::Buffer,
    full_en: wgpu::Buffer,
    stats: wgpu::Buffer,
    dispatch_args: wgpu::Buffer,
    group: wgpu::BindGroup,
    candidate_capacity: u32,
    /// Projection and size the candidates were made for, their count and Ω_frustum.
    candidate_key: Cell<Option<([u32; 6], u32, f32)>>,
    /// The params of the last frame (the uniform is not a copy source).
    last_params: Cell<NegativeParams>,
    bytes: GpuBytes,
}

/// What the GPU left in one view's buffers (tests compare it with the CPU twin).
pub struct NegativeReadback {
    pub positives: Vec<IndirectLight>,
    pub points: Vec<SurfacePoint>,
    pub low_points: Vec<SurfacePoint>,
    pub low_terms: Vec<PositiveTerms>,
    pub full_terms: Vec<PositiveTerms>,
    /// Per 8×8 tile: recomputed at full resolution.
    pub tile_flags: Vec<bool>,
    pub recomputed_pixels: u32,
    pub candidates: Vec<u32>,
    pub omega_frustum: f32,
    pub negatives: Vec<IndirectLight>,
    pub candidates_tried: u32,
    pub low_en: Vec<[f32; 4]>,
    pub full_en: Vec<[f32; 4]>,
    pub full_size: (u32, u32),
    pub low_size: (u32, u32),
    pub d2_min: f32,
}

/// Last frame's counters for the report.
#[derive(Clone, Copy, Debug, Default)]
pub struct NegativeStats {
    pub positive_lights: u32,
    pub negative_lights: u32,
    pub candidates_tried: u32,
    /// 1 − recomputed pixels / all pixels (1 with low resolution off is reported as 0).
    pub lowres_fraction: f64,
    /// Covered pixels where I_s − I_n went below zero in some channel, over covered pixels.
    pub clamp_rate: f64,
    /// Y the clamp added back, over Y of I_s.
    pub clamped_energy: f64,
    /// Y of I_n over Y of I_s.
    pub negative_energy: f64,
    /// (pixel, positive light) pairs whose d² the d²_min guard replaced, over all pairs.
    pub distance_clamp_rate: f64,
}

pub struct NegativeMethod {
    pub raster: Rasterizer,
    pub rsm: Rsm,
    pub settings: NegativeSettings,
    d2_min: f32,
    samples: Vec<PositiveSample>,
    samples_buffer: wgpu::Buffer,
    sample_count_buffer: wgpu::Buffer,
    positives_buffer: wgpu::Buffer,
    /// The positives as the uniform block the view passes read, when they fit one
    /// (`positives_in_block`; else the passes read `positives_buffer`).
    positives_block: wgpu::Buffer,
    positives_in_block: bool,
    positives_group: wgpu::BindGroup,
    positives_pipeline: wgpu::ComputePipeline,
    view_layout: GroupLayout,
    view_pipelines: Vec<(&'static str, wgpu::ComputePipeline)>,
    select_pipeline: wgpu::ComputePipeline,
    views: ViewCache<ViewState>,
    last_view: Option<u64>,
    stats: NegativeStats,
    bytes: GpuBytes,
}

fn buffer(
    bytes: &mut GpuBytes,
    device: &wgpu::Device,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    bytes.buffer(
        device,
        &wgpu::BufferDescriptor {
            label: Some(label),
            size: size.max(16),
            usage,
            mapped_at_creation: false,
        },
    )
}

const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);
/// A uniform block of LIGHT_BLOCK lights, filled by copies from the storage buffer that a pass
/// writes.
fn light_block(bytes: &mut GpuBytes, device: &wgpu::Device, label: &str) -> wgpu::Buffer {
    let usage = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
    let size = u64::from(LIGHT_BLOCK) * std::mem::size_of::<IndirectLight>() as u64;
    buffer(bytes, device, label, size, usage)
}

impl NegativeMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        options: &MethodOptions,
    ) -> Result<Self, RenderError> {
        let settings = NegativeSettings::from_options(options)?;
        let raster = Rasterizer::new(ctx, scene, render)?;
        let rsm = Rsm::new(ctx, scene, &raster, settings.rsm)?;
        let device = &ctx.device;
        let mesh_bounds: Vec<Aabb> = scene.meshes.iter().map(|m| m.model_bounds()).collect();
        let bounds = scene.instance_bounds(&mesh_bounds, &scene.world_from_node());
        let diagonal = if bounds.is_empty() {
            1.0
        } else {
            bounds.extent().length()
        };
        let d2_min = (settings.dmin * diagonal).powi(2);
        let mut bytes = GpuBytes::default();
        let total = (settings.positive as u64 * scene.lights.len() as u64).max(1);
        let samples_buffer = buffer(&mut bytes, device, "negative samples", total * 32, STORAGE);
        let positives_buffer = buffer(&mut bytes, device, "positive lights", total * 48, STORAGE);
        let positives_in_block = total <= u64::from(LIGHT_BLOCK);
        let positives_block = light_block(&mut bytes, device, "positive lights block");
        let sample_count_buffer = bytes.uniform::<SampleCount>(device, "negative sample count");
        let cs = wgpu::ShaderStages::COMPUTE;
        let positives_layout =
            GroupLayout::new(device, "negative positives", cs, POSITIVES_BINDINGS);
        let positives_group = positives_layout.bind(
            device,
            &[
                &sample_count_buffer,
                &samples_buffer,
                &rsm.array_views[0],
                &rsm.array_views[1],
                &rsm.array_views[2],
                &positives_buffer,
            ],
        );
        let positives_pipeline = compute_pipeline_at(
            device,
            "negative positives",
            &ctx.shader("negative_positives.wgsl"),
            &positives_layout.layout,
            "cs_main",
        );
        let view_layout = GroupLayout::new(device, "negative view", cs, VIEW_BINDINGS);
        let module = ctx.shader("negative_view.wgsl");
        let constants = [
            (
                "POSITIVES_IN_BLOCK",
                f64::from(u8::from(positives_in_block)),
            ),
            ("WEIGHT_MODE", f64::from(settings.weight as u32)),
            ("DISC_FALLOFF", f64::from(u8::from(settings.disc))),
        ];
        let view_pipelines = VIEW_ENTRIES
            .iter()
            .map(|e| {
                let layouts = [&view_layout.layout];
                let pipeline = compute_pipeline_groups(device, e, &module, &layouts, e, &constants);
                (*e, pipeline)
            })
            .collect();
        let select_pipeline = compute_pipeline_at(
            device,
            "select_negatives",
            &module,
            &view_layout.layout,
            "select_negatives",
        );
        Ok(Self {
            raster,
            rsm,
            settings,
            d2_min,
            samples: vec![],
            samples_buffer,
            sample_count_buffer,
            positives_buffer,
            positives_block,
            positives_in_block,
            positives_group,
            positives_pipeline,
            view_layout,
            view_pipelines,
            select_pipeline,
            views: ViewCache::default(),
            last_view: None,
            stats: NegativeStats::default(),
            bytes,
        })
    }

    /// The positive samples of the last frame (one list for all views).
    pub fn samples(&self) -> &[PositiveSample] {
        &self.samples
    }

    /// The distance term every point light uses.
    pub fn falloff(&self) -> Falloff {
        if self.settings.disc {
            Falloff::Disc
        } else {
            Falloff::Point {
                d2_min: self.d2_min,
            }
        }
    }

    pub fn stats(&self) -> NegativeStats {
        self.stats
    }

    /// The positive lights of the last frame.
    pub fn read_positives(&self, ctx: &GpuContext) -> Result<Vec<IndirectLight>, GpuError> {
        let all: Vec<IndirectLight> = crate::gpu::read_buffer(ctx, &self.positives_buffer)?;
        Ok(all[..self.samples.len().min(all.len())].to_vec())
    }

    /// Whether the view passes read the positive lights from their uniform block (all of
    /// them fit one), not from the storage buffer.
    pub fn positives_in_block(&self) -> bool {
        self.positives_in_block
    }

    fn pipeline(&self, entry: &str) -> &wgpu::ComputePipeline {
        &self
            .view_pipelines
            .iter()
            .find(|(e, _)| *e == entry)
            .expect("negative_view entry point")
            .1
    }

    fn make_view_state(&self, ctx: &GpuContext, view: &View) -> ViewState {
        let device = &ctx.device;
        let mut bytes = GpuBytes::default();
        let (w, h) = view.render_size();
        let (lw, lh) = (w.div_ceil(2), h.div_ceil(2));
        let full = w as u64 * h as u64;
        let low = lw as u64 * lh as u64;
        let tiles = (w.div_ceil(PIXEL_TILE) * h.div_ceil(PIXEL_TILE)) as u64;
        let candidate_capacity = (64 * self.settings.negative.max(1)).clamp(1024, 1 << 16);
        let params = bytes.uniform::<NegativeParams>(device, "negative params");
        let points = buffer(&mut bytes, device, "negative points", full * 32, STORAGE);
        let low_points = buffer(&mut bytes, device, "negative low points", low * 32, STORAGE);
        let low_terms = buffer(&mut bytes, device, "negative low terms", low * 48, STORAGE);
        let full_terms = buffer(
            &mut bytes,
            device,
            "negative full terms",
            full * 48,
            STORAGE,
        );
        let tiles_buffer = buffer(
            &mut bytes,
            device,
            "negative tiles",
            (TILE_HEADER + 2 * tiles) * 4,
            STORAGE,
        );
        let candidates = buffer(
            &mut bytes,
            device,
            "negative candidates",
            candidate_capacity as u64 * 4,
            STORAGE,
        );
        let negatives = buffer(
            &mut bytes,
            device,
            "negative lights",
            self.settings.negative.max(1) as u64 * 48,
            STORAGE,
        );
        let negatives_block = light_block(&mut bytes, device, "negative lights block");
        let negative_state = buffer(&mut bytes, device, "negative state", 16, STORAGE);
        let low_en = buffer(&mut bytes, device, "negative low E_n", low * 16, STORAGE);
        let full_en = buffer(&mut bytes, device, "negative full E_n", full * 16, STORAGE);
        let stats = buffer(&mut bytes, device, "negative stats", tiles * 32, STORAGE);
        let dispatch_args = buffer(
            &mut bytes,
            device,
            "negative dispatch",
            16,
            wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_DST,
        );
        let t = &view.targets;
        let group = self.view_layout.bind(
            device,
            &[
                &view.frame_buffer,
                &params,
                &t.depth,
                &t.normal,
                &t.diffuse,
                &t.specular,
                &t.radiance_indirect,
                &self.positives_buffer,
                &points,
                &low_points,
                &low_terms,
                &full_terms,
                &tiles_buffer,
                &candidates,
                &negatives,
                &negative_state,
                &low_en,
                &full_en,
                &stats,
                &self.positives_block,
                &negatives_block,
            ],
        );
        ViewState {
            params,
            points,
            low_points,
            low_terms,
            full_terms,
            tiles: tiles_buffer,
            candidates,
            negatives,
            negatives_block,
            negative_state,
            low_en,
            full_en,
            stats,
            dispatch_args,
            group,
            candidate_capacity,
            candidate_key: Cell::new(None),
            last_params: Cell::new(NegativeParams::default()),
            bytes,
        }
    }

    /// Everything the last recorded view's passes left in its buffers.
    pub fn read_view(&self, ctx: &GpuContext) -> Result<NegativeReadback, RenderError> {
        let id = self
            .last_view
            .ok_or_else(|| RenderError::Settings("negative: no view recorded yet".into()))?;
        let state = self
            .views
            .values_by_id(id)
            .ok_or_else(|| RenderError::Settings("negative: the last view is gone".into()))?;
        let p = state.last_params.get();
        let (full, low) = (
            (p.full_width * p.full_height) as usize,
            (p.low_width * p.low_height) as usize,
        );
        let tiles: Vec<u32> = crate::gpu::read_buffer(ctx, &state.tiles)?;
        let tile_count = p.tiles_x as usize * p.full_height.div_ceil(PIXEL_TILE) as usize;
        let state_words: Vec<u32> = crate::gpu::read_buffer(ctx, &state.negative_state)?;
        let negatives: Vec<IndirectLight> = crate::gpu::read_buffer(ctx, &state.negatives)?;
        let count = (state_words[0] as usize).min(negatives.len());
        let candidates: Vec<u32> = crate::gpu::read_buffer(ctx, &state.candidates)?;
        let (_, candidate_count, omega) = state.candidate_key.get().unwrap_or(([0; 6], 0, 0.0));
        let take = |v: Vec<PositiveTerms>, n: usize| v[..n.min(v.len())].to_vec();
        let points: Vec<SurfacePoint> = crate::gpu::read_buffer(ctx, &state.points)?;
        let low_points: Vec<SurfacePoint> = crate::gpu::read_buffer(ctx, &state.low_points)?;
        let low_en: Vec<[f32; 4]> = crate::gpu::read_buffer(ctx, &state.low_en)?;
        let full_en: Vec<[f32; 4]> = crate::gpu::read_buffer(ctx, &state.full_en)?;
        Ok(NegativeReadback {
            positives: self.read_positives(ctx)?,
            points: points[..full].to_vec(),
            low_points: low_points[..low].to_vec(),
            low_terms: take(crate::gpu::read_buffer(ctx, &state.low_terms)?, low),
            full_terms: take(crate::gpu::read_buffer(ctx, &state.full_terms)?, full),
            tile_flags: tiles[TILE_HEADER as usize..TILE_HEADER as usize + tile_count]
                .iter()
                .map(|f| *f != 0)
                .collect(),
            recomputed_pixels: tiles[3],
            candidates: candidates[..candidate_count as usize].to_vec(),
            omega_frustum: omega,
            negatives: negatives[..count].to_vec(),
            candidates_tried: state_words[1],
            low_en: low_en[..low].to_vec(),
            full_en: full_en[..full].to_vec(),
            full_size: (p.full_width, p.full_height),
            low_size: (p.low_width, p.low_height),
            d2_min: p.d2_min,
        })
    }
}

/// The key that decides whether a view's camera candidates are still valid.
fn candidate_key(camera: &CameraView, width: u32, height: u32) -> [u32; 6] {
    let e = camera.tangent_extents();
    [
        e[0].to_bits(),
        e[1].to_bits(),
        e[2].to_bits(),
        e[3].to_bits(),
        width,
        height,
    ]
}

impl Method for NegativeMethod {
    fn name(&self) -> &'static str {
        "negative"
    }

    fn settings(&self) -> RenderSettings {
        self.raster.settings
    }

    fn update(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInput,
        views: &[&View],
        passes: &mut Passes,
    ) -> Result<(), RenderError> {
        self.views.retain(views);
        self.raster
            .update_and_record(ctx, frame.scene, frame.world_from_node, passes)?;
        self.rsm.prepare(ctx, frame.scene, frame.world_from_node);
        // The positive lights read their N texels straight from the maps (§A.1's S_light):
        // no VAL list is compacted.
        self.rsm.record_maps(passes, &self.raster.scene_gpu)?;
        let setup = self.rsm.light_setup(frame.scene, frame.world_from_node);
        let lights = WorldLight::from_scene(frame.scene, frame.world_from_node);
        let samples = cpu::positive_samples(
            &setup,
            &lights,
            &self.rsm.light_sides,
            self.settings.positive,
        );
        if samples != self.samples {
            if !samples.is_empty() {
                // The shader reads the RSM arrays directly: texels where the packed views
                // keep them.
                let packed: Vec<cpu::PositiveSample> = samples
                    .iter()
                    .map(|s| {
                        let (layer, texel_x, texel_y) =
                            self.rsm.physical_texel(s.layer, s.texel_x, s.texel_y);
                        cpu::PositiveSample {
                            layer,
                            texel_x,
                            texel_y,
                            ..*s
                        }
                    })
                    .collect();
                ctx.queue
                    .write_buffer(&self.samples_buffer, 0, bytemuck::cast_slice(&packed));
            }
            let count = SampleCount {
                count: samples.len() as u32,
                ..Default::default()
            };
            ctx.queue
                .write_buffer(&self.sample_count_buffer, 0, bytemuck::bytes_of(&count));
            self.samples = samples;
        }
        let n = self.samples.len() as u32;
        if n > 0 {
            let (x, y) = crate::gpu::linear_groups(
                n.div_ceil(POSITIVE_GROUP),
                ctx.device.limits().max_compute_workgroups_per_dimension,
            );
            passes.compute("negative positives", |pass| {
                pass.set_pipeline(&self.positives_pipeline);
                pass.set_bind_group(0, &self.positives_group, &[]);
                pass.dispatch_workgroups(x, y, 1);
            })?;
            if self.positives_in_block {
                passes.encoder().copy_buffer_to_buffer(
                    &self.positives_buffer,
                    0,
                    &self.positives_block,
                    0,
                    self.positives_buffer.size(),
                );
            }
        }
        Ok(())
    }

    fn record_view(
        &mut self,
        ctx: &GpuContext,
        _frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError> {
        self.raster.record_view_base(ctx, view, passes)?;
        if self.views.get(view).is_none() {
            let state = self.make_view_state(ctx, view);
            self.views.get_or_try_insert(view, || Ok(state))?;
        }
        let state = self.views.get(view).expect("view state");
        let (w, h) = view.render_size();
        let key = candidate_key(&view.camera, w, h);
        if state.candidate_key.get().map(|k| k.0) != Some(key) {
            let (list, omega) =
                cpu::camera_candidates(&view.camera, w, h, state.candidate_capacity);
            if !list.is_empty() {
                ctx.queue
                    .write_buffer(&state.candidates, 0, bytemuck::cast_slice(&list));
            }
            state
                .candidate_key
                .set(Some((key, list.len() as u32, omega)));
        }
        let (_, candidate_count, omega_frustum) = state.candidate_key.get().expect("candidates");
        let [_, _, bottom, top] = view.camera.tangent_extents();
        let s = &self.settings;
        let params = NegativeParams {
            eye: view.camera.position().extend(1.0).to_array(),
            full_width: w,
            full_height: h,
            low_width: w.div_ceil(2),
            low_height: h.div_ceil(2),
            positive_count: self.samples.len() as u32,
            candidate_count,
            negative_target: s.negative,
            pad0: 0,
            lowres: s.lowres as u32,
            tiles_x: w.div_ceil(PIXEL_TILE),
            d2_min: self.d2_min,
            threshold_pos: s.threshold_pos,
            threshold_normal: s.threshold_normal,
            footprint_scale: (top - bottom) / h as f32,
            omega_frustum,
            pad1: 0,
        };
        ctx.queue
            .write_buffer(&state.params, 0, bytemuck::bytes_of(&params));
        state.last_params.set(params);
        ctx.queue.write_buffer(
            &state.negative_state,
            0,
            bytemuck::cast_slice(&[0u32, 0, 0, 0]),
        );
        ctx.queue
            .write_buffer(&state.tiles, 0, bytemuck::cast_slice(&[0u32, 1, 1, 0]));
        let full = (w.div_ceil(PIXEL_TILE), h.div_ceil(PIXEL_TILE));
        // The light loops' workgroups cover COLUMN times as many rows.
        let full_columns = (full.0, h.div_ceil(PIXEL_TILE * COLUMN));
        let low_columns = (
            w.div_ceil(2).div_ceil(PIXEL_TILE),
            h.div_ceil(2).div_ceil(PIXEL_TILE * COLUMN),
        );
        let group = &state.group;
        let run = |passes: &mut Passes, label: &str, entry: &str, groups: (u32, u32)| {
            let pipeline = self.pipeline(entry);
            passes.compute(label, |pass| {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(groups.0, groups.1, 1);
            })
        };
        let patch = |passes: &mut Passes, label: &str, entry: &str| {
            let pipeline = self.pipeline(entry);
            passes.compute(label, |pass| {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups_indirect(&state.dispatch_args, 0);
            })
        };
        if s.lowres {
            // One workgroup per 2 × 2 tiles.
            let blocks = (full.0.div_ceil(2), full.1.div_ceil(2));
            run(
                passes,
                "negative points and blocks",
                "points_blocks",
                blocks,
            )?;
            run(passes, "negative positive low", "positive_low", low_columns)?;
            passes
                .encoder()
                .copy_buffer_to_buffer(&state.tiles, 0, &state.dispatch_args, 0, 12);
            patch(passes, "negative positive tiles", "positive_tiles")?;
        } else {
            run(passes, "negative points", "points_main", full)?;
            run(
                passes,
                "negative positive full",
                "positive_full",
                full_columns,
            )?;
        }
        if s.negative > 0 {
            let pipeline = &self.select_pipeline;
            passes.compute("negative select", |pass| {
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(1, 1, 1);
            })?;
            passes.encoder().copy_buffer_to_buffer(
                &state.negatives,
                0,
                &state.negatives_block,
                0,
                state.negatives.size(),
            );
            if s.lowres {
                run(passes, "negative negative low", "negative_low", low_columns)?;
                patch(passes, "negative negative tiles", "negative_tiles")?;
            } else {
                run(
                    passes,
                    "negative negative full",
                    "negative_full",
                    full_columns,
                )?;
            }
        }
        run(passes, "negative gather", "gather", full)?;
        self.last_view = Some(view.id());
        Ok(ViewResult::DirectAndIndirect)
    }

    fn end_frame(&mut self, ctx: &GpuContext, _timings: &FrameTimings) -> Result<(), RenderError> {
        let Some(state) = self.last_view.and_then(|id| self.views.values_by_id(id)) else {
            return Ok(());
        };
        let tiles: Vec<u32> = crate::gpu::read_buffer(ctx, &state.tiles)?;
        let negative_state: Vec<u32> = crate::gpu::read_buffer(ctx, &state.negative_state)?;
        let stats: Vec<[f32; 4]> = crate::gpu::read_buffer(ctx, &state.stats)?;
        let positives = self.read_positives(ctx)?;
        let key = state.candidate_key.get().map(|k| k.0).unwrap_or_default();
        let (w, h) = (key[4] as u64, key[5] as u64);
        let groups = (w.div_ceil(PIXEL_TILE as u64) * h.div_ceil(PIXEL_TILE as u64)) as usize;
        let mut sum = [0f64; 6];
        for g in 0..groups.min(stats.len() / 2) {
            for (c, s) in sum.iter_mut().take(4).enumerate() {
                *s += stats[2 * g][c] as f64;
            }
            sum[4] += stats[2 * g + 1][0] as f64;
            sum[5] += stats[2 * g + 1][1] as f64;
        }
        let pixels = (w * h).max(1) as f64;
        self.stats = NegativeStats {
            positive_lights: positives.iter().filter(|l| l.is_active()).count() as u32,
            negative_lights: if self.settings.negative > 0 {
                negative_state[0]
            } else {
                0
            },
            candidates_tried: if self.settings.negative > 0 {
                negative_state[1]
            } else {
                0
            },
            lowres_fraction: if self.settings.lowres {
                1.0 - tiles[3] as f64 / pixels
            } else {
                0.0
            },
            clamp_rate: sum[0] / sum[3].max(1.0),
            clamped_energy: sum[1] / sum[2].max(1e-30),
            negative_energy: sum[4] / sum[2].max(1e-30),
            distance_clamp_rate: sum[5] / (sum[3] * positives.len() as f64).max(1.0),
        };
        Ok(())
    }

    fn gpu_bytes(&self) -> u64 {
        self.raster.gpu_bytes()
            + self.rsm.bytes.0
            + self.bytes.0
            + self.views.values().map(|v| v.bytes.0).sum::<u64>()
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let s = &self.settings;
        let t = &self.stats;
        let mut map = serde_json::Map::new();
        map.insert("positive".into(), s.positive.into());
        map.insert("negative".into(), s.negative.into());
        map.insert("lowres".into(), if s.lowres { "on" } else { "off" }.into());
        map.insert("threshold_pos".into(), (s.threshold_pos as f64).into());
        map.insert(
            "threshold_normal".into(),
            (s.threshold_normal as f64).into(),
        );
        map.insert("weight".into(), WeightMode::NAMES[s.weight as usize].into());
        map.insert("rsm".into(), self.rsm.resolution.into());
        map.insert(
            "falloff".into(),
            if s.disc { "disc" } else { "point" }.into(),
        );
        map.insert("positive_lights_active".into(), t.positive_lights.into());
        map.insert("negative_lights".into(), t.negative_lights.into());
        map.insert(
            "negative_candidates_tried".into(),
            t.candidates_tried.into(),
        );
        map.insert("lowres_percent".into(), (100.0 * t.lowres_fraction).into());
        map.insert("clamp_rate".into(), t.clamp_rate.into());
        map.insert("clamped_energy_fraction".into(), t.clamped_energy.into());
        map.insert("negative_energy_fraction".into(), t.negative_energy.into());
        map.insert("distance_clamp_rate".into(), t.distance_clamp_rate.into());
        map
    }
}
