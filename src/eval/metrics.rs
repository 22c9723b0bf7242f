//! Image error metrics against a reference and the temporal-stability metric (DESIGN §7). All
//! work on linear radiance except FLIP, which compares the documented tone map
//! (`Image::tone_map`: exposure, clamp, sRGB OETF). See README.md beside this file.

use crate::image_io::compare::same_size;
pub use crate::image_io::compare::{auto_exposure, flip, flip_with_map, mean_luminance};
use crate::image_io::Image;

/// ε of the relative MSE: keeps black reference pixels from dominating.
pub const RELMSE_EPSILON: f64 = 0.01;

/// Root mean square error over every pixel and RGB channel:
/// `sqrt(1/(3N) Σ_px Σ_c (a − r)²)`.
pub fn rmse(image: &Image, reference: &Image) -> f64 {
    same_size(image, reference);
    let mut sum = 0.0f64;
    for (a, r) in image.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let d = a[c] as f64 - r[c] as f64;
            sum += d * d;
        }
    }
    (sum / (3 * image.pixels.len().max(1)) as f64).sqrt()
}

/// Relative mean square error: `1/(3N) Σ_px Σ_c (a − r)² / (r² + ε)` with ε = 0.01.
pub fn relmse(image: &Image, reference: &Image) -> f64 {
    same_size(image, reference);
    let mut sum = 0.0f64;
    for (a, r) in image.pixels.iter().zip(&reference.pixels) {
        for c in 0..3 {
            let (a, r) = (a[c] as f64, r[c] as f64);
            sum += (a - r) * (a - r) / (r * r + RELMSE_EPSILON);
        }
    }
    sum / (3 * image.pixels.len().max(1)) as f64
}

/// Temporal instability of a frame sequence I_0 … I_{T−1} (the indirect images of a smooth
/// animation): the energy of the second temporal difference relative to the squared mean,
///
/// `flicker = mean_{t=1..T−2} mean_{px,c} (I_{t+1} − 2 I_t + I_{t−1})² / (mean_{t,px,c} I)²`.
///
/// Motion that is linear in time gives 0; frame-to-frame noise gives a large value. `None`
/// with fewer than three frames; 0 for an all-black sequence.
pub fn flicker(frames: &[Image]) -> Option<f64> {
    flicker_where(frames, None)
}

/// [`flicker`] over the pixels where `mask` is true only (both means taken over them), or
/// all pixels with `None`; `None` also when the mask keeps no pixel. With the pixels whose
/// surface stands still ([`static_pixels`]) it leaves out the silhouettes of moving objects,
/// whose sweep across a pixel is a second difference in every method and in the reference.
pub fn flicker_where(frames: &[Image], mask: Option<&[bool]>) -> Option<f64> {
    if frames.len() < 3 {
        return None;
    }
    for f in &frames[1..] {
        same_size(&frames[0], f);
    }
    let keep = |i: usize| mask.is_none_or(|m| m.get(i).copied().unwrap_or(false));
    let kept = (0..frames[0].pixels.len()).filter(|&i| keep(i)).count();
    if kept == 0 {
        return None;
    }
    let n = kept as f64 * 3.0;
    let mut mean = 0.0f64;
    for f in frames {
        for (i, p) in f.pixels.iter().enumerate() {
            if keep(i) {
                mean += (p[0] + p[1] + p[2]) as f64;
            }
        }
    }
    mean /= n * frames.len() as f64;
    let mut energy = 0.0f64;
    for t in 1..frames.len() - 1 {
        let (prev, cur, next) = (&frames[t - 1], &frames[t], &frames[t + 1]);
        let mut sum = 0.0f64;
        for i in (0..cur.pixels.len()).filter(|&i| keep(i)) {
            for c in 0..3 {
                let d = next.pixels[i][c] as f64 - 2.0 * cur.pixels[i][c] as f64
                    + prev.pixels[i][c] as f64;
                sum += d * d;
            }
        }
        energy += sum / n;
    }
    energy /= (frames.len() - 2) as f64;
    if mean == 0.0 {
        return Some(if energy == 0.0 { 0.0 } else { f64::INFINITY });
    }
    Some(energy / (mean * mean))
}

/// Pixels whose camera ray meets the same surface point in every frame: `hits[f][px]` is
/// frame f's first hit (position, shading normal), `None` for a miss. A pixel is static
/// when it misses in every frame, or hits in every frame within `tolerance` of frame 0's
/// position with a normal within 1e-3 of it.
pub fn static_pixels(hits: &[Vec<Option<(glam::Vec3, glam::Vec3)>>], tolerance: f32) -> Vec<bool> {
    let Some(first) = hits.first() else {
        return vec![];
    };
    (0..first.len())
        .map(|i| {
            hits.iter()
                .all(|frame| match (first[i], frame.get(i).copied().flatten()) {
                    (None, None) => true,
                    (Some((p0, n0)), Some((p, n))) => {
                        p.distance(p0) <= tolerance && n.dot(n0) >= 1.0 - 1e-3
                    }
                    _ => false,
                })
        })
        .collect()
}
