//! The fast Legendre ↔ cosine-grid transform against its slow references on seeded random
//! coefficients at L = 10, 100, 1000, 5000. Errors are measured relative to the largest value of
//! the reference (per-element relative errors are meaningless at the zeros of a random series).
//! Measured values print with `--nocapture`; tolerances sit just above them.

mod common;

use common::{Lcg, max_abs, max_abs_diff};
use std::time::Instant;
use tables::legendre::reference::{
    coefficients_by_gauss_quadrature, gauss_legendre, legendre_series_direct,
    legendre_series_direct_cosine_grid,
};
use tables::legendre::{
    chebyshev_to_legendre, coefficients_from_cosine_grid, evaluate_on_cosine_grid,
    legendre_to_chebyshev,
};

const DEGREES: [usize; 4] = [10, 100, 1000, 5000];

fn random_coefficients(l_top: usize, seed: u64) -> Vec<f64> {
    let mut rng = Lcg::new(seed);
    (0..=l_top).map(|_| rng.symmetric()).collect()
}

/// max |x − y| / max |y|.
fn rel(x: &[f64], y: &[f64]) -> f64 {
    max_abs_diff(x, y) / max_abs(y)
}

#[test]
fn conversions_invert_each_other() {
    // Measured: 2.6e-16, 1.2e-15, 1.1e-14, 2.2e-14.
    let tol = [5e-16, 2e-15, 1.5e-14, 3e-14];
    for (i, &l_top) in DEGREES.iter().enumerate() {
        let a = random_coefficients(l_top, 1 + i as u64);
        let back = chebyshev_to_legendre(&legendre_to_chebyshev(&a));
        let err = rel(&back, &a);
        println!("L = {l_top}: Legendre → Chebyshev → Legendre {err:.2e}");
        assert!(err < tol[i], "L = {l_top}: {err:e}");
    }
}

#[test]
fn fast_evaluation_matches_direct_summation() {
    // On N + 1 = L + 1 nodes, on a coarser grid (N = L/5) that exercises the exact fold, and on
    // a finer one (N = 3L). Reference: direct summation at exact θ_j (Reinsch form).
    // Measured worst per L: 1.0e-15, 1.4e-15, 1.2e-14, 3.0e-14.
    let tol = [1.5e-15, 2e-15, 1.5e-14, 3.5e-14];
    for (i, &l_top) in DEGREES.iter().enumerate() {
        let a = random_coefficients(l_top, 10 + i as u64);
        let mut worst = 0.0f64;
        for n in [l_top, (l_top / 5).max(1), 3 * l_top] {
            let t0 = Instant::now();
            let fast = evaluate_on_cosine_grid(&a, n).unwrap();
            let t_fast = t0.elapsed();
            let t0 = Instant::now();
            let slow = legendre_series_direct_cosine_grid(&a, n);
            let t_slow = t0.elapsed();
            let err = rel(&fast, &slow);
            worst = worst.max(err);
            println!(
                "L = {l_top}, N = {n}: fast vs direct {err:.2e}; fast {:.2} ms, direct {:.2} ms",
                t_fast.as_secs_f64() * 1e3,
                t_slow.as_secs_f64() * 1e3
            );
        }
        assert!(worst < tol[i], "L = {l_top}: {worst:e}");
    }
}

#[test]
fn fast_inverse_matches_gauss_quadrature() {
    // Samples of a known degree-L series: at the L + 1 cosine nodes for the fast inverse, at
    // L + 1 Gauss–Legendre nodes (exact for degree ≤ 2L + 1) for the quadrature oracle.
    // Measured: fast 4.6e-16, 1.0e-14, 9.0e-14, 5.0e-13; Gauss oracle 2.6e-15, 2.8e-14, 9.5e-13,
    // 1.4e-11 (its samples come from the plain recurrence at rounded nodes, see
    // `legendre_series_direct_cosine_grid` for why that costs digits at large L).
    let tol_fast = [1e-15, 1.5e-14, 1.2e-13, 6e-13];
    let tol_gauss = [3e-15, 3.5e-14, 1.2e-12, 1.6e-11];
    for (i, &l_top) in DEGREES.iter().enumerate() {
        let a = random_coefficients(l_top, 20 + i as u64);
        let f_cos = legendre_series_direct_cosine_grid(&a, l_top);
        let t0 = Instant::now();
        let a_fast = coefficients_from_cosine_grid(&f_cos).unwrap();
        let t_fast = t0.elapsed();
        let (x, w) = gauss_legendre(l_top + 1);
        let f_gauss = legendre_series_direct(&a, &x);
        let t0 = Instant::now();
        let a_gauss = coefficients_by_gauss_quadrature(&x, &w, &f_gauss, l_top);
        let t_gauss = t0.elapsed();
        let (e_fast, e_gauss, e_cross) =
            (rel(&a_fast, &a), rel(&a_gauss, &a), rel(&a_fast, &a_gauss));
        println!(
            "L = {l_top}: fast inverse {e_fast:.2e}, Gauss oracle {e_gauss:.2e}, fast vs oracle {e_cross:.2e}; fast {:.2} ms, Gauss quadrature {:.2} ms",
            t_fast.as_secs_f64() * 1e3,
            t_gauss.as_secs_f64() * 1e3
        );
        assert!(e_fast < tol_fast[i], "L = {l_top}: {e_fast:e}");
        assert!(e_gauss < tol_gauss[i], "L = {l_top}: {e_gauss:e}");
    }
}

#[test]
fn cosine_grid_round_trip() {
    // Samples → coefficients → samples on the same grid is the identity (interpolation).
    let mut rng = Lcg::new(99);
    for n in [1usize, 2, 7, 1000] {
        let f: Vec<f64> = (0..=n).map(|_| rng.symmetric()).collect();
        let a = coefficients_from_cosine_grid(&f).unwrap();
        let back = evaluate_on_cosine_grid(&a, n).unwrap();
        let err = rel(&back, &f);
        println!("N = {n}: samples round trip {err:.2e}");
        // Measured 3.4e-14 at N = 1000.
        assert!(err < 5e-14, "N = {n}: {err:e}");
    }
    assert!(coefficients_from_cosine_grid(&[1.0]).is_err());
    assert!(evaluate_on_cosine_grid(&[1.0], 0).is_err());
}
