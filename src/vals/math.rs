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
pub fn disc_geometry(x: Vec3, n: Vec3, val: &Val) -> (f32, Vec3) {
    let d = val.position - x;
    let dist2 = d.length_squared();
    if dist2 <= 0.0 {
        return (0.0, Vec3::ZERO);
    }
    let w = d / dist2.sqrt();
    let g = n.dot(w).max(0.0) * (-val.normal.dot(w)).max(0.0) / (dist2 + val.radius_squared());
    (g, w)
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

/// A tile of occluder discs as the occlusion pass culls it: a sphere around every disc
/// centre and the largest disc radius (`write_bounds` in `vals_occluder_bounds.wgsl`), and
/// the discs' area moments, from which [`far_share`] takes a far tile whole.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OccluderBounds {
    pub center: Vec3,
    pub radius: f32,
    pub max_disc_radius: f32,
    /// Half the size of the centres' box (whose centre is `center`).
    pub half_extent: Vec3,
    /// Σ πρ² over the discs.
    pub area: f32,
    pub count: u32,
    /// Σ πρ²·|n| per axis.
    pub axes: Vec3,
    /// Σ πρ²·n nᵀ: (xx, yy, zz), then (xy, xz, yz).
    pub tensor_diagonal: Vec3,
    pub tensor_off: Vec3,
}

impl OccluderBounds {
    /// Σ πρ²·|n·w| over the discs, from above: the smaller of Cauchy–Schwarz's
    /// √(Σπρ² · wᵀ(Σπρ² n nᵀ)w), exact when every |n·w| is equal (a flat patch), and the
    /// triangle inequality's Σ_k (Σπρ²|n_k|)·|w_k|, exact when every normal is on an axis (a
    /// box, a room).
    pub fn projected_area(&self, w: Vec3) -> f32 {
        let d = self.tensor_diagonal;
        let o = self.tensor_off;
        let quadratic = d.x * w.x * w.x
            + d.y * w.y * w.y
            + d.z * w.z * w.z
            + 2.0 * (o.x * w.x * w.y + o.y * w.x * w.z + o.z * w.y * w.z);
        let cauchy_schwarz = (self.area * quadratic.max(0.0)).sqrt();
        let axes = self.axes.dot(w.abs());
        cauchy_schwarz.min(axes)
    }
}

/// The bounds of `discs`: the centre of their centres' box, the farthest centre from it, and
/// their area moments.
pub fn occluder_bounds(discs: &[OccluderDisc]) -> OccluderBounds {
    let (lo, hi) = discs.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), d| (lo.min(d.center), hi.max(d.center)),
    );
    let center = 0.5 * (lo + hi);
    let mut bounds = OccluderBounds {
        center,
        radius: discs
            .iter()
            .map(|d| (d.center - center).length())
            .fold(0.0, f32::max),
        max_disc_radius: discs.iter().map(|d| d.radius).fold(0.0, f32::max),
        half_extent: 0.5 * (hi - lo),
        count: discs.len() as u32,
        ..Default::default()
    };
    for d in discs {
        let a = PI * d.radius * d.radius;
        let n = d.normal;
        bounds.area += a;
        bounds.axes += a * n.abs();
        bounds.tensor_diagonal += a * n * n;
        bounds.tensor_off += a * Vec3::new(n.x * n.y, n.x * n.z, n.y * n.z);
    }
    bounds
}

/// The summed shares of a whole tile of discs seen from (x, n) when it is far
/// (`far_share` in `vals_occlusion.wgsl`); `None` when it is not, and its discs must be taken
/// one by one.
///
/// Far: the tile's radius plus its largest disc's is at most `far` times its distance d, every
/// centre nearer than the light and above the horizon. Seen from x, the discs then lie in a
/// square around the tile's direction ŵ of half side asin(r/d) (each centre's direction is
/// within that angle, and projection onto the tangent plane shortens chords) plus the largest
/// disc's half side; the tile is taken as that square, grey with the discs' summed projected
/// area A = Σ πρ_j²|n_j·ŵ|/(d² + ρ̄²) ([`OccluderBounds::projected_area`], ρ̄² the mean ρ²)
/// spread evenly over it. Its share is A/S × (overlap of the light's square with it)/(its
/// area) × the centre's ramp: A/S when it lies wholly inside the light's square, as the discs
/// one by one give (each overlap then being the disc's whole area), and the evenly spread
/// expectation where it straddles the square's edge. The error is first order in r/d across
/// the tile and cancels to second order for a tile symmetric about its centre.
pub fn far_share(
    x: Vec3,
    n: Vec3,
    light: Vec3,
    sphere: f32,
    bounds: &OccluderBounds,
    far: f32,
) -> Option<f32> {
    let to_light = light - x;
    let light_distance = to_light.length();
    let v = bounds.center - x;
    let distance = v.length();
    let r = bounds.radius;
    if far <= 0.0
        || sphere <= 0.0
        || light_distance <= 0.0
        || bounds.count == 0
        || r + bounds.max_disc_radius > far * distance
        || distance + r >= light_distance
        || n.dot(v) <= r
    {
        return None;
    }
    let (t, b) = tangent_frame(n);
    let wl = to_light / light_distance;
    let wc = v / distance;
    let alpha = (r / distance).min(1.0).asin();
    let sphere_area = PI * sphere * sphere / (sphere * sphere + light_distance * light_distance);
    let rd = bounds.max_disc_radius;
    let nearest = distance - r;
    let disc_half = 0.5 * (PI * rd * rd / (rd * rd + nearest * nearest)).sqrt();
    let tile_side = 2.0 * (alpha + disc_half);
    let tile_area = tile_side * tile_side;
    let overlap = square_overlap(
        (wl.dot(t), wl.dot(b)),
        sphere_area,
        (wc.dot(t), wc.dot(b)),
        tile_area,
    );
    let mean_radius2 = bounds.area / (PI * bounds.count as f32);
    let area = bounds.projected_area(wc) / (distance * distance + mean_radius2);
    let ramp = ((light_distance - distance) / sphere).min(1.0);
    Some(area / sphere_area * (overlap / tile_area) * ramp)
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

/// One receiver of a workgroup as [`group_ball`] sees it: its position and how far its
/// farthest light with a sphere is (`None`: no light can be occluded).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroupReceiver {
    pub x: Vec3,
    pub reach: Option<f32>,
}

/// The occlusion workgroup's reach (`group_ball` in `vals_occlusion.wgsl`): a ball around its
/// receivers (the centre of their box, the farthest from it) grown by the longest distance
/// from a receiver to its own light; `None` when no receiver has a light with a sphere.
pub fn group_ball(receivers: &[GroupReceiver]) -> Option<(Vec3, f32)> {
    let lit = || receivers.iter().filter(|r| r.reach.is_some());
    let (lo, hi) = lit().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), r| (lo.min(r.x), hi.max(r.x)),
    );
    let reach = lit().filter_map(|r| r.reach).reduce(f32::max)?;
    let center = 0.5 * (lo + hi);
    let radius = lit().map(|r| (r.x - center).length()).fold(0.0, f32::max);
    Some((center, radius + reach))
}

/// Whether a super-tile within `bounds` may hold a disc that takes a share of some receiver
/// of the group whose [`group_ball`] is `ball` (`ball_may_reach` in `vals_occlusion.wgsl`).
/// Conservative against [`tile_may_occlude`]: that test is true only for a receiver x with a
/// light at distance L when |c − x| < L + 1.001·r + 10⁻⁶, and |c − x| ≥ |c − g| − R_g, so a
/// centre farther than R_g + L_max + 1.001·r (with slack for rounding) from the group's centre
/// g fails it for every receiver, and the pass may skip the super-tile for the whole group.
pub fn ball_may_reach(ball: Option<(Vec3, f32)>, bounds: &OccluderBounds) -> bool {
    let Some((center, reach)) = ball else {
        return false;
    };
    let limit = (reach + 1.001 * bounds.radius) * 1.0001 + 1e-5;
    (bounds.center - center).length() <= limit
}

/// How the occlusion pass combines and walks the discs: the mode, discs per tile, and the
/// far-tile fraction (`occlusion-far`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OcclusionWalk {
    pub mode: OcclusionMode,
    pub tile: usize,
    pub far: f32,
}

/// Occlusion at receiver `index` from every other disc, as the occlusion pass takes them:
/// super-tiles of [`crate::vals::sparse::OCCLUSION_SUPER_TILE`] tiles of `tile` discs, each
/// skipped when [`tile_may_occlude`] says no, taken whole when [`far_share`] (with `far`)
/// says yes, else opened; an opened tile's discs one by one in order. With `far` = 0 that is
/// every disc in order. A whole tile's k discs of summed share s count as k discs of s/k
/// each in `union`.
pub fn occlusion(
    index: usize,
    receiver: &Receiver,
    light: Vec3,
    sphere: f32,
    discs: &[OccluderDisc],
    walk: OcclusionWalk,
) -> f32 {
    let OcclusionWalk { mode, tile, far } = walk;
    if matches!(mode, OcclusionMode::Off | OcclusionMode::Rays) {
        return 0.0;
    }
    let (x, n) = (receiver.position, receiver.normal);
    let tile = tile.clamp(1, crate::vals::sparse::OCCLUSION_TILE_MAX as usize);
    let span = tile * crate::vals::sparse::OCCLUSION_SUPER_TILE as usize;
    let mut sum = 0.0f32;
    let mut visible = 1.0f32;
    let whole = |share: f32, count: u32, sum: &mut f32, visible: &mut f32| {
        *sum += share;
        *visible *= (1.0 - share / count.max(1) as f32)
            .max(0.0)
            .powi(count as i32);
    };
    for (s, super_discs) in discs.chunks(span).enumerate() {
        let bounds = occluder_bounds(super_discs);
        if !tile_may_occlude(x, n, light, sphere, &bounds) {
            continue;
        }
        if let Some(share) = far_share(x, n, light, sphere, &bounds, far) {
            whole(share, bounds.count, &mut sum, &mut visible);
            continue;
        }
        for (t, tile_discs) in super_discs.chunks(tile).enumerate() {
            let bounds = occluder_bounds(tile_discs);
            if !tile_may_occlude(x, n, light, sphere, &bounds) {
                continue;
            }
            if let Some(share) = far_share(x, n, light, sphere, &bounds, far) {
                whole(share, bounds.count, &mut sum, &mut visible);
                continue;
            }
            for (j, disc) in tile_discs.iter().enumerate() {
                if s * span + t * tile + j == index {
                    continue;
                }
                let o = occluder_share(x, n, light, sphere, disc);
                sum += o;
                visible *= 1.0 - o;
            }
        }
    }
    match mode {
        OcclusionMode::Sum => sum.min(1.0),
        OcclusionMode::Union => 1.0 - visible,
        OcclusionMode::Off | OcclusionMode::Rays => 0.0,
    }
}

/// Step 3 — a vertex's lights from its linked points with normalized weights.
pub fn interpolate(links: &[(usize, f32)], points: &[PointLights]) -> PointLights {
    let total: f32 = links.iter().map(|(_, w)| w).sum();
    if total < WEIGHT_EPSILON {
        return PointLights::default();
    }
    let mut out = PointLights::default();
    for &(j, w) in links {
        let p = &points[j];
        out.diffuse_position += w * p.diffuse_position;
        out.diffuse += w * p.diffuse;
        out.glossy_position += w * p.glossy_position;
        out.glossy += w * p.glossy;
    }
    out.diffuse_position /= total;
    out.diffuse /= total;
    out.glossy_position /= total;
    out.glossy /= total;
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
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(256))]
        /// The workgroup's test is conservative: when `ball_may_reach` skips a super-tile,
        /// `tile_may_occlude` skips it for every receiver of the group and each of its lights.
        #[test]
        fn a_super_tile_the_group_skips_is_skipped_by_every_receiver(
            receivers in proptest::collection::vec(
                (
                    proptest::array::uniform3(-2.0f32..2.0),
                    proptest::array::uniform3(-1.0f32..1.0),
                    proptest::array::uniform3(-4.0f32..4.0),
                    0.0f32..1.0,
                ),
                1..64,
            ),
            centre in proptest::array::uniform3(-8.0f32..8.0),
            radius in 0.0f32..2.0,
            max_disc_radius in 0.001f32..0.3,
        ) {
            let bounds = OccluderBounds { center: Vec3::from(centre), radius, max_disc_radius, ..Default::default() };
            let lit: Vec<_> = receivers
                .iter()
                .map(|&(x, n, light, sphere)| {
                    let (x, light) = (Vec3::from(x), Vec3::from(light));
                    let n = Vec3::from(n).try_normalize().unwrap_or(Vec3::Y);
                    (x, n, light, sphere)
                })
                .collect();
            let group: Vec<GroupReceiver> = lit
                .iter()
                .map(|&(x, _, light, sphere)| GroupReceiver {
                    x,
                    reach: (sphere > 0.0).then(|| (light - x).length()),
                })
                .collect();
            if !ball_may_reach(group_ball(&group), &bounds) {
                for &(x, n, light, sphere) in &lit {
                    proptest::prop_assert!(!tile_may_occlude(x, n, light, sphere, &bounds));
                }
            }
        }
    }

    #[test]
    fn the_group_skips_super_tiles_beyond_its_lights() {
        let receiver = |x: f32, reach: Option<f32>| GroupReceiver {
            x: Vec3::new(x, 0.0, 0.0),
            reach,
        };
        let ball = group_ball(&[
            receiver(-1.0, Some(2.0)),
            receiver(1.0, Some(3.0)),
            receiver(9.0, None),
        ]);
        assert_eq!(ball, Some((Vec3::ZERO, 4.0)));
        let at = |x: f32| OccluderBounds {
            center: Vec3::new(x, 0.0, 0.0),
            radius: 1.0,
            max_disc_radius: 0.1,
            ..Default::default()
        };
        assert!(ball_may_reach(ball, &at(4.9)));
        assert!(!ball_may_reach(ball, &at(5.1)));
        assert!(!ball_may_reach(
            group_ball(&[receiver(0.0, None)]),
            &at(0.0)
        ));
    }

    /// A box of 6 faces × 4 discs and a flat patch: the area moments give Σπρ²|n·w| exactly
    /// (axis normals, equal normals) and from above otherwise.
    #[test]
    fn area_moments_give_the_projected_area() {
        let disc = |normal: Vec3, radius: f32| OccluderDisc {
            center: Vec3::ZERO,
            normal,
            radius,
        };
        let exact = |discs: &[OccluderDisc], w: Vec3| -> f32 {
            discs
                .iter()
                .map(|d| PI * d.radius * d.radius * d.normal.dot(w).abs())
                .sum()
        };
        let faces = [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ];
        let cube: Vec<_> = faces
            .iter()
            .flat_map(|&n| std::iter::repeat_n(disc(n, 0.1), 4))
            .collect();
        let tilted = Vec3::new(0.3, 0.8, -0.5).normalize();
        let patch: Vec<_> = (1..6).map(|i| disc(tilted, 0.02 * i as f32)).collect();
        let mixed: Vec<_> = (0..12)
            .map(|i| {
                let a = i as f32 * 0.7;
                disc(Vec3::new(a.cos(), 0.5, a.sin()).normalize(), 0.05)
            })
            .collect();
        for w in [Vec3::Y, Vec3::new(1.0, 2.0, -0.5).normalize(), tilted] {
            let c = exact(&cube, w);
            assert!((occluder_bounds(&cube).projected_area(w) - c).abs() < 1e-5 * c.max(1.0));
            let p = exact(&patch, w);
            assert!((occluder_bounds(&patch).projected_area(w) - p).abs() < 1e-4 * p.max(1e-3));
            let m = exact(&mixed, w);
            let bound = occluder_bounds(&mixed).projected_area(w);
            assert!(
                bound >= m * (1.0 - 1e-5) && bound <= 1.5 * m,
                "{bound} vs {m}"
            );
        }
    }

    /// A far tile inside a large light counts whole within a few per cent of its discs one by
    /// one; near, straddling the light's edge or behind the light it is not taken whole.
    #[test]
    fn a_far_tile_counts_whole_close_to_its_discs() {
        let x = Vec3::ZERO;
        let n = Vec3::Y;
        let light = Vec3::new(0.0, 20.0, 0.0);
        let sphere = 10.0;
        // A 5×5 grid of discs 0.1 m apart, facing down, 6 m above the receiver.
        let grid = |centre: Vec3| -> Vec<OccluderDisc> {
            (0..25)
                .map(|i| OccluderDisc {
                    center: centre
                        + Vec3::new((i % 5) as f32 * 0.1 - 0.2, 0.0, (i / 5) as f32 * 0.1 - 0.2),
                    normal: Vec3::NEG_Y,
                    radius: 0.04,
                })
                .collect()
        };
        let discs = grid(Vec3::new(0.5, 6.0, 0.3));
        let bounds = occluder_bounds(&discs);
        let one_by_one: f32 = discs
            .iter()
            .map(|d| occluder_share(x, n, light, sphere, d))
            .sum();
        let whole = far_share(x, n, light, sphere, &bounds, 0.15).expect("far and inside");
        assert!(
            (whole - one_by_one).abs() < 0.02 * one_by_one,
            "whole {whole} vs one by one {one_by_one}"
        );
        // Too near for 0.15 (radius 0.33 m at 1 m).
        let near = occluder_bounds(&grid(Vec3::new(0.0, 1.0, 0.0)));
        assert!(far_share(x, n, light, sphere, &near, 0.15).is_none());
        // 0 takes every disc on its own.
        assert!(far_share(x, n, light, sphere, &bounds, 0.0).is_none());
        // A small light whose square is smaller than the tile's, near its edge: the discs
        // spread evenly over the tile's square, so the share is the covered fraction of the
        // whole, near what the discs one by one give on average.
        let small = 0.4;
        let edge = occluder_bounds(&grid(Vec3::new(0.15, 6.0, 0.0)));
        let discs_edge = grid(Vec3::new(0.15, 6.0, 0.0));
        let straddling = far_share(x, n, light, small, &edge, 0.15).expect("far");
        let one_by_one_small: f32 = discs_edge
            .iter()
            .map(|d| occluder_share(x, n, light, small, d))
            .sum();
        assert!(
            straddling > 0.0 && (straddling - one_by_one_small).abs() < 0.5 * one_by_one_small,
            "straddling {straddling} vs one by one {one_by_one_small}"
        );
        // Beside the light's square: nothing.
        assert_eq!(
            far_share(x, n, Vec3::new(15.0, 20.0, 0.0), small, &bounds, 0.15),
            Some(0.0)
        );
        // Beyond the light.
        assert!(far_share(x, n, Vec3::new(0.0, 5.0, 0.0), sphere, &bounds, 0.15).is_none());
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
        let sum = occlusion(
            usize::MAX,
            &receiver,
            light,
            0.5,
            &discs,
            OcclusionWalk {
                mode: OcclusionMode::Sum,
                tile: 64,
                far: 0.0,
            },
        );
        let union = occlusion(
            usize::MAX,
            &receiver,
            light,
            0.5,
            &discs,
            OcclusionWalk {
                mode: OcclusionMode::Union,
                tile: 64,
                far: 0.0,
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
