//! View rigs: how one scene camera becomes the views of a frame — one (`mono`), two eyes
//! (`stereo[:IPD]`), N cameras on a small arc (`grid:N`, for scaling tests), or the walls of a
//! CAVE seen from a tracked head (`cave:FILE.json`, an off-axis frustum per wall).
//!
//! The CAVE file (metres, world space):
//! ```json
//! { "head": [0.278, 0.274, 0.28],
//!   "walls": [ { "name": "front",
//!                "lower_left": [x, y, z], "lower_right": [x, y, z], "upper_left": [x, y, z],
//!                "pixels": [512, 512] } ] }
//! ```
//! `pixels` is optional: by default a wall is `--width` wide and as high as its aspect
//! asks. Each wall's frustum is the generalized perspective projection (Kooima 2008): the
//! screen basis `vr` (lower left → lower right), `vu` (lower left → upper left), normal
//! `vn = vr × vu` towards the head, and the frustum edges where the rays to the corners meet
//! the plane at unit distance.

use std::path::{Path, PathBuf};

use glam::{Mat4, Quat, Vec3};

use crate::raster::RenderError;
use crate::scene::CameraView;

/// Interpupillary distance of `stereo` without a value, metres.
pub const DEFAULT_IPD: f32 = 0.064;
/// Angle between neighbouring cameras of `grid:N`, radians.
pub const GRID_STEP: f32 = 2.0 * std::f32::consts::PI / 180.0;
/// Most views one frame may have (a CAVE has 4–6 walls; grids are for scaling tests).
pub const MAX_VIEWS: usize = 64;

#[derive(Clone, Debug, PartialEq)]
pub enum ViewRig {
    Mono,
    Stereo { ipd: f32 },
    Grid { count: usize },
    Cave(Cave),
}

/// A CAVE: a tracked head and planar walls.
#[derive(Clone, Debug, PartialEq)]
pub struct Cave {
    pub head: Vec3,
    pub walls: Vec<CaveWall>,
    pub source: PathBuf,
}

#[derive(Clone, Debug, PartialEq)]
pub struct CaveWall {
    pub name: String,
    pub lower_left: Vec3,
    pub lower_right: Vec3,
    pub upper_left: Vec3,
    pub pixels: Option<(u32, u32)>,
}

/// One view of a rig: its name, camera and output size.
#[derive(Clone, Debug)]
pub struct RigView {
    pub name: String,
    pub camera: CameraView,
    pub size: (u32, u32),
}

impl ViewRig {
    /// Parses `mono`, `stereo[:IPD_METRES]`, `grid:N` or `cave:FILE.json`.
    pub fn parse(text: &str) -> Result<Self, RenderError> {
        let err = |why: String| RenderError::Settings(format!("--views {text}: {why}"));
        let (kind, arg) = match text.split_once(':') {
            Some((k, a)) => (k, Some(a)),
            None => (text, None),
        };
        match (kind, arg) {
            ("mono", None) => Ok(ViewRig::Mono),
            ("stereo", None) => Ok(ViewRig::Stereo { ipd: DEFAULT_IPD }),
            ("stereo", Some(a)) => {
                let ipd: f32 = a
                    .parse()
                    .map_err(|_| err(format!("'{a}' is not a distance in metres")))?;
                if !(ipd.is_finite() && ipd > 0.0 && ipd <= 1.0) {
                    return Err(err("the IPD must be in (0, 1] metres".into()));
                }
                Ok(ViewRig::Stereo { ipd })
            }
            ("grid", Some(a)) => {
                let count: usize = a
                    .parse()
                    .map_err(|_| err(format!("'{a}' is not a whole number")))?;
                if !(1..=MAX_VIEWS).contains(&count) {
                    return Err(err(format!("N must be 1..={MAX_VIEWS}")));
                }
                Ok(ViewRig::Grid { count })
            }
            ("cave", Some(path)) => Ok(ViewRig::Cave(Cave::load(Path::new(path))?)),
            _ => Err(err(
                "expected mono, stereo[:IPD_METRES], grid:N or cave:FILE.json".into(),
            )),
        }
    }

    /// How the JSON line names the rig.
    pub fn label(&self) -> String {
        match self {
            ViewRig::Mono => "mono".into(),
            ViewRig::Stereo { ipd } => format!("stereo:{ipd}"),
            ViewRig::Grid { count } => format!("grid:{count}"),
            ViewRig::Cave(c) => format!("cave:{}", c.source.display()),
        }
    }

    /// The rig's views for a scene camera `camera` and an output of `size` per view.
    /// `pivot` is the point `grid` cameras turn about (the scene's centre).
    pub fn views(&self, camera: &CameraView, size: (u32, u32), pivot: Vec3) -> Vec<RigView> {
        let view = |name: &str, camera: CameraView| RigView {
            name: name.into(),
            camera,
            size,
        };
        match self {
            ViewRig::Mono => vec![view("main", *camera)],
            ViewRig::Stereo { ipd } => {
                // Parallel eyes, each with the scene camera's frustum: the HMD convention.
                let right = camera.world_from_view.x_axis.truncate().normalize_or_zero();
                let eye = |sign: f32| {
                    let mut c = *camera;
                    c.world_from_view =
                        Mat4::from_translation(right * (sign * ipd * 0.5)) * c.world_from_view;
                    c
                };
                vec![view("left", eye(-1.0)), view("right", eye(1.0))]
            }
            ViewRig::Grid { count } => (0..*count)
                .map(|i| {
                    let angle = (i as f32 - (*count as f32 - 1.0) * 0.5) * GRID_STEP;
                    let mut c = *camera;
                    if angle != 0.0 {
                        let up = camera.world_from_view.y_axis.truncate().normalize_or_zero();
                        let turn = Mat4::from_translation(pivot)
                            * Mat4::from_quat(Quat::from_axis_angle(up, angle))
                            * Mat4::from_translation(-pivot);
                        c.world_from_view = turn * c.world_from_view;
                    }
                    view(&format!("grid{i}"), c)
                })
                .collect(),
            ViewRig::Cave(cave) => cave
                .walls
                .iter()
                .map(|wall| RigView {
                    name: wall.name.clone(),
                    camera: wall.camera(cave.head, camera.znear, camera.zfar),
                    size: wall.pixels.unwrap_or_else(|| wall.default_pixels(size.0)),
                })
                .collect(),
        }
    }
}

impl Cave {
    pub fn load(path: &Path) -> Result<Self, RenderError> {
        let err = |why: String| RenderError::Settings(format!("{}: {why}", path.display()));
        let text = std::fs::read_to_string(path).map_err(|e| err(format!("cannot read: {e}")))?;
        let json: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| err(format!("not JSON: {e}")))?;
        let vec3 = |v: &serde_json::Value, what: &str| -> Result<Vec3, RenderError> {
            let a = v
                .as_array()
                .filter(|a| a.len() == 3)
                .ok_or_else(|| err(format!("{what}: expected [x, y, z]")))?;
            let mut out = [0.0f32; 3];
            for (o, x) in out.iter_mut().zip(a) {
                *o = x
                    .as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| err(format!("{what}: not a finite number")))?
                    as f32;
            }
            Ok(Vec3::from(out))
        };
        let head = vec3(&json["head"], "head")?;
        let walls_json = json["walls"]
            .as_array()
            .filter(|w| !w.is_empty())
            .ok_or_else(|| err("walls: expected a non-empty list".into()))?;
        if walls_json.len() > MAX_VIEWS {
            return Err(err(format!("more than {MAX_VIEWS} walls")));
        }
        let mut walls = Vec::with_capacity(walls_json.len());
        for (i, w) in walls_json.iter().enumerate() {
            let name = w["name"]
                .as_str()
                .map(str::to_string)
                .unwrap_or_else(|| format!("wall{i}"));
            let at = |key: &str| vec3(&w[key], &format!("walls[{i}].{key}"));
            let pixels = match &w["pixels"] {
                serde_json::Value::Null => None,
                p => {
                    let a = p.as_array().filter(|a| a.len() == 2).ok_or_else(|| {
                        err(format!("walls[{i}].pixels: expected [width, height]"))
                    })?;
                    let dim = |v: &serde_json::Value| {
                        v.as_u64()
                            .filter(|n| (1..=16384).contains(n))
                            .map(|n| n as u32)
                            .ok_or_else(|| {
                                err(format!("walls[{i}].pixels: sizes must be 1..=16384"))
                            })
                    };
                    Some((dim(&a[0])?, dim(&a[1])?))
                }
            };
            let wall = CaveWall {
                name,
                lower_left: at("lower_left")?,
                lower_right: at("lower_right")?,
                upper_left: at("upper_left")?,
                pixels,
            };
            let (vr, vu) = (
                wall.lower_right - wall.lower_left,
                wall.upper_left - wall.lower_left,
            );
            if vr.length() < 1e-6
                || vu.length() < 1e-6
                || vr.normalize().dot(vu.normalize()).abs() > 1e-3
            {
                return Err(err(format!(
                    "wall '{}': its corners must span a rectangle (lower_right and upper_left at right angles from lower_left)",
                    wall.name
                )));
            }
            let distance = -wall.normal().dot(wall.lower_left - head);
            if distance <= 1e-6 {
                return Err(err(format!(
                    "wall '{}': the head is not in front of it (corners must run counter-clockwise seen from the head)",
                    wall.name
                )));
            }
            walls.push(wall);
        }
        Ok(Self {
            head,
            walls,
            source: path.to_path_buf(),
        })
    }
}

impl CaveWall {
    fn basis(&self) -> (Vec3, Vec3) {
        (
            (self.lower_right - self.lower_left).normalize(),
            (self.upper_left - self.lower_left).normalize(),
        )
    }

    /// Unit normal from the wall towards the head.
    pub fn normal(&self) -> Vec3 {
        let (vr, vu) = self.basis();
        vr.cross(vu).normalize()
    }

    fn default_pixels(&self, width: u32) -> (u32, u32) {
        let w = (self.lower_right - self.lower_left).length();
        let h = (self.upper_left - self.lower_left).length();
        (width, ((width as f32 * h / w).round() as u32).max(1))
    }

    /// The off-axis camera at `head` whose image is exactly this wall.
    pub fn camera(&self, head: Vec3, znear: f32, zfar: f32) -> CameraView {
        let (vr, vu) = self.basis();
        let vn = self.normal();
        let (va, vb, vc) = (
            self.lower_left - head,
            self.lower_right - head,
            self.upper_left - head,
        );
        let distance = -vn.dot(va);
        let left = vr.dot(va) / distance;
        let right = vr.dot(vb) / distance;
        let bottom = vu.dot(va) / distance;
        let top = vu.dot(vc) / distance;
        CameraView {
            world_from_view: Mat4::from_cols(
                vr.extend(0.0),
                vu.extend(0.0),
                vn.extend(0.0),
                head.extend(1.0),
            ),
            yfov: 2.0 * (0.5 * (top - bottom)).atan(),
            aspect: (right - left) / (top - bottom),
            znear: znear.min(0.5 * distance),
            zfar: zfar.max(2.0 * distance),
            off_axis: Some([left, right, bottom, top]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall() -> CaveWall {
        CaveWall {
            name: "front".into(),
            lower_left: Vec3::new(-1.0, 0.0, -1.0),
            lower_right: Vec3::new(1.0, 0.0, -1.0),
            upper_left: Vec3::new(-1.0, 2.0, -1.0),
            pixels: None,
        }
    }

    #[test]
    fn wall_corners_map_to_the_ndc_corners_from_any_head() {
        for head in [Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.4, 0.3, 0.5)] {
            let camera = wall().camera(head, 0.05, 100.0);
            let clip_from_world = camera.clip_from_world();
            let w = wall();
            let upper_right = w.lower_right + (w.upper_left - w.lower_left);
            for (corner, ndc) in [
                (w.lower_left, [-1.0, -1.0]),
                (w.lower_right, [1.0, -1.0]),
                (w.upper_left, [-1.0, 1.0]),
                (upper_right, [1.0, 1.0]),
            ] {
                let p = clip_from_world.project_point3(corner);
                assert!(
                    (p.x - ndc[0]).abs() < 1e-5 && (p.y - ndc[1]).abs() < 1e-5,
                    "head {head}: corner {corner} → {p}, expected {ndc:?}"
                );
                assert!(p.z > 0.0 && p.z < 1.0, "depth {p}");
            }
        }
    }

    #[test]
    fn symmetric_off_axis_frustum_equals_the_perspective_one() {
        let camera = wall().camera(Vec3::new(0.0, 1.0, 0.0), 0.05, 100.0);
        let symmetric = CameraView {
            off_axis: None,
            ..camera
        };
        let (a, b) = (camera.clip_from_view(), symmetric.clip_from_view());
        assert!(a.abs_diff_eq(b, 1e-5), "{a} vs {b}");
    }

    #[test]
    fn grid_of_one_is_the_camera_and_stereo_eyes_are_ipd_apart() {
        let camera = wall().camera(Vec3::new(0.0, 1.0, 0.0), 0.05, 100.0);
        let grid = ViewRig::Grid { count: 1 }.views(&camera, (8, 8), Vec3::ZERO);
        assert_eq!(grid[0].camera.world_from_view, camera.world_from_view);
        let stereo = ViewRig::parse("stereo:0.07")
            .unwrap()
            .views(&camera, (8, 8), Vec3::ZERO);
        let d = stereo[1].camera.position() - stereo[0].camera.position();
        assert!((d.length() - 0.07).abs() < 1e-6);
        let mid = (stereo[0].camera.position() + stereo[1].camera.position()) * 0.5;
        assert!(mid.abs_diff_eq(camera.position(), 1e-6));
    }

    #[test]
    fn bad_rigs_are_rejected_with_the_reason() {
        for bad in [
            "stereo:-1",
            "stereo:x",
            "grid:0",
            "grid:1000",
            "quad",
            "cave:/nonexistent.json",
        ] {
            let e = ViewRig::parse(bad).unwrap_err().to_string();
            assert!(
                e.contains(bad.split(':').next().unwrap()) || e.contains("nonexistent"),
                "{e}"
            );
        }
    }
}
