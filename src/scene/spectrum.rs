//! Sampled spectra ("λ:v, λ:v, …", wavelengths in nanometres) to linear sRGB, for scene files
//! that describe colours spectrally (Mitsuba's `<spectrum>`).
//!
//! Both conversions integrate the spectrum, linearly interpolated between its samples, against
//! the CIE 1931 2° colour-matching functions over 360–830 nm (1 nm steps, the 5 nm tables
//! interpolated linearly), then take XYZ to linear sRGB with the IEC 61966-2-1 matrix. They
//! differ in normalisation, because a reflectance is a ratio and an emission is an amount:
//!
//! - **Reflectance** ([`reflectance_to_linear_srgb`]): the spectrum is the fraction reflected
//!   of a D65 (sRGB's white) illuminant, white-balanced so that D65 itself is (1, 1, 1):
//!   `rgb = M·∫ρ·D65·c̄ / M·∫D65·c̄`, per channel. A constant spectrum ρ(λ) = c is therefore
//!   exactly the grey (c, c, c), so an RGB renderer multiplying light by this colour treats a
//!   grey surface as grey. Past its first and last samples the spectrum holds its end values
//!   (a measured reflectance does not drop to zero outside the measured band).
//! - **Emission** ([`emission_to_linear_srgb`]): the spectrum is spectral radiance and keeps
//!   its own colour: `XYZ = ∫L·c̄ / ∫ȳ`, so Y is the ȳ-weighted mean radiance (a constant
//!   spectrum L(λ) = 1 has Y = 1 and is equal-energy white, (1.205, 0.948, 0.909) in sRGB, not
//!   D65's (1, 1, 1)). Outside its samples the spectrum is zero. This is how Mitsuba 3's RGB
//!   modes read a sampled emission spectrum.
//!
//! Tables: CIE 1931 2° standard observer x̄, ȳ, z̄ and CIE standard illuminant D65 (relative
//! spectral power), 5 nm from 360 to 830 nm, as published by the CIE (CIE 015:2018 and ISO/CIE
//! 11664-1/-2; the same values Mitsuba 3 carries in `spectrum.cpp` and `d65.cpp`).

use glam::Vec3;

/// Shortest wavelength of the tables, nm.
pub const LAMBDA_MIN_NM: f64 = 360.0;
/// Longest wavelength of the tables, nm.
pub const LAMBDA_MAX_NM: f64 = 830.0;
/// Table spacing, nm.
const TABLE_STEP_NM: f64 = 5.0;
/// Samples per table: 360, 365, …, 830 nm.
const SAMPLES: usize = 95;
/// Integration step, nm.
const INTEGRATION_STEP_NM: f64 = 1.0;
/// Most samples a spectrum may list.
pub const MAX_SPECTRUM_SAMPLES: usize = 10_000;

/// CIE XYZ to linear sRGB (IEC 61966-2-1; D65 white), rows.
const XYZ_TO_LINEAR_SRGB: [[f64; 3]; 3] = [
    [3.2404542, -1.5371385, -0.4985314],
    [-0.9692660, 1.8760108, 0.0415560],
    [0.0556434, -0.2040259, 1.0572252],
];

/// x̄(λ).
const CIE_X: [f64; SAMPLES] = [
    0.0001299,
    0.0002321,
    0.0004149,
    0.0007416,
    0.001368,
    0.002236,
    0.004243,
    0.00765,
    0.01431,
    0.02319,
    0.04351,
    0.07763,
    0.13438,
    0.21477,
    0.2839,
    0.3285,
    0.34828,
    0.34806,
    0.3362,
    0.3187,
    0.2908,
    0.2511,
    0.19536,
    0.1421,
    0.09564,
    0.05795001,
    0.03201,
    0.0147,
    0.0049,
    0.0024,
    0.0093,
    0.0291,
    0.06327,
    0.1096,
    0.1655,
    0.2257499,
    0.2904,
    0.3597,
    0.4334499,
    0.5120501,
    0.5945,
    0.6784,
    0.7621,
    0.8425,
    0.9163,
    0.9786,
    1.0263,
    1.0567,
    1.0622,
    1.0456,
    1.0026,
    0.9384,
    0.8544499,
    0.7514,
    0.6424,
    0.5419,
    0.4479,
    0.3608,
    0.2835,
    0.2187,
    0.1649,
    0.1212,
    0.0874,
    0.0636,
    0.04677,
    0.0329,
    0.0227,
    0.01584,
    0.01135916,
    0.008110916,
    0.005790346,
    0.004109457,
    0.002899327,
    0.00204919,
    0.001439971,
    0.0009999493,
    0.0006900786,
    0.0004760213,
    0.0003323011,
    0.0002348261,
    0.0001661505,
    0.000117413,
    8.307527e-5,
    5.870652e-5,
    4.150994e-5,
    2.935326e-5,
    2.067383e-5,
    1.455977e-5,
    1.025398e-5,
    7.221456e-6,
    5.085868e-6,
    3.581652e-6,
    2.522525e-6,
    1.776509e-6,
    1.251141e-6,
];
/// ȳ(λ).
const CIE_Y: [f64; SAMPLES] = [
    3.917e-6, 6.965e-6, 1.239e-5, 2.202e-5, 3.9e-5, 6.4e-5, 0.00012, 0.000217, 0.000396, 0.00064,
    0.00121, 0.00218, 0.004, 0.0073, 0.0116, 0.01684, 0.023, 0.0298, 0.038, 0.048, 0.06, 0.0739,
    0.09098, 0.1126, 0.13902, 0.1693, 0.20802, 0.2586, 0.323, 0.4073, 0.503, 0.6082, 0.71, 0.7932,
    0.862, 0.9148501, 0.954, 0.9803, 0.9949501, 1.0, 0.995, 0.9786, 0.952, 0.9154, 0.87, 0.8163,
    0.757, 0.6949, 0.631, 0.5668, 0.503, 0.4412, 0.381, 0.321, 0.265, 0.217, 0.175, 0.1382, 0.107,
    0.0816, 0.061, 0.04458, 0.032, 0.0232, 0.017, 0.01192, 0.00821, 0.005723, 0.004102, 0.002929,
    0.002091, 0.001484, 0.001047, 0.00074, 0.00052, 0.0003611, 0.0002492, 0.0001719, 0.00012,
    8.48e-5, 6e-5, 4.24e-5, 3e-5, 2.12e-5, 1.499e-5, 1.06e-5, 7.4657e-6, 5.2578e-6, 3.7029e-6,
    2.6078e-6, 1.8366e-6, 1.2934e-6, 9.1093e-7, 6.4153e-7, 4.5181e-7,
];
/// z̄(λ).
const CIE_Z: [f64; SAMPLES] = [
    0.0006061,
    0.001086,
    0.001946,
    0.003486,
    0.006450001,
    0.01054999,
    0.02005001,
    0.03621,
    0.06785001,
    0.1102,
    0.2074,
    0.3713,
    0.6456,
    1.0390501,
    1.3856,
    1.62296,
    1.74706,
    1.7826,
    1.77211,
    1.7441,
    1.6692,
    1.5281,
    1.28764,
    1.0419,
    0.8129501,
    0.6162,
    0.46518,
    0.3533,
    0.272,
    0.2123,
    0.1582,
    0.1117,
    0.07824999,
    0.05725001,
    0.04216,
    0.02984,
    0.0203,
    0.0134,
    0.008749999,
    0.005749999,
    0.0039,
    0.002749999,
    0.0021,
    0.0018,
    0.001650001,
    0.0014,
    0.0011,
    0.001,
    0.0008,
    0.0006,
    0.00034,
    0.00024,
    0.00019,
    0.0001,
    4.999999e-5,
    3e-5,
    2e-5,
    1e-5,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
    0.0,
];
/// CIE standard illuminant D65, relative spectral power (100 at 560 nm).
const D65: [f64; SAMPLES] = [
    46.6383, 49.3637, 52.0891, 51.0323, 49.9755, 52.3118, 54.6482, 68.7015, 82.7549, 87.1204,
    91.486, 92.4589, 93.4318, 90.057, 86.6823, 95.7736, 104.865, 110.936, 117.008, 117.41, 117.812,
    116.336, 114.861, 115.392, 115.923, 112.367, 108.811, 109.082, 109.354, 108.578, 107.802,
    106.296, 104.79, 106.239, 107.689, 106.047, 104.405, 104.225, 104.046, 102.023, 100.0, 98.1671,
    96.3342, 96.0611, 95.788, 92.2368, 88.6856, 89.3459, 90.0062, 89.8026, 89.5991, 88.6489,
    87.6987, 85.4936, 83.2886, 83.4939, 83.6992, 81.863, 80.0268, 80.1207, 80.2146, 81.2462,
    82.2778, 80.281, 78.2842, 74.0027, 69.7213, 70.6652, 71.6091, 72.979, 74.349, 67.9765, 61.604,
    65.7448, 69.8856, 72.4863, 75.087, 69.3398, 63.5927, 55.0054, 46.4182, 56.6118, 66.8054,
    65.0941, 63.3828, 63.8434, 64.304, 61.8779, 59.4519, 55.7054, 51.959, 54.6998, 57.4406,
    58.8765, 60.3125,
];

/// A spectrum given at increasing wavelengths, nm, piecewise linear between them.
#[derive(Clone, Debug, PartialEq)]
pub struct SampledSpectrum {
    samples: Vec<(f64, f64)>,
}

/// What happens past a spectrum's first and last samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Outside {
    HoldEnds,
    Zero,
}

impl SampledSpectrum {
    /// Reads "λ:v, λ:v, …" (pairs separated by commas and/or whitespace): at least one pair,
    /// finite values, wavelengths strictly increasing. The error is the problem alone.
    pub fn parse(text: &str) -> Result<Self, String> {
        let mut samples = Vec::new();
        for pair in text
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|w| !w.is_empty())
        {
            if samples.len() == MAX_SPECTRUM_SAMPLES {
                return Err(format!("more than {MAX_SPECTRUM_SAMPLES} samples"));
            }
            let shown: String = pair.chars().take(40).collect();
            let (lambda, value) = pair
                .split_once(':')
                .ok_or_else(|| format!("'{shown}' is not a wavelength:value pair"))?;
            let number = |s: &str| -> Result<f64, String> {
                s.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| format!("'{shown}': '{s}' is not a finite number"))
            };
            let (lambda, value) = (number(lambda)?, number(value)?);
            if let Some(&(previous, _)) = samples.last() {
                if lambda <= previous {
                    return Err(format!(
                        "wavelengths must increase ({lambda} nm follows {previous} nm)"
                    ));
                }
            }
            samples.push((lambda, value));
        }
        if samples.is_empty() {
            return Err("no wavelength:value pairs".into());
        }
        Ok(Self { samples })
    }

    /// The spectrum at `lambda` nm.
    fn value(&self, lambda: f64, outside: Outside) -> f64 {
        let (first, last) = (self.samples[0], self.samples[self.samples.len() - 1]);
        if lambda < first.0 || lambda > last.0 {
            return match outside {
                Outside::HoldEnds if lambda < first.0 => first.1,
                Outside::HoldEnds => last.1,
                Outside::Zero => 0.0,
            };
        }
        // The first sample at or beyond λ; its predecessor bounds the interval.
        let upper = self.samples.partition_point(|&(l, _)| l < lambda);
        if upper == 0 {
            return first.1;
        }
        let (l0, v0) = self.samples[upper - 1];
        let (l1, v1) = self.samples[upper];
        v0 + (v1 - v0) * (lambda - l0) / (l1 - l0)
    }
}

/// x̄, ȳ, z̄ and D65 at `lambda` nm (inside the tables' range), linearly interpolated.
fn tables_at(lambda: f64) -> ([f64; 3], f64) {
    let f = ((lambda - LAMBDA_MIN_NM) / TABLE_STEP_NM).clamp(0.0, (SAMPLES - 1) as f64);
    let i = (f as usize).min(SAMPLES - 2);
    let t = f - i as f64;
    let lerp = |table: &[f64; SAMPLES]| table[i] + (table[i + 1] - table[i]) * t;
    ([lerp(&CIE_X), lerp(&CIE_Y), lerp(&CIE_Z)], lerp(&D65))
}

/// ∫ weight(λ)·c̄(λ) dλ over the tables' range (trapezoidal rule), as XYZ.
fn integrate_xyz(weight: impl Fn(f64, f64) -> f64) -> [f64; 3] {
    let steps = ((LAMBDA_MAX_NM - LAMBDA_MIN_NM) / INTEGRATION_STEP_NM).round() as usize;
    let mut xyz = [0.0; 3];
    for k in 0..=steps {
        let lambda = LAMBDA_MIN_NM + k as f64 * INTEGRATION_STEP_NM;
        let end = k == 0 || k == steps;
        let (cmf, d65) = tables_at(lambda);
        let w = weight(lambda, d65) * if end { 0.5 } else { 1.0 };
        for (sum, c) in xyz.iter_mut().zip(cmf) {
            *sum += w * c;
        }
    }
    xyz
}

fn xyz_to_linear_srgb(xyz: [f64; 3]) -> [f64; 3] {
    XYZ_TO_LINEAR_SRGB.map(|row| row[0] * xyz[0] + row[1] * xyz[1] + row[2] * xyz[2])
}

/// Linear sRGB of a reflectance spectrum under D65, white-balanced (see the module
/// documentation): a constant spectrum c is (c, c, c). Not clamped: a saturated spectrum can
/// leave the sRGB gamut (a negative channel) and the caller decides what to do.
pub fn reflectance_to_linear_srgb(spectrum: &SampledSpectrum) -> Vec3 {
    let lit = xyz_to_linear_srgb(integrate_xyz(|lambda, d65| {
        spectrum.value(lambda, Outside::HoldEnds) * d65
    }));
    let white = xyz_to_linear_srgb(integrate_xyz(|_, d65| d65));
    Vec3::new(
        (lit[0] / white[0]) as f32,
        (lit[1] / white[1]) as f32,
        (lit[2] / white[2]) as f32,
    )
}

/// Linear sRGB of an emitted spectral radiance, in the spectrum's units, with Y the
/// ȳ-weighted mean (see the module documentation). Not clamped. Mitsuba 3's RGB modes read
/// every sampled spectrum this way, reflectances included, so applied to a reflectance this
/// reproduces the RGB values its tools write (the measured Cornell box's `bsdfs-rgb.xml`).
pub fn emission_to_linear_srgb(spectrum: &SampledSpectrum) -> Vec3 {
    let xyz = integrate_xyz(|lambda, _| spectrum.value(lambda, Outside::Zero));
    let y_norm = integrate_xyz(|_, _| 1.0)[1];
    let rgb = xyz_to_linear_srgb(xyz.map(|c| c / y_norm));
    Vec3::new(rgb[0] as f32, rgb[1] as f32, rgb[2] as f32)
}

/// Luminance (Y) of a linear sRGB colour.
pub fn luminance(rgb: Vec3) -> f32 {
    rgb.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spectrum(text: &str) -> SampledSpectrum {
        SampledSpectrum::parse(text).unwrap()
    }

    #[test]
    fn constant_reflectance_is_its_grey() {
        for c in [0.0, 0.18, 0.78, 1.0] {
            for text in [
                format!("400:{c}, 700:{c}"),
                format!("360:{c}, 500:{c}, 830:{c}"),
                format!("550:{c}"),
            ] {
                let rgb = reflectance_to_linear_srgb(&spectrum(&text));
                assert!(
                    (rgb - Vec3::splat(c)).abs().max_element() < 1e-6,
                    "{text}: {rgb}"
                );
            }
        }
    }

    #[test]
    fn tables_integrate_to_their_published_sums() {
        // ∫ȳ over 360–830 nm is 106.857 (CIE 1931 2°, 5 nm table); D65 lies at the sRGB white
        // point, so the IEC matrix takes D65's XYZ (Y = 1) close to (1, 1, 1).
        let y = integrate_xyz(|_, _| 1.0)[1];
        assert!((y - 106.857).abs() < 0.05, "{y}");
        let d65 = integrate_xyz(|_, d65| d65);
        let rgb = xyz_to_linear_srgb(d65.map(|c| c / d65[1]));
        for c in rgb {
            assert!((c - 1.0).abs() < 1e-3, "{rgb:?}");
        }
        // D65's chromaticity, x = 0.3127, y = 0.3290.
        let sum: f64 = d65.iter().sum();
        assert!((d65[0] / sum - 0.3127).abs() < 2e-4 && (d65[1] / sum - 0.3290).abs() < 2e-4);
    }

    #[test]
    fn emission_keeps_its_luminance_and_colour() {
        // Equal energy: Y equals the value; sRGB of illuminant E (x = y = 1/3) is reddish.
        let e = emission_to_linear_srgb(&spectrum("360:2, 830:2"));
        assert!((luminance(e) - 2.0).abs() < 2e-3, "{e}");
        assert!(e.x > e.y && e.y > e.z, "{e}");
        // A narrow band at 610 nm is red; at 540 nm green; at 450 nm blue.
        for (centre, channel) in [(610.0, 0), (540.0, 1), (450.0, 2)] {
            let text = format!("{}:0, {centre}:1, {}:0", centre - 5.0, centre + 5.0);
            let rgb = emission_to_linear_srgb(&spectrum(&text));
            let max = rgb.max_element();
            assert_eq!(rgb[channel], max, "{text}: {rgb}");
        }
        // Emission outside its samples is zero: a spectrum ending at 400 nm is almost dark.
        let violet = emission_to_linear_srgb(&spectrum("360:1, 400:1"));
        assert!(luminance(violet) < 1e-3, "{violet}");
    }

    #[test]
    fn malformed_spectra_are_errors() {
        for (text, needle) in [
            ("", "no wavelength"),
            ("400:1, 400:2", "must increase"),
            ("500:1, 400:2", "must increase"),
            ("400:x", "not a finite number"),
            ("400", "not a wavelength:value pair"),
            ("400:inf", "not a finite number"),
        ] {
            let err = SampledSpectrum::parse(text).unwrap_err();
            assert!(err.contains(needle), "{text}: {err}");
        }
    }
}
