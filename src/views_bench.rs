//! `valgi bench --views 1,2,4,6`: what many views cost. For each method, one frame with N
//! views (the `grid:N` rig, each at the request's size) is timed after a warm-up frame: the
//! update (the view-free passes), the mean per-view record, and the total. One more row per
//! method at the large size checks that the update does not depend on the view resolution.
//! Then the price of sharing the glossy solution between the eyes: `--glossy-eye mid` against
//! `per-view` on `glossy-row` with stereo views, as indirect FLIP and RMSE over the pixels of
//! each sphere (Phong k = 1, 10, 100, 1000). Writes `views.csv`, `glossy_eye.csv` and
//! `views.png`. Timings are measurements, never test assertions.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

use plotters::prelude::*;

use crate::app::AppError;
use crate::eval::metrics;
use crate::frame::{record_frame, View, ViewRig};
use crate::gpu::timing::round3;
use crate::gpu::GpuContext;
use crate::image_io::Image;
use crate::method::{self, MethodOptions};
use crate::raster::{RenderError, RenderSettings};
use crate::scene::{self, builtin::BuiltinParams, Scene};

#[derive(Clone, Debug)]
pub struct ViewsBenchRequest {
    pub scene: String,
    /// View counts.
    pub views: Vec<usize>,
    pub methods: Vec<String>,
    pub width: u32,
    pub height: u32,
    /// The size of the resolution-independence row (one view).
    pub large: (u32, u32),
    /// Size of each eye in the glossy-eye comparison.
    pub glossy_size: u32,
    pub out: PathBuf,
}

/// One timed frame.
#[derive(Clone, Debug)]
pub struct ViewsRow {
    pub method: String,
    pub views: usize,
    pub width: u32,
    pub height: u32,
    pub update_ms: f64,
    pub per_view_ms: f64,
    pub total_ms: f64,
}

fn settings(width: u32, height: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        ..RenderSettings::default()
    }
}

/// A small patch-baked atlas of the scene for the `atlas` rows.
fn atlas_file(scene: &Scene, out: &Path) -> Result<PathBuf, AppError> {
    let path = out.join(format!("{}_atlas.exr", crate::eval::slug(&scene.name)));
    let bake_settings = crate::atlas::BakeSettings {
        vpls: 400,
        ..Default::default()
    };
    let bake = crate::atlas::bake(
        scene,
        &scene.world_from_node(),
        &bake_settings,
        &|_, _, _| {},
        &AtomicBool::new(false),
    )
    .map_err(|e| RenderError::Settings(format!("atlas for the views bench: {e}")))?;
    crate::atlas::write_atlas_with_layout(
        &bake.atlas(1, bake_settings.bounces),
        &path,
        1..=bake_settings.bounces,
        &crate::atlas::stored_layout::StoredLayout::of_bake(
            &bake,
            scene,
            &scene.world_from_node(),
            None,
        ),
    )?;
    Ok(path)
}

/// Times one frame of `method` with `count` grid views of `size` (after one warm-up frame).
fn time_frame(
    ctx: &GpuContext,
    scene: &Scene,
    name: &str,
    options: &MethodOptions,
    count: usize,
    (width, height): (u32, u32),
) -> Result<ViewsRow, AppError> {
    let mut m = method::create(name, ctx, scene, settings(width, height), options)?;
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, width as f32 / height as f32, &world)?;
    let bounds = scene.world_bounds(&world);
    let pivot = (bounds.min + bounds.max) * 0.5;
    let views: Vec<View> = ViewRig::Grid { count }
        .views(&camera, (width, height), pivot)
        .into_iter()
        .map(|r| View::new(ctx, &r.name, r.camera, r.size, 1))
        .collect::<Result<_, _>>()?;
    record_frame(m.as_mut(), ctx, scene, &world, &views)?;
    let frame = record_frame(m.as_mut(), ctx, scene, &world, &views)?;
    let per_view: Vec<f64> = frame.timings.views.iter().map(|t| t.total_ms()).collect();
    let update_ms = frame.timings.solution.total_ms();
    let view_sum: f64 = per_view.iter().sum();
    Ok(ViewsRow {
        method: name.to_string(),
        views: count,
        width,
        height,
        update_ms,
        per_view_ms: view_sum / count.max(1) as f64,
        total_ms: update_ms + view_sum,
    })
}

pub fn run(request: &ViewsBenchRequest) -> Result<PathBuf, AppError> {
    std::fs::create_dir_all(&request.out).map_err(|e| {
        RenderError::Settings(format!("cannot create {}: {e}", request.out.display()))
    })?;
    if request
        .views
        .iter()
        .any(|&n| !(1..=crate::frame::rig::MAX_VIEWS).contains(&n))
    {
        return Err(RenderError::Settings(format!(
            "--views: counts must be 1..={}",
            crate::frame::rig::MAX_VIEWS
        ))
        .into());
    }
    let scene = scene::load(&request.scene, &BuiltinParams::default())?;
    let ctx = GpuContext::new()?;
    println!("device: {}", ctx.adapter_label());
    let mut rows = Vec::new();
    let mut atlas = None;
    for name in &request.methods {
        method::entry(name)?;
        let mut options = MethodOptions::default();
        if name == "atlas" || name == "sparse+atlas" {
            if atlas.is_none() {
                atlas = Some(atlas_file(&scene, &request.out)?);
            }
            options.set("atlas", atlas.as_ref().expect("baked").display());
        }
        let mut sizes: Vec<(usize, (u32, u32))> = request
            .views
            .iter()
            .map(|&n| (n, (request.width, request.height)))
            .collect();
        sizes.push((1, request.large));
        for (count, size) in sizes {
            let row = time_frame(&ctx, &scene, name, &options, count, size)?;
            println!(
                "{:<8} {} view(s) {}×{}: update {:.1} ms, per view {:.1} ms, total {:.1} ms",
                row.method,
                row.views,
                row.width,
                row.height,
                row.update_ms,
                row.per_view_ms,
                row.total_ms
            );
            rows.push(row);
        }
    }
    let csv = request.out.join("views.csv");
    let mut text = String::from("method,views,width,height,update_ms,per_view_ms,total_ms\n");
    for r in &rows {
        text += &format!(
            "{},{},{},{},{},{},{}\n",
            r.method,
            r.views,
            r.width,
            r.height,
            round3(r.update_ms),
            round3(r.per_view_ms),
            round3(r.total_ms)
        );
    }
    write(&csv, &text)?;
    chart(
        &request.out.join("views.png"),
        &rows,
        (request.width, request.height),
    )?;
    let glossy = glossy_eye_error(&ctx, request.glossy_size)?;
    let mut text = String::from("phong_k,indirect_flip,indirect_rmse,relative_rmse\n");
    for (k, flip, rmse, rel) in &glossy {
        println!("glossy eye mid vs per-view, k = {k}: FLIP {flip:.4}, RMSE {rmse:.3e} ({:.2} % of the mean)", rel * 100.0);
        text += &format!("{k},{flip},{rmse},{rel}\n");
    }
    write(&request.out.join("glossy_eye.csv"), &text)?;
    Ok(csv)
}

fn write(path: &Path, text: &str) -> Result<(), AppError> {
    std::fs::File::create(path)
        .and_then(|mut f| f.write_all(text.as_bytes()))
        .map_err(|e| RenderError::Settings(format!("{}: cannot write: {e}", path.display())).into())
}

/// Mid-eye against per-view glossy on `glossy-row`, right eye, stereo at the default IPD:
/// (k, FLIP, RMSE, RMSE / mean) of the indirect light over each sphere's pixels.
fn glossy_eye_error(ctx: &GpuContext, size: u32) -> Result<Vec<(f32, f64, f64, f64)>, AppError> {
    let scene = scene::load("glossy-row", &BuiltinParams::default())?;
    let world = scene.world_from_node();
    let camera = scene.camera_view(None, 1.0, &world)?;
    let render = |eye: &str| -> Result<Image, AppError> {
        let mut options = MethodOptions::default();
        options.set("glossy-eye", eye);
        let mut m = method::create("sparse", ctx, &scene, settings(size, size), &options)?;
        let views: Vec<View> = ViewRig::Stereo {
            ipd: crate::frame::rig::DEFAULT_IPD,
        }
        .views(&camera, (size, size), camera.position())
        .into_iter()
        .map(|r| View::new(ctx, &r.name, r.camera, r.size, 1))
        .collect::<Result<_, _>>()?;
        let frame = record_frame(m.as_mut(), ctx, &scene, &world, &views)?;
        let (_, indirect) = views[1].read(ctx, frame.results[1].has_indirect())?;
        Ok(indirect)
    };
    let mid = render("mid")?;
    let per_view = render("per-view")?;
    let spheres = sphere_masks(&scene, &camera, size);
    let mut out = vec![];
    for (k, mask) in spheres {
        let pick = |image: &Image| -> Image {
            let pixels = image
                .pixels
                .iter()
                .zip(&mask)
                .filter(|(_, &m)| m)
                .map(|(p, _)| *p)
                .collect::<Vec<_>>();
            Image::from_rgba(
                pixels.len().max(1) as u32,
                1,
                if pixels.is_empty() {
                    vec![[0.0; 4]]
                } else {
                    pixels
                },
            )
        };
        let (a, b) = (pick(&mid), pick(&per_view));
        let rmse = metrics::rmse(&a, &b);
        let mean = metrics::mean_luminance(&b).max(1e-12);
        let flip = metrics::flip(&a, &b, 0.0);
        out.push((k, flip, rmse, rmse / mean));
    }
    Ok(out)
}

/// Per sphere of `glossy-row` (by its Phong exponent, from its mesh name `sphere_k<K>`), the
/// pixels of a `size`² image from `camera` whose primary ray meets the sphere's bounding
/// sphere (the spheres stand in a row before the walls; nothing hides them).
fn sphere_masks(
    scene: &Scene,
    camera: &crate::scene::CameraView,
    size: u32,
) -> Vec<(f32, Vec<bool>)> {
    let world = scene.world_from_node();
    let mut out = vec![];
    for instance in &scene.instances {
        let mesh = &scene.meshes[instance.mesh];
        let Some(k) = mesh
            .name
            .strip_prefix("sphere_k")
            .and_then(|k| k.parse::<f32>().ok())
        else {
            continue;
        };
        let bounds = mesh.model_bounds();
        let to_world = world[instance.node];
        let centre = to_world.transform_point3((bounds.min + bounds.max) * 0.5);
        let radius = to_world
            .transform_vector3((bounds.max - bounds.min) * 0.5)
            .abs()
            .max_element();
        let mask = (0..size * size)
            .map(|i| {
                let (x, y) = ((i % size) as f32 + 0.5, (i / size) as f32 + 0.5);
                let (origin, dir) = crate::reference::camera_ray(camera, size, size, x, y);
                let to_centre = centre - origin;
                let along = to_centre.dot(dir);
                along > 0.0 && (to_centre - dir * along).length_squared() < radius * radius
            })
            .collect::<Vec<bool>>();
        if mask.iter().any(|&m| m) {
            out.push((k, mask));
        }
    }
    out
}

/// Total ms against the number of views, one line per method (the request's size).
fn chart(path: &Path, rows: &[ViewsRow], size: (u32, u32)) -> Result<(), AppError> {
    let err = |e: String| -> AppError {
        RenderError::Settings(format!("{}: {e}", path.display())).into()
    };
    let rows: Vec<&ViewsRow> = rows
        .iter()
        .filter(|r| (r.width, r.height) == size)
        .collect();
    let max_views = rows.iter().map(|r| r.views).max().unwrap_or(1) as f64;
    let max_ms = rows.iter().map(|r| r.total_ms).fold(1.0, f64::max) * 1.1;
    crate::eval::plot::register_font();
    let (width, height) = (800u32, 500u32);
    let mut buffer = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| err(e.to_string()))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                format!("frame time against views ({}×{} each)", size.0, size.1),
                (crate::eval::plot::FONT, 20),
            )
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0.5..max_views + 0.5, 0.0..max_ms)
            .map_err(|e| err(e.to_string()))?;
        chart
            .configure_mesh()
            .x_desc("views")
            .y_desc("ms per frame")
            .draw()
            .map_err(|e| err(e.to_string()))?;
        let mut methods: Vec<&str> = rows.iter().map(|r| r.method.as_str()).collect();
        methods.dedup();
        for (i, m) in methods.iter().enumerate() {
            let colour = Palette99::pick(i).to_rgba();
            let points: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.method == *m)
                .map(|r| (r.views as f64, r.total_ms))
                .collect();
            chart
                .draw_series(LineSeries::new(points.clone(), colour.stroke_width(2)))
                .map_err(|e| err(e.to_string()))?
                .label(m.to_string())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], colour));
            chart
                .draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                .map_err(|e| err(e.to_string()))?;
        }
        chart
            .configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()
            .map_err(|e| err(e.to_string()))?;
        root.present().map_err(|e| err(e.to_string()))?;
    }
    crate::eval::plot::save_rgb(path, width, height, buffer).map_err(|e| err(e.to_string()))
}
