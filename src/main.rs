//! `valgi` command line: argument parsing only; the work is in the library.

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
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
    /// Bake the multi-bounce light atlas of a scene to an EXR (irradiance per texel); prints
    /// one JSON line with stage times, VPLs, texels and the energy account.
    Bake(BakeArgs),
    /// List the built-in scenes.
    Scenes,
    /// List the rendering methods.
    Methods,
    /// List the GPU adapters wgpu can see (honours WGPU_BACKEND).
    Adapters,
}

#[derive(clap::Args)]
struct RenderArgs {
    /// Built-in scene name (see `valgi scenes`) or a .gltf/.glb file.
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// Rendering method (see `valgi methods`).
    #[arg(long, default_value = "direct")]
    method: String,
    #[arg(long, default_value_t = 512)]
    width: u32,
    #[arg(long, default_value_t = 512)]
    height: u32,
    /// Camera name or index (default: the scene's first camera, or one framing the scene).
    #[arg(long)]
    camera: Option<String>,
    /// Output file (.exr = linear 32-bit float, .png = tone-mapped). Repeatable. Default:
    /// out/<scene>.exr and out/<scene>.png.
    #[arg(long)]
    out: Vec<PathBuf>,
    /// PNG exposure in stops: png = sRGB(clamp(radiance × 2^E)).
    #[arg(long, default_value_t = 0.0)]
    exposure: f32,
    /// Write only the indirect part of the radiance (direct light removed).
    #[arg(long)]
    indirect_only: bool,
    /// N×N supersampling per pixel for anti-aliased edges.
    #[arg(long, default_value_t = 1)]
    ssaa: u32,
    /// Shadow-map resolution per layer (a point light uses six layers).
    #[arg(long, default_value_t = 1024)]
    shadow_res: u32,
    /// Tessellation of built-in scenes: maximum triangle edge length in metres.
    #[arg(long, default_value_t = builtin::BuiltinParams::default().max_edge)]
    max_edge: f32,
    /// Animation time in seconds (glTF animations).
    #[arg(long, default_value_t = 0.0)]
    time: f32,
    /// A method option as key=value (repeatable); the method-specific flags are shorthands.
    #[arg(long = "opt", value_name = "KEY=VALUE")]
    options: Vec<String>,
    /// Baked light atlas for `--method atlas` (shorthand for --opt atlas=FILE).
    #[arg(long)]
    atlas: Option<PathBuf>,
}

#[derive(clap::Args)]
struct BakeArgs {
    /// Built-in scene name (see `valgi scenes`) or a .gltf/.glb file.
    #[arg(long, default_value = "cornell")]
    scene: String,
    /// Output atlas (.exr, linear irradiance in W/m², alpha 1 on texels that hold a surface).
    #[arg(long)]
    out: PathBuf,
    /// Number of VPL patches.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().vpls)]
    vpls: usize,
    /// Indirect bounces kept.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().bounces)]
    bounces: u32,
    /// Atlas width and height in texels.
    #[arg(long, default_value_t = valgi::atlas::BakeSettings::default().atlas_res)]
    atlas_res: u32,
    /// Write bounces K..B only (2 leaves bounce 1 to a dynamic method).
    #[arg(long, default_value_t = 1)]
    from_bounce: u32,
    /// Tessellation of built-in scenes (render with the same value).
    #[arg(long, default_value_t = builtin::BuiltinParams::default().max_edge)]
    max_edge: f32,
}

fn main() -> ExitCode {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    match cli.command {
        Command::Render(args) => {
            let outputs = if args.out.is_empty() {
                let stem = scene_stem(&args.scene);
                vec![
                    PathBuf::from(format!("out/{stem}.exr")),
                    PathBuf::from(format!("out/{stem}.png")),
                ]
            } else {
                args.out
            };
            let mut options = valgi::method::MethodOptions::default();
            for pair in &args.options {
                let Some((key, value)) = pair.split_once('=') else {
                    eprintln!("error: --opt {pair}: expected KEY=VALUE");
                    return ExitCode::FAILURE;
                };
                options.set(key.trim(), value.trim());
            }
            if let Some(atlas) = &args.atlas {
                options.set("atlas", atlas.display());
            }
            let request = RenderRequest {
                scene: args.scene,
                method: args.method,
                options,
                settings: RenderSettings {
                    width: args.width,
                    height: args.height,
                    ssaa: args.ssaa,
                    shadow_resolution: args.shadow_res,
                    ..RenderSettings::default()
                },
                camera: args.camera,
                outputs,
                exposure: args.exposure,
                indirect_only: args.indirect_only,
                max_edge: args.max_edge,
                time: args.time,
            };
            match app::render(&request) {
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
        Command::Bake(args) => bake(args),
        Command::Scenes => {
            for (name, description) in builtin::names() {
                println!("{name:<16} {description}");
            }
            ExitCode::SUCCESS
        }
        Command::Methods => {
            for (name, description) in valgi::method::METHODS {
                println!("{name:<16} {description}");
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
    use std::io::IsTerminal;
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::sync::Arc;

    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        // First Ctrl-C: stop at the next check; a second one: leave at once.
        let handler = move || {
            if cancel.swap(true, Ordering::Relaxed) {
                std::process::exit(130);
            }
        };
        if let Err(e) = ctrlc::set_handler(handler) {
            log::warn!("Ctrl-C handler: {e}");
        }
    }
    let bar = if std::io::stderr().is_terminal() {
        indicatif::ProgressBar::new(1)
    } else {
        indicatif::ProgressBar::hidden()
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} {elapsed}")
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
    );
    let progress = |stage: &str, done: usize, total: usize| {
        bar.set_message(stage.to_string());
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    let request = valgi::atlas::BakeRequest {
        scene: args.scene,
        max_edge: args.max_edge,
        settings: valgi::atlas::BakeSettings {
            vpls: args.vpls,
            bounces: args.bounces,
            atlas_res: args.atlas_res,
            ..Default::default()
        },
        from_bounce: args.from_bounce,
        out: args.out,
    };
    let result = valgi::atlas::bake_to_file(&request, &progress, &cancel);
    bar.finish_and_clear();
    match result {
        Ok(summary) => {
            println!("{summary}");
            ExitCode::SUCCESS
        }
        Err(valgi::atlas::BakeError::Cancelled) => {
            eprintln!("cancelled: no atlas written");
            ExitCode::from(130)
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
