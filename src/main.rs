//! `valgi` command line: argument parsing only; the work is in the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use valgi::app::{self, RenderRequest};
use valgi::raster::RenderSettings;
use valgi::scene::builtin;

#[derive(Parser)]
#[command(
    name = "valgi",
    version,
    about = "Dynamic global illumination with virtual area lights"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a scene to linear EXR and/or tone-mapped PNG; prints one JSON line of timings.
    Render(RenderArgs),
    /// Open a window on a scene: the frames of `render`, a fly camera and a panel of live
    /// knobs (method and its options, exposure, direct/indirect, animation, pass times).
    View(ViewArgs),
    /// Benchmark the sparse method (the paper's Table 1 grid), brute force and the device's
    /// FMA peak; prints a table and writes DIR/bench.csv.
    Bench(BenchArgs),
    /// Render every method on every scene against cached references; write results.csv,
    /// speed/accuracy charts and image sheets.
    Eval(EvalArgs),
    /// Bake the multi-bounce light atlas of a scene to an EXR (irradiance per texel); prints
    /// one JSON line with stage times, VPLs, texels and the energy account.
    Bake(BakeArgs),
    /// Bake time and indirect error against the B-bounce reference per VPL count and scene,
    /// with the path tracer's time to the same error; writes DIR/bake.csv,
    /// DIR/reference_convergence.csv and DIR/bake_<scene>.png.
    BakeBench(BakeBenchArgs),
    /// Seed 002's tables on bunny-box: frame time per (N, M) with the fitted cost model
    /// (Table 1) and a discontinuity-threshold sweep (Table 2); writes DIR/table1.csv and
    /// DIR/table2.csv.
    NegativeBench(NegativeBenchArgs),
    /// Mixed reality: place a virtual object in the room of RGB-D frames, light it with the
    /// frames' pixels as virtual area lights, and composite it into the photos; writes
    /// composite, object (RGBA) and indirect images per frame and prints a JSON report.
    Mr(MrArgs),
    /// Material preview: each material on a shader ball in a small lit room (red/green walls),
    /// direct + diffuse + glossy indirect, as one labelled grid (EXR + PNG); prints a JSON line.
    Preview(PreviewArgs),
    /// List the built-in scenes.
    Scenes,
    /// List the rendering methods.
    Methods,
    /// List the GPU adapters wgpu can see (honours WGPU_BACKEND).
    Adapters,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct MrArgs {
    /// An Open3D-style RGB-D folder (color/, depth/, trajectory.log).
    #[arg(long, conflicts_with_all = ["color", "depth"])]
    rgbd: Option<PathBuf>,
    /// One colour frame (with --depth).
    #[arg(long, requires = "depth")]
    color: Option<PathBuf>,
    /// One 16-bit depth frame (with --color).
    #[arg(long, requires = "color")]
    depth: Option<PathBuf>,
    /// Depth layout: primesense (mm), tum (÷5000), nyu (Kinect disparity), sun (rotated mm).
    #[arg(long, default_value = "primesense")]
    format: String,
    /// Intrinsics JSON (width, height, column-major intrinsic_matrix); PrimeSense defaults
    /// (fx = fy = 525, cx = 319.5, cy = 239.5) without.
    #[arg(long)]
    intrinsics: Option<PathBuf>,
    /// Camera-to-world poses: trajectory.log or TUM `t tx ty tz qx qy qz qw` (default:
    /// DIR/trajectory.log for --rgbd; identity without).
    #[arg(long)]
    trajectory: Option<PathBuf>,
    /// One frame K, or a half-open range A..B.
    #[arg(long, alias = "frame", default_value = "0")]
    frames: String,
    /// `bunny` or a scene file (.glb, .gltf, .ply, .obj).
    #[arg(long, default_value = "bunny")]
    object: String,
    /// Where the object's bottom centre stands: x,y,z in the trajectory's world, or `auto`
    /// (the horizontal real surface nearest the lower middle of the first frame).
    #[arg(long, default_value = "auto")]
    place: String,
    /// The object's turn about world +y, degrees.
    #[arg(long, default_value_t = 0.0)]
    yaw: f32,
    /// The object's uniform scale.
    #[arg(long, default_value_t = 1.0)]
    scale: f32,
    /// A virtual point light, point:x,y,z:intensity[:r,g,b] (W/sr); repeatable.
    #[arg(long)]
    light: Vec<String>,
    /// Radiance (W/(m²·sr)) of a decoded colour value of 1; see src/mixed_reality/README.md.
    #[arg(long, default_value_t = 1.0)]
    real_scale: f32,
    /// At most N real VALs (footprint-weighted, stratified over the image); one per pixel
    /// without.
    #[arg(long)]
    real_vals: Option<u32>,
    /// Merge the sensor's pixels into the coarsest blocks (2×2 up to 32×32) that every virtual
    /// receiver sees smaller than RATIO (block radius over its gap to the objects' bounding
    /// sphere). Default 0.1 unless --real-vals or --accumulate is given; 0: one VAL per pixel.
    /// See src/mixed_reality/README.md.
    #[arg(long, value_name = "RATIO")]
    real_cut: Option<f32>,
    /// The VAL disc area: the facing footprint, or the true (tilted) patch area.
    #[arg(long, default_value = "facing", value_parser = ["facing", "true"])]
    real_area: String,
    /// Fuse the surfels of the last K frames in a world-space voxel hash, one VAL per voxel
    /// (1: the latest frame only).
    #[arg(long, default_value_t = 1)]
    accumulate: u32,
    /// Voxel edge of --accumulate, metres.
    #[arg(long, default_value_t = 0.02)]
    voxel: f32,
    /// The sparse method's indirect occlusion: visibility rays to VAL clusters (the sensor's
    /// image tiles among them), or the paper's sparse-point discs (sum, union).
    #[arg(long, default_value = "rays", value_parser = ["rays", "sum", "union", "off"])]
    occlusion: String,
    /// The real surfaces (the filtered depth) block the virtual object's indirect light (with
    /// --occlusion rays).
    #[arg(long, default_value = "on", value_parser = ["on", "off"])]
    real_occluders: String,
    /// Metres of matter assumed behind every surface the sensor sees (for --real-occluders).
    #[arg(long, default_value_t = valgi::mixed_reality::depth_vals::DEFAULT_REAL_THICKNESS)]
    real_thickness: f32,
    /// Bilateral filter half-width in pixels (0: off).
    #[arg(long, default_value_t = 2)]
    bilateral_radius: u32,
    /// Bilateral spatial σ in pixels.
    #[arg(long, default_value_t = 2.0)]
    sigma_spatial: f32,
    /// Bilateral range σ in metres.
    #[arg(long, default_value_t = 0.03)]
    sigma_range: f32,
    /// Sparse receiver points on the virtual object (1..=1048576).
    #[arg(long, default_value_t = 1024)]
    sparse_points: usize,
    /// RSM resolution of the virtual lights.
    #[arg(long, default_value_t = 128)]
    rsm: u32,
    /// Rays per real pixel for the object's shadow and bounce on the real surfaces (0: off,
    /// at most 4096).
    #[arg(long, default_value_t = 16, value_parser = clap::value_parser!(u32).range(0..=4096))]
    differential_rays: u32,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
}

/// Lights and a camera added to the scene; shared by `render`, `view` and `eval`.
#[derive(clap::Args)]
struct SceneEditArgs {
    /// Add a light (repeatable): point:X,Y,Z,INTENSITY[,R,G,B] (W/sr) |
    /// spot:X,Y,Z,DX,DY,DZ,INNER_DEG,OUTER_DEG,INTENSITY[,R,G,B] | sun:DX,DY,DZ,IRRADIANCE[,R,G,B]
    /// (W/m², travelling along D) | headlight:INTENSITY[,R,G,B] (at the camera).
    #[arg(long = "light", value_name = "SPEC", value_parser = parse_light, allow_hyphen_values = true)]
    lights: Vec<valgi::scene::edits::LightSpec>,
    /// Drop the scene's own lights and emissive surfaces, so that only the --light options
    /// light it (in every method and in the reference).
    #[arg(long)]
    no_scene_lights: bool,
    /// Camera position X,Y,Z in world space (looks at --camera-target, default the scene's
    /// centre).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_eye, allow_hyphen_values = true)]
    camera_eye: Option<glam::Vec3>,
    /// Point the camera looks at, X,Y,Z in world space.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_target, allow_hyphen_values = true)]
    camera_target: Option<glam::Vec3>,
    /// Vertical field of view in degrees (alone: changes the chosen camera's).
    #[arg(long, value_name = "DEG")]
    fov: Option<f32>,
}

/// What many lights may take (`render` and `view`).
#[derive(clap::Args)]
struct LightBudgetArgs {
    /// Shadow-map budget in MiB (1..=65536): lights beyond it get smaller tiles by power
    /// (down to 16²), then the dimmest go unshadowed with a warning.
    #[arg(long, default_value_t = valgi::raster::DEFAULT_SHADOW_MEMORY_MIB,
          value_parser = clap::value_parser!(u32).range(1..=65536))]
    shadow_memory: u32,
    /// Most VALs all lights' RSMs may make together (VAL methods; 1..=2³¹): beyond it every
    /// RSM view gets a smaller side, its VALs carrying the same total flux.
    #[arg(long, default_value_t = valgi::light::rsm::DEFAULT_MAX_VALS,
          value_parser = clap::value_parser!(u32).range(1..=(1 << 31)))]
    max_vals: u32,
    /// Cap in MiB (16..=2²⁰) on the GPU memory the method may own: shadow maps and RSMs get at
    /// most a quarter each, and a setup beyond it is refused with what holds the memory
    /// (default: the device's own limits).
    #[arg(long, value_parser = clap::value_parser!(u32).range(16..=(1 << 20)))]
    gpu_memory: Option<u32>,
}

impl SceneEditArgs {
    fn edits(&self) -> valgi::scene::edits::SceneEdits {
        valgi::scene::edits::SceneEdits {
            lights: self.lights.clone(),
            camera: valgi::scene::edits::CameraEdit {
                eye: self.camera_eye,
                target: self.camera_target,
                yfov_degrees: self.fov,
            },
            drop_scene_lights: self.no_scene_lights,
        }
    }
}

fn parse_light(text: &str) -> Result<valgi::scene::edits::LightSpec, String> {
    text.parse()
}

fn parse_eye(text: &str) -> Result<glam::Vec3, String> {
    valgi::scene::edits::parse_point("--camera-eye", text)
}

fn parse_target(text: &str) -> Result<glam::Vec3, String> {
    valgi::scene::edits::parse_point("--camera-target", text)
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct RenderArgs {
    /// Built-in scene name (see `valgi scenes`) or a .gltf/.glb file.
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// Rendering method (see `valgi methods`). Default: sparse+atlas, the product's image:
    /// direct light, the sparse VALs' bounce 1 and bounces 2.. from an atlas baked in memory
    /// (or --atlas FILE); `sparse` alone, with a warning, for a scene whose atlas the default
    /// bake refuses. `sparse` is one dynamic bounce, `direct` direct light alone.
    #[arg(long)]
    method: Option<String>,
    /// Output width in pixels (per view).
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Output height in pixels (per view).
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Camera name or index (default: the scene's first camera, or one framing the scene).
    #[arg(long)]
    camera: Option<String>,
    #[command(flatten)]
    scene_edits: SceneEditArgs,
    /// Output file (.exr = linear 32-bit float, .png = tone-mapped). Repeatable. Default:
    /// out/<scene>.exr and out/<scene>.png.
    #[arg(long)]
    out: Vec<PathBuf>,
    /// PNG exposure in stops: png = sRGB(clamp(radiance × 2^E)); finite, within ±64.
    #[arg(long, default_value_t = 0.0)]
    exposure: f32,
    /// Pick the PNG exposure from the image: its log-average luminance maps to 0.18 (one
    /// exposure for all frames, from the first); the JSON line reports it.
    #[arg(long, conflicts_with = "exposure")]
    auto_exposure: bool,
    /// Write only the indirect part of the radiance (direct light removed).
    #[arg(long)]
    indirect_only: bool,
    /// N×N supersampling per pixel for anti-aliased edges.
    #[arg(long, default_value_t = 1)]
    ssaa: u32,
    /// Shadow-map side of a light at full resolution (a point light has six views): 16 up to
    /// the device's largest 2D texture side (16384 on most); lights beyond --shadow-memory get
    /// less.
    #[arg(long, default_value_t = 1024)]
    shadow_res: u32,
    #[command(flatten)]
    light_budgets: LightBudgetArgs,
    /// Tessellation: maximum triangle edge length in metres (positive; refused when a built-in
    /// scene would exceed 4 million triangles). Default: 0.05, except with the sparse methods:
    /// an imported scene is refined to 1/√2 of the sparse points' spacing √(area /
    /// sparse-points), and so are a built-in scene's meshes built coarser than that (the
    /// two-triangle walls of bunny-box and coarse-wall).
    #[arg(long)]
    max_edge: Option<f32>,
    /// Animation time in seconds (glTF animations); finite.
    #[arg(long, default_value_t = 0.0)]
    time: f32,
    /// Render F frames of the scene's animation (from --time, at --fps) as numbered EXRs into
    /// the folder given by --out.
    #[arg(long)]
    frames: Option<u32>,
    /// Frames per second of --frames.
    #[arg(long, default_value_t = 30.0)]
    fps: f32,
    /// A method option as key=value (repeatable); the method-specific flags are shorthands.
    #[arg(long = "opt", value_name = "KEY=VALUE")]
    options: Vec<String>,
    /// Views of one frame: mono, stereo[:IPD_METRES] (two eyes from the camera, default
    /// IPD 0.064), grid:N (N cameras on a small arc) or cave:FILE.json (one off-axis view per
    /// wall). One image per view, <stem>_<view>.exr/.png, plus a side-by-side PNG.
    #[arg(long, default_value = "mono")]
    views: String,
    /// Let the scene file reference buffers, images and meshes outside its own folder
    /// (absolute paths, `..`); device files stay refused.
    #[arg(long)]
    allow_external_paths: bool,
    /// Most lights the emissive surfaces become (0..=64, 0 = off): clusters of emissive
    /// triangles, each a Lambertian point emitter of the cluster's power (the reference samples
    /// the triangles themselves).
    #[arg(long, default_value_t = valgi::scene::emitters::DEFAULT_EMITTER_LIGHTS)]
    emitter_lights: u32,
    /// Render and time the frames without reading them back or writing images (a soak run).
    #[arg(long)]
    no_write: bool,
    /// Sample the process's resident memory and the method's GPU bytes every N frames into
    /// the report's "memory" list, with the growth over the run's second half.
    #[arg(long, default_value_t = 0)]
    memory_every: u32,
}

#[derive(clap::Args)]
#[command(allow_negative_numbers = true)]
struct ViewArgs {
    /// Built-in scene name (see `valgi scenes`) or a .gltf/.glb file.
    #[arg(long, default_value = "cornell", conflicts_with = "preview")]
    scene: String,
    /// Rendering method (see `valgi methods`); switchable in the panel. Default: render's,
    /// sparse+atlas (sparse where the in-memory atlas bake is refused), or sparse with
    /// --preview.
    #[arg(long)]
    method: Option<String>,
    /// The material preview room of `valgi preview` instead of --scene, with the ball's base
    /// colour, roughness, metallic and specular factor as knobs in the panel.
    #[arg(long)]
    preview: bool,
    /// With --preview: the ball's starting material, FILE.glb[#NAME|#INDEX] (default a grey
    /// dielectric of roughness 0.5).
    #[arg(long, requires = "preview")]
    material: Option<String>,
    /// With --preview: sphere, or bunny (the shared data's Stanford bunny).
    #[arg(long, requires = "preview", default_value = "sphere")]
    ball: valgi::preview::BallShape,
    /// Width of each view's region of the window, pixels.
    #[arg(long, default_value_t = 512)]
    width: u32,
    /// Height of each view's region, pixels.
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Camera name or index the view starts from (and resets to).
    #[arg(long)]
    camera: Option<String>,
    #[command(flatten)]
    scene_edits: SceneEditArgs,
    /// Exposure in stops (the PNG tone map of `render`).
    #[arg(long, default_value_t = 0.0)]
    exposure: f32,
    #[arg(long, default_value_t = 1)]
    ssaa: u32,
    #[arg(long, default_value_t = 1024)]
    shadow_res: u32,
    #[command(flatten)]
    light_budgets: LightBudgetArgs,
    /// Longest triangle edge, metres (default: 0.05 for built-in scenes; with a sparse method
    /// an imported scene is refined to its sparse-point spacing, and a built-in one's coarser
    /// meshes too, as in `render`).
    #[arg(long)]
    max_edge: Option<f32>,
    /// Animation time of the first frame, seconds.
    #[arg(long, default_value_t = 0.0)]
    time: f32,
    /// A method option as key=value (repeatable); the method-specific flags are shorthands.
    #[arg(long = "opt", value_name = "KEY=VALUE")]
    options: Vec<String>,
    /// mono, or stereo[:IPD_METRES] shown side by side (any rig of `render` works).
    #[arg(long, default_value = "mono")]
    views: String,
    /// Render N frames (the animation at 30 fps), then exit.
    #[arg(long)]
    frames: Option<u32>,
    /// Write the last frame's window to this PNG (with --frames).
    #[arg(long, requires = "frames")]
    screenshot: Option<PathBuf>,
    /// Show a two-view rig (--views stereo) as a red/cyan anaglyph (switchable in the panel).
    #[arg(long)]
    anaglyph: bool,
    /// With --frames: after the first frame change this method option (or `method=NAME`) as
    /// the panel would, and run on until the rebuild is in (the report times it and the UI
    /// frames meanwhile).
    #[arg(long, value_name = "KEY=VALUE", requires = "frames")]
    change_option: Option<String>,
    /// Debug views on from the start (switchable in the panel): `points` (the sparse points
    /// as splats coloured by their diffuse light), `vals` (the VALs coloured by radiance),
    /// `links` (the 8 links of the vertex under the cursor), `occluders` (the light spheres
    /// of the point under the cursor and the occluder discs covering them), `reference` (the
    /// difference to the reference cached by `valgi eval`, see --reference).
    #[arg(long, value_name = "VIEW", value_delimiter = ',')]
    debug: Vec<String>,
    /// The window pixel X,Y whose surface the links and occluder views show (scripted runs;
    /// interactively the cursor's).
    #[arg(long, value_name = "X,Y")]
    pick: Option<String>,
    /// An output folder of `valgi eval` (or the `cache` in it): the reference debug view shows
    /// the difference to its cached reference of the view on screen.
    #[arg(long, value_name = "DIR")]
    reference: Option<PathBuf>,
    #[arg(long)]
    allow_external_paths: bool,
    /// Most lights the emissive surfaces become (0..=64, 0 = off): clusters of emissive
    /// triangles, each a Lambertian point emitter of the cluster's power (the reference samples
    /// the triangles themselves).
    #[arg(long, default_value_t = valgi::scene::emitters::DEFAULT_EMITTER_LIGHTS)]
    emitter_lights: u32,
}

#[derive(clap::Args)]
struct EvalArgs {
    /// Comma-separated built-in scene names or glTF files.
    #[arg(long, default_value = "cornell")]
    scenes: String,
    /// Comma-separated method specs: name[:key=value,...] (a key=value after a comma belongs
    /// to the method before it). Default: direct,sparse,reference (the product's method
    /// between direct light alone and the path tracer); none with --sweep.
    #[arg(long)]
    methods: Option<String>,
    /// Also render the sparse method over the grid of its budget knobs (sparse points × RSM
    /// side × visibility) and write sweep.csv: each setting's time, its error against the
    /// reference and against the grid's richest setting.
    #[arg(long)]
    sweep: bool,
    /// The sweep's sparse-point counts.
    #[arg(long, default_value = "1024,2048,4096,8192,16384", requires = "sweep")]
    sweep_points: String,
    /// The sweep's RSM sides.
    #[arg(long, default_value = "32,64,128", requires = "sweep")]
    sweep_rsm: String,
    /// The sweep's visibility settings: off, sum, rays-adaptive, rays-all.
    #[arg(
        long,
        default_value = "off,sum,rays-adaptive,rays-all",
        requires = "sweep"
    )]
    sweep_visibility: String,
    /// Output folder (results.csv, <scene>_pareto.png, <scene>_sheet.png, images/, cache/).
    #[arg(long, default_value = "out/eval")]
    out: PathBuf,
    #[arg(long, default_value_t = 256)]
    width: u32,
    #[arg(long, default_value_t = 256)]
    height: u32,
    /// Camera name or index.
    #[arg(long)]
    camera: Option<String>,
    #[command(flatten)]
    scene_edits: SceneEditArgs,
    /// Reference paths per pixel.
    #[arg(long, default_value_t = 256)]
    ref_spp: u32,
    /// Reference bounces (1 = one indirect bounce, as the single-bounce methods; or inf).
    #[arg(long, default_value = "1")]
    ref_bounces: String,
    /// The reference's specular lobes: off compares the methods that model diffuse light only
    /// (atlas, the VALs' bounce) with that light alone (glTF dielectrics reflect 4 %
    /// specularly, a large share on dark textures).
    #[arg(long, default_value = "on", value_parser = ["on", "off"])]
    ref_specular: String,
    /// Frames per method (≥ 3 measures flicker); frame f is at time f/30 s.
    #[arg(long, default_value_t = 1)]
    frames: u32,
    /// Longest triangle edge, metres (default: 0.05 for built-in scenes; with a sparse method
    /// an imported scene is refined to its sparse-point spacing, and a built-in one's coarser
    /// meshes too, as in `render`).
    #[arg(long)]
    max_edge: Option<f32>,
    /// Most lights the emissive surfaces become (0..=64, 0 = off): clusters of emissive
    /// triangles, each a Lambertian point emitter of the cluster's power (the reference samples
    /// the triangles themselves).
    #[arg(long, default_value_t = valgi::scene::emitters::DEFAULT_EMITTER_LIGHTS)]
    emitter_lights: u32,
    /// Exposure in stops for FLIP and sheets of the full images (default: automatic).
    #[arg(long)]
    exposure: Option<f32>,
}

#[derive(clap::Args)]
struct BenchArgs {
    #[arg(long, default_value = "cornell")]
    scene: String,
    #[command(flatten)]
    scene_edits: SceneEditArgs,
    #[arg(long, default_value_t = 1920)]
    width: u32,
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Target VAL counts (the RSM resolution is fitted to each).
    #[arg(long, value_delimiter = ',', default_value = "16384,65536,524288")]
    vals: Vec<u32>,
    /// Sparse point counts.
    #[arg(long, value_delimiter = ',', default_value = "4096,16384")]
    points: Vec<usize>,
    /// Square size at which the sparse stages are timed again (resolution independence).
    #[arg(long, default_value_t = 512)]
    small: u32,
    /// Skip the brute-force run (slow on software drivers).
    #[arg(long)]
    no_brute: bool,
    /// Also time the default configuration with the gather split into each of these many
    /// VAL slices (1..=256), at the first --vals count.
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=256))]
    gather_slices: Vec<u32>,
    /// Also time the default configuration with each of these gather tile sizes (1..=256).
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u32).range(1..=256))]
    tiles: Vec<u32>,
    /// Instead of the Table 1 grid: time frames with these numbers of views (grid rig) per
    /// method, plus one view at --large, and the mid-eye glossy error; writes views.csv,
    /// views.png and glossy_eye.csv.
    #[arg(long, value_delimiter = ',')]
    views: Vec<usize>,
    /// Methods of the views benchmark.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "sparse,brute,lpv,holpv,atlas"
    )]
    methods: Vec<String>,
    /// Size of the views benchmark's resolution-independence row, WxH.
    #[arg(long, default_value = "3840x2160")]
    large: String,
    /// Size of each eye in the views benchmark's glossy-eye comparison.
    #[arg(long, default_value_t = 256)]
    glossy_size: u32,
    #[arg(long, default_value = "out/bench")]
    out: PathBuf,
}

#[derive(clap::Args)]
struct BakeArgs {
    /// Built-in scene name (see `valgi scenes`) or a .gltf/.glb file.
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// Output atlas (.exr, linear irradiance in W/m², alpha 1 on texels that hold a surface).
    #[arg(long)]
    out: PathBuf,
    /// Number of VPL patches (1..=16384; photon paths with --lights polygons, 1..=1048576).
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().vpls)]
    vpls: usize,
    /// Indirect bounces kept (1..=64).
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().bounces)]
    bounces: u32,
    /// Atlas width and height in texels.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().atlas_res)]
    atlas_res: u32,
    /// Write bounces K..B only (2 leaves bounce 1 to a dynamic method).
    #[arg(long, default_value_t = 1)]
    from_bounce: u32,
    /// Near-field gather rays per texel (stratified, a square number; 0 = off, every sample a
    /// disc: faster, darker corners and contacts).
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().near_rays)]
    near_rays: u32,
    /// Face resolution of the shooters' depth cubes (finer: fewer rays at depth edges, more
    /// memory: VPLs × 6 × res² × 4 bytes).
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().cube_res)]
    cube_res: usize,
    /// Radius of the near-field gather in sample spacings √C (capped at a tenth of the
    /// scene's diagonal); samples within it are gathered by rays instead of disc kernels.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().near_radius)]
    near_radius: f32,
    /// Tessellation of built-in scenes (render with the same value).
    #[arg(long, default_value_t = builtin::BuiltinParams::default().max_edge)]
    max_edge: f32,
    /// Add a light (repeatable; the formats of `render --light`); render with the same ones.
    #[arg(long = "light", value_name = "SPEC", value_parser = parse_light, allow_hyphen_values = true)]
    added_lights: Vec<valgi::scene::edits::LightSpec>,
    /// Drop the scene's own lights and emissive surfaces, so that only the --light options
    /// light the bake (render with the same flag).
    #[arg(long)]
    no_scene_lights: bool,
    /// Virtual lights: patches (seed 000: --vpls patches) or polygons (seed 001: --vpls
    /// photon paths, each leaving a VPL per bounce, clustered into polygon and sphere lights).
    #[arg(long, default_value = "patches")]
    lights: valgi::atlas::Lights,
    /// Polygon lights: target VPLs per cluster.
    #[arg(long, default_value_t = valgi::atlas::bake::PolygonSettings::default().cluster_size)]
    cluster_size: usize,
    /// Polygon lights: face resolution of each light's depth cube.
    #[arg(long, default_value_t = valgi::atlas::bake::PolygonSettings::default().cube_res)]
    polygon_cube_res: usize,
    /// Seed of the bake's random choices (surface samples and VPL sites; photon paths with
    /// --lights polygons): another seed is another, equally valid bake, and a few show how
    /// much a VPL count's result depends on the draw.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().seed)]
    seed: u64,
}

#[derive(clap::Args)]
struct NegativeBenchArgs {
    #[arg(long, default_value = "bunny-box")]
    scene: String,
    #[arg(long, default_value_t = 640)]
    width: u32,
    #[arg(long, default_value_t = 480)]
    height: u32,
    /// Table 1 rows, N+M.
    #[arg(long, default_value = "100+50,150+0,200+100,300+0,300+150,450+0")]
    rows: String,
    /// Table 2 sweep at N+M = 100+50, TAU_POS:TAU_NORMAL.
    #[arg(
        long,
        default_value = "1e9:-1,12:0.7,3:0.94,2:0.97,1.5:0.98,1:0.99,0:1"
    )]
    thresholds: String,
    /// Timed frames per row (the median is reported).
    #[arg(long, default_value_t = 3)]
    frames: u32,
    #[arg(long, default_value = "out/negative-bench")]
    out: PathBuf,
}

fn negative_bench(args: NegativeBenchArgs) -> ExitCode {
    use valgi::negative::bench;
    let request = (|| {
        Ok::<_, valgi::raster::RenderError>(bench::NegativeBenchRequest {
            scene: args.scene,
            width: args.width,
            height: args.height,
            rows: bench::parse_rows(&args.rows)?,
            thresholds: bench::parse_thresholds(&args.thresholds)?,
            frames: args.frames,
            out: args.out,
        })
    })();
    match request
        .map_err(valgi::app::AppError::from)
        .and_then(|r| bench::run(&r))
    {
        Ok(path) => {
            println!("wrote {}", path.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

#[derive(clap::Args)]
struct PreviewArgs {
    /// Materials of a glTF file: FILE.glb (all of them), FILE.glb#NAME or FILE.glb#INDEX;
    /// repeatable.
    #[arg(long)]
    material: Vec<String>,
    /// Parameter grid, e.g. roughness=0..1:5,metallic=0,1 (ranges a..b:n and lists; roughness,
    /// metallic, specular, base=R/G/B). The first parameter varies along each row.
    #[arg(long)]
    sweep: Option<String>,
    /// Method spec: name[:key=value,...], e.g. sparse, brute:glossy=off, reference:spp=64
    /// (methods taking rsm get rsm=32 unless given: one point light makes six RSM faces).
    #[arg(long, default_value = "sparse")]
    method: String,
    /// The shape the material is shown on: sphere, or bunny (the shared data's Stanford bunny).
    #[arg(long, default_value = "sphere")]
    ball: valgi::preview::BallShape,
    /// Pixels per ball (square).
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Balls per row (default: the sweep's first parameter's count, or up to 5 materials).
    #[arg(long)]
    columns: Option<usize>,
    /// The grid: FILE.png or FILE.exr; both are written.
    #[arg(long, default_value = "out/preview.png")]
    out: PathBuf,
    /// PNG exposure in stops (default: the grid's key exposure).
    #[arg(long)]
    exposure: Option<f32>,
    /// Longest triangle edge of the room and ball, metres.
    #[arg(long, default_value_t = 0.05)]
    max_edge: f32,
}

fn preview(args: PreviewArgs) -> Result<serde_json::Value, valgi::preview::PreviewError> {
    use valgi::preview::PreviewError;
    if !(args.max_edge.is_finite() && args.max_edge >= 0.005) {
        return Err(PreviewError::Spec(format!(
            "--max-edge {}: must be at least 0.005 m",
            args.max_edge
        )));
    }
    if let Some(e) = args
        .exposure
        .filter(|e| !e.is_finite() || e.abs() > app::MAX_EXPOSURE_STOPS)
    {
        return Err(PreviewError::Spec(format!(
            "--exposure {e}: must be within ±{}",
            app::MAX_EXPOSURE_STOPS
        )));
    }
    let (materials, columns) =
        valgi::preview::select_materials(&args.material, args.sweep.as_deref())?;
    let (method, options) = valgi::method::MethodOptions::parse_spec(&args.method)?;
    let request = valgi::preview::PreviewRequest {
        materials,
        columns: args.columns.unwrap_or(columns),
        ball: args.ball,
        options: valgi::preview::preview_options(&method, &options),
        method,
        settings: RenderSettings {
            width: args.size,
            height: args.size,
            ..RenderSettings::default()
        },
        max_edge: args.max_edge,
    };
    valgi::preview::run(&request, &args.out, args.exposure)
}

#[derive(clap::Args)]
struct BakeBenchArgs {
    /// Comma-separated built-in scene names or glTF files.
    #[arg(long, default_value = "cornell,corridor")]
    scenes: String,
    /// VPL counts baked per scene.
    #[arg(long, value_delimiter = ',', default_value = "100,400,1600,6400")]
    vpls: Vec<usize>,
    /// Bakers measured: patches (seed 000, at --vpls) and/or polygons (seed 001, at
    /// --polygon-vpls photon paths).
    #[arg(long, value_delimiter = ',', default_value = "patches")]
    lights: Vec<valgi::atlas::Lights>,
    /// Photon paths of the polygon-light bakes.
    #[arg(long, value_delimiter = ',', default_value = "5000,20000,80000")]
    polygon_vpls: Vec<usize>,
    /// Polygon lights: target VPLs per cluster.
    #[arg(long, default_value_t = valgi::atlas::bake::PolygonSettings::default().cluster_size)]
    cluster_size: usize,
    /// Bounces of the bake and of the reference.
    #[arg(long, default_value_t = 4)]
    bounces: u32,
    #[arg(long, default_value_t = 256)]
    atlas_res: u32,
    /// Image size of the error measurement.
    #[arg(long, default_value_t = 128)]
    width: u32,
    #[arg(long, default_value_t = 128)]
    height: u32,
    /// Paths per pixel of the reference.
    #[arg(long, default_value_t = 4096)]
    ref_spp: u32,
    /// Paths per pixel at which the path tracer's convergence run is measured (one
    /// progressive run; each point is timed as a separate render with that many paths).
    #[arg(long, value_delimiter = ',', default_value = "1,4,16,64,256,1024")]
    pt_spp: Vec<u32>,
    /// FLIP at which the path tracer's time is reported.
    #[arg(long, default_value_t = 0.05)]
    flip_target: f64,
    /// N×N supersampling of the atlas renders, so their pixels cover what the reference's
    /// jittered paths do (a box filter over the pixel).
    #[arg(long, default_value_t = 4)]
    ssaa: u32,
    /// Near-field gather rays per texel of every bake (0 = off).
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().near_rays)]
    near_rays: u32,
    /// Face resolution of the shooters' depth cubes of every bake.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().cube_res)]
    cube_res: usize,
    /// Near-field radius of every bake, in sample spacings √C (capped at a tenth of the
    /// scene's diagonal).
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().near_radius)]
    near_radius: f32,
    /// Tessellation of built-in scenes (metres).
    #[arg(long, default_value_t = builtin::BuiltinParams::default().max_edge)]
    max_edge: f32,
    #[arg(long, default_value = "out/bake-bench")]
    out: PathBuf,
}

fn bake_bench(args: BakeBenchArgs) -> ExitCode {
    let request = valgi::atlas::bench::BakeBenchRequest {
        scenes: valgi::eval::split_list(&args.scenes),
        lights: args.lights,
        vpls: args.vpls,
        polygon_vpls: args.polygon_vpls,
        cluster_size: args.cluster_size,
        bounces: args.bounces,
        atlas_res: args.atlas_res,
        width: args.width,
        height: args.height,
        ref_spp: args.ref_spp,
        pt_spp: args.pt_spp,
        flip_target: args.flip_target,
        ssaa: args.ssaa,
        near_rays: args.near_rays,
        cube_res: args.cube_res,
        near_radius: args.near_radius,
        max_edge: args.max_edge,
        out: args.out,
        ..Default::default()
    };
    match valgi::atlas::bench::run(&request) {
        Ok(summary) => {
            let rows: Vec<serde_json::Value> = summary
                .rows
                .iter()
                .map(|r| {
                    serde_json::json!({
                        "scene": r.scene, "lights": r.lights.name(), "vpls": r.vpls, "bake_ms": r.bake_ms.round(),
                        "flip_indirect": r.flip_indirect, "mean_ratio": r.mean_ratio,
                        "pt_ms_same_flip": r.pt_ms_same_flip.map(f64::round),
                        "speedup": r.speedup(),
                    })
                })
                .collect();
            let report = serde_json::json!({
                "csv": summary.csv.display().to_string(),
                "convergence_csv": summary.convergence_csv.display().to_string(),
                "charts": summary.charts.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "pt_ms_at_flip_target": summary.pt_ms_at_target.iter().map(|(s, t)| (s.clone(), serde_json::json!(t.map(f64::round)))).collect::<serde_json::Map<_, _>>(),
                "rows": rows,
            });
            println!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// On a headless machine without `XDG_RUNTIME_DIR`, libwayland (which the Vulkan driver loads to
/// probe for presentation) prints "XDG_RUNTIME_DIR is invalid or not set" twice for every
/// device opened. A private runtime folder answers its check; there is no Wayland socket in it,
/// so nothing connects. Runs before any thread starts, as changing the environment must.
fn quiet_headless_runtime_dir() {
    let valid = std::env::var_os("XDG_RUNTIME_DIR")
        .is_some_and(|dir| std::path::Path::new(&dir).is_absolute());
    if valid || std::env::var_os("WAYLAND_DISPLAY").is_some() {
        return;
    }
    // One shared name: libwayland only needs an absolute path, not one this user owns.
    let dir = std::env::temp_dir().join("valgi-runtime");
    if std::fs::create_dir_all(&dir).is_ok() {
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
        }
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

/// Prints `e` and picks the exit status: 130 after Ctrl-C, 1 otherwise.
fn failure(e: &dyn std::fmt::Display) -> ExitCode {
    if valgi::progress::cancelled() {
        eprintln!("cancelled: {e}");
        ExitCode::from(valgi::progress::CANCELLED_EXIT_CODE)
    } else {
        eprintln!("error: {e}");
        ExitCode::FAILURE
    }
}

fn main() -> ExitCode {
    quiet_headless_runtime_dir();
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let matches = with_method_flags(Cli::command()).get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli,
        Err(e) => e.exit(),
    };
    match cli.command {
        Command::Render(args) => {
            let into_folder = args
                .out
                .iter()
                .any(|p| !matches!(p.extension().and_then(|e| e.to_str()), Some("exr" | "png")));
            if args.frames.is_some() && into_folder && args.out.len() != 1 {
                eprintln!(
                    "error: --frames writes numbered EXRs into one --out DIR, or numbered files beside --out NAME.exr/.png"
                );
                return ExitCode::FAILURE;
            }
            let outputs = if args.out.is_empty() {
                let stem = scene_stem(&args.scene);
                vec![
                    PathBuf::from(format!("out/{stem}.exr")),
                    PathBuf::from(format!("out/{stem}.png")),
                ]
            } else {
                args.out
            };
            let options = match method_options(&matches, "render", &args.options) {
                Ok(o) => o,
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let views = match valgi::frame::ViewRig::parse(&args.views) {
                Ok(rig) => rig,
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let method_fallback = match args.method {
                Some(_) => None,
                None => Some(valgi::app::DEFAULT_METHOD_FALLBACK.to_string()),
            };
            let request = RenderRequest {
                scene: args.scene,
                method: args
                    .method
                    .unwrap_or_else(|| valgi::app::DEFAULT_METHOD.to_string()),
                method_fallback,
                options,
                settings: RenderSettings {
                    width: args.width,
                    height: args.height,
                    ssaa: args.ssaa,
                    shadow_resolution: args.shadow_res,
                    shadow_memory_mib: args.light_budgets.shadow_memory,
                    max_vals: args.light_budgets.max_vals,
                    gpu_memory_mib: args.light_budgets.gpu_memory,
                    ..RenderSettings::default()
                },
                camera: args.camera,
                edits: args.scene_edits.edits(),
                outputs,
                exposure: args.exposure,
                auto_exposure: args.auto_exposure,
                indirect_only: args.indirect_only,
                max_edge: args.max_edge,
                time: args.time,
                frames: args.frames,
                fps: args.fps,
                views,
                allow_external_paths: args.allow_external_paths,
                emitter_lights: args.emitter_lights,
                write_images: !args.no_write,
                memory_every: args.memory_every,
            };
            valgi::progress::install_ctrl_c();
            match app::render(&request) {
                Ok(report) => {
                    println!("{report}");
                    ExitCode::SUCCESS
                }
                Err(e) => failure(&e),
            }
        }
        Command::View(args) => {
            let options = match method_options(&matches, "view", &args.options) {
                Ok(o) => o,
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::FAILURE;
                }
            };
            let request = (|| {
                let preview = match (args.preview, &args.material) {
                    (false, _) => None,
                    (true, None) => Some(valgi::preview::PreviewMaterial::plain(
                        "preview",
                        valgi::preview::default_material(),
                    )),
                    (true, Some(spec)) => Some(
                        valgi::preview::load_materials(spec)
                            .map_err(|e| valgi::raster::RenderError::Settings(e.to_string()))?
                            .into_iter()
                            .next()
                            .ok_or_else(|| {
                                valgi::raster::RenderError::Settings(format!(
                                    "--material {spec}: the file has no material"
                                ))
                            })?,
                    ),
                };
                Ok::<_, valgi::raster::RenderError>(valgi::viewer::ViewerRequest {
                    scene: args.scene,
                    // The default is render's (the product's image); the preview's is sparse.
                    method_fallback: match (&args.method, args.preview) {
                        (None, false) => Some(valgi::app::DEFAULT_METHOD_FALLBACK.to_string()),
                        _ => None,
                    },
                    method: args.method.unwrap_or_else(|| {
                        if args.preview {
                            "sparse"
                        } else {
                            valgi::app::DEFAULT_METHOD
                        }
                        .to_string()
                    }),
                    preview: preview.map(|material| valgi::viewer::ViewerPreview {
                        material,
                        ball: args.ball,
                    }),
                    options,
                    settings: RenderSettings {
                        width: args.width,
                        height: args.height,
                        ssaa: args.ssaa,
                        shadow_resolution: args.shadow_res,
                        shadow_memory_mib: args.light_budgets.shadow_memory,
                        max_vals: args.light_budgets.max_vals,
                        gpu_memory_mib: args.light_budgets.gpu_memory,
                        ..RenderSettings::default()
                    },
                    camera: args.camera,
                    edits: args.scene_edits.edits(),
                    views: valgi::frame::ViewRig::parse(&args.views)?,
                    max_edge: args.max_edge,
                    allow_external_paths: args.allow_external_paths,
                    emitter_lights: args.emitter_lights,
                    time: args.time,
                    exposure: args.exposure,
                    frames: args.frames,
                    screenshot: args.screenshot,
                    anaglyph: args.anaglyph,
                    debug: {
                        let mut debug = valgi::viewer::DebugViews::default();
                        for name in &args.debug {
                            debug
                                .enable(name)
                                .map_err(valgi::raster::RenderError::Settings)?;
                        }
                        debug
                    },
                    pick: match &args.pick {
                        None => None,
                        Some(xy) => Some(
                            xy.split_once(',')
                                .and_then(|(x, y)| {
                                    Some((x.trim().parse().ok()?, y.trim().parse().ok()?))
                                })
                                .ok_or_else(|| {
                                    valgi::raster::RenderError::Settings(format!(
                                        "--pick {xy}: expected two whole pixel coordinates X,Y"
                                    ))
                                })?,
                        ),
                    },
                    reference: args.reference,
                    change_option: match args.change_option {
                        None => None,
                        Some(kv) => match kv.split_once('=') {
                            Some((k, v)) => Some((k.to_string(), v.to_string())),
                            None => {
                                return Err(valgi::raster::RenderError::Settings(format!(
                                    "--change-option {kv}: expected KEY=VALUE"
                                )))
                            }
                        },
                    },
                })
            })();
            match request
                .map_err(valgi::viewer::ViewerError::from)
                .and_then(|r| valgi::viewer::run(&r))
            {
                Ok(report) => {
                    println!("{report}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Bench(args) if !args.views.is_empty() => {
            let large = args
                .large
                .split_once('x')
                .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                .filter(|&(w, h): &(u32, u32)| w > 0 && h > 0);
            let Some(large) = large else {
                eprintln!("error: --large {}: expected WIDTHxHEIGHT", args.large);
                return ExitCode::FAILURE;
            };
            let request = valgi::views_bench::ViewsBenchRequest {
                scene: args.scene,
                views: args.views,
                methods: args.methods,
                width: args.width,
                height: args.height,
                large,
                glossy_size: args.glossy_size,
                out: args.out,
            };
            match valgi::views_bench::run(&request) {
                Ok(path) => {
                    println!("wrote {}", path.display());
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Bench(args) => {
            let request = valgi::bench::BenchRequest {
                scene: args.scene,
                width: args.width,
                height: args.height,
                vals: args.vals,
                points: args.points,
                small: args.small,
                brute: !args.no_brute,
                out: args.out,
                edits: args.scene_edits.edits(),
                gather_slices: args.gather_slices,
                tiles: args.tiles,
            };
            match valgi::bench::run(&request) {
                Ok(path) => {
                    println!("wrote {}", path.display());
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Eval(args) => run_eval(args),
        Command::Bake(args) => bake(args),
        Command::BakeBench(args) => bake_bench(args),
        Command::NegativeBench(args) => negative_bench(args),
        Command::Mr(args) => {
            match mr_request(args).and_then(|r| valgi::mixed_reality::run::run(&r)) {
                Ok(report) => {
                    println!("{report}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Preview(args) => {
            valgi::progress::install_ctrl_c();
            match preview(args) {
                Ok(report) => {
                    println!("{report}");
                    ExitCode::SUCCESS
                }
                Err(e) => {
                    eprintln!("error: {e}");
                    ExitCode::FAILURE
                }
            }
        }
        Command::Scenes => {
            let names = builtin::names();
            let width = names.iter().map(|(n, _)| n.len()).max().unwrap_or(0);
            for (name, description) in names {
                println!("{name:<width$}  {description}");
            }
            ExitCode::SUCCESS
        }
        Command::Methods => {
            for entry in valgi::method::REGISTRY {
                println!("{:<14} {}", entry.name, entry.help);
                for o in entry.options {
                    let default = if o.default.is_empty() {
                        String::new()
                    } else {
                        format!(" (default {})", o.default)
                    };
                    println!(
                        "{:<16} --{} {}: {}{default}",
                        "",
                        o.name,
                        o.value_hint(),
                        o.help
                    );
                }
            }
            ExitCode::SUCCESS
        }
        Command::Adapters => {
            let instance = wgpu::Instance::new(
                wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
            );
            let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
            if adapters.is_empty() {
                eprintln!("no GPU adapter found");
                return ExitCode::FAILURE;
            }
            for adapter in adapters {
                let info = adapter.get_info();
                println!("{} ({:?}, {:?})", info.name, info.backend, info.device_type);
            }
            ExitCode::SUCCESS
        }
    }
}

/// `valgi bake`: progress bar on a terminal, Ctrl-C stops cleanly (no file is left).
fn bake(args: BakeArgs) -> ExitCode {
    valgi::progress::install_ctrl_c();
    let cancel = valgi::progress::cancel_flag();
    // One progress step per bake stage: a bar on a terminal, a summary line otherwise.
    let stages = valgi::progress::Stages::new("bake");
    let progress = |stage: &str, done: usize, total: usize| stages.report(stage, done, total);
    let request = valgi::atlas::BakeRequest {
        scene: args.scene,
        max_edge: args.max_edge,
        edits: valgi::scene::edits::SceneEdits {
            lights: args.added_lights,
            drop_scene_lights: args.no_scene_lights,
            ..Default::default()
        },
        settings: valgi::atlas::BakeSettings {
            lights: args.lights,
            vpls: args.vpls,
            bounces: args.bounces,
            atlas_res: args.atlas_res,
            near_rays: args.near_rays,
            cube_res: args.cube_res,
            near_radius: args.near_radius,
            seed: args.seed,
            polygon: valgi::atlas::bake::PolygonSettings {
                cluster_size: args.cluster_size,
                cube_res: args.polygon_cube_res,
                ..Default::default()
            },
            ..Default::default()
        },
        from_bounce: args.from_bounce,
        out: args.out,
    };
    let result = valgi::atlas::bake_to_file(&request, &progress, cancel);
    stages.finish();
    match result {
        Ok(summary) => {
            println!("{summary}");
            ExitCode::SUCCESS
        }
        Err(valgi::atlas::BakeError::Cancelled) => {
            eprintln!("cancelled: no atlas written");
            ExitCode::from(valgi::progress::CANCELLED_EXIT_CODE)
        }
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `out/<stem>` for a built-in name or a file path.
fn scene_stem(scene: &str) -> String {
    std::path::Path::new(scene)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("render")
        .to_string()
}

/// The `--sweep-*` axes as a grid.
fn sweep_grid(args: &EvalArgs) -> Result<valgi::eval::sweep::SweepGrid, String> {
    fn numbers(flag: &str, text: &str) -> Result<Vec<u32>, String> {
        valgi::eval::split_list(text)
            .iter()
            .map(|v| {
                v.parse()
                    .map_err(|_| format!("--{flag} {v}: not a whole number"))
            })
            .collect()
    }
    Ok(valgi::eval::sweep::SweepGrid {
        points: numbers("sweep-points", &args.sweep_points)?,
        rsm: numbers("sweep-rsm", &args.sweep_rsm)?,
        visibility: valgi::eval::split_list(&args.sweep_visibility)
            .iter()
            .map(|v| valgi::eval::sweep::SweepVisibility::parse(v).map_err(|e| e.to_string()))
            .collect::<Result<_, _>>()?,
    })
}

fn run_eval(args: EvalArgs) -> ExitCode {
    let ref_bounces = match args.ref_bounces.parse() {
        Ok(b) => b,
        Err(e) => {
            eprintln!("error: --ref-bounces: {e}");
            return ExitCode::FAILURE;
        }
    };
    let sweep = if args.sweep {
        match sweep_grid(&args) {
            Ok(grid) => Some(grid),
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        None
    };
    let methods = match (&args.methods, args.sweep) {
        (Some(text), _) => text.as_str(),
        (None, true) => "",
        (None, false) => "direct,sparse,reference",
    };
    let request = valgi::eval::EvalRequest {
        scenes: valgi::eval::split_list(&args.scenes),
        methods: valgi::eval::split_method_specs(methods),
        sweep,
        out: args.out,
        width: args.width,
        height: args.height,
        camera: args.camera,
        edits: args.scene_edits.edits(),
        ref_spp: args.ref_spp,
        ref_bounces,
        ref_specular: args.ref_specular == "on",
        frames: args.frames,
        max_edge: args
            .max_edge
            .unwrap_or(builtin::BuiltinParams::default().max_edge),
        sparse_spacing: args.max_edge.is_none(),
        emitter_lights: args.emitter_lights,
        exposure: args.exposure,
        ..valgi::eval::EvalRequest::default()
    };
    valgi::progress::install_ctrl_c();
    let (result, seconds) = valgi::eval::timed(|| valgi::eval::run(&request));
    match result {
        Ok(summary) => {
            let report = serde_json::json!({
                "csv": summary.csv.display().to_string(),
                "charts": summary.charts.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "sheets": summary.sheets.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "rows": summary.rows.len(),
                "references_rendered": summary.references_rendered,
                "references_cached": summary.references_cached,
                "sweep_csv": summary.sweep_csv.as_ref().map(|p| p.display().to_string()),
                "wall_s": (seconds * 1000.0).round() / 1000.0,
            });
            println!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => failure(&e),
    }
}

/// A subcommand's method flags and `--opt KEY=VALUE` pairs as method options.
fn method_options(
    matches: &clap::ArgMatches,
    subcommand: &str,
    pairs: &[String],
) -> Result<valgi::method::MethodOptions, String> {
    let mut options = valgi::method::MethodOptions::default();
    if let Some(sub) = matches.subcommand_matches(subcommand) {
        for (spec, _) in valgi::method::all_options() {
            if let Some(value) = sub.get_one::<String>(spec.name) {
                options.set(spec.name, value);
            }
        }
    }
    for pair in pairs {
        let Some((key, value)) = pair.split_once('=') else {
            return Err(format!("--opt {pair}: expected KEY=VALUE"));
        };
        options.set(key.trim(), value.trim());
    }
    Ok(options)
}

/// `valgi render`'s and `valgi view`'s method flags, one per option in the method registry
/// (`--rsm 64` is `--opt rsm=64`); values are checked by the chosen method's entry.
fn with_method_flags(cli: clap::Command) -> clap::Command {
    cli.mut_subcommand("render", add_method_flags)
        .mut_subcommand("view", add_method_flags)
}

fn add_method_flags(render: clap::Command) -> clap::Command {
    let mut render = render;
    {
        for (spec, methods) in valgi::method::all_options() {
            let default = if spec.default.is_empty() {
                String::new()
            } else {
                format!("; default {}", spec.default)
            };
            render = render.arg(
                clap::Arg::new(spec.name)
                    .long(spec.name)
                    .value_name(spec.value_hint())
                    .allow_negative_numbers(true)
                    .help(format!("{} ({}{default})", spec.help, methods.join(", "))),
            );
        }
        render
    }
}

/// The range of `render --sparse-points` (the registry's), for `mr` as well.
const MAX_SPARSE_POINTS: usize = 1 << 20;

/// `valgi mr`'s flags → the library's request.
fn mr_request(
    args: MrArgs,
) -> Result<valgi::mixed_reality::run::MrRequest, valgi::mixed_reality::run::MrError> {
    use valgi::mixed_reality::run::{self, FrameSource, MrError};
    use valgi::mixed_reality::{rgbd::DepthFormat, session};
    let source = match (args.rgbd, args.color, args.depth) {
        (Some(dir), None, None) => FrameSource::Folder(dir),
        (None, Some(color), Some(depth)) => FrameSource::Pair { color, depth },
        _ => {
            return Err(MrError::Settings(
                "give --rgbd DIR, or --color FILE and --depth FILE".into(),
            ))
        }
    };
    let place = match args.place.as_str() {
        "auto" => None,
        text => Some(session::parse_point(text)?),
    };
    let lights = args
        .light
        .iter()
        .map(|l| session::parse_light(l))
        .collect::<Result<Vec<_>, _>>()?;
    let depth = valgi::mixed_reality::depth_vals::DepthValSettings {
        radius: args.bilateral_radius,
        sigma_spatial: args.sigma_spatial,
        sigma_range: args.sigma_range,
        real_scale: args.real_scale,
        true_area: args.real_area == "true",
        real_vals: args.real_vals,
        real_cut: match args.real_cut {
            Some(0.0) => None,
            Some(ratio) => Some(ratio),
            None if args.real_vals.is_none() && args.accumulate <= 1 => {
                Some(valgi::mixed_reality::depth_vals::DEFAULT_REAL_CUT)
            }
            None => None,
        },
        accumulate: args.accumulate,
        voxel: args.voxel,
        real_occluders: args.real_occluders == "on",
        real_thickness: args.real_thickness,
        ..Default::default()
    };
    depth.check()?;
    if !(1..=MAX_SPARSE_POINTS).contains(&args.sparse_points) {
        return Err(MrError::Settings(format!(
            "--sparse-points {}: must be 1..={MAX_SPARSE_POINTS}",
            args.sparse_points
        )));
    }
    let defaults = valgi::vals::SparseSettings::default();
    let sparse = valgi::vals::SparseSettings {
        rsm: args.rsm,
        sparse_points: args.sparse_points,
        options: valgi::vals::sparse::SparseOptions {
            occlusion: match args.occlusion.as_str() {
                "sum" => valgi::vals::math::OcclusionMode::Sum,
                "union" => valgi::vals::math::OcclusionMode::Union,
                "off" => valgi::vals::math::OcclusionMode::Off,
                _ => valgi::vals::math::OcclusionMode::Rays,
            },
            ..defaults.options
        },
        ..defaults
    };
    Ok(run::MrRequest {
        source,
        format: DepthFormat::parse(&args.format)?,
        intrinsics: args.intrinsics,
        trajectory: args.trajectory,
        frames: run::parse_frames(&args.frames)?,
        object: args.object,
        place,
        yaw: args.yaw,
        scale: args.scale,
        lights,
        settings: session::MrSettings {
            depth,
            sparse,
            differential_rays: args.differential_rays,
            ..Default::default()
        },
        out: args.out,
    })
}
