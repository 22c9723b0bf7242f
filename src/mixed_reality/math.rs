//! CPU twins of `shaders/mixed_reality/depth_vals.wgsl`, and the documentation of its math.
//!
//! - Bilateral filter: `z'(p) = Σ_q w z(q) / Σ_q w` over the valid q of a (2r+1)² window,
//!   `w = exp(−|q−p|²/(2σ_s²) − (z(q)−z(p))²/(2σ_r²))`; holes stay holes.
//! - Back-projection: `X = z·((u−c_x)/f_x, (v−c_y)/f_y, 1)`, then `world_from_camera · X`.
//! - Normal: the cross product of the image-axis tangents (central differences on the
//!   surface, one-sided at an edge, none across a jump of more than `max_jump · z`), turned
//!   toward the sensor.
//! - Area: the pixel's solid angle `Ω = cos³α/(f_x f_y)` times `d²` is the facing footprint
//!   `A_f = z²·cos α/(f_x f_y)` (`z²/(f_x f_y)` on the axis); the true area of the tilted
//!   patch is `A_t = A_f / max(cos θ_s, 0.2)`.
//! - Flux: a Lambertian patch of radiance `L = k·srgb⁻¹(c)` and area `A_t` emits
//!   `Φ = π·L·A_t`, so the disc-VAL irradiance `Φ cos cos/(π(d²+r²))` is the patch's
//!   `L·A_t cos cos/d²` far away.
//! - Reduction: the surfels of each block of a `G_x × G_y` grid merge into one VAL: position
//!   and normal weighted by `A_t`, flux and area summed (flux is conserved exactly).
//! - Cut (`--real-cut θ`): the same merge over a quadtree of 2×2 … 32×32-pixel blocks, each
//!   block taken whole where its radius ρ (the largest distance of a surfel from its mean)
//!   is below θ times its gap to the receivers' bounding sphere, `ρ < θ·(|m − c| − R − ρ)`,
//!   so that no receiver sees it larger than about θ radians; else its four children are
//!   tried. A disc of radius ρ at distance d differs from a point of the same flux by
//!   O((ρ/d)²) in irradiance, so θ = 0.1 costs about 1 % where it merges.

use glam::{Mat4, Vec3};

use crate::light::Val;

/// What `bilateral` and `surfel` are told.
#[derive(Clone, Copy, Debug)]
pub struct KernelParams {
    pub world_from_camera: Mat4,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    pub grid_width: u32,
    pub grid_height: u32,
    pub sigma_spatial: f32,
    pub sigma_range: f32,
    pub real_scale: f32,
    pub max_jump: f32,
    pub radius: u32,
    pub true_area: bool,
}

/// The lowest `cos θ_s` the true area divides by (grazing pixels would blow it up).
pub const TRUE_AREA_MIN_COSINE: f32 = 0.2;

/// One pixel's surfel: the VAL it would be, and its true area (the merge weight).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Surfel {
    pub val: Val,
    pub true_area: f32,
}

impl Surfel {
    pub fn is_valid(&self) -> bool {
        self.val.area > 0.0
    }
}

/// The bilateral filter of `depth` (row-major, 0 = hole).
pub fn bilateral(depth: &[f32], p: &KernelParams) -> Vec<f32> {
    let (w, h) = (p.width as i32, p.height as i32);
    let r = p.radius as i32;
    let inv_s = 1.0 / (2.0 * p.sigma_spatial * p.sigma_spatial);
    let inv_r = 1.0 / (2.0 * p.sigma_range * p.sigma_range);
    let mut out = vec![0.0; depth.len()];
    for y in 0..h {
        for x in 0..w {
            let z = depth[(y * w + x) as usize];
            if z <= 0.0 {
                continue;
            }
            let (mut sum, mut weights) = (0.0f32, 0.0f32);
            for dy in -r..=r {
                let yy = y + dy;
                if yy < 0 || yy >= h {
                    continue;
                }
                for dx in -r..=r {
                    let xx = x + dx;
                    if xx < 0 || xx >= w {
                        continue;
                    }
                    let zq = depth[(yy * w + xx) as usize];
                    if zq <= 0.0 {
                        continue;
                    }
                    let dz = zq - z;
                    let wq = (-((dx * dx + dy * dy) as f32) * inv_s - dz * dz * inv_r).exp();
                    sum += wq * zq;
                    weights += wq;
                }
            }
            out[(y * w + x) as usize] = sum / weights;
        }
    }
    out
}

fn camera_point(depth: &[f32], p: &KernelParams, x: u32, y: u32) -> Vec3 {
    let z = depth[(y * p.width + x) as usize];
    Vec3::new(
        (x as f32 - p.cx) / p.fx * z,
        (y as f32 - p.cy) / p.fy * z,
        z,
    )
}

fn tangent(depth: &[f32], p: &KernelParams, x: u32, y: u32, (sx, sy): (u32, u32), z: f32) -> Vec3 {
    let same = |zq: f32| zq > 0.0 && (zq - z).abs() <= p.max_jump * z;
    let has_prev = (sx == 1 && x > 0) || (sy == 1 && y > 0);
    let has_next = (sx == 1 && x + 1 < p.width) || (sy == 1 && y + 1 < p.height);
    let prev_ok = has_prev && same(depth[((y - sy) * p.width + x - sx) as usize]);
    let next_ok = has_next && same(depth[((y + sy) * p.width + x + sx) as usize]);
    let here = camera_point(depth, p, x, y);
    match (prev_ok, next_ok) {
        (true, true) => {
            camera_point(depth, p, x + sx, y + sy) - camera_point(depth, p, x - sx, y - sy)
        }
        (false, true) => camera_point(depth, p, x + sx, y + sy) - here,
        (true, false) => here - camera_point(depth, p, x - sx, y - sy),
        (false, false) => Vec3::ZERO,
    }
}

/// Every pixel's surfel from the filtered depth and the decoded colour.
pub fn surfels(depth: &[f32], color: &[[f32; 3]], p: &KernelParams) -> Vec<Surfel> {
    let mut out = vec![Surfel::default(); depth.len()];
    for y in 0..p.height {
        for x in 0..p.width {
            let i = (y * p.width + x) as usize;
            let z = depth[i];
            if z <= 0.0 {
                continue;
            }
            let c = tangent(depth, p, x, y, (1, 0), z).cross(tangent(depth, p, x, y, (0, 1), z));
            if c.length_squared() <= 1e-20 * z * z * z * z {
                continue;
            }
            let point = camera_point(depth, p, x, y);
            let mut n = c.normalize();
            if n.dot(point) > 0.0 {
                n = -n;
            }
            let d = point.length();
            let cos_sensor = n.dot(-point / d).max(0.0);
            let facing_area = z * z * (z / d) / (p.fx * p.fy);
            let true_area = facing_area / cos_sensor.max(TRUE_AREA_MIN_COSINE);
            let radiance = Vec3::from(color[i]) * p.real_scale;
            out[i] = Surfel {
                val: Val {
                    position: p.world_from_camera.transform_point3(point),
                    normal: p.world_from_camera.transform_vector3(n).normalize(),
                    flux: std::f32::consts::PI * radiance * true_area,
                    area: if p.true_area { true_area } else { facing_area },
                },
                true_area,
            };
        }
    }
    out
}

/// The pixel range `[start, end)` of block `b` of `blocks` over `size` pixels.
pub fn block_range(b: u32, blocks: u32, size: u32) -> (u32, u32) {
    (b * size / blocks, (b + 1) * size / blocks)
}

/// One VAL per grid block (area 0 where the block holds no lit surfel).
pub fn reduce(surfels: &[Surfel], p: &KernelParams) -> Vec<Val> {
    let mut out = Vec::with_capacity((p.grid_width * p.grid_height) as usize);
    for by in 0..p.grid_height {
        for bx in 0..p.grid_width {
            let (x0, x1) = block_range(bx, p.grid_width, p.width);
            let (y0, y1) = block_range(by, p.grid_height, p.height);
            let (mut position, mut normal, mut flux) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
            let (mut area, mut weights) = (0.0f32, 0.0f32);
            for y in y0..y1 {
                for x in x0..x1 {
                    let s = surfels[(y * p.width + x) as usize];
                    if !s.is_valid() {
                        continue;
                    }
                    position += s.true_area * s.val.position;
                    normal += s.true_area * s.val.normal;
                    flux += s.val.flux;
                    area += s.val.area;
                    weights += s.true_area;
                }
            }
            out.push(
                if weights > 0.0 && flux.max_element() > 0.0 && normal.length() > 1e-6 * weights {
                    Val {
                        position: position / weights,
                        normal: normal.normalize(),
                        flux,
                        area,
                    }
                } else {
                    Val::default()
                },
            );
        }
    }
    out
}

/// The cluster tile (of `tiles × tiles` over the image, `light::sensor::pixel_tile`) of block
/// (bx, by): its first pixel's. The reduce pass writes it into each candidate's `flux.w`.
pub fn block_tile(bx: u32, by: u32, p: &KernelParams, tiles: u32) -> u32 {
    let (x0, _) = block_range(bx, p.grid_width, p.width);
    let (y0, _) = block_range(by, p.grid_height, p.height);
    crate::light::sensor::pixel_tile(p.width, p.height, tiles, x0, y0)
}

/// The stratified grid for at most `target` VALs from a `width × height` frame: blocks of
/// near-square shape, every pixel its own block when `target` covers the frame.
pub fn grid_for(width: u32, height: u32, target: Option<u32>) -> (u32, u32) {
    let pixels = width as u64 * height as u64;
    match target {
        Some(n) if (n as u64) < pixels => {
            let n = n.max(1);
            let scale = (n as f64 / pixels as f64).sqrt();
            let gw = ((width as f64 * scale).round() as u32).clamp(1, width.min(n));
            let gh = (n / gw).clamp(1, height);
            (gw, gh)
        }
        _ => (width, height),
    }
}

/// `--real-cut`: the side, in pixels, of the largest block of surfels merged into one VAL
/// (a block of 2^[`CUT_LEVELS`] pixels; one workgroup of the `cut` pass each).
pub const CUT_BLOCK: u32 = 1 << CUT_LEVELS;

/// Merge levels of `--real-cut` above the pixels: 2×2, 4×4, … 32×32 pixels.
pub const CUT_LEVELS: u32 = 5;

/// `--real-cut` merges a block only when the length of its flux-weighted mean normal is
/// at least this (1: all surfels face one way). It keeps a table's top and its edge, or two
/// walls of a corner, apart, while the sensor's normal noise does not split flat surfaces: on
/// the Open3D frame 0 the median over 32×32-pixel blocks is 0.954 (10th percentile 0.733; 16
/// of 282 blocks fall below 0.7), over 8×8 blocks 0.977 (54 of 4255 below).
pub const CUT_NORMAL_AGREEMENT: f32 = 0.7;

/// The virtual receivers (the sparse points) as one world-space sphere: `--real-cut` merges
/// sensor pixels by their angular size seen from the nearest place inside it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Receivers {
    pub centre: Vec3,
    pub radius: f32,
}

/// A block of surfels as the cut merges them: sums, so a merge is exact and order-fixed.
/// Positions and normals are weighted by flux (the mean of its channels), not by area as in
/// [`reduce`]: the flux-weighted centroid is the point about which the first-order term of
/// the block's irradiance at a distant receiver vanishes, so a block whose colour varies
/// across it still merges to second order.
#[derive(Clone, Copy, Debug, Default)]
struct CutNode {
    /// Σ w·position.
    weighted_position: Vec3,
    /// Σ VAL area.
    area: f32,
    /// Σ w·normal.
    weighted_normal: Vec3,
    /// Σ w, w = the flux's channel mean.
    weight: f32,
    flux: Vec3,
    /// Largest distance of a surfel from the block's mean position (an upper bound).
    radius: f32,
}

impl CutNode {
    /// A surfel that emits (unlit and invalid pixels are empty, as in [`reduce`]).
    fn of(s: &Surfel) -> Self {
        let w = s.val.flux.element_sum() / 3.0;
        if !s.is_valid() || w.is_nan() || w <= 0.0 {
            return Self::default();
        }
        Self {
            weighted_position: w * s.val.position,
            area: s.val.area,
            weighted_normal: w * s.val.normal,
            weight: w,
            flux: s.val.flux,
            radius: 0.0,
        }
    }

    fn mean(&self) -> Vec3 {
        self.weighted_position / self.weight
    }

    /// Four children in the order (0,0), (1,0), (0,1), (1,1): the WGSL sums in that order.
    fn merge(c: [CutNode; 4]) -> Self {
        let mut n = Self::default();
        for child in &c {
            n.weighted_position += child.weighted_position;
            n.area += child.area;
            n.weighted_normal += child.weighted_normal;
            n.weight += child.weight;
            n.flux += child.flux;
        }
        if n.weight > 0.0 {
            let mean = n.mean();
            for child in c.iter().filter(|c| c.weight > 0.0) {
                n.radius = n.radius.max((child.mean() - mean).length() + child.radius);
            }
        }
        n
    }

    /// The VAL of the block, as `reduce` makes it (area 0: nothing to emit).
    fn val(&self) -> Val {
        if self.weight > 0.0
            && self.flux.max_element() > 0.0
            && self.weighted_normal.length() > 1e-6 * self.weight
        {
            Val {
                position: self.mean(),
                normal: self.weighted_normal.normalize(),
                flux: self.flux,
                area: self.area,
            }
        } else {
            Val::default()
        }
    }
}

/// Whether a merged block (pixels `x0..x1 × y0..y1`) stands for its surfels at every
/// receiver: no receiver sees it larger than `ratio` (its radius over the gap between it and
/// the receivers' sphere), its normals agree, and it lies in one visibility tile (so its
/// VAL's cluster is every surfel's). A block that emits nothing is taken whole.
#[allow(clippy::too_many_arguments)]
fn cut_accepts(
    n: &CutNode,
    (x0, y0, x1, y1): (u32, u32, u32, u32),
    p: &KernelParams,
    tiles: u32,
    ratio: f32,
    receivers: Option<Receivers>,
) -> bool {
    if n.weight <= 0.0 {
        return true;
    }
    let Some(r) = receivers else {
        return false;
    };
    let tile = |x, y| crate::light::sensor::pixel_tile(p.width, p.height, tiles, x, y);
    if tile(x0, y0) != tile(x1 - 1, y1 - 1) {
        return false;
    }
    if n.weighted_normal.length() < CUT_NORMAL_AGREEMENT * n.weight {
        return false;
    }
    let gap = (n.mean() - r.centre).length() - r.radius - n.radius;
    n.radius < ratio * gap
}

/// CPU twin of the `cut` pass (`--real-cut RATIO`): the frame's surfels merged into the
/// coarsest blocks of a quadtree (2×2 … 32×32 pixels, aligned to [`CUT_BLOCK`]) that
/// [`cut_accepts`]; every lit pixel is in exactly one emitted block, so the flux is conserved
/// exactly. One candidate slot per pixel: a block's VAL sits at its first (top-left) pixel,
/// its other pixels are empty. With no receivers or `ratio` 0 nothing merges and the result
/// is [`reduce`] on a one-pixel grid (to rounding: w·x/w).
pub fn cut(
    surfels: &[Surfel],
    p: &KernelParams,
    tiles: u32,
    ratio: f32,
    receivers: Option<Receivers>,
) -> Vec<Val> {
    let (w, h) = (p.width, p.height);
    let mut out = vec![Val::default(); (w * h) as usize];
    let surfel_node = |x: u32, y: u32| {
        if x < w && y < h {
            CutNode::of(&surfels[(y * w + x) as usize])
        } else {
            CutNode::default()
        }
    };
    for by in 0..h.div_ceil(CUT_BLOCK) {
        for bx in 0..w.div_ceil(CUT_BLOCK) {
            // levels[l][j·side + i]: the block's level-l nodes, side = CUT_BLOCK >> l.
            let mut levels: Vec<Vec<CutNode>> = Vec::with_capacity(CUT_LEVELS as usize + 1);
            levels.push(
                (0..CUT_BLOCK * CUT_BLOCK)
                    .map(|k| {
                        surfel_node(
                            bx * CUT_BLOCK + k % CUT_BLOCK,
                            by * CUT_BLOCK + k / CUT_BLOCK,
                        )
                    })
                    .collect(),
            );
            for l in 1..=CUT_LEVELS {
                let side = CUT_BLOCK >> l;
                let below = &levels[l as usize - 1];
                let child = |i: u32, j: u32| below[(j * 2 * side + i) as usize];
                let level = (0..side * side)
                    .map(|k| {
                        let (i, j) = (2 * (k % side), 2 * (k / side));
                        CutNode::merge([
                            child(i, j),
                            child(i + 1, j),
                            child(i, j + 1),
                            child(i + 1, j + 1),
                        ])
                    })
                    .collect();
                levels.push(level);
            }
            // Top-down: emit a node if it is accepted, else its four children.
            let mut stack = vec![(CUT_LEVELS, 0u32, 0u32)];
            while let Some((l, i, j)) = stack.pop() {
                let size = 1 << l;
                let (x0, y0) = (bx * CUT_BLOCK + i * size, by * CUT_BLOCK + j * size);
                if x0 >= w || y0 >= h {
                    continue;
                }
                let extent = (x0, y0, (x0 + size).min(w), (y0 + size).min(h));
                let node = &levels[l as usize][(j * (CUT_BLOCK >> l) + i) as usize];
                if l == 0 || cut_accepts(node, extent, p, tiles, ratio, receivers) {
                    out[(y0 * w + x0) as usize] = node.val();
                } else {
                    for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        stack.push((l - 1, 2 * i + di, 2 * j + dj));
                    }
                }
            }
        }
    }
    out
}

/// `--accumulate K`: the surfels of the last K frames fused in a world-space voxel hash, one
/// VAL per voxel, so that the light of a surface does not vanish when the camera turns away
/// from it or flicker with each frame's noise (restriction 3 of seed 003 §5). A voxel's VAL
/// is the frames' average: position and normal weighted by true area, flux and area summed
/// over its surfels and divided by the number of frames that saw the voxel.
#[derive(Clone, Debug)]
pub struct VoxelFusion {
    pub frames: usize,
    /// Voxel edge, metres.
    pub voxel: f32,
    history: std::collections::VecDeque<Vec<Surfel>>,
}

#[derive(Clone, Copy, Default)]
struct VoxelSum {
    position: Vec3,
    normal: Vec3,
    flux: Vec3,
    area: f32,
    weight: f32,
    seen_by: u32,
    last_frame: usize,
}

impl VoxelFusion {
    pub fn new(frames: usize, voxel: f32) -> Self {
        Self {
            frames: frames.max(1),
            voxel,
            history: Default::default(),
        }
    }

    /// Adds a frame's surfels and returns the fused VALs, sorted by voxel (deterministic),
    /// at most `capacity` of them.
    pub fn push(&mut self, surfels: Vec<Surfel>, capacity: usize) -> Vec<Val> {
        self.history
            .push_back(surfels.into_iter().filter(Surfel::is_valid).collect());
        while self.history.len() > self.frames {
            self.history.pop_front();
        }
        let mut voxels: std::collections::HashMap<[i32; 3], VoxelSum> = Default::default();
        for (frame, surfels) in self.history.iter().enumerate() {
            for s in surfels {
                let key = (s.val.position / self.voxel).floor().as_ivec3().to_array();
                let v = voxels.entry(key).or_default();
                if v.seen_by == 0 || v.last_frame != frame {
                    v.seen_by += 1;
                    v.last_frame = frame;
                }
                v.position += s.true_area * s.val.position;
                v.normal += s.true_area * s.val.normal;
                v.flux += s.val.flux;
                v.area += s.val.area;
                v.weight += s.true_area;
            }
        }
        let mut keyed: Vec<([i32; 3], VoxelSum)> = voxels.into_iter().collect();
        keyed.sort_unstable_by_key(|(k, _)| *k);
        keyed
            .into_iter()
            .filter(|(_, v)| v.weight > 0.0 && v.normal.length() > 1e-6 * v.weight)
            .filter(|(_, v)| v.flux.max_element() > 0.0)
            .take(capacity)
            .map(|(_, v)| {
                let frames = v.seen_by as f32;
                Val {
                    position: v.position / v.weight,
                    normal: v.normal.normalize(),
                    flux: v.flux / frames,
                    area: v.area / frames,
                }
            })
            .collect()
    }
}
