//! The viewer's state that needs no window: how the camera is controlled (the scene's, flown
//! or orbited), the field of view, the animation clock, the frame-time history, screenshot
//! numbering and the method rebuild in flight. The window code turns events into these
//! transitions, so each is unit-tested without a display.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::{EulerRot, Mat4, Quat, Vec3};

use crate::method::MethodOptions;
use crate::scene::CameraView;

/// Frames the on-screen history plot keeps.
pub const HISTORY_FRAMES: usize = 120;
/// Distance factor of one wheel line towards the orbit target.
const ZOOM_PER_LINE: f32 = 0.9;
/// Speed factor of one wheel line while flying.
const SPEED_PER_LINE: f32 = 1.25;
/// Turn per dragged pixel, radians.
pub const RADIANS_PER_PIXEL: f32 = 0.005;
/// The field-of-view slider's range, degrees.
pub const FOV_RANGE_DEGREES: std::ops::RangeInclusive<f32> = 5.0..=150.0;

/// A camera flown by WASD and mouse drags: a position, a heading about world +y and a pitch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlyCamera {
    pub position: Vec3,
    pub yaw: f32,
    pub pitch: f32,
}

/// Heading about world +y and pitch of a world-space view direction.
fn yaw_pitch(forward: Vec3) -> (f32, f32) {
    let forward = forward.normalize_or(Vec3::NEG_Z);
    (
        (-forward.x).atan2(-forward.z),
        forward.y.clamp(-1.0, 1.0).asin(),
    )
}

fn rotation(yaw: f32, pitch: f32) -> Quat {
    Quat::from_euler(EulerRot::YXZ, yaw, pitch, 0.0)
}

fn clamp_pitch(pitch: f32) -> f32 {
    let limit = std::f32::consts::FRAC_PI_2 - 1e-3;
    pitch.clamp(-limit, limit)
}

/// World-space view direction (−z of the view) of `world_from_view`.
fn forward_of(world_from_view: &Mat4) -> Vec3 {
    -world_from_view.z_axis.truncate()
}

impl FlyCamera {
    /// The heading and pitch of `world_from_view`'s view direction (its roll is dropped).
    pub fn from_matrix(world_from_view: &Mat4) -> Self {
        let (yaw, pitch) = yaw_pitch(forward_of(world_from_view));
        Self {
            position: world_from_view.w_axis.truncate(),
            yaw,
            pitch,
        }
    }

    pub fn from_view(camera: &CameraView) -> Self {
        Self::from_matrix(&camera.world_from_view)
    }

    pub fn world_from_view(&self) -> Mat4 {
        Mat4::from_rotation_translation(rotation(self.yaw, self.pitch), self.position)
    }

    /// Moves by `local` (view-space x right, y up, z backwards) metres.
    pub fn translate_local(&mut self, local: Vec3) {
        self.position += rotation(self.yaw, self.pitch) * local;
    }

    /// Turns by a drag of `dx`, `dy` radians (right and down positive).
    pub fn turn(&mut self, dx: f32, dy: f32) {
        self.yaw -= dx;
        self.pitch = clamp_pitch(self.pitch - dy);
    }
}

/// A camera on a sphere about a world-space target, looking at it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbitCamera {
    pub target: Vec3,
    /// Metres from the target to the eye.
    pub distance: f32,
    pub yaw: f32,
    pub pitch: f32,
}

impl OrbitCamera {
    /// Orbits about the point of `world_from_view`'s view ray at the depth of `pivot` (the
    /// scene's centre), so the image does not jump when orbiting starts.
    pub fn around(world_from_view: &Mat4, pivot: Vec3) -> Self {
        let eye = world_from_view.w_axis.truncate();
        let forward = forward_of(world_from_view).normalize_or(Vec3::NEG_Z);
        let depth = (pivot - eye).dot(forward);
        // A pivot behind or at the eye gives no usable depth: orbit one metre ahead.
        let distance = if depth > 1e-3 { depth } else { 1.0 };
        let (yaw, pitch) = yaw_pitch(forward);
        Self {
            target: eye + forward * distance,
            distance,
            yaw,
            pitch,
        }
    }

    pub fn world_from_view(&self) -> Mat4 {
        let rotation = rotation(self.yaw, self.pitch);
        // The view looks down its −z, so the eye sits at +z (view space) from the target.
        let eye = self.target + rotation * Vec3::new(0.0, 0.0, self.distance);
        Mat4::from_rotation_translation(rotation, eye)
    }

    /// Drags of `dx`, `dy` radians swing the eye about the target (right drag: the scene
    /// turns right, as if grabbed).
    pub fn turn(&mut self, dx: f32, dy: f32) {
        self.yaw -= dx;
        self.pitch = clamp_pitch(self.pitch - dy);
    }

    /// `lines` wheel lines towards the target (negative: away).
    pub fn zoom(&mut self, lines: f32) {
        self.distance = (self.distance * ZOOM_PER_LINE.powf(lines)).clamp(1e-3, 1e6);
    }

    /// Moves the target by `local` (view-space axes) metres.
    pub fn pan_local(&mut self, local: Vec3) {
        self.target += rotation(self.yaw, self.pitch) * local;
    }
}

/// Who places the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CameraControl {
    /// The scene's (possibly animated) camera as is, so a frame matches `render`.
    Scene,
    Fly(FlyCamera),
    Orbit(OrbitCamera),
}

/// What a drag (and the wheel) does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DragMode {
    Fly,
    Orbit,
}

/// Which radiance the window shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Components {
    Direct,
    Indirect,
    Both,
}

impl Components {
    pub fn bits(self) -> u32 {
        match self {
            Components::Direct => 1,
            Components::Indirect => 2,
            Components::Both => 3,
        }
    }
}

/// How a two-eye rig is shown.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StereoDisplay {
    /// Each view in its own region, left to right.
    SideBySide,
    /// Red from the first view, green and blue from the second, in the first region.
    Anaglyph,
}

/// A method rebuild handed to a worker thread.
#[derive(Clone, Debug)]
pub struct PendingRebuild {
    pub generation: u64,
    pub method: &'static str,
    pub options: MethodOptions,
    pub started: Instant,
    /// UI frames drawn while it ran, and the longest interval between two of them, ms.
    pub frames: u32,
    pub longest_frame_ms: f64,
}

/// A finished rebuild, for the panel and the JSON report.
#[derive(Clone, Debug, PartialEq)]
pub struct RebuildRecord {
    pub method: &'static str,
    pub ms: f64,
    pub frames: u32,
    pub longest_frame_ms: f64,
    pub ok: bool,
}

/// The rebuild in flight: the newest request wins, older workers' results are dropped.
#[derive(Debug, Default)]
pub struct Rebuilds {
    generation: u64,
    pending: Option<PendingRebuild>,
    pub last: Option<RebuildRecord>,
}

impl Rebuilds {
    /// Starts a rebuild; returns the generation its worker reports back with.
    pub fn request(&mut self, method: &'static str, options: MethodOptions) -> u64 {
        self.generation += 1;
        self.pending = Some(PendingRebuild {
            generation: self.generation,
            method,
            options,
            started: Instant::now(),
            frames: 0,
            longest_frame_ms: 0.0,
        });
        self.generation
    }

    pub fn pending(&self) -> Option<&PendingRebuild> {
        self.pending.as_ref()
    }

    /// A UI frame starting at `start`, the previous one having started at `previous`, while
    /// the rebuild runs. The interval counts from the request at the latest: the frame that
    /// asked for the rebuild is not charged to it.
    pub fn note_frame(&mut self, previous: Instant, start: Instant) {
        if let Some(p) = &mut self.pending {
            let from = previous.max(p.started);
            let interval_ms = start.saturating_duration_since(from).as_secs_f64() * 1000.0;
            p.frames += 1;
            p.longest_frame_ms = p.longest_frame_ms.max(interval_ms);
        }
    }

    /// The worker of `generation` is done (`ok`: it built a method). `Some` when that is
    /// the rebuild still wanted (its result is to be installed), `None` when a newer request
    /// superseded it.
    pub fn finish(&mut self, generation: u64, ok: bool) -> Option<PendingRebuild> {
        if self.pending.as_ref()?.generation != generation {
            return None;
        }
        let done = self.pending.take()?;
        self.last = Some(RebuildRecord {
            method: done.method,
            ms: done.started.elapsed().as_secs_f64() * 1000.0,
            frames: done.frames,
            longest_frame_ms: done.longest_frame_ms,
            ok,
        });
        Some(done)
    }
}

/// Which debug views are on (the panel's checkboxes, `--debug`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DebugViews {
    /// Sparse points, coloured by the first-bounce radiance of their diffuse light.
    pub points: bool,
    /// VALs, coloured by their disc radiance Φ/(π·A).
    pub vals: bool,
    /// The links of the vertex under the cursor to the points it interpolates.
    pub links: bool,
    /// The light spheres of the point under the cursor and the occluder discs that cover them.
    pub occluders: bool,
    /// The difference to the path-traced reference `valgi eval` cached for this view.
    pub reference: bool,
    /// The light atlas's charts, texels, coverage holes and seams in place of its light.
    pub atlas: bool,
}

/// The debug views' names, as `--debug` takes them.
pub const DEBUG_VIEW_NAMES: &str = "points, vals, links, occluders, reference, atlas";

impl DebugViews {
    /// Turns on the view `name` (one of [`DEBUG_VIEW_NAMES`]), as `--debug` names it.
    pub fn enable(&mut self, name: &str) -> Result<(), String> {
        match name {
            "points" => self.points = true,
            "vals" => self.vals = true,
            "links" => self.links = true,
            "occluders" => self.occluders = true,
            "reference" => self.reference = true,
            "atlas" => self.atlas = true,
            other => {
                return Err(format!(
                    "--debug {other}: unknown debug view (expected one of {DEBUG_VIEW_NAMES})"
                ))
            }
        }
        Ok(())
    }

    /// Whether a view drawn over the image is on (the reference difference and the atlas view
    /// replace the image instead).
    pub fn any_overlay(self) -> bool {
        self.points || self.vals || self.links || self.occluders
    }

    /// Whether a view needs what lies under the cursor.
    pub fn needs_pick(self) -> bool {
        self.links || self.occluders
    }
}

/// Everything the panel and the input change that needs no GPU object.
#[derive(Debug)]
pub struct ViewerState {
    pub control: CameraControl,
    pub drag_mode: DragMode,
    /// The scene camera used (and returned to): `None` is the first, else a name or index.
    pub scene_camera: Option<String>,
    /// Vertical field of view, degrees; `None` keeps the scene camera's.
    pub yfov_degrees: Option<f32>,
    /// Metres per second of WASD.
    pub speed: f32,
    pub exposure: f32,
    pub components: Components,
    pub stereo_display: StereoDisplay,
    pub playing: bool,
    /// Animation time, seconds.
    pub time: f32,
    /// Length of the scene's animation (0: none).
    pub duration: f32,
    /// Interval between the last frames' starts, ms, oldest first.
    pub frame_ms_history: VecDeque<f32>,
    screenshots: u32,
    pub rebuilds: Rebuilds,
    /// The debug views on.
    pub debug: DebugViews,
    /// `--preview`: the material knobs as the panel shows them (applied when a knob is let go).
    pub material: Option<crate::scene::Material>,
}

impl ViewerState {
    pub fn new(scene_camera: Option<String>, time: f32, exposure: f32, duration: f32) -> Self {
        Self {
            control: CameraControl::Scene,
            drag_mode: DragMode::Fly,
            scene_camera,
            yfov_degrees: None,
            speed: 1.0,
            exposure,
            components: Components::Both,
            stereo_display: StereoDisplay::SideBySide,
            playing: duration > 0.0,
            time,
            duration,
            frame_ms_history: VecDeque::with_capacity(HISTORY_FRAMES),
            screenshots: 0,
            rebuilds: Rebuilds::default(),
            debug: DebugViews::default(),
            material: None,
        }
    }

    /// The camera placement that replaces the scene's, if any.
    pub fn world_from_view(&self) -> Option<Mat4> {
        match &self.control {
            CameraControl::Scene => None,
            CameraControl::Fly(f) => Some(f.world_from_view()),
            CameraControl::Orbit(o) => Some(o.world_from_view()),
        }
    }

    /// Takes the camera over in the drag mode, starting from `current` (the placement on
    /// screen) when the scene's camera was in use or the mode changed.
    fn take_over(&mut self, current: &Mat4, pivot: Vec3) {
        self.control = match (self.drag_mode, self.control) {
            (DragMode::Fly, CameraControl::Fly(f)) => CameraControl::Fly(f),
            (DragMode::Orbit, CameraControl::Orbit(o)) => CameraControl::Orbit(o),
            (DragMode::Fly, _) => CameraControl::Fly(FlyCamera::from_matrix(current)),
            (DragMode::Orbit, _) => CameraControl::Orbit(OrbitCamera::around(current, pivot)),
        };
    }

    /// Switches what drags do; the camera stays where it is.
    pub fn set_drag_mode(&mut self, mode: DragMode, current: &Mat4, pivot: Vec3) {
        if mode == self.drag_mode {
            return;
        }
        self.drag_mode = mode;
        if self.control != CameraControl::Scene {
            self.take_over(current, pivot);
        }
    }

    /// A drag of `dx`, `dy` pixels (right and down positive).
    pub fn drag(&mut self, current: &Mat4, pivot: Vec3, dx: f32, dy: f32) {
        self.take_over(current, pivot);
        let (dx, dy) = (dx * RADIANS_PER_PIXEL, dy * RADIANS_PER_PIXEL);
        match &mut self.control {
            CameraControl::Fly(f) => f.turn(dx, dy),
            CameraControl::Orbit(o) => o.turn(dx, dy),
            CameraControl::Scene => {}
        }
    }

    /// `lines` wheel lines up: orbiting, towards the target; flying, faster.
    pub fn wheel(&mut self, current: &Mat4, pivot: Vec3, lines: f32) {
        match self.drag_mode {
            DragMode::Orbit => {
                self.take_over(current, pivot);
                if let CameraControl::Orbit(o) = &mut self.control {
                    o.zoom(lines);
                }
            }
            DragMode::Fly => {
                self.speed = (self.speed * SPEED_PER_LINE.powf(lines)).clamp(0.01, 100.0);
            }
        }
    }

    /// WASD/QE held for `dt` seconds: `direction` in view space (unit or zero).
    pub fn walk(&mut self, current: &Mat4, pivot: Vec3, direction: Vec3, dt: f32) {
        if direction == Vec3::ZERO {
            return;
        }
        self.take_over(current, pivot);
        let step = direction.normalize() * self.speed * dt;
        match &mut self.control {
            CameraControl::Fly(f) => f.translate_local(step),
            CameraControl::Orbit(o) => o.pan_local(step),
            CameraControl::Scene => {}
        }
    }

    /// Back to scene camera `selector` (`None`: the first), as the scene animates it.
    pub fn reset_to(&mut self, selector: Option<String>) {
        self.control = CameraControl::Scene;
        self.scene_camera = selector;
        self.yfov_degrees = None;
    }

    /// `camera` with the field-of-view override applied (off-axis walls keep theirs).
    pub fn apply_fov(&self, camera: &mut CameraView) {
        if let Some(degrees) = self.yfov_degrees {
            camera.yfov = degrees
                .clamp(*FOV_RANGE_DEGREES.start(), *FOV_RANGE_DEGREES.end())
                .to_radians();
        }
    }

    /// The animation clock after `dt` seconds of a frame: it runs while playing; an
    /// interactive run wraps at the animation's end, a scripted one (like `render --frames`)
    /// does not.
    pub fn advance(&mut self, dt: f32, wrap: bool) {
        if !self.playing {
            return;
        }
        self.time += dt;
        if wrap && self.duration > 0.0 {
            self.time = self.time.rem_euclid(self.duration);
        }
    }

    /// The scrub slider put the clock at `time`.
    pub fn scrub(&mut self, time: f32) {
        self.time = if time.is_finite() {
            time.clamp(0.0, self.duration.max(0.0))
        } else {
            0.0
        };
    }

    pub fn push_frame_ms(&mut self, ms: f32) {
        if self.frame_ms_history.len() == HISTORY_FRAMES {
            self.frame_ms_history.pop_front();
        }
        self.frame_ms_history.push_back(ms);
    }

    /// The next free `valgi_view_NNNN.png` in `dir` (the screenshot key's file).
    pub fn next_screenshot_path(&mut self, dir: &Path) -> PathBuf {
        loop {
            self.screenshots += 1;
            let path = dir.join(format!("valgi_view_{:04}.png", self.screenshots));
            if !path.exists() {
                return path;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn look_at(eye: Vec3, target: Vec3) -> Mat4 {
        glam::camera::rh::view::look_at_mat4(eye, target, Vec3::Y).inverse()
    }

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-4
    }

    #[test]
    fn fly_camera_round_trips_a_view_direction() {
        let m = look_at(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.0, 0.5, 0.0));
        let rebuilt = FlyCamera::from_matrix(&m).world_from_view();
        assert!(close(forward_of(&rebuilt), forward_of(&m)));
        assert!(close(rebuilt.w_axis.truncate(), Vec3::new(1.0, 2.0, 3.0)));
        // Without roll the rebuilt right vector stays horizontal.
        assert!(rebuilt.x_axis.y.abs() < 1e-6);
    }

    #[test]
    fn fly_camera_moves_along_its_view() {
        let mut fly = FlyCamera {
            position: Vec3::ZERO,
            yaw: std::f32::consts::FRAC_PI_2,
            pitch: 0.0,
        };
        // Heading +90° about +y looks down −x.
        fly.translate_local(Vec3::NEG_Z);
        assert!(close(fly.position, Vec3::NEG_X), "{:?}", fly.position);
    }

    #[test]
    fn orbit_starts_where_the_camera_is_and_keeps_looking_at_its_target() {
        let eye = Vec3::new(0.0, 1.0, 4.0);
        let m = look_at(eye, Vec3::new(0.0, 1.0, 0.0));
        // The scene's centre off the view ray: the target is on the ray at its depth.
        let mut orbit = OrbitCamera::around(&m, Vec3::new(0.5, 0.0, 1.0));
        assert!(close(orbit.target, Vec3::new(0.0, 1.0, 1.0)), "{orbit:?}");
        assert!((orbit.distance - 3.0).abs() < 1e-5);
        let start = orbit.world_from_view();
        assert!(close(start.w_axis.truncate(), eye));
        assert!(close(forward_of(&start), forward_of(&m)));

        // A quarter turn to the right: the eye swings about the target at the same
        // distance and still looks at it.
        orbit.turn(std::f32::consts::FRAC_PI_2, 0.0);
        let turned = orbit.world_from_view();
        let eye2 = turned.w_axis.truncate();
        assert!((eye2 - orbit.target).length() - 3.0 < 1e-4);
        assert!(close(eye2, Vec3::new(-3.0, 1.0, 1.0)), "{eye2:?}");
        assert!(close(
            forward_of(&turned),
            (orbit.target - eye2).normalize()
        ));

        // The wheel moves the eye towards the target, never through it.
        orbit.zoom(1.0);
        assert!((orbit.distance - 3.0 * ZOOM_PER_LINE).abs() < 1e-5);
        orbit.zoom(1000.0);
        assert!(orbit.distance > 0.0);
    }

    #[test]
    fn drags_take_over_from_the_scene_camera_in_the_chosen_mode_and_reset_returns() {
        let m = look_at(Vec3::new(0.0, 0.0, 5.0), Vec3::ZERO);
        let mut state = ViewerState::new(None, 0.0, 0.0, 0.0);
        assert_eq!(state.world_from_view(), None);

        state.drag(&m, Vec3::ZERO, 0.0, 0.0);
        assert!(matches!(state.control, CameraControl::Fly(_)));
        // A zero drag leaves the image as it was.
        let w = state.world_from_view().unwrap();
        assert!(close(w.w_axis.truncate(), Vec3::new(0.0, 0.0, 5.0)));

        // Switching to orbit keeps the placement, and then drags turn about the centre.
        state.set_drag_mode(DragMode::Orbit, &w, Vec3::ZERO);
        let CameraControl::Orbit(orbit) = state.control else {
            panic!("{:?}", state.control)
        };
        assert!(close(orbit.target, Vec3::ZERO));
        state.drag(&w, Vec3::ZERO, 100.0, 0.0);
        let turned = state.world_from_view().unwrap();
        assert!((turned.w_axis.truncate().length() - 5.0).abs() < 1e-4);
        assert!(!close(turned.w_axis.truncate(), Vec3::new(0.0, 0.0, 5.0)));

        state.wheel(&turned, Vec3::ZERO, 2.0);
        let zoomed = state.world_from_view().unwrap();
        let expected = 5.0 * ZOOM_PER_LINE * ZOOM_PER_LINE;
        assert!((zoomed.w_axis.truncate().length() - expected).abs() < 1e-4);

        // WASD in orbit mode pans the target.
        state.walk(&zoomed, Vec3::ZERO, Vec3::X, 2.0);
        let CameraControl::Orbit(panned) = state.control else {
            panic!()
        };
        assert!((panned.target.length() - 2.0).abs() < 1e-4);

        state.yfov_degrees = Some(30.0);
        state.reset_to(Some("1".into()));
        assert_eq!(state.control, CameraControl::Scene);
        assert_eq!(state.scene_camera.as_deref(), Some("1"));
        assert_eq!(state.yfov_degrees, None);
    }

    #[test]
    fn fly_wheel_changes_speed_and_walking_uses_it() {
        let m = look_at(Vec3::ZERO, Vec3::NEG_Z);
        let mut state = ViewerState::new(None, 0.0, 0.0, 0.0);
        state.wheel(&m, Vec3::ZERO, 1.0);
        assert!((state.speed - SPEED_PER_LINE).abs() < 1e-6);
        assert_eq!(state.control, CameraControl::Scene);
        state.walk(&m, Vec3::ZERO, Vec3::NEG_Z, 2.0);
        let w = state.world_from_view().unwrap();
        assert!(close(
            w.w_axis.truncate(),
            Vec3::new(0.0, 0.0, -2.0 * SPEED_PER_LINE)
        ));
    }

    #[test]
    fn fov_override_replaces_the_scene_camera_s() {
        let mut camera = crate::viewer::dummy_camera();
        let mut state = ViewerState::new(None, 0.0, 0.0, 0.0);
        state.apply_fov(&mut camera);
        assert_eq!(camera.yfov, 1.0);
        state.yfov_degrees = Some(90.0);
        state.apply_fov(&mut camera);
        assert!((camera.yfov - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
        state.yfov_degrees = Some(1000.0);
        state.apply_fov(&mut camera);
        assert!((camera.yfov - FOV_RANGE_DEGREES.end().to_radians()).abs() < 1e-6);
    }

    #[test]
    fn the_clock_plays_wraps_pauses_and_scrubs() {
        let mut state = ViewerState::new(None, 0.0, 0.0, 2.0);
        assert!(state.playing, "a scene with animation starts playing");
        state.advance(1.5, true);
        state.advance(1.0, true);
        assert!((state.time - 0.5).abs() < 1e-6, "{}", state.time);
        // Scripted runs do not wrap, as `render --frames`.
        state.advance(2.0, false);
        assert!((state.time - 2.5).abs() < 1e-6);
        state.playing = false;
        state.advance(1.0, true);
        assert!((state.time - 2.5).abs() < 1e-6);
        state.scrub(1.25);
        assert_eq!(state.time, 1.25);
        state.scrub(9.0);
        assert_eq!(state.time, 2.0);
        state.scrub(f32::NAN);
        assert_eq!(state.time, 0.0);
        assert!(!ViewerState::new(None, 0.0, 0.0, 0.0).playing);
    }

    #[test]
    fn history_keeps_the_last_frames() {
        let mut state = ViewerState::new(None, 0.0, 0.0, 0.0);
        for i in 0..(HISTORY_FRAMES + 5) {
            state.push_frame_ms(i as f32);
        }
        assert_eq!(state.frame_ms_history.len(), HISTORY_FRAMES);
        assert_eq!(state.frame_ms_history.front(), Some(&5.0));
        assert_eq!(
            state.frame_ms_history.back(),
            Some(&((HISTORY_FRAMES + 4) as f32))
        );
    }

    #[test]
    fn screenshot_key_numbers_files_without_overwriting() {
        let dir = std::env::temp_dir().join(format!("valgi_shots_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("valgi_view_0002.png"), b"taken").unwrap();
        let mut state = ViewerState::new(None, 0.0, 0.0, 0.0);
        let first = state.next_screenshot_path(&dir);
        let second = state.next_screenshot_path(&dir);
        assert_eq!(first, dir.join("valgi_view_0001.png"));
        assert_eq!(second, dir.join("valgi_view_0003.png"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_rebuild_is_pending_until_its_worker_reports_and_newer_requests_win() {
        let ms = |n: u64| Duration::from_millis(n);
        let mut rebuilds = Rebuilds::default();
        assert!(rebuilds.pending().is_none());
        let before = Instant::now();
        let first = rebuilds.request("sparse", MethodOptions::default());
        let t0 = rebuilds.pending().unwrap().started;
        // The UI keeps drawing while the rebuild runs: frames are counted, not blocked. The
        // first interval counts from the request, not from the frame that made it.
        rebuilds.note_frame(before - ms(500), t0 + ms(16));
        rebuilds.note_frame(t0 + ms(16), t0 + ms(56));
        assert_eq!(rebuilds.pending().unwrap().frames, 2);
        assert!((rebuilds.pending().unwrap().longest_frame_ms - 40.0).abs() < 1e-6);

        let second = rebuilds.request("direct", MethodOptions::default());
        assert_ne!(first, second);
        // The superseded worker's method is dropped, the newer one stays pending.
        assert!(rebuilds.finish(first, true).is_none());
        assert_eq!(rebuilds.pending().unwrap().method, "direct");
        assert!(rebuilds.last.is_none());

        let t1 = rebuilds.pending().unwrap().started;
        rebuilds.note_frame(t1, t1 + ms(5));
        let done = rebuilds.finish(second, true).expect("current rebuild");
        assert_eq!(done.method, "direct");
        assert!(rebuilds.pending().is_none());
        let record = rebuilds.last.clone().unwrap();
        assert_eq!(record.frames, 1);
        assert!((record.longest_frame_ms - 5.0).abs() < 1e-6);
        assert!(record.ok);
        // Frames after it are not charged to it.
        rebuilds.note_frame(t1, t1 + ms(500));
        assert!((rebuilds.last.unwrap().longest_frame_ms - 5.0).abs() < 1e-6);
    }

    #[test]
    fn debug_views_are_named_as_the_command_line_names_them() {
        let mut debug = DebugViews::default();
        assert!(!debug.any_overlay() && !debug.needs_pick());
        debug.enable("vals").unwrap();
        assert_eq!(
            debug,
            DebugViews {
                vals: true,
                ..Default::default()
            }
        );
        debug.enable("points").unwrap();
        assert!(debug.points && debug.vals && debug.any_overlay() && !debug.needs_pick());
        let mut picking = DebugViews::default();
        picking.enable("occluders").unwrap();
        assert!(picking.needs_pick() && picking.any_overlay() && !picking.links);
        picking.enable("links").unwrap();
        assert!(picking.links);
        let mut reference = DebugViews::default();
        reference.enable("reference").unwrap();
        assert!(reference.reference && !reference.any_overlay() && !reference.needs_pick());
        reference.enable("atlas").unwrap();
        assert!(reference.atlas && !reference.any_overlay());
        let error = DebugViews::default().enable("normals").unwrap_err();
        assert!(error.contains("--debug normals"), "{error}");
        assert!(error.contains(DEBUG_VIEW_NAMES), "{error}");
    }
}
