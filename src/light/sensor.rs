//! A depth sensor's image as seen by the VAL passes: where its VALs' clusters lie, and the
//! real surfaces it saw as occluders of the rays the sparse points' visibility shoots. CPU
//! twin of `shaders/light/sensor_occluder.wgsl`.
//!
//! **Clusters.** The image is cut into `tiles × tiles` rectangles ([`SENSOR_TILES`]); a VAL
//! from the sensor belongs to the tile its pixel (or, for a fused VAL, its projection into
//! the producer's tiling camera) falls in. Each tile is a cluster of the visibility pass like
//! an RSM tile, after the RSM's tiles. Its `CLUSTER_SAMPLE_SIDE²` strata have
//! `rsm::SAMPLE_CANDIDATES` ray sample slots each, at the strata's centre and corner pixels
//! ([`stratum_pixel`]), which the producer fills with VALs ([`sample_slot`]); the rays go to
//! the first candidate of a stratum that reaches the point, as for the RSM's strata.
//!
//! **Occluders.** The sensor's filtered depth is a height field over its image: what lies
//! behind a seen surface, up to `thickness` deeper, is taken to be solid. A shadow ray is
//! marched through the image ([`depth_blocks`]): a sample is inside matter where it lies more
//! than a tolerance behind the depth there and less than `thickness` behind, and the ray is
//! blocked by a run of such samples with free space on both sides. A run that touches an end
//! does not count: the ends lie on virtual content or on a seen surface, and virtual content
//! behind a seen surface shows that the real thing in front is thinner than `thickness`
//! there (a virtual object partly hidden by a real one must not shadow itself; a real VAL
//! beside a depth edge is not hidden by the nearer side of the edge). Pixels outside the
//! image and depth holes are free space. A single depth image
//! knows nothing of what the sensor did not see, so the thickness is a prior, an option of
//! its producer (`--real-thickness`).

use bytemuck::{Pod, Zeroable};
use glam::{Mat4, Vec3};

use super::rsm::{CLUSTER_SAMPLE_SIDE, SAMPLE_CANDIDATES};
use super::Val;

/// Sensor tiles per image side: `SENSOR_TILES²` clusters of the visibility pass (`SENSOR_TILES`
/// in `sensor_occluder.wgsl`). The RSM's tiles share the rest of `rsm::CLUSTER_BUDGET`.
pub const SENSOR_TILES: u32 = 4;

/// Most samples one shadow ray takes of the depth image (one per pixel it crosses, up to
/// this; `SENSOR_MAX_STEPS` in the WGSL).
pub const SENSOR_MAX_STEPS: u32 = 48;

/// Ray samples nearer the sensor than this (m) are clipped off (`SENSOR_NEAR`).
pub const SENSOR_NEAR: f32 = 0.05;

/// A ray sample is behind the seen surface only past this depth margin: the larger of an
/// absolute (m) and a relative part (the sensor's noise grows with depth; the ray's own
/// end on a real VAL lies on the surface).
pub const SENSOR_TOLERANCE_ABS: f32 = 0.02;
pub const SENSOR_TOLERANCE_REL: f32 = 0.02;

/// `SensorParams` in `shaders/light/sensor_occluder.wgsl`: the latest frame's camera and
/// what its image is to the VAL passes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable, PartialEq)]
pub struct SensorParams {
    pub camera_from_world: [[f32; 4]; 4],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    /// Tiles per image side (0: no sensor, no clusters).
    pub tiles: u32,
    /// 1: the depth blocks shadow rays.
    pub occludes: u32,
    /// Metres of solid matter assumed behind every seen surface.
    pub thickness: f32,
    /// 1: a frame has been uploaded (before that the image is empty).
    pub has_frame: u32,
    pub pad: [u32; 2],
}

impl SensorParams {
    /// The camera-space point (OpenCV axes: +z forward) of a world point.
    pub fn camera_point(&self, world: Vec3) -> Vec3 {
        Mat4::from_cols_array_2d(&self.camera_from_world).transform_point3(world)
    }

    /// The image position (pixel centres at integers) of a camera-space point in front.
    pub fn project(&self, p: Vec3) -> (f32, f32) {
        (self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }

    /// The pixel nearest an image position, if it is inside the image.
    pub fn pixel(&self, u: f32, v: f32) -> Option<(u32, u32)> {
        let (x, y) = ((u + 0.5).floor(), (v + 0.5).floor());
        // `!(x >= 0)` also rejects NaN.
        if !(x >= 0.0 && y >= 0.0) || x >= self.width as f32 || y >= self.height as f32 {
            return None;
        }
        Some((x as u32, y as u32))
    }

    /// Whether shadow rays are tested against the depth.
    pub fn is_occluder(&self) -> bool {
        self.occludes != 0 && self.has_frame != 0
    }

    /// Clusters the sensor's tiles make (0 without a sensor).
    pub fn tile_count(&self) -> u32 {
        self.tiles * self.tiles
    }
}

/// The tile (`ty·tiles + tx`) of pixel (x, y) of a `width × height` image.
pub fn pixel_tile(width: u32, height: u32, tiles: u32, x: u32, y: u32) -> u32 {
    let tx = (x.min(width.saturating_sub(1)) as u64 * tiles as u64 / width.max(1) as u64) as u32;
    let ty = (y.min(height.saturating_sub(1)) as u64 * tiles as u64 / height.max(1) as u64) as u32;
    ty * tiles + tx
}

/// The tile of a world point: the tile of the pixel it projects to, clamped into the image
/// (a fused VAL the latest frame does not see joins the nearest tile on the border).
pub fn world_tile(params: &SensorParams, world: Vec3) -> u32 {
    let p = params.camera_point(world);
    let (u, v) = if p.z > 0.0 {
        params.project(p)
    } else {
        // Behind the camera: towards the side the point lies on.
        (
            params.cx + p.x.signum() * 1e9,
            params.cy + p.y.signum() * 1e9,
        )
    };
    let clamp = |c: f32, n: u32| (c + 0.5).floor().clamp(0.0, n.saturating_sub(1) as f32) as u32;
    pixel_tile(
        params.width,
        params.height,
        params.tiles,
        clamp(u, params.width),
        clamp(v, params.height),
    )
}

/// Candidate `k` of stratum `s` (row-major in the tile's `CLUSTER_SAMPLE_SIDE²` grid) of tile
/// `tile`: the stratum's centre pixel (k = 0), then its corner pixels (k = 1–4: first/last
/// column, first/last row), as the RSM's strata have (`rsm::SAMPLE_CANDIDATES`). The strata of
/// all tiles form one even grid over the image.
pub fn stratum_pixel(width: u32, height: u32, tiles: u32, tile: u32, s: u32, k: u32) -> (u32, u32) {
    let side = (tiles * CLUSTER_SAMPLE_SIDE) as u64;
    let gx = ((tile % tiles) * CLUSTER_SAMPLE_SIDE + s % CLUSTER_SAMPLE_SIDE) as u64;
    let gy = ((tile / tiles) * CLUSTER_SAMPLE_SIDE + s / CLUSTER_SAMPLE_SIDE) as u64;
    let (w, h) = (width as u64, height as u64);
    if k == 0 {
        return (
            ((2 * gx + 1) * w / (2 * side)) as u32,
            ((2 * gy + 1) * h / (2 * side)) as u32,
        );
    }
    // Stratum g spans ⌈g·n/side⌉ .. ⌈(g+1)·n/side⌉, inside its tile's span (`pixel_tile`).
    let pick = |g: u64, n: u64, last: bool| {
        if last {
            ((g + 1) * n).div_ceil(side) - 1
        } else {
            (g * n).div_ceil(side)
        }
    };
    (
        pick(gx, w, (k - 1) & 1 == 1) as u32,
        pick(gy, h, (k - 1) >> 1 == 1) as u32,
    )
}

/// Sample slots of `tiles × tiles` sensor tiles.
pub fn sample_slots(tiles: u32) -> usize {
    (tiles * tiles * CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE * SAMPLE_CANDIDATES) as usize
}

/// The slot of candidate `k` of stratum `s` of sensor tile `tile` in the samples buffer.
pub fn sample_slot(tile: u32, s: u32, k: u32) -> usize {
    ((tile * CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE + s) * SAMPLE_CANDIDATES + k) as usize
}

/// Candidate `k` of stratum `s` of sensor tile `tile`, if its slot holds a VAL.
pub fn stratum_sample(samples: &[Val], tile: u32, s: u32, k: u32) -> Option<Val> {
    let sample = *samples.get(sample_slot(tile, s, k))?;
    (sample.area > 0.0).then_some(sample)
}

/// The samples of a frame whose own surfels are the ray targets: each slot holds the surfel
/// at its candidate pixel (`width × height` `surfels`, area ≤ 0 none). The CPU twin of
/// `depth_vals.wgsl::samples`.
pub fn surfel_samples(surfels: &[Val], width: u32, height: u32, tiles: u32) -> Vec<Val> {
    let mut samples = vec![Val::default(); sample_slots(tiles)];
    for tile in 0..tiles * tiles {
        for s in 0..CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE {
            for k in 0..SAMPLE_CANDIDATES {
                let (x, y) = stratum_pixel(width, height, tiles, tile, s, k);
                if let Some(surfel) = surfels.get((y * width + x) as usize) {
                    if surfel.area > 0.0 {
                        samples[sample_slot(tile, s, k)] = *surfel;
                    }
                }
            }
        }
    }
    samples
}

/// The samples of a list of VALs seen by `params`' camera (fused VALs, which are no pixels
/// of one frame): each slot holds the VAL whose projection is nearest its candidate pixel
/// among those in the slot's stratum (ties: the first in the list), or none.
pub fn projected_samples(params: &SensorParams, vals: &[Val]) -> Vec<Val> {
    let tiles = params.tiles;
    let side = tiles * CLUSTER_SAMPLE_SIDE;
    let mut samples = vec![Val::default(); sample_slots(tiles)];
    let mut nearest = vec![f32::INFINITY; samples.len()];
    if side == 0 || params.width == 0 || params.height == 0 {
        return samples;
    }
    for val in vals.iter().filter(|v| v.area > 0.0) {
        let p = params.camera_point(val.position);
        if p.z <= 0.0 {
            continue;
        }
        let (u, v) = params.project(p);
        let Some((x, y)) = params.pixel(u, v) else {
            continue;
        };
        // The stratum whose span ⌈g·n/side⌉ .. ⌈(g+1)·n/side⌉ holds the pixel.
        let stratum = |c: u32, n: u32| ((c as u64 + 1) * side as u64 - 1) / n as u64;
        let (gx, gy) = (
            stratum(x, params.width) as u32,
            stratum(y, params.height) as u32,
        );
        let tile = (gy / CLUSTER_SAMPLE_SIDE) * tiles + gx / CLUSTER_SAMPLE_SIDE;
        let s = (gy % CLUSTER_SAMPLE_SIDE) * CLUSTER_SAMPLE_SIDE + gx % CLUSTER_SAMPLE_SIDE;
        for k in 0..SAMPLE_CANDIDATES {
            let (cx, cy) = stratum_pixel(params.width, params.height, tiles, tile, s, k);
            let d2 = (u - cx as f32).powi(2) + (v - cy as f32).powi(2);
            let slot = sample_slot(tile, s, k);
            if d2 < nearest[slot] {
                nearest[slot] = d2;
                samples[slot] = *val;
            }
        }
    }
    samples
}

/// Whether the real surfaces in `depth` (metres along the optical axis per pixel, 0 a hole)
/// block the segment from `from` to `to` (world space); see the module notes.
pub fn depth_blocks(params: &SensorParams, depth: &[f32], from: Vec3, to: Vec3) -> bool {
    if !params.is_occluder() {
        return false;
    }
    let (mut a, mut b) = (params.camera_point(from), params.camera_point(to));
    if a.z <= SENSOR_NEAR && b.z <= SENSOR_NEAR {
        return false;
    }
    // Clip to the near plane, so every sample projects.
    if a.z < SENSOR_NEAR {
        a = a.lerp(b, (SENSOR_NEAR - a.z) / (b.z - a.z));
    } else if b.z < SENSOR_NEAR {
        b = b.lerp(a, (SENSOR_NEAR - b.z) / (a.z - b.z));
    }
    let (ua, va) = params.project(a);
    let (ub, vb) = params.project(b);
    let pixels = (ub - ua).abs().max((vb - va).abs());
    let steps = if pixels.is_finite() {
        (pixels.ceil() as u32).clamp(1, SENSOR_MAX_STEPS)
    } else {
        SENSOR_MAX_STEPS
    };
    // Free space seen since the start; inside matter after that.
    let (mut left_start, mut inside_run) = (false, false);
    for i in 0..steps {
        let t = (i as f32 + 0.5) / steps as f32;
        let p = a.lerp(b, t);
        let (u, v) = params.project(p);
        let seen = params
            .pixel(u, v)
            .map(|(x, y)| depth[(y * params.width + x) as usize])
            .filter(|&d| d > 0.0);
        let inside = seen.is_some_and(|d| {
            let tolerance = SENSOR_TOLERANCE_ABS.max(SENSOR_TOLERANCE_REL * d);
            p.z > d + tolerance && p.z < d + params.thickness
        });
        if !inside {
            if inside_run {
                return true;
            }
            left_start = true;
        } else if left_start {
            inside_run = true;
        }
    }
    false
}

/// The sensor's image on the CPU, as the visibility pass's twin reads it.
#[derive(Clone, Debug, Default)]
pub struct SensorImage {
    pub params: SensorParams,
    /// Filtered depth per pixel (m, 0 a hole).
    pub depth: Vec<f32>,
    /// The ray samples per slot ([`sample_slot`]; area ≤ 0: none).
    pub samples: Vec<Val>,
}

/// The sensor's image on the GPU, owned by the VAL producer (which writes `params` with each
/// frame): what [`super::ExternalVals::sensor`] lends the visibility pass.
pub struct SensorBuffers {
    /// One [`SensorParams`] (uniform).
    pub params: wgpu::Buffer,
    /// `width × height` f32: the filtered depth.
    pub depth: wgpu::Buffer,
    /// [`sample_slots`] `rsm::GpuVal`: the ray samples of the tiles' strata.
    pub samples: wgpu::Buffer,
    /// Tiles per image side (fixed for the producer's life).
    pub tiles: u32,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 64×48 sensor at the origin looking down +z (camera = world), with a wall at z = 2
    /// over the whole image and a 0.5 m deep post in front of it at z = 1 over columns 20..28.
    fn wall_with_post() -> (SensorParams, Vec<f32>) {
        let (w, h) = (64u32, 48u32);
        let params = SensorParams {
            camera_from_world: Mat4::IDENTITY.to_cols_array_2d(),
            fx: 50.0,
            fy: 50.0,
            cx: 31.5,
            cy: 23.5,
            width: w,
            height: h,
            tiles: SENSOR_TILES,
            occludes: 1,
            thickness: 0.5,
            has_frame: 1,
            pad: [0; 2],
        };
        let depth = (0..w * h)
            .map(|i| {
                if (20..28).contains(&(i % w)) {
                    1.0
                } else {
                    2.0
                }
            })
            .collect();
        (params, depth)
    }

    /// The world point in front of pixel column `u` (row 23.5) at depth z.
    fn at(params: &SensorParams, u: f32, z: f32) -> Vec3 {
        Vec3::new((u - params.cx) / params.fx * z, 0.0, z)
    }

    #[test]
    fn a_ray_in_front_of_every_surface_is_free() {
        let (p, depth) = wall_with_post();
        assert!(!depth_blocks(
            &p,
            &depth,
            at(&p, 5.0, 0.8),
            at(&p, 60.0, 0.9)
        ));
        // Ending on the wall itself (a real VAL) is not blocked by the wall.
        assert!(!depth_blocks(
            &p,
            &depth,
            at(&p, 5.0, 1.5),
            at(&p, 60.0, 2.0)
        ));
    }

    #[test]
    fn a_ray_through_the_post_is_blocked_and_one_behind_its_thickness_is_not() {
        let (p, depth) = wall_with_post();
        // Across the post's columns at 1.3 m: 0.3 m behind its face, inside its 0.5 m.
        assert!(depth_blocks(
            &p,
            &depth,
            at(&p, 5.0, 1.3),
            at(&p, 60.0, 1.3)
        ));
        // At 1.8 m: behind the assumed thickness, free space between post and wall.
        assert!(!depth_blocks(
            &p,
            &depth,
            at(&p, 5.0, 1.8),
            at(&p, 60.0, 1.8)
        ));
        // Thicker prior: blocked.
        let thick = SensorParams {
            thickness: 0.9,
            ..p
        };
        assert!(depth_blocks(
            &thick,
            &depth,
            at(&p, 5.0, 1.8),
            at(&p, 60.0, 1.8)
        ));
        // Off: never.
        let off = SensorParams { occludes: 0, ..p };
        assert!(!depth_blocks(
            &off,
            &depth,
            at(&p, 5.0, 1.3),
            at(&p, 60.0, 1.3)
        ));
        // Holes are free space.
        let holes: Vec<f32> = depth
            .iter()
            .map(|&d| if d < 1.5 { 0.0 } else { d })
            .collect();
        assert!(!depth_blocks(
            &p,
            &holes,
            at(&p, 5.0, 1.3),
            at(&p, 60.0, 1.3)
        ));
    }

    #[test]
    fn a_ray_starting_behind_a_seen_surface_does_not_block_itself() {
        let (p, depth) = wall_with_post();
        // From just behind the post (virtual content there) out to free space, and into
        // it from free space: a run of matter touching an end is not a blocker.
        let behind = at(&p, 24.0, 1.2);
        assert!(!depth_blocks(&p, &depth, behind, at(&p, 60.0, 1.2)));
        assert!(!depth_blocks(&p, &depth, behind, at(&p, 24.0, 0.6)));
        assert!(!depth_blocks(&p, &depth, at(&p, 60.0, 1.2), behind));
        // Free → post → free is.
        assert!(depth_blocks(
            &p,
            &depth,
            at(&p, 60.0, 1.2),
            at(&p, 5.0, 1.2)
        ));
    }

    #[test]
    fn rays_behind_the_camera_are_clipped_and_outside_the_image_is_free() {
        let (p, depth) = wall_with_post();
        // Entirely behind the sensor.
        assert!(!depth_blocks(
            &p,
            &depth,
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, 0.0, -2.0)
        ));
        // From behind the sensor along the depth axis through the post's shadow (columns
        // 21–26 at 1.1–1.5 m): the part in front of the near plane is marched.
        assert!(depth_blocks(
            &p,
            &depth,
            Vec3::new(-0.2, 0.0, -0.5),
            Vec3::new(-0.2, 0.0, 1.8)
        ));
        // Far outside the image's frustum.
        assert!(!depth_blocks(
            &p,
            &depth,
            Vec3::new(10.0, 0.0, 1.3),
            Vec3::new(20.0, 0.0, 1.3)
        ));
    }

    #[test]
    fn a_world_point_joins_the_tile_it_projects_to_or_the_nearest_border_tile() {
        let (p, _) = wall_with_post();
        // Pixel (40, 30) at 2 m: tile (40·4/64, 30·4/48) = (2, 2).
        let seen = Vec3::new((40.0 - p.cx) / p.fx * 2.0, (30.0 - p.cy) / p.fy * 2.0, 2.0);
        assert_eq!(world_tile(&p, seen), 2 * SENSOR_TILES + 2);
        // Far right of the frustum, level with the centre row: the right border's tile.
        assert_eq!(
            world_tile(&p, Vec3::new(50.0, 0.1, 2.0)),
            2 * SENSOR_TILES + SENSOR_TILES - 1
        );
        // Behind the sensor, up and left: the top-left tile.
        assert_eq!(world_tile(&p, Vec3::new(-1.0, -1.0, -2.0)), 0);
    }

    #[test]
    fn projected_samples_take_the_val_nearest_each_candidate_pixel() {
        let (p, _) = wall_with_post();
        let at_pixel = |x: f32, y: f32, z: f32| Val {
            position: Vec3::new((x - p.cx) / p.fx * z, (y - p.cy) / p.fy * z, z),
            normal: Vec3::NEG_Z,
            flux: Vec3::ONE,
            area: 1e-4,
        };
        // Stratum 1 of tile 0 spans columns 4–7 and rows 0–2; its centre pixel is (6, 1).
        let near = at_pixel(6.2, 1.1, 2.0);
        let far = at_pixel(4.4, 0.3, 2.0);
        let behind = Val {
            position: Vec3::new(0.0, 0.0, -1.0),
            ..near
        };
        let samples = projected_samples(&p, &[far, near, behind]);
        assert_eq!(stratum_sample(&samples, 0, 1, 0), Some(near));
        // The corner (4, 0) is nearer `far`.
        assert_eq!(stratum_sample(&samples, 0, 1, 1), Some(far));
        // Other strata stay empty.
        assert_eq!(stratum_sample(&samples, 0, 0, 0), None);
        let filled = samples.iter().filter(|v| v.area > 0.0).count();
        assert_eq!(filled, SAMPLE_CANDIDATES as usize);
    }

    #[test]
    fn tiles_and_strata_cover_the_image_evenly() {
        // Sizes the strata do not divide: every candidate still lies in its own tile.
        for (w, h) in [(30u32, 20u32), (61, 47)] {
            for tile in 0..SENSOR_TILES * SENSOR_TILES {
                for s in 0..CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE {
                    for k in 0..SAMPLE_CANDIDATES {
                        let (x, y) = stratum_pixel(w, h, SENSOR_TILES, tile, s, k);
                        assert!(x < w && y < h);
                        assert_eq!(pixel_tile(w, h, SENSOR_TILES, x, y), tile, "{w}×{h}");
                    }
                }
            }
        }
        let (w, h, t) = (64, 48, SENSOR_TILES);
        assert_eq!(pixel_tile(w, h, t, 0, 0), 0);
        assert_eq!(pixel_tile(w, h, t, 63, 47), t * t - 1);
        assert_eq!(pixel_tile(w, h, t, 16, 12), t + 1);
        let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
        let mut seen = std::collections::HashSet::new();
        for tile in 0..t * t {
            for s in 0..per_tile {
                for k in 0..SAMPLE_CANDIDATES {
                    let (x, y) = stratum_pixel(w, h, t, tile, s, k);
                    // Each candidate lies in its own tile, and no two share a pixel.
                    assert_eq!(pixel_tile(w, h, t, x, y), tile, "tile {tile} stratum {s}");
                    assert!(seen.insert((x, y)), "tile {tile} stratum {s} candidate {k}");
                }
            }
        }
        // 16 strata per side over 64 columns (4 pixels each): centres at 2, 6, 10, …
        assert_eq!(stratum_pixel(w, h, t, 0, 0, 0), (2, 1));
        assert_eq!(stratum_pixel(w, h, t, 0, 1, 0), (6, 1));
        // Corners of stratum 1 (columns 4–7, rows 0–2 of 48/16 = 3).
        assert_eq!(stratum_pixel(w, h, t, 0, 1, 1), (4, 0));
        assert_eq!(stratum_pixel(w, h, t, 0, 1, 2), (7, 0));
        assert_eq!(stratum_pixel(w, h, t, 0, 1, 3), (4, 2));
        assert_eq!(stratum_pixel(w, h, t, 0, 1, 4), (7, 2));
    }
}
