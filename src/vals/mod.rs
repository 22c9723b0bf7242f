//! Sparse virtual-area-light shading, the core method (DESIGN §4, seed 003). See README.md in
//! this folder for the equations and the pass list.
//!
//! - [`rsm`]: reflective shadow maps → one buffer of VALs for all lights.
//! - [`points`]: the preprocessing — sparse points per mesh, vertex links, disc radii.
//! - [`scene_cache`]: what builds over one scene share (budget mode's pilots).
//! - [`sparse`]: the GPU passes gather → renormalize → occlusion → interpolation → apply.
//! - [`math`]: the CPU twin of every kernel, and the documentation of the math.

pub mod budget;
pub mod math;
pub mod points;
pub mod recent;
pub mod scene_cache;
pub mod sparse;
pub mod visibility;

use std::sync::Arc;
use std::time::Instant;

use crate::frame::{FrameInput, IndirectLayer, Method, View, ViewCache, ViewResult};
use crate::gpu::{FrameTimings, GpuContext, Passes};
use crate::image_io::Image;
use crate::light::rsm::Rsm;
use crate::light::val_windows::ValReads;
use crate::light::GlossyGather;
use crate::light::ValSource;
use crate::method::{Entry, MethodOptions, OptionKind, OptionSpec};
use crate::raster::{Rasterizer, RenderError, RenderSettings};
use crate::scene::{CameraView, Scene};
use glam::Mat4;
use math::{OcclusionMode, Weights};
use points::MeshPoints;
use scene_cache::PreparedPoints;
pub use scene_cache::SceneCache;
pub use sparse::Stage;
use sparse::{GatherForm, KernelGroups, SparseGpu, SparseOptions, VisibilityLookup};

/// Everything `--method sparse` can be told.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseSettings {
    /// RSM resolution per light layer (the largest, with `rsm_texels`).
    pub rsm: u32,
    /// RSM texels all lights share by power (`light::rsm::DEFAULT_SHARED_TEXELS` when `rsm`
    /// is not given; `None`: every layer gets `rsm`², within `--max-vals`).
    pub rsm_texels: Option<u32>,
    /// Sparse points for the whole scene.
    pub sparse_points: usize,
    /// Placement seed.
    pub seed: u64,
    pub options: SparseOptions,
    pub glossy_eye: GlossyEye,
    /// Drop the links that pass through other (static) geometry
    /// (`points::cut_links_through_walls`).
    pub link_test: bool,
}

impl Default for SparseSettings {
    fn default() -> Self {
        Self {
            rsm: 128,
            rsm_texels: Some(crate::light::rsm::DEFAULT_SHARED_TEXELS),
            sparse_points: 4096,
            seed: 1,
            options: SparseOptions {
                tile: 128,
                gather: GatherForm::Compute,
                glossy: GlossyGather::Auto,
                occlusion: OcclusionMode::Rays,
                weights: Weights::Geometric,
                visibility_history: 50,
                adaptive_rays: false,
                gather_slices: 0,
                gather_points: 0,
                visibility_lookup: VisibilityLookup::Auto,
                gather_vals: ValReads::Auto,
            },
            glossy_eye: GlossyEye::Mid,
            link_test: true,
        }
    }
}

impl SparseSettings {
    /// Reads the options `rsm`, `sparse-points`, `seed`, `tile`, `gather`, `glossy`, `occlusion` and
    /// `weights` (those not given keep their defaults).
    pub fn from_options(options: &MethodOptions) -> Result<Self, RenderError> {
        let d = Self::default();
        let tile: u32 = options.get("tile", d.options.tile)?;
        if !(1..=256).contains(&tile) {
            return Err(RenderError::Settings(format!(
                "--tile {tile}: must be 1..=256 (workgroup memory holds at most 256 VALs)"
            )));
        }
        let sparse_points: usize = options.get("sparse-points", d.sparse_points)?;
        if sparse_points == 0 {
            return Err(RenderError::Settings(
                "--sparse-points must be at least 1".into(),
            ));
        }
        let rsm_given = options.given("rsm");
        Ok(Self {
            rsm: options.get("rsm", d.rsm)?,
            rsm_texels: if rsm_given { None } else { d.rsm_texels },
            sparse_points,
            seed: options.get("seed", d.seed)?,
            options: SparseOptions {
                tile,
                gather: match options.choice("gather", &["compute", "raster"])? {
                    "raster" => GatherForm::Raster,
                    _ => GatherForm::Compute,
                },
                glossy: GlossyGather::parse(options.choice("glossy", GlossyGather::CHOICES)?),
                occlusion: match options.choice("occlusion", &["rays", "sum", "union", "off"])? {
                    "off" => OcclusionMode::Off,
                    "union" => OcclusionMode::Union,
                    "sum" => OcclusionMode::Sum,
                    _ => OcclusionMode::Rays,
                },
                weights: match options.choice("weights", &["geometric", "flux"])? {
                    "flux" => Weights::Flux,
                    _ => Weights::Geometric,
                },
                visibility_history: options
                    .get("visibility-history", d.options.visibility_history)?,
                adaptive_rays: options.choice("visibility-rays", &["all", "adaptive"])?
                    == "adaptive",
                gather_slices: gather_slices_option(options)?,
                gather_points: match options.choice("gather-points", &["auto", "4", "8", "16"])? {
                    "auto" => 0,
                    n => n.parse().unwrap_or(0),
                },
                visibility_lookup: VisibilityLookup::parse(
                    options.choice("visibility-lookup", VisibilityLookup::CHOICES)?,
                ),
                gather_vals: ValReads::parse(options.choice("gather-vals", ValReads::CHOICES)?),
            },
            glossy_eye: match options.choice("glossy-eye", &["mid", "per-view"])? {
                "per-view" => GlossyEye::PerView,
                _ => GlossyEye::Mid,
            },
            link_test: options.choice("link-test", &["on", "off"])? == "on",
        })
    }
}

/// `gather-slices`: `auto` (0) or a count in 1..=[`sparse::GATHER_SLICES_MAX`].
fn gather_slices_option(options: &MethodOptions) -> Result<u32, RenderError> {
    let text: String = options.get("gather-slices", "auto".to_string())?;
    match text.trim() {
        "auto" => Ok(0),
        n => match n.parse::<u32>() {
            Ok(n) if (1..=sparse::GATHER_SLICES_MAX).contains(&n) => Ok(n),
            _ => Err(RenderError::Settings(format!(
                "--gather-slices {text}: must be auto or a whole number 1..={}",
                sparse::GATHER_SLICES_MAX
            ))),
        },
    }
}

/// Whether [`default_max_edge`] surveys the scene for these options (budget mode with a FLIP
/// target choosing the point count), so that the caller can hand it the edited scene.
pub fn surveys_for_tessellation(options: &MethodOptions) -> Result<bool, RenderError> {
    let given = options.given("sparse-points");
    Ok(!given && matches!(budget_target(options)?, Some(budget::BudgetTarget::Flip(_))))
}

/// Methods that gather at sparse points (they read the `sparse-points` option).
pub fn uses_sparse_points(method: &str) -> bool {
    matches!(method, "sparse" | "sparse+atlas")
}

/// An imported scene's longest edge for the sparse methods, per spacing of their points: the
/// spacing of twice as many points. Pixels take their lights from their triangle's vertices,
/// so the vertex density bounds the accuracy as well as the point count: on Veach Ajar lit
/// through the door (`src/vals/README.md`) 4096 points on a mesh refined to their own
/// spacing gave 0.86 of the reference's mean indirect light, on one refined to 1/√2 of it
/// 0.96 (8192 points on that mesh: 0.95), for 19 % more frame time on lavapipe.
pub const EDGE_PER_POINT_SPACING: f32 = std::f32::consts::FRAC_1_SQRT_2;

/// The default tessellation of an imported scene for the sparse methods: the spacing of
/// their sparse points (`sparse-points` of `options`) times [`EDGE_PER_POINT_SPACING`], so
/// that no triangle spans more than about half a point's share of area. Finer meshes cost
/// preprocessing and per-vertex work (every vertex links to 8 points); coarser ones blur the
/// points' light across a triangle. `None` for a scene without area.
///
/// Under a FLIP target the count comes from a survey of the scene as it will be rendered:
/// `edited` is the scene with the command line's lights and camera (and that camera's name and
/// the image's aspect); without it the raw scene and its default camera at aspect 1 are
/// surveyed. Returns the edge and why it is that edge.
pub fn default_max_edge(
    scene: &Scene,
    options: &MethodOptions,
    edited: Option<(&Scene, Option<&str>, f32)>,
) -> Result<Option<(f32, String)>, RenderError> {
    let mut points: usize =
        options.get("sparse-points", SparseSettings::default().sparse_points)?;
    if points == 0 {
        return Err(RenderError::Settings(
            "--sparse-points must be at least 1".into(),
        ));
    }
    let given = options.given("sparse-points");
    let mut whose = "its".to_string();
    match (budget_target(options)?, given) {
        (Some(budget::BudgetTarget::Flip(flip)), false) => {
            // Budget mode chooses the point count, and so the tessellation, before the scene
            // is refined: survey it lit and seen as it will be rendered.
            let (surveyed, camera, aspect) = edited.unwrap_or((scene, None, 1.0));
            let world = surveyed.world_from_node_at(0.0);
            let camera = surveyed.camera_view(camera, aspect, &world).ok();
            let glossy = GlossyGather::parse(options.choice("glossy", GlossyGather::CHOICES)?);
            let survey = budget::Survey::new(surveyed, &world, camera.as_ref(), 1)
                .pricing_glossy(glossy, surveyed);
            points = survey.choose(budget::BudgetTarget::Flip(flip)).points;
            whose = format!("the survey's point count for FLIP ≤ {flip}:");
        }
        (Some(budget::BudgetTarget::Ms(_)), false) => {
            // A time budget's point count depends on the device, which is not open yet:
            // tessellate for the densest candidate, whose points a coarser mesh would blur
            // (`valgi render` refines the scene again once the budget has chosen).
            points = *budget::CANDIDATE_POINTS.last().expect("candidates");
            whose = "the densest candidate's (a time budget's point count is measured on the \
                     device, after the scene is refined):"
                .to_string();
        }
        _ => {}
    }
    Ok(points::point_spacing(scene, points).map(|spacing| {
        let edge = spacing * EDGE_PER_POINT_SPACING;
        let why = format!(
            "1/√2 of the spacing of {whose} {points} sparse points ({spacing:.3e} m apart)"
        );
        (edge, why)
    }))
}

/// The sparse method's structs shared with WGSL, for the layout test.
pub fn shared_layouts() -> Vec<crate::raster::types::SharedLayout> {
    use crate::raster::types::shared_layout;
    vec![
        shared_layout!(
            "SparseParams",
            "vals_common.wgsl",
            sparse::SparseParams,
            [
                eye,
                point_count,
                instance_count,
                flags,
                occlusion_mode,
                tile,
                vertex_count,
                rsm_tiles,
                visibility_history
            ]
        ),
        shared_layout!(
            "InstanceRange",
            "vals_common.wgsl",
            sparse::InstanceRange,
            [
                vertex_offset,
                vertex_count,
                point_offset,
                link_offset,
                back_offset
            ]
        ),
    ]
}

/// Milliseconds of the gather: its pass plus, split over VAL slices, the reduction.
pub fn gather_ms(timings: &crate::gpu::PassTimings) -> f64 {
    timings.get("gather").unwrap_or(0.0) + timings.get("gather reduce").unwrap_or(0.0)
}

/// Table 2 of the paper: per-pass milliseconds grouped as its rows.
pub fn table2(timings: &crate::gpu::PassTimings) -> serde_json::Value {
    let get = |l: &str| timings.get(l).unwrap_or(0.0);
    let round = crate::gpu::timing::round3;
    serde_json::json!({
        "rsm": round(get("rsm")),
        "direct": round(get("shadow") + get("gbuffer") + get("direct")),
        "gather": round(gather_ms(timings)),
        "renormalize": round(get("renormalize")),
        "visibility": round(get("visibility")),
        "occlusion": round(get("occlusion")),
        "interpolation": round(get("interpolation")),
        "apply": round(get("apply")),
        "total": round(timings.total_ms()),
    })
}

/// Where the glossy lobes of the solution are aimed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GlossyEye {
    /// One solution for every view, for the mid-eye of the frame's views.
    Mid,
    /// The glossy half re-gathered for each view's own eye; everything else shared.
    PerView,
}

/// The sparse method's options, as the registry lists them.
pub const OPTIONS: &[OptionSpec] = &[
    OptionSpec {
        name: "rsm",
        kind: OptionKind::Int { min: 1, max: 2048 },
        default: "128",
        help: "RSM resolution per light layer: R×R texels, six layers for a point light \
               (not given: at most 128², the lights sharing 6·128² texels by power)",
    },
    OptionSpec {
        name: "sparse-points",
        kind: OptionKind::Int { min: 1, max: 1 << 20 },
        default: "4096",
        help: "sparse receiver points for the whole scene",
    },
    OptionSpec {
        name: "seed",
        kind: OptionKind::Int { min: 0, max: i64::MAX },
        default: "1",
        help: "seed of the sparse-point placement",
    },
    OptionSpec {
        name: "tile",
        kind: OptionKind::Int { min: 1, max: 256 },
        default: "128",
        help: "VALs per workgroup-memory tile in the gather",
    },
    OptionSpec {
        name: "gather",
        kind: OptionKind::Choice(&["compute", "raster"]),
        default: "compute",
        help: "the gather as a compute pass (VALs through workgroup memory, several points per invocation) or as a fragment pass over a point target (the paper's form); same sums",
    },
    OptionSpec {
        name: "gather-points",
        kind: OptionKind::Choice(&["auto", "4", "8", "16"]),
        default: "auto",
        help: "sparse points per compute-gather invocation, each VAL read serving them all (auto: 4 on a GPU; on a CPU device the count that balances the workgroups over its threads, more points where the VALs come through workgroup memory); same sums",
    },
    OptionSpec {
        name: "gather-slices",
        kind: OptionKind::Text,
        default: "auto",
        help: "the compute gather split over this many slices of the VAL list, whose partial sums a second pass adds (auto: whole on a CPU device; on a GPU enough slices for about 1024 workgroups, since a few thousand points alone leave most of a large GPU idle)",
    },
    OptionSpec {
        name: "glossy",
        kind: OptionKind::Choice(GlossyGather::CHOICES),
        default: "auto",
        help: "glossy indirect light (auto: where some material has a specular factor above 0; an all-Lambert scene's glossy term is zero, so only diffuse light is gathered)",
    },
    OptionSpec {
        name: "glossy-eye",
        kind: OptionKind::Choice(&["mid", "per-view"]),
        default: "mid",
        help: "the eye of the glossy gather: one solution at the views' mid-eye, or the glossy half per view",
    },
    OptionSpec {
        name: "link-test",
        kind: OptionKind::Choice(&["on", "off"]),
        default: "on",
        help: "drop the vertex links that pass through other geometry that never moves (a room's wall running under a thin partition would otherwise carry one room's light into the other), renormalizing the rest",
    },
    OptionSpec {
        name: "occlusion",
        kind: OptionKind::Choice(&["rays", "sum", "union", "off"]),
        default: "rays",
        help: "indirect occlusion: from the sparse points' discs (sum, union), none, or shadow rays through the scene's BVH to each VAL cluster (rays)",
    },
    OptionSpec {
        name: "visibility-history",
        kind: OptionKind::Int { min: 0, max: 90 },
        default: "50",
        help: "percent of the last frame's cluster visibility kept in this frame's (--occlusion rays): steadies indirect shadows under moving lights, lags them by about a frame",
    },
    OptionSpec {
        name: "visibility-rays",
        kind: OptionKind::Choice(&["all", "adaptive"]),
        default: "all",
        help: "--occlusion rays: shoot at all 16 sample strata of each RSM tile, or at its 2×2 coarse strata first and at the other 12 only where those disagree (adaptive: fewer rays, partly hidden tiles come out all seen or all hidden)",
    },
    OptionSpec {
        name: "visibility-lookup",
        kind: OptionKind::Choice(VisibilityLookup::CHOICES),
        default: "auto",
        help: "--occlusion rays: how the compute gather picks a VAL's cluster visibility: a select tree (faster on a CPU device, which runs every case of a switch) or a switch (measured on a GPU); auto: the tree on a CPU device, the switch on a GPU",
    },
    OptionSpec {
        name: "gather-vals",
        kind: OptionKind::Choice(ValReads::CHOICES),
        default: "auto",
        help: "how the compute gather reads the VAL list: staged through workgroup memory in tiles (splits over VAL slices to fill a GPU) or from uniform windows of 1024 VALs, one dispatch each (a CPU device reads a VAL the whole workgroup shares far faster from a uniform block); auto: windows on a CPU device unless --gather-slices splits the gather, tiles on a GPU; both give the same bits",
    },
    OptionSpec {
        name: "weights",
        kind: OptionKind::Choice(&["geometric", "flux"]),
        default: "geometric",
        help: "weights of the averaged light positions",
    },
    OptionSpec {
        name: "quality",
        kind: OptionKind::Choice(&["manual", "auto"]),
        default: "manual",
        help: "manual: the options as given; auto: sparse points, RSM side, occlusion (and an imported scene's tessellation) chosen from a survey of the scene for --target-flip or --budget-ms (options given explicitly are kept); the JSON line's `budget` says what and why",
    },
    OptionSpec {
        name: "target-flip",
        kind: OptionKind::Text,
        default: "0.05",
        help: "--quality auto: the indirect FLIP allowed against the fully converged setting (the error the knobs control; 0 < F < 1)",
    },
    OptionSpec {
        name: "budget-ms",
        kind: OptionKind::Text,
        default: "",
        help: "--quality auto: instead of a FLIP target, the most accurate setting whose frame fits this many ms at the render's size on this device, measured by timing pilots (the survey's times, fitted on lavapipe and scaled by this device's FMA peak, say which to time first)",
    },
    OptionSpec {
        name: "budget-pilots",
        kind: OptionKind::Int { min: 0, max: 32 },
        // `budget::DEFAULT_PILOTS` (a test keeps them equal).
        default: "8",
        help: "--quality auto: most pilots before choosing; with a FLIP target small frames (at most 256 pixels on the long side) that measure the survey's candidates against the converged one, with --budget-ms candidates timed at the render's size; 0: the survey's prediction alone",
    },
];

/// `--quality auto`'s target from the options, `None` for `--quality manual`.
pub fn budget_target(options: &MethodOptions) -> Result<Option<budget::BudgetTarget>, RenderError> {
    let auto = options.choice("quality", &["manual", "auto"])? == "auto";
    let flip_text: String = options.get("target-flip", String::new())?;
    let ms_text: String = options.get("budget-ms", String::new())?;
    if !auto {
        if !flip_text.is_empty() || !ms_text.is_empty() {
            return Err(RenderError::Settings(
                "--target-flip and --budget-ms need --quality auto".into(),
            ));
        }
        return Ok(None);
    }
    match (flip_text.is_empty(), ms_text.is_empty()) {
        (false, false) => Err(RenderError::Settings(
            "--quality auto takes --target-flip or --budget-ms, not both".into(),
        )),
        (_, false) => match ms_text.parse::<f64>() {
            Ok(ms) if ms.is_finite() && ms > 0.0 => Ok(Some(budget::BudgetTarget::Ms(ms))),
            _ => Err(RenderError::Settings(format!(
                "--budget-ms {ms_text}: must be a positive number of milliseconds"
            ))),
        },
        (true, true) => Ok(Some(budget::BudgetTarget::Flip(DEFAULT_TARGET_FLIP))),
        (false, true) => match flip_text.parse::<f64>() {
            Ok(f) if f > 0.0 && f < 1.0 => Ok(Some(budget::BudgetTarget::Flip(f))),
            _ => Err(RenderError::Settings(format!(
                "--target-flip {flip_text}: must be a number between 0 and 1 (exclusive)"
            ))),
        },
    }
}

/// `--target-flip`'s default.
pub const DEFAULT_TARGET_FLIP: f64 = 0.05;

/// Applies `--quality auto` to `settings`: surveys `scene` as the render's camera (`camera`,
/// an index; `None`: the scene's first) sees it at time 0 in an image of `aspect`, prices the
/// per-pixel passes for frames shading `frame_pixels` (width × height × SSAA² × views),
/// chooses, and sets every budget knob the options do not give explicitly. Returns the JSON
/// `budget` report: per knob its value and why.
///
/// `pilots` measure candidates: under a FLIP target [`Pilots::Flip`] renders a candidate's
/// settings to its indirect image for the pilot search ([`budget::Survey::search`]), under a
/// time budget [`Pilots::Time`] times its frames ([`budget::timed::search`]); `None`, a kind
/// that does not match the target, or `budget-pilots=0` chooses by the survey's prediction
/// alone.
pub fn apply_budget(
    scene: &Scene,
    (camera, aspect, frame_pixels): (Option<usize>, f32, f64),
    options: &MethodOptions,
    target: budget::BudgetTarget,
    device_fma_peak: Option<f64>,
    settings: &mut SparseSettings,
    pilots: Option<Pilots<'_>>,
) -> Result<serde_json::Value, RenderError> {
    let world = scene.world_from_node_at(0.0);
    let selector = camera.map(|i| i.to_string());
    let camera = scene
        .camera_view(selector.as_deref(), aspect, &world)
        .map_err(|e| RenderError::Settings(e.to_string()))?;
    let mut survey = budget::Survey::new(scene, &world, Some(&camera), settings.seed)
        .pricing_glossy(settings.options.glossy, scene)
        .shading(frame_pixels);
    if let Some(peak) = device_fma_peak.filter(|p| *p > 0.0 && p.is_finite()) {
        survey.time_scale = budget::model::FIT_FMA_PEAK / peak;
    }
    let given = |key: &str| options.given(key);
    let (searched, timed) = match (target, pilots) {
        (budget::BudgetTarget::Flip(flip), Some(Pilots::Flip(pilot)))
            if pilot.count > 0 && !survey.is_dark() =>
        {
            let searched =
                search_with_pilots(&survey, options, settings, flip, pilot, (&world, &camera))?;
            (searched, None)
        }
        (budget::BudgetTarget::Ms(ms), Some(Pilots::Time(pilot)))
            if pilot.count > 0 && !survey.is_dark() =>
        {
            let timed = time_with_pilots(&survey, options, settings, ms, pilot, (&world, &camera))?;
            (None, timed)
        }
        _ => (None, None),
    };
    let choice = match (&searched, &timed) {
        (Some((search, _)), _) => search.choice,
        (None, Some((search, _))) => search.choice,
        (None, None) => survey.choose(target),
    };
    // Knobs given explicitly stay; the prediction is for the setting actually used.
    *settings = with_candidate(settings, &choice, given);
    // `union` is priced as no occlusion (it shoots no rays).
    let used_visibility = visibility_of(settings).unwrap_or(budget::Visibility::Off);
    let used = survey.predict(settings.sparse_points, settings.rsm, used_visibility);
    // The setting used, by the timing pilots' fit (a knob given explicitly may have moved it
    // off every pilot).
    let fitted_ms = timed.as_ref().map(|(search, _)| {
        search
            .fit
            .time_ms(used.predicted_ms - survey.predicted_fixed_ms())
    });
    let met = match (target, &searched, &timed) {
        (_, Some((search, _)), _) => search.choice.met,
        // The setting used: a knob given explicitly may have moved it off the candidate.
        (_, None, Some((search, _))) if search.choice.same_setting(&used) => search.choice.met,
        (budget::BudgetTarget::Ms(ms), None, Some(_)) => fitted_ms.is_some_and(|t| t <= ms),
        (budget::BudgetTarget::Flip(f), None, _) => used.predicted_flip <= f,
        (budget::BudgetTarget::Ms(ms), None, None) => used.predicted_ms <= ms,
    };
    let overridden = ["sparse-points", "rsm", "occlusion", "visibility-rays"]
        .iter()
        .any(|k| given(k));
    let target_text = match (target, &searched) {
        (budget::BudgetTarget::Flip(f), Some((_, run))) => format!(
            "measured FLIP ≤ {f} against the converged candidate, in pilot frames of {}×{}",
            run.size.0, run.size.1
        ),
        (budget::BudgetTarget::Flip(f), None) => format!("predicted FLIP ≤ {f}"),
        (budget::BudgetTarget::Ms(ms), _) => match &timed {
            Some((_, run)) => format!(
                "frame ≤ {ms} ms at {}×{}{} on this device, timed by pilots",
                run.size.0,
                run.size.1,
                match run.views {
                    1 => String::new(),
                    n => format!(" through {n} views"),
                }
            ),
            None => format!("predicted frame ≤ {ms} ms"),
        },
    };
    let why = |key: &str, chosen: String| -> String {
        if given(key) {
            "given".to_string()
        } else {
            chosen
        }
    };
    // The search fell back on the converged candidate: no cheaper pilot met the target.
    let converged_kept = searched
        .as_ref()
        .is_some_and(|(search, run)| search.choice.same_setting(&run.converged));
    // The converged candidate is itself predicted to miss the target, the one way a search
    // misses it (`budget::PilotSearch::converged_flip`): what the pilots measured against it
    // cannot meet the target.
    let converged_short = searched
        .as_ref()
        .is_some_and(|(search, _)| !search.choice.met);
    let round3 = crate::gpu::timing::round3;
    let pilot_report = searched.as_ref().map(|(search, run)| {
        serde_json::json!({
            "size": [run.size.0, run.size.1],
            "ms": round3(run.ms),
            "converged": candidate_json(&run.converged, None),
            "converged_predicted_flip": round3(search.converged_flip),
            "measured": search
                .pilots
                .iter()
                .map(|p| candidate_json(&p.choice, Some(p.measured_flip)))
                .collect::<Vec<_>>(),
            "chosen_measured_flip": round3(search.measured_flip),
        })
    });
    let timing_report = timed.as_ref().map(|(search, run)| {
        serde_json::json!({
            "size": [run.size.0, run.size.1],
            "views": run.views,
            "frames": budget::timed::TIMING_FRAMES,
            "ms": round3(run.ms),
            "fit": {
                "fixed_ms": round3(search.fit.fixed_ms),
                "work_scale": round3(search.fit.work_scale),
                "predicted_fixed_ms": round3(survey.predicted_fixed_ms()),
            },
            "measured": search
                .pilots
                .iter()
                .map(|p| {
                    let mut c = candidate_json(&p.choice, None);
                    if let Some(fields) = c.as_object_mut() {
                        fields.remove("measured_flip");
                        fields.insert("measured_ms".into(), serde_json::json!(round3(p.measured_ms)));
                    }
                    c
                })
                .collect::<Vec<_>>(),
            "chosen_measured_ms": search.measured_ms.map(round3),
            "fitted_ms": fitted_ms.map(round3),
            "accuracy": run.accuracy.as_ref().map(|a| serde_json::json!({
                "size": [a.size.0, a.size.1],
                "converged": candidate_json(&a.converged, None),
                "measured": a
                    .search
                    .pilots
                    .iter()
                    .map(|p| candidate_json(&p.choice, Some(p.measured_flip)))
                    .collect::<Vec<_>>(),
                "chosen_measured_flip": a.search.choice.filter(|p| p.choice.same_setting(&search.choice)).map(|p| round3(p.measured_flip)),
                "changed_choice": a.changed,
            })),
        })
    });
    Ok(serde_json::json!({
        "target": target_text,
        "pilots": pilot_report,
        "timing_pilots": timing_report,
        "target_flip": match target {
            budget::BudgetTarget::Flip(f) => Some(f),
            budget::BudgetTarget::Ms(_) => None,
        },
        "budget_ms": match target {
            budget::BudgetTarget::Flip(_) => None,
            budget::BudgetTarget::Ms(ms) => Some(ms),
        },
        "met": met,
        "predicted_flip": crate::gpu::timing::round3(used.predicted_flip),
        "predicted_ms": crate::gpu::timing::round3(used.predicted_ms),
        "survey_ms": crate::gpu::timing::round3(survey.survey_ms),
        "surveyed_from": survey.eye.map(|e| [e.x, e.y, e.z]),
        "time_scale": survey.time_scale,
        // The pixels a frame shades, and the part of its predicted time no knob changes.
        "frame_pixels": survey.frame_pixels,
        "predicted_fixed_ms": crate::gpu::timing::round3(survey.predicted_fixed_ms()),
        // The chosen gather's cost per pair relative to the fitted one: with or without the
        // glossy lobes (`glossy auto` on an all-Lambert scene, or `off`), with or without the
        // cluster visibility.
        "gather_cost": budget::model::gather_cost(survey.gathers_glossy, used.visibility.rays()),
        "device_fma_peak": device_fma_peak,
        "sparse_points": {
            "value": settings.sparse_points,
            "why": why("sparse-points", format!(
                "spacing {:.3e} m over {:.3e} m² of surface; radiance varies {:.3} over that distance (ε + δ)",
                survey.point_spacing(settings.sparse_points), survey.area, used.variation)),
        },
        "rsm": {
            "value": settings.rsm,
            "why": why("rsm", format!(
                "{:.0} VALs {:.3e} m apart over {:.3e} m² lit; their interpolation error ε {:.4}",
                survey.val_count(settings.rsm), survey.val_spacing(settings.rsm),
                survey.lit_area, used.val_error)),
        },
        "occlusion": {
            "value": settings.options.occlusion.name(),
            "why": why("occlusion", if settings.options.occlusion == OcclusionMode::Rays {
                format!("geometry blocks {:.3} of the one-bounce light the camera sees: rays to {} clusters per point",
                    survey.occluded_share, survey.clusters)
            } else if settings.options.occlusion == OcclusionMode::Sum {
                format!("geometry blocks {:.3} of the one-bounce light the camera sees: the points' discs, summed, measured close enough by the pilots",
                    survey.occluded_share)
            } else {
                format!("geometry blocks only {:.3} of the one-bounce light the camera sees: no occlusion",
                    survey.occluded_share)
            }),
        },
        "visibility_rays": {
            "value": visibility_rays_value(settings.options.adaptive_rays),
            "why": why("visibility-rays", match used.visibility {
                budget::Visibility::Off | budget::Visibility::Sum => "no rays".to_string(),
                budget::Visibility::Rays => format!(
                    "every stratum: settling a cluster tile by its coarse strata would get {:.3} of the light wrong",
                    survey.partial_share),
                budget::Visibility::AdaptiveRays => format!(
                    "coarse strata first: settling a cluster tile by them gets only {:.3} of the light wrong, for about {:.0} % of the rays",
                    survey.partial_share, 100.0 * budget::model::ADAPTIVE_RAY_COST),
            }),
        },
        "choice": match (overridden, choice.met) {
            _ if survey.is_dark() => "no light reaches a surface the camera sees: nothing to budget, the cheapest candidate",
            _ if converged_short && converged_kept => "the converged candidate, itself predicted to miss the target (pilots.converged_predicted_flip): no candidate reaches it in this scene (knobs given explicitly kept)",
            _ if converged_short => "the cheapest candidate the pilot frames measured within the target of the converged one, which is itself predicted to miss it (pilots.converged_predicted_flip): no candidate reaches it in this scene (knobs given explicitly kept)",
            _ if converged_kept => "no pilot met the target: the converged candidate (knobs given explicitly kept)",
            _ if searched.is_some() => "the cheapest candidate the pilot frames measured meeting the target (knobs given explicitly kept)",
            _ if timed.as_ref().is_some_and(|(s, _)| !s.choice.met) => "no candidate fits the budget, by the timing pilots: the cheapest (knobs given explicitly kept)",
            _ if timed.as_ref().is_some_and(|(_, run)| run.accuracy.as_ref().is_some_and(|a| a.changed)) => "the most accurate candidate the pilot frames measured among those the timing pilots put within the budget, timed within it (knobs given explicitly kept)",
            _ if timed.as_ref().is_some_and(|(s, _)| s.measured_ms.is_some()) => "the most accurate candidate a timing pilot measured within the budget (knobs given explicitly kept)",
            _ if timed.is_some() => "the most accurate candidate the timing pilots' fit puts within the budget, not itself timed (knobs given explicitly kept)",
            (true, _) => "the best choice for the knobs not given; the prediction is for the setting used",
            (false, true) => match target {
                budget::BudgetTarget::Flip(_) => "the cheapest predicted setting meeting the target",
                budget::BudgetTarget::Ms(_) => "the most accurate predicted setting within the budget",
            },
            (false, false) => "no candidate meets the target: the closest one",
        },
    }))
}

/// The pilot frames of budget mode: how many, and how to render one.
pub struct PilotFrames<'a> {
    /// Most pilots after the converged one (`budget-pilots`).
    pub count: usize,
    /// Their size (width, height).
    pub size: (u32, u32),
    pub render: &'a mut RenderPilot<'a>,
}

/// Renders settings to the indirect image of one pilot frame, seen from the camera the
/// survey looks from with the scene's nodes where they stand.
pub type RenderPilot<'a> =
    dyn FnMut(&SparseSettings, &[Mat4], &CameraView) -> Result<Image, RenderError> + 'a;

/// The pilots of budget mode under `--budget-ms`: how many candidates to time and how, and
/// the small frames that then rank the candidates within the budget by accuracy.
pub struct TimingPilots<'a> {
    /// Most candidates timed (`budget-pilots`).
    pub count: usize,
    /// The render's size (width, height), which they run at.
    pub size: (u32, u32),
    /// Views per frame, as the render's frames record them.
    pub views: u32,
    pub time: &'a mut TimePilot<'a>,
    pub frames: PilotFrames<'a>,
}

/// Renders settings for [`budget::timed::TIMING_FRAMES`] frames at the render's size and
/// through its number of views, seen from the survey's camera, and returns the longest frame
/// time after the first, ms.
pub type TimePilot<'a> =
    dyn FnMut(&SparseSettings, &[Mat4], &CameraView) -> Result<f64, RenderError> + 'a;

/// What measures budget mode's candidates, by its target.
pub enum Pilots<'a> {
    Flip(PilotFrames<'a>),
    Time(TimingPilots<'a>),
}

/// What the pilot frames cost, for the report.
struct PilotRun {
    size: (u32, u32),
    ms: f64,
    converged: budget::BudgetChoice,
}

/// Longest side of a pilot frame, pixels.
pub const PILOT_MAX_SIDE: u32 = 256;

/// The pilots' size for a `width`×`height` image: the same aspect, at most
/// [`PILOT_MAX_SIDE`] on the long side (the gather and visibility, which the knobs price, do
/// not depend on it; the per-pixel passes do).
pub fn pilot_size(width: u32, height: u32) -> (u32, u32) {
    let long = width.max(height).max(1);
    if long <= PILOT_MAX_SIDE {
        return (width.max(1), height.max(1));
    }
    let scale = PILOT_MAX_SIDE as f64 / long as f64;
    let side = |v: u32| ((v as f64 * scale).round() as u32).max(1);
    (side(width), side(height))
}

/// `settings` with a candidate's knobs, except those `given` names (the options given
/// explicitly, which stay).
fn with_candidate(
    settings: &SparseSettings,
    choice: &budget::BudgetChoice,
    given: impl Fn(&str) -> bool,
) -> SparseSettings {
    let mut out = *settings;
    if !given("sparse-points") {
        out.sparse_points = choice.points;
    }
    if !given("rsm") {
        // The side the model priced is every light's own.
        out.rsm = choice.rsm;
        out.rsm_texels = None;
    }
    if !given("occlusion") {
        out.options.occlusion = match choice.visibility {
            budget::Visibility::Off => OcclusionMode::Off,
            budget::Visibility::Sum => OcclusionMode::Sum,
            budget::Visibility::Rays | budget::Visibility::AdaptiveRays => OcclusionMode::Rays,
        };
    }
    if !given("visibility-rays") {
        out.options.adaptive_rays = choice.visibility == budget::Visibility::AdaptiveRays;
    }
    out
}

/// The budget candidates' visibility these settings run; `None` for `union`, which is no
/// candidate.
fn visibility_of(settings: &SparseSettings) -> Option<budget::Visibility> {
    match (settings.options.occlusion, settings.options.adaptive_rays) {
        (OcclusionMode::Off, _) => Some(budget::Visibility::Off),
        (OcclusionMode::Sum, _) => Some(budget::Visibility::Sum),
        (OcclusionMode::Rays, false) => Some(budget::Visibility::Rays),
        (OcclusionMode::Rays, true) => Some(budget::Visibility::AdaptiveRays),
        (OcclusionMode::Union, _) => None,
    }
}

/// The survey's candidates the knobs given explicitly allow.
fn allowed_candidates(
    survey: &budget::Survey,
    options: &MethodOptions,
    settings: &SparseSettings,
) -> Vec<budget::BudgetChoice> {
    let given = |key: &str| options.given(key);
    // The visibility the options pin, if they pin one; `Some(None)` for `occlusion=union`,
    // which is no candidate.
    let pinned_visibility =
        (given("occlusion") || given("visibility-rays")).then_some(visibility_of(settings));
    survey.candidates(|points, rsm, visibility| {
        (!given("sparse-points") || points == settings.sparse_points)
            && (!given("rsm") || rsm == settings.rsm)
            && pinned_visibility.is_none_or(|v| v == Some(visibility))
    })
}

/// A pilot's failure that passes its candidate over (beyond `--gpu-memory`, a mesh given
/// more points than its links address: a candidate the render could not use either), with a
/// warning; cancelling stops the search.
fn passed_over<T>(
    result: Result<T, RenderError>,
    choice: &budget::BudgetChoice,
) -> Result<Option<T>, RenderError> {
    match result {
        Ok(value) => Ok(Some(value)),
        Err(RenderError::Cancelled(c)) => Err(RenderError::Cancelled(c)),
        Err(e) => {
            eprintln!(
                "warning: budget mode: pilot of {} points, RSM {}, {:?} failed ({e}); passed over",
                choice.points, choice.rsm, choice.visibility
            );
            Ok(None)
        }
    }
}

/// Runs the timing search over the candidates the explicitly given knobs allow; `None` when
/// they allow none (a knob given outside the candidates' range, `occlusion=union`).
fn time_with_pilots(
    survey: &budget::Survey,
    options: &MethodOptions,
    settings: &SparseSettings,
    budget_ms: f64,
    pilot: TimingPilots<'_>,
    (world_from_node, camera): (&[Mat4], &CameraView),
) -> Result<Option<(budget::timed::TimeSearch, TimingRun)>, RenderError> {
    let started = Instant::now();
    let candidates = allowed_candidates(survey, options, settings);
    let fixed = survey.predicted_fixed_ms();
    let time = pilot.time;
    let mut time_one = |choice: &budget::BudgetChoice| {
        let measured = time(
            &with_candidate(settings, choice, |_| false),
            world_from_node,
            camera,
        );
        let ms = passed_over(measured, choice)?.unwrap_or(f64::NAN);
        log::info!(
            "budget mode: timing pilot {} points, RSM {}, {:?}: {ms:.1} ms (predicted {:.1})",
            choice.points,
            choice.rsm,
            choice.visibility,
            choice.predicted_ms
        );
        Ok::<_, RenderError>(ms)
    };
    let Some(mut search) =
        budget::timed::search(&candidates, budget_ms, fixed, pilot.count, &mut time_one)?
    else {
        return Ok(None);
    };
    let accuracy = rank_within_budget(
        &candidates,
        &mut search,
        budget_ms,
        fixed,
        pilot.frames,
        &mut time_one,
        (settings, world_from_node, camera),
    )?;
    let run = TimingRun {
        size: pilot.size,
        views: pilot.views,
        ms: started.elapsed().as_secs_f64() * 1000.0,
        accuracy,
    };
    Ok(Some((search, run)))
}

/// The accuracy pilots under a time budget, for the report.
struct AccuracyRun {
    converged: budget::BudgetChoice,
    size: (u32, u32),
    search: budget::WithinSearch,
    /// Whether their choice replaced the timing search's.
    changed: bool,
}

/// Ranks the candidates the timing search puts within the budget by measured accuracy
/// ([`budget::Survey::search_within`], small frames against the richest candidate), and
/// takes the most accurate once a timing pilot has measured it within the budget (timing it
/// if none has). Nothing to rank when the timing search kept the richest candidate, missed the
/// budget, or left one candidate within it; `None` then, or when the richest candidate does
/// not render.
fn rank_within_budget(
    candidates: &[budget::BudgetChoice],
    search: &mut budget::timed::TimeSearch,
    budget_ms: f64,
    fixed_predicted_ms: f64,
    frames: PilotFrames<'_>,
    time_one: &mut dyn FnMut(&budget::BudgetChoice) -> Result<f64, RenderError>,
    (settings, world_from_node, camera): (&SparseSettings, &[Mat4], &CameraView),
) -> Result<Option<AccuracyRun>, RenderError> {
    let eligible: Vec<&budget::BudgetChoice> = candidates
        .iter()
        .filter(|c| c.visibility != budget::Visibility::Sum)
        .collect();
    let Some(converged) = eligible.iter().max_by_key(|c| c.richness()).copied() else {
        return Ok(None);
    };
    let within: Vec<budget::BudgetChoice> = eligible
        .iter()
        .filter(|c| search.time_of(c, fixed_predicted_ms) <= budget_ms)
        .map(|c| **c)
        .collect();
    if frames.count == 0
        || !search.choice.met
        || search.choice.same_setting(converged)
        || within.len() < 2
    {
        return Ok(None);
    }
    let view = (settings, world_from_node, camera);
    let Some(mut probe) = ConvergenceProbe::new(frames.render, view, [converged])? else {
        return Ok(None);
    };
    let ranked = budget::Survey::search_within(&within, converged, frames.count, |choice| {
        probe.measure("accuracy pilot", choice)
    })?;
    let mut changed = false;
    if let Some(best) = ranked
        .choice
        .filter(|b| !b.choice.same_setting(&search.choice))
    {
        // The fit put it within the budget; a measurement decides.
        let known = search
            .pilots
            .iter()
            .any(|p| p.choice.same_setting(&best.choice));
        if !known {
            let measured_ms = time_one(&best.choice)?;
            search.add_pilot(
                budget::timed::TimedPilot {
                    choice: best.choice,
                    measured_ms,
                },
                fixed_predicted_ms,
            );
        }
        let measured_ms = search.time_of(&best.choice, fixed_predicted_ms);
        if measured_ms <= budget_ms {
            search.choice = budget::BudgetChoice {
                met: true,
                ..best.choice
            };
            search.measured_ms = Some(measured_ms);
            changed = true;
        }
    }
    Ok(Some(AccuracyRun {
        converged: *converged,
        size: frames.size,
        search: ranked,
        changed,
    }))
}

/// What the timing pilots cost, for the report.
struct TimingRun {
    size: (u32, u32),
    views: u32,
    ms: f64,
    accuracy: Option<AccuracyRun>,
}

/// Runs the pilot search over the candidates the explicitly given knobs allow.
fn search_with_pilots(
    survey: &budget::Survey,
    options: &MethodOptions,
    settings: &SparseSettings,
    target_flip: f64,
    pilot: PilotFrames<'_>,
    (world_from_node, camera): (&[Mat4], &CameraView),
) -> Result<Option<(budget::PilotSearch, PilotRun)>, RenderError> {
    let started = Instant::now();
    let candidates = allowed_candidates(survey, options, settings);
    // The converged image: the richest candidate that renders. A knob given outside the
    // candidates' range (or `occlusion=union`) leaves nothing to measure, and then, as when
    // nothing renders, the survey's prediction decides.
    let mut by_rank = candidates.clone();
    by_rank.sort_by_key(|c| std::cmp::Reverse(c.richness()));
    let view = (settings, world_from_node, camera);
    let Some(mut probe) = ConvergenceProbe::new(pilot.render, view, by_rank.iter().take(3))? else {
        return Ok(None);
    };
    let converged = probe.converged;
    let search = budget::Survey::search(
        &candidates,
        &converged,
        target_flip,
        pilot.count,
        |choice| probe.measure("pilot", choice),
    )?;
    let run = PilotRun {
        size: pilot.size,
        ms: started.elapsed().as_secs_f64() * 1000.0,
        converged,
    };
    Ok(Some((search, run)))
}

/// Pilot frames that measure candidates' convergence FLIP against a converged image: the
/// first of the given candidates that renders. Under a FLIP target and, within a time budget,
/// for accuracy.
struct ConvergenceProbe<'r, 'a, 'v> {
    render: &'r mut RenderPilot<'a>,
    view: (&'v SparseSettings, &'v [Mat4], &'v CameraView),
    converged: budget::BudgetChoice,
    reference: Image,
    exposure: f32,
}

impl<'r, 'a, 'v> ConvergenceProbe<'r, 'a, 'v> {
    /// `None` when none of `converged_first` renders.
    fn new<'c>(
        render: &'r mut RenderPilot<'a>,
        view: (&'v SparseSettings, &'v [Mat4], &'v CameraView),
        converged_first: impl IntoIterator<Item = &'c budget::BudgetChoice>,
    ) -> Result<Option<Self>, RenderError> {
        for choice in converged_first {
            if let Some(reference) = pilot_image(render, view, choice)? {
                let exposure = crate::image_io::compare::auto_exposure(&reference);
                return Ok(Some(Self {
                    render,
                    view,
                    converged: *choice,
                    reference,
                    exposure,
                }));
            }
        }
        Ok(None)
    }

    /// A candidate's convergence FLIP (NaN when its frame failed and it was passed over),
    /// logged as a `kind` pilot.
    fn measure(&mut self, kind: &str, choice: &budget::BudgetChoice) -> Result<f64, RenderError> {
        let measured = pilot_image(self.render, self.view, choice)?.map_or(f64::NAN, |image| {
            crate::image_io::compare::flip(&image, &self.reference, self.exposure)
        });
        log::info!(
            "budget mode: {kind} {} points, RSM {}, {:?}: FLIP {measured:.4} (predicted {:.4})",
            choice.points,
            choice.rsm,
            choice.visibility,
            choice.predicted_flip
        );
        Ok(measured)
    }
}

/// One pilot frame of a candidate's settings; `None` when it failed and is passed over.
fn pilot_image(
    render: &mut RenderPilot<'_>,
    (settings, world_from_node, camera): (&SparseSettings, &[Mat4], &CameraView),
    choice: &budget::BudgetChoice,
) -> Result<Option<Image>, RenderError> {
    let image = render(
        &with_candidate(settings, choice, |_| false),
        world_from_node,
        camera,
    );
    passed_over(image, choice)
}

/// A candidate for the JSON report.
fn candidate_json(c: &budget::BudgetChoice, measured_flip: Option<f64>) -> serde_json::Value {
    let round3 = crate::gpu::timing::round3;
    serde_json::json!({
        "points": c.points,
        "rsm": c.rsm,
        "visibility": match c.visibility {
            budget::Visibility::Off => "off",
            budget::Visibility::Rays => "rays",
            budget::Visibility::AdaptiveRays => "rays adaptive",
            budget::Visibility::Sum => "sum",
        },
        "predicted_flip": round3(c.predicted_flip),
        "predicted_ms": round3(c.predicted_ms),
        "measured_flip": measured_flip.map(round3),
    })
}

pub static ENTRY: Entry = Entry {
    name: "sparse",
    help: "direct + one-bounce diffuse and glossy light from RSM virtual area lights gathered at sparse model-space points",
    options: OPTIONS,
    create,
};

pub struct SparseMethod {
    pub settings: SparseSettings,
    pub raster: Rasterizer,
    pub rsm: Rsm,
    pub sparse: SparseGpu,
    pub points: Vec<Arc<MeshPoints>>,
    /// Run the frame only up to this pass (tests read intermediate buffers).
    pub last_stage: Stage,
    pub preprocess_ms: f64,
    /// Meshes whose points were computed rather than taken from the cache.
    pub meshes_computed: usize,
    /// What the link test dropped.
    pub link_cut: points::LinkCut,
    /// Further indirect light added after the apply pass (`None` for `--method sparse`).
    pub layer: Option<Box<dyn IndirectLayer>>,
    /// VALs from outside the RSM (a depth sensor's surfels), appended to the RSM's.
    pub val_source: Option<Box<dyn ValSource>>,
    /// Per-view parameter blocks and kernel bindings (`--glossy-eye per-view`).
    per_view: ViewCache<(wgpu::Buffer, KernelGroups)>,
    report: serde_json::Map<String, serde_json::Value>,
    /// What `--quality auto` chose and why (`None` for manual settings).
    pub budget: Option<serde_json::Value>,
    /// The options with that choice written in as manual knobs (`None` for manual settings).
    resolved_options: Option<Vec<(String, String)>>,
}

impl SparseMethod {
    pub fn new(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        settings: SparseSettings,
    ) -> Result<Self, RenderError> {
        Self::with_val_source(ctx, scene, render, settings, None)
    }

    /// The sparse method gathering `val_source`'s VALs along with the RSM's.
    pub fn with_val_source(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        settings: SparseSettings,
        val_source: Option<Box<dyn ValSource>>,
    ) -> Result<Self, RenderError> {
        Self::from_cache(ctx, &SceneCache::new(scene), render, settings, val_source)
    }

    /// The sparse method over `cache`'s scene, taking from `cache` what an earlier build over
    /// it made (budget mode's pilots) and leaving there what this one makes.
    pub fn from_cache(
        ctx: &GpuContext,
        cache: &SceneCache<'_>,
        render: RenderSettings,
        settings: SparseSettings,
        val_source: Option<Box<dyn ValSource>>,
    ) -> Result<Self, RenderError> {
        let scene = cache.scene;
        // A bad size fails before any upload.
        crate::frame::check_size(ctx, render.width, render.height, render.ssaa)?;
        let raster = Rasterizer::over(ctx, scene, render, cache.scene_gpu(ctx)?)?;
        let rsm = Rsm::with_external(
            ctx,
            scene,
            &raster,
            settings.rsm,
            settings.rsm_texels,
            val_source.as_ref().map(|s| s.external()),
        )?;
        let started = Instant::now();
        let PreparedPoints {
            points,
            link_cut,
            meshes_computed,
        } = cache.points(settings.sparse_points, settings.seed, settings.link_test)?;
        let preprocess_ms = started.elapsed().as_secs_f64() * 1000.0;
        let sensor = val_source
            .as_ref()
            .and_then(|source| source.external().sensor.as_ref());
        let sparse = SparseGpu::new(
            ctx,
            scene,
            (&raster.scene_gpu, cache.mesh_bvhs(ctx)?),
            &points,
            &rsm,
            sensor,
        )?;
        Ok(Self {
            settings,
            raster,
            rsm,
            sparse,
            points,
            last_stage: Stage::Apply,
            preprocess_ms,
            meshes_computed,
            link_cut,
            layer: None,
            val_source,
            per_view: ViewCache::default(),
            report: Default::default(),
            budget: None,
            resolved_options: None,
        })
    }

    /// GPU bytes of the sparse solution alone (points, links, vertex lights).
    pub fn solution_bytes(&self) -> u64 {
        self.sparse.bytes.0 + self.sparse.gather_partial_bytes()
    }
}

impl Method for SparseMethod {
    fn name(&self) -> &'static str {
        self.layer.as_ref().map_or("sparse", |l| l.method_name())
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
        let opts = self.settings.options;
        self.raster
            .update_and_record(ctx, frame.scene, frame.world_from_node, passes)?;
        self.rsm.prepare(ctx, frame.scene, frame.world_from_node);
        self.sparse.prepare(ctx, frame.solution_eye, &opts);
        if opts.occlusion == OcclusionMode::Rays {
            self.sparse
                .prepare_bvh(ctx, frame.scene, frame.world_from_node);
        }
        self.per_view.retain(views);
        if let Some(layer) = &mut self.layer {
            layer.update(ctx, frame, views);
        }
        if let Some(source) = &mut self.val_source {
            source.record(ctx, passes)?;
        }
        self.rsm.record(passes, &self.raster.scene_gpu)?;
        self.sparse
            .record_solution(passes, &opts, self.last_stage.min(Stage::Interpolate))?;
        Ok(())
    }

    fn record_view(
        &mut self,
        ctx: &GpuContext,
        _frame: &FrameInput,
        view: &View,
        passes: &mut Passes,
    ) -> Result<ViewResult, RenderError> {
        let opts = self.settings.options;
        self.raster.record_view_base(ctx, view, passes)?;
        if self.last_stage < Stage::Apply {
            return Ok(ViewResult::Direct);
        }
        if self.settings.glossy_eye == GlossyEye::PerView && self.sparse.gathers_glossy(&opts) {
            let sparse = &self.sparse;
            let (params, groups) = self.per_view.get_or_try_insert(view, || {
                let mut bytes = crate::gpu::GpuBytes::default();
                let params =
                    bytes.params::<sparse::SparseParams>(&ctx.device, "view sparse params");
                let groups = sparse.bind_kernels(&ctx.device, &params);
                Ok((params, groups))
            })?;
            let block = sparse.params(view.camera.position(), &opts, true);
            ctx.queue
                .write_buffer(params, 0, bytemuck::bytes_of(&block));
            sparse.record_view_glossy(passes, &opts, groups)?;
        }
        let (sparse, scene_gpu) = (&self.sparse, &self.raster.scene_gpu);
        match &mut self.layer {
            None => sparse.record_apply(
                ctx,
                passes,
                scene_gpu,
                view,
                &view.targets.radiance_indirect,
            )?,
            Some(layer) => layer.record_view(ctx, view, passes, &mut |passes, target| {
                sparse.record_apply(ctx, passes, scene_gpu, view, target)
            })?,
        }
        Ok(ViewResult::DirectAndIndirect)
    }

    fn end_frame(&mut self, ctx: &GpuContext, timings: &FrameTimings) -> Result<(), RenderError> {
        let opts = self.settings.options;
        let vals = self.rsm.read_count(ctx)?;
        let (clamped_d, clamped_s) = self.sparse.read_clamps(ctx)?;
        let points = self.sparse.point_count.max(1) as f64;
        let per_point = (self.sparse.point_bytes as f64) / points;
        let vertices = self.sparse.vertex_count.max(1) as f64;
        let solution = self.solution_bytes();
        self.report = serde_json::json!({
            "table2": table2(&timings.merged()),
            "vals": vals,
            "rsm": self.settings.rsm,
            // Each light's view side: below `rsm` where the lights share texels.
            "rsm_light_sides": self.rsm.light_sides,
            "sparse_points": self.sparse.point_count,
            "instance_vertices": self.sparse.vertex_count,
            "tile": opts.tile,
            "gather": format!("{:?}", opts.gather).to_lowercase(),
            "gather_slices": match opts.gather {
                GatherForm::Compute => self.sparse.gather_slices(&opts),
                GatherForm::Raster => 1,
            },
            "gather_points_per_invocation": match opts.gather {
                GatherForm::Compute => self.sparse.gather_points_per_invocation(&opts),
                GatherForm::Raster => 1,
            },
            "glossy": format!("{:?}", opts.glossy).to_lowercase(),
            "glossy_gathered": self.sparse.gathers_glossy(&opts),
            "spheres_gathered": self.sparse.gathers_spheres(&opts),
            "glossy_eye": match self.settings.glossy_eye { GlossyEye::Mid => "mid", GlossyEye::PerView => "per-view" },
            "occlusion": opts.occlusion.name(),
            "weights": format!("{:?}", opts.weights).to_lowercase(),
            "visibility_rays": visibility_rays_value(opts.adaptive_rays),
            "visibility_lookup": if self.sparse.visibility_select_tree(&opts) { "tree" } else { "switch" },
            "gather_vals": match opts.gather {
                GatherForm::Compute => ValReads::name(self.sparse.gathers_in_windows(&opts)),
                GatherForm::Raster => "buffer",
            },
            "preprocess_ms": crate::gpu::timing::round3(self.preprocess_ms),
            "preprocess_meshes_computed": self.meshes_computed,
            "link_test": if self.settings.link_test { "on" } else { "off" },
            "links_cut": self.link_cut.links,
            "link_rows_kept": self.link_cut.kept_rows,
            "renormalize_clamped": [clamped_d, clamped_s],
            "solution_gpu_bytes": solution,
            "bytes_per_point": per_point,
            "vertex_light_bytes_per_vertex": self.sparse.vertex_light_bytes as f64 / vertices,
            "link_bytes": self.sparse.link_bytes,
        })
        .as_object()
        .cloned()
        .unwrap_or_default();
        if let Some(layer) = &self.layer {
            self.report.extend(layer.report());
        }
        if let Some(source) = &self.val_source {
            self.report.extend(source.report());
        }
        Ok(())
    }

    fn debug_points(&self) -> Option<crate::frame::DebugPointSource<'_>> {
        Some(self.sparse.debug_points(&self.raster.scene_gpu))
    }

    fn debug_vals(&self) -> Option<crate::frame::DebugValSource<'_>> {
        Some(self.rsm.debug_vals())
    }

    fn set_debug_atlas(&mut self, on: bool) -> bool {
        self.layer.as_mut().is_some_and(|l| l.set_debug_atlas(on))
    }

    fn debug_pick(
        &self,
        scene: &Scene,
        world_from_node: &[Mat4],
        pick: &crate::scene::pick::ScenePick,
        eye: glam::Vec3,
    ) -> Option<crate::frame::DebugPick> {
        points::debug_pick(scene, world_from_node, &self.points, pick, eye)
    }

    fn gpu_bytes(&self) -> u64 {
        let layer = self.layer.as_ref().map_or(0, |l| l.gpu_bytes())
            + self.val_source.as_ref().map_or(0, |s| s.gpu_bytes());
        self.raster.gpu_bytes() + self.rsm.bytes.0 + self.solution_bytes() + layer
    }

    fn resolved_options(&self) -> Option<Vec<(String, String)>> {
        self.resolved_options.clone()
    }

    fn report(&self) -> serde_json::Map<String, serde_json::Value> {
        let mut report = self.report.clone();
        if let Some(budget) = &self.budget {
            report.insert("budget".into(), budget.clone());
        }
        report
    }
}

fn create(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    options: &MethodOptions,
) -> Result<Box<dyn Method>, RenderError> {
    Ok(Box::new(SparseMethod::from_options(
        ctx, scene, render, options,
    )?))
}

impl SparseMethod {
    /// The sparse method as its registry options describe it, `--quality auto` included
    /// (methods composed on it, e.g. `sparse+atlas`, take every one of them).
    pub fn from_options(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        options: &MethodOptions,
    ) -> Result<Self, RenderError> {
        Self::from_options_with_layer(ctx, scene, render, options, None)
    }

    /// [`Self::from_options`] with `layer` on top of the sparse light (`sparse+atlas`'s
    /// atlas). Budget mode's timing pilots render with it, so that a time budget holds for
    /// the composed frame.
    pub fn from_options_with_layer(
        ctx: &GpuContext,
        scene: &Scene,
        render: RenderSettings,
        options: &MethodOptions,
        layer: Option<Box<dyn IndirectLayer>>,
    ) -> Result<Self, RenderError> {
        // Lent to each timing pilot in turn.
        let layer = std::cell::RefCell::new(layer);
        let mut settings = SparseSettings::from_options(options)?;
        // Budget mode builds the method once per pilot, then once more for its choice.
        let cache = SceneCache::new(scene);
        let budget = match budget_target(options)? {
            Some(target) => {
                // A time budget is predicted for this device: the fitted times scaled by the
                // FMA peak measured here. An error target's choice does not depend on it.
                let peak = match target {
                    budget::BudgetTarget::Ms(_) => Some(crate::gpu::peak::device_fma_peak(ctx)?),
                    budget::BudgetTarget::Flip(_) => None,
                };
                // Pilot frames: the sparse method itself, small.
                let size = pilot_size(render.width, render.height);
                let pilot_render = RenderSettings {
                    width: size.0,
                    height: size.1,
                    ssaa: 1,
                    ..render
                };
                let aspect = render.width as f32 / render.height.max(1) as f32;
                let mut render_pilot = |settings: &SparseSettings,
                                        world: &[Mat4],
                                        camera: &CameraView|
                 -> Result<Image, RenderError> {
                    let mut method =
                        SparseMethod::from_cache(ctx, &cache, pilot_render, *settings, None)?;
                    let mut indirect = method.render(ctx, scene, world, camera)?.indirect;
                    indirect.sanitize();
                    Ok(indirect)
                };
                // Timing pilots: the sparse method at the render's own size, one view.
                let mut time_pilot = |settings: &SparseSettings,
                                      world: &[Mat4],
                                      camera: &CameraView|
                 -> Result<f64, RenderError> {
                    time_frames(ctx, &cache, render, *settings, (world, camera), &layer)
                };
                let count: usize = options.get("budget-pilots", budget::DEFAULT_PILOTS)?;
                let pilots = match target {
                    budget::BudgetTarget::Flip(_) => Pilots::Flip(PilotFrames {
                        count,
                        size,
                        render: &mut render_pilot,
                    }),
                    budget::BudgetTarget::Ms(_) => Pilots::Time(TimingPilots {
                        count,
                        size: (render.width, render.height),
                        views: render.views_per_frame.max(1),
                        time: &mut time_pilot,
                        frames: PilotFrames {
                            count,
                            size,
                            render: &mut render_pilot,
                        },
                    }),
                };
                let frame_pixels = f64::from(render.width)
                    * f64::from(render.height)
                    * f64::from(render.ssaa.max(1)).powi(2)
                    * f64::from(render.views_per_frame.max(1));
                Some(apply_budget(
                    scene,
                    (render.camera, aspect, frame_pixels),
                    options,
                    target,
                    peak,
                    &mut settings,
                    Some(pilots),
                )?)
            }
            None => None,
        };
        let mut method = SparseMethod::from_cache(ctx, &cache, render, settings, None)?;
        method.resolved_options = budget
            .is_some()
            .then(|| with_choice_written_in(options, &settings));
        method.budget = budget;
        method.layer = layer.into_inner();
        Ok(method)
    }
}

/// The `visibility-rays` option's value for `adaptive` rays or not.
fn visibility_rays_value(adaptive: bool) -> &'static str {
    if adaptive {
        "adaptive"
    } else {
        "all"
    }
}

/// `options` with budget mode's choice (`settings`) written in as manual knobs: they build
/// the chosen method again without its survey and pilots.
fn with_choice_written_in(
    options: &MethodOptions,
    settings: &SparseSettings,
) -> Vec<(String, String)> {
    let search = ["quality", "target-flip", "budget-ms", "budget-pilots"];
    let chosen = [
        ("sparse-points", settings.sparse_points.to_string()),
        ("rsm", settings.rsm.to_string()),
        ("occlusion", settings.options.occlusion.name().to_string()),
        (
            "visibility-rays",
            visibility_rays_value(settings.options.adaptive_rays).to_string(),
        ),
    ];
    let mut pairs: Vec<(String, String)> = options
        .entries()
        .filter(|(key, _)| !search.contains(key) && !chosen.iter().any(|(k, _)| k == key))
        .map(|(key, value)| (key.to_string(), value.to_string()))
        .collect();
    pairs.extend(chosen.map(|(key, value)| (key.to_string(), value)));
    pairs
}

/// One timing pilot: the sparse method with `settings` (and the composed method's `layer`)
/// at `render`'s size, through as many views as the render's frames record
/// (`views_per_frame`, each through `camera`: the per-view passes cost about the same in any
/// direction), for [`budget::timed::TIMING_FRAMES`] frames; the longest frame time (the
/// passes' total, as `valgi render` reports it) after the first, ms: a budget holds for every
/// frame.
fn time_frames(
    ctx: &GpuContext,
    cache: &SceneCache<'_>,
    render: RenderSettings,
    settings: SparseSettings,
    view: (&[Mat4], &CameraView),
    layer: &std::cell::RefCell<Option<Box<dyn IndirectLayer>>>,
) -> Result<f64, RenderError> {
    let mut method = SparseMethod::from_cache(ctx, cache, render, settings, None)?;
    // The composed method's layer rides along, and goes back whatever the frames do.
    method.layer = layer.borrow_mut().take();
    let timed = longest_frame(ctx, cache.scene, render, &mut method, view);
    *layer.borrow_mut() = method.layer.take();
    timed
}

/// The longest of `method`'s [`budget::timed::TIMING_FRAMES`] frames after the first, ms.
fn longest_frame(
    ctx: &GpuContext,
    scene: &Scene,
    render: RenderSettings,
    method: &mut SparseMethod,
    (world_from_node, camera): (&[Mat4], &CameraView),
) -> Result<f64, RenderError> {
    let views = (0..render.views_per_frame.max(1))
        .map(|_| {
            View::new(
                ctx,
                "timing pilot",
                *camera,
                (render.width, render.height),
                render.ssaa,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut longest: f64 = 0.0;
    for frame in 0..budget::timed::TIMING_FRAMES {
        crate::progress::check()?;
        let recorded = crate::frame::record_frame(method, ctx, scene, world_from_node, &views)?;
        if frame > 0 {
            longest = longest.max(recorded.timings.merged().total_ms());
        }
    }
    Ok(longest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pilot_frames_keep_the_aspect_and_cap_the_long_side() {
        assert_eq!(pilot_size(128, 128), (128, 128));
        assert_eq!(pilot_size(1920, 1080), (PILOT_MAX_SIDE, 144));
        assert_eq!(pilot_size(480, 3840), (32, PILOT_MAX_SIDE));
        // A sliver keeps a pixel.
        assert_eq!(pilot_size(10_000, 1), (PILOT_MAX_SIDE, 1));
    }

    #[test]
    fn the_pilot_count_the_options_list_is_the_one_used() {
        let spec = OPTIONS
            .iter()
            .find(|o| o.name == "budget-pilots")
            .expect("budget-pilots is an option");
        assert_eq!(spec.default, budget::DEFAULT_PILOTS.to_string());
    }

    #[test]
    fn a_candidate_sets_every_knob_but_the_ones_given() {
        let base = SparseSettings {
            rsm_texels: Some(4096),
            ..SparseSettings::default()
        };
        let choice = budget::BudgetChoice {
            points: 2048,
            rsm: 48,
            visibility: budget::Visibility::AdaptiveRays,
            predicted_flip: 0.05,
            predicted_ms: 10.0,
            variation: 0.0,
            val_error: 0.0,
            occluded_share: 0.0,
            met: true,
        };
        let all = with_candidate(&base, &choice, |_| false);
        assert_eq!(
            (all.sparse_points, all.rsm, all.rsm_texels),
            (2048, 48, None)
        );
        assert_eq!(visibility_of(&all), Some(budget::Visibility::AdaptiveRays));
        let kept = with_candidate(&base, &choice, |key| key == "rsm" || key == "occlusion");
        assert_eq!(
            (kept.sparse_points, kept.rsm, kept.rsm_texels),
            (2048, base.rsm, Some(4096))
        );
        assert_eq!(kept.options.occlusion, base.options.occlusion);
        // `sum` is a candidate's visibility (measured by the pilots), `union` none's.
        let sum_choice = budget::BudgetChoice {
            visibility: budget::Visibility::Sum,
            ..choice
        };
        let sum = with_candidate(&base, &sum_choice, |_| false);
        assert_eq!(sum.options.occlusion, OcclusionMode::Sum);
        assert_eq!(visibility_of(&sum), Some(budget::Visibility::Sum));
        let mut union = base;
        union.options.occlusion = OcclusionMode::Union;
        assert_eq!(visibility_of(&union), None);
    }
}
