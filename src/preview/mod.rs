//! Glossy material preview (`valgi preview`): each material on a shader ball in a small lit room
//! with coloured walls (see [`scene`]), rendered through the method registry — direct light plus
//! the method's diffuse and glossy indirect light — and laid out as one labelled grid, written
//! as a linear EXR and a tone-mapped PNG. Technique-independent: any registered method renders
//! it. The library calls are [`preview_scene`] (one material's scene, e.g. for a live viewer),
//! [`render_grid`] (all of them) and [`PreviewGrid::write`].

pub mod scene;
pub mod spec;

use std::path::{Path, PathBuf};
use std::time::Instant;

use plotters::prelude::*;

use crate::gpu::{GpuContext, GpuError};
use crate::image_io::{prepare_output, Image, ImageError};
use crate::method::{self, MethodOptions};
use crate::raster::{RenderError, RenderSettings};
use crate::scene::SceneError;

pub use scene::{ball_mesh, mirror_point, preview_scene, BallShape};
pub use spec::{default_material, load_materials, PreviewMaterial, Sweep};

#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    /// A bad `--material`, `--sweep` or other preview option.
    #[error("{0}")]
    Spec(String),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("{path}: {message}")]
    Output { path: PathBuf, message: String },
}

/// Height of the label strip under each ball, pixels.
pub const LABEL_HEIGHT: u32 = 16;
/// Dark gap between cells, pixels.
pub const GAP: u32 = 2;

/// Where the cells of a grid lie: `columns × rows` cells of a ball image with its label strip
/// underneath, `GAP` pixels apart and from the border.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridLayout {
    pub columns: u32,
    pub rows: u32,
    pub ball_width: u32,
    pub ball_height: u32,
}

impl GridLayout {
    /// `cells` balls, `columns` per row (at least 1, at most `cells`).
    pub fn new(cells: usize, columns: usize, ball_width: u32, ball_height: u32) -> Self {
        let columns = columns.clamp(1, cells.max(1)) as u32;
        Self {
            columns,
            rows: (cells as u32).div_ceil(columns).max(1),
            ball_width,
            ball_height,
        }
    }

    pub fn width(&self) -> u32 {
        self.columns * (self.ball_width + GAP) + GAP
    }

    pub fn height(&self) -> u32 {
        self.rows * (self.ball_height + LABEL_HEIGHT + GAP) + GAP
    }

    /// Top-left pixel of cell `index`'s ball image (row-major); its label strip starts
    /// `ball_height` below.
    pub fn ball_origin(&self, index: usize) -> (u32, u32) {
        let (c, r) = (index as u32 % self.columns, index as u32 / self.columns);
        (
            GAP + c * (self.ball_width + GAP),
            GAP + r * (self.ball_height + LABEL_HEIGHT + GAP),
        )
    }
}

/// One `valgi preview` run.
#[derive(Clone, Debug)]
pub struct PreviewRequest {
    /// The balls, in grid order (row-major).
    pub materials: Vec<PreviewMaterial>,
    /// Balls per row.
    pub columns: usize,
    pub ball: BallShape,
    pub method: String,
    pub options: MethodOptions,
    /// Size of one ball's image and the method's quality settings.
    pub settings: RenderSettings,
    /// Longest triangle edge of the room and ball, metres.
    pub max_edge: f32,
}

impl Default for PreviewRequest {
    fn default() -> Self {
        Self {
            materials: vec![],
            columns: 5,
            ball: BallShape::Sphere,
            method: "sparse".into(),
            options: MethodOptions::default(),
            settings: RenderSettings {
                width: 256,
                height: 256,
                ..RenderSettings::default()
            },
            max_edge: 0.05,
        }
    }
}

/// The rendered balls and how they are laid out.
#[derive(Clone, Debug)]
pub struct PreviewGrid {
    pub layout: GridLayout,
    /// Per ball, linear radiance (direct + indirect), `ball_width × ball_height`.
    pub balls: Vec<Image>,
    /// Per ball, the indirect part of `balls` alone.
    pub indirect: Vec<Image>,
    pub labels: Vec<String>,
    /// Per ball: building the method (uploads, pipelines, its preprocessing), ms.
    pub setup_ms: Vec<f64>,
    /// Per ball: the frame, ms (wall clock, readback included).
    pub frame_ms: Vec<f64>,
    /// The whole grid, wall clock, ms.
    pub total_ms: f64,
}

/// Renders every material of `request` in its own preview scene through the method registry.
///
/// What is shared between balls: the GPU context (pipelines the device caches), the ball's
/// mesh, and — for the sparse method — the per-mesh sparse points, whose process-wide cache
/// is keyed by geometry, so only the first ball computes them. The lighting solution itself
/// is not shared: the ball's material enters the reflective shadow map (its diffuse albedo
/// makes the VALs on the ball) and the glossy gather at its points, so each ball gets its own
/// frame; the cost of that is each ball's `setup_ms` and `frame_ms`.
pub fn render_grid(
    ctx: &GpuContext,
    request: &PreviewRequest,
) -> Result<PreviewGrid, PreviewError> {
    if request.materials.is_empty() {
        return Err(PreviewError::Spec(
            "nothing to preview: give --material FILE.glb[#NAME|#INDEX] and/or --sweep".into(),
        ));
    }
    let started = Instant::now();
    let settings = request.settings;
    let ball = ball_mesh(request.ball, request.max_edge)?;
    let mut grid = PreviewGrid {
        layout: GridLayout::new(
            request.materials.len(),
            request.columns,
            settings.width,
            settings.height,
        ),
        balls: vec![],
        indirect: vec![],
        labels: vec![],
        setup_ms: vec![],
        frame_ms: vec![],
        total_ms: 0.0,
    };
    let aspect = settings.width as f32 / settings.height as f32;
    for (i, material) in request.materials.iter().enumerate() {
        crate::progress::check().map_err(|e| PreviewError::Spec(e.to_string()))?;
        let scene = preview_scene(&format!("preview {i}"), material, &ball, request.max_edge);
        let world_from_node = scene.world_from_node();
        let camera = scene.camera_view(None, aspect, &world_from_node)?;
        let setup = Instant::now();
        let mut method = method::create(
            &request.method,
            ctx,
            &scene,
            settings,
            &request.options.clone(),
        )?;
        grid.setup_ms.push(setup.elapsed().as_secs_f64() * 1000.0);
        let frame = Instant::now();
        let output = method.render(ctx, &scene, &world_from_node, &camera)?;
        grid.frame_ms.push(frame.elapsed().as_secs_f64() * 1000.0);
        let mut image = output.radiance(false);
        let mut indirect = output.indirect;
        indirect.sanitize();
        let non_finite = image.sanitize();
        if non_finite > 0 {
            log::warn!(
                "preview '{}': {non_finite} pixels had non-finite radiance; written as black",
                material.label
            );
        }
        grid.balls.push(image);
        grid.indirect.push(indirect);
        grid.labels.push(material.label.clone());
    }
    grid.total_ms = started.elapsed().as_secs_f64() * 1000.0;
    Ok(grid)
}

impl PreviewGrid {
    /// The grid as one linear image: balls in their cells, dark gaps, and each label as
    /// radiance that tone-maps to white at `exposure` (so the EXR carries the labels too).
    pub fn compose(&self, exposure: f32) -> Result<Image, PreviewError> {
        let l = self.layout;
        let mut sheet = Image::new(l.width(), l.height());
        for (i, ball) in self.balls.iter().enumerate() {
            let (x0, y0) = l.ball_origin(i);
            for y in 0..ball.height.min(l.ball_height) {
                for x in 0..ball.width.min(l.ball_width) {
                    sheet.pixels[((y0 + y) * sheet.width + x0 + x) as usize] = ball.get(x, y);
                }
            }
        }
        let mask = self.label_mask()?;
        let white = 2f32.powf(-exposure);
        for (pixel, &coverage) in sheet.pixels.iter_mut().zip(&mask) {
            if coverage > 0 {
                let a = coverage as f32 / 255.0;
                for c in &mut pixel[..3] {
                    *c = *c * (1.0 - a) + white * a;
                }
                pixel[3] = 1.0;
            }
        }
        Ok(sheet)
    }

    /// Per pixel of the grid, how much label text covers it (0..=255).
    fn label_mask(&self) -> Result<Vec<u8>, PreviewError> {
        crate::eval::plot::register_font();
        let l = self.layout;
        let (w, h) = (l.width(), l.height());
        let mut buffer = vec![0u8; (w * h * 3) as usize];
        {
            let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
            let font = (crate::eval::plot::FONT, LABEL_HEIGHT as f64 - 4.0)
                .into_font()
                .color(&WHITE);
            for (i, label) in self.labels.iter().enumerate() {
                let (x0, y0) = l.ball_origin(i);
                // Clipped to its own cell, so a long name cannot run into the next one.
                let cell = root
                    .clone()
                    .shrink((x0, y0 + l.ball_height), (l.ball_width, LABEL_HEIGHT));
                cell.draw(&Text::new(label.clone(), (2, 1), font.clone()))
                    .map_err(|e| PreviewError::Output {
                        path: "label".into(),
                        message: e.to_string(),
                    })?;
            }
            root.present().map_err(|e| PreviewError::Output {
                path: "label".into(),
                message: e.to_string(),
            })?;
        }
        Ok(buffer
            .chunks_exact(3)
            .map(|p| p[0].max(p[1]).max(p[2]))
            .collect())
    }

    /// Exposure (stops) that maps the balls' log-average luminance to middle grey: one for the
    /// whole grid, so the balls can be compared.
    pub fn auto_exposure(&self) -> f32 {
        let all: Vec<[f32; 4]> = self.balls.iter().flat_map(|b| b.pixels.clone()).collect();
        crate::image_io::key_exposure(&Image::from_rgba(all.len() as u32, 1, all)).unwrap_or(0.0)
    }

    /// Writes the grid as `<stem>.exr` (linear) and `<stem>.png` (tone-mapped at `exposure`)
    /// beside `out` (whose extension, `.exr` or `.png`, is replaced). Returns the paths.
    pub fn write(&self, out: &Path, exposure: f32) -> Result<Vec<PathBuf>, PreviewError> {
        match out.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("exr") || e.eq_ignore_ascii_case("png") => {}
            _ => {
                return Err(PreviewError::Output {
                    path: out.to_path_buf(),
                    message: "--out must name a .png or .exr file (both are written)".into(),
                })
            }
        }
        let sheet = self.compose(exposure)?;
        let mut written = vec![];
        for ext in ["exr", "png"] {
            let path = out.with_extension(ext);
            prepare_output(&path)?;
            sheet.write(&path, exposure)?;
            written.push(path);
        }
        Ok(written)
    }
}

/// The materials and columns `--material` and `--sweep` select: the materials of each file
/// (or the sweep's default grey) in a row, each swept when a sweep is given (the sweep's first
/// parameter along the row, the rest down the rows).
pub fn select_materials(
    material_specs: &[String],
    sweep: Option<&str>,
) -> Result<(Vec<PreviewMaterial>, usize), PreviewError> {
    let mut bases = vec![];
    for spec in material_specs {
        bases.extend(load_materials(spec)?);
    }
    let sweep = sweep.map(Sweep::parse).transpose()?;
    match sweep {
        None if bases.is_empty() => Err(PreviewError::Spec(
            "nothing to preview: give --material FILE.glb[#NAME|#INDEX] and/or --sweep".into(),
        )),
        None => {
            let columns = bases.len().min(5);
            Ok((bases, columns))
        }
        Some(sweep) => {
            if bases.is_empty() {
                bases.push(PreviewMaterial::plain("", default_material()));
            }
            let cells: Vec<PreviewMaterial> =
                bases.iter().flat_map(|b| sweep.materials(b)).collect();
            if cells.len() > spec::MAX_CELLS {
                return Err(PreviewError::Spec(format!(
                    "{} materials × the sweep make {} balls; at most {}",
                    bases.len(),
                    cells.len(),
                    spec::MAX_CELLS
                )));
            }
            Ok((cells, sweep.columns()))
        }
    }
}

/// RSM side the preview gives methods that take `rsm` when none is asked for. The room's one
/// point light makes six RSM faces, so the methods' default of 128 gathers 98 304 VALs at
/// every point (4096 points: 4·10⁸ pairs, the whole frame's cost at 2 minutes on a shared
/// lavapipe); 32 makes 6144, ample for a 2.4 m room.
pub const PREVIEW_RSM: u32 = 32;

/// Visibility rays the preview gives methods that take `visibility-rays` when none is asked
/// for: on the preview room (`preview-r30-m100`, 128², 256-spp reference) adaptive rays
/// measured the same indirect FLIP as a ray per stratum (0.174 against 0.176) at 0.72 of the
/// frame time (951 against 1319 ms), the visibility being most of a preview frame.
pub const PREVIEW_VISIBILITY_RAYS: &str = "adaptive";

/// `options` with the preview's defaults filled in where the method takes them and they are
/// not given (see [`PREVIEW_RSM`], [`PREVIEW_VISIBILITY_RAYS`]).
pub fn preview_options(method: &str, options: &MethodOptions) -> MethodOptions {
    let mut options = options.clone();
    let defaults = [
        ("rsm", PREVIEW_RSM.to_string()),
        ("visibility-rays", PREVIEW_VISIBILITY_RAYS.to_string()),
    ];
    let entry = method::entry(method).ok();
    for (key, value) in defaults {
        let takes = entry.is_some_and(|e| e.options.iter().any(|o| o.name == key));
        if takes && !options.given(key) {
            options.set(key, value);
        }
    }
    options
}

/// The method exists and takes these options, checked before any GPU work.
pub fn check_method(name: &str, options: &MethodOptions) -> Result<(), PreviewError> {
    method::check_options(name, options)?;
    Ok(())
}

/// `valgi preview` as a library call: select, render, write; returns the JSON report.
pub fn run(
    request: &PreviewRequest,
    out: &Path,
    exposure: Option<f32>,
) -> Result<serde_json::Value, PreviewError> {
    check_method(&request.method, &request.options)?;
    let ctx = GpuContext::new()?;
    let grid = render_grid(&ctx, request)?;
    let exposure = exposure.unwrap_or_else(|| grid.auto_exposure());
    let written = grid.write(out, exposure)?;
    let round = |v: f64| (v * 1000.0).round() / 1000.0;
    Ok(serde_json::json!({
        "method": request.method,
        "options": request.options.to_string(),
        "ball": format!("{:?}", request.ball).to_lowercase(),
        "balls": grid.balls.len(),
        "columns": grid.layout.columns,
        "rows": grid.layout.rows,
        "ball_width": grid.layout.ball_width,
        "ball_height": grid.layout.ball_height,
        "labels": grid.labels,
        "exposure": round(exposure as f64),
        "setup_ms": grid.setup_ms.iter().map(|v| round(*v)).collect::<Vec<_>>(),
        "frame_ms": grid.frame_ms.iter().map(|v| round(*v)).collect::<Vec<_>>(),
        "total_ms": round(grid.total_ms),
        "adapter": ctx.adapter_label(),
        "outputs": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn preview_defaults_fill_only_options_the_method_takes_and_the_user_left_out() {
        let sparse = preview_options("sparse", &MethodOptions::default());
        let get = |o: &MethodOptions, key: &str| {
            o.entries()
                .find(|(k, _)| *k == key)
                .map(|(_, v)| v.to_string())
        };
        assert_eq!(get(&sparse, "rsm").as_deref(), Some("32"));
        assert_eq!(get(&sparse, "visibility-rays").as_deref(), Some("adaptive"));
        let mut asked = MethodOptions::default();
        asked.set("visibility-rays", "all");
        asked.set("rsm", 64);
        let kept = preview_options("sparse", &asked);
        assert_eq!(get(&kept, "visibility-rays").as_deref(), Some("all"));
        assert_eq!(get(&kept, "rsm").as_deref(), Some("64"));
        // Brute force takes an RSM side but has no visibility rays.
        let brute = preview_options("brute", &MethodOptions::default());
        assert_eq!(get(&brute, "rsm").as_deref(), Some("32"));
        assert_eq!(get(&brute, "visibility-rays"), None);
    }

    #[test]
    fn layout_cells_and_size() {
        let l = GridLayout::new(10, 5, 48, 40);
        assert_eq!((l.columns, l.rows), (5, 2));
        assert_eq!(l.width(), 5 * 50 + 2);
        assert_eq!(l.height(), 2 * (40 + LABEL_HEIGHT + 2) + 2);
        assert_eq!(l.ball_origin(0), (2, 2));
        assert_eq!(l.ball_origin(6), (2 + 50, 2 + 58));
        let l = GridLayout::new(3, 5, 8, 8);
        assert_eq!((l.columns, l.rows), (3, 1));
        let l = GridLayout::new(7, 3, 8, 8);
        assert_eq!((l.columns, l.rows), (3, 3));
    }

    #[test]
    fn compose_places_balls_and_labels() {
        let l = GridLayout::new(3, 2, 40, 30);
        let balls: Vec<Image> = (0..3)
            .map(|i| Image::from_rgba(40, 30, vec![[0.1 * (i + 1) as f32, 0.0, 0.0, 1.0]; 40 * 30]))
            .collect();
        let grid = PreviewGrid {
            layout: l,
            balls,
            indirect: vec![],
            labels: vec!["r=0".into(), "r=0.5".into(), "".into()],
            setup_ms: vec![],
            frame_ms: vec![],
            total_ms: 0.0,
        };
        let sheet = grid.compose(0.0).unwrap();
        assert_eq!((sheet.width, sheet.height), (l.width(), l.height()));
        for i in 0..3 {
            let (x, y) = l.ball_origin(i);
            assert_eq!(sheet.get(x + 20, y + 15)[0], 0.1 * (i + 1) as f32);
        }
        // Text in the first two label strips, none in the third (empty) one nor in a gap.
        let text_pixels = |i: usize| {
            let (x0, y0) = l.ball_origin(i);
            (0..LABEL_HEIGHT)
                .flat_map(|y| (0..l.ball_width).map(move |x| (x0 + x, y0 + l.ball_height + y)))
                .filter(|&(x, y)| sheet.get(x, y)[1] > 0.5)
                .count()
        };
        assert!(text_pixels(0) > 10, "{}", text_pixels(0));
        assert!(text_pixels(1) > text_pixels(0));
        assert_eq!(text_pixels(2), 0);
        assert_eq!(sheet.get(0, 0), [0.0; 4]);
    }

    #[test]
    fn write_wants_png_or_exr() {
        let grid = PreviewGrid {
            layout: GridLayout::new(1, 1, 4, 4),
            balls: vec![Image::new(4, 4)],
            indirect: vec![],
            labels: vec!["x".into()],
            setup_ms: vec![],
            frame_ms: vec![],
            total_ms: 0.0,
        };
        let e = grid.write(Path::new("out/grid.jpg"), 0.0).unwrap_err();
        assert!(e.to_string().contains("must name a .png or .exr"), "{e}");
    }

    #[test]
    fn selection_without_anything_is_an_error() {
        let e = select_materials(&[], None).unwrap_err().to_string();
        assert!(e.contains("nothing to preview"), "{e}");
        let (cells, columns) =
            select_materials(&[], Some("roughness=0..1:5,metallic=0,1")).unwrap();
        assert_eq!((cells.len(), columns), (10, 5));
    }
}
