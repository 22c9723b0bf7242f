//! RGB-D frames from depth sensors: colour + 16-bit depth images in the four common layouts,
//! pinhole intrinsics from Open3D-style JSON, and camera-to-world poses from a
//! `trajectory.log` or a TUM `t tx ty tz qx qy qz qw` file.
//!
//! Depth is decoded to metres along the optical axis (the camera's +z, OpenCV convention:
//! x right, y down). Every invalid sample (0, the sensor's no-return code, a value outside
//! [`DepthRange`]) becomes exactly 0.0, a hole: no later stage turns a hole into a light.

use std::path::{Path, PathBuf};

use glam::{DMat4, DQuat, DVec3, Mat4};

use crate::raster::scene_gpu::srgb_to_linear;

#[derive(Debug, thiserror::Error)]
pub enum RgbdError {
    #[error("{path}: cannot read: {why}")]
    Read { path: PathBuf, why: String },
    #[error("{path}: {why}")]
    Format { path: PathBuf, why: String },
    #[error("colour {color} is {color_size:?} but depth {depth} is {depth_size:?}: the frames of an RGB-D pair must have the same size")]
    SizeMismatch {
        color: PathBuf,
        depth: PathBuf,
        color_size: (u32, u32),
        depth_size: (u32, u32),
    },
    #[error("{0}")]
    Settings(String),
}

/// How a sensor stores depth in its 16-bit samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthFormat {
    /// PrimeSense / Redwood / Open3D: millimetres.
    PrimeSense,
    /// TUM RGB-D benchmark: depth × 5000.
    Tum,
    /// NYU Depth v2 raw Kinect disparity, stored byte-swapped in a PGM:
    /// depth = 351.3 / (1092.5 − d) m.
    Nyu,
    /// SUN RGB-D: the millimetre value rotated left by 3 bits (rotate right by 3 to decode).
    Sun,
}

impl DepthFormat {
    pub const NAMES: &'static [&'static str] = &["primesense", "tum", "nyu", "sun"];

    pub fn parse(name: &str) -> Result<Self, RgbdError> {
        Ok(match name.to_ascii_lowercase().as_str() {
            "primesense" | "redwood" => Self::PrimeSense,
            "tum" => Self::Tum,
            "nyu" => Self::Nyu,
            "sun" => Self::Sun,
            other => {
                return Err(RgbdError::Settings(format!(
                    "--format {other}: expected one of {}",
                    Self::NAMES.join(", ")
                )))
            }
        })
    }

    /// Metres for one stored sample; 0 for the sensor's own invalid codes. `sample` is the
    /// 16-bit value as the image file holds it (PNG and PGM are both big-endian on disk and
    /// decoded to native integers by the reader).
    pub fn metres(self, sample: u16) -> f32 {
        match self {
            Self::PrimeSense => sample as f32 / 1000.0,
            Self::Tum => sample as f32 / 5000.0,
            Self::Nyu => {
                // The NYU toolbox writes the Kinect's little-endian disparity into a PGM
                // without swapping, so the PGM's big-endian reading has its bytes reversed.
                let d = sample.swap_bytes() as f32;
                // 2047 is the Kinect's "no return"; d near 1092.5 is at or behind the eye.
                if d >= 1092.0 {
                    0.0
                } else {
                    351.3 / (1092.5 - d)
                }
            }
            Self::Sun => sample.rotate_right(3) as f32 / 1000.0,
        }
    }
}

/// Depths outside `[near, far]` (metres) are holes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DepthRange {
    pub near: f32,
    pub far: f32,
}

impl Default for DepthRange {
    /// Structured-light and time-of-flight sensors of this kind return nothing useful nearer
    /// than ~0.3 m or beyond ~10 m.
    fn default() -> Self {
        Self {
            near: 0.2,
            far: 10.0,
        }
    }
}

/// Pinhole intrinsics in pixels (OpenCV convention: pixel (u, v) with integer u at the
/// centre of column u).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Intrinsics {
    /// Open3D's `PrimeSenseDefault`, also the camera of the bundled frames.
    pub fn primesense_default() -> Self {
        Self {
            width: 640,
            height: 480,
            fx: 525.0,
            fy: 525.0,
            cx: 319.5,
            cy: 239.5,
        }
    }

    /// Reads `{"width", "height", "intrinsic_matrix": [9 numbers, column-major]}`.
    pub fn read(path: &Path) -> Result<Self, RgbdError> {
        let text = std::fs::read_to_string(path).map_err(|e| RgbdError::Read {
            path: path.into(),
            why: e.to_string(),
        })?;
        let bad = |why: &str| RgbdError::Format {
            path: path.into(),
            why: why.to_string(),
        };
        let json: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| bad(&format!("not JSON: {e}")))?;
        let size = |key: &str| {
            json.get(key)
                .and_then(|v| v.as_u64())
                .filter(|v| (1..=1 << 16).contains(v))
                .map(|v| v as u32)
                .ok_or_else(|| bad(&format!("'{key}' must be a whole number 1..=65536")))
        };
        let (width, height) = (size("width")?, size("height")?);
        let m: Vec<f64> = json
            .get("intrinsic_matrix")
            .and_then(|v| v.as_array())
            .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
            .unwrap_or_default();
        if m.len() != 9 {
            return Err(bad(
                "'intrinsic_matrix' must hold 9 numbers (a column-major 3×3)",
            ));
        }
        let intrinsics = Self {
            width,
            height,
            fx: m[0] as f32,
            fy: m[4] as f32,
            cx: m[6] as f32,
            cy: m[7] as f32,
        };
        let focal_ok = intrinsics.fx > 0.0 && intrinsics.fy > 0.0;
        let centre_ok = intrinsics.cx.is_finite() && intrinsics.cy.is_finite();
        if !(focal_ok && centre_ok) {
            return Err(bad("focal lengths must be positive and the centre finite"));
        }
        Ok(intrinsics)
    }

    /// The camera-space point (OpenCV axes) seen at pixel (u, v) at depth z.
    pub fn back_project(&self, u: f32, v: f32, z: f32) -> glam::Vec3 {
        glam::Vec3::new((u - self.cx) / self.fx * z, (v - self.cy) / self.fy * z, z)
    }
}

/// One decoded RGB-D frame.
#[derive(Clone, Debug)]
pub struct RgbdFrame {
    pub width: u32,
    pub height: u32,
    /// Metres along the optical axis, row-major; 0 = hole.
    pub depth: Vec<f32>,
    /// sRGB-decoded (linear) colour in [0, 1], row-major.
    pub color: Vec<[f32; 3]>,
}

impl RgbdFrame {
    /// Reads a colour image and a 16-bit depth image of the same size.
    pub fn read(
        color_path: &Path,
        depth_path: &Path,
        format: DepthFormat,
        range: DepthRange,
    ) -> Result<Self, RgbdError> {
        let (depth_size, samples) = read_depth_samples(depth_path)?;
        let color = open_image(color_path)?.to_rgb8();
        let color_size = color.dimensions();
        if color_size != depth_size {
            return Err(RgbdError::SizeMismatch {
                color: color_path.into(),
                depth: depth_path.into(),
                color_size,
                depth_size,
            });
        }
        let depth = samples
            .iter()
            .map(|&s| {
                let z = format.metres(s);
                if z.is_finite() && z >= range.near && z <= range.far {
                    z
                } else {
                    0.0
                }
            })
            .collect();
        let color = color
            .pixels()
            .map(|p| p.0.map(|c| srgb_to_linear(c as f32 / 255.0)))
            .collect();
        Ok(Self {
            width: depth_size.0,
            height: depth_size.1,
            depth,
            color,
        })
    }

    /// The median depth of the valid samples (0 when there are none).
    pub fn median_depth(&self) -> f32 {
        let mut valid: Vec<f32> = self.depth.iter().copied().filter(|&z| z > 0.0).collect();
        if valid.is_empty() {
            return 0.0;
        }
        let mid = valid.len() / 2;
        *valid.select_nth_unstable_by(mid, f32::total_cmp).1
    }

    pub fn hole_fraction(&self) -> f32 {
        self.depth.iter().filter(|&&z| z <= 0.0).count() as f32 / self.depth.len().max(1) as f32
    }
}

fn open_image(path: &Path) -> Result<image::DynamicImage, RgbdError> {
    if !path.is_file() {
        return Err(RgbdError::Read {
            path: path.into(),
            why: "no such file".into(),
        });
    }
    image::ImageReader::open(path)
        .and_then(|r| r.with_guessed_format())
        .map_err(|e| RgbdError::Read {
            path: path.into(),
            why: e.to_string(),
        })?
        .decode()
        .map_err(|e| RgbdError::Format {
            path: path.into(),
            why: format!("cannot decode: {e}"),
        })
}

/// The raw 16-bit samples of a single-channel depth image.
fn read_depth_samples(path: &Path) -> Result<((u32, u32), Vec<u16>), RgbdError> {
    let image = open_image(path)?;
    match image {
        image::DynamicImage::ImageLuma16(gray) => Ok((gray.dimensions(), gray.into_raw())),
        other => Err(RgbdError::Format {
            path: path.into(),
            why: format!(
                "depth must be a 16-bit single-channel image, this one is {:?}{}",
                other.color(),
                if other.color().bytes_per_pixel() == 1 {
                    " (an 8-bit depth image has lost the sensor's precision; export 16-bit depth)"
                } else {
                    ""
                }
            ),
        }),
    }
}

/// Camera-to-world poses, one per frame, in the camera's OpenCV axes.
pub fn read_poses(path: &Path) -> Result<Vec<Mat4>, RgbdError> {
    let text = std::fs::read_to_string(path).map_err(|e| RgbdError::Read {
        path: path.into(),
        why: e.to_string(),
    })?;
    let bad = |line: usize, why: &str| RgbdError::Format {
        path: path.into(),
        why: format!("line {line}: {why}"),
    };
    let lines: Vec<(usize, Vec<f64>)> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map(|(i, l)| {
            l.split_whitespace()
                .map(|t| t.parse::<f64>())
                .collect::<Result<Vec<_>, _>>()
                .map(|v| (i + 1, v))
                .map_err(|_| bad(i + 1, "not a list of numbers"))
        })
        .collect::<Result<_, _>>()?;
    let Some((_, first)) = lines.first() else {
        return Err(bad(0, "no poses"));
    };
    let mut poses = Vec::new();
    if first.len() == 8 {
        // TUM: t tx ty tz qx qy qz qw.
        for (line, v) in &lines {
            if v.len() != 8 {
                return Err(bad(
                    *line,
                    "a TUM pose line has 8 numbers: t tx ty tz qx qy qz qw",
                ));
            }
            let q = DQuat::from_xyzw(v[4], v[5], v[6], v[7]);
            if q.length().is_nan() || q.length() <= 1e-6 {
                return Err(bad(*line, "the rotation quaternion is zero"));
            }
            let pose =
                DMat4::from_rotation_translation(q.normalize(), DVec3::new(v[1], v[2], v[3]));
            poses.push(pose.as_mat4());
        }
    } else {
        // trajectory.log: a 3-number header, then the 4×4 matrix row by row.
        if !lines.len().is_multiple_of(5) {
            return Err(bad(
                lines.last().map_or(0, |l| l.0),
                "a trajectory.log holds blocks of 5 lines (a header, then 4 matrix rows)",
            ));
        }
        for block in lines.chunks(5) {
            let mut rows = [[0.0f64; 4]; 4];
            for (r, (line, v)) in block[1..].iter().enumerate() {
                if v.len() != 4 {
                    return Err(bad(*line, "a matrix row has 4 numbers"));
                }
                rows[r].copy_from_slice(v);
            }
            let pose = DMat4::from_cols_array_2d(&rows).transpose();
            if !pose.is_finite() || pose.determinant().abs() < 1e-9 {
                return Err(bad(block[1].0, "the pose matrix is singular or not finite"));
            }
            poses.push(pose.as_mat4());
        }
    }
    Ok(poses)
}

/// The colour and depth files of frame `index` in an Open3D-style folder (`color/`,
/// `depth/`), sorted by name.
pub fn frame_files(dir: &Path, index: usize) -> Result<(PathBuf, PathBuf), RgbdError> {
    let list = |sub: &str| -> Result<Vec<PathBuf>, RgbdError> {
        let folder = dir.join(sub);
        let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
            .map_err(|e| RgbdError::Read {
                path: folder.clone(),
                why: e.to_string(),
            })?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.is_file())
            .collect();
        files.sort();
        Ok(files)
    };
    let (colors, depths) = (list("color")?, list("depth")?);
    if colors.len() != depths.len() {
        return Err(RgbdError::Format {
            path: dir.into(),
            why: format!(
                "{} colour frames but {} depth frames",
                colors.len(),
                depths.len()
            ),
        });
    }
    match (colors.get(index), depths.get(index)) {
        (Some(c), Some(d)) => Ok((c.clone(), d.clone())),
        _ => Err(RgbdError::Format {
            path: dir.into(),
            why: format!("frame {index} requested; the folder has {}", colors.len()),
        }),
    }
}
