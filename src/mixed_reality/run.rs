//! `valgi mr`: the files, the object, the frames → composites on disk and a JSON report.

use std::path::{Path, PathBuf};

use glam::Mat4;

use super::rgbd::{self, DepthFormat, DepthRange, Intrinsics, RgbdError, RgbdFrame};
use super::session::{self, MixedReality, MrFrame, MrSettings, Placement};
use crate::gpu::{GpuContext, GpuError};
use crate::image_io::{Image, ImageError};
use crate::raster::RenderError;
use crate::scene::{LoadParams, SceneError};

#[derive(Debug, thiserror::Error)]
pub enum MrError {
    #[error(transparent)]
    Rgbd(#[from] RgbdError),
    #[error(transparent)]
    Render(#[from] RenderError),
    #[error(transparent)]
    Gpu(#[from] GpuError),
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Image(#[from] ImageError),
    #[error("{0}")]
    Settings(String),
}

/// Where the frames come from.
#[derive(Clone, Debug)]
pub enum FrameSource {
    /// An Open3D-style folder: `color/`, `depth/` (and usually `trajectory.log`).
    Folder(PathBuf),
    /// One colour + depth pair.
    Pair { color: PathBuf, depth: PathBuf },
}

#[derive(Clone, Debug)]
pub struct MrRequest {
    pub source: FrameSource,
    pub format: DepthFormat,
    pub intrinsics: Option<PathBuf>,
    pub trajectory: Option<PathBuf>,
    /// Half-open frame range.
    pub frames: std::ops::Range<usize>,
    /// `bunny` or a scene file (glTF, PLY, OBJ).
    pub object: String,
    /// Where the object's bottom centre stands; `None`: on the horizontal surface near the
    /// image centre.
    pub place: Option<glam::Vec3>,
    /// Degrees about world +y.
    pub yaw: f32,
    pub scale: f32,
    pub lights: Vec<(glam::Vec3, glam::Vec3)>,
    pub settings: MrSettings,
    pub out: PathBuf,
}

/// Parses `K` or `A..B` (half-open).
pub fn parse_frames(text: &str) -> Result<std::ops::Range<usize>, MrError> {
    let bad = || MrError::Settings(format!("--frames {text}: expected K or A..B with A < B"));
    match text.split_once("..") {
        Some((a, b)) => {
            let (a, b): (usize, usize) = (
                a.trim().parse().map_err(|_| bad())?,
                b.trim().parse().map_err(|_| bad())?,
            );
            if a >= b {
                return Err(bad());
            }
            Ok(a..b)
        }
        None => {
            let k: usize = text.trim().parse().map_err(|_| bad())?;
            Ok(k..k + 1)
        }
    }
}

/// The bundled Stanford bunny, looked for beside the repository.
fn resolve_object(spec: &str) -> Result<String, MrError> {
    if spec != "bunny" {
        return Ok(spec.to_string());
    }
    let candidates = [
        "../shared/data/bunny/bun_zipper_res2.ply",
        "shared/data/bunny/bun_zipper_res2.ply",
    ];
    candidates
        .iter()
        .find(|p| Path::new(p).is_file())
        .map(|p| p.to_string())
        .ok_or_else(|| {
            MrError::Settings(format!(
                "--object bunny: the bunny PLY is not at {}; pass --object FILE",
                candidates.join(" or ")
            ))
        })
}

impl MrRequest {
    fn frame_files(&self, index: usize) -> Result<(PathBuf, PathBuf), MrError> {
        Ok(match &self.source {
            FrameSource::Folder(dir) => rgbd::frame_files(dir, index)?,
            FrameSource::Pair { color, depth } => {
                if index != 0 {
                    return Err(MrError::Settings(
                        "--color/--depth is one frame: use --frame 0".into(),
                    ));
                }
                (color.clone(), depth.clone())
            }
        })
    }

    fn poses(&self) -> Result<Option<Vec<Mat4>>, MrError> {
        let path = self.trajectory.clone().or_else(|| match &self.source {
            FrameSource::Folder(dir) => session::default_trajectory(dir),
            FrameSource::Pair { .. } => None,
        });
        Ok(match path {
            Some(p) => Some(rgbd::read_poses(&p)?),
            None => None,
        })
    }
}

fn pose_of(poses: &Option<Vec<Mat4>>, index: usize) -> Result<Mat4, MrError> {
    match poses {
        None => Ok(Mat4::IDENTITY),
        Some(list) => list.get(index).copied().ok_or_else(|| {
            MrError::Settings(format!(
                "frame {index} has no pose: the trajectory holds {}",
                list.len()
            ))
        }),
    }
}

/// Writes `composite`, `object` (RGBA, alpha = coverage) and `indirect` images of frame
/// `index` (EXR in radiance, PNG at the exposure that gives back the photo).
fn write_frame(out: &Path, index: usize, frame: &MrFrame, exposure: f32) -> Result<(), MrError> {
    let name = |what: &str, ext: &str| out.join(format!("{what}_{index:05}.{ext}"));
    frame.composite.write_exr(&name("composite", "exr"))?;
    frame
        .composite
        .write_png(&name("composite", "png"), exposure)?;
    frame.indirect.write_exr(&name("indirect", "exr"))?;
    frame
        .indirect
        .write_png(&name("indirect", "png"), exposure)?;
    frame.object.write_exr(&name("object", "exr"))?;
    let rgb = frame.object.tone_map(exposure);
    let rgba = image::RgbaImage::from_fn(rgb.width(), rgb.height(), |x, y| {
        let p = rgb.get_pixel(x, y).0;
        let a = frame.alpha[(y * rgb.width() + x) as usize];
        image::Rgba([p[0], p[1], p[2], (a.clamp(0.0, 1.0) * 255.0).round() as u8])
    });
    let path = name("object", "png");
    rgba.save(&path).map_err(|e| ImageError::Write {
        path: path.clone(),
        message: e.to_string(),
    })?;
    Ok(())
}

/// Runs the request; returns the JSON report (one entry per frame, the flicker metric).
pub fn run(request: &MrRequest) -> Result<serde_json::Value, MrError> {
    let intrinsics = match &request.intrinsics {
        Some(p) => Intrinsics::read(p)?,
        None => Intrinsics::primesense_default(),
    };
    let poses = request.poses()?;
    // Every frame of the range must exist (and have a pose) before any is rendered.
    let last = request.frames.end.saturating_sub(1);
    request.frame_files(last)?;
    pose_of(&poses, last)?;
    let read_frame = |index: usize| -> Result<(RgbdFrame, Mat4), MrError> {
        let (color, depth) = request.frame_files(index)?;
        let frame = RgbdFrame::read(&color, &depth, request.format, DepthRange::default())?;
        Ok((frame, pose_of(&poses, index)?))
    };
    let (first, first_pose) = read_frame(request.frames.start)?;
    let base = match request.place {
        Some(p) => p,
        None => session::find_floor_point(&first, &intrinsics, first_pose).ok_or_else(|| {
            MrError::Settings(
                "--place auto found no horizontal surface near the image centre; pass --place x,y,z"
                    .into(),
            )
        })?,
    };
    if !(request.scale > 0.0 && request.scale.is_finite() && request.yaw.is_finite()) {
        return Err(MrError::Settings(
            "--scale must be positive and --yaw finite".into(),
        ));
    }
    let placement = Placement {
        base,
        yaw: request.yaw.to_radians(),
        scale: request.scale,
    };
    let object = crate::scene::load_with(
        &resolve_object(&request.object)?,
        &LoadParams {
            max_edge: 0.05,
            emitter_lights: crate::scene::emitters::DEFAULT_EMITTER_LIGHTS,
            allow_external_paths: true,
        },
    )?;
    let scene = session::place_object(object, placement, &request.lights)?;
    let ctx = GpuContext::new()?;
    let mut mr = MixedReality::new(&ctx, scene, intrinsics, request.settings)?;
    // Stops that map the photo's radiance k·c back to c: the PNGs show the photo unchanged.
    let exposure = -request.settings.depth.real_scale.max(1e-12).log2();
    let mut reports = Vec::new();
    let mut layers = Vec::new();
    for index in request.frames.clone() {
        let (frame, pose) = if index == request.frames.start {
            (first.clone(), first_pose)
        } else {
            read_frame(index)?
        };
        let out = mr.render(&ctx, &frame, pose)?;
        write_frame(&request.out, index, &out, exposure)?;
        reports.push(serde_json::json!({
            "frame": index,
            "real_and_rsm_vals": out.real_vals,
            "passes_ms": out.timings.to_json(),
            "composite_ms": crate::gpu::timing::round3(out.composite_ms),
            "object_pixels": out.alpha.iter().filter(|a| **a > 0.5).count(),
        }));
        let points = mr.point_irradiance(&ctx)?;
        layers.push(Image::from_rgba(
            points.len() as u32,
            1,
            points.iter().map(|e| e.extend(1.0).to_array()).collect(),
        ));
    }
    Ok(serde_json::json!({
        "place": [placement.base.x, placement.base.y, placement.base.z],
        "frames": reports,
        // The project's flicker metric over the irradiance at the object's sparse points.
        "point_flicker": crate::eval::metrics::flicker(&layers),
        "report": mr.method_report(),
    }))
}
