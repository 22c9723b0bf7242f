//! Perceptual comparison of two images: FLIP on the documented tone map, and the exposure it
//! is taken at. The evaluation harness reports it (`eval::metrics` re-exports these), and
//! budget mode measures its pilot frames with it, so it lives with the images, below both.

use super::Image;

pub(crate) fn same_size(a: &Image, b: &Image) {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "images of different sizes"
    );
}

/// Mean FLIP (nv-flip, default 67 pixels per degree) between the tone-mapped images, and the
/// FLIP error map coloured with the magma LUT.
pub fn flip_with_map(image: &Image, reference: &Image, exposure: f32) -> (f64, image::RgbImage) {
    same_size(image, reference);
    let (w, h) = (image.width, image.height);
    let a = image.tone_map(exposure);
    let r = reference.tone_map(exposure);
    let error_map = nv_flip::flip(
        nv_flip::FlipImageRgb8::with_data(w, h, r.as_raw()),
        nv_flip::FlipImageRgb8::with_data(w, h, a.as_raw()),
        nv_flip::DEFAULT_PIXELS_PER_DEGREE,
    );
    let mean = nv_flip::FlipPool::from_image(&error_map).mean() as f64;
    let lut = error_map.apply_color_lut(&nv_flip::magma_lut());
    let map =
        image::RgbImage::from_raw(w, h, lut.to_vec()).unwrap_or_else(|| image::RgbImage::new(w, h));
    (mean, map)
}

/// Mean FLIP between the tone-mapped images (0 = identical, 1 = maximal difference).
pub fn flip(image: &Image, reference: &Image, exposure: f32) -> f64 {
    flip_with_map(image, reference, exposure).0
}

/// Luminance (Rec. 709 weights) averaged over the image.
pub fn mean_luminance(image: &Image) -> f64 {
    let m = image.mean_rgb();
    0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2]
}

/// Exposure (stops) that maps the image's mean luminance to 0.18; 0 for a black image.
pub fn auto_exposure(reference: &Image) -> f32 {
    let mean = mean_luminance(reference);
    if mean > 0.0 && mean.is_finite() {
        ((0.18 / mean).log2() as f32).clamp(-30.0, 30.0)
    } else {
        0.0
    }
}
