//! `valgi bake-bench`: bake time and indirect error against the B-bounce path-traced reference
//! for a list of VPL counts per scene (the shape of seed 000's Table 1), and the path tracer's
//! own convergence (time to reach a FLIP against the same high-spp reference), so the atlas's
//! speed-up at equal FLIP is measured, not assumed. Writes `bake.csv`,
//! `reference_convergence.csv` and `bake_<scene>.png` into the output folder; references are
//! cached in `cache/` like the harness's.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use plotters::prelude::*;

use super::bake::PolygonSettings;
use super::{bake, AtlasLayer, AtlasMethod, BakeSettings, Lights};
use crate::eval::{cached_reference, metrics, plot, reference_key, slug, EvalError};
use crate::gpu::GpuContext;
use crate::image_io::Image;
use crate::method::Method;
use crate::raster::{Rasterizer, RenderSettings};
use crate::reference::{self, Bounces, ReferenceSettings};
use crate::scene::{self, builtin::BuiltinParams};

/// One `valgi bake-bench` invocation.
#[derive(Clone, Debug)]
pub struct BakeBenchRequest {
    pub scenes: Vec<String>,
    /// The bakers measured.
    pub lights: Vec<Lights>,
    /// Patch counts of the patch baker.
    pub vpls: Vec<usize>,
    /// Photon paths of the polygon-light baker.
    pub polygon_vpls: Vec<usize>,
    /// Target VPLs per cluster of the polygon-light baker.
    pub cluster_size: usize,
    pub bounces: u32,
    pub atlas_res: u32,
    /// Image size of the error measurement.
    pub width: u32,
    pub height: u32,
    /// Paths per pixel of the reference every error is measured against.
    pub ref_spp: u32,
    pub ref_seed: u64,
    /// Checkpoints of the path tracer's convergence run (paths per pixel, another seed).
    pub pt_spp: Vec<u32>,
    /// The FLIP at which the path tracer's time is reported (`pt_ms_at_target`).
    pub flip_target: f64,
    /// N×N supersampling of the atlas renders (the reference box-filters its pixels).
    pub ssaa: u32,
    /// Near-field gather rays per texel of every bake.
    pub near_rays: u32,
    /// Face resolution of every bake's shooter depth cubes.
    pub cube_res: usize,
    /// Near-field radius of every bake (sample spacings).
    pub near_radius: f32,
    pub max_edge: f32,
    pub out: PathBuf,
    pub progress: bool,
}

impl Default for BakeBenchRequest {
    fn default() -> Self {
        Self {
            scenes: vec!["cornell".into(), "corridor".into()],
            lights: vec![Lights::Patches],
            vpls: vec![100, 400, 1600, 6400],
            polygon_vpls: vec![5000, 20000, 80000],
            cluster_size: PolygonSettings::default().cluster_size,
            bounces: 4,
            atlas_res: 256,
            width: 128,
            height: 128,
            ref_spp: 4096,
            ref_seed: 0x5EED,
            pt_spp: vec![1, 4, 16, 64, 256, 1024],
            flip_target: 0.05,
            ssaa: 4,
            near_rays: BakeSettings::default().near_rays,
            cube_res: BakeSettings::default().cube_res,
            near_radius: BakeSettings::default().near_radius,
            max_edge: BuiltinParams::default().max_edge,
            out: PathBuf::from("out/bake-bench"),
            progress: true,
        }
    }
}

/// One row of `bake.csv`.
#[derive(Clone, Debug)]
pub struct BakeRow {
    pub scene: String,
    pub lights: Lights,
    /// Patches (patch baker) or photon paths (polygon lights).
    pub vpls: usize,
    pub bounces: u32,
    pub atlas_res: u32,
    pub texels: usize,
    pub shots: usize,
    /// Virtual lights the polygon baker made (0 for patches).
    pub virtual_lights: usize,
    /// Wall time of `atlas::bake` (CPU, all cores).
    pub bake_ms: f64,
    pub stages_ms: Vec<(String, f64)>,
    /// GPU time of one atlas frame (lookup + apply + the rest of the frame).
    pub render_ms: f64,
    pub flip_indirect: f64,
    pub rmse_indirect: f64,
    pub relmse_indirect: f64,
    /// Mean indirect luminance over the reference's.
    pub mean_ratio: f64,
    /// Path-tracer wall time to reach the atlas's FLIP (log-log interpolation of the
    /// convergence curve; `None` when the curve never gets there).
    pub pt_ms_same_flip: Option<f64>,
}

impl BakeRow {
    /// Path-tracer time at equal FLIP over bake + render time.
    pub fn speedup(&self) -> Option<f64> {
        self.pt_ms_same_flip
            .map(|pt| pt / (self.bake_ms + self.render_ms))
    }
}

/// One path-tracer run of the convergence curve.
#[derive(Clone, Debug)]
pub struct ConvergencePoint {
    pub scene: String,
    pub spp: u32,
    pub ms: f64,
    pub flip_indirect: f64,
    pub rmse_indirect: f64,
}

/// What a run wrote and measured.
#[derive(Clone, Debug)]
pub struct BakeBenchSummary {
    pub rows: Vec<BakeRow>,
    pub convergence: Vec<ConvergencePoint>,
    /// Per scene: path-tracer ms to reach `flip_target` (`None`: not within the curve).
    pub pt_ms_at_target: Vec<(String, Option<f64>)>,
    pub csv: PathBuf,
    pub convergence_csv: PathBuf,
    pub charts: Vec<PathBuf>,
}

pub const CSV_HEADER: &str = "scene,vpls,bounces,atlas_res,texels,shots,bake_ms,stages_ms,render_ms,flip_indirect,rmse_indirect,relmse_indirect,mean_ratio,pt_ms_same_flip,speedup,lights,virtual_lights";

/// Time the convergence curve needs to reach `flip`: the first run at or below it, log-log
/// interpolated with the run before; `None` when no run gets there.
pub fn time_to_flip(curve: &[ConvergencePoint], flip: f64) -> Option<f64> {
    let i = curve.iter().position(|p| p.flip_indirect <= flip)?;
    if i == 0 {
        return Some(curve[0].ms);
    }
    let (a, b) = (&curve[i - 1], &curve[i]);
    let (fa, fb) = (a.flip_indirect.ln(), b.flip_indirect.ln());
    if (fa - fb).abs() < 1e-12 {
        return Some(b.ms);
    }
    let t = (fa - flip.ln()) / (fa - fb);
    Some((a.ms.ln() + t * (b.ms.ln() - a.ms.ln())).exp())
}

fn output_error(path: &Path, e: impl std::fmt::Display) -> EvalError {
    EvalError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

fn opt(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.3}")).unwrap_or_default()
}

/// Runs the benchmark and writes its files under `request.out`.
pub fn run(request: &BakeBenchRequest) -> Result<BakeBenchSummary, EvalError> {
    if request.scenes.is_empty() || request.vpls.is_empty() || request.pt_spp.is_empty() {
        return Err(EvalError::Settings(
            "bake-bench needs scenes, VPL counts and path-tracer spp".into(),
        ));
    }
    let cache_dir = request.out.join("cache");
    std::fs::create_dir_all(&cache_dir).map_err(|e| output_error(&cache_dir, e))?;
    let ctx = GpuContext::new()?;
    let params = BuiltinParams {
        max_edge: request.max_edge,
    };
    let bounces = Bounces::Limited(request.bounces);
    let mut summary = BakeBenchSummary {
        rows: vec![],
        convergence: vec![],
        pt_ms_at_target: vec![],
        csv: request.out.join("bake.csv"),
        convergence_csv: request.out.join("reference_convergence.csv"),
        charts: vec![],
    };
    for scene_spec in &request.scenes {
        let scene = scene::load(scene_spec, &params)?;
        let world = scene.world_from_node();
        let aspect = request.width as f32 / request.height as f32;
        let camera = scene.camera_view(None, aspect, &world)?;
        let ref_settings = |spp: u32, seed: u64| ReferenceSettings {
            width: request.width,
            height: request.height,
            spp,
            bounces,
            seed,
            progress: request.progress,
            specular: true,
        };
        let key = reference_key(
            scene_spec,
            None,
            request.width,
            request.height,
            bounces,
            request.ref_spp,
            request.ref_seed,
            request.max_edge,
            0.0,
            true,
        );
        let reference = cached_reference(&cache_dir, &key, || {
            log::info!("rendering reference: {key}");
            reference::render(
                &scene,
                &world,
                &camera,
                &ref_settings(request.ref_spp, request.ref_seed),
            )
        })?;
        let ref_indirect = &reference.indirect;
        let ref_exr = request
            .out
            .join(format!("{}_reference.indirect.exr", slug(&scene.name)));
        ref_indirect
            .write_exr(&ref_exr)
            .map_err(|e| output_error(&ref_exr, e))?;
        let exposure = metrics::auto_exposure(ref_indirect);
        let ref_mean = metrics::mean_luminance(ref_indirect);

        // The path tracer's convergence against the same reference (independent seed): one
        // progressive run, each point timed as the separate render it equals.
        let mut curve = vec![];
        reference::render_progressive(
            &scene,
            &world,
            &camera,
            &ref_settings(0, request.ref_seed ^ 0xC0FFEE),
            &request.pt_spp,
            |spp, image| {
                let mut indirect = image.indirect;
                indirect.sanitize();
                log::info!("path tracer {spp} spp: {:.1} s", image.seconds);
                curve.push(ConvergencePoint {
                    scene: scene.name.clone(),
                    spp,
                    ms: image.seconds * 1000.0,
                    flip_indirect: metrics::flip(&indirect, ref_indirect, exposure),
                    rmse_indirect: metrics::rmse(&indirect, ref_indirect),
                });
            },
        );
        curve.sort_by_key(|p| p.spp);
        summary.pt_ms_at_target.push((
            scene.name.clone(),
            time_to_flip(&curve, request.flip_target),
        ));

        let mut rows = vec![];
        let runs: Vec<(Lights, usize)> = request
            .lights
            .iter()
            .flat_map(|&lights| {
                let counts = match lights {
                    Lights::Patches => &request.vpls,
                    Lights::Polygons => &request.polygon_vpls,
                };
                counts.iter().map(move |&n| (lights, n))
            })
            .collect();
        for (lights, vpls) in runs {
            let settings = BakeSettings {
                lights,
                vpls,
                polygon: PolygonSettings {
                    cluster_size: request.cluster_size,
                    ..Default::default()
                },
                bounces: request.bounces,
                atlas_res: request.atlas_res,
                near_rays: request.near_rays,
                cube_res: request.cube_res,
                near_radius: request.near_radius,
                ..Default::default()
            };
            let started = Instant::now();
            let result = bake(
                &scene,
                &world,
                &settings,
                &|_, _, _| {},
                &AtomicBool::new(false),
            )
            .map_err(|e| EvalError::Settings(format!("bake ({lights}) {vpls} VPLs: {e}")))?;
            let bake_ms = started.elapsed().as_secs_f64() * 1000.0;
            let atlas = result.atlas(1, request.bounces);
            let render = RenderSettings {
                width: request.width,
                height: request.height,
                ssaa: request.ssaa.max(1),
                ..RenderSettings::default()
            };
            let raster = Rasterizer::new(&ctx, &scene, render)?;
            let layer = AtlasLayer::new(&ctx, &scene, &atlas)?;
            let mut method = AtlasMethod {
                raster,
                layer,
                setup_ms: Vec::new(),
            };
            let frame = method.render(&ctx, &scene, &world, &camera)?;
            let mut indirect: Image = frame.indirect;
            indirect.sanitize();
            let (flip, flip_map) = metrics::flip_with_map(&indirect, ref_indirect, exposure);
            let stem = request.out.join(match lights {
                Lights::Patches => format!("{}_{vpls}vpls", slug(&scene.name)),
                Lights::Polygons => format!("{}_polygons_{vpls}paths", slug(&scene.name)),
            });
            let exr = stem.with_extension("indirect.exr");
            indirect
                .write_exr(&exr)
                .map_err(|e| output_error(&exr, e))?;
            let png = stem.with_extension("flip.png");
            flip_map.save(&png).map_err(|e| output_error(&png, e))?;
            let row = BakeRow {
                scene: scene.name.clone(),
                lights,
                vpls,
                virtual_lights: result.virtual_lights.len(),
                bounces: request.bounces,
                atlas_res: request.atlas_res,
                texels: result.texel_count(),
                shots: result.shots,
                bake_ms,
                stages_ms: result.stage_ms.clone(),
                render_ms: frame.timings.total_ms(),
                flip_indirect: flip,
                rmse_indirect: metrics::rmse(&indirect, ref_indirect),
                relmse_indirect: metrics::relmse(&indirect, ref_indirect),
                mean_ratio: if ref_mean > 0.0 {
                    metrics::mean_luminance(&indirect) / ref_mean
                } else {
                    f64::NAN
                },
                pt_ms_same_flip: time_to_flip(&curve, flip),
            };
            log::info!(
                "{} {lights} {vpls} VPLs: bake {:.0} ms, indirect FLIP {:.4}",
                scene.name,
                bake_ms,
                flip
            );
            rows.push(row);
        }
        let chart = request.out.join(format!("bake_{}.png", slug(&scene.name)));
        chart_scene(&chart, request, &scene.name, &rows, &curve)?;
        summary.charts.push(chart);
        summary.rows.extend(rows);
        summary.convergence.extend(curve);
    }

    let mut csv = String::new();
    let _ = writeln!(csv, "{CSV_HEADER}");
    for r in &summary.rows {
        let stages: Vec<String> = r
            .stages_ms
            .iter()
            .map(|(s, ms)| format!("{s}={ms:.1}"))
            .collect();
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{:.1},{},{:.3},{:.6},{:.6e},{:.6e},{:.4},{},{},{},{}",
            r.scene,
            r.vpls,
            r.bounces,
            r.atlas_res,
            r.texels,
            r.shots,
            r.bake_ms,
            stages.join(";"),
            r.render_ms,
            r.flip_indirect,
            r.rmse_indirect,
            r.relmse_indirect,
            r.mean_ratio,
            opt(r.pt_ms_same_flip),
            opt(r.speedup()),
            r.lights,
            r.virtual_lights,
        );
    }
    std::fs::write(&summary.csv, csv).map_err(|e| output_error(&summary.csv, e))?;
    let mut csv = String::from("scene,spp,ms,flip_indirect,rmse_indirect\n");
    for p in &summary.convergence {
        let _ = writeln!(
            csv,
            "{},{},{:.1},{:.6},{:.6e}",
            p.scene, p.spp, p.ms, p.flip_indirect, p.rmse_indirect
        );
    }
    std::fs::write(&summary.convergence_csv, csv)
        .map_err(|e| output_error(&summary.convergence_csv, e))?;
    Ok(summary)
}

/// (x, y, label) of a chart point.
type LabelledPoint = (f64, f64, String);

fn tick(v: f64) -> String {
    if v >= 1e4 || (v < 1e-2 && v > 0.0) {
        format!("{v:.0e}")
    } else if v >= 10.0 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Left: bake time against VPL count. Right: indirect FLIP against time, the atlas (bake +
/// render) and the path tracer, with the FLIP target as a dashed line.
fn chart_scene(
    path: &Path,
    request: &BakeBenchRequest,
    scene: &str,
    rows: &[BakeRow],
    curve: &[ConvergencePoint],
) -> Result<(), EvalError> {
    plot::register_font();
    let font = plot::FONT;
    let (width, height) = (1200u32, 520u32);
    let mut buffer = vec![0u8; (width * height * 3) as usize];
    let err = |e| output_error(path, e);
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let root = root
            .titled(
                &format!(
                    "{scene}: atlas bake, {} bounces, {}² texels; error vs {}-spp reference at {}x{}",
                    request.bounces, request.atlas_res, request.ref_spp, request.width, request.height
                ),
                (font, 20),
            )
            .map_err(|e| err(e.to_string()))?;
        let (left, right) = root.split_horizontally(width / 2);
        let log_range = |v: &mut dyn Iterator<Item = f64>| {
            let (lo, hi) = v
                .filter(|x| *x > 0.0 && x.is_finite())
                .fold((f64::INFINITY, 0.0f64), |(lo, hi), x| {
                    (lo.min(x), hi.max(x))
                });
            if lo.is_finite() && hi > 0.0 {
                (lo / 2.0, hi * 2.0)
            } else {
                (1.0, 10.0)
            }
        };
        let (v0, v1) = log_range(&mut rows.iter().map(|r| r.vpls as f64));
        let (t0, t1) = log_range(&mut rows.iter().map(|r| r.bake_ms));
        let mut chart = ChartBuilder::on(&left)
            .margin(16)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((v0..v1).log_scale(), (t0..t1).log_scale())
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("VPLs (log)")
            .y_desc("bake time (ms, log)")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style((font, 13))
            .axis_desc_style((font, 15))
            .draw()
            .map_err(|e| err(e.to_string()))?;
        let color = |lights: Lights| match lights {
            Lights::Patches => Palette99::pick(0).to_rgba(),
            Lights::Polygons => Palette99::pick(2).to_rgba(),
        };
        let second = Palette99::pick(1).to_rgba();
        for &lights in &request.lights {
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.lights == lights)
                .map(|r| (r.vpls as f64, r.bake_ms))
                .collect();
            let c = color(lights);
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                .map_err(|e| err(e.to_string()))?;
            chart
                .draw_series(pts.iter().map(|p| Circle::new(*p, 5, c.filled())))
                .map_err(|e| err(e.to_string()))?;
        }

        let (x0, x1) = log_range(
            &mut rows
                .iter()
                .map(|r| r.bake_ms + r.render_ms)
                .chain(curve.iter().map(|p| p.ms)),
        );
        let (y0, y1) = log_range(
            &mut rows
                .iter()
                .map(|r| r.flip_indirect)
                .chain(curve.iter().map(|p| p.flip_indirect))
                .chain(std::iter::once(request.flip_target)),
        );
        let mut chart = ChartBuilder::on(&right)
            .margin(16)
            .x_label_area_size(45)
            .y_label_area_size(70)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1.min(1.0)).log_scale())
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("wall time (ms, log): bake + render, or path tracing")
            .y_desc("FLIP of the indirect image (log)")
            .x_label_formatter(&|v| tick(*v))
            .y_label_formatter(&|v| tick(*v))
            .label_style((font, 13))
            .axis_desc_style((font, 15))
            .draw()
            .map_err(|e| err(e.to_string()))?;
        let mut series: Vec<(&str, Vec<LabelledPoint>, RGBAColor)> = request
            .lights
            .iter()
            .map(|&lights| {
                (
                    match lights {
                        Lights::Patches => "atlas, patches (VPLs)",
                        Lights::Polygons => "atlas, polygon lights (photon paths)",
                    },
                    rows.iter()
                        .filter(|r| r.lights == lights)
                        .map(|r| {
                            (
                                r.bake_ms + r.render_ms,
                                r.flip_indirect,
                                format!("{}", r.vpls),
                            )
                        })
                        .collect(),
                    color(lights),
                )
            })
            .collect();
        series.push((
            "path tracer (spp)",
            curve
                .iter()
                .map(|p| (p.ms, p.flip_indirect, format!("{}", p.spp)))
                .collect(),
            second,
        ));
        for (name, pts, color) in series {
            chart
                .draw_series(LineSeries::new(
                    pts.iter().map(|p| (p.0, p.1)),
                    color.stroke_width(2),
                ))
                .map_err(|e| err(e.to_string()))?
                .label(name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
            chart
                .draw_series(
                    pts.iter()
                        .map(|p| Circle::new((p.0, p.1), 4, color.filled())),
                )
                .map_err(|e| err(e.to_string()))?;
            chart
                .draw_series(pts.iter().map(|p| {
                    Text::new(
                        p.2.clone(),
                        (p.0, p.1),
                        (font, 12).into_font().color(&BLACK),
                    )
                }))
                .map_err(|e| err(e.to_string()))?;
        }
        chart
            .draw_series(DashedLineSeries::new(
                [(x0, request.flip_target), (x1, request.flip_target)],
                6,
                4,
                BLACK.mix(0.5).stroke_width(1),
            ))
            .map_err(|e| err(e.to_string()))?
            .label(format!("FLIP {}", request.flip_target))
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK.mix(0.5)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((font, 13))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| err(e.to_string()))?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    let image = image::RgbImage::from_raw(width, height, buffer)
        .ok_or_else(|| output_error(path, "image buffer of the wrong size"))?;
    image
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| output_error(path, e))
}
