//! Linear HDR images and their files: 32-bit float EXR (the product) and tone-mapped PNG (for
//! people).
//!
//! The PNG tone map is fixed and documented: `png = srgb_oetf(clamp(radiance · 2^exposure, 0, 1))`
//! per channel, with `exposure` in stops (0 by default) and the sRGB OETF of IEC 61966-2-1.

use std::path::{Path, PathBuf};

pub mod compare;

/// A linear RGBA float image, row-major from the top-left pixel. Alpha is 1 where a surface
/// was rendered and 0 on the background.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<[f32; 4]>,
}

#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    #[error("{path}: cannot write: {message}")]
    Write { path: PathBuf, message: String },
    #[error("{path}: cannot read: {message}")]
    Read { path: PathBuf, message: String },
    #[error("{path}: unsupported image extension (use .exr or .png)")]
    Extension { path: PathBuf },
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            pixels: vec![[0.0; 4]; (width * height) as usize],
        }
    }

    pub fn from_rgba(width: u32, height: u32, pixels: Vec<[f32; 4]>) -> Self {
        assert_eq!(pixels.len(), (width * height) as usize);
        Self {
            width,
            height,
            pixels,
        }
    }

    pub fn get(&self, x: u32, y: u32) -> [f32; 4] {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Pixel-wise sum of the colour channels; alpha is the maximum of both coverages.
    pub fn add(&self, other: &Image) -> Image {
        assert_eq!((self.width, self.height), (other.width, other.height));
        let pixels = self
            .pixels
            .iter()
            .zip(&other.pixels)
            .map(|(a, b)| [a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3].max(b[3])])
            .collect();
        Image::from_rgba(self.width, self.height, pixels)
    }

    /// Number of pixels with a NaN or infinite colour channel.
    pub fn non_finite_count(&self) -> usize {
        self.pixels
            .iter()
            .filter(|p| p[..3].iter().any(|c| !c.is_finite()))
            .count()
    }

    /// Replaces non-finite channels by 0 and returns how many pixels were touched, so no NaN
    /// ever reaches a file.
    pub fn sanitize(&mut self) -> usize {
        let mut count = 0;
        for p in &mut self.pixels {
            if p[..3].iter().any(|c| !c.is_finite()) {
                count += 1;
                for c in &mut p[..3] {
                    if !c.is_finite() {
                        *c = 0.0;
                    }
                }
            }
        }
        count
    }

    /// Mean of the RGB channels over all pixels.
    pub fn mean_rgb(&self) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for p in &self.pixels {
            for c in 0..3 {
                sum[c] += p[c] as f64;
            }
        }
        let n = self.pixels.len().max(1) as f64;
        sum.map(|s| s / n)
    }

    /// Writes by extension: `.exr` (32-bit float RGBA) or `.png` (tone-mapped, 8-bit sRGB).
    pub fn write(&self, path: &Path, exposure: f32) -> Result<(), ImageError> {
        match extension(path).as_deref() {
            Some("exr") => self.write_exr(path),
            Some("png") => self.write_png(path, exposure),
            _ => Err(ImageError::Extension {
                path: path.to_path_buf(),
            }),
        }
    }

    pub fn write_exr(&self, path: &Path) -> Result<(), ImageError> {
        self.write_exr_with(path, &[])
    }

    /// Writes a 32-bit float RGBA EXR whose header also carries the integer attributes
    /// `attributes` (name, value), read back by [`read_exr_int_attribute`].
    pub fn write_exr_with(
        &self,
        path: &Path,
        attributes: &[(&str, i32)],
    ) -> Result<(), ImageError> {
        use exr::prelude::*;
        create_parent_folders(path)?;
        let w = self.width as usize;
        let mut layer_attributes = LayerAttributes::default();
        for &(name, value) in attributes {
            let name = Text::new_or_none(name).ok_or_else(|| ImageError::Write {
                path: path.to_path_buf(),
                message: format!("EXR attribute name '{name}' is not plain text"),
            })?;
            layer_attributes
                .other
                .insert(name, AttributeValue::I32(value));
        }
        let channels = SpecificChannels::rgba(|Vec2(x, y): Vec2<usize>| {
            let p = self.pixels[y * w + x];
            (p[0], p[1], p[2], p[3])
        });
        let layer = Layer::new(
            (w, self.height as usize),
            layer_attributes,
            Encoding::default(),
            channels,
        );
        write_whole(path, |partial| {
            exr::prelude::Image::from_layer(layer)
                .write()
                .to_file(partial)
                .map_err(|e| e.to_string())
        })
    }

    pub fn read_exr(path: &Path) -> Result<Image, ImageError> {
        let read = exr::prelude::read_first_rgba_layer_from_file(
            path,
            |resolution, _| Image::new(resolution.width() as u32, resolution.height() as u32),
            |image: &mut Image, position, (r, g, b, a): (f32, f32, f32, f32)| {
                let i = position.y() * image.width as usize + position.x();
                image.pixels[i] = [r, g, b, a];
            },
        )
        .map_err(|e| ImageError::Read {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Ok(read.layer_data.channel_data.pixels)
    }

    /// The documented tone map: exposure in stops, clamp, sRGB OETF, 8 bits.
    pub fn tone_map(&self, exposure: f32) -> image::RgbImage {
        let scale = 2f32.powf(exposure);
        let mut out = image::RgbImage::new(self.width, self.height);
        for (i, px) in out.pixels_mut().enumerate() {
            let p = self.pixels[i];
            for (out, &radiance) in px.0.iter_mut().zip(&p[..3]) {
                let v = if radiance.is_finite() {
                    radiance * scale
                } else {
                    0.0
                };
                *out = (srgb_oetf(v.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8;
            }
        }
        out
    }

    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<(), ImageError> {
        create_parent_folders(path)?;
        let tone_mapped = self.tone_map(exposure);
        write_whole(path, |partial| {
            tone_mapped
                .save_with_format(partial, image::ImageFormat::Png)
                .map_err(|e| e.to_string())
        })
    }
}

/// Writes through `<path>.partial` renamed into place, so an interrupted or failed write (a
/// full disk, Ctrl-C, a crash) never leaves a truncated image under the real name.
pub(crate) fn write_whole(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), ImageError> {
    let mut partial_name = path.as_os_str().to_owned();
    partial_name.push(".partial");
    let partial = std::path::PathBuf::from(partial_name);
    let result = write(&partial).and_then(|()| {
        std::fs::rename(&partial, path).map_err(|e| format!("renaming into place: {e}"))
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&partial);
    }
    result.map_err(|message| ImageError::Write {
        path: path.to_path_buf(),
        message,
    })
}

/// The integer header attribute `name` of an EXR file ([`Image::write_exr_with`]); `Ok(None)`
/// when the file has no such attribute.
pub fn read_exr_int_attribute(path: &Path, name: &str) -> Result<Option<i32>, ImageError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| ImageError::Read {
        path: path.to_path_buf(),
        message: e.to_string(),
    })?;
    let Some(key) = exr::prelude::Text::new_or_none(name) else {
        return Ok(None);
    };
    Ok(meta
        .headers
        .first()
        .and_then(|header| match header.own_attributes.other.get(&key) {
            Some(exr::meta::attribute::AttributeValue::I32(v)) => Some(*v),
            _ => None,
        }))
}

/// Exposure (stops) that maps the log-average luminance of the lit pixels to middle grey
/// (0.18), Reinhard's key: robust to a few very bright pixels (an emitter, a highlight) that a
/// plain mean would follow. `None` when no pixel has positive finite luminance.
pub fn key_exposure(image: &Image) -> Option<f32> {
    let (mut log_sum, mut count) = (0.0f64, 0u64);
    for p in &image.pixels {
        let luminance = 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64;
        if luminance > 1e-12 && luminance.is_finite() {
            log_sum += luminance.ln();
            count += 1;
        }
    }
    (count > 0).then(|| {
        let log_average = (log_sum / count as f64).exp();
        ((0.18 / log_average).log2() as f32).clamp(-30.0, 30.0)
    })
}

/// Fraction of pixels whose every channel tone-maps to less than 2/255 at `exposure`.
pub fn dark_fraction(image: &Image, exposure: f32) -> f64 {
    let scale = 2f32.powf(exposure);
    // sRGB(x) < 2/255 ⇔ x < 2/255/12.92 (the linear segment).
    let threshold = 2.0 / 255.0 / 12.92;
    let dark = image
        .pixels
        .iter()
        // NaN counts as dark: it is written black.
        .filter(|p| p[..3].iter().all(|&c| c.is_nan() || c * scale < threshold))
        .count();
    dark as f64 / image.pixels.len().max(1) as f64
}

/// The sRGB opto-electronic transfer function (linear → encoded), input in [0, 1].
pub fn srgb_oetf(x: f32) -> f32 {
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
}

/// Checks an output path before rendering: a supported extension and a writable location.
pub fn prepare_output(path: &Path) -> Result<(), ImageError> {
    match extension(path).as_deref() {
        Some("exr") | Some("png") => ensure_writable(path),
        _ => Err(ImageError::Extension {
            path: path.to_path_buf(),
        }),
    }
}

fn create_parent_folders(path: &Path) -> Result<(), ImageError> {
    match path.parent() {
        Some(parent) if !parent.as_os_str().is_empty() => {
            std::fs::create_dir_all(parent).map_err(|e| ImageError::Write {
                path: path.to_path_buf(),
                message: format!("cannot create folder {}: {e}", parent.display()),
            })
        }
        _ => Ok(()),
    }
}

/// Creates the parent folders and checks the file can be opened for writing, so an
/// unwritable output path is reported before minutes of rendering rather than after.
fn ensure_writable(path: &Path) -> Result<(), ImageError> {
    let fail = |message: String| ImageError::Write {
        path: path.to_path_buf(),
        message,
    };
    create_parent_folders(path)?;
    if path.is_dir() {
        return Err(fail("is a folder".into()));
    }
    // Probe without leaving an empty file behind if rendering fails later.
    let existed = path.exists();
    std::fs::OpenOptions::new()
        .append(true)
        .create(true)
        .open(path)
        .map_err(|e| fail(e.to_string()))?;
    if !existed {
        let _ = std::fs::remove_file(path);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_exposure_maps_the_log_average_to_middle_grey() {
        // Uniform luminance 0.045 = 0.18 / 4: two stops up.
        let flat = Image::from_rgba(4, 4, vec![[0.045, 0.045, 0.045, 1.0]; 16]);
        assert!((key_exposure(&flat).unwrap() - 2.0).abs() < 1e-4);
        // One pixel 10⁵ times brighter moves the key by log2(10⁵)/16 ≈ 1.04 stops, where the
        // plain mean would move by log2(10⁵/16) ≈ 12.6.
        let mut hot = flat.clone();
        hot.pixels[0] = [4500.0, 4500.0, 4500.0, 1.0];
        let moved = 2.0 - key_exposure(&hot).unwrap();
        assert!((moved - (1e5f32).log2() / 16.0).abs() < 1e-3, "{moved}");
        // Black pixels are not averaged in; an all-black image has no key.
        let mut half = flat.clone();
        half.pixels[..8].fill([0.0; 4]);
        assert!((key_exposure(&half).unwrap() - 2.0).abs() < 1e-4);
        assert_eq!(key_exposure(&Image::new(2, 2)), None);
    }

    #[test]
    fn dark_fraction_counts_pixels_below_two_codes() {
        // 2/255 in sRGB is 6.07e-4 linear.
        let img = Image::from_rgba(
            4,
            1,
            vec![
                [5e-4, 5e-4, 5e-4, 1.0],
                [7e-4, 0.0, 0.0, 1.0],
                [0.0; 4],
                [f32::NAN, 0.0, 0.0, 1.0],
            ],
        );
        assert_eq!(dark_fraction(&img, 0.0), 0.75);
        assert_eq!(dark_fraction(&img, 1.0), 0.5);
    }

    #[test]
    fn tone_map_is_exposure_clamp_oetf() {
        let img = Image::from_rgba(2, 1, vec![[0.25, 0.5, 4.0, 1.0], [0.0, -1.0, 0.002, 1.0]]);
        let tm = img.tone_map(1.0);
        // 0.25·2 = 0.5 → sRGB 0.7354 → 188; 0.5·2 = 1 → 255; 8 clamps to 255.
        assert_eq!(tm.get_pixel(0, 0).0, [188, 255, 255]);
        // Negative clamps to 0; 0.004 is on the linear segment: 12.92·0.004 = 0.0517 → 13.
        assert_eq!(tm.get_pixel(1, 0).0, [0, 0, 13]);
    }

    #[test]
    fn output_paths_are_checked_without_leaving_files() {
        let dir = std::env::temp_dir().join(format!("valgi-out-{}", std::process::id()));
        let fresh = dir.join("sub/fresh.exr");
        prepare_output(&fresh).unwrap();
        assert!(
            fresh.parent().unwrap().is_dir(),
            "parent folders are created"
        );
        assert!(!fresh.exists(), "the probe leaves no empty file behind");
        let err = prepare_output(&dir.join("x.tiff")).unwrap_err().to_string();
        assert!(err.contains("x.tiff") && err.contains("extension"), "{err}");
        let err = prepare_output(Path::new("/proc/valgi-none/x.png"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("/proc/valgi-none/x.png"), "{err}");
        std::fs::create_dir_all(dir.join("a.png")).unwrap();
        let err = prepare_output(&dir.join("a.png")).unwrap_err().to_string();
        assert!(err.contains("folder"), "{err}");
    }

    #[test]
    fn sanitize_removes_non_finite() {
        let mut img = Image::from_rgba(2, 1, vec![[f32::NAN, 1.0, 0.0, 1.0], [1.0; 4]]);
        assert_eq!(img.non_finite_count(), 1);
        assert_eq!(img.sanitize(), 1);
        assert_eq!(img.get(0, 0), [0.0, 1.0, 0.0, 1.0]);
        assert_eq!(img.non_finite_count(), 0);
    }
}
