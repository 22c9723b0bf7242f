//! The light-atlas baker on the CPU: the closed box against the geometric series, the energy
//! account, cancellation, bad input, and the EXR round trip.

use std::sync::atomic::AtomicBool;

use valgi::atlas::{bake, BakeError, BakeSettings};
use valgi::scene::{self, builtin::BuiltinParams};

fn no_progress(_: &str, _: usize, _: usize) {}

fn box_scene() -> valgi::scene::Scene {
    scene::load("box-point", &BuiltinParams { max_edge: 0.25 }).unwrap()
}

/// Closed 2×2×2 box, albedo ρ = 0.5 everywhere, point light of I = 1 W/sr at the centre.
/// Every watt the light emits (Φ = 4π·I) lands on the walls (A = 24 m²); each reflection keeps
/// the fraction ρ and, the box being closed, all reflected light lands on the walls again. So
/// the area-mean irradiance of bounce b is Ē_b = ρ^b·Φ/A and the B-bounce indirect mean is
/// Φ/A · Σ_{b=1..B} ρ^b = Φ/A · ρ(1 − ρ^B)/(1 − ρ) (0.5236·0.9375 = 0.4909 W/m² for B = 4).
#[test]
fn closed_box_matches_the_geometric_series() {
    let scene = box_scene();
    let settings = BakeSettings {
        vpls: 600,
        bounces: 4,
        atlas_res: 128,
        ..Default::default()
    };
    let result = bake(
        &scene,
        &scene.world_from_node(),
        &settings,
        &no_progress,
        &AtomicBool::new(false),
    )
    .unwrap();
    let rho = 0.5f64;
    let phi_over_a = 4.0 * std::f64::consts::PI / 24.0;
    let centre: Vec<u32> = result
        .layout
        .texels
        .iter()
        .filter(|t| t.centre)
        .map(|t| t.index)
        .collect();
    let mut total = 0.0;
    for b in 1..=4u32 {
        let mean = centre
            .iter()
            .map(|&i| result.irradiance[b as usize - 1][i as usize][1] as f64)
            .sum::<f64>()
            / centre.len() as f64;
        let expected = phi_over_a * rho.powi(b as i32);
        eprintln!("bounce {b}: mean {mean:.4}, expected {expected:.4}");
        assert!(
            (mean / expected - 1.0).abs() < 0.06,
            "bounce {b}: mean {mean} vs {expected}"
        );
        total += mean;
    }
    let expected = phi_over_a * rho * (1.0 - rho.powi(4)) / (1.0 - rho);
    eprintln!("B = 4: mean {total:.4}, expected {expected:.4}");
    assert!(
        (total / expected - 1.0).abs() < 0.04,
        "{total} vs {expected}"
    );
    eprintln!("{}", result.summary());
    let e = result.energy;
    assert!(e.relative_residual() < 1e-6, "{e:?}");
    // Closed box: light leaves only through the form factors' discretization.
    assert!(e.escaped[1] / e.emitted[1] < 0.08, "{e:?}");
}
