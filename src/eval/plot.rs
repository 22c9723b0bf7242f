//! Charts and image sheets. Text uses DejaVu Sans embedded from the `dejavu` crate (registered
//! with plotters' `ab_glyph` backend), so no system font is needed.

use std::path::Path;
use std::sync::Once;

use plotters::prelude::*;
use plotters::style::FontStyle;

use super::EvalError;

pub const FONT: &str = "sans-serif";

/// Registers the embedded font once per process.
pub fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular()).is_err()
        {
            log::warn!("could not register the embedded DejaVu Sans font; charts lack text");
        }
    });
}

fn plot_error(path: &Path, e: impl std::fmt::Display) -> EvalError {
    EvalError::Output {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// One point of the speed/accuracy chart.
#[derive(Clone, Debug)]
pub struct ParetoPoint {
    /// Series (method name).
    pub series: String,
    /// Point label (settings).
    pub label: String,
    pub ms: f64,
    pub error: f64,
}

/// Time against indirect FLIP, both on log axes, one labelled series per method.
pub fn pareto_chart(path: &Path, title: &str, points: &[ParetoPoint]) -> Result<(), EvalError> {
    register_font();
    let floor_ms = 1e-3;
    let floor_err = 1e-4;
    let xs: Vec<f64> = points.iter().map(|p| p.ms.max(floor_ms)).collect();
    let ys: Vec<f64> = points.iter().map(|p| p.error.max(floor_err)).collect();
    let range = |v: &[f64], floor: f64| -> (f64, f64) {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(0.0f64, f64::max);
        if !lo.is_finite() || hi <= 0.0 {
            return (floor, floor * 10.0);
        }
        // Half a decade of margin on each side.
        (lo / 3.0, (hi * 3.0).max(lo * 10.0))
    };
    let (x0, x1) = range(&xs, floor_ms);
    let (y0, y1) = range(&ys, floor_err);
    // FLIP never exceeds 1: no empty decade above it.
    let y1 = if y1 > 1.0 && ys.iter().all(|y| *y <= 1.0) {
        1.0_f64.max(y0 * 10.0)
    } else {
        y1
    };
    let (width, height) = (900u32, 600u32);
    let mut buffer = vec![0u8; (width * height * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_error(path, e))?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, (FONT, 24))
            .margin(16)
            .x_label_area_size(50)
            .y_label_area_size(90)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| plot_error(path, e))?;
        chart
            .configure_mesh()
            .x_desc("time per frame (ms, log)")
            .y_desc("FLIP of the indirect image (log)")
            .x_label_formatter(&|v| short_number(*v))
            .y_label_formatter(&|v| short_number(*v))
            .label_style((FONT, 14))
            .axis_desc_style((FONT, 16))
            .draw()
            .map_err(|e| plot_error(path, e))?;
        let mut series_names: Vec<&str> = Vec::new();
        for p in points {
            if !series_names.contains(&p.series.as_str()) {
                series_names.push(&p.series);
            }
        }
        for (i, name) in series_names.iter().enumerate() {
            let color = Palette99::pick(i).to_rgba();
            let mut pts: Vec<(f64, f64, &str)> = points
                .iter()
                .filter(|p| p.series == *name)
                .map(|p| (p.ms.max(floor_ms), p.error.max(floor_err), p.label.as_str()))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(
                    pts.iter().map(|p| (p.0, p.1)),
                    color.stroke_width(2),
                ))
                .map_err(|e| plot_error(path, e))?
                .label(*name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3))
                });
            chart
                .draw_series(
                    pts.iter()
                        .map(|p| Circle::new((p.0, p.1), 5, color.filled())),
                )
                .map_err(|e| plot_error(path, e))?;
            chart
                .draw_series(pts.iter().filter(|p| !p.2.is_empty()).map(|p| {
                    Text::new(
                        p.2.to_string(),
                        (p.0, p.1),
                        (FONT, 12).into_font().color(&BLACK),
                    )
                }))
                .map_err(|e| plot_error(path, e))?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font((FONT, 14))
            .position(SeriesLabelPosition::UpperRight)
            .draw()
            .map_err(|e| plot_error(path, e))?;
        root.present().map_err(|e| plot_error(path, e))?;
    }
    save_rgb(path, width, height, buffer)
}

pub fn save_rgb(path: &Path, width: u32, height: u32, buffer: Vec<u8>) -> Result<(), EvalError> {
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(|e| plot_error(path, e))?;
    }
    let image = image::RgbImage::from_raw(width, height, buffer)
        .ok_or_else(|| plot_error(path, "image buffer of the wrong size"))?;
    image
        .save_with_format(path, image::ImageFormat::Png)
        .map_err(|e| plot_error(path, e))
}

/// One row of an image sheet: a label and its tiles (all the same size).
pub struct SheetRow {
    pub label: String,
    pub tiles: Vec<image::RgbImage>,
}

/// Rows of equally sized tiles under a header of column titles, each row under its label.
pub fn image_sheet(path: &Path, columns: &[&str], rows: &[SheetRow]) -> Result<(), EvalError> {
    register_font();
    let (tw, th) = rows
        .iter()
        .flat_map(|r| r.tiles.first())
        .map(|t| t.dimensions())
        .next()
        .unwrap_or((64, 64));
    let ncols = rows.iter().map(|r| r.tiles.len()).max().unwrap_or(0) as u32;
    let gap = 4u32;
    let label_h = 20u32;
    let col_w = tw.max(120);
    let width = (ncols.max(1) * (col_w + gap) + gap).max(400);
    let height = label_h + rows.len() as u32 * (th + label_h + gap) + gap;
    let mut canvas = image::RgbImage::from_pixel(width, height, image::Rgb([255, 255, 255]));
    let mut texts: Vec<(String, i32, i32)> = Vec::new();
    for (c, title) in columns.iter().enumerate() {
        texts.push((
            title.to_string(),
            (gap + c as u32 * (col_w + gap)) as i32,
            3,
        ));
    }
    for (r, row) in rows.iter().enumerate() {
        let y = label_h + r as u32 * (th + label_h + gap);
        texts.push((row.label.clone(), gap as i32, y as i32 + 3));
        for (c, tile) in row.tiles.iter().enumerate() {
            let x = gap + c as u32 * (col_w + gap);
            image::imageops::replace(&mut canvas, tile, x as i64, (y + label_h) as i64);
        }
    }
    {
        let mut buffer = canvas.as_raw().clone();
        {
            let root = BitMapBackend::with_buffer(&mut buffer, (width, height)).into_drawing_area();
            for (text, x, y) in &texts {
                root.draw(&Text::new(
                    text.clone(),
                    (*x, *y),
                    (FONT, 14).into_font().color(&BLACK),
                ))
                .map_err(|e| plot_error(path, e))?;
            }
            root.present().map_err(|e| plot_error(path, e))?;
        }
        save_rgb(path, width, height, buffer)
    }
}

/// Axis tick text: at most 3 significant digits, no float noise.
fn short_number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    if v.abs() >= 1e5 || v.abs() < 1e-3 {
        format!("{v:.1e}")
    } else {
        format!("{v:.digits$}")
    }
}
