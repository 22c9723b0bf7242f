//! The polygon-light baker's parts against closed forms and Monte Carlo (methods §B.12): the
//! square-over-point form factor, horizon clipping, the sphere cap, the point-light fallback,
//! the corner shift, bounded irradiance where point lights spike, and the gap-aware split.

use glam::{DVec3, Vec2, Vec3};
use valgi::atlas::polygon::cluster::kd_clusters;
use valgi::atlas::polygon::form_factor::{
    point_irradiance, polygon_form_factor, polygon_irradiance, sphere_cap_cosine,
    sphere_irradiance, unclipped_form_factor, PolygonLight, SphereLight, POINT_FALLBACK,
};
use valgi::reference::sampling::{cosine_hemisphere, Rng};

/// F from a point on the axis of a parallel square of half-side s at height h, a = s/h.
fn square_oracle(a: f64) -> f64 {
    let b = a / (1.0 + a * a).sqrt();
    4.0 / std::f64::consts::PI * b * b.atan()
}

fn square(s: f64, h: f64) -> Vec<DVec3> {
    // Counter-clockwise about −z (the square emits down toward the receiver at the origin).
    vec![
        DVec3::new(-s, -s, h),
        DVec3::new(-s, s, h),
        DVec3::new(s, s, h),
        DVec3::new(s, -s, h),
    ]
}

#[test]
fn square_over_a_point_matches_the_closed_form_and_its_limits() {
    for a in [0.01, 0.1, 0.5, 1.0, 2.0, 10.0, 100.0] {
        let f = polygon_form_factor(DVec3::ZERO, DVec3::Z, &square(a, 1.0));
        let want = square_oracle(a);
        assert!((f - want).abs() < 1e-4, "a = {a}: {f} vs {want}");
        // The winding does not matter.
        let mut rev = square(a, 1.0);
        rev.reverse();
        let g = polygon_form_factor(DVec3::ZERO, DVec3::Z, &rev);
        assert!((f - g).abs() < 1e-12);
    }
    // a → ∞: the square covers the hemisphere.
    let f = polygon_form_factor(DVec3::ZERO, DVec3::Z, &square(1e4, 1.0));
    assert!((f - 1.0).abs() < 1e-3, "{f}");
    // a → 0: the point law A·cos·cos/(π d²) = 4a²/π.
    let a = 1e-3;
    let f = polygon_form_factor(DVec3::ZERO, DVec3::Z, &square(a, 1.0));
    let point = 4.0 * a * a / std::f64::consts::PI;
    assert!((f / point - 1.0).abs() < 1e-4, "{f} vs {point}");
}

/// Monte-Carlo cosine-weighted estimate of F: the fraction of cosine-distributed directions
/// from (0, n = +z) that hit the convex polygon.
fn monte_carlo(poly: &[DVec3], samples: u32) -> f64 {
    let normal = (poly[1] - poly[0]).cross(poly[2] - poly[0]).normalize();
    let mut hits = 0u32;
    let mut rng = Rng::new(7, 1, 0);
    for _ in 0..samples {
        let d = cosine_hemisphere(Vec3::Z, rng.next_f32(), rng.next_f32()).as_dvec3();
        let denom = normal.dot(d);
        if denom.abs() < 1e-12 {
            continue;
        }
        let t = normal.dot(poly[0]) / denom;
        if t <= 0.0 {
            continue;
        }
        let x = d * t;
        let k = poly.len();
        let signs: Vec<f64> = (0..k)
            .map(|i| (poly[(i + 1) % k] - poly[i]).cross(x - poly[i]).dot(normal))
            .collect();
        if signs.iter().all(|&s| s >= 0.0) || signs.iter().all(|&s| s <= 0.0) {
            hits += 1;
        }
    }
    hits as f64 / samples as f64
}

#[test]
fn horizon_clipping_matches_monte_carlo_where_the_unclipped_sum_does_not() {
    // A vertical square standing across the receiver's plane (z from −0.5 to 1), 1 m away.
    let poly = vec![
        DVec3::new(1.0, -0.5, -0.5),
        DVec3::new(1.0, 0.5, -0.5),
        DVec3::new(1.0, 0.5, 1.0),
        DVec3::new(1.0, -0.5, 1.0),
    ];
    let clipped = polygon_form_factor(DVec3::ZERO, DVec3::Z, &poly);
    let unclipped = unclipped_form_factor(DVec3::ZERO, DVec3::Z, &poly);
    let n = 400_000;
    let mc = monte_carlo(&poly, n);
    let sigma = (mc * (1.0 - mc) / n as f64).sqrt();
    eprintln!("clipped {clipped:.5}, unclipped {unclipped:.5}, Monte Carlo {mc:.5} ± {sigma:.5}");
    assert!(
        (clipped - mc).abs() < 4.0 * sigma + 1e-4,
        "{clipped} vs {mc}"
    );
    assert!((unclipped - mc).abs() > 20.0 * sigma, "{unclipped} vs {mc}");
    // A tilted triangle partly below the horizon.
    let tri = vec![
        DVec3::new(0.3, -0.4, -0.3),
        DVec3::new(0.6, 0.5, 0.2),
        DVec3::new(-0.2, 0.4, 0.9),
    ];
    let clipped = polygon_form_factor(DVec3::ZERO, DVec3::Z, &tri);
    let mc = monte_carlo(&tri, n);
    let sigma = (mc * (1.0 - mc) / n as f64).sqrt();
    assert!(
        (clipped - mc).abs() < 4.0 * sigma + 1e-4,
        "{clipped} vs {mc}"
    );
}

#[test]
fn sphere_cap_matches_monte_carlo_across_the_horizon() {
    // A sphere of radius 0.5 at distance 1 (α = 30°), its centre at angle β from the normal.
    let (r, d) = (0.5f64, 1.0f64);
    for beta_deg in [0.0f64, 40.0, 70.0, 90.0, 110.0, 125.0] {
        let beta = beta_deg.to_radians();
        let c = DVec3::new(beta.sin(), 0.0, beta.cos()) * d;
        let n = 400_000u32;
        let mut hits = 0u32;
        let mut rng = Rng::new(3, beta_deg as u64, 0);
        for _ in 0..n {
            let w = cosine_hemisphere(Vec3::Z, rng.next_f32(), rng.next_f32()).as_dvec3();
            let t = w.dot(c);
            if t > 0.0 && (c - w * t).length_squared() <= r * r {
                hits += 1;
            }
        }
        // ∫ cos dω over the cap = π · (fraction of cosine-distributed directions in it).
        let mc = std::f64::consts::PI * hits as f64 / n as f64;
        let got = sphere_cap_cosine(r, d, beta.cos());
        assert!((got - mc).abs() < 0.004, "β = {beta_deg}°: {got} vs {mc}");
    }
    // Inside the sphere the whole hemisphere is lit, and far away it is the point law.
    assert_eq!(sphere_cap_cosine(1.0, 0.5, 0.3), std::f64::consts::PI);
    let light = SphereLight {
        centre: Vec3::new(0.0, 0.0, 3.0),
        radius: 0.02,
        normal: Some(Vec3::NEG_Z),
        power: [1.0; 3],
    };
    let e = sphere_irradiance(&light, Vec3::ZERO, Vec3::Z);
    let point = point_irradiance(
        1.0,
        DVec3::new(0.0, 0.0, 3.0),
        DVec3::NEG_Z,
        DVec3::ZERO,
        DVec3::Z,
    );
    assert!((e / point - 1.0).abs() < 1e-3, "{e} vs {point}");
}

fn square_light(half: f32, at: Vec3) -> PolygonLight {
    // A square emitting down (−y) at height `at.y`, counter-clockwise about −y.
    let v = [
        Vec3::new(-half, 0.0, -half),
        Vec3::new(half, 0.0, -half),
        Vec3::new(half, 0.0, half),
        Vec3::new(-half, 0.0, half),
    ]
    .map(|p| p + at);
    PolygonLight {
        vertices: v.to_vec(),
        normal: Vec3::NEG_Y,
        centre: at,
        power: [1.0; 3],
        area: 4.0 * half * half,
        radius: half * std::f32::consts::SQRT_2,
    }
}

#[test]
fn the_point_light_fallback_is_continuous() {
    let light = square_light(0.05, Vec3::ZERO);
    // Distance at which radius/d = the fallback threshold; receivers just inside and outside,
    // off axis so both cosines matter.
    let d_switch = light.radius as f64 / POINT_FALLBACK;
    let dir = Vec3::new(0.3, -1.0, 0.2).normalize();
    let e = |d: f64| polygon_irradiance(&light, dir * d as f32, -dir, 0.0, 0.0, &|_, _| true);
    let (near, far) = (e(d_switch * 0.9999), e(d_switch * 1.0001));
    let jump = (near / far - 1.0).abs() - (1.0001f64 / 0.9999).powi(2) + 1.0;
    eprintln!("across the switch: {near:.6e} → {far:.6e} (jump {jump:.2e})");
    assert!(jump.abs() < 0.01, "{near} vs {far}");
}

#[test]
fn polygon_lights_stay_bounded_where_point_lights_spike() {
    // Receivers on the axis under a 0.4 m square light, from 1 mm below it down.
    let light = square_light(0.2, Vec3::new(0.0, 1.0, 0.0));
    let bound = 1.0 / light.area as f64; // Φ/A: F ≤ 1.
    let mut poly_max = 0.0f64;
    let mut point_max = 0.0f64;
    for k in 0..200 {
        let h = 1e-3 * 1.04f64.powi(k);
        let p = Vec3::new(0.0, 1.0 - h as f32, 0.0);
        let e = polygon_irradiance(&light, p, Vec3::Y, 0.0, 0.0, &|_, _| true);
        poly_max = poly_max.max(e);
        point_max = point_max.max(point_irradiance(
            1.0,
            light.centre.as_dvec3(),
            DVec3::NEG_Y,
            p.as_dvec3(),
            DVec3::Y,
        ));
    }
    eprintln!(
        "max irradiance per watt: polygon {poly_max:.3} (bound {bound:.3}), point {point_max:.3e}"
    );
    assert!(poly_max <= bound * 1.0001, "{poly_max} vs {bound}");
    assert!(
        poly_max > 0.9 * bound,
        "the bound is reached just under the light"
    );
    assert!(point_max > 100.0 * poly_max);
}

/// A floor light (emitting up) meets a wall at x = 0 facing +x. The wall's texel centres sit
/// at (k − 0.3) texels above the floor (conservative coverage puts the first row's centre just
/// below the floor's plane). Against the exact form factor at the surface point each texel
/// stands for (clamped onto the wall above the floor), the corner row keeps ≥ 0.9 of its
/// neighbours' ratio with the shift; without it, it is dark.
#[test]
fn no_dark_seam_at_a_lit_concave_corner() {
    let texel = 0.01f32;
    let light = PolygonLight {
        vertices: vec![
            Vec3::new(0.0, 0.0, -0.5),
            Vec3::new(0.0, 0.0, 0.5),
            Vec3::new(1.0, 0.0, 0.5),
            Vec3::new(1.0, 0.0, -0.5),
        ],
        normal: Vec3::Y,
        centre: Vec3::new(0.5, 0.0, 0.0),
        power: [1.0; 3],
        area: 1.0,
        radius: 0.71,
    };
    let ratio = |k: usize, shift: bool| {
        let y = (k as f32 - 0.3) * texel;
        let p = Vec3::new(0.0, y, 0.0);
        let (eps, max) = if shift {
            (0.5 * texel, 2.0 * texel)
        } else {
            (0.0, 0.0)
        };
        let got = polygon_irradiance(&light, p, Vec3::X, eps, max, &|_, _| true);
        let on_surface = Vec3::new(0.0, y.max(0.05 * texel), 0.0);
        let want = polygon_irradiance(&light, on_surface, Vec3::X, 0.0, 0.0, &|_, _| true);
        got / want
    };
    let (corner, next, next2) = (ratio(0, true), ratio(1, true), ratio(2, true));
    eprintln!(
        "shifted: corner {corner:.3}, rows 1, 2: {next:.3}, {next2:.3}; unshifted corner {:.3}",
        ratio(0, false)
    );
    assert!(
        corner >= 0.9 * next.min(next2),
        "{corner} vs {next}, {next2}"
    );
    assert!(
        ratio(0, false) < 0.5,
        "without the shift the corner row is dark"
    );
}

#[test]
fn the_gap_aware_split_does_not_straddle_a_shadow_stripe() {
    // VPLs uniform on the unit square except a shadow stripe x ∈ [0.40, 0.47], off the median.
    let mut rng = Rng::new(11, 0, 0);
    let mut pts: Vec<[f32; 2]> = Vec::new();
    while pts.len() < 4000 {
        let p = [rng.next_f32(), rng.next_f32() * 0.25];
        if !(0.40..0.47).contains(&p[0]) {
            pts.push(p);
        }
    }
    let straddling = |rho: f32| {
        let leaves = kd_clusters(&pts, 50, rho);
        let sizes: Vec<usize> = leaves.iter().map(|l| l.members.len()).collect();
        let mean = sizes.iter().sum::<usize>() as f64 / sizes.len() as f64;
        let across = leaves
            .iter()
            .filter(|l| {
                let left = l.members.iter().any(|&i| pts[i][0] < 0.40);
                let right = l.members.iter().any(|&i| pts[i][0] >= 0.47);
                left && right
            })
            .count();
        (across, mean)
    };
    let (gap_across, gap_mean) = straddling(0.5);
    let (median_across, median_mean) = straddling(f32::INFINITY);
    eprintln!("clusters across the stripe: ρ = 0.5 {gap_across} (mean size {gap_mean:.1}), median {median_across} (mean size {median_mean:.1})");
    assert_eq!(gap_across, 0);
    assert!(median_across > 0);
    assert!((25.0..=50.0).contains(&gap_mean), "{gap_mean}");
    let _ = Vec2::ZERO;
}
