//! The sparse virtual-area-light method's equations on the CPU (DESIGN §4). These are the CPU
//! twins of the WGSL kernels in `shaders/vals_*.wgsl`: the same inputs, the same formulas, in
//! plain Rust, so that tests can check the GPU against them and a reader can follow the math
//! without reading shaders.

use glam::Vec3;
use std::f32::consts::PI;

/// ε of the averaged-position weights `w = ε + A·g`: keeps an average defined where no light
/// arrives, small enough not to move it where light does (A·g is ~1e-4 and up in metre scenes).
pub const POSITION_EPSILON: f32 = 1e-12;

/// The renormalization clamp, as a minimum cosine: `c_min = COS_MIN / |l − x|²`. Clamping the
/// cosine (rather than the whole `cos/d²`) keeps the guard independent of the scene's scale.
pub const COS_MIN: f32 = 1e-2;

/// Interpolation weight sum below which a vertex gets no light rather than a division by ~0.
pub const WEIGHT_EPSILON: f32 = 1e-6;

/// The most a vertex's blended diffuse light may give it over the mean of its links' lights
/// evaluated at the vertex ([`interpolate`]). Beyond it the excess is the blend's, not light.
pub const BLEND_GAIN_MAX: f32 = 2.0;

pub use crate::light::Val;

/// A sparse receiver point in world space with its material's Phong exponent.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Receiver {
    pub position: Vec3,
    pub normal: Vec3,
    pub k: f32,
}

/// `g = max(0, n·ω̂)·max(0, −n_j·ω̂) / (|d|² + r_j²)`, ω̂ from x toward the disc: the disc's
/// irradiance per unit flux, times π. Finite at zero distance; the point-light law far away.
/// Computed as the kernels do, with the cosines' 1/|d| folded into the denominator,
/// `max(0, n·d)·max(0, −n_j·d) / (|d|²·(|d|² + r_j²))`: a diffuse sum then needs no square root.
pub fn disc_geometry(x: Vec3, n: Vec3, val: &Val) -> (f32, Vec3) {
    let d = val.position - x;
    let dist2 = d.length_squared();
    let denominator = dist2 * (dist2 + val.radius_squared());
    if denominator <= 0.0 {
        return (0.0, Vec3::ZERO);
    }
    let cosines = n.dot(d).max(0.0) * (-val.normal.dot(d)).max(0.0);
    (cosines / denominator, d / dist2.sqrt())
}

/// `E_j(x) = Φ_j·g_j/π`: irradiance at x (normal n) from one disc VAL.
pub fn disc_irradiance(x: Vec3, n: Vec3, val: &Val) -> Vec3 {
    val.flux * (disc_geometry(x, n, val).0 / PI)
}

/// `max(0, r·ω)^k`, the Phong lobe around the mirror direction r.
pub fn lobe(r: Vec3, w: Vec3, k: f32) -> f32 {
    r.dot(w).max(0.0).powf(k)
}

/// `reflect(−ω_o, n)`: the mirror direction of the view direction ω_o (pointing to the eye).
pub fn mirror(wo: Vec3, n: Vec3) -> Vec3 {
    let i = -wo;
    i - 2.0 * n.dot(i) * n
}

/// Irradiance at x from a point light of intensity `i` at `l`: `I·max(0, n·ω̂)/|l−x|²`.
pub fn diffuse_point(x: Vec3, n: Vec3, l: Vec3, i: Vec3) -> Vec3 {
    i * diffuse_point_factor(x, n, l)
}

pub fn diffuse_point_factor(x: Vec3, n: Vec3, l: Vec3) -> f32 {
    let d = l - x;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return 0.0;
    }
    n.dot(d / dist2.sqrt()).max(0.0) / dist2
}

/// Lobe-weighted irradiance: `I·max(0, r·ω̂)^k·max(0, n·ω̂)/|l−x|²`.
pub fn glossy_point(x: Vec3, n: Vec3, r: Vec3, k: f32, l: Vec3, i: Vec3) -> Vec3 {
    i * glossy_point_factor(x, n, r, k, l)
}

pub fn glossy_point_factor(x: Vec3, n: Vec3, r: Vec3, k: f32, l: Vec3) -> f32 {
    let d = l - x;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return 0.0;
    }
    let w = d / dist2.sqrt();
    lobe(r, w, k) * n.dot(w).max(0.0) / dist2
}

/// How the averaged light positions weight each VAL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Weights {
    /// `w = ε + A_j·g_j` (the paper's): independent of the VALs' flux and of RSM density.
    Geometric,
    /// `w = ε + mean(Φ_j)·g_j`: the irradiance each VAL contributes.
    Flux,
}

/// Step 1's sums at one sparse point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Gathered {
    /// Σ E_j (W/m²).
    pub diffuse: Vec3,
    /// Σ lobe_j·E_j.
    pub glossy: Vec3,
    /// Weighted mean VAL positions.
    pub diffuse_position: Vec3,
    pub glossy_position: Vec3,
    /// Occlusion sphere radii: twice the largest per-axis weighted standard deviation of the
    /// VAL positions around the mean (the σ-box's largest side).
    pub diffuse_sphere: f32,
    pub glossy_sphere: f32,
}

/// Running weighted moments of positions: Σw, Σw·l, Σw·l².
#[derive(Clone, Copy, Debug, Default)]
pub struct Moments {
    pub weight: f32,
    pub sum: Vec3,
    pub sum_squares: Vec3,
}

impl Moments {
    pub fn add(&mut self, w: f32, l: Vec3) {
        self.weight += w;
        self.sum += w * l;
        self.sum_squares += w * l * l;
    }

    /// Mean and sphere radius (2·max σ).
    pub fn mean_and_sphere(&self) -> (Vec3, f32) {
        if self.weight <= 0.0 {
            return (Vec3::ZERO, 0.0);
        }
        let mean = self.sum / self.weight;
        let variance = (self.sum_squares / self.weight - mean * mean).max(Vec3::ZERO);
        (mean, 2.0 * variance.max_element().sqrt())
    }
}

/// Step 1 — gather every VAL at one receiver. `eye` gives the view direction for the glossy
/// lobe; with `glossy` off the glossy sums stay zero.
pub fn gather(
    receiver: &Receiver,
    eye: Vec3,
    vals: &[Val],
    weights: Weights,
    glossy: bool,
) -> Gathered {
    gather_visible(receiver, eye, vals, weights, glossy, |_| 1.0)
}

/// Step 1 with visibility: VAL `j`'s geometry term (its irradiance and its weight in the
/// averaged positions) scaled by `visibility(j)` ∈ [0, 1], its cluster's visible fraction at
/// the receiver (`--occlusion rays`).
pub fn gather_visible(
    receiver: &Receiver,
    eye: Vec3,
    vals: &[Val],
    weights: Weights,
    glossy: bool,
    visibility: impl Fn(usize) -> f32,
) -> Gathered {
    let x = receiver.position;
    let n = receiver.normal;
    let r = mirror((eye - x).normalize_or_zero(), n);
    let mut diffuse = Vec3::ZERO;
    let mut glossy_sum = Vec3::ZERO;
    let mut diffuse_moments = Moments::default();
    let mut glossy_moments = Moments::default();
    for (j, val) in vals.iter().enumerate() {
        let (g, w) = disc_geometry(x, n, val);
        let g = g * visibility(j);
        let e = val.flux * (g / PI);
        let strength = match weights {
            Weights::Geometric => val.area * g,
            Weights::Flux => (val.flux.x + val.flux.y + val.flux.z) / 3.0 * g,
        };
        diffuse += e;
        diffuse_moments.add(POSITION_EPSILON + strength, val.position);
        if glossy {
            let lobe_j = if g > 0.0 { lobe(r, w, receiver.k) } else { 0.0 };
            glossy_sum += e * lobe_j;
            glossy_moments.add(POSITION_EPSILON + strength * lobe_j, val.position);
        }
    }
    let (diffuse_position, diffuse_sphere) = diffuse_moments.mean_and_sphere();
    let (glossy_position, glossy_sphere) = if glossy {
        glossy_moments.mean_and_sphere()
    } else {
        (x, 0.0)
    };
    Gathered {
        diffuse,
        glossy: glossy_sum,
        diffuse_position,
        glossy_position,
        diffuse_sphere,
        glossy_sphere,
    }
}

/// One point light per channel after renormalization.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PointLights {
    pub diffuse_position: Vec3,
    pub diffuse: Vec3,
    pub glossy_position: Vec3,
    pub glossy: Vec3,
}

/// Step 2 — renormalize: intensities that reproduce the gathered sums at x exactly (unless the
/// clamp fires; the flags say which channel clamped).
pub fn renormalize(
    receiver: &Receiver,
    eye: Vec3,
    gathered: &Gathered,
) -> (PointLights, [bool; 2]) {
    let x = receiver.position;
    let n = receiver.normal;
    let r = mirror((eye - x).normalize_or_zero(), n);
    let clamp = |factor: f32, l: Vec3| {
        let c_min = COS_MIN / (l - x).length_squared().max(1e-30);
        (factor.max(c_min), factor < c_min)
    };
    let (fd, clamped_d) = clamp(
        diffuse_point_factor(x, n, gathered.diffuse_position),
        gathered.diffuse_position,
    );
    let (fs, clamped_s) = clamp(
        glossy_point_factor(x, n, r, receiver.k, gathered.glossy_position),
        gathered.glossy_position,
    );
    let has_d = gathered.diffuse.max_element() > 0.0;
    let has_s = gathered.glossy.max_element() > 0.0;
    (
        PointLights {
            diffuse_position: gathered.diffuse_position,
            diffuse: gathered.diffuse / fd,
            glossy_position: gathered.glossy_position,
            glossy: gathered.glossy / fs,
        },
        [clamped_d && has_d, clamped_s && has_s],
    )
}

/// How occluders' shares combine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OcclusionMode {
    Off,
    /// `o = min(1, Σ o_i)` (the paper's; occludes twice behind aligned occluders).
    Sum,
    /// `o = 1 − Π(1 − o_i)`: independent occluders; never more than `Sum`.
    Union,
    /// No discs: shadow rays to each VAL cluster's samples weight its VALs in the gather
    /// ([`crate::vals::visibility`]).
    Rays,
}

impl OcclusionMode {
    /// Its value of the `occlusion` option, as the JSON report also names it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Sum => "sum",
            Self::Union => "union",
            Self::Rays => "rays",
        }
    }
}

/// An occluder disc: a sparse point with its Voronoi radius.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OccluderDisc {
    pub center: Vec3,
    pub normal: Vec3,
    pub radius: f32,
}

/// A tangent frame (t, b) for a unit normal (Duff et al. 2017, branchless and continuous
/// except at n.z = −1's sign flip). The shader builds the same frame so the squares agree.
pub fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let sign = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x),
        Vec3::new(b, sign + n.y * n.y * a, -n.y),
    )
}

/// Overlap area of two axis-aligned squares given centres and areas.
fn square_overlap(a: (f32, f32), area_a: f32, b: (f32, f32), area_b: f32) -> f32 {
    let (ha, hb) = (0.5 * area_a.sqrt(), 0.5 * area_b.sqrt());
    let ox = ((a.0 + ha).min(b.0 + hb) - (a.0 - ha).max(b.0 - hb)).max(0.0);
    let oy = ((a.1 + ha).min(b.1 + hb) - (a.1 - ha).max(b.1 - hb)).max(0.0);
    ox * oy
}

/// The fraction of the light sphere (centre `light`, radius `sphere`) that one disc hides as
/// seen from x, before combining: the projected-square overlap over the sphere's projected
/// area, ramped linearly to 0 as the occluder goes from the sphere's front to its centre.
pub fn occluder_share(x: Vec3, n: Vec3, light: Vec3, sphere: f32, disc: &OccluderDisc) -> f32 {
    let to_light = light - x;
    let light_distance = to_light.length();
    let to_disc = disc.center - x;
    let disc_distance = to_disc.length();
    if sphere <= 0.0 || light_distance <= 0.0 || disc_distance <= 0.0 || disc.radius <= 0.0 {
        return 0.0;
    }
    let wl = to_light / light_distance;
    let wd = to_disc / disc_distance;
    // Below the horizon an occluder cannot block anything the receiver sees.
    if n.dot(wd) <= 0.0 || disc_distance >= light_distance {
        return 0.0;
    }
    let ramp = ((light_distance - disc_distance) / sphere).min(1.0);
    let (t, b) = tangent_frame(n);
    let sphere_area = PI * sphere * sphere / (sphere * sphere + light_distance * light_distance);
    let disc_area = PI * disc.radius * disc.radius
        / (disc.radius * disc.radius + disc_distance * disc_distance)
        * disc.normal.dot(wd).abs();
    let overlap = square_overlap(
        (wl.dot(t), wl.dot(b)),
        sphere_area,
        (wd.dot(t), wd.dot(b)),
        disc_area,
    );
    (overlap / sphere_area).min(1.0) * ramp
}

/// A node of occluder discs as the occlusion pass culls it: a sphere around every disc centre,
/// the box around them, and the largest disc radius (`vals_occluder_bounds.wgsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OccluderBounds {
    pub center: Vec3,
    pub radius: f32,
    pub max_disc_radius: f32,
    /// Half the size of the centres' box (whose centre is `center`).
    pub half_extent: Vec3,
}

/// The bounds of `discs`: the centre of their centres' box, the farthest centre from it.
pub fn occluder_bounds(discs: &[OccluderDisc]) -> OccluderBounds {
    let (lo, hi) = discs.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), d| (lo.min(d.center), hi.max(d.center)),
    );
    let center = 0.5 * (lo + hi);
    OccluderBounds {
        center,
        radius: discs
            .iter()
            .map(|d| (d.center - center).length())
            .fold(0.0, f32::max),
        max_disc_radius: discs.iter().map(|d| d.radius).fold(0.0, f32::max),
        half_extent: 0.5 * (hi - lo),
    }
}

/// False only when no disc inside `bounds` can take a share of the light sphere seen from
/// (x, n), so the pass may skip the whole tile without changing a bit of the result. Every
/// reason [`occluder_share`] returns 0 is checked for the whole box or sphere of centres: all
/// at or below the horizon (the box's highest corner along n is), all at least as far as the
/// light, or too far sideways — a centre within the
/// sphere is within `asin(R/d)` of the sphere's direction, so its projected square centre
/// within that of the sphere's (projection onto the tangent plane shortens chords), and
/// squares overlap only when their centres are closer than the half sides' sum on both axes.
pub fn tile_may_occlude(
    x: Vec3,
    n: Vec3,
    light: Vec3,
    sphere: f32,
    bounds: &OccluderBounds,
) -> bool {
    let to_light = light - x;
    let light_distance = to_light.length();
    if sphere <= 0.0 || light_distance <= 0.0 || bounds.max_disc_radius <= 0.0 {
        return false;
    }
    let v = bounds.center - x;
    // Every centre of the box at or below the horizon (the box's highest corner along n).
    if n.dot(v) + n.abs().dot(bounds.half_extent) <= 0.0 {
        return false;
    }
    let distance = v.length();
    let r = bounds.radius;
    // x inside (or at the rim of) the sphere: every direction is possible.
    if distance <= r * 1.001 + 1e-6 {
        return true;
    }
    if n.dot(v) + r < 0.0 || distance - r >= light_distance {
        return false;
    }
    let (t, b) = tangent_frame(n);
    let wl = to_light / light_distance;
    let wc = v / distance;
    let alpha = (r / distance).min(1.0).asin();
    let sphere_area = PI * sphere * sphere / (sphere * sphere + light_distance * light_distance);
    let nearest = distance - r;
    let rd = bounds.max_disc_radius;
    let disc_area = PI * rd * rd / (rd * rd + nearest * nearest);
    // The margin absorbs rounding in the shares' own evaluation.
    let reach = 0.5 * sphere_area.sqrt() + 0.5 * disc_area.sqrt() + alpha + 1e-4;
    (wl - wc).dot(t).abs() < reach && (wl - wc).dot(b).abs() < reach
}

/// Children per internal node of the occlusion tree (`FANOUT` in `vals_occluder_bounds.wgsl`
/// and `vals_occlusion.wgsl`).
pub const OCCLUSION_FANOUT: usize = 8;

/// Spreads the low 10 bits of `v` to every third bit: one axis of a 30-bit Morton code.
pub fn morton_spread(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    (x | (x << 2)) & 0x0924_9249
}

/// Where each disc goes in the occlusion pass's walk order (`walk[i]`: disc i's place): the
/// discs sorted by the Morton code of their centres in the cube around them (30 bits), ties
/// by index, so that a tile of consecutive discs is a compact patch across instances too.
pub fn walk_order(centres: &[Vec3]) -> Vec<u32> {
    let (lo, hi) = centres.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), c| (lo.min(*c), hi.max(*c)),
    );
    // One scale for all axes: cells are cubes, so a flat scene's runs are patches, not
    // slices.
    let scale = 1023.0 / (hi - lo).max_element().max(1e-20);
    let code = |c: &Vec3| {
        let q = ((*c - lo) * scale).clamp(Vec3::ZERO, Vec3::splat(1023.0));
        morton_spread(q.x as u32)
            | (morton_spread(q.y as u32) << 1)
            | (morton_spread(q.z as u32) << 2)
    };
    let mut by_code: Vec<(u32, u32)> = centres
        .iter()
        .enumerate()
        .map(|(i, c)| (if c.is_finite() { code(c) } else { u32::MAX }, i as u32))
        .collect();
    by_code.sort_unstable();
    let mut walk = vec![0u32; centres.len()];
    for (place, &(_, i)) in by_code.iter().enumerate() {
        walk[i as usize] = place as u32;
    }
    walk
}

/// `discs` placed in the walk order `walk` ([`walk_order`]: disc i goes to `walk[i]`), as the
/// occlusion pass's first stage writes them.
pub fn in_walk_order(discs: &[OccluderDisc], walk: &[u32]) -> Vec<OccluderDisc> {
    let mut placed = discs.to_vec();
    for (disc, &place) in discs.iter().zip(walk) {
        placed[place as usize] = *disc;
    }
    placed
}

/// Bounds around the bounds `children` (`cs_nodes` in `vals_occluder_bounds.wgsl`): the box
/// around their boxes, a sphere from its centre around their spheres, the largest disc. It
/// holds every disc centre its children hold.
pub fn combine_bounds(children: &[OccluderBounds]) -> OccluderBounds {
    let (lo, hi) = children.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), c| {
            (
                lo.min(c.center - c.half_extent),
                hi.max(c.center + c.half_extent),
            )
        },
    );
    let center = 0.5 * (lo + hi);
    let mut out = OccluderBounds {
        center,
        half_extent: 0.5 * (hi - lo),
        ..Default::default()
    };
    for c in children {
        out.radius = out.radius.max((c.center - center).length() + c.radius);
        out.max_disc_radius = out.max_disc_radius.max(c.max_disc_radius);
    }
    out
}

/// Nodes per level of the occlusion tree over `discs` discs at `tile` a leaf: the tiles, then
/// each level of [`OCCLUSION_FANOUT`]-ary internal nodes up to one root (`level_sizes` in
/// `vals_occlusion.wgsl`).
pub fn occlusion_levels(discs: usize, tile: usize) -> Vec<usize> {
    let mut levels = vec![discs.div_ceil(tile.max(1)).max(1)];
    while *levels.last().expect("one level") > 1 {
        let below = *levels.last().expect("one level");
        levels.push(below.div_ceil(OCCLUSION_FANOUT));
    }
    levels
}

/// The occlusion tree's bounds over `discs` in walk order, level by level: the tiles, then
/// each internal node as [`combine_bounds`] of the tiles under it (`cs_nodes` in
/// `vals_occluder_bounds.wgsl`; the spheres are tighter than around its children's).
pub fn occlusion_tree(discs: &[OccluderDisc], tile: usize) -> Vec<Vec<OccluderBounds>> {
    let tile = tile.max(1);
    let mut tiles: Vec<OccluderBounds> = discs.chunks(tile).map(occluder_bounds).collect();
    if tiles.is_empty() {
        tiles.push(OccluderBounds::default());
    }
    let sizes = occlusion_levels(discs.len(), tile);
    let mut levels = vec![tiles];
    let mut span = 1;
    for _ in 1..sizes.len() {
        span *= OCCLUSION_FANOUT;
        let next = levels[0].chunks(span).map(combine_bounds).collect();
        levels.push(next);
    }
    levels
}

/// Below this visible fraction (2⁻²⁰) a light is closed under `union`: it keeps less than a
/// millionth of its power whatever the remaining discs do (`VISIBLE_CLOSED` in
/// `vals_occlusion.wgsl`).
pub const VISIBLE_CLOSED: f32 = 1.0 / 1_048_576.0;

/// Whether more discs can still change a light's occlusion, given its running `sum` of shares
/// and `visible` product: under `sum` the result is `min(1, Σ)`, final once Σ reaches 1; under
/// `union` it is final to within [`VISIBLE_CLOSED`]. The walk stops there, which is what makes
/// a receiver in a crowd cheap: its nearest discs hide the light and the rest are never read.
pub fn light_still_open(mode: OcclusionMode, sum: f32, visible: f32) -> bool {
    match mode {
        OcclusionMode::Sum => sum < 1.0,
        OcclusionMode::Union => visible >= VISIBLE_CLOSED,
        OcclusionMode::Off | OcclusionMode::Rays => false,
    }
}

/// How the occlusion pass combines and walks the discs: the mode and discs per tile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OcclusionWalk {
    pub mode: OcclusionMode,
    pub tile: usize,
}

/// Occlusion at a receiver from `discs` (in walk order, the receiver's own among them: at
/// distance 0 its share is exactly 0), as the occlusion pass takes them: depth first through
/// `tree` ([`occlusion_tree`]), an opened node's children nearest first ([`child_order`]),
/// each node skipped when [`tile_may_occlude`] says no, else opened; an opened tile's discs
/// one by one in walk order — every disc that may take a share, until the light is closed
/// ([`light_still_open`], tested as each node comes off the stack).
pub fn occlusion(
    receiver: &Receiver,
    light: Vec3,
    sphere: f32,
    discs: &[OccluderDisc],
    tree: &[Vec<OccluderBounds>],
    walk: OcclusionWalk,
) -> f32 {
    occlusion_walk(receiver, light, sphere, discs, tree, walk, |_| {})
}

/// [`occlusion`], showing `visit` each disc whose share it adds, in the order it adds them.
pub fn occlusion_walk(
    receiver: &Receiver,
    light: Vec3,
    sphere: f32,
    discs: &[OccluderDisc],
    tree: &[Vec<OccluderBounds>],
    walk: OcclusionWalk,
    mut visit: impl FnMut(usize),
) -> f32 {
    if matches!(walk.mode, OcclusionMode::Off | OcclusionMode::Rays) || discs.is_empty() {
        return 0.0;
    }
    let mut sum = 0.0f32;
    let mut visible = 1.0f32;
    let mut stack = vec![(tree.len() - 1, 0usize)];
    let (x, n) = (receiver.position, receiver.normal);
    while let Some((level, k)) = stack.pop() {
        if !light_still_open(walk.mode, sum, visible) {
            break;
        }
        let bounds = &tree[level][k];
        if !tile_may_occlude(x, n, light, sphere, bounds) {
            continue;
        }
        if level == 0 {
            let first = k * walk.tile;
            let last = (first + walk.tile).min(discs.len());
            for (j, disc) in discs.iter().enumerate().take(last).skip(first) {
                let o = occluder_share(x, n, light, sphere, disc);
                sum += o;
                visible *= 1.0 - o;
                visit(j);
            }
        } else {
            let children =
                k * OCCLUSION_FANOUT..((k + 1) * OCCLUSION_FANOUT).min(tree[level - 1].len());
            let nearest_first = child_order(x, &tree[level - 1], children);
            stack.extend(nearest_first.into_iter().rev().map(|c| (level - 1, c)));
        }
    }
    match walk.mode {
        OcclusionMode::Sum => sum.min(1.0),
        OcclusionMode::Union => 1.0 - visible,
        OcclusionMode::Off | OcclusionMode::Rays => 0.0,
    }
}

/// The nodes `children` of one level, nearest to x first: by the distance from x to each
/// node's sphere (negative inside it), ties by index (`order_swap` in `vals_occlusion.wgsl`
/// sorts the same keys with a sorting network). Near discs hide the most of a light, so a
/// light in a crowd closes ([`light_still_open`]) after a few nodes.
pub fn child_order(
    x: Vec3,
    nodes: &[OccluderBounds],
    children: std::ops::Range<usize>,
) -> Vec<usize> {
    let key = |c: usize| (nodes[c].center - x).length() - nodes[c].radius;
    let mut order: Vec<usize> = children.collect();
    order.sort_by(|&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
    order
}

/// Step 3 — a vertex's lights from its linked points with normalized weights.
///
/// Then the diffuse intensity is capped so that the blended light gives the vertex (world
/// position `vertex`, normal `normal`) at most [`BLEND_GAIN_MAX`] times the irradiance its
/// links' lights give it on average:
/// `I_v ← min(I_v, G·Σ w_j I_j f_d(v, l_j) / (W f_d(v, l_v)))` per channel. Blending the
/// positions of lights that lie in different directions from the vertex (links on both sides
/// of a bunny's ear) puts the blended light near its surface, where `f_d` grows as 1/d²: the
/// ears' vertices came out 5–50× too bright. With G = 1 the cap also took 7 % off
/// `bunny-box`'s mean (each link's light seen from the vertex's own normal loses some
/// cosine on a curved surface); G = 2 removes the outliers and leaves the rest as the paper
/// has it. It never brightens: a light the blend puts at a grazing angle stays as dim as
/// the paper's. The glossy light is left as blended: its factor depends on the view.
pub fn interpolate(
    vertex: Vec3,
    normal: Vec3,
    links: &[(usize, f32)],
    points: &[PointLights],
) -> PointLights {
    let total: f32 = links.iter().map(|(_, w)| w).sum();
    if total < WEIGHT_EPSILON {
        return PointLights::default();
    }
    let mut out = PointLights::default();
    let mut irradiance = Vec3::ZERO;
    for &(j, w) in links {
        let p = &points[j];
        out.diffuse_position += w * p.diffuse_position;
        out.diffuse += w * p.diffuse;
        out.glossy_position += w * p.glossy_position;
        out.glossy += w * p.glossy;
        irradiance += w * p.diffuse * diffuse_point_factor(vertex, normal, p.diffuse_position);
    }
    out.diffuse_position /= total;
    out.diffuse /= total;
    out.glossy_position /= total;
    out.glossy /= total;
    let f = diffuse_point_factor(vertex, normal, out.diffuse_position);
    if f > 0.0 {
        out.diffuse = out.diffuse.min(BLEND_GAIN_MAX * irradiance / (total * f));
    }
    out
}

/// Interpolation weights for one vertex (paper eq. 12): `(1 − d_j/d_max)·clamp(n_v·n_j, 0, 1)`.
pub fn link_weights(vertex: Vec3, vertex_normal: Vec3, points: &[(Vec3, Vec3)]) -> Vec<f32> {
    let distances: Vec<f32> = points.iter().map(|(p, _)| (*p - vertex).length()).collect();
    let d_max = distances.iter().cloned().fold(0.0f32, f32::max);
    points
        .iter()
        .zip(&distances)
        .map(|((_, n), d)| {
            let falloff = if d_max > 0.0 { 1.0 - d / d_max } else { 1.0 };
            falloff * vertex_normal.dot(*n).clamp(0.0, 1.0)
        })
        .collect()
}

/// Step 4 — outgoing indirect radiance at a pixel from the two interpolated point lights.
#[allow(clippy::too_many_arguments)]
pub fn apply(
    p: Vec3,
    n: Vec3,
    wo: Vec3,
    rho_d: Vec3,
    rho_s: Vec3,
    k: f32,
    lights: &PointLights,
) -> Vec3 {
    let r = mirror(wo, n);
    rho_d / PI * diffuse_point(p, n, lights.diffuse_position, lights.diffuse)
        + rho_s
            * ((k + 2.0) / (2.0 * PI))
            * glossy_point(p, n, r, k, lights.glossy_position, lights.glossy)
}

/// The brute-force baseline at one pixel: every VAL through the full BRDF, no interpolation,
/// no occlusion.
#[allow(clippy::too_many_arguments)]
pub fn brute_force(
    p: Vec3,
    n: Vec3,
    wo: Vec3,
    rho_d: Vec3,
    rho_s: Vec3,
    k: f32,
    vals: &[Val],
    glossy: bool,
) -> Vec3 {
    let r = mirror(wo, n);
    let mut out = Vec3::ZERO;
    for val in vals {
        let (g, w) = disc_geometry(p, n, val);
        if g <= 0.0 {
            continue;
        }
        let e = val.flux * (g / PI);
        let mut f = rho_d / PI;
        if glossy {
            f += rho_s * ((k + 2.0) / (2.0 * PI)) * lobe(r, w, k);
        }
        out += f * e;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
        /// Culling a tile never drops a disc that takes a share: when `tile_may_occlude` says
        /// no, every disc in the tile gives exactly 0.
        #[test]
        fn a_culled_tile_holds_no_disc_with_a_share(
            x in proptest::array::uniform3(-1.0f32..1.0),
            n in proptest::array::uniform3(-1.0f32..1.0),
            light in proptest::array::uniform3(-3.0f32..3.0),
            sphere in 0.01f32..1.0,
            centre in proptest::array::uniform3(-3.0f32..3.0),
            spread in 0.01f32..1.0,
            discs in proptest::collection::vec(
                (proptest::array::uniform3(-1.0f32..1.0), proptest::array::uniform3(-1.0f32..1.0), 0.005f32..0.3),
                1..40,
            ),
        ) {
            let n = Vec3::from(n);
            proptest::prop_assume!(n.length() > 0.1);
            let n = n.normalize();
            let discs: Vec<OccluderDisc> = discs
                .iter()
                .filter(|(_, normal, _)| Vec3::from(*normal).length() > 0.1)
                .map(|&(offset, normal, radius)| OccluderDisc {
                    center: Vec3::from(centre) + Vec3::from(offset) * spread,
                    normal: Vec3::from(normal).normalize(),
                    radius,
                })
                .collect();
            proptest::prop_assume!(!discs.is_empty());
            let bounds = occluder_bounds(&discs);
            if !tile_may_occlude(Vec3::from(x), n, Vec3::from(light), sphere, &bounds) {
                for d in &discs {
                    let share = occluder_share(Vec3::from(x), n, Vec3::from(light), sphere, d);
                    proptest::prop_assert_eq!(share, 0.0, "{:?}", d);
                }
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// The tree only skips what takes no share: until the light closes, every disc the
        /// walk leaves out has a share of exactly 0, none is taken twice, and the result is
        /// the visited shares combined, for tiles of 1 to 9 discs.
        #[test]
        fn the_tree_walk_skips_only_discs_without_a_share(
            x in proptest::array::uniform3(-1.0f32..1.0),
            n in proptest::array::uniform3(-1.0f32..1.0),
            light in proptest::array::uniform3(-3.0f32..3.0),
            sphere in 0.05f32..1.5,
            tile in 1usize..10,
            discs in proptest::collection::vec(
                (proptest::array::uniform3(-3.0f32..3.0), proptest::array::uniform3(-1.0f32..1.0), 0.01f32..0.4),
                1..120,
            ),
        ) {
            let n = Vec3::from(n).try_normalize().unwrap_or(Vec3::Y);
            let discs: Vec<OccluderDisc> = discs
                .iter()
                .map(|&(c, normal, radius)| OccluderDisc {
                    center: Vec3::from(c),
                    normal: Vec3::from(normal).try_normalize().unwrap_or(Vec3::X),
                    radius,
                })
                .collect();
            let walk = walk_order(&discs.iter().map(|d| d.center).collect::<Vec<_>>());
            let ordered = in_walk_order(&discs, &walk);
            let receiver = Receiver { position: Vec3::from(x), normal: n, k: 1.0 };
            let tree = occlusion_tree(&ordered, tile);
            for mode in [OcclusionMode::Sum, OcclusionMode::Union] {
                let mut visited = vec![];
                let walk = OcclusionWalk { mode, tile };
                let got = occlusion_walk(&receiver, Vec3::from(light), sphere, &ordered, &tree, walk, |j| visited.push(j));
                // The result is the visited discs' shares, combined in the order visited.
                let share = |j: usize| occluder_share(receiver.position, n, Vec3::from(light), sphere, &ordered[j]);
                let (sum, visible) = visited.iter().fold((0.0f32, 1.0f32), |(s, v), &j| (s + share(j), v * (1.0 - share(j))));
                let want = if mode == OcclusionMode::Sum { sum.min(1.0) } else { 1.0 - visible };
                proptest::prop_assert_eq!(got, want);
                // Each disc at most once.
                let mut once = visited.clone();
                once.sort_unstable();
                once.dedup();
                proptest::prop_assert_eq!(once.len(), visited.len());
                // Until the light closes, only discs without a share are left out: the tree
                // skips nothing that counts.
                if light_still_open(mode, sum, visible) {
                    for j in (0..ordered.len()).filter(|j| once.binary_search(j).is_err()) {
                        proptest::prop_assert_eq!(share(j), 0.0, "disc {} skipped", j);
                    }
                }
            }
        }
    }

    #[test]
    fn a_light_behind_a_crowd_closes_after_its_nearest_discs() {
        // Five layers of 20 × 20 discs between a receiver and its light, the nearest layer
        // last in walk order (the Morton code grows with z): nearest first, `sum` ends after
        // a few dozen discs of the two nearest layers.
        let mut discs = vec![];
        for layer in 1..=5 {
            for i in 0..20 {
                for j in 0..20 {
                    discs.push(OccluderDisc {
                        center: Vec3::new(
                            0.1 * (i as f32 - 9.5),
                            0.1 * (j as f32 - 9.5),
                            layer as f32,
                        ),
                        normal: Vec3::Z,
                        radius: 0.06,
                    });
                }
            }
        }
        let walk = walk_order(&discs.iter().map(|d| d.center).collect::<Vec<_>>());
        let ordered = in_walk_order(&discs, &walk);
        let tree = occlusion_tree(&ordered, 8);
        let receiver = Receiver {
            position: Vec3::new(0.0, 0.0, 6.0),
            normal: -Vec3::Z,
            k: 1.0,
        };
        let light = Vec3::new(0.0, 0.0, -4.0);
        let every = |mode| {
            let mut visited = vec![];
            let walk = OcclusionWalk { mode, tile: 8 };
            let o = occlusion_walk(&receiver, light, 1.0, &ordered, &tree, walk, |j| {
                visited.push(j)
            });
            (o, visited)
        };
        let (sum, visited) = every(OcclusionMode::Sum);
        assert_eq!(sum, 1.0);
        assert!(
            visited.len() <= discs.len() / 10,
            "sum read {} discs",
            visited.len()
        );
        assert!(visited.iter().all(|&j| ordered[j].center.z >= 4.0));
        // `union` does not close here (the light stays 0.3 % visible): it reads every disc in
        // the light's path, and the far layers' too.
        let (union, visited) = every(OcclusionMode::Union);
        assert!(union > 0.99 && 1.0 - union > VISIBLE_CLOSED, "{union}");
        assert!(visited.iter().any(|&j| ordered[j].center.z == 1.0));
    }

    #[test]
    fn the_occlusion_pass_sorts_children_with_a_sorting_network() {
        // The comparators `vals_occlusion.wgsl` applies, in order: by the 0-1 principle they
        // sort every input if they sort every 0/1 input.
        let source = crate::shaders::source("vals_occlusion.wgsl");
        let comparators: Vec<(usize, usize)> = source
            .lines()
            .filter_map(|line| {
                let args = line.trim().strip_prefix("order_swap(&order, ")?;
                let (a, b) = args.strip_suffix("u);")?.split_once("u, ")?;
                Some((a.parse().ok()?, b.parse().ok()?))
            })
            .collect();
        assert_eq!(comparators.len(), 19, "{comparators:?}");
        for bits in 0u32..256 {
            let mut keys: Vec<u32> = (0..8).map(|i| (bits >> i) & 1).collect();
            for &(a, b) in &comparators {
                if keys[a] > keys[b] {
                    keys.swap(a, b);
                }
            }
            assert!(
                keys.windows(2).all(|w| w[0] <= w[1]),
                "{bits:08b} → {keys:?}"
            );
        }
    }

    #[test]
    fn walk_order_is_a_permutation_that_keeps_neighbours_together() {
        // Two clusters listed alternately: the walk puts each cluster's discs together.
        let centres: Vec<Vec3> = (0..20)
            .map(|i| {
                let side = if i % 2 == 0 { -5.0 } else { 5.0 };
                Vec3::new(side + 0.01 * i as f32, 0.0, 0.0)
            })
            .collect();
        let walk = walk_order(&centres);
        let mut seen = walk.clone();
        seen.sort();
        assert_eq!(seen, (0..20).collect::<Vec<u32>>());
        for (i, &w) in walk.iter().enumerate() {
            assert_eq!(w < 10, i % 2 == 0, "disc {i} at {w}");
        }
    }

    #[test]
    fn combined_bounds_hold_their_childrens_discs() {
        let disc = |c: Vec3, n: Vec3, r: f32| OccluderDisc {
            center: c,
            normal: n,
            radius: r,
        };
        let a = [disc(Vec3::ZERO, Vec3::Y, 0.1), disc(Vec3::X, Vec3::Z, 0.2)];
        let b = [disc(Vec3::new(4.0, 1.0, -2.0), Vec3::NEG_X, 0.3)];
        let all: Vec<_> = a.iter().chain(&b).copied().collect();
        let combined = combine_bounds(&[occluder_bounds(&a), occluder_bounds(&b)]);
        for d in &all {
            assert!((d.center - combined.center).length() <= combined.radius + 1e-6);
            assert!(
                ((d.center - combined.center).abs() - combined.half_extent).max_element() <= 1e-6
            );
        }
        assert_eq!(combined.max_disc_radius, 0.3);
        assert_eq!(occlusion_levels(1000, 64), vec![16, 2, 1]);
        assert_eq!(occlusion_levels(5, 64), vec![1]);
    }

    #[test]
    fn culling_skips_tiles_far_from_the_light_path() {
        let discs = [OccluderDisc {
            center: Vec3::new(5.0, 1.0, 0.0),
            normal: Vec3::Y,
            radius: 0.1,
        }];
        let bounds = occluder_bounds(&discs);
        // Receiver at the origin facing up, light straight above: the tile is far to the side.
        assert!(!tile_may_occlude(
            Vec3::ZERO,
            Vec3::Y,
            Vec3::new(0.0, 3.0, 0.0),
            0.2,
            &bounds
        ));
        // The same tile between the receiver and a light behind it is kept.
        assert!(tile_may_occlude(
            Vec3::ZERO,
            Vec3::Y,
            Vec3::new(10.0, 2.0, 0.0),
            0.2,
            &bounds
        ));
    }

    #[test]
    fn disc_irradiance_on_axis_matches_the_exact_disc() {
        // A Lambertian disc of radius r and flux Φ, facing a receiver on its axis at distance
        // h: the exact irradiance is Φ/(π r²)·π·r²/(h² + r²) = Φ/(π(h²+r²)) — which is exactly
        // the VAL law on the axis (both cosines 1).
        for (h, r) in [(0.1f32, 0.05f32), (1.0, 0.3), (0.01, 0.2), (5.0, 0.01)] {
            let val = Val {
                position: Vec3::new(0.0, h, 0.0),
                normal: Vec3::NEG_Y,
                flux: Vec3::splat(2.0),
                area: PI * r * r,
            };
            let e = disc_irradiance(Vec3::ZERO, Vec3::Y, &val);
            let exact = 2.0 / (PI * (h * h + r * r));
            assert!(
                (e.x - exact).abs() <= 1e-5 * exact,
                "h {h} r {r}: {} vs {exact}",
                e.x
            );
        }
    }

    #[test]
    fn a_blend_of_lights_on_both_sides_gives_the_vertex_at_most_twice_their_mean() {
        // Two links' lights 1 m to either side, 0.2 m up: their blend sits 0.2 m above the
        // vertex and would give it 25/0.19 = 133× their mean irradiance.
        let light = |x: f32| PointLights {
            diffuse_position: Vec3::new(x, 0.0, 0.2),
            diffuse: Vec3::ONE,
            ..Default::default()
        };
        let points = [light(1.0), light(-1.0)];
        let links = [(0, 0.5), (1, 0.5)];
        let (v, n) = (Vec3::ZERO, Vec3::Z);
        let mean = diffuse_point_factor(v, n, points[0].diffuse_position);
        let out = interpolate(v, n, &links, &points);
        assert_eq!(out.diffuse_position, Vec3::new(0.0, 0.0, 0.2));
        let given = out.diffuse * diffuse_point_factor(v, n, out.diffuse_position);
        assert!(
            (given / (BLEND_GAIN_MAX * mean) - Vec3::ONE)
                .abs()
                .max_element()
                < 1e-5
        );
        // Lights in one direction blend where they are: nothing to cap.
        let points = [
            light(1.0),
            PointLights {
                diffuse: Vec3::splat(3.0),
                ..light(1.2)
            },
        ];
        let out = interpolate(v, n, &links, &points);
        assert_eq!(out.diffuse, Vec3::splat(2.0));
    }

    #[test]
    fn renormalized_lights_reproduce_the_sums_at_the_point() {
        let receiver = Receiver {
            position: Vec3::new(0.1, 0.0, -0.2),
            normal: Vec3::new(0.1, 1.0, 0.05).normalize(),
            k: 10.0,
        };
        // The eye's mirror direction points up into the VAL cluster, so the lobe sees it.
        let eye = Vec3::new(0.2, 1.0, -0.4);
        let vals: Vec<Val> = (0..50)
            .map(|i| {
                let t = i as f32 * 0.37;
                Val {
                    position: Vec3::new(t.sin() * 0.6, 0.8 + 0.1 * t.cos(), (t * 1.7).cos() * 0.5),
                    normal: Vec3::new(0.05 * t.cos(), -1.0, 0.1).normalize(),
                    flux: Vec3::new(0.01, 0.02, 0.005) * (1.0 + (i % 3) as f32),
                    area: 1e-3,
                }
            })
            .collect();
        let g = gather(&receiver, eye, &vals, Weights::Geometric, true);
        let (lights, clamped) = renormalize(&receiver, eye, &g);
        assert_eq!(clamped, [false, false]);
        let x = receiver.position;
        let n = receiver.normal;
        let r = mirror((eye - x).normalize(), n);
        let d = diffuse_point(x, n, lights.diffuse_position, lights.diffuse);
        let s = glossy_point(x, n, r, receiver.k, lights.glossy_position, lights.glossy);
        assert!((d - g.diffuse).abs().max_element() <= 1e-4 * g.diffuse.max_element());
        assert!((s - g.glossy).abs().max_element() <= 1e-4 * g.glossy.max_element());
        assert!(g.glossy.max_element() > 0.0);
    }

    #[test]
    fn union_never_occludes_more_than_sum() {
        let receiver = Receiver {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            k: 1.0,
        };
        let light = Vec3::new(0.0, 2.0, 0.0);
        let discs: Vec<OccluderDisc> = (0..6)
            .map(|i| OccluderDisc {
                center: Vec3::new(0.05 * i as f32, 0.5 + 0.2 * i as f32, 0.0),
                normal: Vec3::Y,
                radius: 0.2,
            })
            .collect();
        let tree = occlusion_tree(&discs, 64);
        let sum = occlusion(
            &receiver,
            light,
            0.5,
            &discs,
            &tree,
            OcclusionWalk {
                mode: OcclusionMode::Sum,
                tile: 64,
            },
        );
        let union = occlusion(
            &receiver,
            light,
            0.5,
            &discs,
            &tree,
            OcclusionWalk {
                mode: OcclusionMode::Union,
                tile: 64,
            },
        );
        assert!(sum > 0.0 && union > 0.0);
        assert!(union <= sum + 1e-6, "union {union} sum {sum}");
        // A disc behind the light's centre hides nothing.
        let behind = OccluderDisc {
            center: Vec3::new(0.0, 2.5, 0.0),
            normal: Vec3::Y,
            radius: 1.0,
        };
        assert_eq!(
            occluder_share(Vec3::ZERO, Vec3::Y, light, 0.5, &behind),
            0.0
        );
    }

    #[test]
    fn tangent_frame_is_orthonormal() {
        for n in [
            Vec3::Y,
            Vec3::Z,
            Vec3::NEG_Z,
            Vec3::new(0.3, -0.4, 0.8).normalize(),
        ] {
            let (t, b) = tangent_frame(n);
            assert!((t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5);
            assert!(t.dot(b).abs() < 1e-5 && t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5);
        }
    }
}
