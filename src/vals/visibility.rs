//! `--occlusion rays`: visibility of VAL clusters at the sparse points, the CPU twin of
//! `shaders/vals/vals_visibility.wgsl`.
//!
//! The paper's occlusion hides one averaged light sphere behind the sparse points' discs; when
//! a point's VALs lie on both sides of a wall (light coming through a doorway) that sphere
//! spans the wall and the light that does arrive is removed with the light that does not.
//! Here the VALs are grouped into clusters that are tiles of the RSM (spatially coherent, and
//! fixed to texels, so they move smoothly with the light: `light::rsm::texel_cluster`), and
//! each (point, cluster) pair gets a visible fraction from shadow rays through the scene's
//! BVH to the VALs at the cluster's sample strata (per stratum the first of its centre and
//! corner texels whose VAL reaches the point, `rsm::SAMPLE_CANDIDATES`):
//!
//! `V_c(x) = Σ_s w_s·vis(x, l_s) / Σ_s w_s`, `w_s = Φ_s·g(x, n, s)` (flux times the disc
//! geometry term, so the samples that matter most at x count most), and `V_c = 1` where no
//! sample reaches x. The gather then scales each VAL's geometry term by `V_c` of its cluster
//! (`math::gather_visible`), so the renormalized light sits among the VALs the point sees.

use glam::Vec3;

use crate::light::bvh::SceneBvh;
use crate::light::rsm::{GpuVal, CLUSTER_SAMPLE_SIDE, MAX_CLUSTERS, SAMPLE_CANDIDATES};
use crate::light::sensor::{depth_blocks, stratum_sample, SensorImage};
use crate::vals::math::disc_geometry;

/// Ray ends are pulled off both surfaces by this fraction of the segment's length.
pub const RAY_OFFSET: f32 = 2e-3;

/// Most RSM tiles one cluster's rays go to (`MAX_RAY_TILES` in `vals_visibility.wgsl`): a
/// cluster holds every `MAX_CLUSTERS`-th tile, which with hundreds of lights is thousands of
/// rays per point; an evenly strided subset of this many tiles stands for them.
pub const MAX_RAY_TILES: u32 = 4;

/// Step between the tiles cluster `cluster` shoots at: every one of its tiles while it has
/// at most [`MAX_RAY_TILES`], else an even stride that visits that many.
pub fn ray_tile_stride(cluster: u32, all_tiles: u32) -> u32 {
    let tiles_in_cluster = if cluster < all_tiles {
        (all_tiles - cluster).div_ceil(MAX_CLUSTERS)
    } else {
        0
    };
    tiles_in_cluster.div_ceil(MAX_RAY_TILES).max(1) * MAX_CLUSTERS
}

/// Whether stratum `s` of a tile's `CLUSTER_SAMPLE_SIDE²` grid is on an even row and column:
/// the 2×2 coarse grid that adaptive rays try first.
pub fn is_coarse_stratum(s: u32) -> bool {
    (s % CLUSTER_SAMPLE_SIDE).is_multiple_of(2) && (s / CLUSTER_SAMPLE_SIDE).is_multiple_of(2)
}

/// `V_c(x)` for cluster `cluster` at the point (x, n), from the rays to the sampled VALs of
/// its tiles (at most [`MAX_RAY_TILES`] of them, [`ray_tile_stride`]): `rsm_tiles` RSM tiles
/// over all layers, `samples` the RSM's cluster sample slots (1 + VAL index, 0 unlit), `vals`
/// as the GPU holds them. A depth `sensor`'s tiles follow the RSM's, sampled at the VALs its
/// producer put in their strata's slots, and its depth blocks rays too
/// ([`crate::light::sensor`]).
///
/// `adaptive` (`--visibility-rays adaptive`): per tile, rays go to the coarse strata
/// ([`is_coarse_stratum`]) first; when all of those that reach x agree (all seen or all
/// hidden), the other strata are given the same answer without rays (their weights still
/// count), else each gets its own ray. A blocker that slips between the coarse strata of a
/// tile that is otherwise unanimous is missed: the price of a quarter of the rays there.
#[allow(clippy::too_many_arguments)]
pub fn cluster_visibility(
    bvh: &SceneBvh,
    x: Vec3,
    n: Vec3,
    cluster: u32,
    rsm_tiles: u32,
    samples: &[u32],
    vals: &[GpuVal],
    sensor: Option<&SensorImage>,
    adaptive: bool,
) -> f32 {
    let per_tile = CLUSTER_SAMPLE_SIDE * CLUSTER_SAMPLE_SIDE;
    let sensor_tiles = sensor.map_or(0, |s| s.params.tile_count());
    // Candidate k of stratum s of a tile: an RSM slot, or past the RSM's tiles a sensor
    // tile's surfel.
    let candidate = |tile: u32, s: u32, k: u32| match sensor {
        Some(image) if tile >= rsm_tiles => stratum_sample(&image.samples, tile - rsm_tiles, s, k),
        _ => {
            let slot = samples
                .get(((tile * per_tile + s) * SAMPLE_CANDIDATES + k) as usize)
                .copied()
                .unwrap_or(0);
            slot.checked_sub(1)
                .and_then(|i| vals.get(i as usize))
                .map(GpuVal::to_val)
                .filter(|val| val.area > 0.0)
        }
    };
    // (Φ·g at x, ray start, ray end) of a stratum's sample: its first candidate (centre,
    // then corners) that reaches x; None when none does.
    let sample = |tile: u32, s: u32| {
        (0..SAMPLE_CANDIDATES).find_map(|k| {
            let val = candidate(tile, s, k)?;
            let (g, _) = disc_geometry(x, n, &val);
            let weight = g * (val.flux.x + val.flux.y + val.flux.z);
            // A NaN weight is skipped too.
            if weight.is_nan() || weight <= 0.0 {
                return None;
            }
            let offset = RAY_OFFSET * (val.position - x).length();
            Some((weight, x + n * offset, val.position + val.normal * offset))
        })
    };
    let blocked = |from: Vec3, to: Vec3| {
        bvh.occluded(from, to)
            || sensor.is_some_and(|image| depth_blocks(&image.params, &image.depth, from, to))
    };
    let all_tiles = rsm_tiles + sensor_tiles;
    let stride = ray_tile_stride(cluster, all_tiles);
    let (mut seen, mut total) = (0.0f32, 0.0f32);
    let mut tile = cluster;
    while tile < all_tiles {
        let (mut coarse_seen, mut coarse_hidden) = (false, false);
        for s in (0..per_tile).filter(|&s| !adaptive || is_coarse_stratum(s)) {
            let Some((weight, from, to)) = sample(tile, s) else {
                continue;
            };
            total += weight;
            if blocked(from, to) {
                coarse_hidden = true;
            } else {
                seen += weight;
                coarse_seen = true;
            }
        }
        if adaptive {
            let unanimous = coarse_seen != coarse_hidden;
            for s in (0..per_tile).filter(|&s| !is_coarse_stratum(s)) {
                let Some((weight, from, to)) = sample(tile, s) else {
                    continue;
                };
                total += weight;
                let visible = if unanimous {
                    coarse_seen
                } else {
                    !blocked(from, to)
                };
                if visible {
                    seen += weight;
                }
            }
        }
        tile += stride;
    }
    if total <= 0.0 {
        1.0
    } else {
        seen / total
    }
}

/// This frame's visibility with `percent` of last frame's stored byte kept
/// (`--visibility-history`): `V ← (1 − h)·V + h·V_prev`. A light that moves smoothly moves
/// the rays' samples smoothly, but each ray's answer flips at an edge; the blend spreads a
/// flip over a few frames (it halves in one frame at the default h = 0.5).
pub fn blend_history(v: f32, previous: u8, percent: u32) -> f32 {
    let keep = percent.min(100) as f32 / 100.0;
    if keep <= 0.0 {
        return v;
    }
    v + (previous as f32 / 255.0 - v) * keep
}

/// `V·255` rounded, as the GPU stores it.
pub fn quantize(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}
